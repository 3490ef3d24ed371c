"""Subspace identification of a linear innovation model (N4SID type).

Fits ``x(k+1) = A x(k) + B u(k) + K e(k) + c``, ``y(k) = C x(k) + e(k)``
to one or several records. The future outputs are projected obliquely,
along the future inputs, onto the past inputs and outputs: future white
measurement noise is uncorrelated with the past, so unlike a least-squares
ARX fit (whose regressors carry the noise) the estimate stays consistent
under white output noise (Van Overschee & De Moor 1996, ch. 4; Ljung 1999,
sec. 10.6). The past window gives the Kalman-filter states along the data,
from which ``A, B, C, K`` follow by least squares (``K`` from the steady-state
Riccati equation where the least-squares gain gives an unstable predictor).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import solve_discrete_are
from sklearn.utils import Bunch

from sysid_nn._engine import _least_squares as least_squares
from sysid_nn._kernels._linear import linear_free_run

#: Past and future horizon (samples) of the block-Hankel matrices.
HORIZON = 50
#: A linear model counts as stable when its poles lie at least this far
#: inside the unit circle. A pole closer than that is an integrator on any
#: record (its response falls by 1e-4 over 1e5 samples), and which side of
#: the circle it lands on is rounding: a fourth-order test system's fifth
#: mode came out at 1 - 6e-13 and 1 + 5e-14 from two exact factorisations of
#: the same projection, which decided whether that order was a candidate.
UNIT_MARGIN = 1e-9


def is_stable(A: np.ndarray) -> bool:
    """Whether every pole of ``A`` lies :data:`UNIT_MARGIN` inside the unit circle."""
    return bool(np.abs(np.linalg.eigvals(A)).max() < 1.0 - UNIT_MARGIN)


def _hankel(a: np.ndarray, first: int, rows: int, cols: int) -> np.ndarray:
    """Block-Hankel matrix: column ``j`` stacks ``a[first + j : first + j + rows]``."""
    idx = first + np.arange(rows)[:, None] + np.arange(cols)[None, :]
    return a[idx].transpose(0, 2, 1).reshape(rows * a.shape[1], cols)


def _blocks(n_cols: int):
    """``(first, count)`` of consecutive blocks of windows (see
    :mod:`~sysid_nn._engine._least_squares`): the projection and the state
    estimates go block by block, so that their memory does not grow with
    the records (a 10^5-sample record's whole matrices took 400 MB)."""
    for rows in least_squares.row_blocks(n_cols):
        yield rows.start, rows.stop - rows.start


def _windows(Y, U, horizon: int, constant: bool):
    """Blocks of windows of every record, one row per window.

    A row holds the past inputs, the past outputs, the future inputs, a
    constant with ``constant``, and the future outputs.
    """
    for y, u in zip(Y, U, strict=True):
        for first, cols in _blocks(len(y) - 2 * horizon + 1):
            rows = [
                _hankel(u, first, horizon, cols),
                _hankel(y, first, horizon, cols),
                _hankel(u, first + horizon, horizon, cols),
                *([np.ones((1, cols))] if constant else []),
                _hankel(y, first + horizon, horizon, cols),
            ]
            yield np.vstack(rows).T


def subspace_model(
    Y, U, n: int, horizon: int = HORIZON, constant: bool = False
) -> Bunch:
    """Linear innovation model of order ``n`` from records ``Y[s], U[s]``.

    ``Y[s]`` has shape ``(N_s, p)`` and ``U[s]`` ``(N_s, m)``; ``u(k)``
    acts on ``x(k+1)`` (no direct feed-through). Returns a Bunch with ``A,
    B, C, K, c``, ``states`` (the state estimates along the records from
    sample ``horizon`` on, stacked) and ``observer``, the map from a past
    window (``horizon`` inputs, then ``horizon`` outputs, oldest first, as
    stacked in the block-Hankel matrices) to the state estimate at its end.
    ``constant`` projects along a constant too (see :func:`projection`).

    Examples
    --------
    >>> import numpy as np
    >>> from scipy.signal import lfilter
    >>> rng = np.random.default_rng(0)
    >>> u = rng.standard_normal((4000, 1))
    >>> y = lfilter([0.0, 0.5], [1.0, -1.5, 0.7], u[:, 0])[:, None]
    >>> noisy = y + 0.1 * y.std() * rng.standard_normal(y.shape)
    >>> model = subspace_model([noisy], [u], n=2)
    >>> np.round(np.sort(np.abs(np.linalg.eigvals(model.A))), 2)
    array([0.84, 0.84])
    """
    return model_of_order(Y, U, projection(Y, U, horizon, constant), n)


def projection(Y, U, horizon: int = HORIZON, constant: bool = False) -> Bunch:
    """The oblique projection shared by the models of every order.

    Returns a Bunch with ``L_past`` (the future outputs' coefficients on
    the past windows), ``left`` and ``singular_values`` (its SVD along the
    past windows) and ``horizon``. The singular values fall off after the
    system's order: the gap reads the order from the data. With
    ``constant``, the projection is also along a constant, which otherwise
    shows as one more state (an offset of the records).
    """
    m, p = U[0].shape[1], Y[0].shape[1]
    n_past = horizon * (m + p)
    n_design = n_past + horizon * m + int(constant)
    # Oblique projection of the future outputs along the future inputs onto
    # the past: the least-squares coefficients of the past, from the
    # triangular factor of [past, along, future] (as N4SID's LQ does).
    R = least_squares.triangular_factor(_windows(Y, U, horizon, constant))
    R11, R12 = R[:n_design, :n_design], R[:n_design, n_design:]
    n_windows = sum(max(len(y) - 2 * horizon + 1, 0) for y in Y)
    cut = least_squares.cutoff(n_windows, n_design)
    coef = np.linalg.lstsq(R11, R12, rcond=cut)[0].T
    L_past = coef[:, :n_past]
    # ``L_past @ past`` is ``L_past @ R11[:, :n_past].T`` times orthonormal
    # rows: the same left singular vectors and values.
    left, sv, _ = np.linalg.svd(L_past @ R11[:, :n_past].T, full_matrices=False)
    return Bunch(L_past=L_past, left=left, singular_values=sv, horizon=horizon)


def model_of_order(Y, U, proj: Bunch, n: int) -> Bunch:
    """The model of order ``n`` from a :func:`projection` of records ``Y, U``."""
    p, horizon = Y[0].shape[1], proj.horizon
    left, sv, L_past = proj.left, proj.singular_values, proj.L_past
    gamma = left[:, :n] * np.sqrt(sv[:n])  # extended observability matrix
    observer = np.linalg.pinv(gamma) @ L_past
    # Kalman states along every record, then A, B, C, K by least squares.
    x_now, x_next, u_now, y_now = [], [], [], []
    for y, u in zip(Y, U, strict=True):
        cols = len(y) - horizon
        if cols < 2:
            continue
        x = np.vstack(
            [
                (
                    observer
                    @ np.vstack([_hankel(u, a, horizon, k), _hankel(y, a, horizon, k)])
                ).T
                for a, k in _blocks(cols)
            ]
        )  # state at samples horizon .. N - 1
        x_now.append(x[:-1])
        x_next.append(x[1:])
        u_now.append(u[horizon:-1])
        y_now.append(y[horizon:-1])
    x_now, x_next = np.vstack(x_now), np.vstack(x_next)
    u_now, y_now = np.vstack(u_now), np.vstack(y_now)
    C = np.linalg.lstsq(x_now, y_now, rcond=None)[0].T
    e = y_now - x_now @ C.T
    m = u_now.shape[1]
    design = np.hstack([x_now, u_now, e, np.ones((len(e), 1))])
    theta = np.linalg.lstsq(design, x_next, rcond=None)[0].T
    A, B, K, c = np.split(theta, [n, n + m, n + m + p], axis=1)
    if np.abs(np.linalg.eigvals(A - K @ C)).max() >= 1.0:
        # Nearly noise-free records leave the regression's gain unstable
        # (the one-step predictor would diverge): take the Riccati gain.
        w = x_next - design[:, : n + m] @ np.hstack([A, B]).T
        K = kalman_gain(A, C, w, e)
    return Bunch(A=A, B=B, K=K, c=c[:, 0], C=C, states=x_now, observer=observer)


def kalman_gain(A, C, w, v):
    """Steady-state Kalman (predictor) gain from state and output residuals.

    ``w`` and ``v`` are the residuals of the state and output equations
    along the data; their covariances are the process and measurement
    noise's (about their means: ``w`` holds the constant too). The gain of
    the discrete Riccati equation gives a stable predictor ``A - K C``
    whenever one exists.
    """
    n = A.shape[0]
    cov = np.cov(np.hstack([w, v]).T).reshape(n + C.shape[0], -1)
    Q, S, R = cov[:n, :n], cov[:n, n:], cov[n:, n:]
    P = solve_discrete_are(A.T, C.T, Q, R, s=S)
    return (A @ P @ C.T + S) @ np.linalg.inv(C @ P @ C.T + R)


def output_error_model(Y, U, proj: Bunch, n: int) -> Bunch:
    """Linear model of order ``n`` fitted for its free run.

    ``A`` and ``C`` from the shift invariance of the extended observability
    matrix of :func:`projection` (MOESP), then ``B``, ``c`` and the initial
    state of every record by least squares on the free-run (output) error,
    which is linear in them. On the field's lightly damped records this
    simulated far better than the Kalman-state regression of
    :func:`subspace_model`, whose ``A`` was often unstable (Silverbox,
    orders 3-10: validation NRMSE 0.21 against divergence). Returns a Bunch
    with ``A, B, C, c``; ``A`` may be unstable.
    """
    p, m = Y[0].shape[1], U[0].shape[1]
    gamma = proj.left[:, :n] * np.sqrt(proj.singular_values[:n])
    C = gamma[:p]
    A = np.linalg.lstsq(gamma[:-p], gamma[p:], rcond=None)[0]
    theta = np.zeros(n * m + n + n * len(Y))
    if is_stable(A):
        finite = True

        def rows():
            nonlocal finite
            for design, target in _output_error_rows(A, C, Y, U):
                finite = finite and bool(np.all(np.isfinite(design)))
                yield design, target

        fit, _ = least_squares.solve(rows())
        if finite and fit is not None:
            theta = fit[:, 0]
    B = theta[: n * m].reshape(m, n).T
    return Bunch(A=A, B=B, C=C, c=theta[n * m : n * m + n])


def _output_error_rows(A, C, Y, U):
    """Blocks of rows of the output-error regression, and their targets.

    The columns are the model's free-run responses to each entry of ``B``,
    of ``c`` and of every record's initial state (zero on the other
    records), one row per sample and output: linear in those entries, so
    the free run is their least-squares combination. The responses run
    block by block, each from the states the previous block ended in, so
    that only one block of them is held.
    """
    n, p, m = A.shape[0], C.shape[0], U[0].shape[1]
    eye = np.eye(n)
    # Each column's (B, c) of the input and constant terms.
    terms = [
        (np.outer(eye[j], np.eye(m)[i]), np.zeros(n))
        for i in range(m)
        for j in range(n)
    ]
    terms += [(np.zeros((n, m)), eye[j]) for j in range(n)]
    n_init = n * len(Y)
    # Outputs and states of every step: the state a block ends in starts
    # the next one, as in one run over the whole record.
    observed = np.vstack([C, eye])
    zero_b, zero_c = np.zeros((n, m)), np.zeros(n)
    for s, (y, u) in enumerate(zip(Y, U, strict=True)):
        states = np.zeros((len(terms) + n, n))
        states[len(terms) :] = eye  # the initial-state columns start at e_j
        for rows in least_squares.row_blocks(len(y)):
            first, last = rows.start, rows.stop
            ahead = min(last + 1, len(y))  # one more step: the next start
            block = np.zeros((last - first, p, len(terms) + n_init))
            for k in range(len(terms) + n):
                B, c = terms[k] if k < len(terms) else (zero_b, zero_c)
                out = _free_run(A, B, observed, c, u[first:ahead], states[k])
                col = k if k < len(terms) else len(terms) + s * n + (k - len(terms))
                block[:, :, col] = out[: last - first, :p]
                if ahead > last:
                    states[k] = out[-1, p:]
            yield block.reshape(-1, block.shape[2]), y[rows].reshape(-1, 1)


def _free_run(A, B, C, c, u, x0):
    out = np.empty((len(u), C.shape[0]))
    linear_free_run(A, B, C, c, u, x0, out)
    return out
