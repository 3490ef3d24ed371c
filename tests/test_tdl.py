"""Tests of the TDL network and of the shared recurrent engine."""

from __future__ import annotations

import pickle
import warnings
from unittest import mock

import joblib
import numpy as np
import pandas as pd
import pytest
from scipy.signal import lfilter
from sklearn.base import clone
from sklearn.exceptions import ConvergenceWarning, NotFittedError
from sklearn.model_selection import GridSearchCV, KFold
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import FunctionTransformer
from sklearn.utils.estimator_checks import parametrize_with_checks

from sysid_nn import DivergenceWarning, TDLRegressor, _selection
from sysid_nn._records._data import _FREE_RUN

ROW_ORDER_CHECKS = {
    "check_methods_subset_invariance": (
        "rows are consecutive time steps of one experiment: a subset of rows is "
        "a different experiment with different initial conditions"
    ),
    "check_methods_sample_order_invariance": (
        "rows are consecutive time steps: reordering them changes the dynamics"
    ),
}


def _narx(u: np.ndarray) -> np.ndarray:
    """A small nonlinear ARX system used as ground truth."""
    y = np.zeros(len(u))
    for t in range(2, len(u)):
        y[t] = (
            0.6 * y[t - 1]
            - 0.1 * y[t - 2]
            + 0.8 * np.tanh(u[t - 1, 0])
            + 0.2 * u[t - 2, 0] ** 2
            - 0.1 * y[t - 1] ** 2
        )
    return y


# ---------------------------------------------------------------------------
# a slow NumPy twin of the kernels, written independently of them
# ---------------------------------------------------------------------------
def _unpack(model, w):
    sizes = model._sizes_
    mats, p = [], 0
    for i in range(len(sizes) - 1):
        W = w[p : p + sizes[i] * sizes[i + 1]].reshape(sizes[i + 1], sizes[i])
        p += sizes[i] * sizes[i + 1]
        b = w[p : p + sizes[i + 1]]
        p += sizes[i + 1]
        mats.append((W, b))
    L = w[p:].reshape(sizes[-1], sizes[0]) if model._bypass() else None
    return mats, L


def _twin_network(model, w, z):
    """Output and d out / d (w, z) of the network, by explicit matrices."""
    mats, L = _unpack(model, w)
    f = (lambda s: 1 / (1 + np.exp(-s))) if model.activation == "logistic" else np.tanh
    df = (
        (lambda a: a * (1 - a))
        if model.activation == "logistic"
        else (lambda a: 1 - a * a)
    )
    acts = [z]
    for W, b in mats[:-1]:
        acts.append(f(W @ acts[-1] + b))
    W, b = mats[-1]
    out = W @ acts[-1] + b + (L @ z if L is not None else 0.0)
    n_out, n_w = len(out), len(w)
    jw = np.zeros((n_out, n_w))
    jz = np.zeros((n_out, len(z)))
    for j in range(n_out):
        delta = np.eye(n_out)[j]
        grads, p_end = [], sum(W.size + b.size for W, b in mats)
        for layer in range(len(mats) - 1, -1, -1):
            W, b = mats[layer]
            grads.append((np.outer(delta, acts[layer]).ravel(), delta.copy()))
            back = W.T @ delta
            delta = back * df(acts[layer]) if layer > 0 else back
        flat = np.concatenate([np.concatenate(g) for g in reversed(grads)])
        jw[j, :p_end] = flat
        jz[j] = delta
        if L is not None:
            jw[j, p_end:] = np.outer(np.eye(n_out)[j], z).ravel()
            jz[j] += L[j]
    return out, jw, jz


def _twin_run(model, w, data, seg_len):
    """Recurrence with forward sensitivities, one sample at a time."""
    na, nb, nk = model.output_lags_, model.input_lags_, model.input_delay
    Y, U, h = data.Y, data.U, data.h
    n_out = Y.shape[1]
    Yhat = Y.copy()
    sens = np.zeros((len(Y), n_out, len(w)))
    for a, b in zip(data.starts[:-1], data.starts[1:], strict=True):
        for t in range(a + h, b):
            seg_start = a + h + ((t - a - h) // seg_len) * seg_len
            lags = [
                Yhat[t - i] if t - i >= seg_start else Y[t - i]
                for i in range(1, na + 1)
            ]
            phi = np.concatenate([*lags, *[U[t - nk - i] for i in range(nb)]])
            out, jw, jz = _twin_network(model, w, model._S @ phi)
            jphi = jz @ model._S
            total = jw.copy()
            for i in range(1, na + 1):
                if t - i >= seg_start:
                    total += jphi[:, (i - 1) * n_out : i * n_out] @ sens[t - i]
            Yhat[t], sens[t] = out, total
    rows = data.modelled
    return Yhat, sens[rows].reshape(-1, len(w))


def _fitted(n_outputs=1, **params):
    rng = np.random.default_rng(3)
    Xs = [rng.standard_normal((60, 2)) for _ in range(3)]
    ys = [rng.standard_normal((60, n_outputs)) * 0.1 for _ in range(3)]
    defaults = dict(
        output_lags=3,
        input_lags=2,
        hidden_layer_sizes=(4, 3),
        n_init=1,
        max_iter=3,
        early_stopping=False,
        random_state=0,
        # White-noise outputs: the kernels are checked on the measured-start
        # structure, whose lag scaling reads the records as they are.
        shooting="measured",
    )
    defaults.update(params)
    # The kernels are checked on trained network weights: on these
    # white-noise records selection would return the linear model.
    with (
        warnings.catch_warnings(),
        mock.patch.object(_selection, "linear_candidate", return_value=None),
    ):
        warnings.simplefilter("ignore", ConvergenceWarning)
        model = TDLRegressor(**defaults).fit(Xs, ys)
    # Perturb the weights so that the sensitivities are not trivially zero.
    model.coefs_ = model.coefs_ + 0.3 * np.random.default_rng(1).standard_normal(
        model.coefs_.shape
    )
    return model, model._stack(Xs, ys)


KERNEL_CASES = [
    dict(activation="tanh"),
    dict(activation="logistic", lag_representation="delays"),
    dict(activation="tanh", linear_bypass=False, input_delay=0),
    dict(n_outputs=2, activation="logistic"),
    dict(n_outputs=2, output_lags=1, input_lags=3, input_delay=2),
    dict(hidden_layer_sizes=()),
]


@pytest.mark.parametrize("case", KERNEL_CASES)
@pytest.mark.parametrize("seg_len", [1, 7, _FREE_RUN])
def test_jacobian_matches_twin_and_finite_differences(case, seg_len):
    model, data = _fitted(**case)
    w = model.coefs_
    Yhat, J, diverged, _ = model._run(w, data, seg_len, True)
    assert (diverged < 0).all()
    Yt, Jt = _twin_run(model, w, data, seg_len)
    np.testing.assert_allclose(Yhat, Yt, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(J, Jt, rtol=1e-10, atol=1e-12)

    rows = data.modelled
    eps = 1e-6
    Jfd = np.empty_like(J)
    for i in range(len(w)):
        d = np.zeros_like(w)
        d[i] = eps
        up = model._run(w + d, data, seg_len, False)[0][rows].ravel()
        down = model._run(w - d, data, seg_len, False)[0][rows].ravel()
        Jfd[:, i] = (up - down) / (2 * eps)
    err = np.linalg.norm(J - Jfd) / np.linalg.norm(J)
    assert err < 1e-7


@pytest.mark.parametrize("case", KERNEL_CASES)
@pytest.mark.parametrize("seg_len", [1, 7, _FREE_RUN])
def test_adjoint_gradient_equals_jacobian_transpose(case, seg_len):
    model, data = _fitted(**case)
    w = model.coefs_
    Yhat, J, _, state = model._run(w, data, seg_len, True)
    rows = data.modelled
    r = (Yhat[rows] - data.Y[rows]).ravel()
    grad = model._gradient(w, data, seg_len, state)
    np.testing.assert_allclose(grad, J.T @ r, rtol=1e-9, atol=1e-11)


def test_horizon_predictor_is_sliding():
    model, data = _fitted()
    w = model.coefs_
    one = model._run_horizon(w, data, 1)
    np.testing.assert_allclose(one, model._run(w, data, 1, False)[0])
    # horizon k at row t equals a free run started from measurements at t-k.
    k = 5
    pred = model._run_horizon(w, data, k)
    a, h = data.starts[1], data.h
    t = a + h + 20
    sub_starts = np.array([0, h + k])
    from sysid_nn._records._data import _Data

    sub = _Data(
        Y=data.Y[t - k + 1 - h : t + 1].copy(),
        U=data.U[t - k + 1 - h : t + 1].copy(),
        starts=sub_starts,
        h=h,
    )
    free = model._run(w, sub, _FREE_RUN, False)[0]
    assert free[-1, 0] == pytest.approx(pred[t, 0], rel=1e-12)
    # A longer horizon cannot see more than the free run beyond it.
    full = model._run_horizon(w, data, 10_000)
    np.testing.assert_allclose(full, model._run(w, data, _FREE_RUN, False)[0])


# ---------------------------------------------------------------------------
# identification
# ---------------------------------------------------------------------------
def test_linear_model_recovers_arx_coefficients():
    rng = np.random.default_rng(0)
    b, a = [0.0, 0.5, 0.2], [1.0, -1.5, 0.7]
    Xs = [rng.standard_normal((400, 1)) for _ in range(3)]
    ys = [lfilter(b, a, X[:, 0]) for X in Xs]
    model = TDLRegressor(
        output_lags=2,
        input_lags=2,
        hidden_layer_sizes=(),
        lag_representation="delays",
        focus="prediction",
        n_init=1,
        random_state=0,
    ).fit(Xs, ys)
    # Fold the scaling back to obtain y(t) = a1 y(t-1) + a2 y(t-2) + b1 u(t-1) + ...
    sy, sx = model._y_scale[0], model._x_scale[0]
    W = model.coefs_[:4] @ model._S
    coef = np.array([W[0], W[1], W[2] * sy / sx, W[3] * sy / sx])
    np.testing.assert_allclose(coef, [1.5, -0.7, 0.5, 0.2], atol=1e-6)


def test_nonlinear_narx_reaches_near_zero_free_run_error_on_new_data():
    rng = np.random.default_rng(1)
    Xs = [rng.standard_normal((500, 1)) for _ in range(5)]
    ys = [_narx(X) for X in Xs]
    net = TDLRegressor(
        output_lags=2,
        input_lags=2,
        hidden_layer_sizes=(8,),
        n_init=2,
        random_state=0,
        max_iter=100,
    ).fit(Xs[:3], ys[:3], X_val=Xs[3:4], y_val=ys[3:4])
    lin = TDLRegressor(
        output_lags=2, input_lags=2, hidden_layer_sizes=(), n_init=1
    ).fit(Xs[:3], ys[:3])
    e_net = net.simulate(Xs[4]) - ys[4]
    e_lin = lin.simulate(Xs[4]) - ys[4]
    nrmse_net = np.sqrt(np.mean(e_net**2)) / ys[4].std()
    nrmse_lin = np.sqrt(np.mean(e_lin**2)) / ys[4].std()
    assert nrmse_net < 0.05
    assert nrmse_net < 0.2 * nrmse_lin


@pytest.mark.slow
def test_paper_setting_one_step_prediction_at_least_linear():
    """Paper section 4.2: the TDL trained on every third sample (dt = 0.03).

    The paper's structure (6/5 lags, 9 logistic nodes), started at the ARX
    fit through the linear bypass, predicts unseen records one step ahead at
    least as well as the linear model.
    """
    from sysid_nn import HystereticOscillator

    rec = HystereticOscillator().generate(6, random_state=11)
    X = [f[::3, None] for f in rec.excitation]
    y = [d[::3] for d in rec.displacement]
    paper = TDLRegressor(
        output_lags=6,
        input_lags=5,
        hidden_layer_sizes=(9,),
        activation="logistic",
        lag_representation="delays",
        focus="prediction",
        n_init=2,
        max_iter=200,
        random_state=0,
    )
    linear = TDLRegressor(
        output_lags=6, input_lags=5, hidden_layer_sizes=(), focus="prediction"
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        # Every third sample of a broadband excitation: the records do not
        # carry the excitation between the samples, which the fit says.
        with pytest.warns(UserWarning, match="excitation between the samples"):
            paper.fit(X[:2], y[:2], X_val=X[2:3], y_val=y[2:3])
        linear.fit(X[:2], y[:2])

    def one_step(model):
        pred = model.predict(X[3:], y[3:], horizon=1)
        errors = [p - t for p, t in zip(pred, y[3:], strict=True)]
        return np.sqrt(np.mean(np.concatenate(errors) ** 2))

    assert one_step(paper) <= one_step(linear)


# ---------------------------------------------------------------------------
# API behaviour
# ---------------------------------------------------------------------------
def _records(n=4, length=200, seed=0):
    rng = np.random.default_rng(seed)
    Xs = [rng.standard_normal((length, 1)) for _ in range(n)]
    return Xs, [_narx(X) for X in Xs]


def _small(**params):
    defaults = dict(
        output_lags=2,
        input_lags=2,
        hidden_layer_sizes=(3,),
        n_init=1,
        max_iter=10,
        random_state=0,
    )
    defaults.update(params)
    return TDLRegressor(**defaults)


@pytest.fixture(autouse=True)
def _quiet_convergence():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        yield


def test_outputs_mirror_inputs():
    Xs, ys = _records()
    model = _small().fit(Xs, ys)
    sims = model.simulate(Xs)
    assert isinstance(sims, list) and [s.shape for s in sims] == [y.shape for y in ys]
    one = model.predict(Xs[0], ys[0])
    assert isinstance(one, np.ndarray) and one.shape == ys[0].shape
    y2 = [y[:, None] for y in ys]
    model2 = _small().fit(Xs, y2)
    assert model2.predict(Xs[0]).shape == (200, 1)
    assert model.predict(Xs[0]).shape == (200,)
    np.testing.assert_array_equal(model.predict(Xs[1]), model.simulate(Xs[1]))


def test_multi_input_multi_output():
    rng = np.random.default_rng(4)
    X = rng.standard_normal((300, 2))
    y = np.column_stack(
        [lfilter([0, 0.4], [1, -0.5], X[:, 0]), lfilter([0, 0.3], [1, -0.2], X[:, 1])]
    )
    model = _small(hidden_layer_sizes=(), max_iter=50).fit(X, y)
    assert model.n_outputs_ == 2 and model.n_features_in_ == 2
    assert model.simulate(X).shape == (300, 2)
    assert model.score(X, y) > 0.999


def test_measured_initial_outputs_change_the_start_only():
    Xs, ys = _records()
    model = _small().fit(Xs, ys)
    zero = model.simulate(Xs[0])
    init = model.simulate(Xs[0], initial_outputs=[0.5, 0.4])
    assert init[0] != zero[0]
    with pytest.raises(ValueError, match="initial_outputs"):
        model.simulate(Xs[0], initial_outputs=[1.0, 2.0, 3.0])


def test_pandas_inputs_and_feature_names():
    Xs, ys = _records()
    frame = pd.DataFrame(Xs[0], columns=["force"])
    model = _small().fit(frame, pd.Series(ys[0]))
    assert list(model.feature_names_in_) == ["force"]
    # An array for a model fitted on named columns: scikit-learn's warning.
    with pytest.warns(UserWarning, match="does not have valid feature names"):
        unnamed = model.predict(Xs[0])
    np.testing.assert_allclose(model.predict(frame), unnamed)


def test_clone_params_pickle_joblib(tmp_path):
    Xs, ys = _records()
    model = _small().fit(Xs, ys)
    twin = clone(model)
    assert twin.get_params() == model.get_params()
    twin.set_params(hidden_layer_sizes=(5,))
    assert twin.hidden_layer_sizes == (5,)
    restored = pickle.loads(pickle.dumps(model))
    np.testing.assert_array_equal(restored.simulate(Xs[2]), model.simulate(Xs[2]))
    joblib.dump(model, tmp_path / "m.joblib")
    again = joblib.load(tmp_path / "m.joblib")
    np.testing.assert_array_equal(
        again.predict(Xs[2], ys[2], horizon=3), model.predict(Xs[2], ys[2], horizon=3)
    )


def test_same_random_state_same_model_and_restarts_in_parallel():
    Xs, ys = _records()
    a = _small(n_init=2, random_state=5).fit(Xs, ys)
    b = _small(n_init=2, random_state=5, n_jobs=2).fit(Xs, ys)
    np.testing.assert_array_equal(a.coefs_, b.coefs_)
    # The two restarts and the refinement of the linear model.
    assert a.restart_scores_.shape == (3,)
    np.testing.assert_array_equal(a.restart_scores_, b.restart_scores_)


def test_grid_search_over_hidden_nodes_by_experiment():
    Xs, ys = _records(n=6, length=150)
    search = GridSearchCV(
        _small(max_iter=5), {"hidden_layer_sizes": [(), (2,), (4,)]}, cv=KFold(3)
    ).fit(Xs, ys)
    assert search.best_params_["hidden_layer_sizes"] in [(), (2,), (4,)]
    assert np.all(np.isfinite(search.cv_results_["mean_test_score"]))


def test_pipeline_with_row_wise_scaler():
    Xs, ys = _records()
    pipe = make_pipeline(FunctionTransformer(lambda X: 2.0 * X), _small())
    pipe.fit(Xs[0], ys[0])
    assert pipe.predict(Xs[1]).shape == ys[1].shape


def test_solvers_and_focus_all_train():
    Xs, ys = _records()
    for solver in ["lm", "lbfgs", "slsqp"]:
        for focus in ["prediction", "simulation"]:
            model = _small(solver=solver, focus=focus, max_iter=20).fit(Xs[:3], ys[:3])
            assert np.isfinite(model.loss_)
            assert model.score(Xs[3], ys[3]) > 0.5


def test_convergence_warning_when_stopped_short():
    Xs, ys = _records()
    with pytest.warns(ConvergenceWarning, match="max_iter"):
        _small(max_iter=1, early_stopping=False).fit(Xs, ys)


def test_divergent_free_run_returns_nan_and_warns():
    Xs, ys = _records()
    model = _small(hidden_layer_sizes=()).fit(Xs, ys)
    # Make the output feedback explosive.
    model.coefs_[0] = 5.0 / model._S[0, 0]
    with pytest.warns(DivergenceWarning, match="diverged at sample"):
        sim = model.simulate(Xs[0])
    first = np.flatnonzero(np.isnan(sim))[0]
    assert np.all(np.isnan(sim[first:])) and np.all(np.isfinite(sim[:first]))
    with pytest.warns(DivergenceWarning):
        assert model.score(Xs[0], ys[0]) == -np.inf
    # The k-step predictor with measured outputs is guarded the same way.
    with pytest.warns(DivergenceWarning, match="50-step prediction .* diverged"):
        pred = model.predict(Xs[0], ys[0], horizon=50)
    first = np.flatnonzero(np.isnan(pred))[0]
    assert np.all(np.isnan(pred[first:])) and np.all(np.isfinite(pred[:first]))


def test_early_stopping_uses_held_out_data():
    Xs, ys = _records()
    model = _small(max_iter=20).fit(Xs, ys)
    assert model.best_validation_score_ is not None
    model = _small(max_iter=20, early_stopping=False).fit(Xs, ys)
    assert model.best_validation_score_ is None


# ---------------------------------------------------------------------------
# bad input
# ---------------------------------------------------------------------------
def test_bad_input_messages():
    Xs, ys = _records()
    model = _small()
    with pytest.raises(NotFittedError):
        model.predict(Xs[0])
    with pytest.raises(ValueError, match="Reshape your data"):
        model.fit(Xs[0][:, 0], ys[0])
    bad = Xs[1].copy()
    bad[17, 0] = np.nan
    with pytest.raises(ValueError, match=r"X\[1\] contains NaN \(first at sample 17\)"):
        model.fit([Xs[0], bad], ys[:2])
    with pytest.raises(ValueError, match="inf"):
        model.fit(Xs[0], np.where(np.arange(200) == 3, np.inf, ys[0]))
    with pytest.raises(ValueError, match="sequence 1 of X has 2 samples"):
        model.fit([Xs[0], Xs[1][:2]], [ys[0], ys[1][:2]])
    with pytest.raises(ValueError, match="same number of samples in sequence 0"):
        model.fit([Xs[0]], [ys[0][:-1]])
    with pytest.raises(ValueError, match="both be lists"):
        model.fit(Xs, ys[0])
    fitted = _small().fit(Xs, ys)
    with pytest.raises(
        ValueError, match="X has 2 features, but TDLRegressor is expecting 1"
    ):
        fitted.predict(np.ones((50, 2)))
    with pytest.raises(ValueError, match="horizon must be a positive integer"):
        fitted.predict(Xs[0], ys[0], horizon=0)
    with pytest.raises(ValueError, match="hidden_layer_sizes"):
        _small(hidden_layer_sizes=(3, 0)).fit(Xs, ys)
    with pytest.raises(ValueError, match="X_val and y_val must be given together"):
        _small().fit(Xs, ys, X_val=Xs)


@pytest.mark.filterwarnings("ignore:The linear model of:UserWarning")
@parametrize_with_checks(
    [
        TDLRegressor(
            output_lags=2, input_lags=2, hidden_layer_sizes=(3,), n_init=1, max_iter=5
        ),
        # The lags read from the data (the default).
        TDLRegressor(hidden_layer_sizes=(3,), n_init=1, max_iter=5),
    ],
    expected_failed_checks=lambda est: ROW_ORDER_CHECKS,
)
def test_sklearn_compatible(estimator, check):
    check(estimator)


def _free_run_nrmse(model, X, y):
    return np.sqrt(np.mean((model.simulate(X) - y) ** 2)) / np.std(y)


@pytest.mark.parametrize("solver", ["lbfgs", "slsqp"])
def test_quasi_newton_solvers_keep_iterating_from_the_arx_start(solver):
    # On the oscillator the ARX start's one-step loss is about 1e-10 in
    # standardised units: tolerances must be relative to it, or the solvers
    # stop at once and return the starting point.
    from sysid_nn import HystereticOscillator

    rec = HystereticOscillator().generate(1, n_samples=600, random_state=3)
    X, y = rec.excitation[0, :, None], rec.displacement[0]
    settings = dict(
        solver=solver, hidden_layer_sizes=(4,), focus="prediction", early_stopping=False
    )
    net = _small(max_iter=40, **settings).fit(X, y)
    start = _small(max_iter=1, **settings).fit(X, y)
    assert net.n_iter_ >= 20
    assert net.loss_ < 0.9 * start.loss_


def test_tail_block_is_held_out_as_a_record_of_its_own():
    Xs, ys = _records(n=1, length=300)
    model = _small(validation_fraction=0.2)
    model.n_outputs_ = 1
    head, yhead, val, yval, lead = model._split_validation(Xs, [ys[0]], 5)
    assert len(head[0]) == len(yhead[0]) == lead == 240
    # The last fifth alone, judged as a record passed as X_val.
    np.testing.assert_array_equal(val[0], Xs[0][240:])
    np.testing.assert_array_equal(yval[0], ys[0][240:])
    fitted = _small(validation_fraction=0.2, max_iter=20).fit(Xs[0], ys[0])
    passed = _small(max_iter=20).fit(
        Xs[0][:240], ys[0][:240], X_val=Xs[0][240:], y_val=ys[0][240:]
    )
    np.testing.assert_array_equal(fitted.coefs_, passed.coefs_)
    assert fitted.best_validation_score_ == passed.best_validation_score_


def test_last_stage_gets_its_own_patience():
    # Steps of the earlier stages without a better validation loss must not
    # count against the free-run stage's patience.
    Xs, ys = _records(n=4, length=300, seed=5)
    model = _small(hidden_layer_sizes=(4,), max_iter=60, n_iter_no_change=10)
    stages = []
    original = model._fit_stages

    def spy(train, val, restart, stop):
        from sysid_nn._engine import _training

        solve = _training._SOLVERS["lm"]

        def counting(objective, w, iters, tol, tracker, stall=None):
            out = solve(objective, w, iters, tol, tracker, stall)
            stages.append((objective.seg, out[1], tracker.stopped))
            return out

        _training._SOLVERS["lm"] = counting
        try:
            return original(train, val, restart, stop)
        finally:
            _training._SOLVERS["lm"] = solve

    model._fit_stages = spy
    model.fit(Xs[:3], ys[:3], X_val=Xs[3:], y_val=ys[3:])
    seg, n_eval, stopped = stages[-1]
    assert seg == _FREE_RUN
    # Either it converged or it ran at least its patience before stopping.
    assert n_eval >= model.n_iter_no_change or not stopped


def test_stages_before_the_last_stop_when_their_cost_stalls(monkeypatch):
    # Every stage but the free run gets the stall rule; the free run stops
    # by tol, its budget or the validation patience alone.
    from sysid_nn._engine import _selection, _training

    Xs, ys = _records(n=3, length=300, seed=5)
    solve = _training._SOLVERS["lm"]
    stages = []

    def spying(objective, w, iters, tol, tracker, stall=None):
        out = solve(objective, w, iters, tol, tracker, stall)
        stages.append((objective.seg, stall, out[1], iters))
        return out

    monkeypatch.setitem(_training._SOLVERS, "lm", spying)
    # The restart's stages alone (the linear candidate's end the same way).
    monkeypatch.setattr(_selection, "linear_candidate", lambda *args: None)
    _small(hidden_layer_sizes=(4,), max_iter=60, n_init=1).fit(Xs, ys)
    assert [s[1] for s in stages[:-1]] == [_training._STALL_STEPS] * (len(stages) - 1)
    assert stages[-1][0] == _FREE_RUN and stages[-1][1] is None


def test_default_patience_is_shared_and_short():
    # Early stopping keeps the best validation weights, so steps after the
    # best one only cost time: measured on the accuracy benchmark, patience
    # 10 selected the same weights as 30 with a third of the free-run steps.
    from sysid_nn import ISSMRegressor

    assert TDLRegressor().n_iter_no_change == ISSMRegressor().n_iter_no_change == 10


def test_simulation_continues_from_measured_history():
    # A free run restarted at k0 from its own outputs and the excitation
    # before k0 continues exactly where the uninterrupted run was.
    Xs, ys = _records()
    model = _small(output_lags=3, input_lags=3).fit(Xs, ys)
    full = model.simulate(Xs[0])
    k0 = 120
    resumed = model.simulate(
        Xs[0][k0:], initial_outputs=full[k0 - 3 : k0], initial_inputs=Xs[0][:k0]
    )
    np.testing.assert_allclose(resumed, full[k0:], rtol=1e-10, atol=1e-12)
    # Without the past excitation the start differs (zero excitation before).
    cold = model.simulate(Xs[0][k0:], initial_outputs=full[k0 - 3 : k0])
    assert not np.allclose(cold[:3], full[k0 : k0 + 3])
    with pytest.raises(ValueError, match=r"initial_inputs must have shape \(n_past"):
        model.simulate(Xs[0], initial_inputs=np.zeros((4, 2)))
    with pytest.raises(ValueError, match="one array per sequence"):
        model.simulate(Xs[:2], initial_inputs=[np.zeros(3)])


def test_initial_outputs_estimated_from_a_measured_window():
    # A record that starts in motion: the model's own free run from a known
    # non-zero start, measured with noise over its first samples.
    Xs, ys = _records()
    model = _small(output_lags=2, input_lags=2).fit(Xs, ys)
    X = Xs[1]
    true = model.simulate(X, initial_outputs=[[1.5], [1.2]])
    rest = model.simulate(X)
    # Exact measurements: the start is recovered, and the whole run with it.
    exact = model.simulate(X, y_init=true[:30])
    np.testing.assert_allclose(exact, true, atol=1e-6 * np.abs(true).max())
    # Noisy measurements: the run is close, far closer than from rest (this
    # small system forgets its start within a few samples: compare them all).
    noise = 0.02 * true.std() * np.random.default_rng(3).standard_normal(30)
    noisy = model.simulate(X, y_init=true[:30] + noise)
    err = np.abs(noisy - true).max()
    assert err < 0.05 * true.std()
    assert err < 0.1 * np.abs(rest - true).max()
    # One window per sequence for a list; errors name the argument.
    both = model.simulate([X, X], y_init=[true[:30], true[:10]])
    np.testing.assert_allclose(both[0], exact)
    with pytest.raises(ValueError, match="either initial_outputs or y_init"):
        model.simulate(X, initial_outputs=[0.0, 0.0], y_init=true[:30])
    with pytest.raises(ValueError, match=r"y_init must hold .* shape \(n_window, 1\)"):
        model.simulate(X, y_init=np.zeros((30, 2)))
    with pytest.raises(ValueError, match="y_init must hold"):
        model.simulate(X[:5], y_init=true[:30])


@pytest.mark.filterwarnings("ignore:The linear model of:UserWarning")
def test_output_noise_is_estimated_and_warned_about_when_it_swamps_the_dynamics():
    # A lightly damped second-order system sampled finely (about 60 samples
    # per period): its second difference is a small fraction of the output.
    rng = np.random.default_rng(0)
    u = rng.standard_normal((2000, 1))
    y = lfilter([0.0, 1e-3], [1.0, -1.98, 0.9891], u[:, 0])
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)
        clean = _small(max_iter=2).fit(u, y)
    assert clean.output_noise_std_[0] < 1e-6 * y.std()
    noisy_y = y + 0.01 * y.std() * rng.standard_normal(len(y))
    # shooting="auto" trains such records with free segment states instead.
    with pytest.warns(UserWarning, match=r"white misfit .*: about 0.9. % of their"):
        noisy = _small(max_iter=2, shooting="measured").fit(u, noisy_y)
    np.testing.assert_allclose(noisy.output_noise_std_, 0.01 * y.std(), rtol=0.2)


def test_closed_form_fit_regresses_only_on_measured_lags():
    # Records cut from a longer response start in motion: the rows whose
    # lags reach into the history (the rest state, not measurements) are
    # left out of the linear model's least-squares fit, which then recovers
    # the system exactly from noise-free records.
    rng = np.random.default_rng(0)
    b, a = [0.0, 0.5, 0.2], [1.0, -1.5, 0.7]
    Xs = [rng.standard_normal((500, 1)) for _ in range(3)]
    ys = [lfilter(b, a, X[:, 0])[100:] for X in Xs]
    model = TDLRegressor(
        output_lags=2,
        input_lags=2,
        hidden_layer_sizes=(),
        lag_representation="delays",
        max_iter=1,
        n_init=1,
        early_stopping=False,
        random_state=0,
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model.fit([X[100:] for X in Xs], ys)
    sy, sx = model._y_scale[0], model._x_scale[0]
    W = model._closed_form_fits(for_network=False)[0][1][:4] @ model._S
    coef = np.array([W[0], W[1], W[2] * sy / sx, W[3] * sy / sx])
    np.testing.assert_allclose(coef, [1.5, -0.7, 0.5, 0.2], atol=1e-9)


def test_fit_falls_back_and_warns_when_every_free_run_diverges():
    # Validation excitation a thousand times the training range: every
    # restart's free run leaves the divergence bound there, the linear start too.
    Xs, ys = _records()
    with pytest.warns(DivergenceWarning, match="so does the linear starting model"):
        _small().fit(Xs[:2], ys[:2], X_val=[1e3 * Xs[2]], y_val=[ys[2]])
