"""Sequences read by the analyses: an array or a list of them, checked and paired.

The metrics, the residual tests and the correlation tests take model outputs
as well as records (a free run may hold NaN after a divergence); the
estimators' own reader is :func:`sysid_nn._records._data._as_sequence_list`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from sysid_nn._records._data import is_sequence_list
from sysid_nn._records._validation import check_same_width


def as_sequence_list(
    data: Any, name: str, *, allow_nan: bool = True
) -> tuple[list[np.ndarray], bool]:
    """Turn an array or a list of arrays into a list of 2-D float arrays.

    Parameters
    ----------
    data : array-like or list of array-like
        One sequence, shape ``(n_samples,)`` or ``(n_samples, n_columns)``
        (pandas objects accepted), or a list/tuple of such sequences. A list
        whose items are all numbers is one 1-D sequence, a list of lists of
        numbers one 2-D array (as the estimators read them).
    name : str
        Argument name used in error messages.
    allow_nan : bool, default=True
        If False, NaN raises a ``ValueError`` giving sequence and sample.

    Returns
    -------
    sequences : list of ndarray of shape (n_samples_j, n_columns)
        Float64 copies-or-views, one per sequence, all with the same number
        of columns.
    is_list : bool
        Whether ``data`` was a list of sequences (outputs should mirror it).
    """
    is_list = is_sequence_list(data)
    items = list(data) if is_list else [data]
    if is_list and not items:
        raise ValueError(f"{name} is an empty list; pass at least one sequence.")
    sequences = []
    for j, item in enumerate(items):
        where = f"{name}[{j}]" if is_list else name
        try:
            arr = np.asarray(item, dtype=float)
        except (TypeError, ValueError) as exc:
            raise ValueError(
                f"{where} must be numeric array-like; could not convert it to "
                f"float ({exc})."
            ) from exc
        if arr.ndim == 1:
            arr = arr[:, None]
        if arr.ndim != 2:
            raise ValueError(
                f"{where} must be 1-D (n_samples,) or 2-D (n_samples, n_columns); "
                f"got shape {arr.shape}. Pass several experiments as a list of "
                "arrays instead of stacking them."
            )
        if arr.shape[0] == 0:
            raise ValueError(f"{where} has no samples; pass a non-empty sequence.")
        if np.isinf(arr).any():
            raise ValueError(f"{where} contains infinite values; remove or fix them.")
        if not allow_nan:
            raise_on_nan(arr, where)
        sequences.append(arr)
    check_same_width(sequences, name)
    return sequences, is_list


def raise_on_nan(arr: np.ndarray, where: str) -> None:
    """Raise a ValueError naming the first NaN sample of ``arr``."""
    bad = np.flatnonzero(np.isnan(arr).any(axis=1))
    if bad.size:
        raise ValueError(
            f"{where} contain NaN at sample {bad[0]} ({bad.size} samples in all), "
            "e.g. from a diverged free run; test only finite residuals (slice "
            "the sequence before the divergence or drop that realisation)."
        )


def check_paired(
    a: list[np.ndarray], b: list[np.ndarray], name_a: str, name_b: str
) -> None:
    """Check that two sequence lists pair up: same count and lengths."""
    if len(a) != len(b):
        raise ValueError(
            f"{name_a} has {len(a)} sequences but {name_b} has {len(b)}; "
            "pass the same number of sequences."
        )
    for j, (x, y) in enumerate(zip(a, b, strict=True)):
        if x.shape[0] != y.shape[0]:
            where = f" (sequence {j})" if len(a) > 1 else ""
            raise ValueError(
                f"{name_a} has {x.shape[0]} samples but {name_b} has "
                f"{y.shape[0]}{where}; they must have equal lengths."
            )
