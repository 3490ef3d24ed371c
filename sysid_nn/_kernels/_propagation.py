"""Propagation of a weight covariance to every modelled sample.

``var_i = || J_i L ||^2 = J_i C J_i^T`` for ``C = L L^T``: the diagonal of
``J C J^T`` without forming it. Compiled rather than a BLAS product: a band
is one short product per call, where a multi-threaded BLAS on a busy machine
spends more time waking its threads than computing.
"""

from __future__ import annotations

from numba import njit


@njit(cache=True, fastmath=True)
def row_variances(J, LT, out):
    """Write ``sum_k (J[i] @ LT[k])**2`` to ``out[i]`` for every row ``i``.

    ``LT`` is the transposed square root, ``(rank, n_w)``, so that both
    operands of every dot product are contiguous. Four rows share each row
    of ``LT`` while it is in cache.
    """
    n, n_w = J.shape
    r = LT.shape[0]
    i = 0
    while i + 4 <= n:
        s0 = s1 = s2 = s3 = 0.0
        for k in range(r):
            d0 = d1 = d2 = d3 = 0.0
            for j in range(n_w):
                c = LT[k, j]
                d0 += J[i, j] * c
                d1 += J[i + 1, j] * c
                d2 += J[i + 2, j] * c
                d3 += J[i + 3, j] * c
            s0 += d0 * d0
            s1 += d1 * d1
            s2 += d2 * d2
            s3 += d3 * d3
        out[i], out[i + 1], out[i + 2], out[i + 3] = s0, s1, s2, s3
        i += 4
    for row in range(i, n):
        s = 0.0
        for k in range(r):
            d = 0.0
            for j in range(n_w):
                d += J[row, j] * LT[k, j]
            s += d * d
        out[row] = s
