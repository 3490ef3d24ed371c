"""Fits to one record whose tail the estimator holds out for validation.

A user with a single record calls ``fit(X, y)``: the last fifth is held out
and judged (see the user guide's training page). On a lightly damped
structure that record's tail is short against the response to a wrong
start. This script fits the default ``TDLRegressor()`` and
``ISSMRegressor()`` (``random_state`` 0-4) to one record of the hysteretic
oscillator with nothing else passed, and scores the free run from rest
(NRMSE of the displacement):

* ``1500``: ``HystereticOscillator().generate(5, n_samples=1500,
  random_state=11)``, the first record trains; the other four are unseen;
* ``P1 alone``: the training record of the accuracy benchmark's protocol
  P1 (2000 samples, without its validation records); its 25 test records
  are unseen.

Per fit: the NRMSE on its own record, the median and the worst over the
unseen records (``inf``: the free run diverged), whether the tail was
judged as the record's continuation (``validation_continues_record_``) and
the CPU time of the fit.

Run: ``python benchmarks/bench_held_out_tail.py [out.md]`` (about 3 minutes);
results in ``results_held_out_tail.md``.
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import _protocol as P

from sysid_nn import HystereticOscillator, ISSMRegressor, TDLRegressor
from sysid_nn.metrics import nrmse

SEEDS = (0, 1, 2, 3, 4)
MODELS = {"TDLRegressor()": TDLRegressor, "ISSMRegressor()": ISSMRegressor}


def records() -> dict:
    rec = HystereticOscillator().generate(5, n_samples=1500, random_state=11)
    X = [f[:, None] for f in rec.excitation]
    split = P.make_split(P.make_pool(2024), "P1", P.BASE_DT, "x")
    return {
        "1500": (X[0], rec.displacement[0], X[1:], list(rec.displacement[1:])),
        "P1 alone": (split.X_train[0], split.y_train[0], split.X_test, split.y_test),
    }


def _score(model, X, y) -> float:
    with np.errstate(all="ignore"):
        value = float(nrmse(y, model.simulate(X)))
    return value if np.isfinite(value) else np.inf


def rows() -> list[dict]:
    out = []
    for case, (X, y, X_new, y_new) in records().items():
        for label, make in MODELS.items():
            for seed in SEEDS:
                model, cpu = P.timed_fit(make(random_state=seed), X, y)
                unseen = [
                    _score(model, a, b) for a, b in zip(X_new, y_new, strict=True)
                ]
                row = {
                    "case": case,
                    "model": label,
                    "seed": seed,
                    "own": _score(model, X, y),
                    "unseen": float(np.median(unseen)),
                    "worst": float(np.max(unseen)),
                    "continued": getattr(model, "validation_continues_record_", None),
                    "selected": model.selected_,
                    "cpu": cpu,
                    "load": os.getloadavg()[0],
                }
                print(row, flush=True)
                out.append(row)
    return out


def report(found: list[dict], wall: float) -> str:
    lines = [
        "# One record, its tail held out",
        "",
        "Command: `python benchmarks/bench_held_out_tail.py` "
        f"(wall time {wall / 60:.1f} min, fits on one core, 1-minute load "
        f"{P.load_range(found)} on 2 cores). Median (range) over `random_state` "
        "0-4; NRMSE of the free run from rest.",
        "",
        "| record | model | own record | unseen: median | unseen: worst | "
        "fits with a diverged unseen record | tail as continuation | "
        "linear model returned | CPU-s |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for case in dict.fromkeys(r["case"] for r in found):
        for label in MODELS:
            sel = [r for r in found if (r["case"], r["model"]) == (case, label)]
            lines.append(
                f"| {case} | {label} | {P.median_range([r['own'] for r in sel])} | "
                f"{P.median_range([r['unseen'] for r in sel])} | "
                f"{P.median_range([r['worst'] for r in sel])} | "
                f"{sum(not np.isfinite(r['worst']) for r in sel)} of {len(sel)} | "
                f"{sum(bool(r['continued']) for r in sel)} of {len(sel)} | "
                f"{sum(r['selected'] == 'linear' for r in sel)} of {len(sel)} | "
                f"{P.median_range([r['cpu'] for r in sel])} |"
            )
    return "\n".join(lines) + "\n"


def main(out: str | None = None) -> int:
    start = time.time()
    P.write_report(report(rows(), time.time() - start), out, "results_held_out_tail.md")
    return 0


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:]))
