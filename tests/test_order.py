"""Tests of the order chosen from the data (ISSM ``n_states="auto"``, TDL lags)."""

from __future__ import annotations

import warnings

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
import pytest
from scipy.signal import lfilter
from sklearn.exceptions import ConvergenceWarning
from sklearn.model_selection import GridSearchCV, KFold

from sysid_nn import HystereticOscillator, ISSMRegressor, ShearBuilding, TDLRegressor
from sysid_nn._engine._issm_start import lags_per_output, order_lags
from sysid_nn._engine._order import (
    ORDER_FLOOR,
    ORDER_TOLERANCE,
    SAMPLES_PER_WEIGHT,
    SHORT_RECORD_TOLERANCE,
    _n_weights,
    short_record_cap,
)
from sysid_nn.plotting import plot_order_selection

# Short training budgets: the order, not the fit, is under test.
pytestmark = [
    pytest.mark.filterwarnings("ignore::sklearn.exceptions.ConvergenceWarning"),
    # The short-record rule's warning is under test in its own tests.
    pytest.mark.filterwarnings("ignore:.*lowered the order the records show"),
]

#: Two resonances in cascade: a system of order 4.
A1, A2 = [1.0, -1.6, 0.9], [1.0, -1.2, 0.75]


def _fourth_order(n, seed, cubic=0.0):
    """Records of the fourth-order system, with a mild cubic between its blocks."""
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n)
    v = lfilter([0.0, 0.3], A1, u)
    v = v + cubic * v**3
    return u[:, None], lfilter([0.0, 0.4], A2, v)


def _linear_issm(**params):
    settings = {"n_init": 1, "max_iter": 20, "random_state": 0, **params}
    return ISSMRegressor(hidden_layer_sizes=(), **settings)


@pytest.mark.parametrize("cubic", [0.0, 0.05])
def test_auto_order_finds_the_systems_order(cubic):
    X, y = _fourth_order(5000, 0, cubic)
    Xv, yv = _fourth_order(1000, 1, cubic)
    model = _linear_issm().fit(X, y, X_val=Xv, y_val=yv)
    sel = model.order_selection_
    assert sel.linear_order == 4
    assert sel.gap_order == 4
    # Lower orders miss the dynamics; the chosen one is within the tolerance.
    scores = dict(zip(sel.orders, sel.scores, strict=True))
    assert scores[3] > 2 * scores[4]
    assert scores[4] <= (1 + ORDER_TOLERANCE) * np.min(sel.scores) + ORDER_FLOOR
    # The network doubles the linear order (see sysid_nn._engine._order).
    assert model.n_states_ == sel.n_states == 8
    assert np.all(np.diff(sel.singular_values) <= 0)


def test_auto_order_without_separate_validation_data():
    X, y = _fourth_order(4000, 2)
    model = _linear_issm().fit(X, y)
    assert model.order_selection_.linear_order == 4


def _grid_scores(estimator, name, values, Xs, ys):
    """4-fold grid search over one parameter: the search and its mean scores."""
    search = GridSearchCV(estimator, {name: values}, cv=KFold(4))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        search.fit(list(Xs), list(ys))
    results = search.cv_results_
    scores = zip(results[f"param_{name}"], results["mean_test_score"], strict=True)
    return search, dict(scores)


def test_grid_search_over_orders_agrees_with_auto():
    Xs, ys = zip(*(_fourth_order(800, seed) for seed in range(4)), strict=True)
    Xs, ys = list(Xs), list(ys)
    search, score = _grid_scores(
        _linear_issm(early_stopping=False), "n_states", [2, 3, 4, 5, "auto"], Xs, ys
    )
    # Orders below the system's are clearly worse; from 4 on they agree.
    assert score[3] < score[4] - 0.01
    assert score[4] > search.best_score_ - 1e-3
    assert score["auto"] > search.best_score_ - 1e-3
    auto = _linear_issm(early_stopping=False).fit(Xs, ys)
    assert auto.order_selection_.linear_order == 4


def test_unexplained_records_take_the_singular_value_gap():
    # An even non-linearity after a filter: no linear model explains it.
    rng = np.random.default_rng(6)
    u = rng.standard_normal((3000, 1))
    y = lfilter([0.0, 0.3], [1.0, -1.2, 0.5], u[:, 0]) ** 2
    model = _linear_issm(max_iter=200).fit(u, y)
    sel = model.order_selection_
    assert not np.min(sel.scores) <= sel.reliable
    assert sel.n_states == max(sel.gap_order, 3)


def test_short_records_lower_the_order():
    # The lowered order still holds the system's four: its linear model
    # validates as well, so it is kept, and the user is told.
    X, y = _fourth_order(5000, 0)
    long = _linear_issm().fit(X, y, X_val=X[:1000], y_val=y[:1000])
    with pytest.warns(UserWarning, match="lowered the order the records show"):
        short = _linear_issm().fit(X[:2000], y[:2000], X_val=X[:1000], y_val=y[:1000])
    assert (
        long.order_selection_.linear_order == short.order_selection_.linear_order == 4
    )
    assert long.n_states_ == 8
    assert long.order_selection_.short_record_states is None
    # At most one weight per ten samples for the auto-sized network.
    sel = short.order_selection_
    n = short.n_states_
    assert 4 <= n < 8
    assert sel.evidence_states == 8 and sel.short_record_states == n
    assert SAMPLES_PER_WEIGHT * _n_weights(short, n) <= 2000
    assert SAMPLES_PER_WEIGHT * _n_weights(short, n + 1) > 2000
    evidence, lowered = sel.short_record_scores
    assert lowered <= (1 + SHORT_RECORD_TOLERANCE) * evidence + ORDER_FLOOR
    assert "validate within" in sel.reason


def _sixth_order(n, seed, noise=0.01):
    """Records of three lightly damped resonances in cascade (order 6)."""
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n)
    a = np.convolve(np.convolve(A1, A2), [1.0, -0.4, 0.85])
    y = lfilter([0.0, 0.2, 0.1], a, u)
    return u[:, None], y + noise * y.std() * rng.standard_normal(n)


def test_short_record_order_that_misses_the_dynamics_gives_way_to_one_that_holds_them():
    # 1500 samples allow the auto-sized network 4 states, the system has 6
    # (three resonances): the linear models up to 4 states validate far
    # worse, those up to 6 as well as the evidence's 12, so 6 are kept,
    # with a warning naming both orders.
    X, y = _sixth_order(1500, 0)
    Xv, yv = _sixth_order(1000, 1)
    with pytest.warns(UserWarning, match="from 12 to 6 states"):
        model = _linear_issm().fit(X, y, X_val=Xv, y_val=yv)
    sel = model.order_selection_
    assert not sel.short_record_fitted_start
    assert sel.linear_order == 6 and sel.evidence_states == 12
    assert sel.short_record_limit == 4
    assert model.n_states_ == sel.short_record_states == 6
    evidence, kept = sel.short_record_scores
    assert kept <= (1 + SHORT_RECORD_TOLERANCE) * evidence + ORDER_FLOOR
    # Every smaller candidate misses a mode.
    for n in range(sel.short_record_limit, 6):
        best = np.min(sel.scores[sel.orders <= n])
        assert best > (1 + SHORT_RECORD_TOLERANCE) * evidence + ORDER_FLOOR
    assert "(the fewest from 4 up)" in sel.reason
    fig = plot_order_selection(model)
    labels = fig.axes[1].get_legend_handles_labels()[1]
    assert labels[-1] == "short-record order 6 (kept)"
    plt.close(fig)


def test_evidence_order_stays_where_no_lower_order_validates_as_well():
    # The rule itself: candidates 5, 6 and 7 below the evidence's 8 (the
    # limit at 5), each order's linear model better than the last.
    class Network:
        n_outputs_ = 1

    orders = np.arange(1, 9)
    scores = np.array([1.0, 0.9, 0.8, 0.7, 0.6, 0.5, 0.4, 0.1])
    sel = short_record_cap(
        Network(), orders, scores, 8, lambda n: 100 * n, n_samples=5000
    )
    assert sel.n_states == sel.evidence_states == 8
    assert sel.short_record_limit == sel.short_record_states == 5
    np.testing.assert_array_equal(sel.short_record_scores, [0.1, 0.6])
    assert "the evidence's order is kept" in sel.reason
    # With the order 7 within the tolerance it is kept, the fewest passing.
    scores[6] = 0.12
    scores[5] = 0.125
    sel = short_record_cap(
        Network(), orders, scores, 8, lambda n: 100 * n, n_samples=5000
    )
    assert sel.n_states == sel.short_record_states == 6
    np.testing.assert_array_equal(sel.short_record_scores, [0.1, 0.125])
    # With the limit as the one candidate (the TDL's lags) the evidence stays.
    sel = short_record_cap(
        Network(), orders, scores, 8, lambda n: 100 * n, n_samples=5000,
        between=False,
    )  # fmt: skip
    assert sel.n_states == 8 and sel.short_record_states == 5


def test_short_record_order_kept_where_the_evidence_gains_little():
    # A Wiener-Hammerstein-type record (filter, cubic, filter) of 1500
    # samples: the linear models up to the lowered order validate 14 %
    # worse than the evidence's 12 states, a loss a network's
    # non-linearity makes up for (its networks tested 2-4 times better
    # than those of 12 states), so the lowered order is kept.
    rng = np.random.default_rng(7)
    u = rng.standard_normal(1500)
    w = lfilter([0.0, 0.4, 0.2], [1.0, -1.2, 0.5], u)
    y = lfilter([0.0, 0.3], [1.0, -0.6], w + 0.3 * w**3)
    with pytest.warns(UserWarning, match="lowered the order the records show"):
        model = ISSMRegressor(n_init=1, max_iter=1, random_state=0).fit(u[:, None], y)
    sel = model.order_selection_
    # Its linear models forget their start within the tail: judged from rest.
    assert not sel.short_record_fitted_start
    assert model.n_states_ == sel.short_record_states < sel.evidence_states
    evidence, lowered = sel.short_record_scores
    assert (1 + ORDER_TOLERANCE) * evidence < lowered
    assert lowered <= (1 + SHORT_RECORD_TOLERANCE) * evidence


def _modes_in_motion(chain, n, lead=500, seed=0):
    """Three modes of 1 % damping (a displacement), cut ``lead`` samples into
    the response: the record starts in motion."""
    b, a = chain((0.03, 0.08, 0.15), 0.01)
    u = np.random.default_rng(seed).standard_normal(n + lead)
    return u[lead:, None], lfilter(b, a, u)[lead:]


def test_short_record_orders_compared_from_fitted_starts_where_needed(modal_chain):
    # The modes outlast the 400-sample validation tail, which starts in
    # motion: from rest every order's linear model mostly shows its wrong
    # start (the limit's within 30 % of the evidence's); from states fitted
    # to the first samples every order below the three modes' 6 misses
    # modes, and 6 are kept.
    X, y = _modes_in_motion(modal_chain, 2000)
    model = ISSMRegressor(n_init=1, max_iter=1, random_state=0).fit(X, y)
    sel = model.order_selection_
    assert sel.short_record_fitted_start
    assert sel.short_record_limit < 6 < sel.evidence_states
    assert model.n_states_ == sel.short_record_states == 6
    from_rest = [
        np.min(sel.scores[sel.orders <= n])
        for n in (sel.evidence_states, sel.short_record_limit)
    ]
    assert from_rest[1] <= (1 + SHORT_RECORD_TOLERANCE) * from_rest[0]


def test_records_too_short_for_the_projection_keep_p_plus_2():
    X, y = _fourth_order(12, 7)
    model = _linear_issm(early_stopping=False).fit(X, y)
    assert model.n_states_ == 3
    assert model.order_selection_.linear_order is None
    assert len(model.order_selection_.scores) == 0


def test_given_order_leaves_no_selection_behind():
    X, y = _fourth_order(1500, 3)
    model = _linear_issm().fit(X, y)
    assert hasattr(model, "order_selection_")
    model.set_params(n_states=2).fit(X, y)
    assert not hasattr(model, "order_selection_")
    assert model.n_states_ == 2


def test_auto_width_and_segment_starts_follow_the_order():
    X, y = _fourth_order(6000, 0)
    model = ISSMRegressor(n_init=1, max_iter=2, random_state=0).fit(X, y)
    n = model.n_states_
    assert n == model.order_selection_.n_states > 5
    # Three hidden units per unmeasured state; segments from the filter.
    assert model._sizes_[1:-1].tolist() == [3 * (n - 1)]
    assert model.shooting_ == "filter"
    few = ISSMRegressor(n_states=3, n_init=1, max_iter=2, random_state=0).fit(X, y)
    assert few._sizes_[1:-1].tolist() == [7]
    assert few.shooting_ == "measured"


def test_plot_order_selection_marks_the_choice():
    X, y = _fourth_order(1500, 5)
    model = _linear_issm(max_iter=200).fit(X, y)
    fig = plot_order_selection(model)
    top, bottom = fig.axes
    assert top.get_yscale() == "log"
    labels = [line.get_label() for line in bottom.get_lines()]
    n = model.order_selection_.n_states
    assert "linear order 4" in labels and f"n_states {n}" in labels
    plt.close(fig)
    with pytest.raises(ValueError, match="no order selection"):
        plot_order_selection(model.set_params(n_states=4, max_iter=200).fit(X, y))


@pytest.mark.parametrize("n_storeys", [3, 5])
def test_auto_order_of_a_shear_building_is_its_true_order(n_storeys):
    # Every floor's acceleration measured: 2 n linear states, and one
    # hysteretic state per storey that the network adds.
    building = ShearBuilding(n_storeys=n_storeys)
    rec = building.generate(4, random_state=0, outputs="acceleration")
    X = [g[:, None] for g in rec.ground_acceleration]
    y = list(rec.acceleration)
    model = _linear_issm(max_iter=1).fit(X[:3], y[:3], X_val=X[3:], y_val=y[3:])
    sel = model.order_selection_
    assert sel.n_outputs == n_storeys
    assert sel.gap_order == sel.linear_order == building.modal_properties().linear_order
    assert model.n_states_ == sel.n_states == 3 * n_storeys


# --------------------------------------------------------------------------
# The TDL's lags (output_lags="auto", input_lags="auto")
# --------------------------------------------------------------------------
def _second_order(n, seed):
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n)
    return u[:, None], lfilter([0.0, 0.3], A1, u)


def _linear_tdl(**params):
    settings = {"n_init": 1, "max_iter": 20, "random_state": 0, **params}
    return TDLRegressor(hidden_layer_sizes=(), **settings)


def test_auto_lags_grow_with_the_systems_order():
    # The ISSM's rule: 2 L states for one output, one lag per state.
    lags = {}
    for order, records in ((2, _second_order), (4, _fourth_order)):
        X, y = records(5000, 0)
        Xv, yv = records(1000, 1)
        model = _linear_tdl().fit(X, y, X_val=Xv, y_val=yv)
        sel = model.order_selection_
        assert sel.linear_order == order
        assert sel.n_states == 2 * order
        assert model.output_lags_ == model.input_lags_ == 2 * order
        lags[order] = model.output_lags_
    assert lags[2] < lags[4]


@pytest.mark.parametrize("outputs", [("displacement",), ("displacement", "velocity")])
def test_auto_lags_of_the_oscillator_are_the_former_default(outputs):
    # Displacement alone: three states, three lags. With velocity too, four
    # states over two outputs would be 2 lags each; the floor of 3 keeps
    # the lags the oscillator needs.
    rec = HystereticOscillator().generate(3, n_samples=2000, random_state=2024)
    X = [f[:, None] for f in rec.excitation]
    y = [np.column_stack([rec[name][i] for name in outputs]) for i in range(3)]
    model = TDLRegressor(n_init=1, max_iter=2, random_state=0)
    model.fit(X[:1], y[:1], X_val=X[1:], y_val=y[1:])
    p = len(outputs)
    n = model.order_selection_.n_states
    assert n == p + 2
    assert lags_per_output(n, p) == 4 - p
    assert model.output_lags_ == model.input_lags_ == order_lags(n, p) == 3
    assert model._sizes_.tolist() == [3 * (p + 1), 9, p]


@pytest.mark.filterwarnings("ignore:The linear model of:UserWarning")
def test_fitted_lags_are_the_models_lags():
    # The fourth-order system reads further back (8 lags) than the
    # provisional lags the records are checked with.
    X, y = _fourth_order(3000, 0, cubic=0.05)
    params = {"hidden_layer_sizes": (4,), "n_init": 1, "max_iter": 3, "random_state": 0}
    auto = TDLRegressor(**params).fit(X, y)
    assert auto.output_lags_ == auto.input_lags_ == 8
    given = TDLRegressor(output_lags=8, input_lags=8, **params).fit(X, y)
    assert not hasattr(given, "order_selection_")
    np.testing.assert_array_equal(auto.coefs_, given.coefs_)
    np.testing.assert_array_equal(auto.simulate(X[:500]), given.simulate(X[:500]))
    # The initial outputs of a continued run are the chosen lags' worth.
    with pytest.raises(ValueError, match=r"\(8, 1\)"):
        auto.simulate(X[:100], initial_outputs=np.zeros((3, 1)))


def test_auto_lags_mix_with_given_ones():
    X, y = _fourth_order(3000, 2)
    model = _linear_tdl(output_lags=2).fit(X, y)
    n = model.order_selection_.n_states
    assert (
        (model.output_lags_, model.input_lags_) == (2, lags_per_output(n, 1)) == (2, 8)
    )
    model = _linear_tdl(input_lags=1).fit(X, y)
    assert (model.output_lags_, model.input_lags_) == (8, 1)
    assert model.get_params()["output_lags"] == "auto"
    model.set_params(output_lags=4).fit(X, y)
    assert not hasattr(model, "order_selection_")
    assert (model.output_lags_, model.input_lags_) == (4, 1)


@pytest.mark.filterwarnings("ignore:The linear model of:UserWarning")
def test_short_records_lower_the_tdl_lags():
    # At most one weight of the TDL network per ten samples.
    X, y = _fourth_order(5000, 0)
    Xv, yv = X[:1000], y[:1000]
    long = TDLRegressor(n_init=1, max_iter=1, random_state=0).fit(
        X, y, X_val=Xv, y_val=yv
    )
    short = TDLRegressor(n_init=1, max_iter=1, random_state=0).fit(
        X[:1200], y[:1200], X_val=Xv, y_val=yv
    )
    assert long.output_lags_ == 8
    n = short.order_selection_.n_states
    assert 3 <= n < 8 and short.output_lags_ == n
    assert SAMPLES_PER_WEIGHT * short._weights_at_order(n) <= 1200
    assert SAMPLES_PER_WEIGHT * short._weights_at_order(n + 1) > 1200
    assert short._weights_at_order(n) == len(short.coefs_)


def test_tdl_lags_are_the_short_record_limit_or_the_evidence():
    # The TDL's candidates are its limit and the evidence's order only:
    # 1000 samples allow 4 lags, which miss a mode of the six, so the
    # evidence's 12 stay although 6 would validate as well (with lags
    # between the two its linear model tested worse on a chain in motion).
    X, y = _sixth_order(1000, 0)
    Xv, yv = _sixth_order(1000, 1)
    model = TDLRegressor(n_init=1, max_iter=1, random_state=0).fit(
        X, y, X_val=Xv, y_val=yv
    )
    sel = model.order_selection_
    assert sel.short_record_limit == sel.short_record_states == 4
    assert model.output_lags_ == sel.evidence_states == 12
    assert np.min(sel.scores[sel.orders <= 6]) <= 1.01 * np.min(sel.scores)
    assert "the linear models of up to 4 states validate worse" in sel.reason


def test_grid_search_over_given_lags_beside_auto():
    Xs, ys = zip(*(_fourth_order(800, seed) for seed in range(4)), strict=True)
    search, score = _grid_scores(
        _linear_tdl(early_stopping=False), "output_lags", [2, 8, "auto"], Xs, ys
    )
    assert score[2] < score[8] - 0.01
    assert score["auto"] > search.best_score_ - 1e-3
    assert search.best_estimator_.input_lags_ == 8


def test_plot_order_selection_of_a_tdl():
    X, y = _fourth_order(1500, 5)
    model = _linear_tdl(max_iter=5).fit(X, y)
    fig = plot_order_selection(model)
    labels = [line.get_label() for line in fig.axes[1].get_lines()]
    assert f"n_states {model.order_selection_.n_states}" in labels
    plt.close(fig)


@pytest.mark.filterwarnings("ignore:The linear model of:UserWarning")
def test_auto_width_of_the_tdl_follows_its_lags():
    X, y = _fourth_order(6500, 0)
    model = TDLRegressor(hidden_layer_sizes="auto", n_init=1, max_iter=1)
    model.fit(X, y)
    # Three units per fed-back output value; the order's weights counted so.
    assert model.output_lags_ == 8
    assert model._sizes_.tolist() == [16, 24, 1]
    assert model._weights_at_order(model.order_selection_.n_states) == len(model.coefs_)
    few = model.set_params(output_lags=3, input_lags=3).fit(X, y)
    assert few._sizes_.tolist() == [6, 9, 1]
