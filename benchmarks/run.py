"""Run every benchmark script ``benchmarks/bench_*.py`` (or those named).

Usage::

    python benchmarks/run.py            # all benchmarks
    python benchmarks/run.py kernels    # only bench_kernels.py
    python benchmarks/run.py field      # the community's benchmarks (long)

Each script prints its own table and writes its results next to itself;
this runner only executes them in one process tree, one after another, so
that ratios quoted from one run are measured on the same machine state.
"""

from __future__ import annotations

import runpy
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def main(argv: list[str]) -> int:
    scripts = sorted(HERE.glob("bench_*.py"))
    if argv:
        wanted = {
            f"bench_{name.removeprefix('bench_').removesuffix('.py')}.py"
            for name in argv
        }
        unknown = wanted - {s.name for s in scripts}
        if unknown:
            print(
                f"unknown benchmark(s): {', '.join(sorted(unknown))}", file=sys.stderr
            )
            return 2
        scripts = [s for s in scripts if s.name in wanted]
    for script in scripts:
        print(f"=== {script.name}", flush=True)
        start = time.perf_counter()
        # Each script parses its own command line: give it a clean one.
        saved, sys.argv = sys.argv, [str(script)]
        try:
            runpy.run_path(str(script), run_name="__main__")
        finally:
            sys.argv = saved
        print(
            f"=== {script.name} done in {time.perf_counter() - start:.1f} s\n",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
