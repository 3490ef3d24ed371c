"""Starting an ISSM from a trained TDL network (``init="tdl"``).

A TDL network with ``ARX_LAGS`` output and input lags is an ISSM whose states
hold the past outputs and excitation: :func:`realise_tdl` writes the fitted
network's weights as the ISSM's, so that the ISSM runs exactly as the TDL
network. The functions take the ISSM being fitted.
"""

from __future__ import annotations

import copy

import numpy as np
from sklearn.utils import Bunch

from sysid_nn._engine._issm_start import ARX_LAGS, linear_blocks
from sysid_nn._estimators._tdl import TDLRegressor
from sysid_nn._kernels._mlp import n_params


def validate_tdl_start(est) -> None:
    """Check ``n_states`` and ``linear_part`` for a TDL start; set ``n_states_``."""
    p, m = est.n_outputs_, est.n_features_in_
    n = p * ARX_LAGS + m * (ARX_LAGS - 1)
    if est.n_states not in (None, "auto") and est.n_states != n:
        raise ValueError(
            f'init="tdl" realises a TDL network with {ARX_LAGS} output and '
            f"{ARX_LAGS} input lags in state space, which takes n_states = "
            f"{n} here ({ARX_LAGS} x {p} outputs + {ARX_LAGS - 1} x {m} "
            f"inputs); got n_states={est.n_states}. Use n_states='auto' or None."
        )
    if not est.linear_part and est._hidden_layers():
        raise ValueError(
            'init="tdl" needs linear_part=True: the states holding past '
            "outputs and inputs are shifted by the linear part."
        )
    est.n_states_ = n


def start_tdl(est) -> TDLRegressor:
    """The TDL network an ``init="tdl"`` model starts from, unfitted.

    It gets every parameter the two estimators share (structure and
    training); the lags are the TDL defaults the realisation assumes.
    """
    shared = set(est._get_param_names()) & set(TDLRegressor._get_param_names())
    if isinstance(est.hidden_layer_sizes, str):
        shared.discard("hidden_layer_sizes")  # "auto": the TDL's own default
    return TDLRegressor(
        output_lags=ARX_LAGS,
        input_lags=ARX_LAGS,
        **{name: getattr(est, name) for name in sorted(shared)},
    )


def realise_tdl(est, tdl: TDLRegressor) -> tuple[np.ndarray, Bunch]:
    """Weights with which the ISSM ``est`` runs exactly as the fitted ``tdl``.

    The state after sample ``t`` is ``[y(t), y(t-1), ..., y(t-n_a+1),
    F(t-n_k), ..., F(t-n_k-n_b+2)]``: the measured outputs in ``est``'s
    standardised units, the past outputs and excitation in the user's
    units divided by their scale (zero at rest). The TDL's regressor is
    then an affine map ``phi = M z + phi0`` of the network input ``z =
    [x(t-1), F(t-n_k), E(t-1)]``, with the innovations added to the newest
    output (the one-step predictor sees the measured output there); the
    older lags are shifted by the linear part. Returns the weights and
    the linear part ``A, B, K, c``.
    """
    p, m, n = est.n_outputs_, est.n_features_in_, est.n_states_
    na, nb = tdl.output_lags_, tdl.input_lags_
    nz = n + m + p
    sy, my, sx, mx = est._y_scale, est._y_mean, est._x_scale, est._x_mean
    ty, tmy, tx, tmx = tdl._y_scale, tdl._y_mean, tdl._x_scale, tdl._x_mean
    y_states = np.arange(p, na * p)  # y(t-1), ..., y(t-na+1)
    u_states = np.arange(na * p, n)  # F(t-nk), ..., F(t-nk-nb+2)
    u_in, e_in = np.arange(n, n + m), np.arange(n + m, nz)
    M, phi0 = np.zeros((na * p + nb * m, nz)), np.zeros(na * p + nb * m)
    ky, kx = np.tile(np.arange(p), na - 1), np.tile(np.arange(m), nb - 1)
    # Newest output: the state (plus innovation) in the ISSM's units.
    M[np.arange(p), np.arange(p)] = sy / ty
    M[np.arange(p), e_in] = sy / ty
    phi0[:p] = (my - tmy) / ty
    M[y_states, y_states] = sy[ky] / ty[ky]
    phi0[y_states] = -tmy[ky] / ty[ky]
    # Newest excitation from the input, older ones from the states.
    rows = na * p + np.arange(m)
    M[rows, u_in] = sx / tx
    phi0[rows] = (mx - tmx) / tx
    rows = na * p + m + np.arange(len(u_states))
    M[rows, u_states] = sx[kx] / tx[kx]
    phi0[rows] = -tmx[kx] / tx[kx]
    T, t0 = tdl._S @ M, tdl._S @ phi0  # the TDL network's input = T z + t0

    # The linear part: the TDL output in rows :p, shifts below. y(t-1)
    # is the newest output (state plus innovation) back in user units.
    L, c = np.zeros((n, nz)), np.zeros(n)
    if na > 1:
        L[np.arange(p, 2 * p), np.arange(p)] = 1.0
        L[np.arange(p, 2 * p), e_in] = 1.0
        c[p : 2 * p] = my / sy
        L[y_states[p:], y_states[:-p]] = 1.0
    if nb > 1:
        L[u_states[:m], u_in] = 1.0
        c[u_states[:m]] = mx / sx
        L[u_states[m:], u_states[:-m]] = 1.0
    gain = ty / sy  # the TDL's standardised output in the ISSM's units
    c[:p] = (tmy - my) / sy
    w_tdl, sizes = tdl.coefs_, tdl._sizes_
    tdl_layout = tdl._layout()
    layers = tdl_layout.layers
    if tdl._bypass():
        bypass = tdl_layout.bypass_matrix(w_tdl)
        L[:p] = gain[:, None] * (bypass @ T)
        c[:p] += gain * (bypass @ t0)
    w = np.zeros(n_params(est._sizes_, est._bypass()))
    if len(layers) == 1:  # the linear TDL: its map is the linear part
        W, b = tdl_layout.matrices(w_tdl)[0]
        L[:p] = gain[:, None] * (W @ T)
        c[:p] += gain * (W @ t0 + b)
        w[: L.size], w[L.size :] = L.ravel(), c
        return w, linear_blocks(L, c, n, m)
    mine = est._layout()
    for i, (layer, own) in enumerate(zip(layers, mine.layers, strict=True)):
        W, b = w_tdl[layer.weights].reshape(sizes[i + 1], sizes[i]), w_tdl[layer.biases]
        if i == 0:
            W, b = W @ T, b + W @ t0
        if i == len(layers) - 1:
            W = np.vstack([gain[:, None] * W, np.zeros((n - p, W.shape[1]))])
            b = c + np.concatenate([gain * b, np.zeros(n - p)])
        w[own.weights], w[own.biases] = W.ravel(), b
    w[mine.bypass] = L.ravel()
    return w, linear_blocks(L, c, n, m)


def realisation_map(est) -> np.ndarray:
    """Jacobian of an ``init="tdl"`` ISSM's weights by its TDL's weights.

    The realisation is affine in the TDL's weights, so unit steps give it
    exactly.
    """
    tdl = copy.copy(est.tdl_)
    w0 = tdl.coefs_
    base, _ = realise_tdl(est, tdl)
    G = np.empty((len(base), len(w0)))
    for j in range(len(w0)):
        tdl.coefs_ = w0.copy()
        tdl.coefs_[j] += 1.0
        G[:, j] = realise_tdl(est, tdl)[0] - base
    return G
