"""The training schedule: stages on a subset of segments, halving of restarts."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from sklearn.exceptions import ConvergenceWarning

from sysid_nn import ISSMRegressor, TDLRegressor, _schedule
from sysid_nn._records._data import _FREE_RUN


def _records(n=3, length=400, seed=0):
    """Records of a small non-linear system (two lags, saturating input)."""
    rng = np.random.default_rng(seed)
    Xs, ys = [], []
    for _ in range(n):
        u = rng.standard_normal(length)
        y = np.zeros(length)
        for t in range(2, length):
            y[t] = 0.6 * y[t - 1] - 0.1 * y[t - 2] + 0.8 * np.tanh(u[t - 1])
            y[t] += 0.2 * u[t - 2] ** 2 - 0.1 * y[t - 1] ** 2
        Xs.append(u[:, None])
        ys.append(y)
    return Xs, ys


def _tdl(**params):
    defaults = dict(
        output_lags=2,
        input_lags=2,
        hidden_layer_sizes=(3,),
        shooting_segments=(10, 40),
        max_iter=12,
        n_init=1,
        random_state=0,
    )
    return TDLRegressor(**{**defaults, **params})


def _fit(model, Xs, ys, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        warnings.filterwarnings(
            "ignore", "A linear one-step model leaves a white misfit", UserWarning
        )
        return model.fit(Xs, ys, **kwargs)


@pytest.fixture
def small_subsets(monkeypatch):
    """Subsets that kick in on test-sized records."""
    monkeypatch.setattr(_schedule, "STAGE_SAMPLES", 300)
    monkeypatch.setattr(_schedule, "BLOCK_SAMPLES", 50)


def _stacked(model, Xs, ys):
    """The records as a fitted model stacks them for its kernels."""
    return model._stack(Xs, [np.asarray(y)[:, None] for y in ys])


# --------------------------------------------------------- segment subsets
def test_short_records_are_used_whole():
    Xs, ys = _records()
    model = _fit(_tdl(), Xs, ys)
    data = _stacked(model, Xs, ys)
    rng = np.random.RandomState(0)
    assert _schedule.stage_data(data, 10, rng) is data
    # No random draw either: a short record's fit is as without the rule.
    assert rng.randint(1000) == np.random.RandomState(0).randint(1000)


def test_subset_is_whole_segments_with_their_measured_history(small_subsets):
    Xs, ys = _records(n=4)
    model = _fit(_tdl(), Xs, ys)
    data = _stacked(model, Xs, ys)
    seg = 40
    sub = _schedule.stage_data(data, seg, np.random.RandomState(3))
    n_sub = len(sub.modelled)
    assert 300 <= n_sub < 300 + 80 and sub.h == data.h
    # Every block is a whole number of segments of one record, at a segment
    # start of that record, and its history is the measured rows before it.
    full, _, _, _ = model._run(model.coefs_, data, seg, False)
    part, _, _, _ = model._run(model.coefs_, sub, seg, False)
    for a, b in zip(sub.starts[:-1], sub.starts[1:], strict=True):
        block_Y = sub.Y[a:b]
        hits = [
            t
            for t in range(data.starts[-1] - (b - a) + 1)
            if np.array_equal(data.Y[t : t + b - a], block_Y)
            and np.array_equal(data.U[t : t + b - a], sub.U[a:b])
        ]
        assert len(hits) == 1
        t0 = hits[0] + sub.h  # first modelled row of the block in the record
        record = np.searchsorted(data.starts, t0, side="right") - 1
        assert (t0 - data.starts[record] - data.h) % seg == 0
        # The TDL's errors on a block are those of the same segments in the
        # whole record.
        np.testing.assert_allclose(
            part[a + sub.h : b], full[t0 : t0 + b - a - sub.h], rtol=1e-12
        )


def test_subset_is_reproducible_from_the_random_state(small_subsets):
    Xs, ys = _records(n=4)
    model = _fit(_tdl(), Xs, ys)
    data = _stacked(model, Xs, ys)

    def draw(seed):
        return _schedule.stage_data(data, 10, np.random.RandomState(seed)).Y

    np.testing.assert_array_equal(draw(1), draw(1))
    assert not np.array_equal(draw(1), draw(2))


def test_stages_before_the_free_run_see_the_subset(small_subsets, monkeypatch):
    from sysid_nn._engine import _selection, _training

    Xs, ys = _records(n=4)
    solve = _training._SOLVERS["lm"]
    seen = []

    def spying(objective, w, iters, tol, tracker, stall=None):
        seen.append((objective.seg, len(objective.rows)))
        return solve(objective, w, iters, tol, tracker, stall)

    monkeypatch.setitem(_training._SOLVERS, "lm", spying)
    # The restart's stages alone, not those of the linear model selection
    # compares it with.
    monkeypatch.setattr(_selection, "linear_candidate", lambda *args: None)
    _fit(_tdl(), Xs[:3], ys[:3], X_val=Xs[3:], y_val=ys[3:])
    n_train = sum(len(x) for x in Xs[:3])
    assert [s for s, _ in seen] == [1, 10, 40, _FREE_RUN]
    assert all(300 <= n < n_train for _, n in seen[:-1])
    assert seen[-1][1] == n_train


def test_fits_on_subsets_are_reproducible(small_subsets):
    Xs, ys = _records(n=4)
    a = _fit(_tdl(n_init=2), Xs, ys)
    b = _fit(_tdl(n_init=2), Xs, ys)
    c = _fit(_tdl(n_init=2, random_state=1), Xs, ys)
    np.testing.assert_array_equal(a.coefs_, b.coefs_)
    np.testing.assert_array_equal(a.restart_scores_, b.restart_scores_)
    assert not np.array_equal(a.coefs_, c.coefs_)


def test_penalty_stays_relative_to_the_whole_record(small_subsets, monkeypatch):
    from sysid_nn._engine import _training

    Xs, ys = _records(n=4)
    solve = _training._SOLVERS["lm"]
    weights = []

    def spying(objective, w, iters, tol, tracker, stall=None):
        n = len(objective.rows)
        weights.append(objective.alpha / n)
        return solve(objective, w, iters, tol, tracker, stall)

    monkeypatch.setitem(_training._SOLVERS, "lm", spying)
    _fit(_tdl(alpha=0.5), Xs, ys)
    # alpha / n_res of the whole training record in every stage.
    np.testing.assert_allclose(weights, weights[-1], rtol=1e-12)


# --------------------------------------------------------------- halving
def _spy_stages(model, log):
    original = model._fit_stages

    def spy(train, val, restart, stop):
        first = restart.stage
        out = original(train, val, restart, stop)
        log.append((restart.k, first, stop, out[1].criterion))
        return out

    model._fit_stages = spy


def _random_restarts(log, model):
    """The entries of ``log`` of the random restarts, without the run that
    refines the linear model (it runs the last stage only, after them)."""
    refined = [entry for entry in log if entry[0] == model.refined_restart_]
    assert [(first, stop) for _, first, stop, _ in refined] == [
        (len(model._stages()) - 1, len(model._stages()))
    ]
    return [entry for entry in log if entry[0] != model.refined_restart_]


@pytest.mark.parametrize("n_init", [2, 3, 4])
def test_halving_keeps_the_restart_selected_by_validation(n_init):
    Xs, ys = _records(n=4)
    model = _tdl(n_init=n_init)
    log = []
    _spy_stages(model, log)
    _fit(model, Xs[:3], ys[:3], X_val=Xs[3:], y_val=ys[3:])
    log = _random_restarts(log, model)
    n_stages = len(model._stages())
    first = [entry for entry in log if entry[1] == 0]
    later = [entry for entry in log if entry[1] > 0]
    # Every restart ran the first stages; the better half by validation
    # criterion at that point ran the rest.
    assert sorted(k for k, *_ in first) == list(range(n_init))
    assert all(stop == _schedule.HALVING_AFTER for _, _, stop, _ in first)
    at_cut = {k: score for k, _, _, score in first}
    ranked = sorted(at_cut, key=lambda k: (at_cut[k], k))
    going_on = sorted(ranked[: -(-n_init // 2)])
    assert [k for k, *_ in later] == going_on
    assert all(stop == n_stages for _, _, stop, _ in later)
    # The chosen restart is the one with the best final validation score,
    # and no dropped restart was better than it.
    final = {**at_cut, **{k: score for k, _, _, score in later}}
    np.testing.assert_allclose(
        model.restart_scores_[:n_init], [-final[k] for k in range(n_init)]
    )
    best = min(final, key=final.get)
    assert best in going_on
    # ... among those that pass the checks beyond the training range, or
    # the linear model's refinement, where it validated better still.
    kept = [k for k in final if model.restart_bounded_[k]] or list(final)
    chosen = model.best_restart_
    assert chosen in (min(kept, key=final.get), model.refined_restart_)
    candidates = [*kept, model.refined_restart_]
    assert model.best_validation_score_ == model.restart_scores_[candidates].max()
    assert model.best_validation_score_ == model.restart_scores_[chosen]


def test_halving_does_not_change_the_restarts_it_keeps(monkeypatch):
    # A kept restart continues from where it stopped, with its own random
    # state: its final score is the one it has without the halving. A dropped
    # one keeps its score at the cut, which later stages could only improve.
    Xs, ys = _records(n=4)
    fit = dict(X_val=Xs[3:], y_val=ys[3:])
    model = _tdl(n_init=4)
    log = []
    _spy_stages(model, log)
    halved = _fit(model, Xs[:3], ys[:3], **fit).restart_scores_
    kept = [k for k, first, _, _ in _random_restarts(log, model) if first > 0]
    monkeypatch.setattr(_schedule, "HALVING_AFTER", 10**6)
    whole = _fit(_tdl(n_init=4), Xs[:3], ys[:3], **fit).restart_scores_
    assert len(kept) == 2
    np.testing.assert_array_equal(halved[kept], whole[kept])
    dropped = [k for k in range(4) if k not in kept]
    assert np.all(halved[dropped] <= whole[dropped])


def test_halving_runs_the_same_in_parallel():
    Xs, ys = _records(n=4)
    fit = dict(X_val=Xs[3:], y_val=ys[3:])
    serial = _fit(_tdl(n_init=4), Xs[:3], ys[:3], **fit)
    parallel = _fit(_tdl(n_init=4, n_jobs=2), Xs[:3], ys[:3], **fit)
    np.testing.assert_array_equal(serial.restart_scores_, parallel.restart_scores_)
    np.testing.assert_array_equal(serial.coefs_, parallel.coefs_)


def test_halving_without_validation_ranks_by_the_training_free_run():
    Xs, ys = _records(n=3)
    model = _tdl(n_init=4, early_stopping=False)
    log = []
    _spy_stages(model, log)
    _fit(model, Xs, ys)
    log = _random_restarts(log, model)
    assert model.best_validation_score_ is None
    assert sum(stop == _schedule.HALVING_AFTER for _, _, stop, _ in log) == 4
    assert sum(first > 0 for _, first, _, _ in log) == 2
    assert np.all(np.isfinite(model.restart_scores_))


def test_issm_restarts_are_halved_too(small_subsets, monkeypatch):
    # ... but its stages see the whole records: its unmeasured states carry
    # over between segments, so a block of them is not a sum of segments.
    from sysid_nn._engine import _training

    solve = _training._SOLVERS["lm"]
    rows = []

    def spying(objective, w, iters, tol, tracker, stall=None):
        rows.append(len(objective.rows))
        return solve(objective, w, iters, tol, tracker, stall)

    monkeypatch.setitem(_training._SOLVERS, "lm", spying)
    Xs, ys = _records(n=4, length=400)
    # (init="arx": on noisy records "auto" adds a restart from the subspace fit.)
    model = ISSMRegressor(
        hidden_layer_sizes=(3,), shooting_segments=(10, 20), max_iter=8,
        n_init=2, init="arx", random_state=0,
    )  # fmt: skip
    log = []
    _spy_stages(model, log)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        warnings.filterwarnings(
            "ignore", "A linear one-step model leaves a white misfit", UserWarning
        )
        _fit(model, Xs[:3], ys[:3], X_val=Xs[3:], y_val=ys[3:])
    log = _random_restarts(log, model)
    assert [first for _, first, _, _ in log] == [0, 0, _schedule.HALVING_AFTER]
    assert rows and set(rows) == {1200}
