"""Cost of the hysteretic-oscillator data generator (paper section 4.1).

Measures the one-time numba compilation of the RK4 kernel (in fresh
processes with an empty, then a populated ``NUMBA_CACHE_DIR``), the time to
generate the paper's 25 records of 2000 samples once compiled, the Monte Carlo
calibration of ``r0`` and its accuracy on fresh realisations. Prints a table
and writes ``results_generator.md`` next to this file.

Usage::

    python benchmarks/bench_generator.py
"""

from __future__ import annotations

import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent

# Run in a fresh interpreter: time the import and the first (compiling or
# cache-loading) call separately from a second, compiled call.
_PROBE = """
import json, time
t0 = time.perf_counter()
import numpy as np
from sysid_nn.oscillator import HystereticOscillator
t1 = time.perf_counter()
osc = HystereticOscillator()
osc.simulate(np.zeros((1, 10)), 0.01)
t2 = time.perf_counter()
osc.simulate(np.zeros((1, 10)), 0.01)
t3 = time.perf_counter()
print(json.dumps({"import": t1 - t0, "first": t2 - t1, "second": t3 - t2}))
"""


def _probe(cache_dir: str) -> dict[str, float]:
    env = dict(os.environ, NUMBA_CACHE_DIR=cache_dir)
    out = subprocess.run(
        [sys.executable, "-c", _PROBE],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def _median_time(func, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        func()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main() -> None:
    from sysid_nn.oscillator import HystereticOscillator

    with tempfile.TemporaryDirectory() as cache:
        cold = _probe(cache)
        warm = _probe(cache)

    osc = HystereticOscillator()
    osc.simulate(np.zeros((1, 10)), 0.01)  # compile in this process
    # A RandomState bypasses the in-process cache, so each run calibrates.
    t_cal = _median_time(
        lambda: osc.calibrate_r0(random_state=np.random.RandomState(0)), repeat=3
    )
    r0 = osc.calibrate_r0()
    t_gen = _median_time(lambda: osc.generate(25, random_state=1), repeat=9)
    t_gen_frame = _median_time(
        lambda: osc.generate(25, random_state=1, as_frame=True), repeat=9
    )
    fresh = HystereticOscillator(r0=r0).generate(2000, random_state=2024)
    peaks = np.abs(fresh.displacement).max(axis=1)
    ratio = peaks.mean() / (2 * osc.z0)
    ratio_se = peaks.std(ddof=1) / np.sqrt(peaks.size) / (2 * osc.z0)

    rows = [
        ("numba compile, cold cache (first call)", f"{cold['first']:.2f} s"),
        ("first call, warm cache (load)", f"{warm['first']:.3f} s"),
        ("import sysid_nn.oscillator (warm)", f"{warm['import']:.2f} s"),
        ("generate 25 x 2000 samples (median of 9)", f"{1e3 * t_gen:.1f} ms"),
        ("  same, with tidy DataFrame", f"{1e3 * t_gen_frame:.1f} ms"),
        ("calibrate r0, 400 x 2000 samples (median of 3)", f"{t_cal:.2f} s"),
        ("calibrated r0 (default parameters, seed 0)", f"{r0:.5f}"),
        (
            "mean peak abs(X) / (2 z0), 2000 fresh realisations",
            f"{ratio:.4f} +- {ratio_se:.4f}",
        ),
    ]
    width = max(len(name) for name, _ in rows)
    print(f"{'quantity':<{width}}  value")
    for name, value in rows:
        print(f"{name:<{width}}  {value}")

    lines = [
        "# Data generator benchmark",
        "",
        "Produced by `python benchmarks/bench_generator.py` "
        f"(Python {platform.python_version()}, {platform.machine()}, "
        f"{os.cpu_count()} CPUs).",
        "",
        "| quantity | value |",
        "|---|---|",
        *(f"| {name.strip()} | {value} |" for name, value in rows),
        "",
        "Compile times are measured in fresh processes with `NUMBA_CACHE_DIR` "
        "pointing to an empty, then to the populated, temporary directory. "
        "Generation times exclude compilation and calibration (cached in-process). "
        "The fresh-realisation check uses a seed different from the calibration's; "
        "the +- is one Monte Carlo standard error.",
        "",
    ]
    (HERE / "results_generator.md").write_text("\n".join(lines))


if __name__ == "__main__":
    main()
