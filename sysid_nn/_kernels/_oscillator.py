"""Bouc-Wen oscillator (paper eq. 13-15) integrated with classical RK4.

Pure numba functions on float64 arrays; the caller validates everything.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, inline="always", error_model="numpy")
def _bouc_wen_rhs(x, v, z, f, c_damp, k_lin, k_hys, beta_s, gamma_s, n):
    # beta_s = beta / z0**n and gamma_s = gamma / z0**n are folded in by the
    # caller so the inner loop has no division.
    azn = abs(z) if n == 1.0 else abs(z) ** n
    # sign(Xd) |Z|^(n-1) Z = sign(Xd Z) |Z|^n: no 0**(n-1) for n < 1.
    vz = v * z
    s = 1.0 if vz > 0.0 else (-1.0 if vz < 0.0 else 0.0)
    dz = (1.0 - (beta_s * s + gamma_s) * azn) * v
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
    c_damp = 2.0 * zeta * omega0
    k_lin = omega0 * omega0 * alpha
    k_hys = omega0 * omega0 * (1.0 - alpha)
    z0n = z0**n
    beta_s = beta / z0n
    gamma_s = gamma / z0n
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
                a1, b1, c1 = _bouc_wen_rhs(
                    x, v, z, f, c_damp, k_lin, k_hys, beta_s, gamma_s, n
                )
                a2, b2, c2 = _bouc_wen_rhs(
                    x + 0.5 * h * a1,
                    v + 0.5 * h * b1,
                    z + 0.5 * h * c1,
                    f,
                    c_damp,
                    k_lin,
                    k_hys,
                    beta_s,
                    gamma_s,
                    n,
                )
                a3, b3, c3 = _bouc_wen_rhs(
                    x + 0.5 * h * a2,
                    v + 0.5 * h * b2,
                    z + 0.5 * h * c2,
                    f,
                    c_damp,
                    k_lin,
                    k_hys,
                    beta_s,
                    gamma_s,
                    n,
                )
                a4, b4, c4 = _bouc_wen_rhs(
                    x + h * a3,
                    v + h * b3,
                    z + h * c3,
                    f,
                    c_damp,
                    k_lin,
                    k_hys,
                    beta_s,
                    gamma_s,
                    n,
                )
                x += h / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4)
                v += h / 6.0 * (b1 + 2.0 * b2 + 2.0 * b3 + b4)
                z += h / 6.0 * (c1 + 2.0 * c2 + 2.0 * c3 + c4)
    return disp, vel, hyst
