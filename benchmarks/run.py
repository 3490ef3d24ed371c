"""Run every benchmark script ``benchmarks/bench_*.py`` (or those named).

Usage::

    python benchmarks/run.py            # all benchmarks
    python benchmarks/run.py kernels    # only bench_kernels.py
    python benchmarks/run.py field      # the community's benchmarks (long)

Each script prints its own table and writes its results next to itself;
this runner only executes them in one process tree, one after another, so
that ratios quoted from one run are measured on the same machine state.
``bench_peer.py`` is not run here: it trains a peer library's model in an
environment of its own (see its docstring for the command).
"""

from __future__ import annotations

import runpy
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
#: Scripts that need an environment of their own, with the reason.
SEPARATE = {
    "bench_peer.py": "it needs the peer library's own environment; run "
    "`python benchmarks/bench_peer.py --peer-python <that env's python>`",
}


def main(argv: list[str]) -> int:
    scripts = sorted(s for s in HERE.glob("bench_*.py") if s.name not in SEPARATE)
    if argv:
        wanted = {
            f"bench_{name.removeprefix('bench_').removesuffix('.py')}.py"
            for name in argv
        }
        for name in sorted(wanted & set(SEPARATE)):
            print(f"{name} is not run here: {SEPARATE[name]}", file=sys.stderr)
            return 2
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
