"""The innovation gain of the ISSM and the stability of its one-step predictor.

After a simulation-focused fit the weights on the innovations ``E(t-1)`` (which
do not enter the free run) are refitted to the one-step loss and shrunk until
the one-step predictor (eq. 10) is stable; :class:`UnstablePredictorWarning`
says when it is not. The functions take the fitted ISSM.
"""

from __future__ import annotations

import warnings

import numpy as np

from sysid_nn._engine._solvers import _Objective, _solve_lm
from sysid_nn._exceptions import user_stacklevel
from sysid_nn._records._data import _Data

#: Solver iterations spent refitting the innovation weights after a
#: simulation-focused fit.
_INNOVATION_REFIT_ITERS = 40
#: Factors tried on the innovation weights, largest first, until the one-step
#: predictor is stable (0 makes it the free run, stable with the simulator).
_INNOVATION_SHRINKS = (1.0, 0.5, 0.25, 0.125, 0.0625, 0.0)
#: A more shrunk innovation gain is preferred while its one-step validation
#: loss stays within this factor of the best.
_INNOVATION_MARGIN = 1.2


class UnstablePredictorWarning(UserWarning):
    """The one-step predictor of a fitted ISSM is not stable.

    The innovation form ``Phi(t) - K(t) H`` of eq. 10 has spectral radius of
    at least one along the training trajectory (or the one-step predictor left
    the training range there): one-step and k-step predictions may drift away
    from the measurements instead of tracking them.

    Examples
    --------
    >>> from sysid_nn import UnstablePredictorWarning
    >>> issubclass(UnstablePredictorWarning, UserWarning)
    True
    """


class NoTracker:
    """Stands in for the validation tracker where no selection is wanted."""

    stopped = False

    def __call__(self, w) -> None:
        pass


class RestrictedObjective:
    """A stage objective seen through a subset ``idx`` of the weights."""

    def __init__(self, objective: _Objective, w: np.ndarray, idx: np.ndarray):
        self.objective, self.w, self.idx = objective, w.copy(), idx

    def _full(self, v):
        self.w[self.idx] = v
        return self.w

    def residuals(self, v):
        return self.objective.residuals(self._full(v))

    def normal_equations(self, v):
        # Those of the subset are the rows and columns of the whole problem's.
        JtJ, Jtr = self.objective.normal_equations(self._full(v))
        return JtJ[np.ix_(self.idx, self.idx)], Jtr[self.idx]

    def loss(self, v):
        return self.objective.loss(self._full(v))


def stabilise_predictor(est, train: _Data, val: _Data | None) -> None:
    """Refit the innovation gain (simulation focus) and check its stability.

    Sets ``coefs_`` and ``predictor_spectral_radius_``; warns with
    :class:`UnstablePredictorWarning` if the one-step predictor is unstable.
    """
    if est.focus == "simulation":
        est.coefs_ = refit_innovations(est, est.coefs_, train, val)
    rho = predictor_radius(est, est.coefs_, train)
    est.predictor_spectral_radius_ = rho
    if not rho < 1.0:
        warnings.warn(
            f"The one-step predictor of this {type(est).__name__} is not "
            f"stable: the innovation form Phi(t) - K(t) H has spectral radius "
            f"{rho:.4g} >= 1 along the training data. One-step and k-step "
            "predictions may drift from the measurements; use "
            'focus="prediction", linear_part=True or more training data.',
            UnstablePredictorWarning,
            stacklevel=user_stacklevel(),
        )


def substitution_gain(est, w: np.ndarray) -> np.ndarray:
    """Weights on ``E`` copied from those on the measured states.

    The network then sees ``x[:p] + e = y`` in place of the measured
    states: the one-step predictor becomes the model run on measured
    outputs, as in multiple shooting (``K = A H^T`` for the linear part).
    """
    w = w.copy()
    measured = est._input_columns(np.arange(est.n_outputs_))
    w[est._innovation_index()] = w[measured]
    return w


def refit_innovations(
    est, w: np.ndarray, train: _Data, val: _Data | None
) -> np.ndarray:
    """Refit the weights on ``E`` to the one-step loss.

    They do not enter the free run, which therefore stays unchanged. A
    version of the gain counts only if its one-step predictor also stays
    finite on the validation data, when there are any.
    """
    mask = est._penalty_mask()

    def one_step(data: _Data) -> _Objective:
        return _Objective(est, data, 1, mask, len(data.modelled) * est.n_outputs_)

    objective = one_step(train)
    idx = est._innovation_index()
    candidates = [substitution_gain(est, w), w]
    start = min(candidates, key=objective.loss)
    if np.isfinite(objective.loss(start)):
        sub = RestrictedObjective(objective, start, idx)
        v, _, _ = _solve_lm(
            sub, start[idx], _INNOVATION_REFIT_ITERS, est.tol, NoTracker()
        )
        refit = start.copy()
        refit[idx] = v
        candidates.insert(0, refit)
    # Selection keeps the one-step predictor stable: the innovation
    # weights of each candidate are shrunk towards zero (where the
    # predictor is the free run) in steps; a version counts if its
    # innovation form is stable along the training data and its one-step
    # predictor stays finite on the validation data. A refit to noisy
    # records can be stable on them and still diverge on others; dropping
    # the innovations altogether would leave the one-step predictor no
    # better than the free run.
    check = one_step(val) if val is not None else None
    stable = []
    for candidate in candidates:
        for shrink in _INNOVATION_SHRINKS:
            shrunk = candidate.copy()
            shrunk[idx] *= shrink
            if predictor_radius(est, shrunk, train) < 1.0 and (
                check is None or np.isfinite(check.loss(shrunk))
            ):
                stable.append((objective.loss(shrunk), shrink, shrunk))
    if not stable:
        return candidates[0]
    best = min(loss for loss, _, _ in stable)
    if not np.isfinite(best):
        return stable[0][2]
    # The most shrunk version within a margin of the best: a predictor at
    # the edge of stability on a few records diverges on others.
    near = [entry for entry in stable if entry[0] <= _INNOVATION_MARGIN * best]
    return min(near, key=lambda entry: (entry[1], entry[0]))[2]


def predictor_radius(est, w: np.ndarray, data: _Data) -> float:
    """Spectral radius of the mean ``Phi(t) - K(t) H`` of the one-step predictor."""
    X0 = est._initial_states(data)
    _, _, diverged, state = est._run_from(w, data, 1, False, X0, True)
    if (diverged >= 0).any():
        return np.inf
    n, m, p = est.n_states_, est.n_features_in_, est.n_outputs_
    D = state[3][data.modelled]
    M = D[:, :, :n].mean(axis=0)
    M[:, :p] -= D[:, :, n + m :].mean(axis=0)
    return float(np.max(np.abs(np.linalg.eigvals(M))))
