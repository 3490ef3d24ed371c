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

from sysid_nn._kernels._linear import linear_free_run

#: Past and future horizon (samples) of the block-Hankel matrices.
HORIZON = 50


def _hankel(a: np.ndarray, first: int, rows: int, cols: int) -> np.ndarray:
    """Block-Hankel matrix: column ``j`` stacks ``a[first + j : first + j + rows]``."""
    idx = first + np.arange(rows)[:, None] + np.arange(cols)[None, :]
    return a[idx].transpose(0, 2, 1).reshape(rows * a.shape[1], cols)


def _windows(Y, U, horizon):
    """Past windows, future inputs and outputs of every record, side by side."""
    past, u_future, y_future = [], [], []
    for y, u in zip(Y, U, strict=True):
        cols = len(y) - 2 * horizon + 1
        if cols < 1:
            continue
        past.append(
            np.vstack([_hankel(u, 0, horizon, cols), _hankel(y, 0, horizon, cols)])
        )
        u_future.append(_hankel(u, horizon, horizon, cols))
        y_future.append(_hankel(y, horizon, horizon, cols))
    return np.hstack(past), np.hstack(u_future), np.hstack(y_future)


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
    past, u_future, y_future = _windows(Y, U, horizon)
    # Oblique projection of the future outputs along the future inputs onto
    # the past: the least-squares coefficients of the past.
    along = [u_future, np.ones((1, past.shape[1]))] if constant else [u_future]
    design = np.vstack([past, *along])
    coef = np.linalg.lstsq(design.T, y_future.T, rcond=None)[0].T
    L_past = coef[:, : past.shape[0]]
    left, sv, _ = np.linalg.svd(L_past @ past, full_matrices=False)
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
        w = np.vstack([_hankel(u, 0, horizon, cols), _hankel(y, 0, horizon, cols)])
        x = (observer @ w).T  # state at samples horizon .. N - 1
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
    zero_n, zero_b = np.zeros(n), np.zeros((n, m))
    columns = []  # responses to each entry of B, of c, of every x0
    for i in range(m):
        for j in range(n):
            B = zero_b.copy()
            B[j, i] = 1.0
            columns.append([_free_run(A, B, C, zero_n, u, zero_n) for u in U])
    for j in range(n):
        c = zero_n.copy()
        c[j] = 1.0
        columns.append([_free_run(A, zero_b, C, c, u, zero_n) for u in U])
    n_rec = len(Y)
    design = [np.hstack([np.concatenate(col).reshape(-1, 1) for col in columns])]
    for s in range(n_rec):
        for j in range(n):
            x0 = zero_n.copy()
            x0[j] = 1.0
            block = [
                _free_run(A, zero_b, C, zero_n, u, x0)
                if k == s
                else np.zeros((len(u), p))
                for k, u in enumerate(U)
            ]
            design.append(np.concatenate(block).reshape(-1, 1))
    design = np.hstack(design)
    target = np.concatenate(Y).ravel()
    ok = np.all(np.isfinite(design), axis=0)
    theta = np.zeros(design.shape[1])
    if np.abs(np.linalg.eigvals(A)).max() < 1.0 and ok.all():
        theta = np.linalg.lstsq(design, target, rcond=None)[0]
    B = theta[: n * m].reshape(m, n).T
    return Bunch(A=A, B=B, C=C, c=theta[n * m : n * m + n])


def _free_run(A, B, C, c, u, x0):
    out = np.empty((len(u), C.shape[0]))
    linear_free_run(A, B, C, c, u, x0, out)
    return out
