"""Least-squares objective of a training stage and the solvers that minimise it.

A solver is called as ``solver(objective, w, iters, tol, tracker, stall)`` and
returns ``(w, n_evaluations, converged)``; ``tracker(w)`` sees the weights
after every accepted step and may raise :class:`_EarlyStop`; a tracker
with a ``note_loss`` method is also given the stage loss there. With ``stall``
set, Levenberg-Marquardt also ends the stage once its cost fell by less than
``_STALL_IMPROVEMENT`` (relative) over the last ``stall`` accepted steps.

Levenberg-Marquardt works on the Gauss-Newton normal equations ``J'J`` and
``J'r``, which the kernels accumulate while the recurrence runs: its memory
does not grow with the record length. The full ``N x P`` Jacobian stays
available (``_Objective(..., full_jacobian=True)``, ``_Objective.jacobian``)
for checks and for per-sample sensitivities.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from scipy.optimize import minimize

if TYPE_CHECKING:  # pragma: no cover
    from sysid_nn._records._data import _Data


#: Relative fall of a stage's cost over its last ``stall`` accepted steps
#: below which Levenberg-Marquardt ends the stage (see ``_solve_lm``).
_STALL_IMPROVEMENT = 1e-3


#: Levenberg-Marquardt ends a stage once its damping passes this: the step is
#: then below rounding of any weight.
_MAX_DAMPING = 1e16


class _EarlyStop(Exception):
    """Raised inside a solver callback to end a stage early."""


class _Objective:
    """Least-squares objective of one training stage (standardised units).

    ``0.5 * mean(r**2) + 0.5 * alpha / n_res * ||w_masked||**2``, where ``r``
    are the errors of the recurrence restarted every ``seg`` samples. With
    ``full_jacobian`` the normal equations are formed from the full Jacobian
    (memory ``O(N P)``) instead of being accumulated by the kernels.
    ``alpha`` replaces the estimator's penalty (a stage on part of the records
    scales it to keep the penalty relative to the whole record).
    """

    def __init__(
        self,
        est,
        data: _Data,
        seg: int,
        mask: np.ndarray,
        n_res: int,
        full_jacobian: bool = False,
        alpha: float | None = None,
    ):
        self.est, self.data, self.seg, self.mask = est, data, seg, mask
        self.rows = data.modelled
        self.root_n = np.sqrt(n_res)
        self.alpha = est.alpha_ if alpha is None else alpha
        self.root_alpha = np.sqrt(self.alpha)
        self.full_jacobian = full_jacobian
        self._cache_w = None
        self._cache_jac = False

    def _forward(self, w, want_jac):
        # A run with a Jacobian also serves a plain one; state for the adjoint
        # gradient is only kept by the plain runs the gradient solvers make.
        if (
            self._cache_w is not None
            and np.array_equal(w, self._cache_w)
            and (not want_jac or self._cache_jac == want_jac)
        ):
            return self._cache
        result = self.est._run(w, self.data, self.seg, want_jac, keep_state=False)
        self._cache_w, self._cache, self._cache_jac = w.copy(), result, want_jac
        return result

    def residuals(self, w):
        Yhat, _, diverged, _ = self._forward(w, False)
        r = (Yhat[self.rows] - self.data.Y[self.rows]).ravel() / self.root_n
        if (diverged >= 0).any():
            r = np.full_like(r, np.inf)
        if self.root_alpha > 0:
            r = np.concatenate([r, self.root_alpha / self.root_n * w[self.mask]])
        return r

    def jacobian(self, w):
        """Jacobian of :meth:`residuals`, penalty rows included (``O(N P)``)."""
        _, J, _, _ = self._forward(w, True)
        J = J / self.root_n
        if self.root_alpha > 0:
            P = np.zeros((int(self.mask.sum()), len(w)))
            P[np.arange(P.shape[0]), np.flatnonzero(self.mask)] = (
                self.root_alpha / self.root_n
            )
            J = np.vstack([J, P])
        return J

    def normal_equations(self, w):
        """``(J'J, J'r)`` of :meth:`residuals` and :meth:`jacobian` at ``w``.

        Accumulated by the kernels while the recurrence runs; the penalty
        rows add ``alpha / n_res`` to the diagonal of the penalised weights.
        """
        if self.full_jacobian:
            J, r = self.jacobian(w), self.residuals(w)
            return J.T @ J, J.T @ r
        _, (JtJ, Jtr), _, _ = self._forward(w, "normal")
        n = self.root_n**2
        JtJ, Jtr = JtJ / n, Jtr / n
        if self.root_alpha > 0:
            idx = np.flatnonzero(self.mask)
            JtJ[idx, idx] += self.alpha / n
            Jtr[idx] += self.alpha / n * w[idx]
        return JtJ, Jtr

    def start(self, w):
        """The solver's parameter vector of the weights ``w`` (the weights)."""
        return w

    def weights(self, theta):
        return theta

    def track(self, tracker):
        return tracker

    def loss(self, w):
        r = self.residuals(w)
        return 0.5 * float(r @ r) if np.all(np.isfinite(r)) else np.inf

    def loss_and_grad(self, w):
        Yhat, _, diverged, state = self.est._run(w, self.data, self.seg, False)
        if (diverged >= 0).any():
            return np.inf, np.zeros_like(w)
        r = (Yhat[self.rows] - self.data.Y[self.rows]).ravel()
        n = self.root_n**2
        grad = self.est._gradient(w, self.data, self.seg, state) / n
        loss = 0.5 * float(r @ r) / n
        if self.root_alpha > 0:
            wm = np.where(self.mask, w, 0.0)
            loss += 0.5 * self.alpha / n * float(wm @ wm)
            grad += self.alpha / n * wm
        return loss, grad


def _solve_lm(objective, w, iters, tol, tracker, stall=None):
    """Levenberg-Marquardt with the exact recurrent Jacobian.

    Marquardt's scale-invariant damping ``mu * diag(J'J)`` and Nielsen's
    update of ``mu``. The normal equations are solved directly: the problems
    here have many residuals and few weights, where ``J'J`` costs a fraction
    of the SVD a general trust-region solver takes, and ``objective`` forms
    them without holding ``J``. A step whose run diverges has infinite cost
    and is rejected like any other bad step. The tracker sees the weights
    after every accepted step. With ``stall`` set, the stage ends (converged)
    once the cost fell by less than ``_STALL_IMPROVEMENT`` of itself over the
    last ``stall`` accepted steps. The step-norm test ends a stage
    only after an accepted step: where ``J'J`` is huge the first undamped
    step can be below ``tol * |w|`` although the cost still falls along it.
    Returns ``(w, n_evaluations, converged)``.
    """
    r = objective.residuals(w)
    cost = 0.5 * float(r @ r)
    A, g = objective.normal_equations(w)
    mu, nu = 1e-3, 2.0
    tracker.stopped = False
    note_loss = getattr(tracker, "note_loss", None)
    n_eval = 0
    costs = [cost]  # after each accepted step
    try:
        while n_eval < iters:
            if np.max(np.abs(g)) <= tol * max(1.0, cost) or mu > _MAX_DAMPING:
                # (Past that damping no step lowers the cost to rounding, and
                # mu would overflow into NaN steps.)
                return w, n_eval, True
            try:
                # Objectives with block-structured normal equations solve
                # their own damped system.
                step, d = getattr(objective, "damped_step", _damped_step)(A, g, mu)
            except np.linalg.LinAlgError:
                mu, nu = mu * nu, nu * 2.0
                n_eval += 1
                continue
            if len(costs) > 1 and np.linalg.norm(step) <= tol * (
                np.linalg.norm(w) + tol
            ):
                return w, n_eval, True
            w_new = w + step
            r_new = objective.residuals(w_new)
            n_eval += 1
            cost_new = (
                0.5 * float(r_new @ r_new) if np.all(np.isfinite(r_new)) else np.inf
            )
            predicted = 0.5 * float(step @ (mu * d * step - g))
            rho = (cost - cost_new) / predicted if predicted > 0 else -1.0
            if rho > 0:
                small = cost - cost_new <= tol * cost
                w, r, cost = w_new, r_new, cost_new
                A, g = objective.normal_equations(w)
                costs.append(cost)
                if note_loss is not None:
                    note_loss(cost)
                tracker(w)
                mu *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
                nu = 2.0
                if small or _stalled(costs, stall):
                    return w, n_eval, True
            else:
                mu, nu = mu * nu, nu * 2.0
    except _EarlyStop:
        return w, n_eval, True
    return w, n_eval, False


def _damped_step(A, g, mu):
    """The step ``-(A + mu diag(d))^-1 g``; returns ``(step, d)``."""
    d = _damping(np.diag(A))
    return -np.linalg.solve(A + mu * np.diag(d), g), d


def _damping(diag: np.ndarray) -> np.ndarray:
    """Marquardt's damping scale: ``diag(J'J)``, floored for flat directions."""
    return np.maximum(diag, 1e-12 * max(1.0, np.max(diag)))


def _stalled(costs, stall):
    """Whether the cost fell by less than its share over ``stall`` steps."""
    if stall is None or len(costs) <= stall:
        return False
    before = costs[-1 - stall]
    return before - costs[-1] <= _STALL_IMPROVEMENT * before


def _solve_minimize(method):
    # ``stall`` is a Levenberg-Marquardt rule; these solvers stop by ``tol``.
    def solve(objective, w, iters, tol, tracker, stall=None):
        count = {"n": 0, "x": w, "loss": np.inf}
        note_loss = getattr(tracker, "note_loss", None)

        def callback(xk):
            count["n"] += 1
            count["x"] = np.array(xk, copy=True)
            if note_loss is not None:
                # The last evaluation was at xk: the accepted point.
                note_loss(count["loss"])
            tracker(xk)

        tracker.stopped = False
        options = {"maxiter": iters}
        if method == "L-BFGS-B":
            options["gtol"] = tol
        # Scale the stage's loss to 1 at its start so that ``tol`` is relative:
        # started at the ARX fit, the loss can be 1e-10 in standardised units.
        scale = objective.loss(w)
        scale = scale if np.isfinite(scale) and scale > 0 else 1.0

        def scaled(x):
            loss, grad = objective.loss_and_grad(x)
            count["loss"] = loss
            return loss / scale, grad / scale

        try:
            res = minimize(
                scaled,
                w,
                jac=True,
                method=method,
                tol=tol,
                callback=callback,
                options=options,
            )
        except _EarlyStop:
            return count["x"], count["n"], True
        return res.x, int(res.nit), bool(res.success)

    return solve


_SOLVERS = {
    "lm": _solve_lm,
    "lbfgs": _solve_minimize("L-BFGS-B"),
    "slsqp": _solve_minimize("SLSQP"),
}
