"""Speed of the TDL recurrence kernels and of one training restart.

Measures, for the paper's TDL network (6 output and 5 excitation lags, 9
logistic hidden nodes, 118 weights):

- the cost per time step of the forward pass alone and of the forward pass
  with the full recurrent Jacobian (forward sensitivities), at N = 667 and
  N = 2000, and the ratio to the NumPy twin kept in the tests, in the same run;
- the same two kernels against a minimal hand-written numba RTRL kernel for
  the same network (``_rtrl_reference.py``), timed interleaved in one run as
  the best of many repeats of thread CPU time (robust to a loaded machine),
  and the cost of the normal equations ``J'J``, ``J'r`` that Levenberg-
  Marquardt accumulates instead of holding the Jacobian;
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
import threadpoolctl

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))

from _rtrl_reference import forward, forward_jacobian  # noqa: E402
from test_tdl import _twin_run  # noqa: E402 - the NumPy twin lives with the tests

from sysid_nn import HystereticOscillator, TDLRegressor  # noqa: E402
from sysid_nn._records._data import _FREE_RUN  # noqa: E402
from sysid_nn.study import PAPER_TDL  # noqa: E402

#: Repeats of the comparison with the reference kernel: its spread shows how
#: much of a ratio is noise on a shared machine.
REFERENCE_REPEATS = 3

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


def _interleaved(fns: dict, rounds: int = 60) -> dict:
    """Best thread CPU time of each function, the functions taking turns.

    Each turn runs its function twice and times the second call: the first
    refills the caches that the previous function (a Jacobian of megabytes)
    evicted, which would otherwise count against whichever function comes
    next in the round, whatever its own speed.
    """
    best = dict.fromkeys(fns, np.inf)
    for fn in fns.values():
        fn()
    for _ in range(rounds):
        for name, fn in fns.items():
            fn()
            start = time.thread_time()
            fn()
            best[name] = min(best[name], time.thread_time() - start)
    return best


def _reference_row(rec, n: int, repeat: int) -> str:
    """Project kernels against the minimal RTRL kernel, one table row."""
    model, data, w = _paper_model(rec, n)
    na, nb, nk = model._lags()
    h = data.h
    u, y0 = data.U[:, 0].copy(), data.Y[:h, 0].copy()
    yhat = np.empty(len(u))
    J = np.empty((len(u) - h, len(w)))
    forward_jacobian(w, model._S, y0, u, na, nb, nk, yhat, J)
    Yhat, J_project, _, _ = model._run(w, data, _FREE_RUN, True)
    # Same network, same weights: the kernels must agree before being timed.
    assert np.allclose(Yhat[:, 0], yhat, rtol=1e-12, atol=1e-12)
    assert np.allclose(J_project, J, rtol=1e-9, atol=1e-9 * np.abs(J).max())
    S = model._S
    best = _interleaved(
        {
            "ref_fwd": lambda: forward(w, S, y0, u, na, nb, nk, yhat),
            "ref_jac": lambda: forward_jacobian(w, S, y0, u, na, nb, nk, yhat, J),
            "fwd": lambda: model._run(w, data, _FREE_RUN, False, keep_state=False),
            "jac": lambda: model._run(w, data, _FREE_RUN, True, keep_state=False),
            "normal": lambda: model._run(w, data, _FREE_RUN, "normal", False),
            "full_normal": lambda: _full_normal(model, w, data),
        }
    )
    us = {k: v * 1e6 / n for k, v in best.items()}
    return (
        f"| {n} | {repeat} | {os.getloadavg()[0]:.1f} | {us['ref_fwd']:.3f} | "
        f"{us['fwd']:.3f} | "
        f"{us['fwd'] / us['ref_fwd']:.2f} | {us['ref_jac']:.3f} | {us['jac']:.3f} | "
        f"{us['jac'] / us['ref_jac']:.2f} | {us['normal']:.3f} | "
        f"{us['full_normal']:.3f} |"
    )


def _full_normal(model, w, data):
    """Normal equations the way they were formed before: full J, then BLAS."""
    J = model._run(w, data, _FREE_RUN, True, keep_state=False)[1]
    return J.T @ J


def _paper_model(rec, n: int):
    X = rec.excitation[0, :n, None]
    y = rec.displacement[0, :n]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = TDLRegressor(**PAPER_TDL, n_init=1, max_iter=1, random_state=0)
        model.fit(X, y)
    data = model._stack([X], [y[:, None]])
    assert len(model.coefs_) == 118
    return model, data, model.coefs_


def _kernel_row(rec, n: int) -> str:
    """Per-step costs of the paper network on ``n`` samples, one table row."""
    model, data, w = _paper_model(rec, n)
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
    lines += [
        "",
        "## Against a minimal hand-written RTRL kernel",
        "",
        "Same network and weights, free run, one sequence; the kernels agree to "
        "rounding before they are timed. Best of 60 interleaved repeats of the "
        "thread's CPU time (each the second of two calls in a row, so that no "
        "function pays for refilling the caches after another), in "
        "microseconds per step; `forward` and `forward + "
        "Jacobian` are the project's `_run` without the adjoint state. `normal "
        "equations` is the accumulated `J'J`, `J'r` Levenberg-Marquardt uses "
        "(BLAS `dsyrk` by blocks of 256 rows, memory independent of N); `full J, "
        "then J'J` is how they were formed before (N x P Jacobian, then a "
        "matrix product). The whole comparison is repeated "
        f"{REFERENCE_REPEATS} times in this run; load is the machine's load "
        "average (2 cores) when each row was measured.",
        "",
        "| N | repeat | load | reference forward | forward | ratio | reference "
        "forward + Jacobian | forward + Jacobian | ratio | normal equations | "
        "full J, then J'J |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    # A stationary record long enough for both lengths (the modulation of the
    # paper's excitation ends at t2).
    long = HystereticOscillator(t2=200.0).generate(1, 20000, random_state=0)
    with threadpoolctl.threadpool_limits(limits=1, user_api="blas"):
        for repeat in range(1, REFERENCE_REPEATS + 1):
            for n in (2000, 20000):
                lines.append(_reference_row(long, n, repeat))

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
