"""How close a fit to a noisy record comes to the best point of its own objective.

With noise-free truth available, the weights fitted to the *clean* record
(the same estimator, settings and ``random_state``) are a reference point of
the objective a fit to the *noisy* record minimises: their free run from rest
on the noisy training record has a mean squared error the fit could reach.
The **oracle ratio** is

    ratio = MSE(fit's free run, noisy record) / MSE(clean fit's free run, noisy record)

so 1 means training reached the reference point, and above 1 that a better
point of the very objective exists and training stopped short of it. The
scores beside it say whether reaching it matters on unseen data:

* ``test``: median NRMSE of the fit's free run from rest on noise-free test
  records;
* ``clean test``: the same for the clean fit (what the records allow);
* ``schedule, clean``: the TDL network fitted to the *clean* record with the
  schedule the noisy records chose (``shooting="free"``): it separates what
  the noise costs from what the noisy-record schedule costs.

Systems (every fit with the defaults and ``random_state`` 0-2):

* the hysteretic oscillator of the accuracy benchmark's protocol P1 (one
  training record of 2000 samples at dt = 0.01 s, displacement out, two
  validation records passed as ``X_val``; noise on the training and
  validation outputs; 25 test records);
* a lightly damped two-mode chain (2 % damping, one record of 1024 samples
  under white excitation; the last fifth validates; a test record of 1000
  samples).

Noise: white, 0.1 %, 1 % and 3 % of each output's standard deviation.

Each network also with ``refit=True`` (its chosen weights continued on the
validation records too; the reference fitted so as well); the
``refit_steps_`` column lists the steps each seed's fit took on all records.

Run: ``python benchmarks/bench_oracle.py [out.md]`` (about 10 minutes);
results in ``results_oracle.md``.
"""

from __future__ import annotations

import os
import sys
import time
from functools import partial
from pathlib import Path

import numpy as np
from scipy.signal import lfilter

sys.path.insert(0, str(Path(__file__).resolve().parent))

import _protocol as P
from bench_linear import chain

from sysid_nn import ISSMRegressor, TDLRegressor

LEVELS = (0.001, 0.01, 0.03)
SEEDS = (0, 1, 2)
POOL_SEED = 2024
MODELS = {
    "TDL": TDLRegressor,
    "ISSM": ISSMRegressor,
    "TDL, refit": partial(TDLRegressor, refit=True),
    "ISSM, refit": partial(ISSMRegressor, refit=True),
}


def oscillator():
    """Training, validation and test records of the accuracy protocol P1."""
    split = P.make_split(P.make_pool(POOL_SEED), "P1", P.BASE_DT, "x")

    def noisy(level):
        s = P.with_noise(split, level, seed=(POOL_SEED, round(level * 1e6)))
        return s.X_train, s.y_train, s.X_val, s.y_val

    clean = (split.X_train, split.y_train, split.X_val, split.y_val)
    return clean, noisy, (split.X_test, split.y_test)


def two_mode_chain():
    """One record of a lightly damped chain; validation from its tail."""
    b, a = chain((0.04, 0.11), 0.02)
    rng = np.random.default_rng(0)
    u = rng.standard_normal(1024)
    y = lfilter(b, a, u)
    u_test = np.random.default_rng(100).standard_normal(1000)

    def noisy(level):
        e = np.random.default_rng(round(level * 1e6)).standard_normal(len(y))
        return [u[:, None]], [y + level * y.std() * e], None, None

    clean = ([u[:, None]], [y], None, None)
    return clean, noisy, ([u_test[:, None]], [lfilter(b, a, u_test)])


SYSTEMS = {"oscillator, P1": oscillator, "two-mode chain": two_mode_chain}


def _fit(make, records, **params):
    return P.timed_fit(make(**params), *records)


def free_run_mse(est, X, y) -> float:
    """Mean squared error of the free runs from rest over the records."""
    with np.errstate(all="ignore"):
        err = np.concatenate(
            [est.simulate(Xi) - yi for Xi, yi in zip(X, y, strict=True)]
        )
    value = float(np.mean(err**2))
    return value if np.isfinite(value) else np.inf


def test_nrmse(est, test) -> float:
    with np.errstate(all="ignore"):
        scores = [
            P.record_nrmse(y, est.simulate(X)) for X, y in zip(*test, strict=True)
        ]
    return float(np.median(np.nan_to_num(scores, nan=np.inf)))


def rows_of(system: str) -> list[dict]:
    clean, noisy, test = SYSTEMS[system]()
    rows = []
    for name, make in MODELS.items():
        for seed in SEEDS:
            params = dict(random_state=seed)
            ref, _ = _fit(make, clean, **params)
            sched = None
            if name == "TDL":
                sched, _ = _fit(make, clean, shooting="free", **params)
            for level in LEVELS:
                records = noisy(level)
                est, cpu = _fit(make, records, **params)
                X, y = records[0], records[1]
                row = {
                    "system": system,
                    "model": name,
                    "seed": seed,
                    "noise": level,
                    "fit_mse": free_run_mse(est, X, y),
                    "oracle_mse": free_run_mse(ref, X, y),
                    "test": test_nrmse(est, test),
                    "clean_test": test_nrmse(ref, test),
                    "schedule_clean_test": (
                        test_nrmse(sched, test) if sched is not None else np.nan
                    ),
                    "shooting": est.shooting_,
                    "refit_steps": est.refit_steps_,
                    "cpu": cpu,
                    "load": os.getloadavg()[0],
                }
                row["ratio"] = row["fit_mse"] / row["oracle_mse"]
                print(row, flush=True)
                rows.append(row)
    return rows


def report(rows: list[dict], wall: float) -> str:
    lines = [
        "# Oracle comparison",
        "",
        "Command: `python benchmarks/bench_oracle.py` "
        f"(wall time {wall / 60:.1f} min; fit CPU time "
        f"{P.median_range([r['cpu'] for r in rows])} s, one core; 1-minute load "
        f"{P.load_range(rows)} on 2 cores).",
        "",
        "Median (range) over `random_state` 0-2. `ratio`: the fit's free-run MSE "
        "on its noisy training record over the clean fit's on the same record "
        "(1 = the reference point of the objective reached). Test scores: "
        "median NRMSE of the free run from rest on noise-free test records.",
        "",
        "| system | model | noise | ratio | test | clean test | "
        "schedule, clean | shooting_ | refit_steps_ |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for system in SYSTEMS:
        for name in MODELS:
            for level in LEVELS:
                sel = [
                    r
                    for r in rows
                    if (r["system"], r["model"], r["noise"]) == (system, name, level)
                ]
                if not sel:
                    continue
                sched = [r["schedule_clean_test"] for r in sel]
                shooting = sorted({r["shooting"] for r in sel})
                steps = [r["refit_steps"] for r in sel]
                lines.append(
                    f"| {system} | {name} | {level:.1%} | "
                    f"{P.median_range([r['ratio'] for r in sel])} | "
                    f"{P.median_range([r['test'] for r in sel])} | "
                    f"{P.median_range([r['clean_test'] for r in sel])} | "
                    f"{P.median_range(sched) if np.all(np.isfinite(sched)) else '-'} | "
                    f"{', '.join(shooting)} | "
                    f"{'-' if None in steps else ', '.join(map(str, steps))} |"
                )
    return "\n".join(lines) + "\n"


def main(out: str | None = None) -> int:
    start = time.time()
    rows = [r for system in SYSTEMS for r in rows_of(system)]
    P.write_report(report(rows, time.time() - start), out, "results_oracle.md")
    return 0


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:]))
