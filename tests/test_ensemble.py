"""EnsembleRegressor: members on their own seeds and held-out shares, and
the pointwise median of their runs."""

import warnings

import numpy as np
import pytest
from sklearn.base import BaseEstimator, RegressorMixin, clone
from sklearn.utils import check_random_state
from sklearn.utils.estimator_checks import parametrize_with_checks
from test_tdl import ROW_ORDER_CHECKS

from sysid_nn import EnsembleRegressor, ISSMRegressor, TDLRegressor
from sysid_nn._estimators._base import free_run_r2


def _record(seed, n=300):
    rng = np.random.default_rng(seed)
    u = rng.standard_normal((n, 1))
    y = np.convolve(u[:, 0], [0.0, 0.5, 0.25])[:n]
    return u, np.tanh(y) + 0.01 * rng.standard_normal(n)


def _net(**params):
    return TDLRegressor(
        output_lags=2, input_lags=2, hidden_layer_sizes=(3,), n_init=1,
        max_iter=5, **params,
    )  # fmt: skip


@pytest.mark.filterwarnings("ignore:The linear model of:UserWarning")
@parametrize_with_checks(
    [EnsembleRegressor(_net(), n_members=2)],
    expected_failed_checks=lambda est: ROW_ORDER_CHECKS,
)
def test_sklearn_compatible(estimator, check):
    check(estimator)


@pytest.mark.filterwarnings("ignore:The linear model of:UserWarning")
def test_members_are_the_fits_of_their_seeds_and_held_out_shares():
    X, y = _record(0)
    ensemble = EnsembleRegressor(
        _net(), n_members=3, validation_fractions=(0.2, 0.3), random_state=0
    ).fit(X, y)
    assert ensemble.member_validation_fractions_ == [0.2, 0.3, 0.2]
    assert len(set(ensemble.member_random_states_)) == 3
    for member, seed, share in zip(
        ensemble.estimators_,
        ensemble.member_random_states_,
        ensemble.member_validation_fractions_,
        strict=True,
    ):
        alone = _net(random_state=seed, validation_fraction=share).fit(X, y)
        np.testing.assert_array_equal(member.coefs_, alone.coefs_)
    # Reproducible, and the seeds are the ensemble's draws.
    again = clone(ensemble).fit(X, y)
    assert again.member_random_states_ == ensemble.member_random_states_
    np.testing.assert_array_equal(again.simulate(X), ensemble.simulate(X))


@pytest.mark.filterwarnings("ignore:The linear model of:UserWarning")
def test_given_validation_records_are_every_members():
    (X, y), (Xv, yv) = _record(0), _record(1)
    ensemble = EnsembleRegressor(_net(), n_members=2, random_state=0)
    ensemble.fit(X, y, X_val=Xv, y_val=yv)
    assert ensemble.member_validation_fractions_ == [None, None]
    seed = ensemble.member_random_states_[1]
    alone = _net(random_state=seed).fit(X, y, X_val=Xv, y_val=yv)
    np.testing.assert_array_equal(ensemble.estimators_[1].coefs_, alone.coefs_)


@pytest.mark.filterwarnings("ignore:The linear model of:UserWarning")
def test_runs_are_the_pointwise_median_of_the_finite_members(monkeypatch):
    X, y = _record(0)
    Xs, ys = [X[:150], X[150:]], [y[:150], y[150:]]
    ensemble = EnsembleRegressor(_net(), n_members=3, random_state=0).fit(Xs, ys)
    runs = np.array([m.simulate(X) for m in ensemble.estimators_])
    assert not np.allclose(np.median(runs, axis=0), runs.mean(axis=0))
    np.testing.assert_array_equal(ensemble.simulate(X), np.median(runs, axis=0))
    one_step = np.array([m.predict(X, y) for m in ensemble.estimators_])
    np.testing.assert_array_equal(ensemble.predict(X, y), np.median(one_step, axis=0))
    # Lists in, lists out, sequence by sequence.
    parts = ensemble.simulate(Xs)
    assert isinstance(parts, list) and len(parts) == 2
    for part, Xk in zip(parts, Xs, strict=True):
        runs_k = [m.simulate(Xk) for m in ensemble.estimators_]
        np.testing.assert_array_equal(part, np.median(runs_k, axis=0))
    assert ensemble.score(X, y) == free_run_r2(ensemble.simulate(X), y)
    # A member whose run diverges is left out where it is not finite.
    astray = ensemble.estimators_[0]
    wild = np.where(np.arange(len(X)) < 100, runs[0], np.inf)
    wild[50] = np.nan
    monkeypatch.setattr(astray, "simulate", lambda X, **kwargs: wild)
    combined = ensemble.simulate(X)
    np.testing.assert_array_equal(combined[:50], np.median(runs, axis=0)[:50])
    np.testing.assert_array_equal(combined[100:], runs[1:, 100:].mean(axis=0))
    assert combined[50] == runs[1:, 50].mean()


def test_errors_name_the_argument():
    X, y = _record(0)
    with pytest.raises(ValueError, match="validation_fractions must hold"):
        EnsembleRegressor(_net(), validation_fractions=(0.2, 1.0)).fit(X, y)
    with pytest.raises(ValueError, match="validation_fractions must hold"):
        EnsembleRegressor(_net(), validation_fractions=()).fit(X, y)
    with pytest.raises(ValueError, match="n_members"):
        EnsembleRegressor(_net(), n_members=0).fit(X, y)
    with pytest.raises(ValueError, match="max_error_ratio"):
        EnsembleRegressor(_net(), max_error_ratio=0.5).fit(X, y)
    fitted = EnsembleRegressor(_net(), n_members=1, random_state=0).fit(X, y)
    with pytest.raises(ValueError, match="return_std is not available"):
        fitted.simulate(X, return_std=True)


def test_default_members_are_issm_networks():
    X, y = _record(0, n=200)
    ensemble = EnsembleRegressor(n_members=1, random_state=0)
    ensemble.set_params(estimator=None)
    fitted = ensemble.fit(X, y)
    assert isinstance(fitted.estimators_[0], ISSMRegressor)
    assert fitted.n_features_in_ == 1


class _ShareGain(RegressorMixin, BaseEstimator):
    """A stand-in member: ``y = gain * u``, the gain off where it held out
    more than a fifth of the record."""

    def __init__(self, validation_fraction=0.2, random_state=None):
        self.validation_fraction = validation_fraction
        self.random_state = random_state

    def fit(self, X, y, X_val=None, y_val=None):
        self.n_features_in_ = 1
        self.gain_ = 1.0 if self.validation_fraction <= 0.2 else 4.0
        self.gain_ += 0.01 * self.random_state / np.iinfo(np.int32).max
        return self

    def simulate(self, X, **kwargs):
        return self.gain_ * np.asarray(X, dtype=float)[:, 0]

    def predict(self, X, y=None, *, horizon=1):
        return self.simulate(X)


def test_members_that_miss_the_fitted_records_are_left_out_of_the_median():
    rng = np.random.default_rng(0)
    X = rng.standard_normal((400, 1))
    y = X[:, 0] + 0.1 * rng.standard_normal(400)
    ensemble = EnsembleRegressor(_ShareGain(), random_state=0).fit(X, y)
    shares = np.array(ensemble.member_validation_fractions_)
    # The members holding out 25 and 30 % miss the record 30 times worse.
    errors = ensemble.member_record_errors_
    assert np.all(errors[shares > 0.2] > 20 * errors[shares <= 0.2].max())
    np.testing.assert_array_equal(ensemble.members_used_, shares <= 0.2)
    members = np.array(ensemble.estimators_, dtype=object)
    good = [m.simulate(X) for m in members[shares <= 0.2]]
    np.testing.assert_array_equal(ensemble.simulate(X), np.median(good, axis=0))
    np.testing.assert_array_equal(ensemble.predict(X), np.median(good, axis=0))
    # max_error_ratio=None: every member; here half of them are off, and the
    # median of all is far from the record.
    every = clone(ensemble).set_params(max_error_ratio=None).fit(X, y)
    assert every.members_used_.all()
    runs = [m.simulate(X) for m in every.estimators_]
    np.testing.assert_array_equal(every.simulate(X), np.median(runs, axis=0))
    assert every.score(X, y) < 0 < 0.9 < ensemble.score(X, y)


@pytest.mark.filterwarnings("ignore:The linear model of:UserWarning")
def test_member_record_errors_are_free_runs_over_every_fitted_record():
    (X, y), (Xv, yv) = _record(0), _record(1)
    Xs, ys = [X[:150], X[150:]], [y[:150], y[150:]]
    ensemble = EnsembleRegressor(_net(), n_members=3, random_state=0)
    ensemble.fit(Xs, ys, X_val=Xv, y_val=yv)
    measured = np.concatenate([*ys, yv])
    for member, error in zip(
        ensemble.estimators_, ensemble.member_record_errors_, strict=True
    ):
        runs = np.concatenate([*member.simulate(Xs), member.simulate(Xv)])
        expected = np.sqrt(np.mean(((runs - measured) / measured.std()) ** 2))
        assert error == pytest.approx(expected, rel=1e-12)
    errors = ensemble.member_record_errors_
    level = np.sort(errors)[0]  # the lower quartile of three: the best
    np.testing.assert_array_equal(ensemble.members_used_, errors <= 3 * level)


class _Recorder(RegressorMixin, BaseEstimator):
    """A stand-in member: ``y = gain * u``, the gain fitted by least squares
    and nudged by the seed; it keeps the records it was fitted to."""

    def __init__(self, validation_fraction=0.2, random_state=None):
        self.validation_fraction = validation_fraction
        self.random_state = random_state

    def fit(self, X, y, X_val=None, y_val=None):
        self.X_, self.y_ = X, y
        self.X_val_, self.y_val_ = X_val, y_val
        Xs, ys = (X, y) if isinstance(X, list) else ([X], [y])
        u = np.concatenate([np.asarray(x)[:, 0] for x in Xs])
        t = np.concatenate([np.asarray(v) for v in ys])
        self.gain_ = float(u @ t / (u @ u))
        self.gain_ *= 1 + 0.1 * self.random_state / np.iinfo(np.int32).max
        self.n_features_in_ = 1
        return self

    def simulate(self, X, **kwargs):
        if isinstance(X, list):
            return [self.simulate(x) for x in X]
        return self.gain_ * np.asarray(X, dtype=float)[:, 0]

    def predict(self, X, y=None, *, horizon=1):
        return self.simulate(X)


def _spectrum(x):
    return np.abs(np.fft.rfft(x[:, 0] - x[:, 0].mean()))


def test_the_distilled_network_is_fitted_to_the_median_on_records_like_its_records():
    rng = np.random.default_rng(0)
    X = rng.standard_normal((400, 1))
    y = np.tanh(X[:, 0]) + 0.1 * rng.standard_normal(400)
    ensemble = EnsembleRegressor(_Recorder(), n_members=3, distil=True, random_state=0)
    ensemble.fit(X, y)
    net = ensemble.network_
    # Trained on the record and four draws like it, validated on two more,
    # every target the median's free run.
    assert len(net.X_) == 5 and len(net.X_val_) == 2
    np.testing.assert_array_equal(net.X_[0], X)
    for x, target in zip(net.X_ + net.X_val_, net.y_ + net.y_val_, strict=True):
        np.testing.assert_array_equal(target, ensemble.simulate(x))
    assert not np.allclose(net.y_[0], y)  # the median's run, not the record
    draws = net.X_[1:] + net.X_val_
    for k, x in enumerate(draws):
        assert x.shape == X.shape and not np.allclose(x, X)
        assert X.min() <= x.min() and x.max() <= X.max()
        assert x.mean() == pytest.approx(X.mean(), abs=0.02)
        assert np.corrcoef(_spectrum(x), _spectrum(X))[0, 1] > 0.9
        assert not any(np.allclose(x, other) for other in draws[k + 1 :])
    # How far the network is from the median, over its validation draws.
    median = np.concatenate([ensemble.simulate(x) for x in net.X_val_])
    copied = np.concatenate([net.simulate(x) for x in net.X_val_])
    assert ensemble.network_median_error_ == pytest.approx(
        np.sqrt(np.mean(((copied - median) / median.std()) ** 2)), rel=1e-12
    )
    assert 0 < ensemble.network_median_error_ < 0.2
    # Linear members part from the median alike on any excitation.
    parted = [
        np.concatenate([m.simulate(x) for x in xs]) - np.concatenate(ts)
        for m in ensemble.estimators_
        for xs, ts in ((net.X_val_, net.y_val_), ([X], [net.y_[0]]))
    ]
    scales = (median.std(), net.y_[0].std())
    distance = [
        np.sqrt(np.mean((p / scales[k % 2]) ** 2)) for k, p in enumerate(parted)
    ]
    assert ensemble.draw_disagreement_ == pytest.approx(
        np.median(distance[0::2]) / np.median(distance[1::2]), rel=1e-12
    )
    assert 0.8 < ensemble.draw_disagreement_ < 1.2
    assert ensemble.network_record_error_ == pytest.approx(
        np.sqrt(np.mean(((net.simulate(X) - y) / y.std()) ** 2)), rel=1e-12
    )
    # Distilling changes no member; the network has a seed of its own, and
    # the whole is reproducible.
    plain = clone(ensemble).set_params(distil=False).fit(X, y)
    assert not hasattr(plain, "network_")
    assert [m.gain_ for m in plain.estimators_] == [
        m.gain_ for m in ensemble.estimators_
    ]
    assert net.random_state not in ensemble.member_random_states_
    again = clone(ensemble).fit(X, y).network_
    for a, b in zip(again.X_ + again.X_val_, net.X_ + net.X_val_, strict=True):
        np.testing.assert_array_equal(a, b)


def test_the_distilled_network_learns_the_validation_records_too():
    rng = np.random.default_rng(1)
    Xs = [rng.standard_normal((200, 1)), rng.standard_normal((300, 1))]
    ys = [x[:, 0] for x in Xs]
    Xv, yv = rng.standard_normal((150, 1)), np.zeros(150)
    ensemble = EnsembleRegressor(_Recorder(), n_members=2, distil=True, random_state=0)
    ensemble.fit(Xs, ys, X_val=Xv, y_val=yv)
    net = ensemble.network_
    # The records, X_val, and four draws like each training record.
    assert len(net.X_) == 3 + 4 * 2 and len(net.X_val_) == 2 * 2
    for given, x in zip([*Xs, Xv], net.X_[:3], strict=True):
        np.testing.assert_array_equal(given, x)
    assert [len(x) for x in net.X_[3:]] == [200, 300] * 4


def test_distilling_a_median_that_diverges_is_refused():
    X, y = _record(0)

    class _Diverging(_Recorder):
        def simulate(self, X, **kwargs):
            return np.full(len(X), np.nan)

    ensemble = EnsembleRegressor(_Diverging(), n_members=2, distil=True)
    with pytest.raises(ValueError, match="distil=True needs the median's free runs"):
        ensemble.fit(X, y)


def test_a_fit_without_distil_keeps_no_network_of_an_earlier_fit():
    from sysid_nn._estimators._ensemble import _NETWORK_ATTRIBUTES, one_network

    X, y = _record(0)
    ensemble = EnsembleRegressor(_Recorder(), n_members=3, distil=True, random_state=0)
    ensemble.fit(X, y)
    assert all(hasattr(ensemble, name) for name in _NETWORK_ATTRIBUTES)
    assert one_network(ensemble) is ensemble.network_
    # Refitted to other records without distil: the earlier network is no
    # network of this median, and nothing reads it as one.
    ensemble.set_params(distil=False).fit(X, 2 * y)
    assert not any(hasattr(ensemble, name) for name in _NETWORK_ATTRIBUTES)
    with pytest.raises(ValueError, match=r"median of 3 networks.*distil=True"):
        one_network(ensemble)
    # A network passes through.
    member = ensemble.estimators_[0]
    assert one_network(member) is member


@pytest.mark.filterwarnings("ignore:The linear model of:UserWarning")
@pytest.mark.filterwarnings("ignore::sklearn.exceptions.ConvergenceWarning")
def test_readouts_of_an_ensemble_name_the_network_to_pass():
    from sysid_nn import (
        backbone,
        frequency_response,
        instantaneous_frequency,
        modal_parameters,
        nonlinearity_test,
    )

    X, y = _record(0)
    ensemble = EnsembleRegressor(_net(), n_members=2, random_state=0).fit(X, y)
    for readout in (
        lambda m: modal_parameters(m, 0.01),
        lambda m: backbone(m, 0.01),
        lambda m: nonlinearity_test(m, X, y),
        lambda m: instantaneous_frequency(m, X, 0.01),
        lambda m: frequency_response(m, 0.01),
    ):
        with pytest.raises(TypeError, match=r"distil=True, then network_\) or a"):
            readout(ensemble)
        with pytest.raises(TypeError, match="got _Recorder"):
            readout(_Recorder(random_state=0).fit(X, y))
    # The network fitted to the median is read as any network.
    ensemble.set_params(distil=True).fit(X, y)
    assert len(modal_parameters(ensemble.network_, 0.01))


@pytest.mark.filterwarnings("ignore:The linear model of:UserWarning")
def test_a_distilled_network_is_a_network_the_file_keeps(tmp_path):
    from sysid_nn import load_model, save_model

    X, y = _record(0)
    ensemble = EnsembleRegressor(_net(), n_members=2, distil=True, random_state=0)
    ensemble.fit(X, y)
    assert isinstance(ensemble.network_, TDLRegressor)
    assert ensemble.network_.n_features_in_ == 1
    save_model(ensemble, tmp_path / "e.sysid")
    loaded = load_model(tmp_path / "e.sysid")
    np.testing.assert_array_equal(
        loaded.network_.simulate(X), ensemble.network_.simulate(X)
    )
    np.testing.assert_array_equal(loaded.simulate(X), ensemble.simulate(X))
    save_model(ensemble.network_, tmp_path / "n.sysid")
    np.testing.assert_array_equal(
        load_model(tmp_path / "n.sysid").simulate(X), ensemble.network_.simulate(X)
    )


class _PartsOffTheRecord(_Recorder):
    """Members that agree on the record they were fitted to and part, by a
    term of their own seed, wherever the excitation leaves it."""

    def fit(self, X, y, X_val=None, y_val=None):
        self.record_ = np.asarray(X, dtype=float)[:, 0]
        return super().fit(X, y, X_val, y_val)

    def simulate(self, X, **kwargs):
        if isinstance(X, list):
            return [self.simulate(x) for x in X]
        u = np.asarray(X, dtype=float)[:, 0]
        off = u - self.record_ if len(u) == len(self.record_) else u
        return u + 0.01 * self.gain_ + self.random_state / 1e9 * off


def test_members_that_part_off_the_records_are_warned_of(monkeypatch):
    from sysid_nn._estimators import _ensemble

    rng = np.random.default_rng(0)
    X = rng.standard_normal((400, 1))
    y = X[:, 0].copy()
    ensemble = EnsembleRegressor(
        _PartsOffTheRecord(), n_members=3, distil=True, random_state=0
    )
    with pytest.warns(UserWarning, match=r"part \d+\.\d times more under excitations"):
        ensemble.fit(X, y)
    ratio = ensemble.draw_disagreement_
    assert ratio > 5
    # Warned just where the ratio is above the limit.
    monkeypatch.setattr(_ensemble, "_DISAGREEMENT_WARNING", 1.01 * ratio)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        # This stand-in's network misses the records: warned of too.
        warnings.filterwarnings("ignore", "The network fitted")
        clone(ensemble).fit(X, y)
    monkeypatch.setattr(_ensemble, "_DISAGREEMENT_WARNING", 0.99 * ratio)
    with pytest.warns(UserWarning, match="draw_disagreement_"):
        clone(ensemble).fit(X, y)
    # Members that agree wherever they run: no warning at the default.
    monkeypatch.undo()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        EnsembleRegressor(_Recorder(), n_members=3, distil=True, random_state=0).fit(
            X, y + 0.5 * rng.standard_normal(400)
        )


class _OddSeedsMiss(_Recorder):
    """A stand-in whose networks fitted to a median (with ``X_val``) on an
    odd seed miss the records five times."""

    def fit(self, X, y, X_val=None, y_val=None):
        super().fit(X, y, X_val, y_val)
        if X_val is not None and self.random_state % 2:
            self.gain_ *= 5
        return self


def _network_seeds(random_state, n_members):
    rng = check_random_state(random_state)
    rng.randint(np.iinfo(np.int32).max, size=n_members)
    return rng.randint(np.iinfo(np.int32).max, size=3)


def test_a_network_that_misses_the_records_is_fitted_again_on_another_seed():
    rng = np.random.default_rng(0)
    X = rng.standard_normal((400, 1))
    y = X[:, 0] + 0.5 * rng.standard_normal(400)
    parity = {k: tuple(_network_seeds(k, 3) % 2) for k in range(40)}
    # The first network misses, the second fits: two attempts, the second kept.
    k = next(k for k, p in parity.items() if p[:2] == (1, 0))
    ensemble = EnsembleRegressor(_OddSeedsMiss(), n_members=3, distil=True)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ensemble.set_params(random_state=k).fit(X, y)
    errors, level = (
        ensemble.network_record_errors_,
        np.sort(ensemble.member_record_errors_)[0],
    )
    assert len(errors) == 2 and errors[0] > 3 * level >= errors[1]
    assert ensemble.network_.random_state == _network_seeds(k, 3)[1]
    assert ensemble.network_record_error_ == errors[1]
    # The first fits: one attempt.
    k = next(k for k, p in parity.items() if p[0] == 0)
    assert (
        len(clone(ensemble).set_params(random_state=k).fit(X, y).network_record_errors_)
        == 1
    )
    # Every attempt misses: the best kept, and warned.
    k = next(k for k, p in parity.items() if p == (1, 1, 1))
    with pytest.warns(UserWarning, match="network_record_errors_"):
        missed = clone(ensemble).set_params(random_state=k).fit(X, y)
    assert len(missed.network_record_errors_) == 3
    assert missed.network_record_error_ == missed.network_record_errors_.min()
    # max_error_ratio=None: the first network, whatever it fits.
    k = next(k for k, p in parity.items() if p[0] == 1)
    every = clone(ensemble).set_params(random_state=k, max_error_ratio=None)
    assert len(every.fit(X, y).network_record_errors_) == 1


@pytest.mark.filterwarnings("ignore:The linear model of:UserWarning")
@pytest.mark.filterwarnings("ignore::sklearn.exceptions.ConvergenceWarning")
def test_the_report_reads_the_structure_of_the_network_fitted_to_the_median():
    from sysid_nn.study._structure import structure_lines

    X, y = _record(0)
    Xv, yv = _record(1)
    ensemble = EnsembleRegressor(_net(), n_members=2, random_state=0).fit(X, y)
    (line,) = structure_lines(ensemble, [Xv], [yv], 0.01)
    assert line.startswith("No modes or non-linearity test: the model is the median")
    ensemble.set_params(distil=True).fit(X, y)
    lines = structure_lines(ensemble, [Xv], [yv], 0.01)
    assert lines[0] == "Of the network fitted to the ensemble's median (`network_`):"
    assert lines[2:] == structure_lines(ensemble.network_, [Xv], [yv], 0.01)
    assert any(line.startswith("| mode |") for line in lines)
