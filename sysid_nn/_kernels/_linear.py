"""Free run of a linear state-space model, for scoring candidate orders."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def linear_free_run(A, B, C, c, U, x0, Y):
    """``x(k+1) = A x(k) + B u(k) + c``, ``Y[k] = C x(k)`` from ``x(0) = x0``.

    Stops at a non-finite state, leaving the remaining rows of ``Y`` NaN.
    """
    n = A.shape[0]
    x = x0.copy()
    nxt = np.empty(n)
    Y[:, :] = np.nan
    for k in range(U.shape[0]):
        for i in range(C.shape[0]):
            acc = 0.0
            for j in range(n):
                acc += C[i, j] * x[j]
            Y[k, i] = acc
        for i in range(n):
            acc = c[i]
            for j in range(n):
                acc += A[i, j] * x[j]
            for j in range(U.shape[1]):
                acc += B[i, j] * U[k, j]
            nxt[i] = acc
        for i in range(n):
            if not np.isfinite(nxt[i]):
                return
            x[i] = nxt[i]
