"""``refit=True``: the chosen weights continued on the validation records too.

Each test here fails on a one-line break of the code it guards (see
``benchmarks/mutations.py``).
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest
from sklearn.utils._param_validation import InvalidParameterError
from test_engine import _oscillator_records as _records
from test_engine import _small

from sysid_nn import ISSMRegressor
from sysid_nn._engine import _refit
from sysid_nn._engine._selection import _SIGNIFICANT, validation_loss
from sysid_nn._engine._solvers import _EarlyStop, _Objective
from sysid_nn._records._data import _FREE_RUN


def _model(**params):
    # Seed 2: a fit whose continuation the inner validation and the margins
    # keep (seed 0's fits the training part 3.2 times worse).
    return _small(**{"random_state": 2, **params})


def _fit(model, *args, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return model.fit(*args, **kwargs)


@pytest.fixture(scope="module")
def records():
    X, y = _records(2, seed=0, n_samples=800)
    return X, [yi[:, None] for yi in y]


@pytest.fixture(scope="module")
def plain(records):
    """The fit without ``refit``: its weights are the ones a refit starts at."""
    X, y = records
    return _fit(_model(), X[0], y[0])


def test_refit_judges_the_second_half_of_the_held_out_tail(records, plain):
    X, y = records
    refitted = _fit(_model(refit=True), X[0], y[0])
    # 800 samples, the last fifth held out: the tail starts at 640, and
    # the inner validation judges it from its middle, 720, in continuation.
    record = plain._stack([X[0]], [y[0]])
    half = dataclasses.replace(record, lead=720)
    whole_tail = dataclasses.replace(record, lead=640)
    at_start = refitted.refit_losses_[0]
    assert at_start == pytest.approx(validation_loss(plain, plain.coefs_, half))
    assert at_start != pytest.approx(validation_loss(plain, plain.coefs_, whole_tail))


def test_refit_continues_on_every_record_for_the_steps_the_inner_validation_chose(
    records,
):
    X, y = records
    # A budget of 20: the inner validation's best step (12) falls short of
    # it, so one step more or fewer on all the records would show.
    plain = _fit(_model(max_iter=20), X[0], y[0])
    refitted = _fit(_model(refit=True, max_iter=20), X[0], y[0])
    steps = refitted.refit_steps_
    assert steps < len(refitted.refit_losses_) - 1
    assert steps == np.argmin(refitted.refit_losses_) > 0
    assert refitted.refit_advantage_ > _SIGNIFICANT
    # The same continuation by hand: the last stage, on the whole record,
    # from the chosen weights, for that many accepted steps.
    whole = plain._stack([X[0]], [y[0]])
    taken = []

    def count(_):
        taken.append(1)
        if len(taken) >= steps:
            raise _EarlyStop

    by_hand = _refit._continue(plain, whole, plain.coefs_, count)
    np.testing.assert_allclose(refitted.coefs_, by_hand)
    n_res = len(whole.modelled)
    final = _Objective(plain, whole, _FREE_RUN, plain._penalty_mask(), n_res)
    assert refitted.loss_ == pytest.approx(final.loss(by_hand))
    assert refitted.loss_ < final.loss(plain.coefs_)


def test_refit_reports_the_steps_taken_where_the_stage_ends_before_them(
    records, monkeypatch
):
    X, y = records
    original = _refit._continue
    calls = []

    def ends_early(est, data, w, observe):
        calls.append(data)
        if len(calls) == 1:  # the inner continuation runs as it would
            return original(est, data, w, observe)

        taken = []

        def three(weights):  # on all the records, the stage ends after three
            observe(weights)
            taken.append(1)
            if len(taken) == 3:
                raise _EarlyStop

        return original(est, data, w, three)

    monkeypatch.setattr(_refit, "_continue", ends_early)
    refitted = _fit(_model(refit=True), X[0], y[0])
    assert np.argmin(refitted.refit_losses_) > 3
    assert refitted.refit_steps_ == 3


def test_refit_keeps_the_chosen_weights_unless_a_step_is_clearly_ahead(
    records, plain, monkeypatch
):
    X, y = records
    monkeypatch.setattr(_refit, "validation_advantage", lambda *a: _SIGNIFICANT)
    kept = _fit(_model(refit=True), X[0], y[0])
    assert kept.refit_steps_ == 0 and kept.refit_advantage_ == _SIGNIFICANT
    np.testing.assert_array_equal(kept.coefs_, plain.coefs_)
    assert kept.loss_ == plain.loss_
    ahead = _SIGNIFICANT + 0.01
    monkeypatch.setattr(_refit, "validation_advantage", lambda *a: ahead)
    taken = _fit(_model(refit=True), X[0], y[0])
    assert taken.refit_steps_ == np.argmin(taken.refit_losses_) > 0


def test_refit_keeps_the_chosen_weights_where_the_training_records_fit_worse(
    records, plain, monkeypatch
):
    X, y = records
    refitted = _fit(_model(refit=True), X[0], y[0])
    train = plain._stack([X[0][:640]], [y[0][:640]])  # the tail held out
    n_res = len(train.modelled)
    on_train = _Objective(plain, train, _FREE_RUN, plain._penalty_mask(), n_res)
    ratio = on_train.loss(refitted.coefs_) / on_train.loss(plain.coefs_)
    assert refitted.refit_steps_ > 0
    assert refitted.refit_training_ratio_ == pytest.approx(ratio)
    # The same continuation held to a margin it exceeds: the chosen weights.
    monkeypatch.setattr(_refit, "_LINEAR_FIT_MARGIN", 0.99 * ratio)
    kept = _fit(_model(refit=True), X[0], y[0])
    assert kept.refit_steps_ == 0
    assert kept.refit_training_ratio_ == pytest.approx(ratio)
    np.testing.assert_array_equal(kept.coefs_, plain.coefs_)
    # Unpatched: seed 0's continuation fits the training part 3.2 times worse.
    worse = _fit(_small(refit=True), X[0], y[0])
    assert worse.refit_training_ratio_ > 2 and worse.refit_steps_ == 0
    np.testing.assert_array_equal(worse.coefs_, _fit(_small(), X[0], y[0]).coefs_)


def test_refit_judges_validation_records_after_half_the_shortest(records):
    X, y = records
    Xv, yv = [X[1][:300], X[1][300:500]], [y[1][:300], y[1][300:500]]
    plain = _fit(_model(), X[0][:600], y[0][:600], X_val=Xv, y_val=yv)
    refitted = _fit(_model(refit=True), X[0][:600], y[0][:600], X_val=Xv, y_val=yv)
    judged = dataclasses.replace(
        plain._stack(Xv, yv),
        lead=100,  # half the shorter record, of 200 samples
        burn=plain.validation_burn_in_,  # none here: the half is what counts
        start_window=plain.validation_start_window_,
    )
    assert plain.validation_burn_in_ == 0
    assert refitted.refit_losses_[0] == pytest.approx(
        validation_loss(plain, plain.coefs_, judged)
    )


def test_refit_needs_validation_records_long_enough_to_halve(records, plain):
    X, y = records
    assert plain.refit_steps_ is None and plain.refit_losses_ is None
    alone = _fit(_model(refit=True, early_stopping=False), X[0], y[0])
    assert alone.refit_steps_ is None and alone.refit_advantage_ is None
    # A half of 3 samples is shorter than a record the fit accepts (its
    # three lags and one sample to model).
    short = [X[1][:7]], [y[1][:7]]
    kept = _fit(_model(refit=True), X[0], y[0], X_val=short[0], y_val=short[1])
    again = _fit(_model(), X[0], y[0], X_val=short[0], y_val=short[1])
    assert kept.refit_steps_ == 0 and kept.refit_losses_ is None
    np.testing.assert_array_equal(kept.coefs_, again.coefs_)


def test_a_continuation_whose_free_run_diverges_is_not_kept(
    records, plain, monkeypatch
):
    X, y = records
    original = _refit._continue
    calls = []

    def diverging(est, data, w, observe):
        out = original(est, data, w, observe)
        calls.append(data)
        return out if len(calls) == 1 else np.full_like(out, np.nan)

    monkeypatch.setattr(_refit, "_continue", diverging)
    kept = _fit(_model(refit=True), X[0], y[0])
    assert len(calls) == 2  # the inner continuation, then the one on all
    assert kept.refit_steps_ == 0
    np.testing.assert_array_equal(kept.coefs_, plain.coefs_)


def test_a_continuation_that_diverges_on_the_validation_records_is_not_kept(
    records, plain, monkeypatch
):
    # Fits the training records as well as ever, and its free run over the
    # whole record (the held-out tail included) diverges.
    X, y = records
    chosen = _fit(_model(refit=True), X[0], y[0])
    assert chosen.refit_steps_ > 0

    class Diverging(_Objective):
        def loss(self, w):
            whole = len(self.data.Y) > 700
            moved = not np.array_equal(w, plain.coefs_)
            return np.inf if whole and moved else super().loss(w)

    monkeypatch.setattr(_refit, "_Objective", Diverging)
    kept = _fit(_model(refit=True), X[0], y[0])
    assert kept.refit_steps_ == 0
    assert kept.refit_training_ratio_ == pytest.approx(chosen.refit_training_ratio_)
    np.testing.assert_array_equal(kept.coefs_, plain.coefs_)


def test_refit_runs_for_the_issm(records):
    X, y = records
    model = ISSMRegressor(
        n_states=2, hidden_layer_sizes=(3,), n_init=1, max_iter=8, random_state=0
    )
    refitted = _fit(model.set_params(refit=True), X[0], y[0])
    assert isinstance(refitted.refit_steps_, int)
    assert len(refitted.refit_losses_) > 1
    assert np.all(np.isfinite(refitted.simulate(X[1])))


def test_refit_must_be_a_flag(records):
    X, y = records
    with pytest.raises(InvalidParameterError, match="'refit' parameter"):
        _model(refit="yes").fit(X[0], y[0])
