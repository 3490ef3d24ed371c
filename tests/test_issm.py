"""Tests of the innovation state-space network (ISSMRegressor)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from sysid_nn import ISSMRegressor
from sysid_nn._base import _FREE_RUN


# --------------------------------------------------------------------------
# a slow NumPy twin of the recurrence, written from the equations
# --------------------------------------------------------------------------
def _twin_mlp(w, sizes, activation, bypass, z):
    f = np.tanh if activation == "tanh" else (lambda s: 1.0 / (1.0 + np.exp(-s)))
    a, pos = z, 0
    for i in range(len(sizes) - 1):
        n_in, n_out = sizes[i], sizes[i + 1]
        W = w[pos : pos + n_in * n_out].reshape(n_out, n_in)
        pos += n_in * n_out
        s = W @ a + w[pos : pos + n_out]
        pos += n_out
        a = s if i == len(sizes) - 2 else f(s)
    if bypass:
        a = a + w[pos:].reshape(sizes[-1], sizes[0]) @ z
    return a


def _twin_run(est, w, data, seg_len):
    """Outputs of the modelled rows, stacked, by a plain Python loop."""
    n, p, nk = est.n_states_, est.n_outputs_, est.input_delay
    sizes, bypass = list(est._sizes_), est._bypass()
    out = []
    for a, b in zip(data.starts[:-1], data.starts[1:], strict=True):
        x = np.zeros(n)
        x[:p] = data.Y[a + data.h - 1]
        for t in range(a + data.h, b):
            k = t - a - data.h
            e = np.zeros(p)
            if seg_len == 1:
                e = data.Y[t - 1] - x[:p]
            elif k > 0 and k % seg_len == 0:
                x = x.copy()
                x[:p] = data.Y[t - 1]
            z = np.concatenate([x, data.U[t - nk], e])
            x = _twin_mlp(w, sizes, est.activation, bypass, z)
            out.append(x[:p])
    return np.array(out)


def _small_fitted(p, hidden=(4,), n_states=3, activation="tanh", linear_part=True):
    rng = np.random.default_rng(p)
    X = [rng.standard_normal((n, 2)) for n in (31, 24, 40)]
    y = [np.cumsum(rng.standard_normal((len(x), p)), axis=0) * 0.1 for x in X]
    est = ISSMRegressor(
        n_states=n_states, hidden_layer_sizes=hidden, activation=activation,
        linear_part=linear_part, n_init=1, max_iter=1, early_stopping=False,
        random_state=0,
    )  # fmt: skip
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        est.fit(X, y)
    data = est._stack(
        [np.asarray(x) for x in X], [np.asarray(v).reshape(len(v), -1) for v in y]
    )
    w = est.coefs_ + 0.05 * rng.standard_normal(len(est.coefs_))
    return est, data, w


MODES = [1, 7, _FREE_RUN]
CASES = [
    (1, (4,), "tanh", True),
    (2, (4,), "logistic", True),
    (2, (3, 2), "tanh", False),
    (1, (), "tanh", True),
]


@pytest.mark.parametrize("seg_len", MODES)
@pytest.mark.parametrize(("p", "hidden", "activation", "linear_part"), CASES)
def test_kernel_matches_twin_and_finite_differences(
    seg_len, p, hidden, activation, linear_part
):
    est, data, w = _small_fitted(p, hidden, 3, activation, linear_part)
    rows = data.modelled
    Yhat, J, diverged, state = est._run(w, data, seg_len, True)
    assert (diverged < 0).all()
    # Forward pass: the numba kernel against the NumPy twin.
    np.testing.assert_allclose(
        Yhat[rows], _twin_run(est, w, data, seg_len), rtol=1e-12, atol=1e-12
    )
    # Jacobian (eq. 10 sensitivities) against central differences of the twin.
    eps = 1e-6
    fd = np.empty_like(J)
    for c in range(len(w)):
        dw = np.zeros(len(w))
        dw[c] = eps
        up = _twin_run(est, w + dw, data, seg_len)
        down = _twin_run(est, w - dw, data, seg_len)
        fd[:, c] = ((up - down) / (2 * eps)).ravel()
    rel = np.linalg.norm(J - fd) / np.linalg.norm(fd)
    assert rel < 1e-6, rel
    # Adjoint gradient of 0.5 ||yhat - y||^2 against J^T r.
    r = (Yhat[rows] - data.Y[rows]).ravel()
    grad = est._gradient(w, data, seg_len, state)
    np.testing.assert_allclose(
        grad, J.T @ r, rtol=1e-9, atol=1e-10 * np.abs(J.T @ r).max()
    )
