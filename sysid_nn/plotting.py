"""Figures of the paper's section 4 (figs 4.1-4.7) and of residual analyses.

matplotlib is imported inside the functions, so ``import sysid_nn`` (and
even ``import sysid_nn.plotting``) does not load it. Every function takes
``ax=None``: given Axes are drawn on, otherwise a new figure is created. A
single-panel function returns its Axes, a multi-panel one its Figure.
Confidence bands are drawn as dotted horizontal lines, as in the paper. Axis
labels carry units where they are known (time and lags in seconds); the
labels of the user's quantities are arguments, so that their units can be
given (e.g. ``ylabel="displacement X [m]"``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from sysid_nn._docstrings import fill_doc

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
    "plot_backbone",
    "plot_band",
    "plot_cross_correlation",
    "plot_error_statistics",
    "plot_frequency_response",
    "plot_hysteresis",
    "plot_instantaneous_frequency",
    "plot_order_selection",
    "plot_records",
    "plot_residual_analysis",
    "plot_response",
]

# The ``ax`` (and ``title``) parameters of the plotting functions, and their
# time axis, documented once.
_AX_DOC = "ax : Axes, optional\n    Axes to draw on; a new figure if None."
_document_axes = fill_doc(
    t="t : array-like of shape (n_samples,)\n    Time.",
    ax=_AX_DOC,
    title_ax="title : str\n    Axes title.\n" + _AX_DOC,
    ax_pair="ax : pair of Axes, optional\n    Axes for the two panels; a new "
    "figure if None.",
)

_BAND_STYLE = {"color": "k", "linestyle": ":", "linewidth": 1.0}
_REFERENCE_STYLE = {"color": "0.65", "linewidth": 2.5, "zorder": 1}
_MODEL_STYLE = {"linestyle": "-", "linewidth": 0.8, "zorder": 2}


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
    n_rows: int, *, n_cols: int = 1, row_height: float = 2.4, width: float = 7.5
) -> tuple[Figure, list[Axes]]:
    """Create a figure of ``n_rows`` by ``n_cols`` panels without pyplot.

    The figure is not registered with pyplot and does not switch the user's
    backend: it is meant for scripts and reports that save figures to files
    (``fig.savefig`` renders with Agg whatever the interactive backend is).

    Parameters
    ----------
    n_rows : int
        Number of panel rows, one above the other.
    n_cols : int, default=1
        Number of panels side by side in each row.
    row_height : float, default=2.4
        Height of each panel in inches.
    width : float, default=7.5
        Figure width in inches.

    Returns
    -------
    fig : matplotlib.figure.Figure
        The figure (constrained layout).
    axes : list of matplotlib.axes.Axes
        Its panels, row by row from the top.

    Examples
    --------
    >>> from sysid_nn.plotting import panel_figure
    >>> fig, axes = panel_figure(3)
    >>> len(axes), round(float(fig.get_figheight()), 2)
    (3, 8.4)
    """
    for name, value in (("n_rows", n_rows), ("n_cols", n_cols)):
        if not isinstance(value, (int, np.integer)) or value < 1:
            raise ValueError(f"{name} must be a positive integer; got {value!r}.")
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, 1.2 + row_height * n_rows), layout="constrained")
    return fig, list(np.ravel(fig.subplots(n_rows, n_cols, squeeze=False)))


def _band(ax: Axes, band: float, alpha: float) -> None:
    """Dotted confidence limits at +-band (two lines, one legend entry)."""
    ax.axhline(band, label=f"{100 * (1 - alpha):g}% confidence band", **_BAND_STYLE)
    ax.axhline(-band, **_BAND_STYLE)


def _lag_axis(lags: np.ndarray, dt: float | None) -> tuple[np.ndarray, str]:
    if dt is None:
        return lags, "lag τ [samples]"
    return lags * dt, "lag τ [s]"


def _lag_style(lags: np.ndarray) -> dict[str, Any]:
    """A marker per lag while the markers stay apart, a plain line beyond."""
    return {"marker": "o" if lags.size <= 61 else "", "markersize": 3}


def _finish(ax: Axes, xlabel: str, ylabel: str, title: str | None) -> Axes:
    """Label the axes, set the title (None keeps it) and draw the legend."""
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    if title is not None:
        ax.set_title(title)
    ax.legend()
    return ax


@_document_axes
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
    %(t)s
    excitation, displacement : array-like
        One record ``(n_samples,)``, or ``(n_records, n_samples)`` with one
        row per record (all drawn).
    excitation_label, displacement_label : str
        Y-axis labels (units are the user's).
    %(ax_pair)s

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
        panel.set_xlabel("time t [s]")
    top.set_title("Training data")
    return top.figure


@_document_axes
def plot_response(
    t: Any,
    measured: Any,
    model: Any,
    *,
    label: str = "model",
    ylabel: str = "displacement",
    title: str | None = None,
    ax: Axes | None = None,
) -> Axes:
    """Measured against predicted or simulated response (figs 4.2, 4.6).

    Parameters
    ----------
    %(t)s
    measured : array-like of shape (n_samples,)
        Measured (Runge-Kutta simulated) response, drawn solid.
    model : array-like of shape (n_samples,) or dict of str to array-like
        One model response (named ``label``), or ``{name: response}`` to
        compare several models; drawn dashed.
    label : str, default="model"
        Legend text of a single ``model``.
    ylabel : str, default="displacement"
        Y-axis label, with the unit of the response, e.g.
        ``"displacement X [m]"``.
    title : str, optional
        Axes title.
    %(ax)s

    Returns
    -------
    matplotlib.axes.Axes
        The Axes drawn on: the measured response solid, every model dashed,
        and a legend.

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
    return _finish(ax, "time t [s]", ylabel, title)


@_document_axes
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
    %(title_ax)s

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
    ax.plot(x, whiteness_result.acf, label="autocorrelation", **_lag_style(x))
    _band(ax, whiteness_result.band, whiteness_result.alpha)
    return _finish(ax, xlabel, "r_ee(τ) / r_ee(0)", title)


@_document_axes
def plot_cross_correlation(
    cc_result: CrossCorrelationResult,
    *,
    dt: float | None = None,
    input_names: Sequence[str] | None = None,
    title: str = "Cross-correlation of residuals and input",
    ax: Axes | None = None,
) -> Axes:
    """Residual/input cross-correlation for lags -M..M with its band (fig. 4.4).

    Parameters
    ----------
    cc_result : CrossCorrelationResult
        From :func:`sysid_nn.residuals.cross_correlation_test`; one line per
        input column.
    dt : float, optional
        Sampling step; lags are shown in seconds when given.
    input_names : sequence of str, optional
        Legend text of every input column, e.g. ``["excitation F"]``;
        ``input i`` by default.
    %(title_ax)s

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
    n = cc_result.n_inputs
    names = [f"input {i}" for i in range(n)] if input_names is None else input_names
    if len(names) != n:
        raise ValueError(
            f"input_names must name the {n} input column(s); got {len(names)} names."
        )
    ax = _new_axes(ax)
    x, xlabel = _lag_axis(cc_result.lags, dt)
    for i, name in enumerate(names):
        ax.plot(x, cc_result.ccf[:, i], label=name, **_lag_style(x))
    _band(ax, cc_result.band, cc_result.alpha)
    ax.axvline(0.0, color="0.7", linewidth=0.5)
    return _finish(ax, xlabel + "  (τ > 0: input leads residual)", "r_eu(τ)", title)


@_document_axes
def plot_error_statistics(
    statistics: Mapping[str, ErrorStatistics],
    *,
    unit: str | None = None,
    scale: str = "auto",
    title: str = "Error statistics",
    ax: Axes | None = None,
) -> Axes:
    """Draw bars of ``mu_Ns`` and ``sigma_Ns`` for several models (figs 4.5, 4.7).

    Every bar is labelled with its value, so that bars of very different
    heights can be read off.

    Parameters
    ----------
    statistics : dict of str to ErrorStatistics
        ``{model name: error_statistics(...)}``.
    unit : str, optional
        Unit of the errors (the output's), e.g. ``"m"``, shown on the y axis.
    scale : {"auto", "linear", "symlog"}, default="auto"
        Y-axis scale. ``"symlog"`` is logarithmic in both directions
        (``mu_Ns`` may be negative) and linear below the smallest non-zero
        bar; ``"auto"`` chooses it when the largest bar is more than 100
        times the smallest non-zero one.
    %(title_ax)s

    Returns
    -------
    matplotlib.axes.Axes
        Two bar groups (``mu_Ns``, ``sigma_Ns``), one bar per model each,
        with value labels.

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
    if scale not in ("auto", "linear", "symlog"):
        raise ValueError(f"scale must be 'auto', 'linear' or 'symlog'; got {scale!r}.")
    ax = _new_axes(ax)
    names = list(statistics)
    x = np.arange(len(names))
    width = 0.38
    mus = [statistics[n].mu for n in names]
    sigmas = [statistics[n].sigma for n in names]
    for shift, values, label in (
        (-width / 2, mus, "μ_Ns (eq. 19)"),
        (width / 2, sigmas, "σ_Ns (eq. 20)"),
    ):
        bars = ax.bar(x + shift, values, width, label=label)
        ax.bar_label(bars, fmt="%.2g", fontsize=7, padding=2)
    sizes = np.abs(np.asarray(mus + sigmas, dtype=float))
    sizes = sizes[np.isfinite(sizes) & (sizes > 0)]
    if scale == "auto":
        scale = "symlog" if sizes.size and sizes.max() > 100 * sizes.min() else "linear"
    if scale == "symlog" and sizes.size:
        ax.set_yscale("symlog", linthresh=sizes.min())
        # Room for the value labels: a factor of 5 beyond the longest bars.
        ends = np.asarray(mus + sigmas, dtype=float)
        ends = ends[np.isfinite(ends)]
        ax.set_ylim(5 * min(ends.min(), 0.0), 5 * max(ends.max(), 0.0))
        # At most five labelled decades a side, no minor ticks: a symlog axis
        # otherwise labels every decade, which is slow to lay out and unreadable.
        low, high = np.floor(np.log10(sizes.min())), np.ceil(np.log10(sizes.max()))
        decades = 10.0 ** np.arange(low, high + 1, max(1, int(high - low) // 5 + 1))
        ticks = [*(-decades[::-1] if ends.min() < 0 else []), 0.0, *decades]
        ax.set_yticks(ticks if ends.max() > 0 else ticks[: decades.size + 1])
        ax.minorticks_off()
    else:
        ax.margins(y=0.12)
    ax.axhline(0.0, color="k", linewidth=0.5)
    ax.set_xticks(x, names)
    ylabel = "error" if unit is None else f"error [{unit}]"
    if scale == "symlog":
        ylabel += " (symmetric log scale)"
    return _finish(ax, "", ylabel, title)


@_document_axes
def plot_hysteresis(
    displacement: Any,
    restoring_force: Any,
    *,
    label: str = "measured",
    models: Mapping[str, Any] | None = None,
    xlabel: str = "displacement",
    ylabel: str = "restoring force",
    title: str = "Hysteresis loop",
    ax: Axes | None = None,
) -> Axes:
    """Draw a hysteresis loop: restoring force (or hysteretic state) vs displacement.

    Parameters
    ----------
    displacement, restoring_force : array-like of shape (n_samples,)
        Reference trajectory, drawn as a wide grey line.
    label : str, default="measured"
        Legend text of the reference.
    models : dict of str to array-like or (array-like, array-like), optional
        Models to overlay (thin coloured lines): a force over the same
        ``displacement``, or a tuple ``(displacement, force)`` of the model's
        own.
    xlabel : str, default="displacement"
        X-axis label, with the unit, e.g. ``"displacement X [m]"``.
    ylabel : str, default="restoring force"
        Y-axis label, e.g. ``"hysteretic state Z [m]"``.
    title : str, default="Hysteresis loop"
        Axes title.
    %(ax)s

    Returns
    -------
    matplotlib.axes.Axes
        The loops of the reference (grey) and of the models (coloured), with
        a legend naming them.

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
    # The reference as a wide grey band under the models' thin lines, so that
    # both stay visible where they coincide.
    curves = [(label, (displacement, restoring_force), _REFERENCE_STYLE)]
    for name, value in (models or {}).items():
        xy = value if isinstance(value, tuple) else (displacement, value)
        curves.append((name, xy, _MODEL_STYLE))
    for name, (d, f), style in curves:
        ax.plot(
            np.asarray(d, dtype=float), np.asarray(f, dtype=float), label=name, **style
        )
    return _finish(ax, xlabel, ylabel, title)


@_document_axes
def plot_residual_analysis(
    analysis: ResidualAnalysis,
    *,
    sequence: int | str = 0,
    output: int = 0,
    dt: float | None = None,
    input_names: Sequence[str] | None = None,
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
    input_names : sequence of str, optional
        Legend text of every input column (default ``input i``).
    %(ax_pair)s

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
        input_names=input_names,
        title=f"Cross-correlation of {kind} errors and input",
        ax=bottom,
    )
    top.figure.tight_layout()
    return top.figure


@_document_axes
def plot_band(
    t: Any,
    mean: Any,
    std: Any,
    *,
    level: float = 0.95,
    color: str | None = None,
    label: str = "model",
    ax: Axes | None = None,
) -> Axes:
    """Predicted or simulated response with its shaded interval.

    Parameters
    ----------
    %(t)s
    mean : array-like of shape (n_samples,)
        Predicted or simulated response, drawn as a line.
    std : array-like of shape (n_samples,)
        Its standard deviation, as returned with ``return_std=True``.
    level : float, default=0.95
        Level of the Gaussian interval shaded around ``mean`` (see
        :func:`sysid_nn.uncertainty.normal_interval`).
    color : str, optional
        Colour of the line and the band; the next colour of the Axes if None.
    label : str, default="model"
        Legend text of the line; the band is labelled with its level.
    %(ax)s

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


def plot_order_selection(estimator: Any, *, ax: Sequence[Axes] | None = None) -> Figure:
    """The evidence behind an ``"auto"`` order of a fitted model.

    The ``n_states="auto"`` of an :class:`ISSMRegressor`, or the ``"auto"``
    lags of a :class:`TDLRegressor` (``ceil(n_states / n_outputs)`` each).

    Top: the leading singular values of the subspace projection (log
    scale), with the order after their largest gap marked. Bottom: the
    validation free-run NRMSE of the linear model of every candidate order,
    the tolerance band above the best, and the chosen linear order and
    number of states marked, and, where the short-record rule offered a
    lower order, that order and which of the two validation kept
    (``order_selection_.reason``).

    Parameters
    ----------
    estimator : ISSMRegressor or TDLRegressor
        Fitted with ``n_states="auto"`` or ``"auto"`` lags (it has
        ``order_selection_``).
    ax : pair of Axes, optional
        Axes for the two panels; a new figure if None.

    Returns
    -------
    matplotlib.figure.Figure
        The figure drawn on.

    Examples
    --------
    >>> import numpy as np
    >>> from scipy.signal import lfilter
    >>> from sysid_nn import ISSMRegressor
    >>> u = np.random.default_rng(0).standard_normal((600, 1))
    >>> y = lfilter([0.0, 0.5], [1.0, -1.5, 0.7], u[:, 0])
    >>> model = ISSMRegressor(hidden_layer_sizes=(), n_init=1,
    ...                       random_state=0).fit(u, y)
    >>> fig = plot_order_selection(model)
    >>> len(fig.axes)
    2
    >>> import matplotlib.pyplot as plt
    >>> plt.close(fig)
    """
    selection = getattr(estimator, "order_selection_", None)
    if selection is None or selection.linear_order is None:
        raise ValueError(
            "estimator has no order selection to draw: fit an ISSMRegressor "
            'with n_states="auto" (or a TDLRegressor with "auto" lags) on '
            "records long enough for it (see order_selection_) first."
        )
    top, bottom = _new_panels(ax, 2, figsize=(6.4, 6.4))
    sv = np.asarray(selection.singular_values, dtype=float)
    orders = np.arange(1, len(sv) + 1)
    top.semilogy(orders, sv / sv[0], "o-", linewidth=1.0)
    top.axvline(
        selection.gap_order + 0.5,
        label=f"gap after {selection.gap_order}",
        **_BAND_STYLE,
    )
    _finish(top, "index", "singular value / largest", "Subspace singular values")
    scores = np.asarray(selection.scores, dtype=float)
    finite = np.isfinite(scores)
    bottom.plot(
        selection.orders[finite],
        scores[finite],
        "o-",
        linewidth=1.0,
        label="linear model",
    )
    if finite.any():
        bottom.axhline(
            (1.0 + selection.tolerance) * scores[finite].min() + selection.floor,
            label=f"best + {100 * selection.tolerance:g} %",
            **_BAND_STYLE,
        )
    bottom.axvline(
        selection.linear_order,
        color="C1",
        label=f"linear order {selection.linear_order}",
    )
    bottom.axvline(
        selection.n_states,
        color="C2",
        linestyle="--",
        label=f"n_states {selection.n_states}",
    )
    lowered = selection.get("short_record_states")
    if lowered is not None:
        # The short-record rule's order, and whether validation kept it.
        kept = lowered == selection.n_states
        bottom.axvline(
            lowered,
            color="C3",
            linestyle=":",
            label=f"short-record order {lowered} ("
            + ("kept" if kept else f"evidence's {selection.evidence_states} kept")
            + ")",
        )
    _finish(bottom, "order", "validation NRMSE", "Free run of the linear models")
    top.figure.tight_layout()
    return top.figure


@_document_axes
def plot_backbone(
    curve: Any,
    reference: Any = None,
    *,
    label: str = "model",
    reference_label: str = "generator",
    amplitude_label: str = "amplitude",
    ax: Sequence[Axes] | None = None,
) -> Figure:
    """Frequency and damping ratio against amplitude (a backbone).

    Top: the equivalent natural frequency; bottom: the equivalent damping
    ratio; both against the response amplitude, as returned by
    :func:`~sysid_nn.backbone`. A reference (e.g. the same analysis of the
    generator's own equations) is drawn beneath in grey.

    Parameters
    ----------
    curve : pandas.DataFrame
        From :func:`~sysid_nn.backbone`: columns ``amplitude``,
        ``frequency_hz``, ``damping_ratio``.
    reference : pandas.DataFrame, optional
        Another such curve, drawn beneath.
    label, reference_label : str
        Legend entries of ``curve`` and ``reference``.
    amplitude_label : str, default="amplitude"
        Label of the amplitude axis (give its units).
    %(ax_pair)s

    Returns
    -------
    matplotlib.figure.Figure
        The figure of the two panels.

    Examples
    --------
    >>> from sysid_nn import HystereticOscillator, backbone
    >>> curve = backbone(HystereticOscillator(r0=0.06), 0.01,
    ...                  amplitudes=[0.001, 0.003, 0.005])
    >>> fig = plot_backbone(curve, amplitude_label="amplitude [m]")
    >>> len(fig.axes)
    2
    >>> import matplotlib.pyplot as plt
    >>> plt.close(fig)
    """
    columns = ("amplitude", "frequency_hz", "damping_ratio")
    for name, frame in (("curve", curve), ("reference", reference)):
        if frame is not None and not all(
            c in getattr(frame, "columns", ()) for c in columns
        ):
            raise ValueError(
                f"{name} must be a DataFrame returned by sysid_nn.backbone, with "
                f"columns {', '.join(columns)}."
            )
    top, bottom = _new_panels(ax, 2, figsize=(6.4, 6.4), sharex=True)
    for panel, column in ((top, "frequency_hz"), (bottom, "damping_ratio")):
        if reference is not None:
            panel.plot(
                reference["amplitude"],
                reference[column],
                label=reference_label,
                **_REFERENCE_STYLE,
            )
        panel.plot(
            curve["amplitude"], curve[column], marker="o", label=label, **_MODEL_STYLE
        )
    _finish(top, "", "frequency [Hz]", "Backbone")
    _finish(bottom, amplitude_label, "damping ratio", None)
    top.figure.tight_layout()
    return top.figure


@_document_axes
def plot_instantaneous_frequency(
    track: Any,
    *,
    rest: float | None = None,
    title: str | None = "First mode along the record",
    ax: Axes | None = None,
) -> Axes:
    """The first mode's frequency along a record, by local linearisation.

    Parameters
    ----------
    track : pandas.DataFrame
        From :func:`~sysid_nn.instantaneous_frequency`: columns ``t`` and
        ``frequency_hz``.
    rest : float, optional
        A frequency drawn as a dotted line for reference (e.g. the first
        mode of :func:`~sysid_nn.modal_parameters`, at rest).
    %(title_ax)s

    Returns
    -------
    matplotlib.axes.Axes
        The axes drawn on.

    Examples
    --------
    >>> import pandas as pd
    >>> track = pd.DataFrame({"t": [0.0, 0.01, 0.02],
    ...                       "frequency_hz": [1.0, 0.9, 0.95]})
    >>> ax = plot_instantaneous_frequency(track, rest=1.0)
    >>> len(ax.lines)
    2
    >>> import matplotlib.pyplot as plt
    >>> plt.close(ax.figure)
    """
    if not all(c in getattr(track, "columns", ()) for c in ("t", "frequency_hz")):
        raise ValueError(
            "track must be a DataFrame returned by sysid_nn.instantaneous_frequency, "
            "with columns t and frequency_hz."
        )
    ax = _new_axes(ax)
    ax.plot(
        track["t"], track["frequency_hz"], label="local linearisation", **_MODEL_STYLE
    )
    if rest is not None:
        ax.axhline(rest, label=f"at rest, {rest:.3g} Hz", **_BAND_STYLE)
    return _finish(ax, "time [s]", "frequency [Hz]", title)


@_document_axes
def plot_frequency_response(
    frf: Any,
    dt: float | None = None,
    X: Any = None,
    y: Any = None,
    *,
    output: int = 0,
    input: int = 0,
    title: str | None = "Frequency response",
    ax: Sequence[Axes] | None = None,
) -> Figure:
    """A model's frequency response at small amplitude, and the data's.

    Top: the magnitude of the model's frequency response function (log
    scale) with its confidence band dotted, and, when the table has it, the
    data's H1 estimate beneath in grey; bottom: the coherence of the data
    or, without data, the model's phase.

    Parameters
    ----------
    frf : pandas.DataFrame or estimator
        From :func:`~sysid_nn.frequency_response`; or a fitted
        TDLRegressor or ISSMRegressor, whose table is computed with ``dt``,
        ``X`` and ``y``.
    dt : float, optional
        Sampling interval in seconds, needed with an estimator.
    X, y : array-like or list of array-like, optional
        Records for the H1 estimate, with an estimator.
    output, input : int, default=0
        The output-input pair drawn.
    title : str
        Title of the top panel.
    %(ax_pair)s

    Returns
    -------
    matplotlib.figure.Figure
        The figure: the magnitude above, the coherence or phase below.

    Examples
    --------
    >>> import numpy as np
    >>> from scipy.signal import lfilter
    >>> from sysid_nn import TDLRegressor
    >>> rng = np.random.default_rng(0)
    >>> u = rng.standard_normal((500, 1))
    >>> y = lfilter([0.0, 1.0], [1.0, -1.6, 0.81], u[:, 0])
    >>> model = TDLRegressor(output_lags=2, input_lags=1, hidden_layer_sizes=(),
    ...                      n_init=1, random_state=0).fit(u, y)
    >>> fig = plot_frequency_response(model, 0.01, u, y)
    >>> top, bottom = fig.axes
    >>> len(top.lines), top.get_yscale(), bottom.get_ylabel()
    (4, 'log', 'coherence')
    >>> import matplotlib.pyplot as plt
    >>> plt.close(fig)
    """
    if not hasattr(frf, "columns"):
        from sysid_nn._analysis._frf import frequency_response

        if dt is None:
            raise ValueError(
                "dt must be given with an estimator (the sampling interval in "
                "seconds); or pass the table of sysid_nn.frequency_response."
            )
        frf = frequency_response(frf, dt, X, y)
    columns = ("frequency_hz", "output", "input", "magnitude", "magnitude_low")
    if not all(c in frf.columns for c in columns):
        raise ValueError(
            "frf must be a DataFrame returned by sysid_nn.frequency_response, "
            f"with columns {', '.join(columns)}."
        )
    rows = frf[(frf["output"] == output) & (frf["input"] == input)]
    if not len(rows):
        raise ValueError(
            f"output={output!r}, input={input!r} is not a pair of the table; its "
            f"outputs are 0 to {frf['output'].max()} and inputs 0 to "
            f"{frf['input'].max()}."
        )
    top, bottom = _new_panels(ax, 2, figsize=(6.4, 6.4), sharex=True)
    f = rows["frequency_hz"]
    data = "h1_magnitude" in rows.columns
    if data:
        top.plot(f, rows["h1_magnitude"], label="data (H1)", **_REFERENCE_STYLE)
    top.plot(f, rows["magnitude"], label="model at rest", **_MODEL_STYLE)
    level = frf.attrs.get("level", 0.95)
    top.plot(f, rows["magnitude_low"], label=f"{100 * level:g}% band", **_BAND_STYLE)
    top.plot(f, rows["magnitude_high"], **_BAND_STYLE)
    top.set_yscale("log")
    _finish(top, "", "magnitude", title)
    if data:
        bottom.plot(f, rows["coherence"], label="data", **_MODEL_STYLE)
        bottom.set_ylim(0.0, 1.05)
        _finish(bottom, "frequency [Hz]", "coherence", None)
    else:
        bottom.plot(f, rows["phase_deg"], label="model at rest", **_MODEL_STYLE)
        _finish(bottom, "frequency [Hz]", "phase [deg]", None)
    top.figure.tight_layout()
    return top.figure
