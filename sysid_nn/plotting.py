"""Figures of the paper's section 4 (figs 4.1-4.7) and of residual analyses.

matplotlib is imported inside the functions, so ``import sysid_nn`` (and
even ``import sysid_nn.plotting``) does not load it. Every function takes
``ax=None``: given Axes are drawn on, otherwise a new figure is created. A
single-panel function returns its Axes, a multi-panel one its Figure.
Confidence bands are drawn as dotted horizontal lines, as in the paper.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from sysid_nn.metrics import ErrorStatistics
    from sysid_nn.residuals import (
        CrossCorrelationResult,
        ResidualAnalysis,
        WhitenessResult,
    )

__all__ = [
    "panel_figure",
    "plot_autocorrelation",
    "plot_band",
    "plot_cross_correlation",
    "plot_error_statistics",
    "plot_hysteresis",
    "plot_records",
    "plot_residual_analysis",
    "plot_response",
]

_BAND_STYLE = {"color": "k", "linestyle": ":", "linewidth": 1.0}


def _new_axes(ax: Axes | None) -> Axes:
    """The given Axes, or the Axes of a new figure."""
    if ax is not None:
        return ax
    import matplotlib.pyplot as plt

    return plt.subplots()[1]


def _new_panels(ax: Sequence[Axes] | None, n: int, **kwargs: Any) -> list[Axes]:
    """``n`` given Axes, or those of a new figure with ``n`` rows."""
    if ax is not None:
        axes = list(np.ravel(ax))
        if len(axes) != n:
            raise ValueError(f"ax must hold {n} Axes for this figure; got {len(axes)}.")
        return axes
    import matplotlib.pyplot as plt

    return list(np.ravel(plt.subplots(n, 1, **kwargs)[1]))


def panel_figure(
    n_rows: int, *, row_height: float = 2.4, width: float = 7.5
) -> tuple[Figure, list[Axes]]:
    """Create a figure of ``n_rows`` stacked panels without pyplot.

    The figure is not registered with pyplot and does not switch the user's
    backend: it is meant for scripts and reports that save figures to files
    (``fig.savefig`` renders with Agg whatever the interactive backend is).

    Parameters
    ----------
    n_rows : int
        Number of panels, one above the other.
    row_height : float, default=2.4
        Height of each panel in inches.
    width : float, default=7.5
        Figure width in inches.

    Returns
    -------
    fig : matplotlib.figure.Figure
        The figure (constrained layout).
    axes : list of matplotlib.axes.Axes
        Its panels, top to bottom.

    Examples
    --------
    >>> from sysid_nn.plotting import panel_figure
    >>> fig, axes = panel_figure(3)
    >>> len(axes), round(float(fig.get_figheight()), 2)
    (3, 8.4)
    """
    if not isinstance(n_rows, (int, np.integer)) or n_rows < 1:
        raise ValueError(f"n_rows must be a positive integer; got {n_rows!r}.")
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, 1.2 + row_height * n_rows), layout="constrained")
    return fig, list(np.ravel(fig.subplots(n_rows, 1, squeeze=False)))


def _band(ax: Axes, band: float, alpha: float) -> None:
    """Dotted confidence limits at +-band (two lines, one legend entry)."""
    ax.axhline(band, label=f"{100 * (1 - alpha):g}% confidence band", **_BAND_STYLE)
    ax.axhline(-band, **_BAND_STYLE)


def _lag_axis(lags: np.ndarray, dt: float | None) -> tuple[np.ndarray, str]:
    if dt is None:
        return lags, "lag τ [samples]"
    return lags * dt, "lag τ [s]"


def plot_records(
    t: Any,
    excitation: Any,
    displacement: Any,
    *,
    excitation_label: str = "excitation F(t)",
    displacement_label: str = "displacement X(t)",
    ax: Sequence[Axes] | None = None,
) -> Figure:
    """Training records: excitation and displacement panels (fig. 4.1).

    Parameters
    ----------
    t : array-like of shape (n_samples,)
        Time.
    excitation, displacement : array-like
        One record ``(n_samples,)``, or ``(n_records, n_samples)`` with one
        row per record (all drawn).
    excitation_label, displacement_label : str
        Y-axis labels (units are the user's).
    ax : pair of Axes, optional
        Axes for the two panels; a new figure if None.

    Returns
    -------
    matplotlib.figure.Figure
        Figure with the excitation (top) and displacement (bottom) panels.

    Examples
    --------
    >>> import numpy as np
    >>> t = np.arange(100) * 0.01
    >>> fig = plot_records(t, np.sin(t), np.cos(t))
    >>> [a.get_ylabel() for a in fig.axes]
    ['excitation F(t)', 'displacement X(t)']
    >>> import matplotlib.pyplot as plt
    >>> plt.close(fig)
    """
    top, bottom = _new_panels(ax, 2, sharex=True)
    t = np.asarray(t, dtype=float)
    for panel, data, label in (
        (top, excitation, excitation_label),
        (bottom, displacement, displacement_label),
    ):
        for row in np.atleast_2d(np.asarray(data, dtype=float)):
            panel.plot(t, row, linewidth=0.8)
        panel.set_ylabel(label)
    bottom.set_xlabel("time t [s]")
    top.set_title("Training data")
    return top.figure


def plot_response(
    t: Any,
    measured: Any,
    model: Any,
    *,
    label: str = "model",
    title: str | None = None,
    ax: Axes | None = None,
) -> Axes:
    """Measured against predicted or simulated response (figs 4.2, 4.6).

    Parameters
    ----------
    t : array-like of shape (n_samples,)
        Time.
    measured : array-like of shape (n_samples,)
        Measured (Runge-Kutta simulated) response, drawn solid.
    model : array-like of shape (n_samples,) or dict of str to array-like
        One model response (named ``label``), or ``{name: response}`` to
        compare several models; drawn dashed.
    label : str, default="model"
        Legend text of a single ``model``.
    title : str, optional
        Axes title.
    ax : Axes, optional
        Axes to draw on; a new figure if None.

    Returns
    -------
    matplotlib.axes.Axes
        The Axes drawn on, with a legend.

    Examples
    --------
    >>> import numpy as np
    >>> t = np.linspace(0, 1, 50)
    >>> ax = plot_response(t, np.sin(t), {"TDL": np.sin(t), "ISSM": 0.9 * np.sin(t)})
    >>> [text.get_text() for text in ax.get_legend().get_texts()]
    ['measured', 'TDL', 'ISSM']
    >>> import matplotlib.pyplot as plt
    >>> plt.close(ax.figure)
    """
    ax = _new_axes(ax)
    models = dict(model) if isinstance(model, Mapping) else {label: model}
    ax.plot(t, np.asarray(measured, dtype=float), "k-", linewidth=1.0, label="measured")
    for name, values in models.items():
        ax.plot(t, np.asarray(values, dtype=float), "--", linewidth=1.0, label=name)
    ax.set_xlabel("time t [s]")
    ax.set_ylabel("displacement")
    if title is not None:
        ax.set_title(title)
    ax.legend()
    return ax


def plot_autocorrelation(
    whiteness_result: WhitenessResult,
    *,
    dt: float | None = None,
    title: str = "Autocorrelation of residuals",
    ax: Axes | None = None,
) -> Axes:
    """Residual autocorrelation with its dotted confidence band (fig. 4.3).

    Parameters
    ----------
    whiteness_result : WhitenessResult
        From :func:`sysid_nn.residuals.whiteness_test`.
    dt : float, optional
        Sampling step; lags are shown in seconds when given.
    title : str
        Axes title.
    ax : Axes, optional
        Axes to draw on; a new figure if None.

    Returns
    -------
    matplotlib.axes.Axes
        One line for the autocorrelation (lags 0..M), two dotted band lines.

    Examples
    --------
    >>> import numpy as np
    >>> from sysid_nn.residuals import whiteness_test
    >>> res = whiteness_test(np.random.default_rng(0).standard_normal(400), 10)
    >>> ax = plot_autocorrelation(res)
    >>> len(ax.get_lines())
    3
    >>> import matplotlib.pyplot as plt
    >>> plt.close(ax.figure)
    """
    ax = _new_axes(ax)
    x, xlabel = _lag_axis(whiteness_result.lags, dt)
    ax.plot(x, whiteness_result.acf, "o-", markersize=3, label="autocorrelation")
    _band(ax, whiteness_result.band, whiteness_result.alpha)
    ax.set_xlabel(xlabel)
    ax.set_ylabel("r_ee(τ) / r_ee(0)")
    ax.set_title(title)
    ax.legend()
    return ax


def plot_cross_correlation(
    cc_result: CrossCorrelationResult,
    *,
    dt: float | None = None,
    title: str = "Cross-correlation of residuals and input",
    ax: Axes | None = None,
) -> Axes:
    """Residual/input cross-correlation for lags -M..M with its band (fig. 4.4).

    Parameters
    ----------
    cc_result : CrossCorrelationResult
        From :func:`sysid_nn.residuals.cross_correlation_test`; one line per
        input column (labelled ``input i``).
    dt : float, optional
        Sampling step; lags are shown in seconds when given.
    title : str
        Axes title.
    ax : Axes, optional
        Axes to draw on; a new figure if None.

    Returns
    -------
    matplotlib.axes.Axes
        One line per input over the lags, two dotted band lines.

    Examples
    --------
    >>> import numpy as np
    >>> from sysid_nn.residuals import cross_correlation_test
    >>> rng = np.random.default_rng(0)
    >>> e, u = rng.standard_normal((2, 400))
    >>> res = cross_correlation_test(e, u, max_lag=10)
    >>> ax = plot_cross_correlation(res)
    >>> ax.get_lines()[0].get_xdata().tolist() == list(range(-10, 11))
    True
    >>> import matplotlib.pyplot as plt
    >>> plt.close(ax.figure)
    """
    ax = _new_axes(ax)
    x, xlabel = _lag_axis(cc_result.lags, dt)
    for i in range(cc_result.n_inputs):
        ax.plot(x, cc_result.ccf[:, i], "o-", markersize=3, label=f"input {i}")
    _band(ax, cc_result.band, cc_result.alpha)
    ax.axvline(0.0, color="0.7", linewidth=0.5)
    ax.set_xlabel(xlabel + "  (τ > 0: input leads residual)")
    ax.set_ylabel("r_eu(τ)")
    ax.set_title(title)
    ax.legend()
    return ax


def plot_error_statistics(
    statistics: Mapping[str, ErrorStatistics],
    *,
    title: str = "Error statistics",
    ax: Axes | None = None,
) -> Axes:
    """Draw bars of ``mu_Ns`` and ``sigma_Ns`` for several models (figs 4.5, 4.7).

    Parameters
    ----------
    statistics : dict of str to ErrorStatistics
        ``{model name: error_statistics(...)}``.
    title : str
        Axes title.
    ax : Axes, optional
        Axes to draw on; a new figure if None.

    Returns
    -------
    matplotlib.axes.Axes
        Two bar groups (``mu_Ns``, ``sigma_Ns``), one bar per model each.

    Examples
    --------
    >>> from sysid_nn.metrics import error_statistics
    >>> stats = {
    ...     "TDL": error_statistics([[0.1, 0.3]]),
    ...     "ISSM": error_statistics([[0.0, 0.4]]),
    ... }
    >>> ax = plot_error_statistics(stats)
    >>> [t.get_text() for t in ax.get_xticklabels()]
    ['TDL', 'ISSM']
    >>> import matplotlib.pyplot as plt
    >>> plt.close(ax.figure)
    """
    if not statistics:
        raise ValueError("statistics is empty; pass {model name: ErrorStatistics}.")
    ax = _new_axes(ax)
    names = list(statistics)
    x = np.arange(len(names))
    width = 0.38
    mus = [statistics[n].mu for n in names]
    sigmas = [statistics[n].sigma for n in names]
    ax.bar(x - width / 2, mus, width, label="μ_Ns (eq. 19)")
    ax.bar(x + width / 2, sigmas, width, label="σ_Ns (eq. 20)")
    ax.axhline(0.0, color="k", linewidth=0.5)
    ax.set_xticks(x, names)
    ax.set_ylabel("error")
    ax.set_title(title)
    ax.legend()
    return ax


def plot_hysteresis(
    displacement: Any,
    restoring_force: Any,
    *,
    label: str = "measured",
    models: Mapping[str, Any] | None = None,
    ylabel: str = "restoring force",
    ax: Axes | None = None,
) -> Axes:
    """Draw a hysteresis loop: restoring force (or hysteretic state) vs displacement.

    Parameters
    ----------
    displacement, restoring_force : array-like of shape (n_samples,)
        Reference trajectory, drawn solid.
    label : str, default="measured"
        Legend text of the reference.
    models : dict of str to array-like or (array-like, array-like), optional
        Models to overlay (dashed): a force over the same ``displacement``,
        or a tuple ``(displacement, force)`` of the model's own.
    ylabel : str, default="restoring force"
        Y-axis label, e.g. ``"hysteretic state Z"``.
    ax : Axes, optional
        Axes to draw on; a new figure if None.

    Returns
    -------
    matplotlib.axes.Axes
        The Axes drawn on, with a legend.

    Examples
    --------
    >>> import numpy as np
    >>> x = np.sin(np.linspace(0, 6, 200))
    >>> ax = plot_hysteresis(x, np.tanh(3 * x), models={"ISSM": np.tanh(2.9 * x)})
    >>> len(ax.get_lines())
    2
    >>> import matplotlib.pyplot as plt
    >>> plt.close(ax.figure)
    """
    ax = _new_axes(ax)
    ax.plot(
        np.asarray(displacement, dtype=float),
        np.asarray(restoring_force, dtype=float),
        "k-",
        linewidth=0.8,
        label=label,
    )
    for name, value in (models or {}).items():
        d, f = value if isinstance(value, tuple) else (displacement, value)
        ax.plot(
            np.asarray(d, dtype=float),
            np.asarray(f, dtype=float),
            "--",
            linewidth=0.8,
            label=name,
        )
    ax.set_xlabel("displacement")
    ax.set_ylabel(ylabel)
    ax.set_title("Hysteresis loop")
    ax.legend()
    return ax


def plot_residual_analysis(
    analysis: ResidualAnalysis,
    *,
    sequence: int | str = 0,
    output: int = 0,
    dt: float | None = None,
    ax: Sequence[Axes] | None = None,
) -> Figure:
    """Autocorrelation and cross-correlation panels of a residual analysis.

    Parameters
    ----------
    analysis : ResidualAnalysis
        From :func:`sysid_nn.residuals.analyze_residuals`.
    sequence : int or "pooled", default=0
        Which sequence's results to draw.
    output : int, default=0
        Output column.
    dt : float, optional
        Sampling step; lags in seconds when given.
    ax : pair of Axes, optional
        Axes for the two panels; a new figure if None.

    Returns
    -------
    matplotlib.figure.Figure
        Two panels: autocorrelation (top), cross-correlation (bottom).

    Examples
    --------
    >>> import numpy as np
    >>> from sysid_nn.residuals import analyze_residuals
    >>> class Zero:
    ...     def simulate(self, X):
    ...         return np.zeros(len(X))
    >>> rng = np.random.default_rng(0)
    >>> report = analyze_residuals(Zero(), rng.standard_normal((300, 1)),
    ...                            rng.standard_normal(300), mode="simulation")
    >>> fig = plot_residual_analysis(report)
    >>> [ax.get_ylabel() for ax in fig.axes]
    ['r_ee(τ) / r_ee(0)', 'r_eu(τ)']
    >>> import matplotlib.pyplot as plt
    >>> plt.close(fig)
    """
    key = (sequence, output)
    if key not in analysis.whiteness:
        if sequence in analysis.divergent:
            raise ValueError(
                f"sequence {sequence!r} diverged (its residuals contain NaN), "
                "so it has no correlations to plot; choose another sequence."
            )
        raise ValueError(
            f"No results for sequence={sequence!r}, output={output!r}; available: "
            f"{sorted(analysis.whiteness, key=str)}."
        )
    top, bottom = _new_panels(ax, 2, figsize=(6.4, 6.4))
    kind = "prediction" if analysis.mode == "prediction" else "simulation"
    plot_autocorrelation(
        analysis.whiteness[key],
        dt=dt,
        title=f"Autocorrelation of {kind} errors",
        ax=top,
    )
    plot_cross_correlation(
        analysis.cross_correlation[key],
        dt=dt,
        title=f"Cross-correlation of {kind} errors and input",
        ax=bottom,
    )
    top.figure.tight_layout()
    return top.figure


def plot_band(
    t: Any,
    mean: Any,
    std: Any,
    *,
    level: float = 0.95,
    label: str = "model",
    color: str | None = None,
    ax: Axes | None = None,
) -> Axes:
    """Predicted or simulated response with its shaded interval.

    Parameters
    ----------
    t : array-like of shape (n_samples,)
        Time.
    mean : array-like of shape (n_samples,)
        Predicted or simulated response, drawn as a line.
    std : array-like of shape (n_samples,)
        Its standard deviation, as returned with ``return_std=True``.
    level : float, default=0.95
        Level of the Gaussian interval shaded around ``mean`` (see
        :func:`sysid_nn.uncertainty.normal_interval`).
    label : str, default="model"
        Legend text of the line; the band is labelled with its level.
    color : str, optional
        Colour of the line and the band; the next colour of the Axes if None.
    ax : Axes, optional
        Axes to draw on; a new figure if None.

    Returns
    -------
    matplotlib.axes.Axes
        The Axes drawn on.

    Examples
    --------
    >>> import numpy as np
    >>> t = np.linspace(0, 1, 50)
    >>> ax = plot_band(t, np.sin(t), np.full(50, 0.1), level=0.9)
    >>> [line.get_label() for line in ax.get_lines()]
    ['model']
    >>> len(ax.collections)
    1
    >>> import matplotlib.pyplot as plt
    >>> plt.close(ax.figure)
    """
    from sysid_nn.uncertainty import normal_interval

    ax = _new_axes(ax)
    mean = np.asarray(mean, dtype=float)
    lower, upper = normal_interval(mean, np.asarray(std, dtype=float), level)
    (line,) = ax.plot(t, mean, "-", linewidth=1.0, color=color, label=label)
    ax.fill_between(
        t,
        lower,
        upper,
        color=line.get_color(),
        alpha=0.25,
        linewidth=0.0,
        label=f"{100 * level:g} % interval",
    )
    return ax
