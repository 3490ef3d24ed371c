"""Multilayer-perceptron primitives shared by the recurrent kernels.

A network maps an input vector ``z`` (length ``sizes[0]``) through sigmoid
hidden layers ``sizes[1:-1]`` to a linear output layer (length ``sizes[-1]``),
optionally plus a linear bypass ``L z``. All parameters live in one flat
vector ``w``: for each layer the weight matrix (row-major, ``(n_out, n_in)``)
followed by its biases, then the bypass matrix ``(sizes[-1], sizes[0])``.

Hidden activations are written to a caller-owned flat buffer so that the
recurrent kernels can keep them per time step for the adjoint pass.
"""

from __future__ import annotations

import numpy as np
from numba import njit

LOGISTIC = 0
TANH = 1
ACTIVATIONS = {"logistic": LOGISTIC, "tanh": TANH}


def n_params(sizes: np.ndarray, bypass: bool) -> int:
    """Length of the flat parameter vector for layer ``sizes``."""
    n = sum(
        int(sizes[i]) * int(sizes[i + 1]) + int(sizes[i + 1])
        for i in range(len(sizes) - 1)
    )
    return n + (int(sizes[0]) * int(sizes[-1]) if bypass else 0)


def n_hidden(sizes: np.ndarray) -> int:
    """Total number of hidden units (length of the activation buffer)."""
    # A Python sum: this runs at every kernel call, where np.sum's overhead
    # of microseconds shows on short records.
    return sum(int(s) for s in sizes[1:-1])


@njit(cache=True, inline="always")
def _activate(s, act):
    if act == LOGISTIC:
        # exp(-s) may overflow to inf for very negative s: the limit 0 is right.
        return 1.0 / (1.0 + np.exp(-s))
    return np.tanh(s)


@njit(cache=True, inline="always")
def _activation_slope(a, act):
    # Derivative expressed through the activation value itself.
    if act == LOGISTIC:
        return a * (1.0 - a)
    return 1.0 - a * a


@njit(cache=True, inline="always")
def _dot(w, p, x, off, n):
    """``w[p:p + n] @ x[off:off + n]``."""
    s = 0.0
    for i in range(n):
        s += w[p + i] * x[off + i]
    return s


@njit(cache=True, inline="always")
def mlp_forward(w, sizes, act, bypass, z, acts, out):
    """Evaluate the network at ``z``; hidden activations go to ``acts``."""
    n_layers = sizes.shape[0] - 1
    n_o = sizes[n_layers]
    n_z = sizes[0]
    if n_layers == 1:
        for k in range(n_o):
            out[k] = w[n_z * n_o + k] + _dot(w, k * n_z, z, 0, n_z)
        p = n_z * n_o + n_o
    else:
        # First hidden layer from z, the others from the previous layer's
        # activations: separate loops keep the input choice out of the
        # innermost loops.
        n_h = sizes[1]
        bias = n_z * n_h
        for j in range(n_h):
            s = _dot(w, j * n_z, z, 0, n_z)
            acts[j] = _activate(s + w[bias + j], act)
        p = bias + n_h
        in_off = 0
        for layer in range(1, n_layers - 1):
            n_in = n_h
            n_h = sizes[layer + 1]
            bias = p + n_in * n_h
            out_off = in_off + n_in
            for j in range(n_h):
                s = _dot(w, p + j * n_in, acts, in_off, n_in)
                acts[out_off + j] = _activate(s + w[bias + j], act)
            p = bias + n_h
            in_off = out_off
        bias = p + n_h * n_o
        for k in range(n_o):
            s = w[bias + k]
            for j in range(n_h):
                s += w[p + k * n_h + j] * acts[in_off + j]
            out[k] = s
        p = bias + n_o
    if bypass:
        for k in range(n_o):
            out[k] += _dot(w, p + k * n_z, z, 0, n_z)


@njit(cache=True, inline="always")
def mlp_vjp(w, sizes, act, bypass, z, acts, v, gw, gz, delta, delta_prev):
    """Vector-Jacobian product of the network at a stored forward pass.

    Adds ``v @ d out / d w`` to ``gw`` and writes ``v @ d out / d z`` to
    ``gz``. ``delta`` and ``delta_prev`` are scratch buffers of length
    ``max(sizes)``.
    """
    n_layers = sizes.shape[0] - 1
    n_z = sizes[0]
    n_o = sizes[n_layers]
    # Offsets of each layer's parameters and of its input activations.
    p_end = 0
    for layer in range(n_layers):
        p_end += sizes[layer] * sizes[layer + 1] + sizes[layer + 1]
    for j in range(n_o):
        delta[j] = v[j]
    for i in range(n_z):
        gz[i] = 0.0
    if bypass:
        for j in range(n_o):
            vj = v[j]
            if vj != 0.0:
                row = p_end + j * n_z
                for i in range(n_z):
                    gw[row + i] += vj * z[i]
                    gz[i] += vj * w[row + i]
    p = p_end
    act_end = 0
    for layer in range(n_layers - 1):
        act_end += sizes[layer + 1]
    for layer in range(n_layers - 1, -1, -1):
        n_in = sizes[layer]
        n_out = sizes[layer + 1]
        p -= n_in * n_out + n_out
        bias = p + n_in * n_out
        in_off = act_end - n_in  # start of this layer's input activations
        for i in range(n_in):
            delta_prev[i] = 0.0
        for j in range(n_out):
            dj = delta[j]
            if dj == 0.0:
                continue
            gw[bias + j] += dj
            row = p + j * n_in
            if layer == 0:
                for i in range(n_in):
                    gw[row + i] += dj * z[i]
                    delta_prev[i] += dj * w[row + i]
            else:
                for i in range(n_in):
                    gw[row + i] += dj * acts[in_off + i]
                    delta_prev[i] += dj * w[row + i]
        if layer == 0:
            for i in range(n_in):
                gz[i] += delta_prev[i]
        else:
            for i in range(n_in):
                delta[i] = delta_prev[i] * _activation_slope(acts[in_off + i], act)
            act_end = in_off


@njit(cache=True, inline="always")
def out_of_range(out, bound, n_bounded):
    """True when a value of ``out`` is non-finite, or one of its first
    ``n_bounded`` is beyond ``bound`` (divergence)."""
    for j in range(out.shape[0]):
        size = np.abs(out[j])
        # The negated comparisons also catch NaN.
        if not (size <= bound if j < n_bounded else size < np.inf):
            return True
    return False
