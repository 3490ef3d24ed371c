"""Single fits against ensembles of fits, under the draws a user does not see.

A single default fit to one record depends on its seed and on which share
of the record is held out to validate it. This benchmark fits, on the
systems of :mod:`bench_constants` (the field benchmarks with their tail
held out, the estimators' default protocol; the lightly damped chain; the
oscillator's protocol P1, whose validation records are given as ``X_val``):

* single default networks with ``validation_fraction`` 0.15, 0.2, 0.25
  and 0.3 (the default only where ``X_val`` is given), once per
  ``random_state``;
* ``EnsembleRegressor`` of the same network (eight members, the four
  shares in turn), once per ``random_state``; each ensemble is also scored
  with every member in its median (``max_error_ratio=None``: the same fits,
  combined as before members that miss the fitted records were left out);

and reports, per case and network, the median test error, its range and
spread (largest over smallest) over the single fits of every share and
seed (the draws a user of one fit gets) and over the ensembles, the single
fits' median per share, and the median CPU time of a fit. Run::

    python benchmarks/bench_ensemble.py [--only cascaded_tanks,emps]
        [--seeds 0,1,2,3,4] [--shifts 0] [--data-home DIR] [--out FILE]

``--shifts -10,10,25`` also fits, on the field benchmarks, the ensembles
whose members' held-out parts start that many samples later than the
shares put them (the ensemble's own splits moved, as ``bench_stability``
moves a single fit's), and reports every ensemble of the five splits
together; the single fits under moved splits are ``bench_stability``'s.

``--distil`` fits every ensemble with ``distil=True`` and also scores the
network fitted to its median (``network_``: the members, and so the
ensembles' columns, are the same as without it); ``--no-single`` skips the
single fits (their columns are then empty); ``--networks issm`` fits the
ISSM alone.

(the defaults: about 40 CPU-minutes; ``results_ensemble.md`` also holds
``--only chains,oscillator --seeds 0,1,2``).
"""

from __future__ import annotations

import argparse
import copy
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import _protocol as P
from bench_constants import cases, fit_scored
from bench_field import BENCHMARKS

from sysid_nn import EnsembleRegressor, ISSMRegressor, TDLRegressor
from sysid_nn.study._report import blas_kernels

HERE = Path(__file__).resolve().parent
OUT = HERE / "results_ensemble.md"
NETWORKS = {"TDLRegressor()": TDLRegressor, "ISSMRegressor()": ISSMRegressor}
FRACTIONS = (0.15, 0.2, 0.25, 0.3)
#: Systems whose cases pass validation records (the shares do not act).
WITH_X_VAL = {"oscillator"}


def _range(values) -> str:
    """``"median (min - max), spread"`` of test errors."""
    v = np.asarray(values, dtype=float)
    if not len(v):
        return "-"
    if not np.all(np.isfinite(v)):
        return f"{np.median(v):.4g}, not finite in {np.sum(~np.isfinite(v))}"
    return f"{P.median_range(v, 4)}, {v.max() / v.min():.2f}"


def moved(n_train: int | None, shift: int) -> tuple:
    """The ensemble's held-out shares of a record of ``n_train`` samples,
    each part starting ``shift`` samples later (``n_train`` is needed only
    where ``shift`` is not 0)."""
    if not shift:
        return FRACTIONS
    return tuple((round(f * n_train) - shift) / n_train for f in FRACTIONS)


def _every(ensemble, score) -> float:
    """``score`` of ``ensemble`` with every member in its median."""
    every = copy.copy(ensemble)
    every.members_used_ = np.ones(len(ensemble.estimators_), dtype=bool)
    return score(every)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--only", default="cascaded_tanks,emps")
    parser.add_argument("--seeds", default="0,1,2,3,4")
    parser.add_argument("--shifts", default="0", help="held-out starts moved")
    parser.add_argument("--data-home", default=None, help="data directory")
    parser.add_argument("--out", default=str(OUT), help="report file (markdown)")
    parser.add_argument(
        "--distil", action="store_true", help="also score each ensemble's network_"
    )
    parser.add_argument("--no-single", action="store_true", help="no single fits")
    parser.add_argument("--networks", default="tdl,issm", help="tdl, issm or both")
    args = parser.parse_args(argv)
    seeds = [int(s) for s in args.seeds.split(",")]
    shifts = sorted({0, *(int(s) for s in args.shifts.split(","))})
    started, loads = time.time(), [os.getloadavg()[0]]
    lines = [
        f"Command: `python benchmarks/bench_ensemble.py --only {args.only} "
        f"--seeds {args.seeds} --shifts {args.shifts}"
        f"{' --distil' if args.distil else ''}"
        f"{' --no-single' if args.no_single else ''}"
        f"{'' if args.networks == 'tdl,issm' else ' --networks ' + args.networks}`; "
        f"{platform.machine()}, "
        f"{os.cpu_count()} cores shared with other jobs, BLAS {blas_kernels()}.",
        "",
        "| system | case | network | single: median (range), spread | "
        "ensemble: median (range), spread | every member | members left out | "
        f"single, median per share {' / '.join(map(str, FRACTIONS))} | "
        "CPU-s single / ensemble |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    moved_lines: list[str] = []
    for system in [s for s in args.only.split(",") if s]:
        shares = (None,) if system in WITH_X_VAL else FRACTIONS
        n_train = None
        if system in BENCHMARKS:
            n_train = len(BENCHMARKS[system][0](data_home=args.data_home).y_train[0])
        for label, fit, score in cases(system, args.data_home):
            if label.startswith("split"):
                continue  # the field records' default protocol only
            for name, network in NETWORKS.items():
                if network.__name__.removesuffix(
                    "Regressor"
                ).lower() not in args.networks.split(","):
                    continue
                single, per_share, ensemble, cpu_single, cpu_ensemble = (
                    [],
                    {},
                    [],
                    [],
                    [],
                )
                moved_ensembles: dict = {}
                moved_every: dict = {}
                moved_networks: dict = {}
                disagreements: list = []
                attempts: list = []
                left_out = members = 0
                for seed in seeds:
                    for share in shares if not args.no_single else ():
                        extra = {} if share is None else {"validation_fraction": share}
                        _, test, cpu = fit_scored(
                            fit, score, network(random_state=seed, **extra)
                        )
                        single.append(test)
                        per_share.setdefault(share, []).append(test)
                        cpu_single.append(cpu)
                    for shift in shifts if n_train else (0,):
                        fitted, test, cpu = fit_scored(
                            fit,
                            score,
                            EnsembleRegressor(
                                network(),
                                validation_fractions=moved(n_train, shift),
                                distil=args.distil,
                                random_state=seed,
                            ),
                        )
                        moved_ensembles.setdefault(shift, []).append(test)
                        moved_every.setdefault(shift, []).append(_every(fitted, score))
                        if args.distil:
                            network_test = score(fitted.network_)
                            moved_networks.setdefault(shift, []).append(network_test)
                            disagreements.append(fitted.draw_disagreement_)
                            attempts.append(len(fitted.network_record_errors_))
                        if shift == 0:
                            left_out += int(np.sum(~fitted.members_used_))
                            members += len(fitted.estimators_)
                        cpu_ensemble.append(cpu)
                    loads.append(os.getloadavg()[0])
                    print(system, label, name, seed, single[-len(shares) :],
                          [v[-1] for v in moved_ensembles.values()],
                          [v[-1] for v in moved_networks.values()],
                          disagreements[-len(moved_networks):],
                          attempts[-len(moved_networks):],
                          flush=True)  # fmt: skip
                medians = " / ".join(f"{np.median(v):.4g}" for v in per_share.values())
                medians = medians or "-"
                ensemble = moved_ensembles.get(0, [])
                if len(moved_ensembles) > 1 or moved_networks:
                    for tag, runs in (
                        ("", moved_ensembles),
                        (", every member", moved_every),
                        (
                            ", network_ (draw_disagreement_ "
                            f"{min(disagreements, default=0):.2g}-"
                            f"{max(disagreements, default=0):.2g}; fitted again "
                            f"in {sum(a > 1 for a in attempts)} of {len(attempts)})",
                            moved_networks,
                        ),
                    ):
                        if not runs:
                            continue
                        every = np.concatenate(list(runs.values()))
                        moved_lines.append(
                            f"| {system} | {label} | {name}{tag} | "
                            + " | ".join(_range(runs[k]) for k in sorted(runs))
                            + f" | {_range(every)} |"
                        )
                lines.append(
                    f"| {system} | {label} | {name} | {_range(single)} | "
                    f"{_range(ensemble)} | {_range(moved_every.get(0, []))} | "
                    f"{left_out} of {members} | "
                    f"{medians} | "
                    f"{np.median(cpu_single) if single else np.nan:.1f} / "
                    f"{np.median(cpu_ensemble):.1f} |"
                )
    if moved_lines:
        lines += [
            "",
            "Ensembles whose members' held-out parts start "
            + ", ".join(map(str, sorted(shifts)))
            + " samples later than the shares put them:",
            "",
            "| system | case | network | "
            + " | ".join(f"{k:+d}" for k in sorted(shifts))
            + " | all |",
            "|---" * (4 + len(shifts)) + "|",
            *moved_lines,
        ]
    lines += [
        "",
        f"Wall time {(time.time() - started) / 60:.0f} min; 1-minute load "
        f"{min(loads):.1f}-{max(loads):.1f}.",
        "",
    ]
    Path(args.out).write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
