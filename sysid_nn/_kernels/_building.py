"""Shear building with a Bouc-Wen spring in every storey, integrated with RK4.

Pure numba functions on float64 arrays; the caller validates everything.
The storey spring is the oscillator's (``_oscillator``), driven by the
inter-storey drift instead of the displacement.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from sysid_nn._kernels._oscillator import _hysteretic_slope


@njit(cache=True, inline="always", error_model="numpy")
def _floor_forces(x, z, k_lin, k_hys, out):
    # Storey i carries k_lin d_i + k_hys z_i between floors i - 1 and i
    # (floor -1 is the ground); out[i] is the net spring force on floor i.
    for i in range(x.shape[0]):
        d = x[i] - (x[i - 1] if i > 0 else 0.0)
        s = k_lin[i] * d + k_hys[i] * z[i]
        out[i] = s
        if i > 0:
            out[i - 1] -= s


@njit(cache=True, error_model="numpy")
def _rhs(y, ag, p, dy):
    # y = (x, v, z) as rows; relative coordinates: M x'' + C x' + f_s = -M 1 a_g.
    # p = (inv_mass, damping, k_lin, k_hys, beta_s, gamma_s, nexp).
    inv_mass, damping, k_lin, k_hys, beta_s, gamma_s, nexp = p
    x, v, z = y[0], y[1], y[2]
    n = x.shape[0]
    _floor_forces(x, z, k_lin, k_hys, dy[1])
    for i in range(n):
        cv = 0.0
        for j in range(n):
            cv += damping[i, j] * v[j]
        dy[1, i] = -(cv + dy[1, i]) * inv_mass[i] - ag
        dy[0, i] = v[i]
        drift_rate = v[i] - (v[i - 1] if i > 0 else 0.0)
        slope = _hysteretic_slope(z[i], drift_rate, beta_s[i], gamma_s[i], nexp[i])
        dy[2, i] = slope * drift_rate


@njit(cache=True, error_model="numpy")
def simulate_shear_building(
    ground,
    dt,
    n_substeps,
    inv_mass,
    damping,
    k_lin,
    k_hys,
    beta_s,
    gamma_s,
    nexp,
    state0,
):  # pragma: no cover - compiled; exercised through ShearBuilding
    """Integrate the building for every row of ``ground`` (zero-order hold).

    ``ground`` has shape (n_realizations, n_samples): the ground acceleration,
    ``ground[r, k]`` acting on [t_k, t_{k+1}). ``state0`` has shape
    (n_realizations, 3 n) with (x, v, z) at t_0. Storey ``i`` has linear
    stiffness ``k_lin[i]``, hysteretic stiffness ``k_hys[i]`` and loop
    parameters ``beta_s[i] = beta / z0**n``, ``gamma_s[i] = gamma / z0**n``,
    ``nexp[i] = n``; ``damping`` is the damping matrix. Returns floor
    displacements, velocities (relative to the ground), hysteretic states and
    absolute floor accelerations, each (n_realizations, n_samples, n); index
    k along the second axis is the state at t_k.
    """
    n_real, n_samp = ground.shape
    n = inv_mass.shape[0]
    p = (inv_mass, damping, k_lin, k_hys, beta_s, gamma_s, nexp)
    out = np.empty((3, n_real, n_samp, n))  # x, v, z at the samples
    acc = np.empty((n_real, n_samp, n))
    h = dt / n_substeps
    # RK4: stage c is evaluated at y + offset[c] * k[c - 1], weighted by weight[c].
    offset = np.array([0.0, 0.5 * h, 0.5 * h, h])
    weight = np.array([h / 6.0, h / 3.0, h / 3.0, h / 6.0])
    y = np.empty((3, n))
    ys = np.empty((3, n))
    k = np.zeros((4, 3, n))
    dy = np.empty((3, n))
    for r in range(n_real):
        for c in range(3):
            y[c] = state0[r, c * n : (c + 1) * n]
        for s in range(n_samp):
            out[:, r, s] = y
            # The absolute acceleration x'' + a_g does not depend on a_g.
            _rhs(y, 0.0, p, dy)
            acc[r, s] = dy[1]
            if s == n_samp - 1:
                break  # ground[r, -1] only acts after the last recorded sample
            ag = ground[r, s]
            for _ in range(n_substeps):
                for stage in range(4):
                    prev = max(stage - 1, 0)  # stage 0: offset 0
                    for c in range(3):
                        for i in range(n):
                            ys[c, i] = y[c, i] + offset[stage] * k[prev, c, i]
                    _rhs(ys, ag, p, k[stage])
                for c in range(3):
                    for i in range(n):
                        y[c, i] += (
                            weight[0] * k[0, c, i]
                            + weight[1] * k[1, c, i]
                            + weight[2] * k[2, c, i]
                            + weight[3] * k[3, c, i]
                        )
    return out[0], out[1], out[2], acc
