"""Single fits against ensembles of fits, under the draws a user does not see.

A single default fit to one record depends on its seed and on which share
of the record is held out to validate it. This benchmark fits, on the
field benchmarks' training record (the tail held out, the estimators'
default protocol):

* single default networks with ``validation_fraction`` 0.15, 0.2, 0.25
  and 0.3, once per ``random_state``;
* ``EnsembleRegressor`` of the same network (eight members, the same four
  shares in turn), once per ``random_state``;

and reports, per benchmark and network, the median test RMSE (free run
from rest after the initialisation window, as :mod:`bench_field`), its
range, the spread (largest over smallest) and the median CPU time of a
fit. Run::

    python benchmarks/bench_ensemble.py [--only cascaded_tanks,emps]
        [--seeds 0,1,2,3,4] [--data-home DIR]

(about 40 CPU-minutes for both benchmarks; ``results_ensemble.md``).
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_field import BENCHMARKS, run_one

from sysid_nn import EnsembleRegressor, ISSMRegressor, TDLRegressor

HERE = Path(__file__).resolve().parent
OUT = HERE / "results_ensemble.md"
NETWORKS = {"TDLRegressor()": TDLRegressor, "ISSMRegressor()": ISSMRegressor}
FRACTIONS = (0.15, 0.2, 0.25, 0.3)


def candidates(network):
    """``(label, factory)`` of the single fits at each held-out share and
    of the ensemble."""
    for share in FRACTIONS:
        yield (
            f"single, validation_fraction={share}",
            lambda seed, share=share: network(
                random_state=seed, validation_fraction=share
            ),
        )
    yield (
        "EnsembleRegressor, 8 members",
        lambda seed: EnsembleRegressor(network(), random_state=seed),
    )


def _summary(values) -> str:
    v = np.asarray(values, dtype=float)
    if not np.all(np.isfinite(v)):
        return f"{np.median(v):.4g} (diverged) | - "
    return f"{np.median(v):.4g} ({v.min():.4g}-{v.max():.4g}) | {v.max() / v.min():.2f}"


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--only", default="cascaded_tanks,emps")
    parser.add_argument("--seeds", default="0,1,2,3,4")
    parser.add_argument("--data-home", default=None, help="data directory")
    parser.add_argument("--out", default=str(OUT), help="report file (markdown)")
    args = parser.parse_args(argv)
    seeds = [int(s) for s in args.seeds.split(",")]
    started = time.time()
    lines = [
        "# Single fits and ensembles of fits",
        "",
        "Command: `python benchmarks/bench_ensemble.py "
        f"--only {args.only} --seeds {args.seeds}`; "
        f"{platform.machine()}, {os.cpu_count()} cores shared with other jobs, "
        f"1-minute load at the start {os.getloadavg()[0]:.1f}.",
        "",
        f"Test RMSE of the free run from rest, over `random_state` {seeds}, the "
        "training record's tail held out (no `X_val`). `single, all shares`: "
        "the single fits of the four shares together, the draws a user of one "
        "fit gets. Spread: largest over smallest. CPU-s: median of a fit, one "
        "core.",
        "",
        "| benchmark | network | fits | median (range) | spread | CPU-s |",
        "|---|---|---|---|---|---|",
    ]
    for benchmark in [b for b in args.only.split(",") if b]:
        data = BENCHMARKS[benchmark][0](data_home=args.data_home)
        for name, network in NETWORKS.items():
            pooled, pooled_cpu = [], []
            for label, factory in candidates(network):
                errors, cpu = [], []
                for seed in seeds:
                    (row,) = run_one(
                        benchmark, label, data, "tail", random_state=seed,
                        factory=factory,
                    )  # fmt: skip
                    errors.append(row["rmse"])
                    cpu.append(row["cpu_s"])
                if label.startswith("single"):
                    pooled += errors
                    pooled_cpu += cpu
                else:
                    lines.append(
                        f"| {benchmark} | {name} | single, all shares | "
                        f"{_summary(pooled)} | {np.median(pooled_cpu):.1f} |"
                    )
                lines.append(
                    f"| {benchmark} | {name} | {label} | {_summary(errors)} "
                    f"| {np.median(cpu):.1f} |"
                )
    lines += [
        "",
        f"Wall time {(time.time() - started) / 60:.0f} min; 1-minute load at the "
        f"end {os.getloadavg()[0]:.1f}. Errors in the benchmark's unit "
        "(V for Cascaded Tanks, m for EMPS).",
        "",
    ]
    Path(args.out).write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
