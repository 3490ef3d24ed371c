"""Tests of sysid_nn.metrics: error measures, eq. 19-20 and scorers."""

from __future__ import annotations

import pickle
import warnings

import numpy as np
import pandas as pd
import pytest
from scipy.signal import lfilter
from sklearn.base import BaseEstimator
from sklearn.metrics import r2_score
from sklearn.model_selection import GridSearchCV, KFold, cross_val_score

from sysid_nn.metrics import (
    ErrorStatistics,
    error_statistics,
    fit_percent,
    make_prediction_scorer,
    make_simulation_scorer,
    nrmse,
    r2,
    simulation_scorer,
)

# ----------------------------------------------------------------------------
# A first-order filter y(t) = a y(t-1) + b u(t-1) + w(t) as an estimator whose
# parameter selects the exact model, a wrong one or a diverging one.
# ----------------------------------------------------------------------------
A_TRUE, B_TRUE = 0.8, 1.0
MODELS = {
    "oracle": (A_TRUE, B_TRUE),
    "wrong": (0.3, 0.4),
    "diverging": (A_TRUE, B_TRUE),
}


class FilterModel(BaseEstimator):
    def __init__(self, model: str = "oracle"):
        self.model = model

    def fit(self, X, y):
        self.coef_ = MODELS[self.model]
        return self

    def _run(self, X, y, horizon):
        a, b = self.coef_
        u_prev = np.concatenate([[0.0], np.asarray(X, dtype=float)[:-1, 0]])
        if y is None:
            out = lfilter([1.0], [1.0, -a], b * u_prev)
        else:
            out = np.asarray(y, dtype=float)
            for _ in range(horizon):  # p_j(t) = a p_{j-1}(t-1) + b u(t-1)
                out = a * np.concatenate([[0.0], out[:-1]]) + b * u_prev
        if self.model == "diverging":
            out = out.copy()
            out[len(out) // 2 :] = np.nan
        return out

    def predict(self, X, y=None, *, horizon=1):
        if isinstance(X, list):
            ys = [None] * len(X) if y is None else y
            return [self._run(x, v, horizon) for x, v in zip(X, ys, strict=True)]
        return self._run(X, y, horizon)

    def simulate(self, X):
        return self.predict(X)


def make_sequences(n_sequences: int = 6, n_samples: int = 300, seed: int = 0):
    rng = np.random.default_rng(seed)
    X, y = [], []
    for _ in range(n_sequences):
        u = rng.standard_normal(n_samples)
        u_prev = np.concatenate([[0.0], u[:-1]])
        noise = 0.05 * rng.standard_normal(n_samples)
        X.append(u[:, None])
        y.append(lfilter([1.0], [1.0, -A_TRUE], B_TRUE * u_prev + noise))
    return X, y


# ----------------------------------------------------------------------------
# nrmse, fit_percent, r2
# ----------------------------------------------------------------------------
def test_nrmse_and_fit_percent_match_hand_computation():
    y = np.array([1.0, 3.0, 2.0, 6.0])
    yhat = np.array([1.5, 2.0, 2.0, 5.0])
    rmse = np.sqrt(np.mean((y - yhat) ** 2))
    assert nrmse(y, yhat) == pytest.approx(rmse / np.std(y))
    fit = 100 * (1 - np.linalg.norm(y - yhat) / np.linalg.norm(y - y.mean()))
    assert fit_percent(y, yhat) == pytest.approx(fit)
    assert r2(y, yhat) == pytest.approx(r2_score(y, yhat))
    assert nrmse(y, np.full(4, y.mean())) == pytest.approx(1.0)


def test_multioutput_and_pandas():
    rng = np.random.default_rng(1)
    y = rng.standard_normal((50, 2)) * [1.0, 10.0]
    yhat = y + rng.standard_normal((50, 2)) * [0.1, 5.0]
    raw = nrmse(y, yhat, multioutput="raw_values")
    assert raw.shape == (2,)
    expected = np.sqrt(np.mean((y - yhat) ** 2, axis=0)) / np.std(y, axis=0)
    np.testing.assert_allclose(raw, expected)
    assert nrmse(y, yhat) == pytest.approx(expected.mean())
    np.testing.assert_allclose(
        r2(y, yhat, multioutput="raw_values"),
        r2_score(y, yhat, multioutput="raw_values"),
    )
    frame = pd.DataFrame(y, columns=["x", "v"])
    assert nrmse(frame, yhat) == pytest.approx(nrmse(y, yhat))
    with pytest.raises(ValueError, match="multioutput"):
        nrmse(y, yhat, multioutput="variance_weighted")


def test_lists_are_pooled_over_all_samples():
    rng = np.random.default_rng(2)
    ys = [rng.standard_normal(n) for n in (30, 70)]
    preds = [v + 0.3 * rng.standard_normal(v.size) for v in ys]
    pooled = nrmse(np.concatenate(ys), np.concatenate(preds))
    assert nrmse(ys, preds) == pytest.approx(pooled)
    # Not the mean of per-sequence scores.
    per_sequence = np.mean([nrmse(a, b) for a, b in zip(ys, preds, strict=True)])
    assert nrmse(ys, preds) != pytest.approx(per_sequence)
    # A 1-D prediction matches a one-column target.
    assert nrmse([v[:, None] for v in ys], preds) == pytest.approx(pooled)


def test_nan_propagates():
    y = np.arange(10.0)
    yhat = y.copy()
    yhat[6:] = np.nan
    assert np.isnan(nrmse(y, yhat))
    assert np.isnan(fit_percent(y, yhat))
    assert np.isnan(r2(y, yhat))
    both = np.c_[y, y], np.c_[y, yhat]
    raw = nrmse(*both, multioutput="raw_values")
    assert raw[0] == 0.0 and np.isnan(raw[1])


@pytest.mark.parametrize(
    ("y_true", "y_pred", "match"),
    [
        (np.ones(5), np.ones(4), "y_true has 5 samples but y_pred has 4"),
        ([np.ones(5)], [np.ones(5), np.ones(5)], "y_true has 1 sequences"),
        (np.ones((5, 2)), np.ones((5, 3)), "y_true has 2 outputs but y_pred has 3"),
        (np.ones((5, 2, 2)), np.ones((5, 2, 2)), "y_true must be 1-D"),
        (np.ones(5), ["a"] * 5, "y_pred must be numeric"),
        (np.r_[1.0, np.inf], np.ones(2), "y_true contains infinite"),
        ([], [], "y_true has no samples"),
    ],
)
def test_bad_input(y_true, y_pred, match):
    with pytest.raises(ValueError, match=match):
        nrmse(y_true, y_pred)


# ----------------------------------------------------------------------------
# error_statistics (eq. 19-20)
# ----------------------------------------------------------------------------
def test_error_statistics_matches_equations_19_20():
    errors = np.array(
        [[1.0, 2.0, 3.0, 6.0], [0.0, -1.0, 1.0, 0.0], [2.0, 2.0, 2.0, 2.0]]
    )
    res = error_statistics(errors, dt=0.01)
    assert isinstance(res, ErrorStatistics)
    # By hand: realisation means 3, 0, 2; mean squared deviations 3.5, 0.5, 0.
    np.testing.assert_allclose(res.means, [3.0, 0.0, 2.0])
    assert res.mu == pytest.approx(5.0 / 3.0)
    assert res.sigma == pytest.approx(np.sqrt((3.5 + 0.5 + 0.0) / 3))
    np.testing.assert_allclose(res.stds, np.sqrt([3.5, 0.5, 0.0]))
    frame = res.to_frame()
    assert list(frame.columns) == ["mean", "std", "n_samples", "duration", "divergent"]
    assert frame["duration"].tolist() == pytest.approx([0.04] * 3)
    assert res.summary["n_realizations"] == 3
    # dt only scales durations: the time integrals are normalised by N dt.
    assert error_statistics(errors, dt=1.0).sigma == pytest.approx(res.sigma)


def test_error_statistics_lists_of_different_lengths_and_trapezoid():
    errors = [np.array([0.0, 2.0, 4.0]), np.array([1.0, 1.0])]
    rect = error_statistics(errors, dt=0.5)
    assert rect.mu == pytest.approx((2.0 + 1.0) / 2)
    assert rect.sigma == pytest.approx(np.sqrt((8.0 / 3.0 + 0.0) / 2))
    np.testing.assert_array_equal(rect.n_samples, [3, 2])
    trap = error_statistics(errors, dt=0.5, method="trapezoid")
    # Trapezoid: (dt/2 (0 + 2) + dt/2 (2 + 4)) / (2 dt) = 2.
    assert trap.means[0] == pytest.approx(2.0)
    # Deviations (-2, 0, 2): ((4 + 0)/2 + (0 + 4)/2) / 2 = 2.
    assert trap.stds[0] == pytest.approx(np.sqrt(2.0))
    assert trap.method == "trapezoid"


def test_error_statistics_counts_divergent_realisations():
    errors = [np.array([0.1, -0.1, 0.2]), np.array([0.0, np.nan, np.nan])]
    res = error_statistics(errors)
    assert res.n_divergent == 1
    assert res.divergent.tolist() == [False, True]
    assert np.isnan(res.mu) and np.isnan(res.sigma)
    assert np.isfinite(res.means[0])


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"errors": np.ones((2, 3)), "dt": 0.0}, "dt must be a positive"),
        ({"errors": np.ones((2, 3)), "method": "simpson"}, "method"),
        ({"errors": np.ones((2, 3, 1))}, "errors must be 2-D"),
        ({"errors": []}, "errors holds no realisation"),
        ({"errors": [np.ones(3), np.ones((2, 2))]}, r"errors\[1\]"),
    ],
)
def test_error_statistics_bad_input(kwargs, match):
    with pytest.raises(ValueError, match=match):
        error_statistics(**kwargs)


# ----------------------------------------------------------------------------
# Scorers
# ----------------------------------------------------------------------------
@pytest.mark.parametrize(
    "scoring",
    [
        simulation_scorer,
        make_simulation_scorer("r2"),
        make_simulation_scorer("fit_percent"),
        make_prediction_scorer(horizon=1),
        make_prediction_scorer(horizon=5, metric="r2"),
    ],
    ids=repr,
)
def test_scorers_rank_oracle_first_in_grid_search(scoring):
    X, y = make_sequences()
    search = GridSearchCV(
        FilterModel(), {"model": ["wrong", "oracle"]}, scoring=scoring, cv=KFold(3)
    ).fit(X, y)
    assert search.best_params_ == {"model": "oracle"}
    scores = search.cv_results_["mean_test_score"]
    assert scores[1] > scores[0]


def test_scorer_values_are_greater_is_better():
    X, y = make_sequences(2)
    oracle = FilterModel("oracle").fit(X, y)
    expected = nrmse(y, oracle.simulate(X))
    assert simulation_scorer(oracle, X, y) == pytest.approx(-expected)
    assert 0 < expected < 0.2
    pred = make_prediction_scorer(horizon=2, metric="fit_percent")
    assert pred(oracle, X[0], y[0]) == pytest.approx(
        fit_percent(y[0], oracle.predict(X[0], y[0], horizon=2))
    )
    # cross_val_score passes lists through the scorer as well.
    scores = cross_val_score(FilterModel(), X * 2, y * 2, cv=KFold(2), scoring=pred)
    assert scores.shape == (2,)
    assert repr(pred) == "make_prediction_scorer(horizon=2, metric='fit_percent')"


def test_divergent_candidate_scores_last_without_crashing():
    X, y = make_sequences()
    grid = {"model": ["diverging", "wrong", "oracle"]}
    with warnings.catch_warnings():
        # GridSearchCV warns that some test scores are non-finite (-inf) and
        # numpy warns computing their standard deviation.
        warnings.filterwarnings("ignore", message=".*non-finite", category=UserWarning)
        warnings.filterwarnings(
            "ignore", message="invalid value", category=RuntimeWarning
        )
        search = GridSearchCV(
            FilterModel(), grid, scoring=simulation_scorer, cv=KFold(3)
        ).fit(X, y)
    results = search.cv_results_
    assert results["mean_test_score"][0] == -np.inf
    assert results["rank_test_score"].tolist() == [3, 2, 1]
    assert search.best_params_ == {"model": "oracle"}
    # A finite penalty keeps the ranking and avoids non-finite scores.
    penalised = make_simulation_scorer(divergence_score=-1e6)
    search = GridSearchCV(FilterModel(), grid, scoring=penalised, cv=KFold(3)).fit(X, y)
    assert search.cv_results_["mean_test_score"][0] == -1e6
    assert search.best_params_ == {"model": "oracle"}


def test_scorers_pickle_for_parallel_search():
    X, y = make_sequences(2)
    oracle = FilterModel("oracle").fit(X, y)
    scorer = make_prediction_scorer(horizon=3, metric="r2")
    clone = pickle.loads(pickle.dumps(scorer))
    assert clone(oracle, X, y) == scorer(oracle, X, y)


def test_scorer_bad_arguments():
    with pytest.raises(ValueError, match="metric must be one of"):
        make_simulation_scorer("mse")
    with pytest.raises(ValueError, match="horizon must be an integer >= 1"):
        make_prediction_scorer(horizon=0)
