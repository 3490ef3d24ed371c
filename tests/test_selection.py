"""Tests of model selection: the linear candidate, validation from rest,
bounded free runs."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy.signal import lfilter
from sklearn.exceptions import ConvergenceWarning

from sysid_nn import ISSMRegressor, TDLRegressor


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


def _nrmse(model, X, y):
    return np.sqrt(np.mean((model.simulate(X) - y) ** 2)) / y.std()


@pytest.mark.parametrize(
    ("cls", "params", "seed"),
    [(TDLRegressor, dict(output_lags=2, input_lags=2), 6), (ISSMRegressor, {}, 21)],
)
def test_linear_model_is_returned_where_no_restart_beats_it(cls, params, seed):
    # Noisy records of a linear system: the networks' restarts fit the noise
    # and validate worse than the linear output-error model (measured).
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


def test_validation_record_from_rest_judges_as_the_tail_within_the_record():
    # Slow dynamics: a validation record cut from the motion and simulated
    # from rest starts with a long transient that is no fault of the model.
    X, y, _ = _linear_record(3, n=1000, noise=0.01, poles=(-1.8, 0.85))
    n = 800
    model = dict(output_lags=2, input_lags=2, n_init=1, max_iter=30, random_state=0)
    within = TDLRegressor(**model).fit(X, y)
    apart = TDLRegressor(**model).fit(X[:n], y[:n], X_val=X[n:], y_val=y[n:])
    ratio = apart.best_validation_score_ / within.best_validation_score_
    assert 1 / 1.5 < ratio < 1.5


def test_restart_that_diverges_beyond_the_training_range_is_not_chosen():
    from sysid_nn._selection import bounded_beyond_range, choose
    from sysid_nn._training import _Run

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
    # Within the training range the two are the same model.
    np.testing.assert_allclose(
        model._run(bad, train, 1, False)[0], model._run(good, train, 1, False)[0]
    )
    runs = [
        _Run(bad, 0.0, 0.5, 0.5, 1, True, [], 0),
        _Run(good, 0.0, 1.0, 1.0, 1, True, [], 0),
    ]
    chosen, selected = choose(model, train, None, runs, None)
    assert chosen.w is good
    assert selected == "restart"


def test_burn_in_only_for_records_that_start_in_motion():
    from sysid_nn._selection import burn_in

    X, y, _ = _linear_record(3, n=1000, noise=0.01, poles=(-1.8, 0.85))
    model = TDLRegressor(
        output_lags=2, input_lags=2, hidden_layer_sizes=(), max_iter=30,
        random_state=0,
    ).fit(X, y)  # fmt: skip
    at_rest = model._stack([X[:200]], [y[:200, None]])
    in_motion = model._stack([X[600:800]], [y[600:800, None]])
    assert burn_in(model, model.coefs_, at_rest) == 0
    # The slowest mode (radius 0.92) takes about 80 samples to fall to 0.1 %.
    assert 40 <= burn_in(model, model.coefs_, in_motion) <= 100
