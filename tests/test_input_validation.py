"""Input checks shared by the recurrent estimators (the base class's rules)."""

from __future__ import annotations

import re
import warnings

import numpy as np
import pandas as pd
import pytest
from sklearn.base import clone
from sklearn.exceptions import ConvergenceWarning
from sklearn.utils.estimator_checks import check_dataframe_column_names_consistency

from sysid_nn import ISSMRegressor, TDLRegressor
from sysid_nn._estimators._issm import UnstablePredictorWarning

SMALL = {"hidden_layer_sizes": (3,), "n_init": 1, "max_iter": 6, "random_state": 0}


def _estimators():
    return [
        TDLRegressor(**SMALL),
        ISSMRegressor(**SMALL),
        ISSMRegressor(init="tdl", **SMALL),
    ]


def _ids(est):
    return f"{type(est).__name__}-{getattr(est, 'init', '')}"


ESTIMATORS = pytest.mark.parametrize("est", _estimators(), ids=_ids)


def _record(n=200, seed=0):
    rng = np.random.default_rng(seed)
    u = rng.standard_normal((n, 1))
    y = np.zeros(n)
    for t in range(2, n):
        y[t] = 1.2 * y[t - 1] - 0.5 * y[t - 2] + 0.4 * np.tanh(u[t - 1, 0])
    return u, y


@pytest.fixture(autouse=True)
def _quiet_training():
    # Few iterations on small data: not converging is expected here.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        warnings.simplefilter("ignore", UnstablePredictorWarning)
        yield


# --------------------------------------------------------------------------
# one minimum-length rule
# --------------------------------------------------------------------------
@ESTIMATORS
@pytest.mark.parametrize("n", [2, 3])
def test_too_short_sequences_are_rejected_by_every_estimator(est, n):
    u, y = _record()
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        with pytest.raises(ValueError, match=f"X has {n} samples; .* at least 4"):
            est.fit(u[:n], y[:n])
        with pytest.raises(ValueError, match=f"sequence 1 of X has {n} samples"):
            est.fit([u, u[:n]], [y, y[:n]])
        with pytest.raises(ValueError, match=f"X_val has {n} samples"):
            est.fit(u, y, X_val=u[:n], y_val=y[:n])


@pytest.mark.filterwarnings("ignore:The linear model of:UserWarning")
@ESTIMATORS
@pytest.mark.filterwarnings("ignore::sysid_nn.DivergenceWarning")  # 4 samples
def test_the_shortest_accepted_sequence_fits_without_numpy_warnings(est):
    u, y = _record()
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        est.fit(u[:4], y[:4])  # early stopping on: too short to split
        assert np.all(np.isfinite(est.predict(u[:4], y[:4])))
        est.fit([u[:4], u[:4], u], [y[:4], y[:4], y])
        assert np.all(np.isfinite(est.predict(u, y)))


def test_minimum_length_follows_the_structure():
    u, y = _record()
    # Six states for one output: the linear start is a 6-lag ARX fit.
    issm = ISSMRegressor(n_states=6, **SMALL)
    with pytest.raises(ValueError, match="at least 7 samples"):
        issm.fit(u[:6], y[:6])
    issm.fit(u[:7], y[:7])
    tdl = TDLRegressor(output_lags=2, input_lags=4, input_delay=2, **SMALL)
    with pytest.raises(ValueError, match="at least 6 samples"):
        tdl.fit(u[:5], y[:5])
    tdl.fit(u[:6], y[:6])


# --------------------------------------------------------------------------
# data that float64 cannot standardise
# --------------------------------------------------------------------------
@ESTIMATORS
@pytest.mark.parametrize(
    ("argument", "factor", "problem"),
    [
        ("y", 1e200, "overflows"),
        ("X", 1e200, "overflows"),
        ("y", 1e-200, "cannot square"),
        ("X", 1e-200, "cannot square"),
    ],
)
def test_unstandardisable_data_is_rejected_naming_the_argument(
    est, argument, factor, problem
):
    u, y = _record()
    X_bad, y_bad = (u * factor, y) if argument == "X" else (u, y * factor)
    message = f"{argument} cannot be standardised: column 0 .*{problem}"
    with pytest.raises(ValueError, match=message):
        est.fit(X_bad, y_bad)
    with pytest.raises(ValueError, match=message.replace(argument, argument + "_val")):
        est.fit(u, y, X_val=X_bad, y_val=y_bad)


@pytest.mark.parametrize("factor", [1e-13, 1e150])
def test_models_are_unit_free_over_the_usable_range(factor):
    # A tiny but varying input used to count as constant: the model was
    # blind to it. Every usable scale now gives the same model.
    u, y = _record()
    reference = TDLRegressor(**SMALL).fit(u, y).predict(u[:100])
    scaled_input = TDLRegressor(**SMALL).fit(u * factor, y).predict(u[:100] * factor)
    scaled_output = TDLRegressor(**SMALL).fit(u, y * factor).predict(u[:100])
    np.testing.assert_allclose(scaled_input, reference, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(scaled_output / factor, reference, rtol=1e-6, atol=1e-9)


@pytest.mark.filterwarnings("ignore:The linear model of:UserWarning")
@ESTIMATORS
def test_an_offset_channel_with_rounding_noise_is_a_constant(est):
    # A channel at a level of 1e6 that varies only in its last bits: left
    # unscaled, its rounding noise made the ISSM's linear start diverge.
    u, y = _record()
    bits = 1.0 + 4e-16 * np.random.default_rng(3).integers(0, 3, (len(u), 1))
    ones = clone(est).fit(np.hstack([u, np.ones_like(u)]), y)
    offset = clone(est).fit(np.hstack([u, 1e6 * bits]), y)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        reference = ones.predict(np.hstack([u, np.ones_like(u)]))
        np.testing.assert_allclose(
            offset.predict(np.hstack([u, 1e6 * bits])), reference, rtol=1e-6, atol=1e-9
        )


@ESTIMATORS
# Constant outputs: the linear model fits them as well as any network.
@pytest.mark.filterwarnings("ignore:The linear model of:UserWarning")
def test_constant_channels_stay_finite(est):
    u, y = _record()
    flat = np.hstack([u, np.full_like(u, 3.0)])
    est.fit(flat, np.full_like(y, 2.0))
    np.testing.assert_allclose(est.predict(flat), 2.0)
    est.fit(np.zeros_like(u), y)
    assert np.all(np.isfinite(est.predict(np.zeros_like(u))))
    # A constant far beyond where its square overflows is still a constant.
    est.fit(u, np.full_like(y, 1e300))
    np.testing.assert_allclose(est.predict(u), 1e300)


# --------------------------------------------------------------------------
# feature names, as scikit-learn checks them
# --------------------------------------------------------------------------
@pytest.mark.filterwarnings("ignore:The linear model of:UserWarning")
@ESTIMATORS
def test_scikit_learn_column_name_check(est):
    check_dataframe_column_names_consistency(type(est).__name__, est)


def _frames(names=("force",), n_seq=3):
    records = [_record(seed=s) for s in range(n_seq)]
    X = [pd.DataFrame(u, columns=list(names)) for u, _ in records]
    return X, [y for _, y in records]


@ESTIMATORS
def test_names_are_checked_by_every_method_after_a_fit_on_frames(est):
    X, y = _frames()
    est.fit(X, y)
    assert est.feature_names_in_.tolist() == ["force"]
    renamed = X[0].rename(columns={"force": "F"})
    unseen = re.escape(
        "The feature names should match those that were passed during fit.\n"
        "Feature names unseen at fit time:\n- F\n"
    )
    simulate = est.simulate
    for method in (est.predict, simulate, lambda X: est.score(X, y[0])):
        with pytest.raises(ValueError, match=unseen):
            method(renamed)
        with pytest.warns(UserWarning, match="X does not have valid feature names"):
            method(X[0].to_numpy())
    with pytest.raises(ValueError, match=unseen):
        est.predict(renamed, y[0], horizon=2)
    with pytest.raises(ValueError, match=r"X\[1\]: The feature names should match"):
        simulate([X[0], renamed])
    with pytest.raises(ValueError, match="The feature names should match"):
        est.fit(X[:2], y[:2], X_val=renamed, y_val=y[2])


@ESTIMATORS
def test_training_frames_must_agree_and_refits_forget_names(est):
    X, y = _frames()
    with pytest.raises(ValueError, match=r"(?s)X\[1\]: .*unseen at fit time:\n- F"):
        est.fit([X[0], X[1].rename(columns={"force": "F"})], y[:2])
    est.fit([x.to_numpy() for x in X], y)
    assert not hasattr(est, "feature_names_in_")
    with pytest.warns(UserWarning, match="X has feature names, but .* without"):
        est.predict(X[0])


def test_issm_state_estimates_check_names():
    X, y = _frames()
    est = ISSMRegressor(**SMALL).fit(X, y)
    with pytest.raises(ValueError, match="should match those that were passed"):
        est.predict_states(X[0].rename(columns={"force": "F"}), y[0])


# --------------------------------------------------------------------------
# structure and call arguments
# --------------------------------------------------------------------------
@ESTIMATORS
def test_an_int_hidden_layer_size_is_one_layer(est):
    u, y = _record()
    as_int = clone(est).set_params(hidden_layer_sizes=5).fit(u, y)
    as_tuple = clone(est).set_params(hidden_layer_sizes=(5,)).fit(u, y)
    assert as_int._sizes_.tolist() == as_tuple._sizes_.tolist()
    np.testing.assert_array_equal(as_int.coefs_, as_tuple.coefs_)


@pytest.mark.parametrize("cls", [TDLRegressor, ISSMRegressor])
@pytest.mark.parametrize("sizes", [(True,), True, (3, False), (3, 0), 0, -2])
def test_bools_and_non_positive_sizes_are_rejected(cls, sizes):
    u, y = _record()
    with pytest.raises(ValueError, match="hidden_layer_sizes"):
        cls(**{**SMALL, "hidden_layer_sizes": sizes}).fit(u, y)


@ESTIMATORS
@pytest.mark.parametrize("horizon", [0, -1, True, 1.0])
def test_bad_horizons_are_rejected_with_or_without_y(est, horizon):
    u, y = _record()
    est.fit(u, y)
    with pytest.raises(ValueError, match="horizon must be a positive integer"):
        est.predict(u, horizon=horizon)
    with pytest.raises(ValueError, match="horizon must be a positive integer"):
        est.predict(u, y, horizon=horizon)


@ESTIMATORS
def test_one_dimensional_X_shows_the_reshape_not_the_data(est):
    u, y = _record()
    for call in (lambda: est.fit(u[:, 0], y), lambda: est.fit([u, u[:, 0]], [y, y])):
        with pytest.raises(ValueError) as info:
            call()
        message = str(info.value)
        assert re.search(r"X(\[1\])?\.reshape\(-1, 1\)", message)
        assert "(200,)" in message
        # No values dumped, no advice that makes a record one time step.
        assert "array=" not in message and "reshape(1, -1)" not in message
        assert len(message) < 200
