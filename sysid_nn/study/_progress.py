"""Progress bars of the study's long steps (stderr, off by default)."""

from __future__ import annotations

from collections.abc import Iterable, Iterator


def _progress(items: Iterable, total: int, desc: str, show: bool) -> Iterator:
    from tqdm.auto import tqdm

    return iter(tqdm(items, total=total, desc=desc, disable=not show, leave=False))
