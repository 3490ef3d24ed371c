"""Tapped-delay-line recurrence (paper eq. 4-6) with exact sensitivities.

Data layout shared by every kernel here: all sequences are stacked in ``Y``
(``(n_rows, n_outputs)``) and ``U`` (``(n_rows, n_inputs)``); sequence ``s``
occupies rows ``starts[s]:starts[s + 1]``, whose first ``h`` rows are its
history (the initial conditions) and the rest are modelled. The regressor at
row ``t`` is

``phi = [y(t-1), ..., y(t-na), u(t-nk), ..., u(t-nk-nb+1)]``

(each block over all channels), the network sees ``z = S @ phi`` and
returns ``y(t)``. Within a segment of ``seg_len`` modelled rows the network
is fed its own outputs; at each segment start it restarts from measured
values, so ``seg_len = 1`` is the one-step predictor, a length beyond the
sequence is the free run and anything between is multiple shooting.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from sysid_nn._kernels._mlp import mlp_forward, mlp_vjp, out_of_range
from sysid_nn._kernels._recurrence import (
    FULL_JAC,
    NO_JAC,
    NORMAL,
    add_row,
    copy_rows,
    fill_rows,
    finish,
    keep_step,
    new_block,
)


@njit(cache=True, inline="always")
def _regressor(Yhat, Y, U, t, seg_start, na, nb, nk, phi):
    n_out = Y.shape[1]
    n_in = U.shape[1]
    for i in range(1, na + 1):
        src = t - i
        # Two loops rather than one over a chosen array: selecting between
        # arrays costs reference counting at every lag.
        if src >= seg_start:
            for k in range(n_out):
                phi[(i - 1) * n_out + k] = Yhat[src, k]
        else:
            for k in range(n_out):
                phi[(i - 1) * n_out + k] = Y[src, k]
    base = na * n_out
    for i in range(nb):
        for k in range(n_in):
            phi[base + i * n_in + k] = U[t - nk - i, k]


@njit(cache=True)
def _compress(S, by_rows):
    """The nonzeros of ``S`` by rows (``by_rows``) or by columns.

    Returns ``(ptr, idx, val)``: the nonzeros of row (column) ``r`` are
    ``val[ptr[r]:ptr[r + 1]]`` in columns (rows) ``idx[...]``, in increasing
    order. The lag transform is the identity or a band of differences, so
    most of ``S`` is zero; skipping those products changes no value (adding
    ``0 * x`` to a finite sum leaves it as it is).
    """
    n_outer, n_inner = S.shape if by_rows else (S.shape[1], S.shape[0])
    ptr = np.zeros(n_outer + 1, dtype=np.int64)
    idx = np.empty(S.size, dtype=np.int64)
    val = np.empty(S.size)
    q = 0
    for r in range(n_outer):
        for c in range(n_inner):
            x = S[r, c] if by_rows else S[c, r]
            if x != 0.0:
                idx[q] = c
                val[q] = x
                q += 1
        ptr[r + 1] = q
    return ptr, idx[:q], val[:q]


@njit(cache=True, inline="always")
def _sparse_product(ptr, idx, val, x, out, n):
    """``out[:n] = M[:n] @ x`` for ``M`` compressed by :func:`_compress`."""
    for r in range(n):
        s = 0.0
        for q in range(ptr[r], ptr[r + 1]):
            s += val[q] * x[idx[q]]
        out[r] = s


@njit(cache=True, inline="always")
def _step(
    w, sizes, act, bypass, Sr, Yhat, Y, U, t, seg_start, na, nb, nk, bound,
    phi, z, acts, out, keep, Z, A,
):  # fmt: skip
    """One step of the recurrence at row ``t``: False when it diverged.

    ``Sr`` is the lag transform by rows; ``phi``, ``z``, ``acts`` and
    ``out`` are scratch. The output goes to ``Yhat[t]`` and, with ``keep``
    and when they have rows, ``z`` and the activations to ``Z[t]`` and
    ``A[t]``.
    """
    _regressor(Yhat, Y, U, t, seg_start, na, nb, nk, phi)
    _sparse_product(Sr[0], Sr[1], Sr[2], phi, z, z.shape[0])
    mlp_forward(w, sizes, act, bypass, z, acts, out)
    if keep:
        keep_step(Z, A, t, z, acts)
    if out_of_range(out, bound, out.shape[0]):
        return False
    for k in range(out.shape[0]):
        Yhat[t, k] = out[k]
    return True


@njit(cache=True, inline="always")
def _sensitivity_rows(
    w, sizes, act, bypass, Sc, z, acts, J, r0, lag_rows, n_fed, v, gz, gphi, d1, d2
):  # fmt: skip
    """Rows ``J[r0:r0 + n_out]`` of one step by forward sensitivities (eq. 6).

    The direct derivative of the network plus, carried through the delay
    line, those of the ``n_fed`` fed-back outputs at rows ``lag_rows``
    (``Sc`` is the lag transform by columns).
    """
    n_out = v.shape[0]
    for j in range(n_out):
        gw = J[r0 + j]
        gw[:] = 0.0
        v[:] = 0.0
        v[j] = 1.0
        mlp_vjp(w, sizes, act, bypass, z, acts, v, gw, gz, d1, d2)
        # Only the fed-back lags' entries of d out / d phi are needed.
        _sparse_product(Sc[0], Sc[1], Sc[2], gz, gphi, n_fed * n_out)
        for i in range(n_fed):
            srow = lag_rows[i]
            for k in range(n_out):
                coef = gphi[i * n_out + k]
                if coef != 0.0:
                    for c in range(gw.shape[0]):
                        gw[c] += coef * J[srow + k, c]


@njit(cache=True, inline="always")
def _loop(
    w, sizes, act, bypass, S, Y, U, starts, h, na, nb, nk, seg_len, bound, jac,
    keep, Yhat, J, Z, A, JtJ, Jtr, syrk, diverged,
):  # fmt: skip
    # Inlined three times by tdl_run, with the constants NO_JAC and no kept
    # state (the solvers' plain runs), with no kept state (their Jacobian
    # runs) and in general, so that the loops the solvers run compile
    # without the branches they do not take.
    n_out = Y.shape[1]
    n_z = sizes[0]
    n_w = w.shape[0]
    width = np.max(sizes)
    Sr = _compress(S, True)
    Sc = _compress(S, False)
    phi = np.empty(S.shape[1])
    z = np.empty(n_z)
    acts = np.zeros(max(1, A.shape[1]))
    out = np.empty(n_out)
    v = np.zeros(n_out)
    gz = np.empty(n_z)
    gphi = np.empty(S.shape[1])
    d1 = np.empty(width)
    d2 = np.empty(width)
    Jb, rb = new_block(n_w, jac)
    m = 0
    ring = na + 1
    lag_rows = np.empty(max(1, na), dtype=np.int64)
    row_base = 0
    for s in range(starts.shape[0] - 1):
        a = starts[s]
        b = starts[s + 1]
        diverged[s] = -1
        copy_rows(Yhat, Y, a, a + h)
        seg_start = a + h
        for t in range(a + h, b):
            if t - seg_start == seg_len:
                seg_start = t
            if not _step(w, sizes, act, bypass, Sr, Yhat, Y, U, t, seg_start, na, nb,
                         nk, bound, phi, z, acts, out, keep, Z, A):  # fmt: skip
                diverged[s] = t - a - h
                fill_rows(Yhat, t, b, np.full(n_out, np.nan))
                break
            if jac == NO_JAC:
                continue
            local = t - a - h
            slot = local % ring  # of this step's rows in the ring (NORMAL)
            r0 = row_base + local * n_out if jac == FULL_JAC else slot * n_out
            # Rows of the fed-back outputs of this segment, newest first.
            n_fed = min(na, t - seg_start)
            for i in range(1, n_fed + 1):
                if jac == FULL_JAC:
                    lag_rows[i - 1] = r0 - i * n_out
                else:
                    lag_rows[i - 1] = (slot - i + (ring if slot < i else 0)) * n_out
            _sensitivity_rows(
                w, sizes, act, bypass, Sc, z, acts, J, r0, lag_rows, n_fed,
                v, gz, gphi, d1, d2,
            )  # fmt: skip
            if jac == NORMAL:
                for j in range(n_out):
                    m = add_row(J[r0 + j], out[j] - Y[t, j], Jb, rb, m, JtJ, Jtr, syrk)
        row_base += (b - a - h) * n_out
    finish(Jb, rb, m, JtJ, Jtr, syrk)


@njit(cache=True)
def tdl_run(
    w, sizes, act, bypass, S, Y, U, starts, h, na, nb, nk, seg_len, bound, jac,
    Yhat, J, Z, A, JtJ, Jtr, syrk, diverged,
):  # fmt: skip
    """Run the recurrence; optionally its Jacobian or normal equations.

    ``Yhat`` receives the outputs (history rows copied from ``Y``; NaN after
    a divergence). ``jac`` is a mode of :mod:`._recurrence`: with
    ``FULL_JAC``, ``J`` (``(n_modelled_rows * n_out, n_w)``) receives ``d
    yhat / d w`` by forward sensitivities; with ``NORMAL``, ``J`` is a ring
    of the last ``na + 1`` steps' rows (``((na + 1) * n_out, n_w)``) and
    ``JtJ``, ``Jtr`` receive the sums over all rows of ``J' J`` and ``J'
    (yhat - y)`` (``syrk`` is :data:`._recurrence.SYRK`). ``Z`` and ``A``
    (per-row network inputs and hidden activations) are kept for the adjoint
    pass when they have rows. ``diverged[s]`` is the first modelled index of
    sequence ``s`` whose output left ``[-bound, bound]``, or -1.
    """
    if jac == NO_JAC and Z.shape[0] == 0:
        _loop(w, sizes, act, bypass, S, Y, U, starts, h, na, nb, nk, seg_len, bound,
              NO_JAC, False, Yhat, J, Z, A, JtJ, Jtr, syrk, diverged)  # fmt: skip
    elif Z.shape[0] == 0:
        _loop(w, sizes, act, bypass, S, Y, U, starts, h, na, nb, nk, seg_len, bound,
              jac, False, Yhat, J, Z, A, JtJ, Jtr, syrk, diverged)  # fmt: skip
    else:
        _loop(w, sizes, act, bypass, S, Y, U, starts, h, na, nb, nk, seg_len, bound,
              jac, True, Yhat, J, Z, A, JtJ, Jtr, syrk, diverged)  # fmt: skip


@njit(cache=True)
def tdl_gradient(
    w,
    sizes,
    act,
    bypass,
    S,
    Y,
    starts,
    h,
    na,
    seg_len,
    Yhat,
    Z,
    A,
    grad,
):
    """Adjoint (backpropagation-through-time) gradient of ``0.5 ||Yhat - Y||^2``.

    Needs the ``Yhat``, ``Z`` and ``A`` of a completed :func:`tdl_run`
    without divergence; adds the gradient to ``grad``.
    """
    n_out = Y.shape[1]
    n_reg = S.shape[1]
    n_z = sizes[0]
    width = np.max(sizes)
    gz = np.empty(n_z)
    gphi = np.empty(n_reg)
    d1 = np.empty(width)
    d2 = np.empty(width)
    adj = np.empty((Y.shape[0], n_out))
    Sc = _compress(S, False)
    for s in range(starts.shape[0] - 1):
        a = starts[s]
        b = starts[s + 1]
        for t in range(a + h, b):
            for k in range(n_out):
                adj[t, k] = Yhat[t, k] - Y[t, k]
        for t in range(b - 1, a + h - 1, -1):
            seg_start = a + h + ((t - a - h) // seg_len) * seg_len
            mlp_vjp(w, sizes, act, bypass, Z[t], A[t], adj[t], grad, gz, d1, d2)
            _sparse_product(Sc[0], Sc[1], Sc[2], gz, gphi, na * n_out)
            for i in range(1, na + 1):
                src = t - i
                if src < seg_start:
                    break
                for k in range(n_out):
                    adj[src, k] += gphi[(i - 1) * n_out + k]


@njit(cache=True)
def tdl_predict_horizon(
    w,
    sizes,
    act,
    bypass,
    S,
    Y,
    U,
    starts,
    h,
    na,
    nb,
    nk,
    horizon,
    Yhat,
):
    """Sliding ``horizon``-step-ahead predictor.

    Each modelled ``Yhat[t]`` is the network run from measured outputs up to
    ``t - horizon`` (history rows count as measured); no value sees a later
    measurement.
    """
    n_out = Y.shape[1]
    n_reg = S.shape[1]
    n_z = sizes[0]
    phi = np.empty(n_reg)
    z = np.empty(n_z)
    acts = np.empty(max(1, np.sum(sizes[1:-1])))
    out = np.empty(n_out)
    work = np.empty_like(Y)
    Sr = _compress(S, True)
    for s in range(starts.shape[0] - 1):
        a = starts[s]
        b = starts[s + 1]
        for t in range(a, a + h):
            for k in range(n_out):
                Yhat[t, k] = Y[t, k]
        for t in range(a + h, b):
            first = max(t - horizon + 1, a + h)
            for tt in range(first, t + 1):
                _regressor(work, Y, U, tt, first, na, nb, nk, phi)
                _sparse_product(Sr[0], Sr[1], Sr[2], phi, z, n_z)
                mlp_forward(w, sizes, act, bypass, z, acts, out)
                for k in range(n_out):
                    work[tt, k] = out[k]
            for k in range(n_out):
                Yhat[t, k] = work[t, k]
