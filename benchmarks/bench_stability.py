"""The same answer under perturbations a user does not see: seeds and splits.

Fits the default models of :mod:`bench_field` on the community's benchmarks
once per ``random_state`` and per validation split, and reports for every
test record the median test RMSE (free run from rest, after the benchmark's
initialisation window), its range, the spread (largest over smallest) and how
the worst fit compares with the median linear model. The validation splits:

* ``tail``: the estimators' default on one record, the last fifth held out;
* ``split+k``: the last fifth, its start moved ``k`` samples later (``k``
  negative: earlier), passed as ``X_val`` (``split+0`` gives the same fit as
  ``tail``, so it is not run); by default 25 samples later and 10 either way.

Rows go to ``results_stability.csv`` (one per fit and test record, replaced
per benchmark, model, split and seed) and the summary to
``results_stability.md``::

    python benchmarks/bench_stability.py      # Cascaded Tanks and EMPS
    python benchmarks/bench_stability.py --only silverbox,boucwen --shifts 0
    python benchmarks/bench_stability.py --only wiener_hammerstein --shifts 0
    python benchmarks/bench_stability.py --report

(the published file: the three commands above, about 15 CPU-minutes for
the first, 2 CPU-hours for the others). The Bouc-Wen data are generated
once, by ``random_state=0``, for every seed of the fits.

A model ``name[param=value]`` is the model with that parameter set:
``--models "issm[n_init=8]" --out FILE`` fits the ISSM with eight restarts
(``results_restarts.md``).

A figure quoted from this file is a median over seeds with its range, not
one draw. It holds for the BLAS kernel each row records (column ``blas``):
OpenBLAS picks its kernels by the processor, and a training path, which
amplifies the last digit of a sum, ends elsewhere under another kernel.
``OPENBLAS_CORETYPE=Haswell`` (set before Python starts) runs the kernel of
the published rows on any x86-64 processor with AVX2. Rows fitted on another
machine, written with ``--out``, are compared fit by fit with::

    python benchmarks/bench_stability.py --report --against other.csv
"""

from __future__ import annotations

import argparse
import csv
import os
import platform
import subprocess
from collections import Counter
from pathlib import Path

import numpy as np
from _results import read_rows
from bench_field import BENCHMARKS, DEFAULT_MODELS, MODELS, model_variant, run_one

from sysid_nn.study._report import blas_kernels

HERE = Path(__file__).resolve().parent
CSV = HERE / "results_stability.csv"
FIELDS = [
    "benchmark", "model", "split", "random_state", "test", "unit", "rmse",
    "cpu_s", "load", "warnings", "tree", "blas",
]  # fmt: skip


def _tree() -> str:
    """The commit the fits ran on (with ``+`` if the checkout had changes)."""
    try:
        head = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"],
            capture_output=True, text=True, cwd=HERE, check=True,
        ).stdout.strip()  # fmt: skip
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"],
            capture_output=True, text=True, cwd=HERE, check=True,
        ).stdout.strip()  # fmt: skip
    except (OSError, subprocess.CalledProcessError):
        return "?"
    return head + ("+" if dirty else "")


def _key(row: dict) -> tuple:
    return (row["benchmark"], row["model"], row["split"], str(row["random_state"]))


def _store(path: Path, rows: list[dict]) -> list[dict]:
    """Replace the stored rows of the same fits; keep the others."""
    new = {_key(r) for r in rows}
    merged = [r for r in read_rows(path) if _key(r) not in new] + rows
    order = list(BENCHMARKS)
    merged.sort(
        key=lambda r: (
            order.index(r["benchmark"]),
            r["test"],
            list(MODELS).index(r["model"]),
            r["split"],
            int(r["random_state"]),
        )
    )
    with path.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=FIELDS)
        writer.writeheader()
        writer.writerows(merged)
    return merged


def summarise(rows: list[dict]) -> list[str]:
    """One Markdown line per benchmark, test record and model."""
    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        groups.setdefault((r["benchmark"], r["test"], r["model"]), []).append(r)
    lines = [
        "| benchmark | test | model | fits | median | range | spread | "
        "worst / linear median | median CPU-s | trees |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for (benchmark, test, model), group in groups.items():
        rmse = np.array([float(r["rmse"]) for r in group])
        linear = [
            float(r["rmse"])
            for r in rows
            if (r["benchmark"], r["test"], r["model"]) == (benchmark, test, "linear")
        ]
        ratio = f"{rmse.max() / np.median(linear):.2f}" if linear else ""
        cpu = np.median([float(r["cpu_s"]) for r in group])
        splits = sorted({r["split"] for r in group})
        trees = ", ".join(sorted({r.get("tree", "?") for r in group}))
        finite = np.isfinite(rmse).all()
        spread = f"{rmse.max() / rmse.min():.2f}" if finite else "diverged"
        lines.append(
            f"| {benchmark} | {test} | {MODELS[model][0]} | {len(group)} "
            f"({len(splits)} splits) | {np.median(rmse):.4g} {group[0]['unit']} | "
            f"{rmse.min():.4g} - {rmse.max():.4g} | {spread} | {ratio} | "
            f"{cpu:.1f} | {trees} |"
        )
    return lines


def compare(rows: list[dict], other: list[dict]) -> list[str]:
    """Fit by fit, ``other``'s rows (another machine's, say) against
    ``rows``: per benchmark, test and model, how many of the fits both hold
    are identical (to 1e-9 relative), and both ranges over those fits."""
    mine = {(*_key(r), r["test"]): float(r["rmse"]) for r in rows}
    groups: dict[tuple, list[tuple]] = {}
    for r in other:
        k = (*_key(r), r["test"])
        if k in mine:
            groups.setdefault((r["benchmark"], r["test"], r["model"]), []).append(
                (mine[k], float(r["rmse"]), r.get("blas") or "not recorded")
            )
    lines = [
        "| benchmark | test | model | fits | identical | range here | range there "
        "| kernels there |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for (benchmark, test, model), pairs in groups.items():
        a, b, kinds = (np.array(v) for v in zip(*pairs, strict=True))
        same = int(np.sum(np.isclose(a, b, rtol=1e-9, atol=0.0)))
        lines.append(
            f"| {benchmark} | {test} | {MODELS[model][0]} | {len(a)} | {same} | "
            f"{a.min():.4g} - {a.max():.4g} | {b.min():.4g} - {b.max():.4g} | "
            f"{', '.join(sorted(set(kinds)))} |"
        )
    return lines


def write_report(path: Path, rows: list[dict]) -> str:
    splits = sorted({r["split"] for r in rows})
    seeds = sorted({int(r["random_state"]) for r in rows})
    loads = [float(r["load"]) for r in rows if r.get("load")]
    text = "\n".join(
        [
            "# The same answer under seeds and validation splits",
            "",
            "Test RMSE of the free run from rest after the initialisation window, "
            f"over `random_state` in {seeds} and the validation splits {splits} "
            "(`tail`: the estimators' default, the last fifth of the training "
            "record held out; `split+k`: the last fifth moved `k` samples later, "
            "passed as `X_val`). Spread: largest over smallest test RMSE of a "
            "model's fits. Worst / linear median: its worst fit over the median "
            "of the linear model's. CPU time of one fit on one core "
            f"({platform.machine()}, {os.cpu_count()} cores shared with other "
            f"jobs, 1-minute load {min(loads, default=0):.1f}-"
            f"{max(loads, default=0):.1f}). BLAS kernels: "
            f"{_kernels(rows)}. Written by `benchmarks/bench_stability.py`.",
            "",
            *summarise(rows),
            "",
        ]
    )
    path.with_suffix(".md").write_text(text)
    return text


def _kernels(rows: list[dict]) -> str:
    """The kernels the rows record, with how many rows ran on each."""
    counts = Counter(r.get("blas") or "not recorded" for r in rows)
    return "; ".join(f"{k} ({n} rows)" for k, n in sorted(counts.items()))


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--only", default="cascaded_tanks,emps")
    parser.add_argument("--models", default=",".join(DEFAULT_MODELS))
    parser.add_argument("--seeds", default="0,1,2,3,4")
    parser.add_argument(
        "--shifts",
        default="0,25,10,-10",
        help="validation starts, in samples after four fifths (0: the default tail)",
    )
    parser.add_argument("--data-home", default=None, help="data directory")
    parser.add_argument("--out", default=str(CSV), help="results CSV")
    parser.add_argument("--report", action="store_true", help="only summarise")
    parser.add_argument(
        "--against",
        default=None,
        help="another results CSV (another machine's) to compare fit by fit",
    )
    args = parser.parse_args(argv)
    out = Path(args.out)
    benchmarks = [b for b in args.only.split(",") if b]
    models = [m for m in args.models.split(",") if m]
    unknown = set(benchmarks) - set(BENCHMARKS) | {
        m for m in models if not model_variant(m)
    }
    if unknown:
        parser.error(f"unknown benchmark or model: {', '.join(sorted(unknown))}")
    published = read_rows(out)
    for row in published:
        model_variant(row["model"])  # the variants fitted before
    if args.against:
        print("\n".join(compare(published, read_rows(Path(args.against)))))
        return
    if not args.report:
        tree, blas = _tree(), blas_kernels()
        seeds = [int(s) for s in args.seeds.split(",")]
        shifts = [int(s) for s in args.shifts.split(",")]
        for benchmark in benchmarks:
            data = BENCHMARKS[benchmark][0](data_home=args.data_home)
            for shift in shifts:
                split = "tail" if shift == 0 else f"split{shift:+d}"
                validation = "tail" if shift == 0 else "split"
                for model in models:
                    for seed in seeds:
                        fitted = run_one(
                            benchmark,
                            model,
                            data,
                            validation,
                            random_state=seed,
                            shift=shift,
                        )
                        rows = [
                            {
                                **{k: r[k] for k in FIELDS if k in r},
                                "split": split,
                                "random_state": seed,
                                "tree": tree,
                                "blas": blas,
                            }
                            for r in fitted
                        ]
                        _store(out, rows)
    print(write_report(out, read_rows(out)))


if __name__ == "__main__":
    main()
