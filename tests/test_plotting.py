"""Tests of sysid_nn.plotting: what is drawn, not just that it runs."""

from __future__ import annotations

import subprocess
import sys

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
import pytest
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from sysid_nn.metrics import error_statistics
from sysid_nn.plotting import (
    panel_figure,
    plot_autocorrelation,
    plot_cross_correlation,
    plot_error_statistics,
    plot_hysteresis,
    plot_records,
    plot_residual_analysis,
    plot_response,
)
from sysid_nn.residuals import (
    analyze_residuals,
    cross_correlation_test,
    whiteness_test,
)


@pytest.fixture(autouse=True)
def close_figures():
    yield
    plt.close("all")


def band_lines(ax: Axes) -> list[Line2D]:
    return [line for line in ax.get_lines() if line.get_linestyle() == ":"]


def legend_texts(ax: Axes) -> list[str]:
    return [t.get_text() for t in ax.get_legend().get_texts()]


def test_import_sysid_nn_does_not_import_matplotlib():
    code = (
        "import sys, sysid_nn, sysid_nn.residuals, sysid_nn.metrics, "
        "sysid_nn.plotting, sysid_nn.study, sysid_nn.cli; "
        "print('matplotlib' in sys.modules)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    )
    assert out.stdout.strip() == "False"


def test_panel_figure_stacks_panels_without_pyplot():
    import matplotlib.pyplot as plt

    before = plt.get_fignums()
    fig, axes = panel_figure(3, row_height=2.0, width=6.0)
    assert isinstance(fig, Figure) and len(axes) == 3
    assert fig.get_size_inches() == pytest.approx((6.0, 7.2))
    # Panels top to bottom, one column.
    tops = [ax.get_position().y0 for ax in axes]
    assert tops == sorted(tops, reverse=True)
    assert plt.get_fignums() == before  # not registered with pyplot
    with pytest.raises(ValueError, match="n_rows"):
        panel_figure(0)


def test_plot_records_two_panels():
    t = np.arange(200) * 0.01
    excitation = np.vstack([np.sin(t), np.cos(t)])
    fig = plot_records(t, excitation, t**2)
    assert isinstance(fig, Figure)
    top, bottom = fig.axes
    assert len(top.get_lines()) == 2 and len(bottom.get_lines()) == 1
    np.testing.assert_allclose(bottom.get_lines()[0].get_ydata(), t**2)
    assert top.get_ylabel() == "excitation F(t)"
    assert bottom.get_xlabel() == "time t [s]"
    assert top.get_title() == "Training data"
    # Given axes are used.
    fig2, axes = plt.subplots(2, 1)
    assert plot_records(t, t, t, ax=axes) is fig2
    with pytest.raises(ValueError, match="ax must hold 2 Axes"):
        plot_records(t, t, t, ax=axes[:1])


def test_plot_response_overlays_models():
    t = np.linspace(0, 2, 100)
    measured = np.sin(t)
    ax = plot_response(t, measured, 0.9 * measured, label="TDL simulation")
    assert isinstance(ax, Axes)
    lines = ax.get_lines()
    assert len(lines) == 2
    np.testing.assert_allclose(lines[0].get_ydata(), measured)
    np.testing.assert_allclose(lines[1].get_ydata(), 0.9 * measured)
    assert legend_texts(ax) == ["measured", "TDL simulation"]
    _, given = plt.subplots()
    out = plot_response(t, measured, {"TDL": measured, "ISSM": measured}, ax=given)
    assert out is given
    assert legend_texts(given) == ["measured", "TDL", "ISSM"]


def test_plot_autocorrelation_draws_acf_and_band():
    res = whiteness_test(np.random.default_rng(0).standard_normal(500), max_lag=15)
    ax = plot_autocorrelation(res)
    acf_line = ax.get_lines()[0]
    np.testing.assert_array_equal(acf_line.get_xdata(), np.arange(16))
    np.testing.assert_allclose(acf_line.get_ydata(), res.acf)
    bands = band_lines(ax)
    assert len(bands) == 2
    assert sorted(b.get_ydata()[0] for b in bands) == pytest.approx(
        [-res.band, res.band]
    )
    assert legend_texts(ax) == ["autocorrelation", "95% confidence band"]
    assert ax.get_xlabel() == "lag τ [samples]"
    seconds = plot_autocorrelation(res, dt=0.01)
    np.testing.assert_allclose(seconds.get_lines()[0].get_xdata(), np.arange(16) * 0.01)
    assert seconds.get_xlabel() == "lag τ [s]"


def test_plot_cross_correlation_one_line_per_input():
    rng = np.random.default_rng(1)
    res = cross_correlation_test(
        rng.standard_normal(400), rng.standard_normal((400, 2)), 10, alpha=0.01
    )
    ax = plot_cross_correlation(res)
    solid = [line for line in ax.get_lines() if line.get_linestyle() == "-"]
    assert len(solid) == 3  # two inputs and the vertical zero-lag marker
    np.testing.assert_array_equal(solid[0].get_xdata(), np.arange(-10, 11))
    np.testing.assert_allclose(solid[1].get_ydata(), res.ccf[:, 1])
    bands = band_lines(ax)
    assert [b.get_ydata()[0] for b in bands] == pytest.approx([res.band, -res.band])
    assert legend_texts(ax) == ["input 0", "input 1", "99% confidence band"]
    assert ax.get_ylabel() == "r_eu(τ)"


def test_plot_error_statistics_bars():
    stats = {
        "TDL": error_statistics([[0.1, 0.3], [0.0, 0.2]]),
        "ISSM": error_statistics([[0.5, -0.5]]),
    }
    ax = plot_error_statistics(stats)
    heights = [p.get_height() for p in ax.patches]
    mu = [stats[k].mu for k in stats]
    sigma = [stats[k].sigma for k in stats]
    assert heights == pytest.approx(mu + sigma)
    assert [t.get_text() for t in ax.get_xticklabels()] == ["TDL", "ISSM"]
    assert legend_texts(ax) == ["μ_Ns (eq. 19)", "σ_Ns (eq. 20)"]
    with pytest.raises(ValueError, match="statistics is empty"):
        plot_error_statistics({})


def test_plot_hysteresis_loops():
    x = np.sin(np.linspace(0, 6, 100))
    force = np.tanh(3 * x)
    own_x = 1.1 * x
    ax = plot_hysteresis(
        x,
        force,
        models={"TDL": 0.9 * force, "ISSM": (own_x, force)},
        ylabel="hysteretic state Z",
    )
    lines = ax.get_lines()
    assert len(lines) == 3
    np.testing.assert_allclose(lines[1].get_xdata(), x)
    np.testing.assert_allclose(lines[1].get_ydata(), 0.9 * force)
    np.testing.assert_allclose(lines[2].get_xdata(), own_x)
    assert legend_texts(ax) == ["measured", "TDL", "ISSM"]
    assert ax.get_ylabel() == "hysteretic state Z"
    assert ax.get_xlabel() == "displacement"


class _Zero:
    def predict(self, X, y=None, *, horizon=1):
        return (
            [np.zeros(len(x)) for x in X] if isinstance(X, list) else np.zeros(len(X))
        )

    def simulate(self, X):
        return self.predict(X)


def test_residual_analysis_plot():
    rng = np.random.default_rng(2)
    X = [rng.standard_normal((300, 1)) for _ in range(2)]
    y = [rng.standard_normal(300) for _ in range(2)]
    report = analyze_residuals(_Zero(), X, y, mode="simulation", max_lag=8)
    fig = report.plot()
    assert isinstance(fig, Figure)
    top, bottom = fig.axes
    pooled = report.whiteness["pooled", 0]
    np.testing.assert_allclose(top.get_lines()[0].get_ydata(), pooled.acf)
    assert top.get_title() == "Autocorrelation of simulation errors"
    assert bottom.get_title() == "Cross-correlation of simulation errors and input"
    fig0 = plot_residual_analysis(report, sequence=0)
    np.testing.assert_allclose(
        fig0.axes[0].get_lines()[0].get_ydata(), report.whiteness[0, 0].acf
    )
    with pytest.raises(ValueError, match="No results for sequence=5"):
        report.plot(sequence=5)


def test_residual_analysis_plot_refuses_divergent_sequence():
    class Diverging(_Zero):
        def simulate(self, X):
            return np.full(len(X), np.nan)

    rng = np.random.default_rng(3)
    report = analyze_residuals(
        Diverging(), rng.standard_normal((100, 1)), np.ones(100), mode="simulation"
    )
    with pytest.raises(ValueError, match="sequence 0 diverged"):
        report.plot()


def test_panel_figure_columns_row_by_row():
    _, axes = panel_figure(2, n_cols=3)
    assert len(axes) == 6
    rows = [round(ax.get_subplotspec().rowspan.start) for ax in axes]
    assert rows == [0, 0, 0, 1, 1, 1]
    with pytest.raises(ValueError, match="n_cols"):
        panel_figure(1, n_cols=0)


def test_plot_cross_correlation_names_the_inputs():
    rng = np.random.default_rng(4)
    res = cross_correlation_test(
        rng.standard_normal(300), rng.standard_normal((300, 2)), 5
    )
    ax = plot_cross_correlation(res, input_names=["force F [N]", "base a [m/s²]"])
    assert legend_texts(ax)[:2] == ["force F [N]", "base a [m/s²]"]
    with pytest.raises(ValueError, match="input_names must name the 2"):
        plot_cross_correlation(res, input_names=["force"])


def test_plot_error_statistics_readable_across_orders_of_magnitude():
    close = {
        "A": error_statistics([[0.1, 0.3]]),
        "B": error_statistics([[0.2, 0.1]]),
    }
    ax = plot_error_statistics(close, unit="m")
    assert ax.get_yscale() == "linear" and ax.get_ylabel() == "error [m]"
    labels = [t.get_text() for t in ax.texts]
    assert len(labels) == 4 and f"{close['A'].sigma:.2g}" in labels
    apart = {
        "A": error_statistics([[1e-6, -1e-6]]),
        "B": error_statistics([[-0.5, 0.7]]),
    }
    ax = plot_error_statistics(apart, unit="m")
    assert ax.get_yscale() == "symlog"
    assert ax.get_ylabel() == "error [m] (symmetric log scale)"
    low, high = ax.get_ylim()
    assert low < apart["B"].mu and high > apart["B"].sigma
    assert plot_error_statistics(apart, scale="linear").get_yscale() == "linear"
    with pytest.raises(ValueError, match="scale must be"):
        plot_error_statistics(apart, scale="log")


def test_plot_labels_carry_the_users_units():
    t = np.linspace(0, 1, 50)
    ax = plot_response(t, t, t, ylabel="strain ε [µm/m]")
    assert ax.get_ylabel() == "strain ε [µm/m]"
    ax = plot_hysteresis(
        t, t**2, xlabel="drift [mm]", ylabel="force [kN]", title="Storey 1"
    )
    assert (ax.get_xlabel(), ax.get_ylabel(), ax.get_title()) == (
        "drift [mm]",
        "force [kN]",
        "Storey 1",
    )
    # The reference stays visible under the models: wider and drawn below.
    ref, model = plot_hysteresis(t, t**2, models={"M": t**2}).get_lines()
    assert ref.get_linewidth() > model.get_linewidth()
    assert ref.get_zorder() < model.get_zorder()


def test_residual_analysis_plot_names_the_inputs():
    rng = np.random.default_rng(5)
    report = analyze_residuals(
        _Zero(), rng.standard_normal((200, 1)), rng.standard_normal(200), max_lag=5
    )
    fig = plot_residual_analysis(report, input_names=["force F [N]"])
    assert legend_texts(fig.axes[1])[0] == "force F [N]"
