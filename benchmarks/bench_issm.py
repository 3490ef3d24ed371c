"""Speed of the ISSM recurrence kernels and of one training restart.

Measures, for the paper's ISSM network (3 states with displacement and
velocity measured, 7 logistic hidden nodes, no linear part, 73 weights) on
one hysteretic-oscillator record of N = 2000 samples:

- the cost per time step of the forward pass alone and of the forward pass
  with the full recurrent Jacobian (eq. 10 sensitivities), in prediction mode
  (innovations fed back) and in free-run simulation mode;
- the adjoint (BPTT) gradient per step;
- the fit time of one restart of the paper's configuration, and of the
  default configuration for comparison.

Run: ``python benchmarks/bench_issm.py``; writes ``results_issm.md``.
"""

from __future__ import annotations

import platform
import time
import timeit
import warnings
from pathlib import Path

import numpy as np

from sysid_nn import HystereticOscillator, ISSMRegressor
from sysid_nn._records._data import _FREE_RUN
from sysid_nn.study import PAPER_ISSM

HERE = Path(__file__).resolve().parent


def _best_time(fn) -> float:
    return min(timeit.repeat(fn, repeat=7, number=5)) / 5


def main() -> None:
    rec = HystereticOscillator().generate(3, random_state=0)
    X = [f[:, None] for f in rec.excitation]
    Y = [
        np.column_stack([d, v])
        for d, v in zip(rec.displacement, rec.velocity, strict=True)
    ]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = ISSMRegressor(**PAPER_ISSM, n_init=1, max_iter=2, random_state=0)
        model.fit(X[0], Y[0])
    data = model._stack([X[1]], [Y[1]])
    w = model.coefs_
    n_steps = len(data.modelled)
    rows = [
        f"# ISSM kernel benchmark\n\nMachine: {platform.machine()}, "
        f"{platform.python_version()}. Paper network: {len(w)} weights, "
        f"N = {n_steps} steps.\n",
        "| measurement | per step (us) |",
        "|---|---|",
    ]
    for label, seg in [("prediction", 1), ("simulation", _FREE_RUN)]:
        t_fwd = _best_time(lambda seg=seg: model._run(w, data, seg, False))
        t_jac = _best_time(lambda seg=seg: model._run(w, data, seg, True))
        state = model._run(w, data, seg, False)[3]
        t_adj = _best_time(lambda seg=seg, st=state: model._gradient(w, data, seg, st))
        rows.append(f"| forward, {label} | {1e6 * t_fwd / n_steps:.3f} |")
        rows.append(f"| forward + Jacobian, {label} | {1e6 * t_jac / n_steps:.3f} |")
        rows.append(f"| adjoint gradient, {label} | {1e6 * t_adj / n_steps:.3f} |")
    rows += [
        "",
        "| fit (one restart, 2 records of 2000, 1 validation) | seconds |",
        "|---|---|",
    ]
    for label, params in [("paper configuration", PAPER_ISSM), ("defaults", {})]:
        est = ISSMRegressor(**params, n_init=1, random_state=0)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            start = time.perf_counter()
            est.fit(X[:2], Y[:2], X_val=X[2], y_val=Y[2])
        rows.append(f"| {label} | {time.perf_counter() - start:.1f} |")
    text = "\n".join(rows) + "\n"
    print(text)
    (HERE / "results_issm.md").write_text(text)


if __name__ == "__main__":
    main()
