"""Tests of the innovation state-space network (ISSMRegressor)."""

from __future__ import annotations

import copy
import pickle
import threading
import warnings

import joblib
import numpy as np
import pytest
import threadpoolctl
from scipy.linalg import solve_discrete_are
from scipy.signal import lfilter
from sklearn.exceptions import ConvergenceWarning, NotFittedError
from sklearn.model_selection import GridSearchCV, KFold
from sklearn.utils.estimator_checks import parametrize_with_checks

from sysid_nn import DivergenceWarning, ISSMRegressor
from sysid_nn._engine._innovation import predictor_radius, refit_innovations
from sysid_nn._estimators._issm import UnstablePredictorWarning
from sysid_nn._estimators._issm_realisation import realise_tdl
from sysid_nn._records._data import _FREE_RUN


# --------------------------------------------------------------------------
# a slow NumPy twin of the recurrence, written from the equations
# --------------------------------------------------------------------------
def _twin_mlp(w, sizes, activation, bypass, z):
    f = np.tanh if activation == "tanh" else (lambda s: 1.0 / (1.0 + np.exp(-s)))
    a, pos = z, 0
    for i in range(len(sizes) - 1):
        n_in, n_out = sizes[i], sizes[i + 1]
        W = w[pos : pos + n_in * n_out].reshape(n_out, n_in)
        pos += n_in * n_out
        s = W @ a + w[pos : pos + n_out]
        pos += n_out
        a = s if i == len(sizes) - 2 else f(s)
    if bypass:
        a = a + w[pos:].reshape(sizes[-1], sizes[0]) @ z
    return a


def _twin_run(est, w, data, seg_len, filt=False):
    """Outputs of the modelled rows, stacked, by a plain Python loop.

    With ``filt``, segments start from the one-step predictor run beside the
    simulation, which also gives the first segment.
    """
    n, p, nk = est.n_states_, est.n_outputs_, est.input_delay
    sizes, bypass = list(est._sizes_), est._bypass()
    filt = filt and 1 < seg_len < _FREE_RUN
    out = []
    for a, b in zip(data.starts[:-1], data.starts[1:], strict=True):
        x = np.zeros(n)
        x[:p] = data.Y[a + data.h - 1]
        xf = x.copy()
        for t in range(a + data.h, b):
            k = t - a - data.h
            if filt:
                zf = np.concatenate([xf, data.U[t - nk], data.Y[t - 1] - xf[:p]])
                xf = _twin_mlp(w, sizes, est.activation, bypass, zf)
                if k < seg_len or k % seg_len == 0:
                    x = xf
                    out.append(x[:p])
                    continue
            e = np.zeros(p)
            if seg_len == 1:
                e = data.Y[t - 1] - x[:p]
            elif k > 0 and k % seg_len == 0:
                x = x.copy()
                x[:p] = data.Y[t - 1]
            z = np.concatenate([x, data.U[t - nk], e])
            x = _twin_mlp(w, sizes, est.activation, bypass, z)
            out.append(x[:p])
    return np.array(out)


def _small_fitted(p, hidden=(4,), n_states=3, activation="tanh", linear_part=True):
    rng = np.random.default_rng(p)
    X = [rng.standard_normal((n, 2)) for n in (31, 24, 40)]
    y = [np.cumsum(rng.standard_normal((len(x), p)), axis=0) * 0.1 for x in X]
    est = ISSMRegressor(
        n_states=n_states, hidden_layer_sizes=hidden, activation=activation,
        linear_part=linear_part, n_init=1, max_iter=1, early_stopping=False,
        random_state=0,
    )  # fmt: skip
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        warnings.filterwarnings(
            "ignore", "A linear one-step model leaves a white misfit", UserWarning
        )
        est.fit(X, y)
    data = est._stack(
        [np.asarray(x) for x in X], [np.asarray(v).reshape(len(v), -1) for v in y]
    )
    w = est.coefs_ + 0.05 * rng.standard_normal(len(est.coefs_))
    return est, data, w


MODES = [1, 7, _FREE_RUN]
CASES = [
    (1, (4,), "tanh", True),
    (2, (4,), "logistic", True),
    (2, (3, 2), "tanh", False),
    (1, (), "tanh", True),
]


@pytest.mark.parametrize("filt", [False, True])
@pytest.mark.parametrize("seg_len", MODES)
@pytest.mark.parametrize(("p", "hidden", "activation", "linear_part"), CASES)
def test_kernel_matches_twin_and_finite_differences(
    seg_len, p, hidden, activation, linear_part, filt
):
    """Filtered segment starts (``filt``) included: gradients through the filter."""
    est, data, w = _small_fitted(p, hidden, 3, activation, linear_part)
    est.shooting_ = "filter" if filt else "measured"
    rows = data.modelled
    Yhat, J, diverged, state = est._run(w, data, seg_len, True)
    assert (diverged < 0).all()
    # Forward pass: the numba kernel against the NumPy twin.
    np.testing.assert_allclose(
        Yhat[rows], _twin_run(est, w, data, seg_len, filt), rtol=1e-12, atol=1e-12
    )
    # Jacobian (eq. 10 sensitivities) against central differences of the twin.
    eps = 1e-6
    fd = np.empty_like(J)
    for c in range(len(w)):
        dw = np.zeros(len(w))
        dw[c] = eps
        up = _twin_run(est, w + dw, data, seg_len, filt)
        down = _twin_run(est, w - dw, data, seg_len, filt)
        fd[:, c] = ((up - down) / (2 * eps)).ravel()
    rel = np.linalg.norm(J - fd) / np.linalg.norm(fd)
    assert rel < 1e-6, rel
    # Adjoint gradient of 0.5 ||yhat - y||^2 against J^T r.
    r = (Yhat[rows] - data.Y[rows]).ravel()
    grad = est._gradient(w, data, seg_len, state)
    np.testing.assert_allclose(
        grad, J.T @ r, rtol=1e-9, atol=1e-10 * np.abs(J.T @ r).max()
    )


# --------------------------------------------------------------------------
# the linear innovation model is the steady-state Kalman predictor
# --------------------------------------------------------------------------
A_TRUE = np.array([[1.5, -0.7], [1.0, 0.0]])
B_TRUE = np.array([1.0, 0.0])
C_TRUE = np.array([[0.5, 0.3]])
Q_TRUE = np.diag([0.2, 0.05])
R_TRUE = np.array([[0.3]])


def _linear_gaussian(n, seed):
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n)
    w = rng.multivariate_normal(np.zeros(2), Q_TRUE, size=n)
    v = rng.normal(0.0, np.sqrt(R_TRUE[0, 0]), size=n)
    x = np.zeros(2)
    y = np.empty(n)
    for t in range(n):
        y[t] = C_TRUE[0] @ x + v[t]
        x = A_TRUE @ x + B_TRUE * u[t] + w[t]
    return u[:, None], y


def _kalman_predictor():
    P = solve_discrete_are(A_TRUE.T, C_TRUE.T, Q_TRUE, R_TRUE)
    S = float((C_TRUE @ P @ C_TRUE.T + R_TRUE)[0, 0])
    K = A_TRUE @ P @ C_TRUE.T / S
    return S, K


def _kalman_errors(u, y, K):
    x = np.zeros(2)
    e = np.empty(len(y))
    for t in range(len(y)):
        e[t] = y[t] - C_TRUE[0] @ x
        x = A_TRUE @ x + B_TRUE * u[t, 0] + K[:, 0] * e[t]
    return e


def test_linear_issm_is_the_kalman_predictor():
    u, y = _linear_gaussian(20000, 0)
    u_test, y_test = _linear_gaussian(20000, 1)
    S, K = _kalman_predictor()
    model = ISSMRegressor(
        n_states=2, hidden_layer_sizes=(), focus="prediction", n_init=1,
        max_iter=60, early_stopping=False, random_state=0,
    ).fit(u, y)  # fmt: skip
    e_model = y_test - model.predict(u_test, y_test)
    e_kalman = _kalman_errors(u_test, y_test, K)
    skip = 50  # both start from a zero state
    ratio = np.var(e_model[skip:]) / S
    ratio_kalman = np.var(e_model[skip:]) / np.var(e_kalman[skip:])
    assert abs(ratio - 1.0) < 0.03, ratio
    assert ratio_kalman < 1.01, ratio_kalman
    # The learned predictor Phi - K H has the Kalman predictor's poles
    # (coordinates differ; eigenvalues do not).
    lin = model.predict_states(u_test, y_test)
    H = np.array([[1.0, 0.0]])
    M = lin.Phi[100] - lin.K[100] @ H
    learned = np.sort_complex(np.linalg.eigvals(M))
    true = np.sort_complex(np.linalg.eigvals(A_TRUE - K @ C_TRUE))
    np.testing.assert_allclose(learned, true, atol=0.03)
    assert model.predictor_spectral_radius_ == pytest.approx(
        np.abs(true).max(), abs=0.03
    )


# --------------------------------------------------------------------------
# the hysteretic oscillator: the unmeasured state is the hysteretic Z
# --------------------------------------------------------------------------
def _nrmse(pred, true):
    return np.sqrt(np.mean((pred - true) ** 2, axis=0)) / np.std(true, axis=0)


@pytest.mark.slow
def test_oscillator_displacement_and_velocity_measured():
    from sysid_nn import HystereticOscillator

    rec = HystereticOscillator().generate(10, random_state=0)
    X = [f[:, None] for f in rec.excitation]
    Y = [np.column_stack(dv) for dv in zip(rec.displacement, rec.velocity, strict=True)]
    train, val, test = slice(0, 3), slice(3, 4), slice(6, 10)
    scores = {}
    for name, hidden in [("linear", ()), ("network", (7,))]:
        model = ISSMRegressor(hidden_layer_sizes=hidden, n_init=2, random_state=0)
        model.fit(X[train], Y[train], X_val=X[val], y_val=Y[val])
        sim = model.simulate(X[test])
        one = model.predict(X[test], Y[test])
        k20 = model.predict(X[test], Y[test], horizon=20)
        assert all(np.all(np.isfinite(a)) for a in [*sim, *one, *k20])
        scores[name] = {
            "sim": np.median(
                [_nrmse(a, b)[0] for a, b in zip(sim, Y[test], strict=True)]
            ),
            "one": np.median(
                [_nrmse(a, b)[0] for a, b in zip(one, Y[test], strict=True)]
            ),
            "k20": np.median(
                [_nrmse(a, b)[0] for a, b in zip(k20, Y[test], strict=True)]
            ),
        }
        assert model.predictor_spectral_radius_ < 1.0
        # Stable, yet still a filter: the innovations are fed back.
        assert np.any(model.coefs_[model._innovation_index()] != 0.0)
    lin, net = scores["linear"], scores["network"]
    # Free run and 20-step prediction: an order of magnitude better.
    assert net["sim"] < 0.1 * lin["sim"], scores
    assert net["k20"] < 0.2 * lin["k20"], scores
    # One step at dt = 0.01 is nearly trivial for both (NRMSE ~1e-5).
    assert net["one"] < 1e-3, scores
    # The unmeasured state tracks the hysteretic component Z.
    r = []
    for x, y, z in zip(X[test], Y[test], rec.hysteretic[test], strict=True):
        states = model.predict_states(x, y).states
        r.append(abs(np.corrcoef(states[:, 2], z)[0, 1]))
    assert np.median(r) > 0.8, r
    print(f"\nscores {scores}, |r(state 3, Z)| median {np.median(r):.3f}")


# --------------------------------------------------------------------------
# scikit-learn conformance
# --------------------------------------------------------------------------
ROWS_ARE_TIME = "rows are time steps of a recurrence, not independent samples"


@pytest.mark.filterwarnings("ignore:The linear model of:UserWarning")
@parametrize_with_checks(
    [
        ISSMRegressor(hidden_layer_sizes=(3,), n_init=1, max_iter=6, random_state=0),
        ISSMRegressor(
            init="tdl", hidden_layer_sizes=(3,), n_init=1, max_iter=6, random_state=0
        ),
    ],
    expected_failed_checks=lambda est: {
        "check_methods_subset_invariance": ROWS_ARE_TIME,
        "check_methods_sample_order_invariance": ROWS_ARE_TIME,
    },
)
@pytest.mark.filterwarnings("ignore::sysid_nn.DivergenceWarning")  # tiny checks' data
def test_sklearn_compatible(estimator, check):
    with warnings.catch_warnings():
        # Few iterations on random data: not converging is expected here.
        warnings.simplefilter("ignore", UnstablePredictorWarning)
        warnings.simplefilter("ignore", ConvergenceWarning)
        warnings.filterwarnings(
            "ignore", "A linear one-step model leaves a white misfit", UserWarning
        )
        check(estimator)


def _sequences(n_seq=6, n=120, p=2, seed=0):
    rng = np.random.default_rng(seed)
    X = [rng.standard_normal((n, 1)) for _ in range(n_seq)]
    y = []
    for u in X:
        x = np.zeros(3)
        out = np.empty((n, p))
        for t in range(n):
            out[t] = x[:p]
            x = np.array(
                [0.9 * x[0] + 0.1 * x[1], -0.2 * x[0] + 0.8 * x[1], 0.5 * x[2]]
            )
            x += np.array([0.0, u[t, 0], np.tanh(x[1])])
        y.append(out)
    return X, y


def test_grid_search_over_structure_with_kfold_on_sequences():
    X, y = _sequences()
    search = GridSearchCV(
        ISSMRegressor(n_init=1, max_iter=5, random_state=0),
        {"hidden_layer_sizes": [(), (3,)], "n_states": [2, 3]},
        cv=KFold(3),
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        warnings.filterwarnings(
            "ignore", "A linear one-step model leaves a white misfit", UserWarning
        )
        search.fit(X, y)
    assert search.best_params_["n_states"] in (2, 3)
    assert np.isfinite(search.best_score_)


def test_pickle_and_joblib_round_trips(tmp_path):
    X, y = _sequences(3)
    model = ISSMRegressor(n_init=1, max_iter=5, random_state=0).fit(X, y)
    path = tmp_path / "issm.joblib"
    joblib.dump(model, path)
    for clone in (pickle.loads(pickle.dumps(model)), joblib.load(path)):
        np.testing.assert_array_equal(clone.simulate(X[0]), model.simulate(X[0]))
        np.testing.assert_array_equal(
            clone.predict(X[0], y[0]), model.predict(X[0], y[0])
        )
        a, b = clone.predict_states(X[0], y[0]), model.predict_states(X[0], y[0])
        np.testing.assert_array_equal(a.K, b.K)


def test_outputs_mirror_inputs_and_initial_state():
    X, y = _sequences(3)
    model = ISSMRegressor(n_init=1, max_iter=5, random_state=0).fit(X, y)
    assert isinstance(model.simulate(X), list)
    assert model.simulate(X[0]).shape == y[0].shape
    res = model.predict_states(X, y)
    assert len(res) == 3
    assert model.n_states_ == 4  # default: two states beyond the p = 2 measured
    assert res[0].states.shape == (120, 4)
    assert res[0].Phi.shape == (120, 4, 4)
    assert res[0].K.shape == (120, 4, 2)
    start = model.simulate(X[0], initial_state=[1.0, -1.0, 0.5, 0.0])
    assert not np.allclose(start[:5], model.simulate(X[0])[:5])
    # Measured states in the user's units: the state outputs are the predictions.
    np.testing.assert_allclose(
        model.predict_states(X[0], y[0]).states[:, :2], model.predict(X[0], y[0])
    )
    # A horizon longer than the record is the free run from the same start.
    np.testing.assert_allclose(
        model.predict(X[0], y[0], horizon=10_000),
        model.simulate(X[0], initial_state=np.zeros(4)),
    )


def test_unmeasured_state_coordinates_do_not_change_the_simulation():
    # The unmeasured states live in the network's own coordinates: scaling one
    # of them changes the states, not the outputs, and must not make a bounded
    # run count as divergent (the guard bounds the outputs, not every state).
    X, y = _sequences(3)
    model = ISSMRegressor(
        n_states=4, hidden_layer_sizes=(5,), n_init=1, max_iter=5, random_state=0
    ).fit(X, y)
    reference = model.predict_states(X[0], y[0]).states
    j = 3  # an unmeasured state, taken far beyond the outputs' range
    c = 1e3 * model._bound / np.abs(reference[:, j]).max()
    w = model.coefs_.copy()
    layout = model._layout()
    (W1, _), (W2, b2) = layout.matrices(w)
    bypass = layout.bypass_matrix(w)
    W1[:, j] /= c
    bypass[:, j] /= c
    W2[j] *= c
    b2[j] *= c
    bypass[j] *= c
    scaled = copy.deepcopy(model)
    scaled.coefs_ = w
    with warnings.catch_warnings():
        warnings.simplefilter("error", DivergenceWarning)
        sim = scaled.simulate(X)
        states = scaled.predict_states(X[0], y[0]).states
    for a, b in zip(sim, model.simulate(X), strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(states[:, :j], reference[:, :j], rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(states[:, j], c * reference[:, j], rtol=1e-6)
    assert np.abs(states[:, j]).max() > scaled._bound


def test_innovation_refit_leaves_free_run_unchanged():
    X, y = _sequences(3)
    model = ISSMRegressor(n_init=1, max_iter=8, random_state=0).fit(X, y)
    data = model._stack(X, y)
    stale = model.coefs_.copy()
    stale[model._innovation_index()] = 0.0
    before = model._run(stale, data, _FREE_RUN, False)[0]
    refit = refit_innovations(model, stale, data, None)
    np.testing.assert_array_equal(model._run(refit, data, _FREE_RUN, False)[0], before)
    one = model._run(refit, data, 1, False)[0]
    one_stale = model._run(stale, data, 1, False)[0]
    rows = data.modelled
    assert np.mean((one - data.Y)[rows] ** 2) < np.mean((one_stale - data.Y)[rows] ** 2)


def test_unstable_predictor_warns():
    X, y = _sequences(2)
    model = ISSMRegressor(n_init=1, max_iter=5, random_state=0).fit(X, y)
    data = model._stack(X, y)
    bad = model.coefs_.copy()
    bad[model._innovation_index()] *= -3.0  # over-correcting innovations
    model.coefs_ = bad
    assert predictor_radius(model, bad, data) > 1.0
    model.focus = "prediction"  # keep _after_fit from repairing it
    with pytest.warns(UnstablePredictorWarning, match="spectral radius"):
        model._after_fit(data, None)


@pytest.mark.parametrize(
    ("X", "y", "params", "match"),
    [
        (np.full((50, 1), np.nan), np.zeros(50), {}, "NaN"),
        (np.zeros(50), np.zeros(50), {}, "Reshape"),
        (np.zeros((1, 1)), np.zeros(1), {}, "1 sample"),
        (np.zeros((50, 1)), np.zeros((50, 3)), {"n_states": 2}, "n_states >= 3"),
    ],
)
def test_bad_input_is_explained(X, y, params, match):
    with pytest.raises(ValueError, match=match):
        ISSMRegressor(n_init=1, max_iter=2, **params).fit(X, y)


# --------------------------------------------------------------------------
# start from a TDL network realised in state space
# --------------------------------------------------------------------------
TDL_CASES = [
    # (outputs, inputs, hidden, activation, input_delay)
    (1, 1, (4,), "tanh", 1),
    (2, 2, (3, 2), "logistic", 0),
    (1, 1, (), "tanh", 2),
]


def _tdl_records(p, m, n_seq=3, n=150, seed=0):
    rng = np.random.default_rng(seed)
    X = [rng.standard_normal((n, m)) + 0.5 for _ in range(n_seq)]
    y = []
    for u in X:
        x = np.zeros(2)
        out = np.empty((n, 2))
        for t in range(n):
            out[t] = x
            x = np.array([1.2 * x[0] - 0.5 * x[1], x[0]]) + 0.3 * u[t].sum()
            x[0] += 0.2 * np.tanh(2.0 * x[0])
        y.append(out[:, :p] + 1.0)
    return X, y


@pytest.mark.filterwarnings("ignore:The linear model of:UserWarning")
@pytest.mark.filterwarnings("ignore::sklearn.exceptions.ConvergenceWarning")
@pytest.mark.parametrize(("p", "m", "hidden", "activation", "delay"), TDL_CASES)
def test_tdl_start_runs_exactly_as_its_tdl(p, m, hidden, activation, delay):
    X, y = _tdl_records(p, m)
    params = dict(
        hidden_layer_sizes=hidden, activation=activation, input_delay=delay,
        init="tdl", n_init=2, max_iter=6, random_state=0,
    )  # fmt: skip
    # With the prediction focus no innovation gain is refitted: the one-step
    # predictor is the TDL's too (measured outputs in every lag).
    model = ISSMRegressor(focus="prediction", **params).fit(X[:2], y[:2])
    Xn, yn = X[2], y[2]
    assert model.n_states_ == 3 * p + 2 * m
    # The TDL's restarts, and its refinement of the linear model where it is
    # a network, or its closed-form fit where it is linear.
    refined = 2 if len(hidden) else None
    assert len(model.restart_scores_) == 3
    assert model.tdl_.refined_restart_ == refined == model.refined_restart_
    assert model.tdl_.closed_form_restarts_ == ([] if len(hidden) else [2])
    np.testing.assert_allclose(model.simulate(Xn), model.tdl_.simulate(Xn), atol=1e-10)
    for k in (1, 5):
        np.testing.assert_allclose(
            model.predict(Xn, yn, horizon=k),
            model.tdl_.predict(Xn, yn, horizon=k),
            atol=1e-10,
        )
    # The realisation holds in any internal units of the state-space model.
    model._y_mean, model._y_scale = model._y_mean + 0.7, model._y_scale * 3.0
    model._x_mean, model._x_scale = model._x_mean - 0.4, model._x_scale * 0.5
    model.coefs_, _ = realise_tdl(model, model.tdl_)
    np.testing.assert_allclose(model.simulate(Xn), model.tdl_.simulate(Xn), atol=1e-9)
    np.testing.assert_allclose(
        model.predict(Xn, yn), model.tdl_.predict(Xn, yn), atol=1e-9
    )
    # The simulation focus refits the innovation gain and keeps the free run.
    model = ISSMRegressor(**params).fit(X[:2], y[:2])
    np.testing.assert_allclose(model.simulate(Xn), model.tdl_.simulate(Xn), atol=1e-10)
    assert model.predictor_spectral_radius_ < 1.0
    # A later fit from the ARX start leaves no TDL behind.
    assert not hasattr(model.set_params(init="arx").fit(X[:2], y[:2]), "tdl_")


def test_grid_search_chooses_the_start():
    X, y = _tdl_records(1, 1, n_seq=6)
    search = GridSearchCV(
        ISSMRegressor(n_init=1, max_iter=5, random_state=0),
        {"init": ["arx", "tdl"]},
        cv=KFold(3),
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        warnings.filterwarnings(
            "ignore", "A linear one-step model leaves a white misfit", UserWarning
        )
        warnings.simplefilter("ignore", DivergenceWarning)  # the arx start diverges
        search.fit(X, y)
    scores = search.cv_results_["mean_test_score"]
    assert np.all(np.isfinite(scores))
    assert search.best_params_["init"] == ["arx", "tdl"][int(np.argmax(scores))]
    best = search.best_estimator_
    # The TDL start's five states, or the order the records show.
    assert best.n_states_ == (
        5 if search.best_params_["init"] == "tdl" else best.order_selection_.n_states
    )


@pytest.mark.parametrize(
    ("params", "match"),
    [
        ({"n_states": 3}, "n_states = 5"),
        ({"linear_part": False}, "linear_part=True"),
        ({"init": "pca"}, "init"),
    ],
)
def test_tdl_start_explains_bad_settings(params, match):
    X, y = _tdl_records(1, 1)
    with pytest.raises(ValueError, match=match):
        ISSMRegressor(init="tdl", n_init=1, max_iter=2).set_params(**params).fit(X, y)


def test_bad_calls_after_fit():
    X, y = _sequences(2)
    with pytest.raises(NotFittedError):
        ISSMRegressor().predict(X[0])
    model = ISSMRegressor(n_init=1, max_iter=3, random_state=0).fit(X, y)
    with pytest.raises(ValueError, match="expecting 1 features"):
        model.simulate(np.zeros((10, 2)))
    with pytest.raises(ValueError, match="n_states = 4"):
        model.simulate(X[0], initial_state=[0.0, 1.0])
    with pytest.raises(ValueError, match="fitted with 2"):
        model.predict(X[0], np.zeros((120, 1)))


def test_simulation_continues_from_its_own_state_and_past_excitation():
    X, y = _sequences(2)
    model = ISSMRegressor(n_init=1, max_iter=5, random_state=0).fit(X, y)
    full = model.simulate(X[0])
    states = model.predict_states(X[0]).states
    k0 = 60
    resumed = model.simulate(
        X[0][k0:], initial_state=states[k0 - 1], initial_inputs=X[0][:k0]
    )
    np.testing.assert_allclose(resumed, full[k0:], rtol=1e-9, atol=1e-12)


@pytest.mark.filterwarnings("ignore:The linear model of:UserWarning")
@pytest.mark.filterwarnings("ignore::sklearn.exceptions.ConvergenceWarning")
def test_fits_in_other_threads_match_the_serial_fit():
    # Multi-threaded BLAS rounds differently: every fit must run under the
    # same BLAS limit, whichever thread runs it and whatever ran before it.
    from sysid_nn import HystereticOscillator

    data = HystereticOscillator().generate(2, n_samples=600, random_state=3)
    X, y = data.excitation[0][:, None], data.displacement[0][:, None]

    def fit(**params):
        est = ISSMRegressor(max_iter=4, n_init=2, focus="prediction", random_state=0)
        return est.set_params(**params).fit(X, y).coefs_

    def blas_limits():
        info = threadpoolctl.threadpool_info()
        return {lib["filepath"]: lib["num_threads"] for lib in info}

    serial = fit()
    before = blas_limits()
    with joblib.parallel_backend("threading"):
        threaded_restarts = fit(n_jobs=2)
    in_thread = {}
    worker = threading.Thread(target=lambda: in_thread.setdefault("w", fit()))
    worker.start()
    worker.join()
    np.testing.assert_array_equal(threaded_restarts, serial)
    np.testing.assert_array_equal(in_thread["w"], serial)
    # The limit is lifted afterwards, whichever thread was the last to leave.
    assert blas_limits() == before


@pytest.mark.filterwarnings("ignore::sklearn.exceptions.ConvergenceWarning")
def test_one_step_predictor_from_noisy_records_stays_finite_on_others():
    # Innovation weights refitted to one noisy record can be stable on it and
    # diverge on other records; the choice must hold on the validation data
    # and keep a margin from the edge of stability. Records of typical
    # amplitude, as in the accuracy benchmark: a larger one would make the
    # free run itself extrapolate.
    from sysid_nn import HystereticOscillator

    data = HystereticOscillator().generate(32, n_samples=2000, random_state=2024)
    peaks = np.abs(data.displacement).max(axis=1)
    order = np.argsort(np.abs(peaks - np.median(peaks)), kind="stable")
    y = np.stack([data.displacement, data.velocity], axis=-1)
    X = data.excitation[..., None]
    rng = np.random.default_rng((2024, 10000))
    noisy = {i: y[i] + 0.01 * y[i].std(axis=0) * rng.standard_normal(y[i].shape)
             for i in order[:3]}  # fmt: skip
    train, val, unseen = order[0], order[1:3], order[7:13]
    model = ISSMRegressor(random_state=0, n_jobs=2)
    model.fit(X[train], noisy[train], X_val=[X[i] for i in val],
              y_val=[noisy[i] for i in val])  # fmt: skip
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no DivergenceWarning
        predictions = model.predict([X[i] for i in unseen], [y[i] for i in unseen])
    assert all(np.all(np.isfinite(p)) for p in predictions)


def test_initial_state_estimated_from_a_measured_window():
    X, y = _sequences(3)
    model = ISSMRegressor(n_init=1, max_iter=10, random_state=0).fit(X, y)
    start = [1.0, -0.5, 0.8, -0.3]
    true = model.simulate(X[0], initial_state=start)
    rest = model.simulate(X[0])
    exact = model.simulate(X[0], y_init=true[:40])
    np.testing.assert_allclose(exact, true, atol=1e-5 * np.abs(true).max())
    noisy = true[:40] + 0.02 * true.std(axis=0) * np.random.default_rng(
        1
    ).standard_normal((40, 2))
    est = model.simulate(X[0], y_init=noisy)
    # This small system forgets its start within tens of samples: compare all.
    assert np.abs(est - true).max() < 0.25 * np.abs(rest - true).max()
    with pytest.raises(ValueError, match="either initial_state or y_init"):
        model.simulate(X[0], initial_state=start, y_init=true[:40])


# --------------------------------------------------------------------------
# the linear start under output noise
# --------------------------------------------------------------------------
def _noisy_second_order(level, n=3000, seed=1):
    rng = np.random.default_rng(seed)
    u = rng.standard_normal((n, 1))
    y = lfilter([0.0, 0.5], [1.0, -1.6, 0.9], u[:, 0])
    return u, y + level * y.std() * rng.standard_normal(n)


def _start_poles(init, u, y):
    model = ISSMRegressor(n_states=2, hidden_layer_sizes=(), init=init, n_init=1,
                          max_iter=1, early_stopping=False)  # fmt: skip
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        warnings.filterwarnings(
            "ignore", "A linear one-step model leaves a white misfit", UserWarning
        )
        model.fit(u, y)
    return model, np.sort_complex(np.linalg.eigvals(model.linear_model_.A))


def test_subspace_start_is_consistent_under_output_noise():
    true = np.sort_complex(np.roots([1.0, -1.6, 0.9]))
    u, y = _noisy_second_order(0.2)
    model, subspace = _start_poles("subspace", u, y)
    _, arx = _start_poles("arx", u, y)
    # The least-squares ARX fit takes the noisy outputs as exact regressors:
    # its poles shrink towards the origin. The subspace fit's do not.
    np.testing.assert_allclose(subspace, true, atol=0.01)
    assert np.abs(arx - true).max() > 0.04
    # With white output noise alone the Kalman predictor is the free run.
    assert np.abs(model.linear_model_.K).max() < 0.05
    # Without noise both starts are the system itself.
    clean = _noisy_second_order(0.0)
    np.testing.assert_allclose(_start_poles("arx", *clean)[1], true, atol=1e-6)
    np.testing.assert_allclose(_start_poles("subspace", *clean)[1], true, atol=1e-6)


def test_subspace_start_has_a_stable_one_step_predictor():
    # On a clean record of the hysteretic oscillator the regression's gain
    # gives an unstable predictor; the start takes the Riccati gain then.
    from sysid_nn import HystereticOscillator
    from sysid_nn._engine._subspace import kalman_gain

    data = HystereticOscillator().generate(1, n_samples=2000, random_state=2024)
    u, y = data.excitation[0][:, None], data.displacement[0]
    model = ISSMRegressor(hidden_layer_sizes=(), init="subspace", n_init=1,
                          max_iter=1, early_stopping=False)  # fmt: skip
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        warnings.filterwarnings(
            "ignore", "A linear one-step model leaves a white misfit", UserWarning
        )
        lin = model.fit(u, y).linear_model_
    predictor = lin.A - lin.K @ np.array([[1.0, 0.0, 0.0]])
    assert np.abs(np.linalg.eigvals(predictor)).max() < 1.0
    # The Riccati gain of an innovation model's own residuals is its gain.
    rng = np.random.default_rng(0)
    K = np.array([[0.5], [0.2]])
    e = rng.standard_normal((20000, 1))
    np.testing.assert_allclose(kalman_gain(A_TRUE, C_TRUE, e @ K.T, e), K, atol=0.02)


@pytest.mark.filterwarnings("ignore::sklearn.exceptions.ConvergenceWarning")
def test_default_start_follows_the_noise_on_the_records():
    def fit(y):
        with warnings.catch_warnings():
            warnings.simplefilter("error", UserWarning)  # no noise warning
            warnings.simplefilter("ignore", ConvergenceWarning)
            warnings.filterwarnings(
                "ignore", "A linear one-step model leaves a white misfit", UserWarning
            )
            # One step of training: the linear model may win.
            warnings.filterwarnings("ignore", "The linear model of", UserWarning)
            return ISSMRegressor(n_init=1, max_iter=1, random_state=0).fit(u, y)

    u, y = _noisy_second_order(0.0)
    model = fit(y)
    assert model.init_ == "arx"
    # The restart, and the refinement of the linear model; the linear model
    # is exact, no network fits better, and a second batch of one restart
    # runs after them.
    assert model.refined_restart_ == 1 and model.restart_batches_ == 2
    assert len(model.restart_scores_) == 3
    # Noisy: the subspace start, and one restart more from the ARX start;
    # init_ and linear_model_ are the chosen restart's.
    u, y = _noisy_second_order(0.05)
    model = fit(y)
    # (The third run refines the linear model, trained from its own start;
    # a second batch of both starts follows where no run fitted better.)
    assert model.refined_restart_ == 2
    assert len(model.restart_scores_) == 1 + 2 * model.restart_batches_
    best = np.argmax(model.restart_scores_[:2])
    if model.best_restart_ == best:
        assert model.init_ == ["subspace", "arx"][best]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        warnings.filterwarnings(
            "ignore", "A linear one-step model leaves a white misfit", UserWarning
        )
        ref = ISSMRegressor(init=model.init_, n_init=1, max_iter=1).fit(u, y)
    np.testing.assert_array_equal(model.linear_model_.A, ref.linear_model_.A)
    # With several outputs the ARX start kept its accuracy under noise.
    assert fit(np.column_stack([y, np.roll(y, 1)])).init_ == "arx"
    with pytest.warns(UserWarning, match="white measurement noise"):
        ISSMRegressor(init="arx", n_init=1, max_iter=1, random_state=0).fit(u, y)


def test_subspace_start_needs_records_long_enough():
    u, y = _noisy_second_order(0.05, n=12)
    with pytest.raises(ValueError, match='init="subspace" needs longer'):
        ISSMRegressor(init="subspace", n_init=1, max_iter=1).fit(u, y)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        warnings.filterwarnings(
            "ignore", "A linear one-step model leaves a white misfit", UserWarning
        )
        model = ISSMRegressor(n_init=1, max_iter=1, early_stopping=False).fit(u, y)
    assert model.init_ == "arx"
