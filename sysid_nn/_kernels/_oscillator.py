"""Bouc-Wen oscillator (paper eq. 13-15) integrated with classical RK4.

Pure numba functions on float64 arrays; the caller validates everything.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, inline="always", error_model="numpy")
def _scaled_loop_params(beta, gamma, n, z0):
    # beta / z0**n and gamma / z0**n, folded in once so that the inner loops
    # have no division.
    z0n = z0**n
    return beta / z0n, gamma / z0n


@njit(cache=True, inline="always", error_model="numpy")
def _hysteretic_slope(z, dx, beta_s, gamma_s, n):
    # dZ/dX of eq. 15 for a displacement moving in the direction of dx.
    azn = abs(z) if n == 1.0 else abs(z) ** n
    # sign(Xd) |Z|^(n-1) Z = sign(Xd Z) |Z|^n: no 0**(n-1) for n < 1.
    s = dx * z
    sign = 1.0 if s > 0.0 else (-1.0 if s < 0.0 else 0.0)
    return 1.0 - (beta_s * sign + gamma_s) * azn


@njit(cache=True, inline="always", error_model="numpy")
def _bouc_wen_rhs(x, v, z, f, p):
    # p = (c_damp, k_lin, k_hys, beta_s, gamma_s, n), see simulate_bouc_wen.
    c_damp, k_lin, k_hys, beta_s, gamma_s, n = p
    dz = _hysteretic_slope(z, v, beta_s, gamma_s, n) * v
    dv = f - c_damp * v - k_lin * x - k_hys * z
    return v, dv, dz


@njit(cache=True, error_model="numpy")
def simulate_bouc_wen(
    force, dt, n_substeps, zeta, omega0, alpha, beta, gamma, n, z0, state0
):  # pragma: no cover - compiled; exercised through HystereticOscillator
    """Integrate eq. 13-15 for every row of ``force`` (zero-order hold).

    ``force`` has shape (n_realizations, n_samples); ``force[r, k]`` acts on
    [t_k, t_{k+1}). ``state0`` has shape (n_realizations, 3) with (X, Xd, Z)
    at t_0. Returns displacement, velocity and hysteretic arrays shaped like
    ``force``; column k is the state at t_k.
    """
    n_real, n_samp = force.shape
    disp = np.empty((n_real, n_samp))
    vel = np.empty((n_real, n_samp))
    hyst = np.empty((n_real, n_samp))
    h = dt / n_substeps
    hh = 0.5 * h
    beta_s, gamma_s = _scaled_loop_params(beta, gamma, n, z0)
    w2 = omega0 * omega0
    p = (2.0 * zeta * omega0, w2 * alpha, w2 * (1.0 - alpha), beta_s, gamma_s, n)
    for r in range(n_real):
        x = state0[r, 0]
        v = state0[r, 1]
        z = state0[r, 2]
        for k in range(n_samp):
            disp[r, k] = x
            vel[r, k] = v
            hyst[r, k] = z
            if k == n_samp - 1:
                break  # force[r, -1] only acts after the last recorded sample
            f = force[r, k]
            for _ in range(n_substeps):
                a1, b1, c1 = _bouc_wen_rhs(x, v, z, f, p)
                a2, b2, c2 = _bouc_wen_rhs(x + hh * a1, v + hh * b1, z + hh * c1, f, p)
                a3, b3, c3 = _bouc_wen_rhs(x + hh * a2, v + hh * b2, z + hh * c2, f, p)
                a4, b4, c4 = _bouc_wen_rhs(x + h * a3, v + h * b3, z + h * c3, f, p)
                x += h / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4)
                v += h / 6.0 * (b1 + 2.0 * b2 + 2.0 * b3 + b4)
                z += h / 6.0 * (c1 + 2.0 * c2 + 2.0 * c3 + c4)
    return disp, vel, hyst


@njit(cache=True, error_model="numpy")
def hysteretic_state(
    x, n_substeps, beta, gamma, n, z0
):  # pragma: no cover - compiled; exercised through HystereticOscillator
    """Bouc-Wen state ``Z`` (eq. 15) along every row of displacements, from rest.

    Eq. 15 is rate-independent (``dZ/dX`` depends on ``Z`` and the direction
    of ``dX`` only), so ``Z`` follows any displacement history; integrated in
    ``X`` by RK4 on ``n_substeps`` pieces of every sample step. ``x`` has
    shape (n_realizations, n_samples); so has the result.
    """
    beta_s, gamma_s = _scaled_loop_params(beta, gamma, n, z0)
    z = np.zeros(x.shape)
    for r in range(x.shape[0]):
        for k in range(1, x.shape[1]):
            h = (x[r, k] - x[r, k - 1]) / n_substeps
            zk = z[r, k - 1]
            for _ in range(n_substeps):
                k1 = _hysteretic_slope(zk, h, beta_s, gamma_s, n)
                k2 = _hysteretic_slope(zk + 0.5 * h * k1, h, beta_s, gamma_s, n)
                k3 = _hysteretic_slope(zk + 0.5 * h * k2, h, beta_s, gamma_s, n)
                k4 = _hysteretic_slope(zk + h * k3, h, beta_s, gamma_s, n)
                zk += h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
            z[r, k] = zk
    return z
