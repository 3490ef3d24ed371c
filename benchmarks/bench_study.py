"""Wall time of the section-4 study: ``sysid-nn reproduce``, quick and full.

Runs the command in fresh processes (as a user or CI would), first the
``--quick`` run with an empty numba cache (the cost on a clean install),
then the full study with ``--n-jobs 2`` (the paper's 25 test realisations,
four restarts per network), and writes ``results_study.md`` next to this
file with the times, the per-step split from the study's report and the
full run's summary table.

Usage::

    python benchmarks/bench_study.py            # quick and full
    python benchmarks/bench_study.py --quick    # quick run only
"""

from __future__ import annotations

import os
import platform
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def _reproduce(out: Path, *args: str, env: dict[str, str] | None = None) -> float:
    cmd = [sys.executable, "-m", "sysid_nn", "reproduce", "--out", str(out)]
    start = time.perf_counter()
    subprocess.run([*cmd, *args, "--quiet"], check=True, env=env)
    return time.perf_counter() - start


def _steps(report: Path) -> str:
    """The per-step wall times stated in the report's setup section."""
    found = re.search(r"- Wall time: (.*)", report.read_text(encoding="utf-8"))
    return found.group(1) if found else "n/a"


def _glance(report: Path) -> str:
    """The report's 'Results at a glance' table."""
    text = report.read_text(encoding="utf-8")
    section = text.split("## Results at a glance", 1)[1].split("\n\n", 2)[1]
    return section.strip()


def main(argv: list[str]) -> int:
    quick_only = "--quick" in argv
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp / "numba_cache")}
        seconds = _reproduce(tmp / "quick", "--quick", env=env)
        rows.append(("`reproduce --quick`, empty numba cache", seconds, tmp / "quick"))
        if not quick_only:
            seconds = _reproduce(tmp / "full", "--n-jobs", "2")
            rows.append(("`reproduce --n-jobs 2` (full study)", seconds, tmp / "full"))
        lines = [
            "# Section-4 study benchmark",
            "",
            f"Produced by `python benchmarks/bench_study.py` (Python "
            f"{platform.python_version()}, {platform.machine()}, "
            f"{os.cpu_count()} CPUs).",
            "",
            "| run | wall time | steps (from report.md) |",
            "|---|---|---|",
        ]
        lines += [
            f"| {name} | {sec:.0f} s | {_steps(out / 'report.md')} |"
            for name, sec, out in rows
        ]
        name, _, out = rows[-1]
        lines += [
            "",
            f"Summary of the last run ({name}):",
            "",
            _glance(out / "report.md"),
        ]
    lines += [
        "",
        "Wall times include interpreter start, imports and numba compilation "
        "(cold for the quick run, from the cache for the full run), and the "
        "figures. Other processes on the machine slow every step.",
    ]
    text = "\n".join(lines) + "\n"
    (HERE / "results_study.md").write_text(text, encoding="utf-8")
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
