"""Results files of the benchmarks: rows of a CSV, replaced per benchmark and model.

Kept free of the package's imports: the peer benchmark's worker reads it in
an environment of its own.
"""

from __future__ import annotations

import csv
from collections.abc import Callable
from pathlib import Path


def read_rows(path: Path) -> list[dict]:
    """Rows of a results file; none if it does not exist yet."""
    if not path.is_file():
        return []
    with path.open(newline="") as f:
        return list(csv.DictReader(f))


def store_rows(
    path: Path, fields: list[str], rows: list[dict], order: Callable
) -> list[dict]:
    """Replace the stored rows of the benchmarks and models of ``rows``.

    The merged rows, sorted by ``order``, are written to ``path`` and
    returned.
    """
    new = {(r["benchmark"], r["model"]) for r in rows}
    old = [r for r in read_rows(path) if (r["benchmark"], r["model"]) not in new]
    merged = sorted([*old, *rows], key=order)
    with path.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=fields)
        writer.writeheader()
        writer.writerows(merged)
    return merged
