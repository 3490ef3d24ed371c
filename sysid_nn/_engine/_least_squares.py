"""Linear least squares over blocks of rows, in memory of one block.

The linear fits of a fit (the lags and order rule's projection and its
linear models, the ARX starts, the one-step misfit of the record
diagnosis) regress on one row per sample. Formed whole, their regressors
grew with the records: a 4e5-sample record took 1.4 GB above the data.
Here each block of rows is factorised together with the triangular factor
of the rows before it (Golub & Van Loan, sec. 5.2), which gives the ``R``
of the whole matrix; the solution and the residual cross-products follow
from it.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator

import numpy as np

#: Rows per block: 4096 rows of a few hundred columns are a few MB.
BLOCK = 4096


def row_blocks(n_rows: int, block: int = BLOCK) -> Iterator[slice]:
    """Consecutive slices of at most ``block`` rows covering ``n_rows``."""
    for first in range(0, n_rows, block):
        yield slice(first, min(first + block, n_rows))


def cutoff(n_rows: int, n_cols: int) -> float:
    """``rcond`` that drops the singular values :func:`numpy.linalg.lstsq`
    drops on the whole ``n_rows x n_cols`` matrix (its default, ``eps *
    max(n_rows, n_cols)``): the triangular factor has the same singular
    values, but fewer rows, and would keep more of them."""
    return float(np.finfo(float).eps * max(n_rows, n_cols))


def with_intercept(design: np.ndarray) -> np.ndarray:
    """``design`` with a column of ones appended (the intercept)."""
    return np.hstack([design, np.ones((len(design), 1))])


def triangular_factor(blocks: Iterable[np.ndarray]) -> np.ndarray | None:
    """``R`` of the QR factorisation of the row blocks stacked (None if none).

    Examples
    --------
    >>> import numpy as np
    >>> M = np.random.default_rng(0).standard_normal((10, 3))
    >>> R = triangular_factor([M[:4], M[4:]])
    >>> bool(np.allclose(R.T @ R, M.T @ M))
    True
    """
    R = None
    for block in blocks:
        stacked = block if R is None else np.vstack([R, block])
        R = np.linalg.qr(stacked, mode="r")
    return R


def solve(blocks: Iterable[tuple[np.ndarray, np.ndarray]]):
    """Least-squares ``theta`` of ``target ~ design @ theta`` from row blocks.

    ``blocks`` yields ``(design, target)`` pairs of the same rows. Returns
    ``(theta, residual_products)``, the latter ``E^T E`` of the residuals
    ``E = target - design @ theta`` (its diagonal: the residual sums of
    squares), or ``(None, None)`` when there are no rows. Rank-deficient
    designs get the minimum-norm solution, as :func:`numpy.linalg.lstsq`.

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> D = rng.standard_normal((9000, 2))
    >>> y = D @ [[1.0], [-2.0]] + 0.1 * rng.standard_normal((9000, 1))
    >>> theta, products = solve((D[s], y[s]) for s in row_blocks(len(D)))
    >>> np.round(theta.ravel(), 2)
    array([ 1., -2.])
    >>> bool(np.isclose(products[0, 0], np.sum((y - D @ theta) ** 2)))
    True
    """
    k = n_rows = 0

    def joined():
        nonlocal k, n_rows
        for design, target in blocks:
            k, n_rows = design.shape[1], n_rows + len(design)
            yield np.hstack([design, target])

    R = triangular_factor(joined())
    if R is None:
        return None, None
    theta = np.linalg.lstsq(R[:k, :k], R[:k, k:], rcond=cutoff(n_rows, k))[0]
    rest = R[k:, k:]
    return theta, rest.T @ rest
