"""Speed of the TDL recurrence kernels and of one training restart.

Measures, for the paper's TDL network (6 output and 5 excitation lags, 9
logistic hidden nodes, 118 weights):

- the cost per time step of the forward pass alone and of the forward pass
  with the full recurrent Jacobian (forward sensitivities), at N = 667 and
  N = 2000, and the ratio to the NumPy twin kept in the tests, in the same run;
- the adjoint (BPTT) gradient per step;
- the fit time of one restart of the paper's configuration;
- cold (empty numba cache) and warm import + first-call times.

Run: ``python benchmarks/bench_kernels.py``; writes ``results_kernels.md``.
"""

from __future__ import annotations

import os
import platform
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numba
import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))

from test_tdl import _twin_run  # noqa: E402 - the NumPy twin lives with the tests

from sysid_nn import HystereticOscillator, TDLRegressor  # noqa: E402
from sysid_nn._base import _FREE_RUN  # noqa: E402
from sysid_nn.study import PAPER_TDL  # noqa: E402

FIRST_CALL = """
import time, numpy as np
t0 = time.perf_counter()
from sysid_nn import TDLRegressor
rng = np.random.default_rng(0)
X = rng.standard_normal((300, 1)); y = np.cumsum(X[:, 0]) * 0.01
TDLRegressor(n_init=1, max_iter=2, shooting_segments=(), random_state=0).fit(X, y)
print(time.perf_counter() - t0)
"""


def _best_time(fn, repeat: int = 7, number: int = 5) -> float:
    best = np.inf
    for _ in range(repeat):
        start = time.perf_counter()
        for _ in range(number):
            fn()
        best = min(best, (time.perf_counter() - start) / number)
    return best


def _first_call(cache_dir: str) -> float:
    env = dict(os.environ, NUMBA_CACHE_DIR=cache_dir)
    out = subprocess.run(
        [sys.executable, "-c", FIRST_CALL], env=env, capture_output=True, text=True
    )
    if out.returncode != 0:
        raise RuntimeError(out.stderr)
    return float(out.stdout.strip().splitlines()[-1])


def _kernel_row(rec, n: int) -> str:
    """Per-step costs of the paper network on ``n`` samples, one table row."""
    X = rec.excitation[0, :n, None]
    y = rec.displacement[0, :n]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = TDLRegressor(**PAPER_TDL, n_init=1, max_iter=1, random_state=0)
        model.fit(X, y)
    data = model._stack([X], [y[:, None]])
    w = model.coefs_
    assert len(w) == 118
    state = model._run(w, data, _FREE_RUN, False)[3]
    per_step = 1e6 / n
    fwd = _best_time(lambda: model._run(w, data, _FREE_RUN, False)) * per_step
    jac = _best_time(lambda: model._run(w, data, _FREE_RUN, True)) * per_step
    grad = _best_time(lambda: model._gradient(w, data, _FREE_RUN, state)) * per_step
    twin = _best_time(lambda: _twin_run(model, w, data, _FREE_RUN), 1, 1) * per_step
    return (
        f"| {n} | {fwd:.3f} | {jac:.3f} | {grad:.3f} | {twin:.1f} | {twin / jac:.0f} |"
    )


def main() -> str:
    rec = HystereticOscillator().generate(3, random_state=0)
    lines = [
        "# TDL kernel speed",
        "",
        f"Machine: {platform.machine()}, {os.cpu_count()} cores, "
        f"Python {platform.python_version()}, NumPy {np.__version__}, "
        f"numba {numba.__version__}.",
        "",
        "Paper network: 6/5 lags, 9 logistic hidden nodes, 118 weights; free run.",
        "",
        "| N | forward (us/step) | forward + Jacobian (us/step) | adjoint gradient "
        "(us/step) | NumPy twin forward + Jacobian (us/step) | twin / kernel |",
        "|---|---|---|---|---|---|",
    ]
    for n in (667, 2000):
        lines.append(_kernel_row(rec, n))

    X = rec.excitation[0, ::3, None]
    y = rec.displacement[0, ::3]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        start = time.perf_counter()
        model = TDLRegressor(**PAPER_TDL, n_init=1, max_iter=200, random_state=0)
        model.fit(X, y)
        fit = time.perf_counter() - start
    lines += [
        "",
        f"Fit of one restart of the paper's configuration (667 samples at dt = 0.03 s, "
        f"one-step focus, LM, up to 200 iterations; {model.n_iter_} used): "
        f"{fit:.2f} s.",
    ]
    with tempfile.TemporaryDirectory() as cache:
        cold = _first_call(cache)
        warm = _first_call(cache)
    lines += [
        "",
        f"Import + first fit in a fresh process: cold numba cache {cold:.1f} s, "
        f"warm cache {warm:.1f} s.",
    ]
    text = "\n".join(lines) + "\n"
    (HERE / "results_kernels.md").write_text(text)
    return text


if __name__ == "__main__":
    print(main())
