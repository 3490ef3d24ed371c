"""Innovation state-space recurrence (paper eq. 7-12) with exact sensitivities.

Data layout as in the TDL kernels: sequences are stacked in ``Y``
(``(n_rows, p)``, standardised measured outputs) and ``U`` (``(n_rows,
n_inputs)``); sequence ``s`` occupies rows ``starts[s]:starts[s + 1]``, the
first ``h`` of them history. The state ``x`` has ``n`` components, the first
``p`` of which are the measured outputs (``H = [I 0]``). At modelled row
``t`` the network sees

``z = [x(t-1), u(t-nk), e(t-1)]``  (lengths ``n``, ``n_inputs``, ``p``)

and returns ``x(t)``; ``yhat(t) = x(t)[:p]``. Before the first modelled row
the state is ``X0[s]``. Three modes, chosen by ``seg_len``:

* ``seg_len == 1``: the one-step predictor, innovations
  ``e(t-1) = y(t-1) - x(t-1)[:p]`` fed back (eq. 10 with ``Phi - K H``);
* ``seg_len > 1``: simulation (``e = 0``) in segments of ``seg_len`` rows; at
  each later segment start the measured states are reset to the measured
  outputs while the unmeasured ones carry over (multiple shooting);
* ``seg_len`` beyond the sequence: the free run from ``X0``.

With ``filt`` and ``seg_len > 1``, the one-step predictor (the model's own
innovation filter) runs beside the simulation, and every segment starts from
its state, the unmeasured states included, with exact sensitivities through
it; the filter's burn-in, the first segment of each sequence, gives that
segment's rows as one-step predictions.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from sysid_nn._kernels import _recurrence as rec
from sysid_nn._kernels._mlp import mlp_forward, mlp_vjp, out_of_range


@njit(cache=True, inline="always")
def _network_input(x, U, t, nk, e, z):
    n = x.shape[0]
    m = U.shape[1]
    for i in range(n):
        z[i] = x[i]
    for k in range(m):
        z[n + k] = U[t - nk, k]
    for k in range(e.shape[0]):
        z[n + m + k] = e[k]


@njit(cache=True, inline="always")
def _advance(w, sizes, act, bypass, x, U, t, nk, e, z, acts, out, bound):
    """One step of the network from state ``x``; True if it left the range.

    The measured states (the first ``p``, ``p = e.shape[0]``) must stay within
    ``bound``, the others finite: their coordinates are the network's own,
    and a bounded run may take them far beyond the outputs' range.
    """
    _network_input(x, U, t, nk, e, z)
    mlp_forward(w, sizes, act, bypass, z, acts, out)
    return out_of_range(out, bound, e.shape[0])


@njit(cache=True, inline="always")
def _sensitivity_step(
    w, sizes, act, bypass, z, acts, predictor, want_jac, want_lin, t, D,
    psi_prev, psi, v, lam, gz, coef, d1, d2, n, m, p,
):  # fmt: skip
    """``Psi(t)`` from ``Psi(t-1)`` (eq. 10) and ``D[t] = d x(t) / d z``."""
    n_z = z.shape[0]
    n_w = w.shape[0]
    for j in range(n):
        v[:] = 0.0
        v[j] = 1.0
        lam[:] = 0.0
        mlp_vjp(w, sizes, act, bypass, z, acts, v, lam, gz, d1, d2)
        if want_lin:
            for c in range(n_z):
                D[t, j, c] = gz[c]
        if not want_jac:
            continue
        # Eq. 10: Psi(t) = Lambda(t) + [Phi(t) - K(t) H] Psi(t-1).
        for i in range(n):
            coef[i] = gz[i]
        if predictor:
            for k in range(p):
                coef[k] -= gz[n + m + k]
        for i in range(n):
            c_i = coef[i]
            if c_i != 0.0:
                for c in range(n_w):
                    lam[c] += c_i * psi_prev[i, c]
        for c in range(n_w):
            psi[j, c] = lam[c]


@njit(cache=True, inline="always")
def _loop(
    w, sizes, act, bypass, Y, U, starts, h, nk, X0, seg_len, bound, jac,
    want_lin, Xs, J, Z, A, D, JtJ, Jtr, syrk, diverged, filt,
):  # fmt: skip
    # Inlined twice by issm_run, once with the constants NO_JAC and False, so
    # that the plain run compiles without the sensitivity branches.
    n = Xs.shape[1]
    p = Y.shape[1]
    m = U.shape[1]
    n_z = sizes[0]
    n_w = w.shape[0]
    width = np.max(sizes)
    predictor = seg_len == 1
    filt = filt and not predictor
    want_jac = jac != rec.NO_JAC
    sens = want_jac or want_lin
    x = np.empty(n)
    e = np.zeros(p)
    out = np.empty(n)
    v = np.zeros(n)
    gz = np.empty(n_z)
    coef = np.empty(n)
    d1 = np.empty(width)
    d2 = np.empty(width)
    z = np.empty(n_z)
    acts = np.zeros(max(1, A.shape[1]))
    lam = np.empty(n_w)  # d x_j / d w at this step before the recursion
    psi = np.zeros((n, n_w if want_jac else 0))
    psi_prev = np.zeros((n, n_w if want_jac else 0))
    # The innovation filter run beside a filtered-start simulation.
    n_f = n_w if (want_jac and filt) else 0
    xf = np.empty(n)
    psif = np.zeros((n, n_f))
    psif_prev = np.zeros((n, n_f))
    Jb, rb = rec.new_block(n_w, jac)
    n_b = 0
    row_base = 0
    for s in range(starts.shape[0] - 1):
        a = starts[s]
        b = starts[s + 1]
        diverged[s] = -1
        rec.fill_rows(Xs, a, a + h, X0[s])
        for i in range(n):
            x[i] = X0[s, i]
            xf[i] = X0[s, i]
        if want_jac:
            psi_prev[:, :] = 0.0
            psif_prev[:, :] = 0.0
        for t in range(a + h, b):
            k_local = t - a - h
            at_start = (not predictor) and k_local > 0 and k_local % seg_len == 0
            # Filtered segments: the burn-in and every segment start are the
            # innovation filter's rows.
            from_filter = filt and (k_local < seg_len or at_start)
            if filt:
                for k in range(p):
                    e[k] = Y[t - 1, k] - xf[k]
                if _advance(
                    w, sizes, act, bypass, xf, U, t, nk, e, z, acts, out, bound
                ):
                    diverged[s] = k_local
                    rec.fill_rows(Xs, t, b, np.full(n, np.nan))
                    break
                for i in range(n):
                    xf[i] = out[i]
                if want_jac or (want_lin and from_filter):
                    _sensitivity_step(
                        w, sizes, act, bypass, z, acts, True, want_jac,
                        want_lin and from_filter, t, D, psif_prev, psif, v, lam,
                        gz, coef, d1, d2, n, m, p,
                    )  # fmt: skip
                if want_jac and from_filter:
                    psi[:, :] = psif
            if not from_filter:
                if at_start:
                    # Multiple shooting: measured states restart from the
                    # data; their sensitivities vanish, the unmeasured ones
                    # carry over.
                    for k in range(p):
                        x[k] = Y[t - 1, k]
                    if want_jac:
                        psi_prev[:p, :] = 0.0
                if predictor:
                    for k in range(p):
                        e[k] = Y[t - 1, k] - x[k]
                else:
                    e[:] = 0.0
                if _advance(w, sizes, act, bypass, x, U, t, nk, e, z, acts, out, bound):
                    diverged[s] = k_local
                    rec.fill_rows(Xs, t, b, np.full(n, np.nan))
                    break
                if sens:
                    _sensitivity_step(
                        w, sizes, act, bypass, z, acts, predictor, want_jac,
                        want_lin, t, D, psi_prev, psi, v, lam, gz, coef, d1, d2,
                        n, m, p,
                    )  # fmt: skip
            rec.keep_step(Z, A, t, z, acts)
            for i in range(n):
                x[i] = out[i]
                Xs[t, i] = out[i]
            if jac == rec.FULL_JAC:
                rec.copy_rows(J[row_base + k_local * p :], psi, 0, p)
            elif jac == rec.NORMAL:
                for k in range(p):
                    n_b = rec.add_row(
                        psi[k], out[k] - Y[t, k], Jb, rb, n_b, JtJ, Jtr, syrk
                    )
            if want_jac:
                psi, psi_prev = psi_prev, psi
                if filt:
                    psif, psif_prev = psif_prev, psif
        row_base += (b - a - h) * p
    rec.finish(Jb, rb, n_b, JtJ, Jtr, syrk)


@njit(cache=True)
def issm_run(
    w, sizes, act, bypass, Y, U, starts, h, nk, X0, seg_len, bound, jac,
    want_lin, Xs, J, Z, A, D, JtJ, Jtr, syrk, diverged, filt=False,
):  # fmt: skip
    """Run the state recurrence; optionally the Jacobian and linearisation.

    ``Xs`` (``(n_rows, n)``) receives the states (history rows hold ``X0``;
    NaN from a divergence on). ``jac`` is a mode of :mod:`._recurrence`:
    with ``FULL_JAC``, ``J`` (``(n_modelled * p, n_w)``) receives ``d yhat /
    d w = H Psi`` by the forward sensitivities of eq. 10; with ``NORMAL``,
    ``JtJ`` and ``Jtr`` receive the sums of ``J' J`` and ``J' (yhat - y)``
    (``syrk`` is :data:`._recurrence.SYRK`) and ``J`` is not used (only
    ``Psi(t-1)`` is kept). With ``want_lin``, ``D[t]`` (``(n, n_z)``)
    receives ``d x(t) / d z``, whose blocks are ``Phi(t)`` and ``K(t)`` of
    eq. 12. ``Z`` and ``A`` keep the network
    inputs and hidden activations for the adjoint pass when they have rows.
    ``diverged[s]`` is the first modelled index of sequence ``s`` whose
    measured states (the outputs) left ``[-bound, bound]`` or whose state
    became non-finite, or -1. With ``filt``, simulated segments start
    from the innovation filter run beside them (see the module docstring);
    ``Z`` and ``A`` then hold no usable adjoint state.
    """
    if jac == rec.NO_JAC and not want_lin:
        _loop(w, sizes, act, bypass, Y, U, starts, h, nk, X0, seg_len, bound,
              rec.NO_JAC, False, Xs, J, Z, A, D, JtJ, Jtr, syrk, diverged,
              filt)  # fmt: skip
    else:
        _loop(w, sizes, act, bypass, Y, U, starts, h, nk, X0, seg_len, bound,
              jac, want_lin, Xs, J, Z, A, D, JtJ, Jtr, syrk, diverged,
              filt)  # fmt: skip


@njit(cache=True)
def issm_gradient(w, sizes, act, bypass, Y, U, starts, h, seg_len, Xs, Z, A, grad):
    """Adjoint (backpropagation-through-time) gradient of ``0.5 ||H x - Y||^2``.

    Needs ``Xs``, ``Z`` and ``A`` of a completed :func:`issm_run` in the same
    mode without divergence; adds the gradient to ``grad``.
    """
    n = Xs.shape[1]
    p = Y.shape[1]
    m = U.shape[1]
    n_z = sizes[0]
    width = np.max(sizes)
    predictor = seg_len == 1
    gz = np.empty(n_z)
    d1 = np.empty(width)
    d2 = np.empty(width)
    adj = np.zeros((Xs.shape[0], n))
    for s in range(starts.shape[0] - 1):
        a = starts[s]
        b = starts[s + 1]
        for t in range(b - 1, a + h - 1, -1):
            for k in range(p):
                adj[t, k] += Xs[t, k] - Y[t, k]
            mlp_vjp(w, sizes, act, bypass, Z[t], A[t], adj[t], grad, gz, d1, d2)
            k_local = t - a - h
            if k_local == 0:
                continue  # the initial state does not depend on w
            first = p if (not predictor and k_local % seg_len == 0) else 0
            for i in range(first, n):
                adj[t - 1, i] += gz[i]
            if predictor:
                for k in range(p):
                    adj[t - 1, k] -= gz[n + m + k]


@njit(cache=True)
def issm_predict_horizon(
    w, sizes, act, bypass, U, starts, h, nk, horizon, X0, Xp, Yhat
):
    """Sliding ``horizon``-step-ahead predictor from one-step predictor states.

    ``Xp`` holds the states of the one-step predictor (innovations fed back);
    ``Xp[t]`` uses measurements up to ``t - 1``. Each modelled ``Yhat[t]``
    continues from ``Xp[t - horizon + 1]`` with ``e = 0`` (from ``X0`` at the
    sequence start when that row lies before it), so no value sees a
    measurement later than ``t - horizon``.
    """
    n = Xp.shape[1]
    p = Yhat.shape[1]
    n_z = sizes[0]
    z = np.empty(n_z)
    acts = np.empty(max(1, np.sum(sizes[1:-1])))
    out = np.empty(n)
    x = np.empty(n)
    e = np.zeros(p)
    for s in range(starts.shape[0] - 1):
        a = starts[s]
        b = starts[s + 1]
        for t in range(a, a + h):
            for k in range(p):
                Yhat[t, k] = X0[s, k]
        for t in range(a + h, b):
            first = t - horizon + 1
            if first >= a + h:
                for i in range(n):
                    x[i] = Xp[first, i]
                first += 1
            else:
                for i in range(n):
                    x[i] = X0[s, i]
                first = a + h
            for tt in range(first, t + 1):
                _network_input(x, U, tt, nk, e, z)
                mlp_forward(w, sizes, act, bypass, z, acts, out)
                for i in range(n):
                    x[i] = out[i]
            for k in range(p):
                Yhat[t, k] = x[k]
