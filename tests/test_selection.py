"""Tests of model selection: the linear candidate, validation from rest,
bounded free runs."""

from __future__ import annotations

import warnings
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.signal import lfilter
from sklearn.exceptions import ConvergenceWarning

from sysid_nn import HystereticOscillator, ISSMRegressor, TDLRegressor
from sysid_nn.metrics import nrmse


@pytest.fixture(autouse=True)
def _quiet_convergence():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        # The estimated output noise (these records are noisy on purpose).
        warnings.filterwarnings("ignore", "The training outputs", UserWarning)
        yield


def _linear_record(seed, n=300, noise=0.1, poles=(-1.2, 0.5)):
    """A second-order linear system; noisy outputs and the clean ones."""
    rng = np.random.default_rng(seed)
    u = rng.standard_normal((n, 1))
    y = lfilter([0, 0.5, 0.2], [1, *poles], u[:, 0])
    return u, y + noise * y.std() * rng.standard_normal(n), y


def _run(w, loss, val_loss):
    """A training run with the given losses, judged by its validation loss."""
    from sysid_nn._engine._training import _Run

    return _Run(
        w=w,
        loss=loss,
        val_loss=val_loss,
        criterion=val_loss,
        n_iter=1,
        converged=True,
        history=[],
        best_stage=0,
    )


def _nrmse(model, X, y):
    return np.sqrt(np.mean((model.simulate(X) - y) ** 2)) / y.std()


@pytest.mark.parametrize(
    ("cls", "params", "seed"),
    [(TDLRegressor, dict(output_lags=2, input_lags=2), 6), (ISSMRegressor, {}, 22)],
)
def test_linear_model_is_returned_where_no_restart_beats_it(cls, params, seed):
    # Noisy records of a linear system: the networks' restarts fit the noise
    # and validate worse than the linear output-error model (measured; on
    # seeds 20-31 the linear model's refinement validated better on 3 (TDL)
    # and 5 (ISSM) of 12 by the validation's noise, at test errors 0.97-1.8
    # times the linear model's).
    records = (_linear_record(seed + k) for k in range(3))
    (X, y, _), (Xv, yv, _), (Xt, _, yt) = records
    common = dict(max_iter=30, random_state=0, **params)
    linear = cls(hidden_layer_sizes=(), n_init=1, **common).fit(
        X, y, X_val=Xv, y_val=yv
    )
    with pytest.warns(UserWarning, match="selected_ = 'linear'"):
        net = cls(n_init=2, **common).fit(X, y, X_val=Xv, y_val=yv)
    assert net.selected_ == "linear"
    assert net.linear_score_ >= net.restart_scores_.max()
    # The network computes the linear model exactly.
    np.testing.assert_allclose(net.simulate(Xt), linear.simulate(Xt), atol=1e-12)
    assert _nrmse(net, Xt, yt) == pytest.approx(_nrmse(linear, Xt, yt))


def test_issm_linear_candidate_comes_from_its_better_linear_start(monkeypatch):
    # The ISSM's restarts start from a subspace and an ARX model; on the
    # EMPS benchmark the linear model trained from the first diverged on
    # validation, from the second it did not. Both are tried; here the
    # first is made to diverge.
    from dataclasses import replace

    records = (_linear_record(21 + k) for k in range(2))
    (X, y, _), (Xv, yv, _) = records
    trained = []
    fit_one = ISSMRegressor._fit_one

    def spy(self, train, val, restart, stop):
        restart_, run = fit_one(self, train, val, restart, stop)
        if not self._hidden_layers():
            start = self._linear_starts[self._start_of(restart.k)][0]
            if start == "subspace":  # weights whose free run diverges
                run = replace(run, w=1e3 * run.w, criterion=np.inf, val_loss=np.inf)
            trained.append((restart.k, start, run.criterion))
        return restart_, run

    monkeypatch.setattr(ISSMRegressor, "_fit_one", spy)
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", "The linear model of", UserWarning)
        net = ISSMRegressor(n_init=2, max_iter=30, random_state=0).fit(
            X, y, X_val=Xv, y_val=yv
        )
    # Trained from each start; the starts as they are are no candidates of
    # a network's linear model (on the EMPS benchmark they moved the
    # networks' reference and their test median from 3.3 to 5.5 mm).
    assert [(k, start) for k, start, _ in trained] == [(0, "subspace"), (2, "arx")]
    # The records start at rest: no burn-in, the score is the training's.
    assert net.linear_score_ == pytest.approx(-trained[1][2], rel=1e-9)
    # The linear model is returned, or its refinement (which validated
    # better here); either reports the start it was trained from.
    assert net.selected_ == "linear" or net.best_restart_ == net.refined_restart_
    assert net.init_ == "arx"


def test_issm_linear_model_keeps_its_start_where_training_fits_worse(monkeypatch):
    # Fitted as a linear model, the ISSM has its subspace and ARX starts as
    # candidates as they are. Its trained fits are made to validate best
    # while fitting the training records worse than the starts: they lose
    # to the starts, of which the subspace one is made to validate better.
    (X, y, _), (Xv, yv, _) = (_linear_record(21 + k) for k in range(2))
    fit_one = ISSMRegressor._fit_one

    def made(self, train, val, restart, stop):
        restart_, run = fit_one(self, train, val, restart, stop)
        if run.history:  # trained
            return restart_, replace(run, loss=10 * run.loss + 1, criterion=0.0)
        if self._linear_starts[self._start_of(restart.k)][0] == "arx":
            return restart_, replace(run, criterion=run.criterion + 1.0)
        return restart_, run

    monkeypatch.setattr(ISSMRegressor, "_fit_one", made)
    model = ISSMRegressor(hidden_layer_sizes=(), n_init=2, max_iter=30).fit(
        X, y, X_val=Xv, y_val=yv
    )
    assert model.closed_form_restarts_ == [3, 4]  # after the three trained
    assert model.best_restart_ == 3
    assert model.init_ == "subspace"
    start = model._weights_at(model.linear_model_, np.random.RandomState(0))
    # The innovation gain is the fitted one's (zero: an output-error fit).
    start[model._innovation_index()] = model.coefs_[model._innovation_index()]
    np.testing.assert_array_equal(model.coefs_, start)
    assert model.training_history_[3] == []


@pytest.mark.parametrize(("ratio", "kept"), [(1.5, "subspace"), (3.0, "arx")])
def test_linear_fit_clearly_worse_on_training_is_no_candidate(
    monkeypatch, linear_candidates, ratio, kept
):
    # The linear model trained from the subspace start made to validate
    # better than the one from the ARX start while fitting the training
    # records ``ratio`` times worse: within twice, validation chooses it;
    # beyond, it is no candidate.
    from dataclasses import replace

    (X, y, _), (Xv, yv, _) = (_linear_record(21 + k) for k in range(2))
    fit_one = ISSMRegressor._fit_one

    def made(self, train, val, restart, stop):
        restart_, run = fit_one(self, train, val, restart, stop)
        if not self._hidden_layers():
            start = self._linear_starts[self._start_of(restart.k)][0]
            subspace = start == "subspace"
            loss, criterion = (ratio, 0.5) if subspace else (1.0, 1.0)
            run = replace(run, loss=0.01 * loss, criterion=criterion)
        return restart_, run

    monkeypatch.setattr(ISSMRegressor, "_fit_one", made)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        net = ISSMRegressor(n_init=2, max_iter=5, random_state=0)
        net.fit(X, y, X_val=Xv, y_val=yv)
    assert linear_candidates[0].k == {"subspace": 0, "arx": 2}[kept]


@pytest.mark.parametrize("cls", [TDLRegressor, ISSMRegressor])
def test_linear_model_is_refined_from_where_its_training_ended(cls):
    # The last run starts at the trained linear model (network output
    # silent) and runs the final stage only: its first validation loss is
    # the linear model's score, and it can only improve on it.
    (X, y, _), (Xv, yv, _) = (_linear_record(s) for s in (0, 1))
    y, yv = np.tanh(2 * y), np.tanh(2 * yv)
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", "The linear model of", UserWarning)
        net = cls(n_init=2, max_iter=30, random_state=0).fit(X, y, X_val=Xv, y_val=yv)
    k = net.refined_restart_
    assert k == net.n_restarts_ - 1 == len(net.training_history_) - 1
    (stage,) = net.training_history_[k]
    whole = max(net.training_history_[:k], key=len)  # a restart halving kept
    assert stage.segment == whole[-1].segment  # the free run
    assert stage.validation[0] == pytest.approx(-net.linear_score_, rel=1e-9)
    assert net.restart_scores_[k] >= net.linear_score_
    # A linear network has no linear model to refine.
    linear = cls(hidden_layer_sizes=(), n_init=2, max_iter=5, random_state=0)
    assert linear.fit(X, y, X_val=Xv, y_val=yv).refined_restart_ is None


def test_refinement_has_a_budget_of_several_last_stages():
    from sysid_nn._engine._training import _REFINE_BUDGET

    (X, y, _), (Xv, yv, _) = (_linear_record(s) for s in (0, 1))
    y, yv = np.tanh(2 * y), np.tanh(2 * yv)
    # tol=0: every stage runs to its budget.
    net = TDLRegressor(n_init=2, max_iter=3, tol=0.0, random_state=0)
    net.fit(X, y, X_val=Xv, y_val=yv)
    last = [history[-1].n_iter for history in net.training_history_]
    assert last[net.refined_restart_] == _REFINE_BUDGET * 3 > 3 >= max(last[:-1])


def test_refinement_reports_the_start_of_its_linear_model(monkeypatch):
    # Noisy records: the ISSM's restarts start from a subspace and an ARX
    # fit. The linear model trained from the ARX start is made to lose, so
    # the one refined is the subspace start's, and so is the returned start.
    from dataclasses import replace

    from sysid_nn._engine import _selection

    (X, y, _), (Xv, yv, _) = (_linear_record(21 + k) for k in range(2))
    fit_one = ISSMRegressor._fit_one

    def spy(self, train, val, restart, stop):
        restart_, run = fit_one(self, train, val, restart, stop)
        start = self._linear_starts[self._start_of(restart.k)][0]
        if not self._hidden_layers() and start == "arx":
            run = replace(run, criterion=np.inf, val_loss=np.inf)
        return restart_, run

    choose = _selection.choose

    def refinement_wins(
        est, train, val, runs, linear, closed_form=(), retry=False, refined=None
    ):
        _, _, bounded, excursions, cycling, checks, _ = choose(
            est, train, val, runs, linear, closed_form
        )
        return runs[-1], "restart", bounded, excursions, cycling, checks, None

    monkeypatch.setattr(ISSMRegressor, "_fit_one", spy)
    monkeypatch.setattr(_selection, "choose", refinement_wins)
    net = ISSMRegressor(n_init=2, max_iter=30, random_state=0)
    net.fit(X, y, X_val=Xv, y_val=yv)
    assert net.best_restart_ == net.refined_restart_ == 3
    assert net.init_ == "subspace"
    ref = ISSMRegressor(init="subspace", n_init=1, max_iter=1)
    ref.fit(X, y, X_val=Xv, y_val=yv)
    np.testing.assert_array_equal(net.linear_model_.A, ref.linear_model_.A)


def test_network_that_beats_the_linear_model_is_kept():
    (X, y, _), (Xv, yv, _) = (_linear_record(s, poles=(-1.2, 0.5)) for s in (0, 1))
    # A nonlinear system: the network wins.
    y, yv = np.tanh(2 * y), np.tanh(2 * yv)
    with warnings.catch_warnings():
        warnings.filterwarnings("error", "The linear model of", UserWarning)
        net = TDLRegressor(n_init=2, max_iter=30, random_state=0).fit(
            X, y, X_val=Xv, y_val=yv
        )
    assert net.selected_ == "restart"
    assert net.linear_score_ < net.restart_scores_.max()


def _replayed_choice(net, significant=2.0):
    """``(selected_, best_restart_)`` recomputed from the fitted evidence."""
    k_all = np.arange(net.n_restarts_)
    settling = k_all[~net.restart_self_oscillating_]
    # The bounded ones; where none, those that do not self-oscillate; else all.
    pool = k_all[net.restart_bounded_] if net.restart_bounded_.any() else settling
    pool = pool if pool.size else k_all
    if net.linear_loss_ is not None and net.best_validation_score_ is not None:
        tie = 1e-12 * (1.0 + net.linear_loss_)
        pool = pool[net.restart_losses_[pool] <= net.linear_loss_ + tie]
    if pool.size == 0:
        return "linear", None
    best = int(pool[np.argmax(net.restart_scores_[pool])])
    if net.refinement_advantage_ is not None:
        # The refinement, a candidate beating the linear model, against the
        # best restart: kept unless the restart is ahead beyond
        # ``significant`` standard errors.
        ref = net.refined_restart_
        assert ref in pool and best != ref
        assert net.restart_scores_[ref] > net.linear_score_
        if not net.refinement_advantage_ > significant:
            best = ref
    if net.linear_score_ is None or net.restart_scores_[best] > net.linear_score_:
        return "restart", best
    return "linear", None


def _no_self_oscillation(monkeypatch):
    """Every restart passes the self-oscillation check (the other checks alone)."""
    from sysid_nn._engine import _selection

    monkeypatch.setattr(
        _selection, "self_oscillating", lambda est, runs, train: [False] * len(runs)
    )


def test_the_choice_among_restarts_is_explained_by_fitted_attributes(monkeypatch):
    # Which restarts were bounded at twice the training amplitude, their
    # training losses and the linear model's: the choice follows from them.
    from sysid_nn._engine import _selection

    (X, y, _), (Xv, yv, _) = (_linear_record(s) for s in (0, 1))
    y, yv = np.tanh(2 * y), np.tanh(2 * yv)
    params = dict(n_init=3, max_iter=30, random_state=0)
    net = TDLRegressor(**params).fit(X, y, X_val=Xv, y_val=yv)
    assert net.restart_bounded_.all()
    # Three restarts learnt a limit cycle of the saturating system (under
    # the median excitation held; 0.2-0.5 standard deviations wide); they
    # pass the bound checks, so that does not decide.
    assert net.restart_self_oscillating_.tolist() == [True, True, True, False]
    assert (net.selected_, net.best_restart_) == _replayed_choice(net)
    winner = net.best_restart_
    # The winner made to diverge at twice the amplitude: held out, and the
    # next best restart that fits the training records is chosen.
    checked = []
    check = _selection.bounded_beyond_range

    def unbounded_winner(est, w, train, like=()):
        checked.append(w)
        return not np.array_equal(w, net.coefs_) and check(est, w, train, like)

    monkeypatch.setattr(_selection, "bounded_beyond_range", unbounded_winner)
    held = TDLRegressor(**params).fit(X, y, X_val=Xv, y_val=yv)
    assert held.restart_bounded_.tolist() == [
        k != winner for k in range(held.n_restarts_)
    ]
    # Which check it failed: twice the amplitude, the constant input and the
    # excitations like the training records' passed.
    assert held.restart_checks_.shape == (held.n_restarts_, 3)
    assert held.restart_checks_[:, 1].tolist() == held.restart_bounded_.tolist()
    assert held.restart_checks_[:, [0, 2]].all()
    np.testing.assert_array_equal(held.restart_scores_, net.restart_scores_)
    assert held.best_restart_ != winner
    assert (held.selected_, held.best_restart_) == _replayed_choice(held)


def test_refinement_comparison_is_a_fitted_attribute_that_decides(monkeypatch):
    # The restart that validates best is ahead of the refinement of the
    # linear model by a reported number of standard errors; the choice
    # follows it: with the threshold just below it the restart is kept,
    # just above it the refinement. (How far ahead depends on the path,
    # which the BLAS kernel moves: 1.7 on one machine, above 2 on another.)
    from sysid_nn._engine import _selection

    (X, y, _), (Xv, yv, _) = (_linear_record(s) for s in (0, 1))
    y, yv = np.tanh(2 * y), np.tanh(2 * yv)
    params = dict(n_init=3, max_iter=30, random_state=0)
    _no_self_oscillation(monkeypatch)  # the comparison alone (see above)
    net = TDLRegressor(**params).fit(X, y, X_val=Xv, y_val=yv)
    ahead = net.refinement_advantage_
    assert ahead is not None and 0 < ahead < np.inf
    assert (net.selected_, net.best_restart_) == _replayed_choice(net)
    for margin, keeps_restart in ((-1e-9, True), (1e-9, False)):
        monkeypatch.setattr(_selection, "_SIGNIFICANT", ahead + margin)
        again = TDLRegressor(**params).fit(X, y, X_val=Xv, y_val=yv)
        assert again.refinement_advantage_ == ahead
        assert (again.best_restart_ != again.refined_restart_) is keeps_restart
        assert again.best_restart_ is not None
        replayed = _replayed_choice(again, ahead + margin)
        assert (again.selected_, again.best_restart_) == replayed
    # No comparison without validation records.
    alone = TDLRegressor(early_stopping=False, **params).fit(X, y)
    assert alone.refinement_advantage_ is None


def test_validation_record_from_rest_judges_as_the_tail_within_the_record():
    # Slow dynamics: a validation record cut from the motion and simulated
    # from rest starts with a long transient that is no fault of the model.
    X, y, _ = _linear_record(3, n=1000, noise=0.01, poles=(-1.8, 0.85))
    n = 800
    model = dict(output_lags=2, input_lags=2, n_init=1, max_iter=30, random_state=0)
    with warnings.catch_warnings():
        # A linear system: either fit may return its linear model.
        warnings.filterwarnings("ignore", "The linear model of", UserWarning)
        within = TDLRegressor(**model).fit(X, y)
        apart = TDLRegressor(**model).fit(X[:n], y[:n], X_val=X[n:], y_val=y[n:])
    ratio = apart.best_validation_score_ / within.best_validation_score_
    assert 1 / 1.5 < ratio < 1.5


def test_short_tail_of_a_record_at_rest_is_judged_as_its_continuation():
    # The hysteretic oscillator from rest, one record: from rest at its own
    # start, the held-out fifth (300 samples, under three periods) shows
    # mostly the response to that wrong start, which this lightly damped
    # structure has not forgotten by the tail's end; every network lost to
    # the linear model there, which fitted its own record to 0.58 NRMSE.
    rec = HystereticOscillator().generate(1, n_samples=1500, random_state=11)
    X, y = rec.excitation[0][:, None], rec.displacement[0]
    net = TDLRegressor(random_state=1).fit(X, y)
    assert net.validation_continues_record_
    assert net.validation_burn_in_ == net.validation_start_window_ == 0
    # Judged: the tail's rows of the free run from rest over the whole record.
    n = len(y) - round(0.2 * len(y))
    e = (net.simulate(X)[n:] - y[n:]) / net._y_scale
    np.testing.assert_allclose(-net.best_validation_score_, np.mean(e**2), rtol=1e-6)
    assert net.selected_ == "restart"
    assert nrmse(y, net.simulate(X)) < 0.05


@pytest.mark.parametrize(
    ("radius", "offset", "continued"),
    [(0.998, 0.0, True), (0.98, 0.0, False), (0.998, 1.0, True)],
)
def test_tail_is_judged_as_its_records_continuation_only_where_needed(
    radius, offset, continued
):
    # One mode of 31 samples a period, from rest, the last 200 of 1000
    # samples held out. Radius 0.998: the response to a wrong start keeps
    # about 70 % of its size over the tail, which is judged as the record's
    # continuation. Radius 0.98: about 4 % is left, the tail is judged
    # from rest (after a burn-in). A record moved off rest at its start
    # (offset in standard deviations) is continued from its first measured
    # outputs: the judged rows are the tail of the free run from there.
    rng = np.random.default_rng(0)
    u = rng.standard_normal((1000, 1))
    a = [1.0, -2 * radius * np.cos(0.2), radius**2]
    y = lfilter([0.0, 0.1], a, u[:, 0])
    y = y + 0.001 * y.std() * rng.standard_normal(len(y)) + offset * y.std()
    params = dict(output_lags=2, input_lags=2, hidden_layer_sizes=(3,), n_init=1)
    net = TDLRegressor(max_iter=30, random_state=0, **params).fit(u, y)
    assert net.validation_continues_record_ is continued
    if continued:
        n, h = len(y) - 200, 2
        if offset:
            run = net.simulate(u[h:], initial_outputs=y[:h], initial_inputs=u[:h])
            e = (run[n - h :] - y[n:]) / net._y_scale
        else:
            e = (net.simulate(u)[n:] - y[n:]) / net._y_scale
        # (``simulate`` from rest runs in to the model's own rest first.)
        np.testing.assert_allclose(
            -net.best_validation_score_, np.mean(e**2), rtol=1e-3
        )


def test_tail_of_a_record_in_motion_is_judged_from_its_measured_start(modal_chain):
    # Two modes of 2 % damping, the record cut 500 samples into the
    # response. From rest on the tail the response to the wrong start
    # swamps the networks' errors: one that tested at 0.58 NRMSE was chosen
    # over the linear model (0.037). From the record's measured start the
    # judge sees the drift.
    b, a = modal_chain((0.04, 0.11), 0.02)
    rng = np.random.default_rng(0)
    u = rng.standard_normal(1524)
    y = lfilter(b, a, u)
    u, y = u[500:, None], y[500:]
    net = TDLRegressor(random_state=0).fit(u, y)
    assert net.validation_continues_record_
    u_test = np.random.default_rng(100).standard_normal((1000, 1))
    assert nrmse(lfilter(b, a, u_test[:, 0]), net.simulate(u_test)) < 0.06


def test_restart_that_diverges_beyond_the_training_range_is_not_chosen():
    from sysid_nn._engine._selection import bounded_beyond_range, choose
    from sysid_nn._records._data import _FREE_RUN

    X, y, _ = _linear_record(0, noise=0.0)
    y = np.tanh(y)
    model = TDLRegressor(
        output_lags=2, input_lags=2, hidden_layer_sizes=(1,), activation="logistic",
        n_init=1, max_iter=5, early_stopping=False, random_state=0,
    ).fit(X, y)  # fmt: skip
    train = model._stack([X], [y[:, None]])
    # A hidden node that wakes up only above 1.6 times the largest training
    # excitation: silent in ``good``, in ``bad`` it then throws the output
    # far out of range.
    good = model.coefs_.copy()
    hidden, out = model._layout().layers
    w1, b1, w2 = hidden.weights, hidden.biases, out.weights
    u_col = model.output_lags_ * model.n_outputs_  # first excitation lag
    good[w1] = 0.0
    good[w1.start + u_col] = 50.0 / np.abs(train.U).max()
    good[b1] = -100.0
    good[w2] = 0.0
    bad = good.copy()
    bad[w2] = 1e6
    assert bounded_beyond_range(model, good, train)
    assert not bounded_beyond_range(model, bad, train)
    # Within the divergence bound, but ten times the training outputs'
    # largest value: a network gone wild beyond the records.
    wild = good.copy()
    wild[w2] = 10 * np.abs(train.Y).max()
    Yhat = model._run(wild, replace(train, U=2 * train.U), _FREE_RUN, False)[0]
    assert 6 * np.abs(train.Y).max() < np.abs(Yhat).max() < model._bound
    assert not bounded_beyond_range(model, wild, train)
    # Within the training range the two are the same model.
    np.testing.assert_allclose(
        model._run(bad, train, 1, False)[0], model._run(good, train, 1, False)[0]
    )
    runs = [
        _run(bad, 0.0, 0.5),
        _run(good, 0.0, 1.0),
    ]
    chosen, selected, bounded, *_ = choose(model, train, None, runs, None)
    assert chosen.w is good
    assert selected == "restart"
    assert bounded == [False, True]


def test_surrogate_excitation_keeps_spectrum_range_and_history():
    from sysid_nn._engine._selection import surrogate_excitation

    _, train = _first_order_tdl()
    a, b = train.h, len(train.U)
    one = surrogate_excitation(train, np.random.default_rng(0))
    again = surrogate_excitation(train, np.random.default_rng(0))
    other = surrogate_excitation(train, np.random.default_rng(1))
    np.testing.assert_array_equal(one.U, again.U)  # reproducible
    assert not np.allclose(one.U[a:b], other.U[a:b])
    assert not np.allclose(one.U[a:b], train.U[a:b])
    np.testing.assert_array_equal(one.U[:a], train.U[:a])  # history rows
    np.testing.assert_array_equal(one.Y, train.Y)
    u, v = train.U[a:b, 0], one.U[a:b, 0]
    assert u.min() <= v.min() and v.max() <= u.max()
    # The amplitude spectrum, but where clipping to the range acted.
    spectra = [np.abs(np.fft.rfft(x - u.mean())) for x in (u, v)]
    assert np.corrcoef(*spectra)[0, 1] > 0.99
    assert np.mean(v) == pytest.approx(np.mean(u), abs=0.05 * np.std(u))


def test_network_wild_under_excitations_like_the_records_is_not_chosen():
    # A binary excitation (standardised about +-1, at rest 0). Two hidden
    # nodes that together wake up only for an excitation lag between 0.3 and
    # 0.7 leave the training run, and the run at twice its amplitude, as
    # they are; under the records' spectrum with other phases (values
    # between the two levels) they throw the output far out.
    from sysid_nn._engine._selection import (
        LinearCandidate,
        bounded_beyond_range,
        choose,
        surrogate_bounds,
    )
    from sysid_nn._records._data import _FREE_RUN

    u = np.sign(np.random.default_rng(3).standard_normal(800))[:, None]
    y = lfilter([0.0, 0.5], [1.0, -0.5], u[:, 0])
    model = TDLRegressor(
        output_lags=1, input_lags=2, hidden_layer_sizes=(2,), activation="logistic",
        lag_representation="delays", n_init=1, max_iter=5, early_stopping=False,
        random_state=0,
    ).fit(u, y)  # fmt: skip
    train = model._stack([u], [y[:, None]])
    hidden, out = model._layout().layers
    good = model.coefs_.copy()
    good[out.weights] = 0.0  # the bypass alone: the linear model
    wild = good.copy()
    lag = hidden.weights.start + model.output_lags_ * model.n_outputs_
    level = np.abs(train.U[train.modelled]).mean()  # the standardised levels
    for j, edge in enumerate((0.3, 0.7)):
        wild[lag + j * hidden.n_in] = 100.0 / level
        wild[hidden.biases.start + j] = -100.0 * edge
    reach = np.abs(train.Y[train.modelled]).max()
    # Four times the training outputs' reach under such excitations.
    wild[out.weights] = [2 * reach, -2 * reach]
    np.testing.assert_allclose(
        model._run(wild, train, _FREE_RUN, False)[0],
        model._run(good, train, _FREE_RUN, False)[0],
        atol=1e-9,
    )
    assert bounded_beyond_range(model, wild, train)  # training-amplitude checks
    linear = LinearCandidate(run=_run(good.copy(), 1.0, 1.0), w=good.copy())
    like = surrogate_bounds(model, train, linear)
    assert len(like) == 2
    assert bounded_beyond_range(model, good, train, like)
    assert not bounded_beyond_range(model, wild, train, like)
    assert surrogate_bounds(model, train, None) == []  # no linear reference
    # Judged against the linear model's run under the same excitation: a
    # linear model of three times the gain reaches as far itself.
    louder = good.copy()
    u_cols = model.output_lags_ * model.n_outputs_ + np.arange(2)
    louder[model._layout().bypass.start + u_cols] *= 3.0  # excitation lags
    steep = surrogate_bounds(
        model, train, LinearCandidate(run=_run(louder, 1.0, 1.0), w=louder)
    )
    assert len(steep) == 2 and all(r > 5 * reach for _, r in steep)
    assert bounded_beyond_range(model, wild, train, steep)
    runs = [_run(wild, 0.1, 0.1), _run(good.copy(), 0.5, 0.5)]
    chosen, selected, bounded, *_ = choose(model, train, None, runs, linear)
    assert chosen is runs[1] and selected == "restart"
    assert bounded == [False, True]


def test_restart_that_fits_its_training_records_worse_than_linear_is_not_chosen():
    # On the Cascaded Tanks benchmark restarts whose free run on the training
    # record was 1.2-4 times the linear model's validated up to 24 % better
    # on the 205 validation samples, and tested 1.5-3 times worse.
    from sysid_nn._engine._selection import LinearCandidate, choose

    X, y, _ = _linear_record(0, noise=0.0)
    model = TDLRegressor(
        output_lags=2, input_lags=2, hidden_layer_sizes=(2,), n_init=1,
        max_iter=5, early_stopping=False, random_state=0,
    ).fit(X, y)  # fmt: skip
    train = model._stack([X], [y[:, None]])
    w = model.coefs_
    lucky = _run(w.copy(), 0.30, 0.10)
    sound = _run(w.copy(), 0.05, 0.15)
    linear = LinearCandidate(run=_run(w.copy(), 0.20, 0.20), w=w.copy())
    chosen, selected, *_ = choose(model, train, train, [lucky, sound], linear)
    assert chosen is sound
    assert selected == "restart"
    # Without validation records the score is the training loss itself.
    chosen, *_ = choose(model, train, None, [lucky, sound], linear)
    assert chosen is lucky
    # No restart fits better than the linear model: it is returned, and the
    # warning says why.
    with pytest.warns(UserWarning, match="1 of 1 fitted the training records worse"):
        chosen, selected, *_ = choose(model, train, train, [lucky], linear)
    assert selected == "linear"
    assert chosen.w is linear.w


def test_refinement_kept_unless_a_restart_validates_clearly_better():
    # On Cascaded Tanks the refinement of the linear model tested better
    # than the restart that validated better in 9 of 10 fits where both were
    # candidates; the restart is kept only where its validation error is
    # lower beyond the validation's noise.
    from sysid_nn._engine._selection import (
        _SIGNIFICANT,
        LinearCandidate,
        choose,
        validation_advantage,
        validation_loss,
    )

    (X, y, _), (Xv, yv, _) = (_linear_record(s, n=600, noise=0.1) for s in (0, 1))
    y, yv = np.tanh(y), np.tanh(yv)
    model = TDLRegressor(
        output_lags=2, input_lags=2, hidden_layer_sizes=(3,), n_init=1,
        max_iter=20, random_state=0,
    ).fit(X, y, X_val=Xv, y_val=yv)  # fmt: skip
    train = model._stack([X], [y[:, None]])
    val = model._stack([Xv], [yv[:, None]])
    w = model.coefs_
    drift = np.random.default_rng(0).standard_normal(w.shape)
    seg = model._final_segment()

    def run(weights):
        return _run(weights, 0.01, validation_loss(model, weights, val, seg))

    linear = LinearCandidate(run=_run(w.copy(), 1.0, 1.0), w=w.copy())
    restart = run(w.copy())
    for scale, kept in ((1e-4, "refinement"), (0.03, "restart")):
        refinement = run(w + scale * drift)
        assert restart.criterion < refinement.criterion < linear.run.criterion
        ahead = validation_advantage(model, restart.w, refinement.w, val, seg)
        assert (ahead > _SIGNIFICANT) == (kept == "restart")
        chosen, selected, *_, advantage = choose(
            model, train, val, [restart, refinement], linear, refined=1
        )
        assert selected == "restart" and advantage == ahead
        assert chosen is (refinement if kept == "refinement" else restart)
    # Without a refinement, or without validation records, the best is kept
    # and no comparison is reported.
    refinement = run(w + 1e-4 * drift)
    chosen, *_, advantage = choose(model, train, val, [restart, refinement], linear)
    assert chosen is restart and advantage is None


def test_validation_advantage_allows_for_autocorrelated_errors(monkeypatch):
    # Free-run errors drift: the same mean difference is clear where the
    # per-sample differences are independent and not where they wander.
    from sysid_nn._engine import _selection

    rng = np.random.default_rng(0)
    n = 400
    noise = rng.standard_normal(n)
    wander = lfilter([1.0], [1.0, -0.95], noise) * np.sqrt(1 - 0.95**2)
    for d, clear in ((noise, True), (wander, False)):
        gap = 0.5 * (d - d.mean()) + 0.15  # the difference in squared error
        ours = np.full((n, 1), 2.0)
        theirs = np.sqrt(4.0 + gap)[:, None]
        monkeypatch.setattr(
            _selection,
            "validation_residuals",
            lambda est, w, val, seg, ours=ours, theirs=theirs: (
                ours if w == 0 else theirs
            ),
        )
        val = SimpleNamespace(starts=np.array([0, n]), judged=np.arange(n))
        ahead = _selection.validation_advantage(None, 0, 1, val, 1)
        assert (ahead > _selection._SIGNIFICANT) == clear


def test_linear_candidate_is_scored_on_the_restarts_objective():
    # With focus="prediction" the restarts are judged by their one-step
    # validation error; the linear model must be judged alike, not by its
    # free run.
    (X, y, _), (Xv, yv, _) = (_linear_record(s, noise=0.05) for s in (0, 1))
    params = dict(
        output_lags=2, input_lags=2, focus="prediction", n_init=1, max_iter=20,
        random_state=0,
    )  # fmt: skip
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", "The linear model of", UserWarning)
        net = TDLRegressor(hidden_layer_sizes=(3,), **params).fit(
            X, y, X_val=Xv, y_val=yv
        )
    alone = TDLRegressor(hidden_layer_sizes=(), **params).fit(X, y, X_val=Xv, y_val=yv)
    assert net.linear_score_ == pytest.approx(alone.best_validation_score_, rel=1e-9)


def test_validation_record_of_an_integrating_plant_starts_from_a_fitted_state():
    # A position driven through a lag: the initial state of a validation
    # record cut from the motion is never forgotten, so no burn-in helps;
    # from rest (measured position, zero velocity) the ISSM's free run keeps
    # an offset. The state is fitted to the record's first samples instead.
    rng = np.random.default_rng(0)

    def record(n):
        u = rng.standard_normal((n, 1))
        y = np.cumsum(lfilter([0, 0.1], [1, -0.9], u[:, 0]))
        return u, y + 0.001 * y.std() * rng.standard_normal(n)

    (u, y), (u_rest, y_rest) = record(1000), record(300)
    params = dict(n_states=2, hidden_layer_sizes=(3,), n_init=1, max_iter=30)
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", "The linear model of", UserWarning)
        net = ISSMRegressor(random_state=0, **params).fit(
            u[:800], y[:800], X_val=u[800:], y_val=y[800:]
        )
        # The same last fifth held out by the estimator itself.
        tail = ISSMRegressor(random_state=0, **params).fit(u, y)
        # A validation record that starts at rest needs no fitted start.
        rest = ISSMRegressor(random_state=0, **params).fit(
            u[:700], y[:700], X_val=u_rest, y_val=y_rest
        )
    assert net.validation_start_window_ == net.validation_burn_in_ == 50
    assert rest.validation_start_window_ == 0
    # Held out by the estimator or passed, the same records choose alike.
    assert tail.validation_start_window_ == tail.validation_burn_in_ == 50
    np.testing.assert_array_equal(tail.coefs_, net.coefs_)
    # The validation judges the model, not its ignorance of the start.
    assert -net.linear_score_ < 1e-3
    assert -net.best_validation_score_ < 1e-3


def _tanks(seed, n=1400, rate=0.2, noise=0.05):
    """Two cascaded tanks (outflow as the square root of the level) filled
    by a piecewise-constant inflow; the lower level, noisy."""
    rng = np.random.default_rng(seed)
    u = np.repeat(rng.uniform(0.0, 1.0, (n // 20, 1)), 20, axis=0)
    upper, lower = np.zeros(n), np.zeros(n)
    for t in range(1, n):
        out_upper = 0.5 * np.sqrt(max(upper[t - 1], 0.0))
        out_lower = 0.5 * np.sqrt(max(lower[t - 1], 0.0))
        upper[t] = upper[t - 1] + rate * (u[t - 1, 0] - out_upper)
        lower[t] = lower[t - 1] + rate * (out_upper - out_lower)
    return u, lower + noise * lower.std() * rng.standard_normal(n)


def test_fitted_validation_start_is_weighed_against_the_burn_in():
    # A validation record cut from the tanks' motion: from rest, the run's
    # error in its first 50 samples is its wrong start, which the burn-in
    # leaves out. After the burn-in, a state fitted to the first samples
    # does not halve the error (the linear model is not the system), so the
    # run from rest after the burn-in judges it. Compared within the burn-in,
    # the fitted start won: on the Cascaded Tanks benchmark the judgement
    # changed so as the split moved by ten samples.
    from sysid_nn._engine._selection import judgement, start_window, validation_loss

    u, y = _tanks(0)
    model = ISSMRegressor(
        n_states=2, hidden_layer_sizes=(), n_init=1, max_iter=10, random_state=0
    ).fit(u[:1000], y[:1000])
    train = model._stack([u[:1000]], [y[:1000, None]])
    val = model._stack([u[1050:1250]], [y[1050:1250, None]])
    w = model.coefs_
    burn, window, whole, score = judgement(model, model, w, train, val)
    assert window == 0 and whole is None
    assert burn > start_window(val)  # the start is not forgotten within it
    assert score == pytest.approx(validation_loss(model, w, replace(val, burn=burn)))

    def loss(fitted, after):
        window = start_window(val) if fitted else 0
        return validation_loss(model, w, replace(val, start_window=window, burn=after))

    assert loss(True, burn) >= 0.5 * loss(False, burn)
    assert loss(True, start_window(val)) < 0.5 * loss(False, start_window(val))


def _first_batches_lost(monkeypatch, n_lost):
    """Make the first ``n_lost`` batches of restarts (and, if any, the
    refinement of the linear model) diverge; returns the seeds of every
    batch run."""
    from sysid_nn._engine import _training

    real, batches = _training.run_batch, []

    def run_batch(est, train_data, val, seeds, halving):
        runs = real(est, train_data, val, seeds, halving)
        batches.append([int(seed) for seed in seeds])
        if len(batches) <= n_lost:
            runs = [
                replace(r, loss=np.inf, val_loss=np.inf, criterion=np.inf) for r in runs
            ]
        return runs

    def refine_linear(*args):
        run = real_refine(*args)
        if not n_lost:
            return run
        return replace(run, loss=np.inf, val_loss=np.inf, criterion=np.inf)

    real_refine = _training.refine_linear
    monkeypatch.setattr(_training, "run_batch", run_batch)
    monkeypatch.setattr(_training, "refine_linear", refine_linear)
    return batches


def _cubic_record():
    rng = np.random.default_rng(0)
    u = rng.standard_normal((1200, 1))
    x = lfilter([0, 0.5, 0.2], [1, -1.2, 0.5], u[:, 0])
    return u, x + 0.3 * np.tanh(2 * x) ** 3 + 0.02 * rng.standard_normal(1200)


def test_second_batch_of_restarts_where_the_first_lost_to_the_linear_model(
    monkeypatch,
):
    # A first batch none of whose restarts beats the linear model (on the
    # EMPS benchmark the TDL's four restarts of random_state=2 all stopped
    # short of the networks' basin): a second batch on new seeds runs, and
    # its best restart is kept, without the linear model's warning.
    u, y = _cubic_record()
    params = dict(
        output_lags=2, input_lags=2, hidden_layer_sizes=(3,), n_init=2,
        max_iter=10, random_state=0,
    )  # fmt: skip
    with monkeypatch.context() as spied:
        plain_batches = _first_batches_lost(spied, 0)
        plain = TDLRegressor(**params).fit(u, y)
    assert len(plain_batches) == plain.restart_batches_ == 1
    assert plain.n_restarts_ == 3
    batches = _first_batches_lost(monkeypatch, 1)
    with warnings.catch_warnings():
        warnings.filterwarnings("error", "The linear model of", UserWarning)
        model = TDLRegressor(**params).fit(u, y)
    assert len(batches) == 2 and set(batches[0]).isdisjoint(batches[1])
    assert model.restart_batches_ == 2 and model.n_restarts_ == 5
    assert model.selected_ == "restart"
    assert model.best_restart_ in (3, 4)  # after the first batch and the refinement
    # The first batch's seeds are the plain fit's.
    assert batches[0] == plain_batches[0]
    assert -model.best_validation_score_ == -model.restart_scores_[model.best_restart_]


def test_linear_model_returned_after_every_batch_lost_warns_once(monkeypatch):
    u, y = _cubic_record()
    batches = _first_batches_lost(monkeypatch, 2)
    with pytest.warns(UserWarning, match="beat every trained network") as caught:
        model = TDLRegressor(
            output_lags=2, input_lags=2, hidden_layer_sizes=(3,), n_init=2,
            max_iter=10, random_state=0,
        ).fit(u, y)  # fmt: skip
    assert len(batches) == 2
    assert sum("beat every trained network" in str(w.message) for w in caught) == 1
    assert model.selected_ == "linear" and model.restart_batches_ == 2
    assert model.n_restarts_ == 5


def test_burn_in_only_for_records_that_start_in_motion():
    from sysid_nn._engine._selection import burn_in

    X, y, _ = _linear_record(3, n=1000, noise=0.01, poles=(-1.8, 0.85))
    model = TDLRegressor(
        output_lags=2, input_lags=2, hidden_layer_sizes=(), max_iter=30,
        random_state=0,
    ).fit(X, y)  # fmt: skip
    at_rest = model._stack([X[:200]], [y[:200, None]])
    in_motion = model._stack([X[600:800]], [y[600:800, None]])
    assert burn_in(model, model.coefs_, at_rest) == (0, True)
    # The slowest mode (radius 0.92) takes about 80 samples to fall to 0.1 %.
    burn, settled = burn_in(model, model.coefs_, in_motion)
    assert 40 <= burn <= 100
    assert settled


def _first_order_tdl():
    """A fitted one-lag linear TDL and its standardised training records."""
    rng = np.random.default_rng(0)
    # A slow excitation: the outputs' second differences are small.
    u = lfilter([0.1], [1, -0.95], rng.standard_normal(600))[:, None]
    y = lfilter([0, 0.5], [1, -0.5], u[:, 0])
    model = TDLRegressor(
        hidden_layer_sizes=(), output_lags=1, input_lags=1, n_init=1,
        max_iter=2, early_stopping=False, random_state=0,
    ).fit(u, y)  # fmt: skip
    return model, model._stack([u], [y[:, None]])


def test_constant_input_responses_show_where_a_run_settles_and_swings():
    from sysid_nn._engine._selection import _median_step, level_responses

    model, train = _first_order_tdl()
    # Weights [output lag, excitation lag, bias] on standardised values.
    end, swing = level_responses(
        model, np.array([0.5, 0.5, 0.0]), train, _median_step(train)
    )
    u_levels = np.quantile(train.U[train.modelled], (0, 0.25, 0.5, 0.75, 1), axis=0)
    # Static gain 0.5 / (1 - 0.5) = 1: each run ends at its level.
    np.testing.assert_allclose(end, u_levels, rtol=1e-2)
    np.testing.assert_array_equal(swing, 0.0)
    # A pole at -1 swings for ever about its level: it never settles.
    end, swing = level_responses(
        model, np.array([-1.0, 0.5, 0.0]), train, _median_step(train)
    )
    assert np.isnan(end).all()
    assert (swing > 1.0).all()


def test_restart_that_settles_on_the_wrong_side_or_swings_is_not_chosen(monkeypatch):
    # On the Cascaded Tanks benchmark a restart that validated best settled
    # at 100 V under the lowest training input, where the linear model fell
    # below the training outputs, and ran the test record to 107 V.
    from sysid_nn._engine import _selection
    from sysid_nn._engine._selection import LinearCandidate, choose, excursion_ratios

    # The constant-input check alone: these linear restarts also leave the
    # bound at twice the amplitude and the linear model's reach under
    # excitations like the records', which would hold them out on their own.
    monkeypatch.setattr(_selection, "_AMPLITUDE_PEAK", np.inf)
    monkeypatch.setattr(_selection, "_SURROGATES", 0)

    model, train = _first_order_tdl()
    linear = LinearCandidate(
        run=_run(np.array([0.5, 0.5, 0.0]), 1.0, 1.0), w=np.array([0.5, 0.5, 0.0])
    )
    wrong = _run(np.array([0.5, -20.0, 0.0]), 0.1, 0.1)  # gain -40
    swinging = _run(np.array([-1.0, 0.5, 0.0]), 0.1, 0.2)  # a pole at -1
    steeper = _run(np.array([0.5, 20.0, 0.0]), 0.1, 0.3)  # gain 40, same side
    ratios = excursion_ratios(model, [wrong, swinging, steeper], train, linear)
    # Wrong side: how far, over ten times the training outputs' largest
    # value.
    reach = np.abs(train.Y[train.modelled]).max()
    u_max = np.abs(train.U[train.modelled]).max()
    assert ratios[0] == pytest.approx(40 * u_max / (10 * reach), rel=1e-2)
    assert ratios[0] > 1.0
    assert ratios[1] > 1.0
    # Settling further out on the linear model's side is not judged.
    assert ratios[2] == 0.0
    runs = [wrong, swinging, steeper]
    chosen, selected, bounded, excursions, cycling, checks, _ = choose(
        model, train, train, runs, linear
    )
    assert chosen is steeper
    assert selected == "restart"
    assert bounded == [False, False, True]
    assert checks[:, 0].tolist() == [False, False, True]  # the constant input
    assert cycling == [False, False, False]  # from rest, even the pole at -1
    np.testing.assert_array_equal(excursions, ratios)


def test_restart_that_self_oscillates_comes_after_one_that_settles_where_none_passes(
    monkeypatch,
):
    # On Silverbox with the validation part moved 10 samples earlier, the
    # restart that validated best circled 25 mV wide under zero excitation
    # and tested at 6.1 mV on the full arrow; one that validated 5 % worse
    # came to rest and tested at 0.78 mV. No restart passed the bound checks.
    from sysid_nn._engine import _selection
    from sysid_nn._engine._selection import LinearCandidate, choose

    model, train = _first_order_tdl()
    w_lin = np.array([0.5, 0.5, 0.0])
    linear = LinearCandidate(run=_run(w_lin, 1.0, 1.0), w=w_lin)
    # The first restart validated best and self-oscillates (the check on
    # networks: test_the_choice_among_restarts_is_explained_by_fitted_attributes).
    circling = _run(np.array([0.4, 0.6, 0.0]), 0.1, 0.1)
    settling = _run(np.array([0.5, 0.5, 0.0]), 0.1, 0.2)
    runs = [circling, settling]
    flagged = circling.w
    monkeypatch.setattr(
        _selection,
        "self_oscillating",
        lambda est, runs, train: [r.w is flagged for r in runs],
    )
    # Both pass the bound checks: the better one, self-oscillating or not
    # (holding it out there cost the oscillator's TDL at dt = 0.03 s).
    chosen, _, bounded, _, cycling, *_ = choose(model, train, train, runs, linear)
    assert cycling == [True, False]
    assert chosen is circling and bounded == [True, True]
    # Every restart failing a bound check another passes: the one that
    # settles first.
    monkeypatch.setattr(
        _selection, "bounded_beyond_range", lambda est, w, train: w is flagged
    )
    monkeypatch.setattr(_selection, "surrogate_bounds", lambda *a: [(train, 1.0)])
    monkeypatch.setattr(
        _selection, "_peak", lambda est, w, data: np.inf if w is flagged else 0.0
    )
    chosen, selected, bounded, _, cycling, *_ = choose(
        model, train, train, runs, linear
    )
    assert (chosen, selected, bounded) == (settling, "restart", [False, False])
    assert choose(model, train, train, runs, linear)[5].tolist() == [
        [True, True, False],
        [True, False, True],
    ]
    # Where every restart self-oscillates, the best of them.
    chosen, selected, *_ = choose(model, train, train, [circling], linear)
    assert (chosen, selected) == (circling, "restart")


def test_linear_fit_far_worse_on_training_loses_on_a_record_in_motion(modal_chain):
    # Three modes of 1 % damping, 1 % output noise, the record cut in
    # motion. From rest at its start the validation tail shows mostly the
    # wrong start: there the linear model trained from the ARX start scored
    # 0.48 against 0.94 for the one from the subspace start, although it
    # fitted the training records 4.6 times worse (and, judged from a
    # fitted start as the networks then are, scored 0.48 against 0.0023).
    # The ARX one, kept, tested at 0.68 NRMSE.
    b, a = modal_chain((0.03, 0.08, 0.15), 0.01)
    rng = np.random.default_rng(0)
    u = rng.standard_normal(2500)
    y = lfilter(b, a, u)
    y = (y + 0.01 * y.std() * rng.standard_normal(len(y)))[500:]
    model = ISSMRegressor(n_init=1, random_state=0).fit(u[500:, None], y)
    assert model.init_ == "subspace"
    assert model.validation_start_window_ > 0
    u_test = np.random.default_rng(100).standard_normal((1000, 1))
    assert nrmse(lfilter(b, a, u_test[:, 0]), model.simulate(u_test)) < 0.1
