"""Linear starting point of the ISSM, from an ARX or a subspace fit.

An ``init="arx"`` model starts with its linear part exactly at a linear
innovation model fitted to the training data: a least-squares ARX model, its
observer-form states along the data, mapped to the model's state coordinates
(measured outputs first, the others by variance), and a least-squares linear
innovation model on those states. The least-squares fits take noisy measured
outputs as exact regressors and are biased under output noise; an
``init="subspace"`` model starts at a subspace fit instead (consistent under
white output noise), in the same state coordinates. The functions take the
estimator being fitted (its sizes, delay and standardised data).
"""

from __future__ import annotations

from itertools import pairwise

import numpy as np
from sklearn.utils import Bunch

from sysid_nn._engine import _least_squares as least_squares
from sysid_nn._engine._least_squares import with_intercept
from sysid_nn._engine._subspace import HORIZON, subspace_model
from sysid_nn._records._data import _Data

#: Output and input lags of the ARX model the linear part starts from, and
#: of the TDL network an ``init="tdl"`` model starts from.
ARX_LAGS = 3


def lags_per_output(n_states: int, n_outputs: int) -> int:
    """Lags of each output that hold ``n_states`` states: ``ceil(n / p)``.

    An ARX model with that many output and input lags has (at least) the
    order ``n``.

    Examples
    --------
    >>> lags_per_output(3, 1), lags_per_output(4, 2), lags_per_output(9, 3)
    (3, 2, 3)
    """
    return -(-n_states // n_outputs)


def order_lags(n_states: int, n_outputs: int) -> int:
    """Lags of each output and input of an ARX model with ``n_states`` states.

    ``ceil(n / p)``, at least :data:`ARX_LAGS`: with displacement and velocity
    of the hysteretic oscillator measured (4 states), 2 lags lost the TDL
    network's free run (accuracy benchmark, P1: median NRMSE 0.73 against
    0.060 with 3).

    Examples
    --------
    >>> order_lags(3, 1), order_lags(4, 2), order_lags(6, 1)
    (3, 3, 6)
    """
    return max(ARX_LAGS, lags_per_output(n_states, n_outputs))


def arx_lags(est) -> int:
    """Lags of the ARX fit the linear start is realised from."""
    return order_lags(est.n_states_, est.n_outputs_)


def linear_start(est, data: _Data) -> Bunch:
    """The linear innovation model ``A, B, K, c`` fitted to ``data``."""
    p, n, nk = est.n_outputs_, est.n_states_, est.input_delay
    lags = arx_lags(est)
    A_i, B_j, c, rows = arx(est, data, lags)
    # Observer-form ARX states along the data: block i is the part of
    # the prediction of y(t + i) already fixed by data up to t - 1, so
    # block 0 is the one-step prediction yhat(t).
    xi = np.zeros((len(rows), lags * p))
    for i in range(lags):
        for j in range(i, lags):
            xi[:, i * p : (i + 1) * p] += data.Y[rows - 1 - j + i] @ A_i[j].T
            xi[:, i * p : (i + 1) * p] += data.U[rows - nk - j + i] @ B_j[j].T
    xi[:, :p] += c
    x = xi @ state_coordinates(xi, p, n).T
    # Zero of the unmeasured states: their mean where the training
    # records start (the rest state for records that start at rest).
    first = np.flatnonzero(np.diff(rows, prepend=-2) != 1)
    x[:, p:] -= x[first, p:].mean(axis=0)
    return fit_linear_model(est, data, rows, x)


def arx(est, data: _Data, lags: int):
    """Least-squares ARX fit ``y(t) = sum A_i y(t-i) + sum B_j u(t-nk-j) + c``.

    Only rows whose lags lie in the measured part of a sequence are used.
    Returns ``(A_list, B_list, c, rows)``.
    """
    p, nk = est.n_outputs_, est.input_delay
    rows = data.measured_rows(max(lags, nk + lags - 1))
    n_reg = lags * (p + est.n_features_in_)
    theta, _ = least_squares.solve(
        (with_intercept(arx_regressors(est, data, rows[s], lags)), data.Y[rows[s]])
        for s in least_squares.row_blocks(len(rows))
    )
    if theta is None:
        theta = np.zeros((n_reg + 1, p))
    m = est.n_features_in_
    A = [theta[i * p : (i + 1) * p].T for i in range(lags)]
    B = [theta[lags * p + j * m : lags * p + (j + 1) * m].T for j in range(lags)]
    return A, B, theta[-1], rows


def arx_regressors(est, data: _Data, rows: np.ndarray, lags: int) -> np.ndarray:
    """The ARX regressors of ``rows``: ``lags`` past outputs, then inputs."""
    nk = est.input_delay
    blocks = [data.Y[rows - i] for i in range(1, lags + 1)]
    blocks += [data.U[rows - nk - j] for j in range(lags)]
    return np.hstack(blocks) if blocks else np.empty((len(rows), 0))


def fit_linear_model(est, data: _Data, rows: np.ndarray, x: np.ndarray) -> Bunch:
    """Least-squares linear innovation model on the ARX-derived states.

    ``x(t) = A [y(t-1); x_u(t-1)] + B u(t-nk) + c`` with ``x_u`` the
    unmeasured states, i.e. ``K = A H^T`` in
    ``x(t) = A x(t-1) + B u(t-nk) + K e(t-1) + c``.
    """
    p, n, m = est.n_outputs_, est.n_states_, est.n_features_in_
    pairs = np.flatnonzero(np.diff(rows) == 1) + 1
    t = rows[pairs]
    # K = A H^T: the one-step predictor feeds the measured outputs in
    # place of the measured states. A free least-squares K made the
    # reduced predictor unstable on the hysteretic oscillator.

    def design(s):
        return with_intercept(
            np.hstack(
                [data.Y[t[s] - 1], x[pairs[s] - 1, p:], data.U[t[s] - est.input_delay]]
            )
        )

    theta, _ = least_squares.solve(
        (design(s), x[pairs[s]]) for s in least_squares.row_blocks(len(t))
    )
    if theta is None:
        theta = np.zeros((n + m + 1, n))
    A, B = theta[:n].T, theta[n : n + m].T
    K = A[:, :p].copy()
    return Bunch(A=A, B=B, K=K, c=theta[-1])


def state_coordinates(xi: np.ndarray, p: int, n: int) -> np.ndarray:
    """Fixed map ``x = T xi`` from observer-form to model states.

    The first ``p`` states are the predicted outputs themselves; the
    others are the remaining observer-form directions with the part
    explained by the outputs removed (least-squares residual), ordered by
    variance along the training data and scaled to unit variance.
    Directions beyond ``n`` are dropped.
    """
    N = xi.shape[1]
    T = np.zeros((n, N))
    T[:p, :p] = np.eye(p)
    if len(xi) > 1:
        centred = xi - xi.mean(axis=0)
        out, rest = centred[:, :p], centred[:, p:]
        C, *_ = np.linalg.lstsq(out, rest, rcond=None)  # rest ~ out @ C
        resid = rest - out @ C
    else:
        C, resid = np.zeros((p, N - p)), np.zeros((1, N - p))
    var, V = np.linalg.eigh(resid.T @ resid / max(1, len(resid)))
    var, V = var[::-1][: n - p], V[:, ::-1][:, : n - p]
    # Directions the data barely excite (an ARX of higher order than the
    # system) keep a bounded scale instead of blowing up.
    total = float(np.var(xi, axis=0).sum()) if len(xi) > 1 else 1.0
    var = np.maximum(var, max(1e-8 * var.max(initial=0.0), 1e-12 * total, 1e-300))
    W = V.T / np.sqrt(var)[:, None]
    T[p:, p:] = W
    T[p:, :p] = -W @ C.T
    return T


def linear_blocks(L: np.ndarray, c: np.ndarray, n: int, m: int) -> Bunch:
    """``A, B, K, c`` of a linear part ``L = [A B K]`` on ``[x, F, E]``."""
    return Bunch(A=L[:, :n], B=L[:, n : n + m], K=L[:, n + m :], c=c)


def subspace_records(est, data: _Data):
    """The training records as the subspace fit takes them.

    ``u(k)`` of the subspace model acts on ``x(k+1)``: it is ``F(t + 1 -
    n_k)`` for the output ``y(t)``.
    """
    nk = est.input_delay
    Y, U = [], []
    for a, b in pairwise(data.starts):
        first, last = a + data.h + max(0, nk - 1), b - max(0, 1 - nk)
        Y.append(data.Y[first:last])
        U.append(data.U[first + 1 - nk : last + 1 - nk])
    return Y, U


def subspace_horizon(est, data: _Data, n: int | None = None) -> int:
    """Past and future horizon of the subspace start; 0 if the records are too short.

    The longest up to ``HORIZON`` for which the projection has at least
    twice as many windows as coefficients and the extended observability
    matrix more rows than ``n`` states (default ``n_states_``).
    """
    p, m = est.n_outputs_, est.n_features_in_
    n = est.n_states_ if n is None else n
    lengths = np.array([len(y) for y in subspace_records(est, data)[0]])
    for horizon in range(HORIZON, 0, -1):
        windows = np.maximum(lengths - 2 * horizon + 1, 0).sum()
        if horizon * p > n and windows >= 2 * horizon * (2 * m + p):
            return horizon
    return 0


def subspace_start(est, data: _Data) -> Bunch:
    """The linear innovation model ``A, B, K, c`` from subspace identification.

    Consistent under white output noise, unlike the ARX fit of
    :func:`linear_start` (see :mod:`sysid_nn._engine._subspace`). The Kalman gain
    ``K`` is the subspace fit's. The states are put in the coordinates of
    :func:`state_coordinates` (along the subspace fit's state estimates),
    with the unmeasured states zero at the model's rest state.
    """
    p, n = est.n_outputs_, est.n_states_
    Y, U = subspace_records(est, data)
    # Measured (Wiener-Hammerstein, 6 states, internal split): projecting
    # along a constant too gave 0.34 mV where the plain projection gave a
    # model that failed on the test record (784 mV); the oscillator's starts
    # (at most two unmeasured states) keep the plain projection.
    constant = n - p > 2
    lin = subspace_model(Y, U, n, subspace_horizon(est, data), constant)
    # Measured outputs first: x -> [C x; the rest of the state space].
    rest = np.linalg.svd(lin.C)[2][p:]
    M = np.vstack([lin.C, rest])
    T = state_coordinates(lin.states @ M.T, p, n) @ M
    Ti = np.linalg.inv(T)
    A, B, K, c = T @ lin.A @ Ti, T @ lin.B, T @ lin.K, T @ lin.c
    # Unmeasured states zero at rest (zero excitation in the user's units):
    # shifting them by d adds (A - I) d to the constant.
    u_rest = -est._x_mean / est._x_scale
    x_rest = np.linalg.lstsq(np.eye(n) - A, B @ u_rest + c, rcond=None)[0]
    shift = np.r_[np.zeros(p), x_rest[p:]]
    return Bunch(A=A, B=B, K=K, c=c + (A - np.eye(n)) @ shift)
