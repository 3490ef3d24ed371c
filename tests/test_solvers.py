"""Tests of the stage objective and the solvers (normal equations, LM)."""

from __future__ import annotations

import tracemalloc
import warnings
from unittest import mock

import numpy as np
import pytest
from scipy.signal import lfilter
from sklearn.exceptions import ConvergenceWarning

from sysid_nn import ISSMRegressor, TDLRegressor, _selection
from sysid_nn._engine._innovation import RestrictedObjective
from sysid_nn._engine._solvers import _STALL_IMPROVEMENT, _Objective, _solve_lm
from sysid_nn._records._data import _FREE_RUN


def _fitted(kind, n_outputs=1, length=300, n_seq=2, **params):
    """A briefly fitted estimator, perturbed weights and its training data."""
    rng = np.random.default_rng(n_outputs)
    Xs = [rng.standard_normal((length, 2)) for _ in range(n_seq)]
    # Stable first-order responses with a little noise.
    ys = [
        lfilter([0.3], [1.0, -0.8], X[:, :1] + 0.3 * X[:, 1:] ** 2, axis=0)
        @ np.ones((1, n_outputs))
        + 0.05 * rng.standard_normal((length, n_outputs))
        for X in Xs
    ]
    if kind == "tdl":
        # The kernels' normal equations on the measured-start structure.
        defaults = dict(output_lags=3, input_lags=2, hidden_layer_sizes=(4,))
        defaults.update(shooting="measured")
        cls = TDLRegressor
    else:
        defaults = dict(n_states=3, hidden_layer_sizes=(4,))
        cls = ISSMRegressor
    defaults.update(n_init=1, max_iter=1, early_stopping=False, random_state=0)
    defaults.update(params)
    # Trained network weights: on these records selection may return the
    # linear model.
    with (
        warnings.catch_warnings(),
        mock.patch.object(_selection, "linear_candidate", return_value=None),
    ):
        warnings.simplefilter("ignore", ConvergenceWarning)
        warnings.filterwarnings(
            "ignore", "A linear one-step model leaves a white misfit", UserWarning
        )
        est = cls(**defaults).fit(Xs, ys)
    w = est.coefs_ + 0.05 * rng.standard_normal(len(est.coefs_))
    return est, est._stack(Xs, ys), w


def _objective(est, data, seg, full=False):
    n_res = len(data.modelled) * est.n_outputs_
    return _Objective(est, data, seg, est._penalty_mask(), n_res, full_jacobian=full)


CASES = [
    ("tdl", 1, {}),
    ("tdl", 2, {"activation": "logistic", "alpha": 1e-2}),
    ("tdl", 1, {"hidden_layer_sizes": (3, 2), "linear_bypass": False}),
    ("issm", 1, {}),
    ("issm", 2, {"activation": "logistic", "alpha": 1e-2}),
]


@pytest.mark.parametrize(("kind", "n_outputs", "params"), CASES)
@pytest.mark.parametrize("seg", [1, 7, _FREE_RUN])
def test_accumulated_normal_equations_equal_full_jacobian(kind, n_outputs, params, seg):
    # 2 x 300 rows per output: several blocks of the accumulation, one partial.
    est, data, w = _fitted(kind, n_outputs, **params)
    objective = _objective(est, data, seg)
    assert (est._run(w, data, seg, False)[2] < 0).all()
    J, r = objective.jacobian(w), objective.residuals(w)
    JtJ, Jtr = objective.normal_equations(w)
    assert J.shape[0] > 512
    scale = np.abs(J.T @ J).max()
    np.testing.assert_allclose(JtJ, J.T @ J, rtol=1e-10, atol=1e-12 * scale)
    np.testing.assert_allclose(Jtr, J.T @ r, rtol=1e-10, atol=1e-12 * scale)
    # The plain run the normal equations come with is the plain run.
    Yhat = est._run(w, data, seg, False)[0]
    np.testing.assert_array_equal(est._run(w, data, seg, "normal")[0], Yhat)


class _Recorder:
    """Tracker that records every accepted iterate."""

    stopped = False

    def __init__(self):
        self.iterates = []

    def __call__(self, w):
        self.iterates.append(w.copy())


@pytest.mark.parametrize(("kind", "seg"), [("tdl", 7), ("tdl", _FREE_RUN), ("issm", 1)])
def test_lm_iterates_equal_those_of_the_full_jacobian(kind, seg):
    est, data, w = _fitted(kind, 1, length=400, hidden_layer_sizes=(3,), alpha=1e-3)
    runs = []
    for full in (True, False):
        tracker = _Recorder()
        objective = _objective(est, data, seg, full)
        w_end, n_eval, converged = _solve_lm(objective, w, 10, 1e-12, tracker)
        runs.append((tracker.iterates, n_eval, converged, objective.loss(w_end)))
    (steps_full, *end_full), (steps_acc, *end_acc) = runs
    assert len(steps_full) == len(steps_acc) >= 5
    assert end_full[:2] == end_acc[:2]
    # Each step solves with J'J (condition number about 1e8 here), which
    # amplifies the different summation order of the two ways of forming it
    # by roughly ten per step: early iterates agree to 1e-12 of the step,
    # later ones less, and the end point to the loss.
    for a, b in zip(steps_full[:3], steps_acc[:3], strict=True):
        assert np.abs(a - b).max() <= 1e-9 * np.abs(a - w).max()
    assert np.isclose(end_acc[2], end_full[2], rtol=1e-8)


class _Explicit:
    """Least-squares objective given by its residual and Jacobian functions."""

    def __init__(self, residuals, jacobian):
        self.residuals, self._jacobian = residuals, jacobian

    def normal_equations(self, w):
        J = self._jacobian(w)
        return J.T @ J, J.T @ self.residuals(w)


def test_step_test_does_not_end_a_stage_before_an_accepted_step():
    # Steep linear residuals: J'J is 1e12, the gradient far above tol, but the
    # exact Gauss-Newton step is below tol * |w|. The stage must take it
    # rather than end at iteration 0.
    J0 = 1e6 * np.eye(3)
    target = np.array([1.0, 2.0, 3.0]) + 1e-9
    objective = _Explicit(lambda w: J0 @ (w - target), lambda w: J0)
    w0 = np.array([1.0, 2.0, 3.0])
    tracker = _Recorder()
    w, n_eval, converged = _solve_lm(objective, w0, 20, 1e-8, tracker)
    assert n_eval >= 1 and len(tracker.iterates) >= 1
    np.testing.assert_allclose(w, target, rtol=0, atol=1e-12)
    r0, r1 = objective.residuals(w0), objective.residuals(w)
    assert r1 @ r1 < 1e-3 * (r0 @ r0)
    assert converged


def test_stage_ends_when_its_cost_stalls():
    # r = (w^2, 1): the cost falls towards 0.5 by ever smaller amounts, long
    # after its relative fall over three steps is below _STALL_IMPROVEMENT.
    objective = _Explicit(
        lambda w: np.array([w[0] ** 2, 1.0]),
        lambda w: np.array([[2.0 * w[0]], [0.0]]),
    )
    runs = {}
    for stall in (None, 3):
        tracker = _Recorder()
        _, _, converged = _solve_lm(
            objective, np.array([1.0]), 200, 1e-14, tracker, stall
        )
        costs = [
            0.5 * float(objective.residuals(v) @ objective.residuals(v))
            for v in tracker.iterates
        ]
        runs[stall] = (costs, converged)
    plain, stalled = runs[None][0], runs[3][0]
    assert runs[3][1] and runs[None][1]
    assert len(stalled) < len(plain)
    # It stops at the first step whose fall over the last three is too small.
    start = 0.5 * (1.0 + 1.0)
    costs = [start, *stalled]
    falls = [(costs[k - 3] - costs[k]) / costs[k - 3] for k in range(3, len(costs))]
    assert falls[-1] <= _STALL_IMPROVEMENT
    assert all(f > _STALL_IMPROVEMENT for f in falls[:-1])


def test_restricted_normal_equations_are_those_of_the_subset():
    est, data, w = _fitted("issm", 2, alpha=1e-2)
    objective = _objective(est, data, 1)
    idx = est._innovation_index()
    sub = RestrictedObjective(objective, w, idx)
    J = objective.jacobian(w)[:, idx]
    r = objective.residuals(w)
    JtJ, Jtr = sub.normal_equations(w[idx])
    np.testing.assert_allclose(JtJ, J.T @ J, rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(Jtr, J.T @ r, rtol=1e-10, atol=1e-14)


@pytest.mark.parametrize("kind", ["tdl", "issm"])
def test_normal_equations_memory_does_not_grow_with_the_jacobian(kind):
    peaks = []
    for length in (1000, 4000):
        est, data, w = _fitted(kind, 1, length=length, n_seq=1)
        objective = _objective(est, data, _FREE_RUN)
        objective.normal_equations(w)  # compiled and warm
        objective._cache_w = None
        tracemalloc.start()
        objective.normal_equations(w)
        peaks.append(tracemalloc.get_traced_memory()[1])
        tracemalloc.stop()
    growth = peaks[1] - peaks[0]
    full_jacobian = 3000 * len(w) * 8
    # Only per-row outputs (a few numbers per row) may grow, not N x P.
    assert growth < 3000 * 8 * 8 < full_jacobian / 3, (growth, full_jacobian)


def test_stage_ends_when_no_damped_step_lowers_the_cost():
    # Every trial step raises the cost: the damping grows until no step can
    # change the weights, and the stage ends there instead of overflowing
    # the damping into NaN steps.
    class Uphill:
        def residuals(self, w):
            return np.array([1.0 + float(np.abs(w - 1.0).sum() > 0)])

        def normal_equations(self, w):
            return np.eye(2), np.array([1.0, -1.0])

    class Tracker:
        stopped = False

        def __call__(self, w):
            raise AssertionError("no step may be accepted")

    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        w, n_eval, converged = _solve_lm(Uphill(), np.ones(2), 10_000, 1e-8, Tracker())
    np.testing.assert_array_equal(w, np.ones(2))
    assert converged and n_eval < 100
