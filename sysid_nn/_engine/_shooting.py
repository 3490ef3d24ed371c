"""Multiple shooting with fitted segment initial states, for noisy records.

The default simulation schedule starts with a one-step fit and restarts
every shooting segment from the measured outputs: both take measured
outputs as exact regressors. Under white measurement noise that biases the
fit (an errors-in-variables problem); at 100 samples per period the noise
swamps the outputs' second difference, where the dynamics show.

Here the initial outputs of every segment are parameters, fitted together
with the weights (Bock's multiple shooting, without continuity terms). The
loss is an output-error loss over the segments, which stays consistent under
white output noise, while the segments keep the landscape smoother than a
single free run.

:class:`_FreeStateObjective` gives the residuals and the normal equations in
the weights and the segment states. Its Levenberg-Marquardt step eliminates
the states segment by segment (a Schur complement), so a step costs
``O(S P^2 m)`` for ``S`` segments of ``m`` state components and ``P``
weights, and the kernels run on chunks of segments, so memory is bounded
by a chunk, not the record. The states' sensitivities come from finite
differences: segments are independent, so perturbing one state component of
every segment at once gives the whole block-diagonal state Jacobian in one
extra run per component.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sysid_nn._engine._solvers import _damping
from sysid_nn._engine._state_estimation import _segments
from sysid_nn._records._data import _FREE_RUN, _Data

#: Rows (times outputs) of one kernel call when forming the normal
#: equations: bounds the full Jacobian block held at once.
_CHUNK_ROWS = 2**15
#: Step of the finite differences of the segment states (standardised units).
_STATE_STEP = 1e-6


@dataclass
class _Segments:
    """The modelled rows of stacked sequences cut into independent segments.

    ``data`` stacks one sequence per segment whose ``h`` history rows are
    copies of the rows before the segment; ``first`` are the rows of
    ``data`` where each segment's modelled rows begin, ``origin`` the rows of
    the records where they began; ``chunks`` are ``(first segment, end
    segment)`` ranges of at most ``_CHUNK_ROWS`` rows.
    """

    data: object
    first: np.ndarray
    origin: np.ndarray
    chunks: list


def _segment(data, seg_len: int, n_out: int) -> _Segments:
    """Cut the modelled rows of ``data`` into segments of ``seg_len`` rows.

    A remainder shorter than half a segment joins the segment before it.
    """
    h, pieces = data.h, []
    for t, b in _segments(data.starts, h):
        while t < b:
            end = min(t + seg_len, b)
            if b - end < seg_len // 2:
                end = b
            pieces.append((t, end))
            t = end
    rows = np.concatenate([np.arange(t - h, end) for t, end in pieces])
    lengths = np.array([end - t + h for t, end in pieces])
    starts = np.concatenate([[0], np.cumsum(lengths)]).astype(np.int64)
    seg = _Data(Y=data.Y[rows].copy(), U=data.U[rows].copy(), starts=starts, h=h)
    chunks, lo = [], 0
    for s in range(1, len(pieces) + 1):
        if (starts[s] - starts[lo]) * n_out > _CHUNK_ROWS and s - 1 > lo:
            chunks.append((lo, s - 1))
            lo = s - 1
    chunks.append((lo, len(pieces)))
    origin = np.array([t for t, _ in pieces], dtype=np.int64)
    return _Segments(data=seg, first=starts[:-1] + h, origin=origin, chunks=chunks)


def _chunk(data, lo: int, hi: int):
    """Segments ``lo:hi`` of segmented ``data`` as their own stacked data."""
    a, b = data.starts[lo], data.starts[hi]
    return _Data(
        Y=data.Y[a:b], U=data.U[a:b], starts=data.starts[lo : hi + 1] - a, h=data.h
    )


class _FreeStateObjective:
    """Output-error loss over segments started from fitted initial outputs.

    The parameters are ``theta = [w, v]``: the weights, then the initial
    outputs of every segment (``n_state`` rows of all outputs, standardised,
    oldest last as in the history rows), started from ``start_data``'s
    values, a low-passed copy of the records for noisy ones. The penalty is
    that of :class:`sysid_nn._engine._solvers._Objective` on the weights (``alpha``,
    by default the estimator's ``alpha_``).
    """

    def __init__(
        self, est, data, seg_len, mask, n_res, n_state, start_data=None, alpha=None
    ):
        self.est, self.mask, self.seg = est, mask, seg_len
        self.p = data.Y.shape[1]
        self.segments = _segment(data, seg_len, self.p)
        self.n_state = n_state
        self.m = n_state * self.p
        self.n_seg = len(self.segments.first)
        self.n = float(n_res)
        self.alpha = est.alpha_ if alpha is None else alpha
        # The starting states: the rows before each segment in the records.
        Y = (data if start_data is None else start_data).Y
        origin = self.segments.origin
        self._v0 = np.stack([Y[origin - i] for i in range(1, n_state + 1)], axis=1)
        self.n_w = None
        self._chunks = [
            _chunk(self.segments.data, lo, hi) for lo, hi in self.segments.chunks
        ]

    # ---------------------------------------------------------- parameters
    def start(self, w):
        """``theta`` of the weights ``w`` and the starting segment states."""
        self.n_w = len(w)
        return np.concatenate([w, self._v0.ravel()])

    def weights(self, theta):
        return theta[: self.n_w]

    def track(self, tracker):
        """``tracker`` called with the weights of ``theta``."""
        return _WeightsTracker(tracker, self.n_w)

    def _place(self, theta):
        V = theta[self.n_w :].reshape(self.n_seg, self.n_state, self.p)
        Y, first = self.segments.data.Y, self.segments.first
        for i in range(1, self.n_state + 1):
            Y[first - i] = V[:, i - 1]

    def _chunk_run(self, w, chunk, want_jac):
        Yhat, J, diverged, _ = self.est._run(w, chunk, _FREE_RUN, want_jac, False)
        rows = chunk.modelled
        return Yhat[rows], chunk.Y[rows], J, (diverged >= 0).any()

    # ------------------------------------------------------------- values
    def residuals(self, theta):
        w = self.weights(theta)
        self._place(theta)
        parts = []
        for chunk in self._chunks:
            Yhat, Y, _, diverged = self._chunk_run(w, chunk, False)
            if diverged:  # the later chunks need not run
                r = np.full(int(self.n), np.inf)
                break
            parts.append((Yhat - Y).ravel())
        else:
            r = np.concatenate(parts) / np.sqrt(self.n)
        if self.alpha > 0:
            r = np.concatenate([r, np.sqrt(self.alpha / self.n) * w[self.mask]])
        return r

    def loss(self, theta):
        r = self.residuals(theta)
        return 0.5 * float(r @ r) if np.all(np.isfinite(r)) else np.inf

    def normal_equations(self, theta):
        """``((A_ww, B, D), g)``: the normal equations in block form.

        ``A_ww`` (``P x P``) of the weights, ``B`` (``S x P x m``) coupling
        each segment's states to the weights, ``D`` (``S x m x m``) the
        segments' own blocks; ``g`` the gradient, weights first.
        """
        w = self.weights(theta)
        self._place(theta)
        P, m, p = self.n_w, self.m, self.p
        A = np.zeros((P, P))
        B = np.zeros((self.n_seg, P, m))
        D = np.zeros((self.n_seg, m, m))
        g_w = np.zeros(P)
        g_v = np.zeros((self.n_seg, m))
        for (lo, hi), chunk in zip(self.segments.chunks, self._chunks, strict=True):
            Yhat, Y, J, _ = self._chunk_run(w, chunk, True)
            r = (Yhat - Y).ravel()
            Jv = self._state_jacobian(w, chunk, Yhat, hi - lo)
            A += J.T @ J
            g_w += J.T @ r
            bounds = (chunk.starts - chunk.h * np.arange(hi - lo + 1)) * p
            for s in range(hi - lo):
                a, b = bounds[s], bounds[s + 1]
                B[lo + s] = J[a:b].T @ Jv[a:b]
                D[lo + s] = Jv[a:b].T @ Jv[a:b]
                g_v[lo + s] = Jv[a:b].T @ r[a:b]
        A, B, D, g_w, g_v = (
            A / self.n,
            B / self.n,
            D / self.n,
            g_w / self.n,
            g_v / self.n,
        )
        if self.alpha > 0:
            idx = np.flatnonzero(self.mask)
            A[idx, idx] += self.alpha / self.n
            g_w[idx] += self.alpha / self.n * w[idx]
        return (A, B, D), np.concatenate([g_w, g_v.ravel()])

    def _state_jacobian(self, w, chunk, Yhat, n_seg):
        """``d yhat / d v`` of a chunk's rows (``(rows * p, m)``), by differences.

        Column ``(i, k)`` perturbs output ``k`` of history row ``i`` of every
        segment of the chunk at once: each segment only sees its own.
        """
        first = chunk.starts[:-1] + chunk.h
        Jv = np.empty((Yhat.size, self.m))
        for i in range(1, self.n_state + 1):
            for k in range(self.p):
                saved = chunk.Y[first - i, k].copy()
                step = _STATE_STEP * np.maximum(1.0, np.abs(saved))
                chunk.Y[first - i, k] = saved + step
                moved, _, _, _ = self._chunk_run(w, chunk, False)
                chunk.Y[first - i, k] = saved
                per_row = np.repeat(step, np.diff(chunk.starts) - chunk.h)
                Jv[:, (i - 1) * self.p + k] = (
                    (moved - Yhat) / per_row[:, None]
                ).ravel()
        return Jv

    # --------------------------------------------------------------- step
    def damped_step(self, A, g, mu):
        """Levenberg-Marquardt step with the segment states eliminated.

        The damped system ``(N + mu diag(d)) step = -g`` of the whole
        parameter vector, solved by the Schur complement of the
        block-diagonal state part; returns ``(step, d)``.
        """
        A_ww, B, D = A
        P = self.n_w
        d_all = _damping(
            np.concatenate([np.diag(A_ww), np.einsum("sii->si", D).ravel()])
        )
        d_w, d_v = d_all[:P], d_all[P:].reshape(self.n_seg, self.m)
        Dmu = D + mu * np.einsum("si,ij->sij", d_v, np.eye(self.m))
        g_w, g_v = g[:P], g[P:].reshape(self.n_seg, self.m)
        # Dmu^-1 [B', g_v] for every segment at once.
        rhs = np.concatenate([np.transpose(B, (0, 2, 1)), g_v[:, :, None]], axis=2)
        sol = np.linalg.solve(Dmu, rhs)
        reduced = A_ww + mu * np.diag(d_w) - np.einsum("spm,smq->pq", B, sol[:, :, :P])
        step_w = -np.linalg.solve(
            reduced, g_w - np.einsum("spm,sm->p", B, sol[:, :, P])
        )
        step_v = -(sol[:, :, P] + np.einsum("smp,p->sm", sol[:, :, :P], step_w))
        return np.concatenate([step_w, step_v.ravel()]), d_all


class _WeightsTracker:
    """A stage tracker fed the weights part of ``theta``."""

    def __init__(self, tracker, n_w: int):
        object.__setattr__(self, "_tracker", tracker)
        object.__setattr__(self, "_n_w", n_w)

    def __call__(self, theta) -> None:
        self._tracker(theta[: self._n_w])

    def __getattr__(self, name):
        return getattr(self._tracker, name)

    def __setattr__(self, name, value):
        setattr(self._tracker, name, value)
