"""ONNX export and the linear state-space system, against ``simulate``."""

import json
import sys
import warnings

import numpy as np
import onnxruntime as ort
import pytest
from scipy.signal import dlsim
from sklearn.base import clone

from sysid_nn import EnsembleRegressor, export_onnx, to_dlti

KINDS = [(kind, p) for kind in ("linear", "tdl", "issm") for p in (1, 2)]
IDS = [f"{kind}-{p}" for kind, p in KINDS]


def _session(path):
    return ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])


def _simulated(est, X):
    return est.simulate(X).reshape(len(X), -1)


@pytest.mark.parametrize("kind", KINDS, ids=IDS)
def test_onnx_free_run_equals_simulate(fitted_models, tmp_path, kind):
    est, X, _ = fitted_models[kind]
    path = tmp_path / "model.onnx"
    export_onnx(est, path)
    session = _session(path)
    assert [(i.name, i.shape) for i in session.get_inputs()] == [
        ("u", ["n_samples", est.n_features_in_])
    ]
    assert [o.name for o in session.get_outputs()] == ["y"]
    # A record the model was not fitted to, at another length.
    u = np.random.default_rng(5).standard_normal((411, X.shape[1]))
    for record in (X, u):
        (y_onnx,) = session.run(None, {"u": record})
        expected = _simulated(est, record)
        assert y_onnx.dtype == np.float64 and y_onnx.shape == expected.shape
        assert np.all(np.abs(y_onnx - expected) <= 1e-6 * expected.std(axis=0))


@pytest.mark.parametrize("kind", [("tdl", 2), ("issm", 2), ("linear", 1)])
def test_onnx_step_map_reproduces_the_free_run(fitted_models, tmp_path, kind):
    est, X, _ = fitted_models[kind]
    path = tmp_path / "step.onnx"
    export_onnx(est, path, step=True)
    session = _session(path)
    meta = session.get_modelmeta().custom_metadata_map
    assert meta["graph"] == "step" and meta["estimator"] == type(est).__name__
    rest = np.array(json.loads(meta["rest_state"]))
    # Two records side by side in one batch, each from the rest.
    records = [X[:120], X[120:240][::-1]]
    state = np.tile(rest, (2, 1))
    outputs = []
    for t in range(120):
        u = np.stack([r[t] for r in records])
        state, y = session.run(None, {"state": state, "u": u})
        outputs.append(y)
    outputs = np.stack(outputs, axis=1)
    for record, y in zip(records, outputs, strict=True):
        expected = _simulated(est, record)
        assert np.all(np.abs(y - expected) <= 1e-6 * expected.std(axis=0))


@pytest.mark.parametrize("p", [1, 2])
def test_dlti_of_the_linear_model_is_its_free_run(fitted_models, p):
    est, X, _ = fitted_models["linear", p]
    system = to_dlti(est, dt=0.01)
    assert system.dt == 0.01
    assert system.B.shape[1] == est.n_features_in_ and system.C.shape[0] == p
    expected = _simulated(est, X)
    _, response, _ = dlsim(system, X)
    response = response.reshape(len(X), -1)
    np.testing.assert_allclose(
        est.rest_output_ + response, expected, rtol=0, atol=1e-12 * expected.std()
    )
    # Impulse and step responses: the free run's deviation from rest.
    for u in (np.eye(60, 1), np.ones((60, 1))):
        U = np.hstack([u, np.zeros((60, est.n_features_in_ - 1))])
        _, response, _ = dlsim(system, U)
        deviation = _simulated(est, U) - est.rest_output_
        np.testing.assert_allclose(
            response.reshape(60, -1), deviation, rtol=0, atol=1e-12
        )


@pytest.mark.parametrize("kind", [("tdl", 1), ("tdl", 2), ("issm", 2)], ids=str)
def test_dlti_of_a_network_is_its_small_amplitude_response(fitted_models, kind):
    est, X, _ = fitted_models[kind]
    system = to_dlti(est)
    errors = []
    for amplitude in (1e-3, 1e-4):
        U = amplitude * X[:150]
        deviation = _simulated(est, U) - est.rest_output_
        _, response, _ = dlsim(system, U)
        error = np.abs(response.reshape(150, -1) - deviation).max()
        errors.append(error / np.abs(deviation).max())
    # First-order right: the relative error is small and falls with the
    # amplitude (the neglected terms are of second order).
    assert errors[0] < 1e-2
    assert errors[1] < 0.2 * errors[0]
    # A network is no linear model: at full amplitude the response differs.
    deviation = _simulated(est, X) - est.rest_output_
    _, response, _ = dlsim(system, X)
    assert np.abs(response.reshape(len(X), -1) - deviation).max() > 1e-3


def test_dlti_warns_without_a_rest(fitted_models):
    import copy

    est = copy.deepcopy(fitted_models["issm", 2][0])
    assert est.rest_check_.start == "rest"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        to_dlti(est)
    # As a model that does not settle has it: from zero, or on its cycle.
    est.rest_output_ = None
    for start in ("zero", "cycle"):
        est.rest_check_.start = start
        with pytest.warns(UserWarning, match="no rest"):
            to_dlti(est)


def test_export_needs_a_fitted_estimator_and_onnx(fitted_models, tmp_path, monkeypatch):
    from sklearn.exceptions import NotFittedError
    from sklearn.linear_model import Ridge

    from sysid_nn import ISSMRegressor

    with pytest.raises(TypeError, match="TDLRegressor or an ISSMRegressor"):
        export_onnx(Ridge(), tmp_path / "m.onnx")
    est, X, y = fitted_models["tdl", 1]
    ensemble = EnsembleRegressor(clone(est), n_members=2, random_state=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ensemble.fit(X, y)
    with pytest.raises(TypeError, match=r"distil=True, then network_\) or a member"):
        export_onnx(ensemble, tmp_path / "m.onnx")
    with pytest.raises(TypeError, match="got an EnsembleRegressor"):
        to_dlti(ensemble)
    with pytest.raises(NotFittedError):
        to_dlti(ISSMRegressor())
    monkeypatch.setitem(sys.modules, "onnx", None)  # not installed
    est, _, _ = fitted_models["tdl", 1]
    with pytest.raises(ImportError, match=r"sysid_nn\[onnx\]"):
        export_onnx(est, tmp_path / "m.onnx")
    assert not (tmp_path / "m.onnx").exists()


def test_onnx_of_delays_and_direct_feedthrough(tmp_path):
    """Lag representations, input delays 0 and 2, the logistic activation."""
    from sysid_nn import ISSMRegressor, TDLRegressor

    rng = np.random.default_rng(1)
    X = rng.standard_normal((250, 1))
    y = np.convolve(np.tanh(X[:, 0]), [0.4, 0.3, 0.2])[:250]
    small = {"n_init": 1, "max_iter": 3, "random_state": 0}
    models = [
        TDLRegressor(
            output_lags=2,
            input_lags=2,
            input_delay=0,
            activation="logistic",
            lag_representation="delays",
            hidden_layer_sizes=(3, 2),
            **small,
        ),
        TDLRegressor(
            output_lags=1, input_lags=3, input_delay=2, hidden_layer_sizes=(2,), **small
        ),
        ISSMRegressor(n_states=2, input_delay=0, hidden_layer_sizes=(3,), **small),
        ISSMRegressor(n_states=2, input_delay=2, hidden_layer_sizes=(3,), **small),
    ]
    for est in models:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            est.fit(X, y)
        export_onnx(est, tmp_path / "m.onnx")
        (y_onnx,) = _session(tmp_path / "m.onnx").run(None, {"u": X})
        expected = _simulated(est, X)
        assert np.all(np.abs(y_onnx - expected) <= 1e-6 * expected.std()), est
