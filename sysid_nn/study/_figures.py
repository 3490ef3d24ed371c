"""The study's figures (figs 4.1-4.7 and the hysteresis loops)."""

from __future__ import annotations

import re
import warnings
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
from sklearn.utils import Bunch

from sysid_nn.plotting import panel_figure
from sysid_nn.study._models import StudyModel
from sysid_nn.study._scoring import _scored


def _label(data: Bunch, field: str) -> str:
    """Axis label of a record field: its name and, when known, its unit.

    A unit the name already carries (``"x [m]"``, ``"v (m/s)"``) is not repeated.
    """
    name = data.get("names", {}).get(field, field)
    unit = data.get("units", {}).get(field)
    if not unit or any(f"{a}{unit}{b}" in name for a, b in ("[]", "()")):
        return name
    return f"{name} [{unit}]"


def _first_record(data: Bunch) -> str:
    """How the figures name the record they draw (the study's or the user's)."""
    return f"{data.get('record_name', 'test realisation')} 0"


def _panels(models, evaluation) -> list[tuple[str, StudyModel, int, str]]:
    """``(name, model, column, field)`` of every model's scored outputs."""
    return [
        (name, model, k, field)
        for name, model in models.items()
        for k, field in _scored(model, evaluation.outputs)
    ]


def _panel_title(model: StudyModel, field: str, data: Bunch, evaluation) -> str:
    """The model's label, and the output's when several outputs are scored."""
    if len(evaluation.outputs) == 1:
        return model.label
    return f"{model.label}: {_label(data, field)}"


def _model_grid(model: StudyModel, n: int, dt: float) -> np.ndarray:
    return np.arange(n) * dt * model.step


#: Records longer than this many samples get an error trace and a zoomed inset:
#: at full length measured and modelled lines overlap into one.
LONG_RECORD = 1000


def show_long_record(ax, t, measured, model, std=None) -> Any:
    """Add the error trace and a zoom on the largest error to a long record's axes.

    ``std`` (the model's standard deviation) also draws the band in the zoom.
    Returns the inset axes.
    """
    t, measured, model = (np.asarray(a, dtype=float) for a in (t, measured, model))
    error = measured - model
    ax.plot(t, error, color="C3", linewidth=0.6, label="error (measured - model)")
    ax.legend(fontsize=7, loc="lower left")
    # A window of a twentieth of the record (at least 100 samples) around the
    # largest finite error.
    width = max(100, t.size // 20)
    finite = np.where(np.isfinite(error), np.abs(error), -1.0)
    centre = int(np.argmax(finite))
    lo = max(0, min(centre - width // 2, t.size - width))
    window = slice(lo, lo + width)
    inset = ax.inset_axes([0.62, 0.62, 0.36, 0.34])
    if std is not None:
        std = np.asarray(std, dtype=float)
        inset.fill_between(
            t[window],
            (model - 1.96 * std)[window],
            (model + 1.96 * std)[window],
            color="C0",
            alpha=0.25,
            linewidth=0,
        )
    inset.plot(t[window], measured[window], "k-", linewidth=0.8)
    inset.plot(t[window], model[window], "--", color="C0", linewidth=0.8)
    inset.tick_params(labelsize=6)
    inset.set_title("zoom: largest error", fontsize=7)
    ax.indicate_inset_zoom(inset, edgecolor="0.4")
    return inset


def _response_figure(models, data, evaluation, mode, title) -> Any:
    from sysid_nn.plotting import plot_response

    panels = _panels(models, evaluation)
    fig, axes = panel_figure(len(panels))
    for ax, (name, model, k, field) in zip(axes, panels, strict=True):
        (_,), (y,) = model.arrays(data.test, [0])
        y_k = y.reshape(len(y), -1)[:, k]
        e = evaluation.errors[name, mode, field][0]
        t = _model_grid(model, y_k.size, data.dt)
        ylabel = _label(data, field)
        plot_response(t, y_k, y_k - e, label=model.label, ylabel=ylabel, ax=ax)
        if y_k.size > LONG_RECORD:
            show_long_record(ax, t, y_k, y_k - e)
        ax.set_title(
            f"{title}: {_panel_title(model, field, data, evaluation)}, "
            f"{_first_record(data)}",
            fontsize=9,
        )
    return fig


def _lag_span(models, data, evaluation) -> float:
    """Lag range in seconds shared by every correlation panel.

    The tests' largest lag on the coarsest model grid, and at least one
    natural period when the system's is known, so that a period's worth of
    residual correlation is in view whatever the model's sampling step.
    """
    span = max(evaluation.max_lag * data.dt * m.step for m in models.values())
    return max(span, data.get("natural_period", 0.0))


def _correlation_figure(models, data, evaluation, kind) -> Any:
    from sysid_nn.plotting import plot_autocorrelation, plot_cross_correlation
    from sysid_nn.residuals import cross_correlation_test, whiteness_test

    span = _lag_span(models, data, evaluation)
    panels = _panels(models, evaluation)
    fig, axes = panel_figure(len(panels))
    for ax, (name, model, _, field) in zip(axes, panels, strict=True):
        e = evaluation.errors[name, "prediction", field][0]
        label = _panel_title(model, field, data, evaluation)
        if not np.all(np.isfinite(e)):
            ax.text(0.5, 0.5, f"{label}: prediction diverged", ha="center")
            continue
        step = data.dt * model.step
        lags = int(np.ceil(span / step - 1e-9))
        tested = evaluation.max_lag * step
        ax.axvspan(0 if kind == "acf" else -tested, tested, color="0.92", zorder=0)
        if kind == "acf":
            found = whiteness_test(e, lags, evaluation.alpha)
            plot_autocorrelation(found, dt=step, title=label, ax=ax)
            ax.set_xlim(-0.02 * span, 1.02 * span)
        else:
            (X,), _ = model.arrays(data.test, [0])
            found = cross_correlation_test(e, X, lags, evaluation.alpha)
            names = [_label(data, field) for field in model.inputs]
            plot_cross_correlation(
                found, dt=step, input_names=names, title=label, ax=ax
            )
            ax.set_xlim(-1.02 * span, 1.02 * span)
    period = data.get("natural_period")
    fig.suptitle(
        f"One-step prediction errors, {_first_record(data)}: lags up to {span:.3g} s"
        + (f" (natural period {period:.3g} s)" if period else "")
        + f";\nshaded: the lags of the tables' tests (up to {evaluation.max_lag} "
        "samples of each model), whose verdicts are chi-square tests over all "
        "those lags together;\ndotted: the per-lag band, which a few lags leave "
        "by chance",
        fontsize=9,
    )
    return fig


def _statistics_figure(data, evaluation, mode, title) -> Any:
    """One panel per scored output: its errors' eq. 19-20 bars, in its unit."""
    from sysid_nn.plotting import plot_error_statistics

    outputs = evaluation.outputs
    fig, axes = panel_figure(len(outputs), row_height=3.6)
    for ax, field in zip(axes, outputs, strict=True):
        plot_error_statistics(
            evaluation.statistics[mode][field],
            unit=data.get("units", {}).get(field),
            title=title if len(outputs) == 1 else f"{title}: {_label(data, field)}",
            ax=ax,
        )
        if not data.get("paper_terms", True):  # a user's records: plain names
            handles, _ = ax.get_legend_handles_labels()
            ax.legend(handles, ["mean error", "error std"])
    return fig


def hysteresis_loops(
    models: Mapping[str, StudyModel], data: Bunch, evaluation: Bunch
) -> Bunch:
    """Restoring force and hysteretic state against displacement, test record 0.

    The truth is ``g = alpha X + (1 - alpha) Z`` (eq. 14) against ``X``. Each
    model is drawn along its simulated displacement ``X_m``: the restoring
    force ``alpha X_m + (1 - alpha) Z(X_m)`` that the true hysteretic element
    (eq. 15, rate-independent) develops under that displacement history, so
    loops compare at a glance whatever the model's sampling step. Models
    with unmeasured states (the ISSMs) are also drawn by their estimated
    states, mapped onto ``Z`` by least squares (the states' coordinates are
    the network's own; ``|r|`` says how well they track ``Z``).

    Parameters
    ----------
    models : dict of str to StudyModel
        The fitted models, e.g. from :func:`fit_models`.
    data : Bunch
        From :func:`generate_data`.
    evaluation : Bunch
        From :func:`evaluate`.

    Returns
    -------
    Bunch
        ``truth``: ``(X, g, Z)``; ``force``: ``{label: (X_m, g_m)}``;
        ``state``: ``{label: (X_m, Z_m)}`` for models with states;
        ``state_correlation``: ``{label: |r|}`` of ``Z_m`` and ``Z``.

    Examples
    --------
    >>> from sysid_nn.study import StudyConfig, evaluate, fit_models, generate_data
    >>> from sysid_nn.study import hysteresis_loops
    >>> config = StudyConfig(models=("linear",), n_samples=600, n_test=2, max_lag=10,
    ...                      n_candidates=3, estimator_params={"all": {"n_init": 1}})
    >>> data = generate_data(config)
    >>> models = fit_models(data, config)
    >>> loops = hysteresis_loops(models, data, evaluate(models, data, config))
    >>> sorted(loops.force), loops.state
    (['linear (OE)'], {})
    """
    alpha = data.oscillator.get_params()["alpha"]
    x, z = data.test.displacement[0], data.test.hysteretic[0]
    out = Bunch(truth=(x, alpha * x + (1 - alpha) * z, z), force={}, state={})
    out.state_correlation = {}
    for name, model in models.items():
        (X,), _ = model.arrays(data.test, [0])
        cut = slice(None, None, model.step)
        e = evaluation.errors[name, "simulation", "displacement"][0]
        x_m = x[cut] - e
        if not np.all(np.isfinite(x_m)):
            continue
        z_x = data.oscillator.hysteretic_state(x_m)
        out.force[model.label] = (x_m, alpha * x_m + (1 - alpha) * z_x)
        if hasattr(model.estimator, "predict_states"):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                states = model.estimator.predict_states(X).states
            hidden = states[:, len(model.outputs) :]
            design = np.column_stack([np.ones(len(hidden)), hidden])
            coef = np.linalg.lstsq(design, z[cut], rcond=None)[0]
            z_m = design @ coef
            out.state[model.label] = (x_m, z_m)
            out.state_correlation[model.label] = float(
                abs(np.corrcoef(z_m, z[cut])[0, 1])
            )
    return out


def _hysteresis_figure(loops: Bunch, data: Bunch) -> Any:
    from sysid_nn.plotting import plot_hysteresis

    # Only models with a hidden state are drawn: the true hysteretic element
    # evaluated along another model's displacement would show Bouc-Wen loops
    # that the model itself does not have.
    x, _, z = loops.truth
    panels = [
        (
            f"{label}: estimated hidden state, |r| = "
            f"{loops.state_correlation[label]:.2f}",
            "true Z",
            _label(data, "hysteretic"),
            z,
            xy,
        )
        for label, xy in loops.state.items()
    ]
    fig, axes = panel_figure(max(1, -(-len(panels) // 2)), n_cols=2, width=10.0)
    for ax, (title, truth, ylabel, y, xy) in zip(axes, panels, strict=False):
        plot_hysteresis(
            x,
            y,
            label=truth,
            models={title.split(":")[0]: xy},
            xlabel=_label(data, "displacement"),
            ylabel=ylabel,
            title=title,
            ax=ax,
        )
        ax.title.set_fontsize(9)
    for ax in axes[len(panels) :]:
        ax.set_visible(False)
    fig.suptitle(
        "Hysteresis on test realisation 0: the true hysteretic state Z (grey) and "
        "each ISSM's estimated hidden state along its own free run, mapped onto Z "
        "by least squares",
        fontsize=9,
    )
    return fig


#: Figure files of a study directory, in the paper's order.
FIGURES = {
    "fig4_1_training_data.png": "Training data (fig. 4.1)",
    "fig4_2_prediction.png": "One-step prediction of the first test record (fig. 4.2)",
    "fig4_3_residual_autocorrelation.png": (
        "Autocorrelation of prediction errors (fig. 4.3)"
    ),
    "fig4_4_residual_cross_correlation.png": (
        "Cross-correlation of prediction errors and input (fig. 4.4)"
    ),
    "fig4_5_prediction_error_statistics.png": (
        "μ_Ns and σ_Ns of prediction errors (fig. 4.5)"
    ),
    "fig4_6_simulation.png": "Free-run simulation of the first test record (fig. 4.6)",
    "fig4_7_simulation_error_statistics.png": (
        "μ_Ns and σ_Ns of simulation errors (fig. 4.7)"
    ),
    "hysteresis.png": "Hysteresis: the true hysteretic state and the ISSMs' hidden "
    "states",
}


#: Share of the room a panel's title may take (the constrained layout moves
#: panels a little after the titles are wrapped).
_TITLE_SHARE = 0.95


def _wrapped(text: str, font, width: float) -> str:
    """``text`` with its lines broken between words to ``width`` points."""
    from matplotlib.backends.backend_agg import RendererAgg

    renderer = RendererAgg(1, 1, 72)  # 72 dpi: widths in points

    def fits(line: str) -> bool:
        w, _, _ = renderer.get_text_width_height_descent(line, font, ismath=False)
        return w <= width

    out = []
    for paragraph in text.split("\n"):
        line = ""
        for word in paragraph.split(" "):
            candidate = f"{line} {word}" if line else word
            if line and not fits(candidate):
                out.append(line)
                candidate = word
            line = candidate
        out.append(line)
    return "\n".join(out)


def fit_titles(fig) -> None:
    """Wrap the figure's and its panels' titles, and legend entries, to fit.

    Long titles (a model label with all its options, the correlation
    figures' explanations) are otherwise clipped at the figure's edges, and
    a long legend entry squeezes its panel; the constrained layout makes room
    for the extra lines.
    """

    def wrap(text, limit: float) -> None:
        if text.get_text():
            font = text.get_fontproperties()
            text.set_text(_wrapped(text.get_text(), font, limit))

    width = fig.get_figwidth() * 72
    # A legend entry (a model's label) may take half its panel's width;
    # then the layout places the panels as they will be drawn.
    for ax in fig.axes:
        legend = ax.get_legend()
        for text in legend.get_texts() if legend is not None else []:
            wrap(text, 0.5 * ax.get_position().width * width)
    fig.draw_without_rendering()
    if fig._suptitle is not None:
        wrap(fig._suptitle, width)
    for ax in fig.axes:
        # A title is centred on its panel and may reach over the panel's
        # margins, not over the figure's edges.
        box = ax.get_position()
        centre = (box.x0 + box.x1) / 2
        room = _TITLE_SHARE * 2 * min(centre, 1 - centre) * width
        for title in (ax.title, ax._left_title, ax._right_title):
            wrap(title, room)


#: The paper's names of the error statistics and the plain ones of a report
#: on a user's own records (as in the report's tables).
_PLAIN_STATISTICS = ("μ_Ns and σ_Ns of", "Mean error and error std of")


def figure_caption(name: str, paper_terms: bool = True) -> str:
    """The caption of figure ``name``; without the paper's figure numbers and
    notation for a report on a user's own records."""
    caption = FIGURES[name]
    if paper_terms:
        return caption
    return re.sub(r" \(figs?\. [^)]*\)", "", caption).replace(*_PLAIN_STATISTICS)


def figure_file(name: str, paper_terms: bool = True) -> str:
    """The file name of figure ``name``: ``prediction.png`` rather than the
    paper's ``fig4_2_prediction.png`` for a user's own records."""
    return name if paper_terms else re.sub(r"^fig\d+_\d+_", "", name)


def _figures(models, data, evaluation, loops) -> dict[str, Callable[[], Any]]:
    """Figure builders by file name; those needing absent data are left out."""
    from sysid_nn.plotting import plot_records

    def training() -> Any:
        _, axes = panel_figure(2)
        t = np.arange(data.train.excitation.shape[1]) * data.dt
        return plot_records(
            t,
            data.train.excitation,
            data.train.displacement,
            excitation_label=_label(data, "excitation"),
            displacement_label=_label(data, "displacement"),
            ax=axes,
        )

    names = list(FIGURES)
    paper = data.get("paper_terms", True)
    builders = {
        names[1]: lambda: _response_figure(
            models, data, evaluation, "prediction", "Prediction"
        ),
        names[2]: lambda: _correlation_figure(models, data, evaluation, "acf"),
        names[3]: lambda: _correlation_figure(models, data, evaluation, "ccf"),
        names[4]: lambda: _statistics_figure(
            data, evaluation, "prediction", figure_caption(names[4], paper)
        ),
        names[5]: lambda: _response_figure(
            models, data, evaluation, "simulation", "Simulation"
        ),
        names[6]: lambda: _statistics_figure(
            data, evaluation, "simulation", figure_caption(names[6], paper)
        ),
    }
    if "train" in data:
        builders[names[0]] = training
    if loops is not None and loops.state:
        builders[names[7]] = lambda: _hysteresis_figure(loops, data)
    return {name: builders[name] for name in names if name in builders}
