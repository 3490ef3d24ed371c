"""Small input-checking helpers shared by the public modules.

Every helper raises :class:`ValueError` (for a wrong type,
:class:`InvalidArgumentError`, which is also a :class:`TypeError`) with a
message that names the argument, says what was wrong and how to fix it.
Random states are converted with :func:`sklearn.utils.check_random_state`;
nothing here duplicates it.
"""

from __future__ import annotations

import numbers
from collections.abc import Sequence

import numpy as np

from sysid_nn._docstrings import fill_doc

__all__ = [
    "InvalidArgumentError",
    "check_finite_array",
    "check_in_range",
    "check_positive",
    "check_positive_int",
    "check_real",
    "check_same_width",
]


class InvalidArgumentError(ValueError, TypeError):
    """An argument of the wrong type; both a ValueError and a TypeError.

    Callers that catch ``ValueError`` for bad input (as scikit-learn users
    do) also catch a wrong type, and ``TypeError`` handlers keep working.
    """


#: Sections every scalar checker shares, filled in by :func:`_checker_doc`.
_VALUE_DOC = """\
Parameters
----------
x : object
    The value to check ({what}).
name : str
    The argument name used in the error message."""
_RETURNS_DOC = """\
Returns
-------
{kind}
    ``{kind}(x)``."""


def _checker_doc(what: str, kind: type):
    """Fill ``%(value)s`` and ``%(returns)s`` in a checker's docstring."""
    return fill_doc(
        value=_VALUE_DOC.format(what=what),
        returns=_RETURNS_DOC.format(kind=kind.__name__),
    )


def _check_type(x: object, name: str, kind: type, need: str) -> None:
    """Raise :class:`InvalidArgumentError` unless ``x`` is a ``kind``, not a bool."""
    if isinstance(x, bool) or not isinstance(x, kind):
        raise InvalidArgumentError(
            f"{name} must be {need}, got {x!r} of type {type(x).__name__}."
        )


@_checker_doc("a real number, not a bool", float)
def check_real(x: object, name: str) -> float:
    """Return ``x`` as a finite Python float, or raise naming ``name``.

    %(value)s

    %(returns)s

    Examples
    --------
    >>> check_real(2, "dt")
    2.0
    >>> check_real(True, "dt")  # doctest: +IGNORE_EXCEPTION_DETAIL
    Traceback (most recent call last):
    ...
    InvalidArgumentError: dt must be a real number, got True ...
    """
    _check_type(x, name, numbers.Real, "a real number")
    value = float(x)
    if not np.isfinite(value):
        raise ValueError(f"{name} must be finite, got {value!r}; pass a finite number.")
    return value


@_checker_doc("a real number", float)
def check_positive(x: object, name: str, *, allow_zero: bool = False) -> float:
    """Return ``x`` as a float after checking that it is positive.

    %(value)s
    allow_zero : bool, default=False
        Accept ``0`` as well (non-negative check).

    %(returns)s

    Examples
    --------
    >>> check_positive(0.01, "dt")
    0.01
    >>> check_positive(0.0, "zeta", allow_zero=True)
    0.0
    """
    value = check_real(x, name)
    if value < 0 or (value == 0 and not allow_zero):
        need = "non-negative (>= 0)" if allow_zero else "positive (> 0)"
        raise ValueError(
            f"{name} must be {need}, got {value!r}; pass a {need.split()[0]} value."
        )
    return value


@_checker_doc("a real number", float)
def check_in_range(
    x: object,
    name: str,
    low: float,
    high: float,
    *,
    closed: tuple[bool, bool] = (True, True),
) -> float:
    """Return ``x`` as a float after checking ``low <= x <= high``.

    %(value)s
    low, high : float
        The bounds of the admissible interval.
    closed : tuple of bool, default=(True, True)
        Whether the lower and upper bound belong to the interval.

    %(returns)s

    Examples
    --------
    >>> check_in_range(0.05, "alpha", 0.0, 1.0)
    0.05
    """
    value = check_real(x, name)
    ok_low = value >= low if closed[0] else value > low
    ok_high = value <= high if closed[1] else value < high
    if not (ok_low and ok_high):
        interval = (
            f"{'[' if closed[0] else '('}{low}, {high}{']' if closed[1] else ')'}"
        )
        raise ValueError(
            f"{name} must lie in {interval}, got {value!r}; pass a value in {interval}."
        )
    return value


@_checker_doc("an integral number, not a bool", int)
def check_positive_int(x: object, name: str) -> int:
    """Return ``x`` as an int after checking it is an integer >= 1.

    %(value)s

    %(returns)s

    Examples
    --------
    >>> check_positive_int(25, "n_realizations")
    25
    """
    _check_type(x, name, numbers.Integral, "an integer >= 1")
    if x < 1:
        raise ValueError(f"{name} must be an integer >= 1, got {x!r}; pass at least 1.")
    return int(x)


def check_finite_array(
    a: object,
    name: str,
    *,
    ndim: int | Sequence[int] = (1, 2),
    min_samples: int = 1,
) -> np.ndarray:
    """Return ``a`` as a float64 array after checking its dimensions and values.

    Parameters
    ----------
    a : array-like
        The values to check (lists, NumPy arrays, pandas objects).
    name : str
        The argument name used in the error message.
    ndim : int or sequence of int, default=(1, 2)
        Admissible numbers of dimensions.
    min_samples : int, default=1
        Minimum length of the last axis (the time axis).

    Returns
    -------
    ndarray of float64
        A C-contiguous copy or view of ``a``.

    Examples
    --------
    >>> check_finite_array([0.0, 1.0, 2.0], "F")
    array([0., 1., 2.])
    """
    allowed = (ndim,) if isinstance(ndim, numbers.Integral) else tuple(ndim)
    try:
        arr = np.asarray(a, dtype=np.float64, order="C")
    except (TypeError, ValueError) as exc:
        raise ValueError(
            f"{name} must be a numeric array; could not convert it ({exc})."
        ) from exc
    if arr.ndim not in allowed:
        dims = " or ".join(f"{d}-D" for d in allowed)
        raise ValueError(
            f"{name} must be {dims}, got a {arr.ndim}-D array of shape {arr.shape}; "
            f"reshape it (one row per realisation, time along the last axis)."
        )
    if arr.ndim > 0 and arr.shape[-1] < min_samples:
        raise ValueError(
            f"{name} must have at least {min_samples} sample(s) along its last axis, "
            f"got shape {arr.shape}."
        )
    if not np.all(np.isfinite(arr)):
        bad = int(np.size(arr) - np.count_nonzero(np.isfinite(arr)))
        raise ValueError(
            f"{name} contains {bad} NaN or infinite value(s); remove or "
            f"interpolate them before passing {name}."
        )
    return arr


def check_same_width(
    arrays: Sequence[np.ndarray], name: str, what: str = "columns"
) -> int:
    """Return the number of columns that all 2-D ``arrays`` share.

    Parameters
    ----------
    arrays : sequence of ndarray
        The 2-D sequences of one argument, one per experiment.
    name : str
        The argument name used in the error message.
    what : str, default="columns"
        What a column is, e.g. ``"features"`` or ``"outputs"``.

    Returns
    -------
    int
        The common number of columns.

    Examples
    --------
    >>> check_same_width([np.zeros((5, 2)), np.ones((3, 2))], "X")
    2
    """
    widths = sorted({a.shape[1] for a in arrays})
    if len(widths) > 1:
        raise ValueError(
            f"All sequences of {name} must have the same number of {what}; got "
            f"{widths}."
        )
    return widths[0]
