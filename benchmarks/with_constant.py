"""Run one benchmark script with a decision constant of the engine set.

The constants benchmark (:mod:`bench_constants`) refits its own systems;
this runs any other benchmark script with the constant changed, so that a
value can be checked on that script's systems too::

    python benchmarks/with_constant.py _selection._AMPLITUDE_MARGIN 3 \\
        bench_accuracy.py --out /tmp/accuracy_margin3
    python benchmarks/with_constant.py _selection._AMPLITUDE_MARGIN 3 \\
        bench_stability.py --only silverbox --shifts 0 --out /tmp/sb.csv

The constant is a module-level name of ``sysid_nn._engine`` read when a
fit runs, set as :mod:`bench_constants` sets it; the script runs in this
process with the remaining arguments (give it an ``--out`` of its own, so
that the published results stay as they are).
"""

from __future__ import annotations

import importlib
import runpy
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))


def main(argv: list[str]) -> int:
    if len(argv) < 3:
        print(__doc__, file=sys.stderr)
        return 2
    constant, value, script, *rest = argv
    from bench_constants import _set

    module_name, name = constant.rsplit(".", 1)
    module = importlib.import_module(f"sysid_nn._engine.{module_name}")
    _set(module, name, value)
    print(f"{constant} = {getattr(module, name)!r}", flush=True)
    saved, sys.argv = sys.argv, [str(HERE / script), *rest]
    try:
        runpy.run_path(sys.argv[0], run_name="__main__")
    finally:
        sys.argv = saved
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
