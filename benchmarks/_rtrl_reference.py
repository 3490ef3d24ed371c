"""Minimal hand-written RTRL kernels: the speed reference of the TDL kernels.

One sequence, one output, one logistic hidden layer, no bypass: the paper's
TDL network and nothing more general. The regressor ``phi = [y(t-1), ...,
y(t-na), u(t-nk), ..., u(t-nk-nb+1)]`` goes through the lag transform ``z = S
phi`` into the network; the run is free (the network is fed its own outputs).
The weights use the project's flat layout (hidden weights row-major, hidden
biases, output weights, output bias), so both kernels take the same ``w`` and
must give the same outputs and Jacobian.

``forward`` simulates; ``forward_jacobian`` also fills the full Jacobian
``J[t] = d yhat(h + t) / d w`` by real-time recurrent learning (forward
sensitivities): the direct derivative of the network plus the sensitivities
of the fed-back outputs, ``J[t] += sum_i (d y / d y(t-i)) J[t-i]``.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def _step(w, S, yhat, u, t, na, nb, nk, phi, z, a):
    """Output at ``t`` from the fed-back outputs; activations go to ``a``."""
    n_z = S.shape[0]
    n_h = a.shape[0]
    b1 = n_h * n_z
    w2 = b1 + n_h
    for i in range(na):
        phi[i] = yhat[t - 1 - i]
    for i in range(nb):
        phi[na + i] = u[t - nk - i]
    for r in range(n_z):
        s = 0.0
        for c in range(na + nb):
            s += S[r, c] * phi[c]
        z[r] = s
    out = w[w2 + n_h]
    for j in range(n_h):
        s = w[b1 + j]
        for i in range(n_z):
            s += w[j * n_z + i] * z[i]
        a[j] = 1.0 / (1.0 + np.exp(-s))
        out += w[w2 + j] * a[j]
    return out


@njit(cache=True)
def forward(w, S, y0, u, na, nb, nk, yhat):
    """Free run from the ``h`` history values ``y0``; ``yhat`` as long as ``u``."""
    n_z = S.shape[0]
    phi = np.empty(na + nb)
    z = np.empty(n_z)
    a = np.empty((w.shape[0] - 1) // (n_z + 2))
    h = y0.shape[0]
    yhat[:h] = y0
    for t in range(h, u.shape[0]):
        yhat[t] = _step(w, S, yhat, u, t, na, nb, nk, phi, z, a)


@njit(cache=True)
def forward_jacobian(w, S, y0, u, na, nb, nk, yhat, J):
    """:func:`forward` plus the full Jacobian ``J`` (``(len(u) - h, n_w)``)."""
    n_z = S.shape[0]
    n_w = w.shape[0]
    n_h = (n_w - 1) // (n_z + 2)
    b1 = n_h * n_z
    w2 = b1 + n_h
    phi = np.empty(na + nb)
    z = np.empty(n_z)
    a = np.empty(n_h)
    gz = np.empty(n_z)
    h = y0.shape[0]
    yhat[:h] = y0
    for t in range(h, u.shape[0]):
        yhat[t] = _step(w, S, yhat, u, t, na, nb, nk, phi, z, a)
        # Direct derivatives of the network output.
        row = J[t - h]
        gz[:] = 0.0
        for j in range(n_h):
            d = w[w2 + j] * a[j] * (1.0 - a[j])
            for i in range(n_z):
                row[j * n_z + i] = d * z[i]
                gz[i] += d * w[j * n_z + i]
            row[b1 + j] = d
            row[w2 + j] = a[j]
        row[w2 + n_h] = 1.0
        # Sensitivities carried through the fed-back outputs.
        for i in range(na):
            if t - 1 - i < h:
                break
            g = 0.0
            for r in range(n_z):
                g += gz[r] * S[r, i]
            if g != 0.0:
                prev = J[t - 1 - i - h]
                for c in range(n_w):
                    row[c] += g * prev[c]
