"""Variance of fits to one record: what selection and averaging can recover.

With one training record (protocol P1 of ``_protocol.py``) the restarts of a
fit land in different minima, and their test errors spread over an order of
magnitude. This benchmark measures, per pool seed, noise level and network:

* the default fit (``n_init=4``, ``random_state=0``);
* ``--n-fits`` single-restart fits (``n_init=1``, ``random_state=k``), each
  scored on the two validation records (free-run NRMSE from rest against the
  noisy validation outputs: what a user sees) and on the 25 noise-free test
  records (median free-run NRMSE);
* the single fit with the best validation score (selection among many
  restarts), and the average of the simulations of the best 2, 4 and 8 by
  validation (an ensemble of the best restarts);
* the spread of the single fits' test errors and the rank correlation of
  their validation and test scores.

Usage::

    python benchmarks/bench_single_record.py              # full run, ~4 min on 2 cores
    python benchmarks/bench_single_record.py --seeds 2024 --noise 0.01 --n-fits 6

Writes ``results_single_record.md`` next to this file (``--out`` elsewhere).
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import sys
import time
import warnings
from pathlib import Path

import numpy as np
from joblib import Parallel, delayed
from scipy.stats import spearmanr

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import _protocol as P  # noqa: E402

from sysid_nn import ISSMRegressor, TDLRegressor  # noqa: E402

#: name -> (label, estimator class, measured outputs)
MODELS = {
    "tdl": ("TDL default", TDLRegressor, "x"),
    "issm_x": ("ISSM default, X only", ISSMRegressor, "x"),
    "issm_xv": ("ISSM default, X+V measured", ISSMRegressor, "xv"),
}
ENSEMBLES = (2, 4, 8)


def _median_test(split: P.Split, sims) -> float:
    return float(
        np.median(
            [P.record_nrmse(t, s) for t, s in zip(split.y_test, sims, strict=True)]
        )
    )


def _fit(cls, split: P.Split, **params):
    """Fit on the split's one record; its validation score and test simulations."""
    est = cls(**params)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        est.fit(split.X_train, split.y_train, X_val=split.X_val, y_val=split.y_val)
        val = [
            P.record_nrmse(t, s)
            for t, s in zip(split.y_val, est.simulate(split.X_val), strict=True)
        ]
        sims = est.simulate(split.X_test)
    return float(np.mean(val)), sims


def _average(sims_list) -> list:
    """Record by record, the mean of the members' simulations."""
    return [np.mean(members, axis=0) for members in zip(*sims_list, strict=True)]


def measure(seed: int, noise: float, model: str, n_fits: int, n_jobs: int) -> dict:
    label, cls, outputs = MODELS[model]
    split = P.make_split(P.make_pool(seed), "P1", P.BASE_DT, outputs)
    if noise:
        # The accuracy benchmark's noise: the same draw for every model.
        split = P.with_noise(split, noise, seed=(seed, round(noise * 1e6)))
    start = time.perf_counter()
    _, default_sims = _fit(cls, split, random_state=0)
    singles = Parallel(n_jobs=n_jobs)(
        delayed(_fit)(cls, split, n_init=1, random_state=k) for k in range(n_fits)
    )
    val = np.array([v for v, _ in singles])
    test = np.array([_median_test(split, s) for _, s in singles])
    order = np.argsort(val, kind="stable")
    row = {
        "seed": seed,
        "noise": noise,
        "model": label,
        "default": _median_test(split, default_sims),
        "best of n by validation": float(test[order[0]]),
    }
    for k in ENSEMBLES:
        if k <= n_fits:
            members = [singles[i][1] for i in order[:k]]
            row[f"average of best {k}"] = _median_test(split, _average(members))
    finite = np.isfinite(test) & np.isfinite(val)
    row["single fits min / median / max"] = (
        f"{test.min():.3g} / {np.median(test):.3g} / {test.max():.3g}"
    )
    row["rank correlation val-test"] = (
        float(spearmanr(val[finite], test[finite])[0]) if finite.sum() > 2 else np.nan
    )
    row["wall s"] = time.perf_counter() - start
    row["load"] = os.getloadavg()[0]
    return row


def _cell(v) -> str:
    return f"{v:.3g}" if isinstance(v, float) else str(v)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", default="2024,2025", help="pool seeds")
    ap.add_argument("--noise", default="0,0.01,0.03", help="noise levels")
    ap.add_argument("--models", default=",".join(MODELS), help="comma list")
    ap.add_argument("--n-fits", type=int, default=12, help="single-restart fits")
    ap.add_argument("--n-jobs", type=int, default=2, help="parallel fits")
    ap.add_argument("--out", default=str(HERE), help="output directory")
    args = ap.parse_args(argv)
    models = args.models.split(",")
    unknown = set(models) - set(MODELS)
    if unknown:
        ap.error(f"unknown model(s) {sorted(unknown)}; choose from {', '.join(MODELS)}")
    wall = time.perf_counter()
    rows = []
    for seed in (int(s) for s in args.seeds.split(",")):
        for noise in (float(v) for v in args.noise.split(",")):
            for model in models:
                row = measure(seed, noise, model, args.n_fits, args.n_jobs)
                print(" | ".join(f"{k} {_cell(v)}" for k, v in row.items()), flush=True)
                rows.append(row)
    keys = list(rows[0])
    lines = [
        "# Fits to one record: selection and averaging",
        "",
        f"Command: `python benchmarks/bench_single_record.py {' '.join(argv or [])}`"
        f" (run time {(time.perf_counter() - wall) / 60:.1f} min)",
        "",
        f"- date: {datetime.datetime.now().isoformat(timespec='seconds')}",
        f"- {platform.platform()}, {platform.machine()}, {os.cpu_count()} CPUs; "
        f"fits run {args.n_jobs} at a time (`wall s`: the row's wall time, "
        "`load`: the 1-minute load average after it)",
        "",
        "Protocol P1 of the accuracy benchmark (one training record, two "
        "validation records, 25 noise-free test records; white noise on the "
        "training and validation outputs). Median free-run NRMSE from rest on "
        f"the test records. {args.n_fits} single-restart fits (`n_init=1`, "
        "`random_state=k`) are ranked by their validation NRMSE.",
        "",
        "| " + " | ".join(keys) + " |",
        "|" + "---|" * len(keys),
    ]
    lines += ["| " + " | ".join(_cell(r[k]) for k in keys) + " |" for r in rows]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "results_single_record.md").write_text("\n".join(lines) + "\n")
    print(f"wrote {out / 'results_single_record.md'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
