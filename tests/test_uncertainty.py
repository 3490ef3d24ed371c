"""Tests of the confidence and prediction bands (``return_std=True``)."""

from __future__ import annotations

import pickle
import re
import warnings
from itertools import pairwise

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
import pytest
from scipy.signal import lfilter
from sklearn.exceptions import ConvergenceWarning

from sysid_nn import ISSMRegressor, TDLRegressor
from sysid_nn._analysis._uncertainty import _bandwidth, _bartlett
from sysid_nn.plotting import plot_band
from sysid_nn.uncertainty import ensemble_std, interval_coverage, normal_interval

NOISE = 0.2


def linear_record(n, rng, noise=NOISE):
    """Output-error system: ``y = G u + e`` with white Gaussian ``e``."""
    u = rng.standard_normal((n, 1))
    clean = lfilter([0.0, 0.5], [1.0, -1.5, 0.7], u[:, 0])
    return u, clean, clean + noise * rng.standard_normal(n)


def nonlinear_record(n, rng, noise=0.05):
    u = rng.standard_normal((n, 1))
    y = np.zeros(n)
    for t in range(2, n):
        y[t] = 1.2 * y[t - 1] - 0.5 * y[t - 2] + np.tanh(0.8 * u[t - 1, 0])
    return u, y + noise * rng.standard_normal(n)


def linear_model():
    return TDLRegressor(
        output_lags=2,
        input_lags=1,
        hidden_layer_sizes=(),
        n_init=1,
        early_stopping=False,
        random_state=0,
    )


@pytest.fixture(scope="module")
def fitted():
    """A small network of each kind on a weakly non-linear noisy record."""
    rng = np.random.default_rng(3)
    u, y = nonlinear_record(300, rng)
    u_new, y_new = nonlinear_record(200, rng)
    common = dict(n_init=1, max_iter=20, early_stopping=False, random_state=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        warnings.filterwarnings(
            "ignore", "A linear one-step model leaves a white misfit", UserWarning
        )
        models = {
            "tdl": TDLRegressor(
                output_lags=2, input_lags=2, hidden_layer_sizes=(3,), **common
            ).fit(u, y),
            "issm": ISSMRegressor(hidden_layer_sizes=(3,), **common).fit(u, y),
            "issm-prediction": ISSMRegressor(
                hidden_layer_sizes=(3,), focus="prediction", **common
            ).fit(u, y),
        }
    return models, u_new, y_new


def test_linear_coverage_of_new_records():
    """Nominal 95 % intervals cover 93-97 % of new samples (Monte Carlo).

    Each repetition fits the linear model to a fresh short record of an
    output-error system and scores a new record: the prediction interval
    (weights and noise) against the noisy measurements, the confidence
    interval (weights only) against the noise-free response.
    """
    rng = np.random.default_rng(1)
    pred, noise_only, conf = [], [], []
    for _ in range(100):
        u, _, y = linear_record(80, rng)
        model = linear_model().fit(u, y)
        u_new, clean_new, y_new = linear_record(200, rng)
        mean, std = model.simulate(u_new, return_std=True)
        pred.append(interval_coverage(y_new, *normal_interval(mean, std)))
        s_noise = np.sqrt(model.noise_variance_)
        noise_only.append(interval_coverage(y_new, *normal_interval(mean, s_noise)))
        _, std_c = model.simulate(u_new, return_std=True, interval="confidence")
        conf.append(interval_coverage(clean_new, *normal_interval(mean, std_c)))
    assert 0.93 <= np.mean(pred) <= 0.97
    assert 0.92 <= np.mean(conf) <= 0.975
    # The weights' share is real: the noise alone covers less.
    assert np.mean(noise_only) < np.mean(pred) - 0.003


def test_noise_variance_estimates_the_measurement_noise():
    rng = np.random.default_rng(2)
    u, _, y = linear_record(2000, rng)
    model = linear_model().fit(u, y)
    np.testing.assert_allclose(np.sqrt(model.noise_variance_), NOISE, rtol=0.05)
    # Output error: the one-step predictor feeds back noisy outputs and errs more.
    assert model.one_step_noise_variance_[0] > model.noise_variance_[0]
    assert model.n_effective_params_ == pytest.approx(4.0)


def test_long_records_use_the_accumulated_normal_matrix(monkeypatch):
    """Past the memory limit the full Jacobian is never formed.

    The covariance then assumes white residuals: on a white-noise linear
    output-error record it agrees with the autocorrelation-robust one.
    """
    from sysid_nn._analysis import _uncertainty

    rng = np.random.default_rng(2)
    u, _, y = linear_record(2000, rng)
    full = linear_model().fit(u, y)
    monkeypatch.setattr(_uncertainty, "_FULL_JACOBIAN_LIMIT", 1000)
    with pytest.warns(UserWarning, match="assumes white residuals"):
        bounded = linear_model().fit(u, y)
    np.testing.assert_array_equal(bounded.coefs_, full.coefs_)
    np.testing.assert_allclose(bounded.noise_variance_, full.noise_variance_)
    np.testing.assert_allclose(
        np.diag(bounded.coefs_covariance_), np.diag(full.coefs_covariance_), rtol=0.3
    )
    _, std = bounded.simulate(u[:200], return_std=True)
    assert np.all(np.isfinite(std)) and np.all(std > 0)


def _finite_difference_std(model, run, step=1e-4):
    """Propagate ``coefs_covariance_`` by central differences of ``run``.

    ``var(f) = sum_k lam_k (f(w + h v_k) - f(w - h v_k))^2 / (2 h)^2`` over
    ``C = sum_k lam_k v_k v_k^T``, factored on ``C`` scaled to a unit
    diagonal: a network with large output and small hidden weights (the
    refinement of a linear model) has a covariance of condition 1e17, whose
    smallest eigenvalues an unscaled factoring drops, and they matter.
    """
    w0 = model.coefs_.copy()
    cov = model.coefs_covariance_
    d = np.sqrt(np.diag(cov))
    lam, V = np.linalg.eigh(cov / np.outer(d, d))
    var = 0.0
    try:
        for k in np.flatnonzero(lam > len(lam) * np.finfo(float).eps * lam.max()):
            v = d * V[:, k]
            norm = np.linalg.norm(v)
            model.coefs_ = w0 + step * v / norm
            plus = run()
            model.coefs_ = w0 - step * v / norm
            minus = run()
            var = var + lam[k] * norm**2 * ((plus - minus) / (2 * step)) ** 2
    finally:
        model.coefs_ = w0
    return np.sqrt(var)


@pytest.mark.parametrize("name", ["tdl", "issm", "issm-prediction"])
def test_propagated_variance_matches_finite_differences(fitted, name):
    models, u_new, y_new = fitted
    model = models[name]
    _, std = model.simulate(u_new, return_std=True, interval="confidence")
    expected = _finite_difference_std(model, lambda: model.simulate(u_new))
    np.testing.assert_allclose(std, expected, rtol=1e-4, atol=1e-8 * expected.max())
    _, std = model.predict(u_new, y_new, return_std=True, interval="confidence")
    expected = _finite_difference_std(model, lambda: model.predict(u_new, y_new))
    np.testing.assert_allclose(std, expected, rtol=1e-4, atol=1e-8 * expected.max())


def test_prediction_interval_adds_the_noise_variance(fitted):
    models, u_new, y_new = fitted
    model = models["tdl"]
    _, conf = model.simulate(u_new, return_std=True, interval="confidence")
    _, pred = model.simulate(u_new, return_std=True)
    np.testing.assert_allclose(pred**2, conf**2 + model.noise_variance_)
    _, conf = model.predict(u_new, y_new, return_std=True, interval="confidence")
    _, pred = model.predict(u_new, y_new, return_std=True)
    np.testing.assert_allclose(pred**2, conf**2 + model.one_step_noise_variance_)
    # Without measured outputs predict is the free run, band included.
    mean, std = model.predict(u_new, return_std=True)
    np.testing.assert_array_equal(mean, model.simulate(u_new))
    np.testing.assert_array_equal(std, model.simulate(u_new, return_std=True)[1])


def test_innovation_weights_get_the_one_step_covariance(fitted):
    """After the innovation refit, those weights have a variance of their own."""
    models, _, _ = fitted
    model = models["issm"]
    idx = model._innovation_index()
    cov = model.coefs_covariance_
    assert np.all(np.isfinite(cov))
    others = np.setdiff1d(np.arange(len(model.coefs_)), idx)
    np.testing.assert_array_equal(cov[np.ix_(idx, others)], 0.0)
    assert np.trace(cov[np.ix_(idx, idx)]) > 0


def test_tdl_start_carries_the_tdl_covariance():
    """An ISSM realising a TDL network simulates it with the same band."""
    rng = np.random.default_rng(4)
    u, y = nonlinear_record(300, rng)
    u_new, _ = nonlinear_record(150, rng)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        warnings.filterwarnings(
            "ignore", "A linear one-step model leaves a white misfit", UserWarning
        )
        model = ISSMRegressor(
            hidden_layer_sizes=(3,),
            init="tdl",
            n_init=1,
            max_iter=20,
            early_stopping=False,
            random_state=0,
        ).fit(u, y)
    mean, std = model.simulate(u_new, return_std=True, interval="confidence")
    mean_tdl, std_tdl = model.tdl_.simulate(
        u_new, return_std=True, interval="confidence"
    )
    np.testing.assert_allclose(mean, mean_tdl, rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(std, std_tdl, rtol=1e-6, atol=1e-12)


def test_shapes_mirror_the_input():
    rng = np.random.default_rng(5)
    u = rng.standard_normal((200, 1))
    y = np.column_stack(
        [lfilter([0, 0.5], [1, -0.5], u[:, 0]), lfilter([0, 0.2], [1, -0.3], u[:, 0])]
    )
    y = y + 0.01 * rng.standard_normal(y.shape)
    model = ISSMRegressor(
        hidden_layer_sizes=(), n_init=1, early_stopping=False, random_state=0
    ).fit(u, y)
    mean, std = model.simulate([u, u[:50]], return_std=True)
    assert isinstance(std, list) and [s.shape for s in std] == [(200, 2), (50, 2)]
    assert all(np.all(s > 0) for s in std)
    np.testing.assert_allclose(std[0][:50], std[1])  # same start, same band
    mean, std = model.predict(u, y, return_std=True)
    assert std.shape == mean.shape == (200, 2)
    one = linear_model().fit(u, y[:, 0])
    assert one.simulate(u, return_std=True)[1].shape == (200,)


def test_bad_arguments():
    rng = np.random.default_rng(6)
    u, _, y = linear_record(100, rng)
    model = linear_model().fit(u, y)
    with pytest.raises(ValueError, match="interval must be"):
        model.simulate(u, return_std=True, interval="credible")
    with pytest.raises(ValueError, match="horizon=1"):
        model.predict(u, y, horizon=3, return_std=True)
    with pytest.raises(ValueError, match="level must be"):
        normal_interval(np.zeros(3), np.ones(3), level=95)
    with pytest.raises(ValueError, match="must have the shape"):
        normal_interval(np.zeros(3), np.ones(4))
    with pytest.raises(ValueError, match="lists of at least two"):
        ensemble_std(model, u, y, u)
    with pytest.raises(ValueError, match="method must be"):
        ensemble_std(model, [u, u], [y, y], u, method="jackknife")


def test_pickle_keeps_the_band():
    rng = np.random.default_rng(7)
    u, _, y = linear_record(100, rng)
    model = linear_model().fit(u, y)
    again = pickle.loads(pickle.dumps(model))
    np.testing.assert_array_equal(
        again.simulate(u, return_std=True)[1], model.simulate(u, return_std=True)[1]
    )


def test_helpers_on_lists():
    mean = [np.zeros(4), np.ones(2)]
    std = [np.ones(4), np.full(2, 0.5)]
    lower, upper = normal_interval(mean, std, level=0.5)
    z = 0.6744897501960817
    np.testing.assert_allclose(upper[1], 1 + 0.5 * z)
    y = [np.array([0.0, 0.5, 2.0, -3.0]), np.array([1.0, 1.0])]
    assert interval_coverage(y, lower, upper) == pytest.approx(4 / 6)


def test_bootstrap_spread_agrees_with_the_delta_method():
    """On a linear model the ensemble check and the delta method agree."""
    rng = np.random.default_rng(8)
    records = [linear_record(150, rng) for _ in range(6)]
    X = [r[0] for r in records]
    y = [r[2] for r in records]
    u_new, _, _ = linear_record(200, rng)
    model = linear_model().fit(X, y)
    _, delta = model.simulate(u_new, return_std=True, interval="confidence")
    mean, spread = ensemble_std(
        model, X, y, u_new, n_members=12, random_state=0, n_jobs=1
    )
    assert mean.shape == delta.shape
    ratio = np.median(spread / delta)
    # 0.94 here; bands half as wide again (or two thirds as wide) fall out.
    assert 0.7 < ratio < 1.4
    # Restarts of a linear least-squares fit land on the same minimum.
    _, same = ensemble_std(model, X, y, u_new, method="restarts", n_members=3)
    assert np.max(same) < 1e-2 * np.max(delta)


def test_plot_band_shades_the_interval():
    t = np.arange(5.0)
    ax = plot_band(t, np.zeros(5), np.ones(5), level=0.95, label="sim")
    (band,) = ax.collections
    ys = band.get_paths()[0].vertices[:, 1]
    assert ys.max() == pytest.approx(1.959964, rel=1e-5)
    assert ys.min() == pytest.approx(-1.959964, rel=1e-5)
    assert ax.get_lines()[0].get_label() == "sim"
    plt.close(ax.figure)


def test_cli_validate_draws_and_reports_bands(tmp_path, capsys):
    import pandas as pd

    from sysid_nn.cli import main

    rng = np.random.default_rng(9)
    frames = []
    for k in range(3):
        u, _, y = linear_record(300, rng, noise=0.05)
        frames.append(pd.DataFrame({"realization": k, "force": u[:, 0], "x": y}))
    train, new = tmp_path / "train.csv", tmp_path / "new.csv"
    frames[0].to_csv(train, index=False)
    pd.concat(frames[1:]).to_csv(new, index=False)
    model = tmp_path / "model.sysid"
    argv = ["fit", str(train), "--input", "force", "--output", "x", "--hidden", "0"]
    argv += ["--output-lags", "2", "--input-lags", "1", "--n-init", "1"]
    assert main([*argv, "--dt", "0.01", "--save", str(model)]) == 0
    out = tmp_path / "validation"
    argv = ["validate", "--model", str(model), str(new), "--split-by", "realization"]
    assert main([*argv, "--out", str(out), "--max-lag", "5", "--band", "0.9"]) == 0
    captured = capsys.readouterr()
    printed = captured.out
    table = pd.read_csv(out / "band.csv")
    assert list(table["record"]) == [0, 1]
    assert np.all((table["coverage"] > 0.8) & (table["coverage"] < 0.97))
    assert np.all(table["band_std_over_output_std"] < 0.5)
    assert "90 % prediction band of the free run covers" in printed
    assert "band is wide" not in captured.err
    assert (out / "band_0.png").exists() and (out / "band_1.png").exists()
    report = (out / "report.md").read_text()
    assert "`band.csv`" in report and "`band_<k>.png`" in report
    with pytest.raises(SystemExit):
        main([*argv, "--out", str(out), "--band", "95"])
    # A band ten times the output's spread covers everything, and is flagged.
    from sysid_nn import load_model, save_model

    est, info = load_model(model, with_info=True)
    est._noise_units = tuple(v + 100.0 for v in est._noise_units)
    wide = tmp_path / "wide.sysid"
    save_model(est, wide, inputs=info.inputs, outputs=info.outputs, dt=info.dt)
    argv[2] = str(wide)
    out = tmp_path / "wide"
    assert main([*argv, "--out", str(out), "--max-lag", "5", "--band", "0.9"]) == 0
    err = capsys.readouterr().err
    found = re.search(r"warning: The band is wide: .* on average ([\d.]+) times", err)
    assert found and 5 < float(found[1]) < 20
    assert pd.read_csv(out / "band.csv")["band_std_over_output_std"].min() > 5
    assert pd.read_csv(out / "band.csv")["coverage"].min() == 1.0
    assert "The band is wide" in (out / "report.md").read_text()


@pytest.mark.parametrize("rho", [0.0, 0.9])
def test_long_run_variance_of_correlated_residuals(rho):
    """The Bartlett estimate finds the long-run variance ``(1 + rho) / (1 - rho)``.

    White residuals get a bandwidth of a sample or two and the plain
    variance; AR(1) residuals the inflation that makes ``J^T J`` overstate
    the information in correlated data.
    """
    rng = np.random.default_rng(10)
    n = 40000
    e = rng.standard_normal(n)
    r = lfilter([1.0], [1.0, -rho], e) * np.sqrt(1 - rho**2)
    bounds = np.array([0, n // 2, n])
    L = _bandwidth(r[:, None], bounds)
    meat = sum(_bartlett(r[a:b, None], L) for a, b in pairwise(bounds))
    expected = (1 + rho) / (1 - rho)
    assert float(meat[0, 0]) / n == pytest.approx(expected, rel=0.15)
    assert L <= 2 if rho == 0 else L > 10


def test_interval_coverage_refuses_a_mean_and_std_for_bounds():
    from sysid_nn.uncertainty import interval_coverage, normal_interval

    rng = np.random.default_rng(3)
    y = rng.standard_normal(400)
    mean, std = y + 0.1 * rng.standard_normal(400), np.full(400, 0.1)
    with pytest.raises(ValueError, match=r"lower exceeds upper.*normal_interval"):
        interval_coverage(y, mean, std)  # the natural slip for (y, lower, upper)
    coverage = interval_coverage(y, *normal_interval(mean, std, 0.95))
    assert 0.9 < coverage <= 1.0
    # NaN bounds (a diverged run) still count as outside, not as crossed.
    lower, upper = normal_interval(mean, std, 0.95)
    lower[:100] = upper[:100] = np.nan
    assert interval_coverage(y, lower, upper) < 0.76
