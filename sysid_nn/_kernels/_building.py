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
def _rhs(
    x, v, z, ag, inv_mass, damping, k_lin, k_hys, beta_s, gamma_s, nexp, dx, dv, dz
):
    # Relative coordinates: M x'' + C x' + f_s(x, z) = -M 1 a_g.
    n = x.shape[0]
    _floor_forces(x, z, k_lin, k_hys, dv)
    for i in range(n):
        cv = 0.0
        for j in range(n):
            cv += damping[i, j] * v[j]
        dv[i] = -(cv + dv[i]) * inv_mass[i] - ag
        dx[i] = v[i]
        drift_rate = v[i] - (v[i - 1] if i > 0 else 0.0)
        dz[i] = _hysteretic_slope(z[i], drift_rate, beta_s[i], gamma_s[i], nexp[i]) * (
            drift_rate
        )


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
    disp = np.empty((n_real, n_samp, n))
    vel = np.empty((n_real, n_samp, n))
    hyst = np.empty((n_real, n_samp, n))
    acc = np.empty((n_real, n_samp, n))
    h = dt / n_substeps
    hh = 0.5 * h
    x = np.empty(n)
    v = np.empty(n)
    z = np.empty(n)
    xs = np.empty(n)
    vs = np.empty(n)
    zs = np.empty(n)
    k = np.zeros((4, 3, n))  # RK4 stages of (x, v, z); stage 0 reads 0 * k[0]
    for r in range(n_real):
        x[:] = state0[r, :n]
        v[:] = state0[r, n : 2 * n]
        z[:] = state0[r, 2 * n :]
        for s in range(n_samp):
            disp[r, s] = x
            vel[r, s] = v
            hyst[r, s] = z
            # The absolute acceleration x'' + a_g does not depend on a_g.
            _rhs(
                x,
                v,
                z,
                0.0,
                inv_mass,
                damping,
                k_lin,
                k_hys,
                beta_s,
                gamma_s,
                nexp,
                xs,
                acc[r, s],
                zs,
            )
            if s == n_samp - 1:
                break  # ground[r, -1] only acts after the last recorded sample
            ag = ground[r, s]
            for _ in range(n_substeps):
                for stage in range(4):
                    # Stage 0 at the step's start, 1 and 2 at its middle, 3 at its end.
                    step = 0.0 if stage == 0 else (h if stage == 3 else hh)
                    prev = max(stage - 1, 0)
                    for i in range(n):
                        xs[i] = x[i] + step * k[prev, 0, i]
                        vs[i] = v[i] + step * k[prev, 1, i]
                        zs[i] = z[i] + step * k[prev, 2, i]
                    _rhs(
                        xs,
                        vs,
                        zs,
                        ag,
                        inv_mass,
                        damping,
                        k_lin,
                        k_hys,
                        beta_s,
                        gamma_s,
                        nexp,
                        k[stage, 0],
                        k[stage, 1],
                        k[stage, 2],
                    )
                for i in range(n):
                    x[i] += (
                        h
                        / 6.0
                        * (
                            k[0, 0, i]
                            + 2.0 * k[1, 0, i]
                            + 2.0 * k[2, 0, i]
                            + k[3, 0, i]
                        )
                    )
                    v[i] += (
                        h
                        / 6.0
                        * (
                            k[0, 1, i]
                            + 2.0 * k[1, 1, i]
                            + 2.0 * k[2, 1, i]
                            + k[3, 1, i]
                        )
                    )
                    z[i] += (
                        h
                        / 6.0
                        * (
                            k[0, 2, i]
                            + 2.0 * k[1, 2, i]
                            + 2.0 * k[2, 2, i]
                            + k[3, 2, i]
                        )
                    )
    return disp, vel, hyst, acc
