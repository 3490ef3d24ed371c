"""Tests of the handling of field-like records: padding, amplitude, sampling."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy.signal import lfilter
from sklearn.exceptions import ConvergenceWarning

from sysid_nn import ISSMRegressor, TDLRegressor
from sysid_nn._records._record_checks import padded_length, samples_per_period


def _oscillator_records(n_records=3, n=1500, seed=0):
    """A lightly damped second-order system (about 60 samples per period)."""
    rng = np.random.default_rng(seed)
    Xs = [rng.standard_normal((n, 1)) for _ in range(n_records)]
    ys = [lfilter([0.0, 1e-3], [1.0, -1.98, 0.9891], X[:, 0]) for X in Xs]
    return Xs, ys


def _pad(X, y, k):
    X, y = X.copy(), y.copy()
    X[-k:] = 0.0
    y[-k:] = 0.0
    return X, y


@pytest.mark.parametrize("Model", [TDLRegressor, ISSMRegressor])
def test_zero_padded_record_ends_are_left_out_of_training(Model):
    Xs, ys = _oscillator_records()
    padded = [_pad(Xs[1], ys[1], 200), _pad(Xs[2], ys[2], 100)]
    X_pad = [Xs[0], padded[0][0], padded[1][0]]
    y_pad = [ys[0], padded[0][1], padded[1][1]]
    X_cut = [Xs[0], Xs[1][:-200], Xs[2][:-100]]
    y_cut = [ys[0], ys[1][:-200], ys[2][:-100]]
    kw = dict(hidden_layer_sizes=(), n_init=1, max_iter=6, random_state=0)
    with pytest.warns(
        UserWarning,
        match=r"sequence 1: the last 200 of 1500 samples; sequence 2: the last 100 ",
    ):
        on_padded = Model(**kw).fit(X_pad, y_pad)
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)
        warnings.simplefilter("ignore", ConvergenceWarning)
        on_cut = Model(**kw).fit(X_cut, y_cut)
    # The padding changes nothing: the same model as from the cut records,
    # with no noise read into the jump to zero.
    np.testing.assert_array_equal(on_padded.coefs_, on_cut.coefs_)
    np.testing.assert_array_equal(on_padded.output_noise_std_, on_cut.output_noise_std_)


def test_padding_is_only_an_exactly_zero_end_of_both_signals():
    X = np.ones((10, 2))
    y = np.ones(10)[:, None]
    assert padded_length(X, y) == 0
    X[-3:], y[-4:] = 0.0, 0.0
    assert padded_length(X, y) == 3  # where both are zero
    X[-2, 1] = 1e-300
    assert padded_length(X, y) == 1
    assert padded_length(np.zeros((5, 1)), np.zeros((5, 1))) == 5


def test_padding_keeps_the_shortest_record_a_fit_accepts():
    # The TDL's default lags read 3 past samples: 4 samples are kept.
    Xs, ys = _oscillator_records(n_records=1, n=200)
    X, y = _pad(Xs[0], ys[0], 198)
    model = TDLRegressor(
        hidden_layer_sizes=(), n_init=1, max_iter=2, early_stopping=False
    )
    with pytest.warns(UserWarning, match="the last 196 of 200 samples"):
        model.fit(X, y)
    assert np.all(np.isfinite(model.predict(X)))


@pytest.mark.parametrize("hidden", [(), (3,)])
def test_tdl_start_is_stable_when_fewer_lags_fit_exactly(hidden):
    # Noise-free records of a second-order system: the three-lag least-squares
    # ARX is free to add a cancelling pole-zero pair, and put it outside the
    # unit circle (a pole near 16 here). Its free run diverged from rounding,
    # every stage was skipped and the fit fell back to that same start.
    Xs, ys = _oscillator_records(n_records=4)
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)
        warnings.simplefilter("ignore", ConvergenceWarning)
        model = TDLRegressor(
            hidden_layer_sizes=hidden, n_init=1, max_iter=6, random_state=0
        ).fit(Xs[:3], ys[:3])
    assert model._arx_radius(model._arx) < 1.0
    y_sim = model.predict(Xs[3])
    assert np.sqrt(np.mean((y_sim - ys[3]) ** 2)) < 1e-3 * ys[3].std()


@pytest.mark.parametrize("period", [12.0, 60.0, 170.0, 400.0])
def test_samples_per_period_is_read_from_the_output_spectrum(period):
    # A lightly damped resonance under white excitation, with slow drift.
    rng = np.random.default_rng(0)
    w = 2 * np.pi / period
    a = [1.0, -2 * np.exp(-0.02 * w) * np.cos(w), np.exp(-0.04 * w)]
    ys = []
    for _ in range(3):
        y = lfilter([1.0], a, rng.standard_normal(6000))
        ys.append(y + 0.5 * y.std() * np.linspace(0, 1, 6000))
    Y = np.concatenate(ys)[:, None]
    assert samples_per_period(Y, [(0, 6000), (6000, 12000), (12000, 18000)]) == (
        pytest.approx(period, rel=0.05)
    )


def test_fit_warns_on_records_sampled_far_outside_the_defaults():
    rng = np.random.default_rng(0)
    X = rng.standard_normal((8000, 1))
    w = 2 * np.pi / 1000  # 1000 samples per period
    a = [1.0, -2 * np.exp(-0.02 * w) * np.cos(w), np.exp(-0.04 * w)]
    y = lfilter([0.0, 1e-6], a, X[:, 0])
    model = TDLRegressor(hidden_layer_sizes=(), n_init=1, max_iter=2)
    # Decimation by 50 would leave 160 samples; the advice keeps 2000.
    with pytest.warns(
        UserWarning, match=r"about \d{3,4} samples.*resample_poly\(a, 1, 3,"
    ):
        model.fit(X, y)
    Xs, ys = _oscillator_records(n_records=1)  # about 60 samples per period
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)
        warnings.simplefilter("ignore", ConvergenceWarning)
        model.fit(Xs[0], ys[0])


@pytest.mark.filterwarnings("ignore::sklearn.exceptions.ConvergenceWarning")
def test_noise_warning_tells_how_to_decimate_oversampled_records():
    # About 66 samples per period with 1 % noise: decimate by 3 (to 22); the
    # 6400 samples left after the validation tail allow that.
    Xs, ys = _oscillator_records(n_records=1, n=8000)
    y = ys[0] + 0.01 * ys[0].std() * np.random.default_rng(1).standard_normal(8000)
    # (shooting="auto" would train such records with free segment states and
    # not warn.)
    model = TDLRegressor(
        hidden_layer_sizes=(), n_init=1, max_iter=2, shooting="measured"
    )
    with pytest.warns(UserWarning, match=r"about 6\d samples per period.*1, 3, axis"):
        model.fit(Xs[0], y)


def test_tdl_start_keeps_the_pole_of_an_integrating_structure():
    # A position driven by a force through an integrator (as in EMPS): the
    # ARX pole sits at one, up to rounding. It is not an instability to cut
    # lags for; a start without output lags would not integrate at all.
    rng = np.random.default_rng(0)
    Xs = [rng.standard_normal((1500, 1)) for _ in range(3)]
    ys = [lfilter([0.0, 0.01], [1.0, -1.0], X[:, 0]) for X in Xs]
    model = TDLRegressor(
        hidden_layer_sizes=(), n_init=1, max_iter=2, early_stopping=False
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        model.fit(Xs[:2], ys[:2])
    assert model._arx_radius(model._arx) == pytest.approx(1.0, abs=1e-6)
    y_sim = model.predict(Xs[2])
    assert np.sqrt(np.mean((y_sim - ys[2]) ** 2)) < 1e-3 * ys[2].std()


def test_a_slow_motion_is_not_read_as_an_oscillation():
    # A smooth positioning trajectory (one slow swing per record) has no
    # resolved period: no estimate, so no advice to decimate it.
    t = np.linspace(0, 1, 8000)
    y = (np.sin(2 * np.pi * t) + 0.1 * t)[:, None]
    assert np.isnan(samples_per_period(y, [(0, 8000)]))
