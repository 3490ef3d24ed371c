"""Tests of sysid_nn.residuals: levels, power, formulas, pooling and errors."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from scipy import stats
from scipy.signal import lfilter
from statsmodels.stats.diagnostic import acorr_ljungbox
from statsmodels.tsa.stattools import acf, ccf

from sysid_nn.residuals import (
    CrossCorrelationResult,
    NonlinearTestResult,
    ResidualAnalysis,
    WhitenessResult,
    analyze_residuals,
    cross_correlation_test,
    nonlinear_correlation_tests,
    whiteness_test,
)

N_TRIALS = 400
ALPHA = 0.05
# Three binomial standard deviations around the nominal level.
TOLERANCE = 3 * np.sqrt(ALPHA * (1 - ALPHA) / N_TRIALS)


def ar1(rng: np.random.Generator, n: int, phi: float) -> np.ndarray:
    return lfilter([1.0], [1.0, -phi], rng.standard_normal(n))


# ----------------------------------------------------------------------------
# A first-order ARX system y(t) = a y(t-1) + b u(t-1) + w(t) and its exact
# predictor, exposing the estimator contract (predict with horizon, simulate).
# ----------------------------------------------------------------------------
A_TRUE, B_TRUE = 0.8, 1.0


class FirstOrderARX:
    """Exact k-step predictor and simulator of a first-order ARX model."""

    def __init__(self, a: float = A_TRUE, b: float = B_TRUE, diverge_after=None):
        self.a, self.b, self.diverge_after = a, b, diverge_after

    def _one(self, X, y, horizon):
        u = np.asarray(X, dtype=float)[:, 0]
        if y is None:
            out = lfilter([0.0, self.b], [1.0, -self.a], u)
        else:
            # p_j(t) = a p_{j-1}(t-1) + b u(t-1), p_0 = y, zero initial values.
            out = np.asarray(y, dtype=float).ravel()
            u_prev = np.concatenate([[0.0], u[:-1]])
            for _ in range(horizon):
                out = self.a * np.concatenate([[0.0], out[:-1]]) + self.b * u_prev
        if self.diverge_after is not None:
            out = out.copy()
            out[self.diverge_after :] = np.nan
        return out

    def predict(self, X, y=None, *, horizon=1):
        if isinstance(X, list):
            ys = [None] * len(X) if y is None else y
            return [self._one(x, yy, horizon) for x, yy in zip(X, ys, strict=True)]
        return self._one(X, y, horizon)

    def simulate(self, X):
        return self.predict(X)


class ListwiseDiverging(FirstOrderARX):
    """Diverges (NaN) on the sequence with index ``bad`` only."""

    def __init__(self, bad: int):
        super().__init__()
        self.bad = bad

    def predict(self, X, y=None, *, horizon=1):
        out = super().predict(X, y, horizon=horizon)
        out[self.bad] = out[self.bad].copy()
        out[self.bad][50:] = np.nan
        return out


def arx_data(rng: np.random.Generator, n: int, noise: float = 0.1):
    u = rng.standard_normal(n)
    w = noise * rng.standard_normal(n)
    u_prev = np.concatenate([[0.0], u[:-1]])
    y = lfilter([1.0], [1.0, -A_TRUE], B_TRUE * u_prev + w)
    return u[:, None], y


# ----------------------------------------------------------------------------
# Whiteness
# ----------------------------------------------------------------------------
def test_whiteness_statistic_equals_textbook_formula():
    rng = np.random.default_rng(0)
    e = rng.standard_normal(300) + 0.3
    m = 12
    res = whiteness_test(e, max_lag=m, alpha=0.05)
    ec = e - e.mean()
    r0 = ec @ ec / e.size
    r = np.array([ec[k:] @ ec[: e.size - k] / e.size for k in range(m + 1)])
    x = e.size * np.sum(r[1:] ** 2) / r0**2
    assert isinstance(res, WhitenessResult)
    assert res.statistic == pytest.approx(x, rel=1e-12)
    assert res.dof == m
    assert res.p_value == pytest.approx(stats.chi2.sf(x, m))
    assert res.band == pytest.approx(1.959964 / np.sqrt(300), rel=1e-6)
    np.testing.assert_allclose(res.acf, r / r0, atol=1e-12)
    np.testing.assert_allclose(res.acf, acf(e, nlags=m, adjusted=False), atol=1e-12)
    lb = acorr_ljungbox(e, lags=[m], boxpierce=True)
    assert res.statistic == pytest.approx(lb["bp_stat"].iloc[0], rel=1e-10)
    assert res.ljung_box == pytest.approx(lb["lb_stat"].iloc[0], rel=1e-10)
    assert res.ljung_box_p_value == pytest.approx(lb["lb_pvalue"].iloc[0], rel=1e-8)


def test_whiteness_holds_level_on_white_noise():
    rng = np.random.default_rng(1)
    rejections = np.array(
        [
            not whiteness_test(rng.standard_normal(1000), 20).passed
            for _ in range(N_TRIALS)
        ]
    )
    assert abs(rejections.mean() - ALPHA) <= TOLERANCE


def test_whiteness_rejects_ar1():
    rng = np.random.default_rng(2)
    res = whiteness_test(ar1(rng, 500, 0.5), max_lag=25)
    assert not res.passed
    assert res.p_value < 1e-10
    assert res.acf[1] == pytest.approx(0.5, abs=0.1)
    frame = res.to_frame()
    assert frame.index.name == "lag"
    assert frame.loc[1, "outside"] and not frame.loc[0, "outside"]
    assert not res.summary["passed"]


def test_whiteness_pooling_sums_within_sequences():
    rng = np.random.default_rng(3)
    seqs = [rng.standard_normal(n) + off for n, off in ((200, 5.0), (150, -5.0))]
    m = 5
    res = whiteness_test(seqs, max_lag=m)
    # Lagged sums inside each centred sequence, then over sequences.
    cen = [s - s.mean() for s in seqs]
    sums = np.array([sum(c[k:] @ c[: c.size - k] for c in cen) for k in range(m + 1)])
    np.testing.assert_allclose(res.acf, sums / sums[0], atol=1e-12)
    assert res.n_samples == 350
    assert res.statistic == pytest.approx(350 * np.sum((sums[1:] / sums[0]) ** 2))
    # The offsets would make the concatenation look strongly correlated.
    assert whiteness_test(np.concatenate(seqs), max_lag=m).acf[1] > 0.9
    # A list of one sequence is that sequence.
    assert (
        whiteness_test([seqs[0]], m).statistic == whiteness_test(seqs[0], m).statistic
    )


# ----------------------------------------------------------------------------
# Cross-correlation
# ----------------------------------------------------------------------------
def test_cross_correlation_convention_matches_statsmodels_ccf():
    rng = np.random.default_rng(4)
    e, u = rng.standard_normal(400), rng.standard_normal(400)
    res = cross_correlation_test(e, u, max_lag=8)
    assert isinstance(res, CrossCorrelationResult)
    np.testing.assert_array_equal(res.lags, np.arange(-8, 9))
    # Positive lag tau: corr(e(t), u(t - tau)) = ccf(e, u)[tau].
    np.testing.assert_allclose(res.ccf[8:, 0], ccf(e, u, adjusted=False, nlags=9))
    np.testing.assert_allclose(res.ccf[8::-1, 0], ccf(u, e, adjusted=False, nlags=9))
    frame = res.to_frame()
    assert list(frame.columns) == ["input", "lag", "ccf", "lower", "upper", "outside"]
    assert len(frame) == 17


def test_cross_correlation_statistic_is_soderstrom_stoica_form():
    rng = np.random.default_rng(5)
    n, m = 500, 6
    e = rng.standard_normal(n)
    u = ar1(rng, n, 0.7)
    res = cross_correlation_test(e, u, max_lag=m)
    ec, uc = e - e.mean(), u - u.mean()
    lam = ec @ ec / n

    def cov(a, b, tau):  # cov(a(t), b(t - tau)) for either sign of tau
        return a[tau:] @ b[: n - tau] / n if tau >= 0 else b[-tau:] @ a[: n + tau] / n

    for tests, lags in ((res.positive, range(0, m + 1)), (res.negative, range(-m, 0))):
        lags = np.array(list(lags))
        r = np.array([cov(ec, uc, t) for t in lags])
        ru = np.array([[cov(uc, uc, abs(i - j)) for j in lags] for i in lags])
        x = n * r @ np.linalg.solve(lam * ru, r)
        assert tests[0].statistic == pytest.approx(x, rel=1e-10)
        assert tests[0].dof == lags.size
    no_zero = cross_correlation_test(e, u, max_lag=m, include_zero_lag=False)
    assert no_zero.positive[0].dof == m
    np.testing.assert_array_equal(no_zero.positive[0].lags, np.arange(1, m + 1))


def test_cross_correlation_holds_level_for_independent_signals():
    rng = np.random.default_rng(6)
    pos = neg = 0
    for _ in range(N_TRIALS):
        res = cross_correlation_test(rng.standard_normal(500), ar1(rng, 500, 0.8), 15)
        pos += not res.positive[0].passed
        neg += not res.negative[0].passed
    assert abs(pos / N_TRIALS - ALPHA) <= TOLERANCE
    assert abs(neg / N_TRIALS - ALPHA) <= TOLERANCE


def test_cross_correlation_rejects_filtered_input_at_positive_lags():
    rng = np.random.default_rng(7)
    u = rng.standard_normal((1000, 2))
    # Unmodelled dynamics from input 1 only.
    leak = lfilter([0.0, 0.0, 0.2], [1.0, -0.5], u[:, 1])
    res = cross_correlation_test(rng.standard_normal(1000) + leak, u, max_lag=10)
    summary = res.summary.set_index(["input", "side"])
    assert not summary.loc[(1, "positive"), "passed"]
    assert summary.loc[(0, "positive"), "passed"]
    assert summary.loc[(1, "negative"), "passed"]
    assert res.ccf[res.lags == 2, 1] > 3 * res.band


def test_cross_correlation_negative_lags_detect_feedback():
    rng = np.random.default_rng(8)
    pos = neg = 0
    trials = 100
    for _ in range(trials):
        e = rng.standard_normal(600)
        # The input depends on past residuals: feedback from output to input.
        u = rng.standard_normal(600) + lfilter([0.0, 0.6], [1.0, -0.5], e)
        res = cross_correlation_test(e, u, max_lag=10)
        pos += not res.positive[0].passed
        neg += not res.negative[0].passed
    assert neg / trials >= 0.95
    assert pos / trials <= ALPHA + 3 * np.sqrt(ALPHA * (1 - ALPHA) / trials)


# ----------------------------------------------------------------------------
# Higher-order tests
# ----------------------------------------------------------------------------
def test_nonlinear_tests_pass_on_white_independent_residuals():
    rng = np.random.default_rng(9)
    trials = 150
    rejected: dict[str, int] = {}
    for _ in range(trials):
        res = nonlinear_correlation_tests(
            rng.standard_normal(600), ar1(rng, 600, 0.5), max_lag=10
        )
        for t in res.tests:
            rejected[t.name] = rejected.get(t.name, 0) + (not t.passed)
    assert set(rejected) == {"phi_ee", "phi_ue", "phi_u2e", "phi_u2e2", "phi_eeu"}
    limit = ALPHA + 3 * np.sqrt(ALPHA * (1 - ALPHA) / trials)
    assert all(count / trials <= limit for count in rejected.values()), rejected


def test_nonlinear_tests_detect_squared_input_term():
    rng = np.random.default_rng(10)
    u = rng.standard_normal(2000)
    e = 0.2 * rng.standard_normal(2000) + 0.3 * (np.roll(u, 1) ** 2 - 1.0)
    res = nonlinear_correlation_tests(e, u, max_lag=10)
    assert isinstance(res, NonlinearTestResult)
    # A symmetric input hides u^2 from the linear cross-correlation ...
    linear, squared = res.get("phi_ue"), res.get("phi_u2e")
    assert abs(linear.values[linear.lags == 1][0]) < 0.1
    # ... but not from the higher-order one (true correlation about 0.9).
    assert squared.values[squared.lags == 1][0] > 0.8
    assert not squared.passed
    assert squared.statistic > 20 * linear.statistic
    assert not res.passed
    summary = res.summary
    assert set(summary.columns) >= {"test", "input", "p_value", "n_outside"}
    assert summary.loc[summary.test == "phi_u2e", "dof"].item() == 21


def test_nonlinear_tests_detect_residual_input_product():
    rng = np.random.default_rng(11)
    u, w = rng.standard_normal((2, 3000))
    # White but not independent: e(t) contains e(t-1) u(t-1).
    e = w + 0.6 * np.roll(w * u, 1)
    res = nonlinear_correlation_tests(e, u, max_lag=8)
    assert res.get("phi_ee").passed
    assert res.get("phi_ue").passed
    assert not res.get("phi_eeu").passed
    frame = res.to_frame()
    assert set(frame["test"]) == {"phi_ee", "phi_ue", "phi_u2e", "phi_u2e2", "phi_eeu"}


# ----------------------------------------------------------------------------
# analyze_residuals
# ----------------------------------------------------------------------------
def rows_per_sequence(n_out: int, n_in: int) -> int:
    return n_out * (1 + n_in * 5)  # whiteness + (2 cross + 3 higher-order) / input


def test_analyze_residuals_prediction_on_array():
    rng = np.random.default_rng(12)
    X, y = arx_data(rng, 1500)
    report = analyze_residuals(FirstOrderARX(), X, y, max_lag=15)
    assert isinstance(report, ResidualAnalysis)
    assert report.residuals.shape == y.shape
    summary = report.summary
    assert list(summary.columns) == [
        "sequence",
        "output",
        "input",
        "test",
        "statistic",
        "dof",
        "p_value",
        "passed",
        "n_samples",
        "status",
    ]
    assert len(summary) == rows_per_sequence(1, 1)
    assert set(summary["sequence"]) == {0}
    # The exact predictor leaves the white equation error.
    w = summary.set_index("test")
    assert w.loc["whiteness", "passed"]
    assert w.loc["cross_positive", "dof"] == 16
    assert (summary["status"] == "ok").all()
    frame = report.to_frame()
    assert set(frame["test"]) >= {"acf", "r_eu", "phi_u2e"}
    assert {"sequence", "output", "lag", "value", "lower", "upper"} <= set(frame)


def test_analyze_residuals_simulation_sees_coloured_error():
    rng = np.random.default_rng(13)
    X, y = arx_data(rng, 1500)
    report = analyze_residuals(FirstOrderARX(), X, y, mode="simulation", max_lag=15)
    w = report.summary.set_index("test")
    # Free-run error = AR(1)-filtered noise: coloured, but not input-correlated.
    assert not w.loc["whiteness", "passed"]
    assert w.loc["cross_positive", "passed"]
    # A wrong gain leaves the input in the residual.
    bad = analyze_residuals(FirstOrderARX(b=0.5), X, y, mode="simulation", max_lag=15)
    assert not bad.summary.set_index("test").loc["cross_positive", "passed"]
    assert not bad.passed


def test_analyze_residuals_lists_and_pooling():
    rng = np.random.default_rng(14)
    data = [arx_data(rng, n) for n in (600, 700, 800)]
    X = [d[0] for d in data]
    y = [d[1] for d in data]
    for mode in ("prediction", "simulation"):
        report = analyze_residuals(FirstOrderARX(), X, y, mode=mode, max_lag=10)
        assert isinstance(report.residuals, list)
        assert [r.shape for r in report.residuals] == [v.shape for v in y]
        summary = report.summary
        assert len(summary) == 4 * rows_per_sequence(1, 1)
        assert list(pd.unique(summary["sequence"])) == [0, 1, 2, "pooled"]
        pooled = summary[summary["sequence"] == "pooled"]
        assert (pooled["n_samples"] == 2100).all()
        # The pooled result is the pooled test on the three residual series.
        direct = whiteness_test(report.residuals, 10)
        assert report.whiteness["pooled", 0].statistic == pytest.approx(
            direct.statistic
        )
    horizon = analyze_residuals(FirstOrderARX(), X, y, horizon=3, max_lag=10)
    # k-step residuals are MA(k - 1) even for the exact model.
    assert not horizon.whiteness["pooled", 0].passed
    assert horizon.horizon == 3


def test_analyze_residuals_multioutput_rows():
    rng = np.random.default_rng(15)
    X = rng.standard_normal((400, 2))

    class TwoOutputs:
        def predict(self, X, y=None, *, horizon=1):
            return np.zeros((len(X), 2))

        def simulate(self, X):
            return self.predict(X)

    y = rng.standard_normal((400, 2))
    report = analyze_residuals(TwoOutputs(), X, y, max_lag=5, nonlinear=False)
    assert len(report.summary) == 2 * (1 + 2 * 2)
    assert set(report.whiteness) == {(0, 0), (0, 1)}
    assert report.nonlinear == {}


def test_analyze_residuals_reports_divergent_sequence():
    rng = np.random.default_rng(16)
    data = [arx_data(rng, 500) for _ in range(3)]
    X = [d[0] for d in data]
    y = [d[1] for d in data]
    report = analyze_residuals(ListwiseDiverging(bad=1), X, y, max_lag=10)
    assert report.divergent == (1,)
    summary = report.summary
    bad = summary[summary["sequence"] == 1]
    assert (bad["status"] == "divergent").all()
    assert bad["statistic"].isna().all()
    assert not bad["passed"].any()
    assert len(bad) == rows_per_sequence(1, 1)
    pooled = summary[summary["sequence"] == "pooled"]
    assert (pooled["status"] == "ok").all()
    assert (pooled["n_samples"] == 1000).all()  # sequences 0 and 2
    assert (1, 0) not in report.whiteness
    assert not report.passed
    # Array input that diverges: reported, not raised.
    single = analyze_residuals(FirstOrderARX(diverge_after=100), X[0], y[0], max_lag=5)
    assert single.divergent == (0,)
    assert (single.summary["status"] == "divergent").all()


def test_analyze_residuals_skip_drops_transient():
    rng = np.random.default_rng(17)
    X, y = arx_data(rng, 500)
    report = analyze_residuals(FirstOrderARX(), X, y, skip=20, max_lag=5)
    assert (report.summary["n_samples"] == 480).all()
    assert report.residuals.shape == (500,)


def test_summaries_print_whole_whatever_the_display_options():
    rng = np.random.default_rng(18)
    data = [arx_data(rng, 400) for _ in range(3)]
    X, y = [d[0] for d in data], [d[1] for d in data]
    report = analyze_residuals(FirstOrderARX(), X, y, max_lag=5)
    summary = report.summary
    cross = cross_correlation_test(report.residuals[0], X[0], max_lag=5)
    nonlinear = nonlinear_correlation_tests(report.residuals[0], X[0], max_lag=5)
    cramped = {
        "display.max_rows": 4,
        "display.min_rows": 2,
        "display.max_columns": 3,
        "display.width": 40,
        "display.max_colwidth": 6,
    }
    with pd.option_context(*[item for pair in cramped.items() for item in pair]):
        for frame in (summary, cross.summary, nonlinear.summary):
            printed = str(frame)
            assert "..." not in printed
            lines = printed.splitlines()
            assert len(lines) == len(frame) + 1  # the header, then every row
            assert lines[0].split() == [str(c) for c in frame.columns]
            name = "test" if "test" in frame else "side"
            for line, (_, row) in zip(lines[1:], frame.iterrows(), strict=True):
                for column in (name, "dof", "passed"):
                    assert str(row[column]) in line.split()
            assert frame.to_html().count("<tr") == frame._repr_html_().count("<tr")
        # What is cut from the summary prints whole too.
        pooled = summary[summary["sequence"] == "pooled"]
        assert len(str(pooled).splitlines()) == len(pooled) + 1
    # Still a DataFrame, and a plain one on request.
    assert isinstance(summary, pd.DataFrame)
    assert type(pd.DataFrame(summary)) is pd.DataFrame
    assert summary["passed"].dtype == bool


# ----------------------------------------------------------------------------
# Bad input
# ----------------------------------------------------------------------------
def test_nan_residuals_raise_naming_sample():
    e = np.random.default_rng(18).standard_normal(100)
    e[7] = np.nan
    with pytest.raises(ValueError, match="residuals contain NaN at sample 7"):
        whiteness_test(e)
    with pytest.raises(ValueError, match=r"residuals\[1\] contain NaN at sample 7"):
        cross_correlation_test([e[8:], e], [np.ones((92, 1)), np.ones((100, 1))])


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda e, u: whiteness_test(e, max_lag=100), "max_lag"),
        (lambda e, u: whiteness_test(e, max_lag=0), "max_lag"),
        (lambda e, u: whiteness_test(e, max_lag=2.5), "max_lag"),
        (lambda e, u: whiteness_test(e, alpha=1.5), "alpha"),
        (lambda e, u: whiteness_test(np.c_[e, e]), "residuals must be one series"),
        (lambda e, u: whiteness_test(e[:, None, None]), "residuals must be 1-D"),
        (lambda e, u: cross_correlation_test(e, u[:50]), "but inputs has 50"),
        (lambda e, u: cross_correlation_test(e, np.ones(100)), r"inputs\[:, 0\]"),
        (lambda e, u: cross_correlation_test([e], [u, u]), "but inputs has 2"),
        (lambda e, u: nonlinear_correlation_tests(e, u, max_lag=-1), "max_lag"),
    ],
)
def test_bad_input_raises_value_error(call, match):
    rng = np.random.default_rng(19)
    e, u = rng.standard_normal(100), rng.standard_normal((100, 1))
    with pytest.raises(ValueError, match=match):
        call(e, u)


def test_analyze_residuals_bad_arguments():
    rng = np.random.default_rng(20)
    X, y = arx_data(rng, 200)
    with pytest.raises(ValueError, match="mode"):
        analyze_residuals(FirstOrderARX(), X, y, mode="free")
    with pytest.raises(ValueError, match="skip"):
        analyze_residuals(FirstOrderARX(), X, y, skip=-1)
    with pytest.raises(ValueError, match="skip=200 leaves no samples"):
        analyze_residuals(FirstOrderARX(), X, y, skip=200)
    with pytest.raises(ValueError, match="X has 200 samples but y has 150"):
        analyze_residuals(FirstOrderARX(), X, y[:150])
    with pytest.raises(ValueError, match="both be arrays or both be lists"):
        analyze_residuals(FirstOrderARX(), [X], y)


def test_analyze_residuals_lags_follow_the_command_line_rule(tmp_path, capsys):
    from sysid_nn.cli._records import _Records
    from sysid_nn.cli._validate import _check_max_lag

    rng = np.random.default_rng(21)
    X, y = arx_data(rng, 30)
    # 30 samples hold 2 * 10 + 10: ten lags, not 25 (the default).
    with pytest.raises(ValueError, match=r"max_lag must be between 1 and 10 .* 30"):
        analyze_residuals(FirstOrderARX(), X, y)
    report = analyze_residuals(FirstOrderARX(), X, y, max_lag=10)
    assert (report.summary["n_samples"] == 30).all()
    # The command line draws the line at the same place.
    records = _Records({"y": [y]}, origins=["r.csv"])
    _check_max_lag(10, records)
    with pytest.raises(ValueError, match="--max-lag 10 or less"):
        _check_max_lag(11, records)
    # A skip counts against the record's length.
    with pytest.raises(ValueError, match="between 1 and 5"):
        analyze_residuals(FirstOrderARX(), X, y, max_lag=10, skip=10)
    # Too short for any lag: no advice to use about 25.
    X, y = arx_data(rng, 11)
    with pytest.raises(ValueError, match="at least 12 samples") as info:
        analyze_residuals(FirstOrderARX(), X, y, max_lag=1)
    assert "25" not in str(info.value)


def test_plot_names_the_inputs_by_their_columns():
    import matplotlib.pyplot as plt

    class Zero:
        def simulate(self, X):
            if isinstance(X, list):
                return [np.zeros(len(x)) for x in X]
            return np.zeros(len(X))

    rng = np.random.default_rng(0)
    X = pd.DataFrame(rng.standard_normal((300, 2)), columns=["force [N]", "wind"])
    y = rng.standard_normal(300)

    def legend(analysis, **kwargs):
        fig = analysis.plot(**kwargs)
        texts = [t.get_text() for t in fig.axes[1].get_legend().get_texts()]
        plt.close(fig)
        return texts[:2]

    on_frame = analyze_residuals(Zero(), X, y, mode="simulation", max_lag=5)
    assert on_frame.input_names == ("force [N]", "wind")
    assert legend(on_frame) == ["force [N]", "wind"]
    assert legend(on_frame, input_names=["F", "v"]) == ["F", "v"]
    # A list of frames, and arrays for an estimator fitted on named columns.
    on_list = analyze_residuals(Zero(), [X, X], [y, y], mode="simulation", max_lag=5)
    assert legend(on_list) == ["force [N]", "wind"]
    named = Zero()
    named.feature_names_in_ = np.array(["a", "b"], dtype=object)
    on_array = analyze_residuals(named, X.to_numpy(), y, mode="simulation", max_lag=5)
    assert legend(on_array) == ["a", "b"]
    anonymous = analyze_residuals(Zero(), X.to_numpy(), y, mode="simulation", max_lag=5)
    assert anonymous.input_names is None
    assert legend(anonymous) == ["input 0", "input 1"]


def test_y_init_starts_free_runs_from_measured_samples():
    from sysid_nn import TDLRegressor

    rng = np.random.default_rng(0)
    u = rng.standard_normal((700, 1))
    y = lfilter([0.0, 0.5], [1.0, -1.8, 0.9], u[:, 0])
    est = TDLRegressor(output_lags=2, input_lags=1, hidden_layer_sizes=(), n_init=1)
    est.fit(u[:400], y[:400])
    X, y_moving = u[500:], y[500:]  # starts in motion
    from_window = analyze_residuals(
        est, X, y_moving, mode="simulation", max_lag=10, y_init=30
    )
    expected = y_moving - est.simulate(X, y_init=y_moving[:30])
    np.testing.assert_array_equal(from_window.residuals, expected)
    # The window is left out of the tests, as skip leaves samples out.
    from_rest = analyze_residuals(est, X, y_moving, mode="simulation", max_lag=10)
    assert from_window.summary["n_samples"].iloc[0] == len(X) - 30
    assert from_rest.summary["n_samples"].iloc[0] == len(X)
    with pytest.raises(ValueError, match="y_init starts a free run"):
        analyze_residuals(est, X, y_moving, max_lag=10, y_init=30)
    with pytest.raises(ValueError, match="y_init must be an integer >= 0"):
        analyze_residuals(est, X, y_moving, mode="simulation", y_init=-1)
