"""The study's ``report.md``: tables laid out as the paper's figures."""

from __future__ import annotations

import contextlib
import os
import platform
from collections.abc import Mapping, Sequence
from dataclasses import asdict
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from sklearn.utils import Bunch

import sysid_nn
from sysid_nn.study._config import _QUICK_PARAMS, StudyConfig
from sysid_nn.study._figures import FIGURES, figure_caption, figure_file
from sysid_nn.study._models import StudyModel


def _fmt(value: Any) -> str:
    if isinstance(value, (bool, np.bool_)):
        return "yes" if value else "no"
    if isinstance(value, (float, np.floating)):
        return "diverged" if np.isnan(value) else f"{value:.4g}"
    return str(value)


def _md_table(frame: pd.DataFrame) -> str:
    """GitHub markdown table of a frame (index dropped)."""
    head = "| " + " | ".join(map(str, frame.columns)) + " |"
    rule = "|" + "|".join("---" for _ in frame.columns) + "|"
    body = [
        "| " + " | ".join(_fmt(v) for v in row) + " |"
        for row in frame.itertuples(index=False)
    ]
    return "\n".join([head, rule, *body])


def _percent(rate: float) -> str:
    return f"{100 * rate:.0f} %"


def _several(summary: pd.DataFrame) -> bool:
    """Whether the tables need an output column (more than one output scored)."""
    return summary["output"].nunique() > 1


def _who(row: Any, labels: Mapping[str, str], several: bool) -> str:
    """A summary row's model, and its output when several are scored."""
    return (
        f"{row.label} ({labels.get(row.output, row.output)})" if several else row.label
    )


#: The paper's names of the error statistics, and plain ones for a user's test.
_STAT_NAMES = {
    True: ("μ_Ns", "σ_Ns", "N_s", " (eq. 19)", " (eq. 20)"),
    False: ("mean error", "error std", "records", "", ""),
}


def _glance(
    summary: pd.DataFrame,
    labels: Mapping[str, str] | None = None,
    paper_terms: bool = True,
) -> pd.DataFrame:
    """Rows = models (and outputs), columns = what a reader compares with the paper."""
    labels = labels or {}
    several = _several(summary)
    by = summary.set_index(["model", "output", "mode"])
    rows = []
    for name, output in dict.fromkeys(
        zip(summary["model"], summary["output"], strict=True)
    ):
        p, s = (
            by.loc[(name, output, "prediction")],
            by.loc[(name, output, "simulation")],
        )
        linear = by["nrmse_median"].get(("linear", output, "simulation"))
        row = {"model": p["label"]}
        if several:
            row["output"] = labels.get(output, output)
        row |= {
            "NRMSE pred. (median)": p["nrmse_median"],
            "NRMSE sim. (median)": s["nrmse_median"],
        }
        if linear is not None:
            row["sim. / linear"] = s["nrmse_median"] / linear
        mu, sigma = _STAT_NAMES[paper_terms][:2]
        row |= {
            f"{mu} pred.": p["mu_Ns"],
            f"{sigma} pred.": p["sigma_Ns"],
            f"{mu} sim.": s["mu_Ns"],
            f"{sigma} sim.": s["sigma_Ns"],
            "white (pred.)": _percent(p["whiteness_pass_rate"]),
            "uncorrelated with input (pred.)": _percent(p["cross_positive_pass_rate"]),
            "diverged (pred./sim.)": (
                f"{p['n_divergent']}/{s['n_divergent']} of {s['n_realizations']}"
            ),
        }
        rows.append(row)
    return pd.DataFrame(rows)


def _mode_table(
    summary: pd.DataFrame,
    mode: str,
    labels: Mapping[str, str] | None = None,
    paper_terms: bool = True,
) -> pd.DataFrame:
    mu, sigma, n, eq19, eq20 = _STAT_NAMES[paper_terms]
    cols = {"label": "model"}
    if _several(summary):
        cols["output"] = "output"
    cols |= {
        "n_realizations": n,
        "nrmse_median": "NRMSE median",
        "nrmse_mean": "NRMSE mean",
        "fit_percent_median": "fit % median",
        "mu_Ns": mu + eq19,
        "sigma_Ns": sigma + eq20,
        "whiteness_pass_rate": "whiteness passed",
        "cross_positive_pass_rate": "cross τ>0 passed",
        "cross_negative_pass_rate": "cross τ<0 passed",
    }
    frame = summary.query("mode == @mode")[list(cols)].rename(columns=cols)
    if "output" in frame:
        frame["output"] = frame["output"].map(lambda f: (labels or {}).get(f, f))
    for c in ("whiteness passed", "cross τ>0 passed", "cross τ<0 passed"):
        frame[c] = frame[c].map(_percent)
    return frame


def _non_default_params(estimator: Any) -> str:
    defaults = type(estimator)().get_params(deep=False)
    skip = {"random_state", "n_jobs", "verbose"}
    changed = {
        k: v
        for k, v in estimator.get_params(deep=False).items()
        if k not in skip and _differs(v, defaults[k])
    }
    # One line per table cell: a member's repr may wrap.
    return (
        ", ".join(f"{k}={' '.join(repr(v).split())}" for k, v in changed.items())
        or "defaults"
    )


def _differs(value: Any, default: Any) -> bool:
    """Whether a parameter differs from its default; an estimator (an
    ensemble's member) is equal only to itself, so it is compared by repr."""
    if hasattr(value, "get_params") or hasattr(default, "get_params"):
        return repr(value) != repr(default)
    return value != default


def _versions() -> str:
    names = ["numpy", "scipy", "scikit-learn", "statsmodels", "pandas", "numba"]
    names += ["joblib", "matplotlib", "dask", "distributed"]
    found = [f"sysid_nn {sysid_nn.__version__}"]
    for name in names:
        with contextlib.suppress(metadata.PackageNotFoundError):
            found.append(f"{name} {metadata.version(name)}")
    return ", ".join(found)


def blas_kernels() -> str:
    """The BLAS libraries numpy and scipy run, with the kernels they picked.

    OpenBLAS picks its kernels by the processor (its ``architecture``, for
    example ``Haswell`` or ``SkylakeX``), and sums in another order under
    another kernel: a training path carries that last digit to another end
    point, so figures are reproduced only under the same kernel
    (``OPENBLAS_CORETYPE`` set before Python starts chooses it).
    """
    import scipy.linalg  # noqa: F401  (loads scipy's own BLAS)
    from threadpoolctl import threadpool_info

    kinds = {
        f"{info.get('internal_api', '?')} {info.get('architecture', '?')}"
        for info in threadpool_info()
        if info.get("user_api") == "blas"
    }
    return ", ".join(sorted(kinds)) or "none found"


def _machine() -> str:
    return (
        f"{platform.platform()}, Python {platform.python_version()}, "
        f"{os.cpu_count()} logical CPUs ({platform.machine()}), BLAS "
        f"{blas_kernels()}"
    )


#: Which residual test the verdicts are, and how it differs from the figures.
_TEST_NAMES = (
    "Which tests: *whiteness* is the portmanteau (Box-Pierce) chi-square test "
    "of the residual autocorrelation over lags {lags} together; *uncorrelated "
    "with input* the chi-square test of the residual-input cross-correlation "
    "over the same positive lags. The correlation figures draw the per-lag "
    "{level} % band (dotted): a few lags outside it are expected by chance (about "
    "1 in 20) and do not fail the chi-square test, and many lags inside it but "
    "away from zero can."
)

# Where the user guide explains the verdicts below.
_PITFALLS = (
    "the user guide's *Known pitfalls of the hysteretic oscillator problem* "
    "(`docs/user_guide/pitfalls.rst`, section \"The paper's networks as "
    'published")'
)
_PAPER = ("tdl_paper", "issm_paper")


def _verdicts(
    summary: pd.DataFrame,
    labels: Mapping[str, str] | None = None,
    records: str = "test realisations",
) -> list[str]:
    """Plain statements, from the computed results, that a reader must not miss.

    Whether the paper's networks simulate unseen realisations (median free-run
    NRMSE at most 1, i.e. better than the displacement's mean) and which
    models' one-step residuals pass the whiteness test.
    """
    # The paper's networks are judged on the paper's output, the displacement.
    by = summary.query("output == 'displacement'").set_index(["model", "mode"])
    lines = []
    paper = [m for m in _PAPER if (m, "simulation") in by.index]
    if paper:
        sim = {m: by.loc[(m, "simulation"), "nrmse_median"] for m in paper}
        failing = [m for m in paper if not sim[m] <= 1]  # a NaN fails too
        numbers = ", ".join(
            f"{by.loc[(m, 'simulation'), 'label']} {_fmt(sim[m])}" for m in paper
        )
        if len(failing) == len(paper):
            head = "The paper's networks as published do not simulate"
        elif failing:
            head = "Not every one of the paper's networks as published simulates"
        else:
            head = "The paper's networks as published simulate"
        lines.append(
            f"**{head} unseen realisations**: median free-run NRMSE {numbers} "
            "(above 1 is worse than the displacement's mean)."
        )
    pred = summary.query("mode == 'prediction'")
    n = int(pred["n_realizations"].max())
    rates = pred["whiteness_pass_rate"]
    several = _several(summary)
    listed = ", ".join(
        f"{_who(r, labels or {}, several)} {_percent(r.whiteness_pass_rate)}"
        for r in pred.itertuples()
    )
    if summary["model"].nunique() == 1:
        if rates.max() == 0:
            head = "The model's one-step residuals do not pass the whiteness test"
        elif rates.max() < 0.5:
            head = (
                "The model's one-step residuals do not pass the whiteness test on "
                f"most {records}"
            )
        else:
            head = "The model's one-step residuals pass the whiteness test"
    elif rates.max() == 0:
        head = "No model's one-step residuals pass the whiteness test"
    elif rates.max() < 0.5:
        head = (
            f"No model's one-step residuals pass the whiteness test on most {records}"
        )
    elif rates.min() >= 0.5:
        head = "Every model's one-step residuals pass the whiteness test"
    else:
        head = "Some models' one-step residuals pass the whiteness test"
    text = f"**{head}** (share of the {n} {records}: {listed})"
    if paper and rates.max() < 0.5:
        text += (
            ", unlike the paper's figs 4.3-4.4, where the prediction errors of "
            "both networks are white"
        )
    lines.append(text + ".")
    if paper:
        lines.append(f"Why: see {_PITFALLS}.")
    return lines


def _findings(summary: pd.DataFrame, labels: Mapping[str, str]) -> list[str]:
    lines = []
    if summary["model"].nunique() > 1:
        for output, rows in summary.query("mode == 'simulation'").groupby(
            "output", sort=False
        ):
            best = rows.loc[rows["nrmse_median"].idxmin()]
            of = f" of {labels.get(output, output)}" if _several(summary) else ""
            lines.append(
                f"Best simulator{of} on unseen realisations: {best['label']} "
                f"(median free-run NRMSE {_fmt(best['nrmse_median'])})."
            )
    sim = summary.query("mode == 'simulation' and output == 'displacement'")
    sim = sim.set_index("model")
    if {"tdl_paper", "issm_paper"} <= set(sim.index):
        tdl, issm = sim.loc["tdl_paper", "sigma_Ns"], sim.loc["issm_paper", "sigma_Ns"]
        better = "TDL" if tdl < issm else "ISSM"
        lines.append(
            f"Paper's networks in simulation: σ_Ns = {_fmt(tdl)} (TDL) against "
            f"{_fmt(issm)} (ISSM); the smaller is the {better}'s "
            "(the paper found the TDL's smaller, fig. 4.7)."
        )
    return lines


def write_report(
    path: str | os.PathLike,
    summary: pd.DataFrame,
    *,
    title: str,
    setup: Sequence[str],
    models: Mapping[str, StudyModel],
    figures: Sequence[str] = (),
    extra: Mapping[str, Sequence[str]] | None = None,
    output_labels: Mapping[str, str] | None = None,
    alpha: float = 0.05,
    records: str = "test realisations",
    max_lag: int | None = None,
    paper_terms: bool = True,
    files: Mapping[str, str] | None = None,
) -> None:
    """Write ``report.md``: verdicts, setup, tables laid out as the paper's figures.

    The report opens with plain statements derived from ``summary``: whether
    the paper's networks (when present) simulate unseen realisations
    (median free-run NRMSE at most 1) and how often each model's one-step
    residuals pass the whiteness test, compared with the paper's figs 4.3-4.4.

    Parameters
    ----------
    path : path-like
        File to write.
    summary : pandas.DataFrame
        From :func:`summarize`.
    title : str
        First heading.
    setup : sequence of str
        Bullet lines of the setup section (seeds, data, parallelism, ...).
    models : dict of str to StudyModel
        Fitted models; their non-default parameters and fit times are listed.
    figures : sequence of str
        Figure file names present next to the report (keys of ``FIGURES``).
    extra : dict of str to sequence of str, optional
        Further sections, heading to lines.
    output_labels : dict of str to str, optional
        How the scored outputs (``summary["output"]``) are named, e.g.
        ``{"x": "x [m]"}``; default their field names.
    alpha : float, default=0.05
        Significance level of the residual tests in ``summary``.
    records : str, default="test realisations"
        What the evaluated records are called in the text.
    max_lag : int, optional
        Largest lag of the residual tests, named where the report explains
        them.
    paper_terms : bool, default=True
        Name sections, statistics and figures as the paper does (section,
        equation and figure numbers, ``μ_Ns``); False for a report on the
        user's own records, in plain words.
    files : dict of str to str, optional
        Further files next to the report, name to description, listed with
        the others.

    Examples
    --------
    >>> from sysid_nn.study import StudyConfig, fit_models, generate_data
    >>> from sysid_nn.study import evaluate, summarize, write_report
    >>> import tempfile, pathlib
    >>> config = StudyConfig(models=("linear",), n_samples=600, n_test=2, max_lag=10,
    ...                      n_candidates=3, estimator_params={"all": {"n_init": 1}})
    >>> data = generate_data(config)
    >>> models = fit_models(data, config)
    >>> summary = summarize(evaluate(models, data, config), models)
    >>> path = pathlib.Path(tempfile.mkdtemp()) / "report.md"
    >>> write_report(path, summary, title="Tiny study", setup=["seed 0"],
    ...              models=models)
    >>> path.read_text().splitlines()[0]
    '# Tiny study'
    """
    has = set(figures)
    rows = []
    for m in models.values():
        est = m.estimator
        rows.append(
            {
                "model": m.label,
                "estimator": type(est).__name__,
                "sees": f"{', '.join(m.inputs)} -> {', '.join(m.outputs)}, every "
                f"{m.step}. sample"
                if m.step > 1
                else f"{', '.join(m.inputs)} -> {', '.join(m.outputs)}",
                "parameters": _non_default_params(est),
                "iterations": getattr(est, "n_iter_", ""),
                "fit time [s]": (
                    round(float(est.fit_time_), 1) if hasattr(est, "fit_time_") else ""
                ),
            }
        )
    lines = [f"# {title}", ""]
    lines += ["## Results at a glance", ""]
    labels = dict(output_labels or {})
    named = [labels.get(f, f) for f in dict.fromkeys(summary["output"])]
    glance = _glance(summary, labels, paper_terms)
    lines += [f"- {line}" for line in _verdicts(summary, labels, records)] + [""]
    lines += [_md_table(glance), ""]
    whose = "its" if len(named) == 1 else "each output's"
    units = f"the units of the {named[0]}" if len(named) == 1 else "each output's units"
    lines += [
        f"NRMSE: root-mean-square error of the {' and '.join(named)} over "
        f"{whose} standard deviation "
        "(0 perfect, 1 no better than its mean)"
        + (
            "; `sim. / linear`: median free-run NRMSE relative to the linear baseline"
            if "sim. / linear" in glance
            else ""
        )
        + (
            f". μ_Ns and σ_Ns (eq. 19-20) are in {units}, averaged over the "
            f"N_s {records} as in figs 4.5 and 4.7. Residual tests at the "
            f"{100 * (1 - alpha):g} % level on each of the {records} (figs 4.3-4.4)."
            if paper_terms
            else f". Mean error and error std are in {units}: the mean and the "
            f"standard deviation of each record's errors, averaged over the "
            f"{records}. Residual tests at the {100 * (1 - alpha):g} % level on "
            f"each of the {records}."
        ),
        "",
        _TEST_NAMES.format(
            lags=f"1 to {max_lag}" if max_lag else "1 to max_lag",
            level=f"{100 * (1 - alpha):g}",
        ),
        "",
    ]
    if "issm_paper" in models or "tdl_paper" in models:
        lines += [
            "The paper (figs 4.5, 4.7) shows bars for its TDL and ISSM only: small "
            "differences between the two in prediction, a smaller σ_Ns for the TDL "
            'in simulation ("the TDL network seems to be a better simulator"), '
            "and prediction errors that pass the whiteness and cross-correlation "
            "tests (figs 4.3-4.4).",
            "",
        ]
    lines += [f"- {line}" for line in _findings(summary, labels)] + [""]
    lines += ["## Setup", ""] + [f"- {line}" for line in setup] + [""]
    first = next(iter(FIGURES))
    if first in has:
        lines += [f"![{FIGURES[first]}]({first})", ""]
    lines += ["### Models", "", _md_table(pd.DataFrame(rows)), ""]
    for heading, mode, figs in (
        ("One-step prediction (section 4.3)", "prediction", [1, 2, 3, 4]),
        ("Free-run simulation (section 4.4)", "simulation", [5, 6]),
    ):
        if not paper_terms:
            heading = heading.split(" (")[0]
        table = _mode_table(summary, mode, labels, paper_terms)
        lines += [f"## {heading}", "", _md_table(table), ""]
        for i in figs:
            name = list(FIGURES)[i]
            if name in has:
                shown = figure_file(name, paper_terms)
                lines += [f"![{figure_caption(name, paper_terms)}]({shown})", ""]
        if mode == "simulation":
            lines += [
                "Free-run residuals are coloured even for a good simulator (they "
                "accumulate); the whiteness test is designed for one-step "
                "prediction errors.",
                "",
            ]
    for heading, body in (extra or {}).items():
        lines += [f"## {heading}", "", *body, ""]
    lines += ["## Files", ""]
    lines += ["- `results.csv`: one row per record, model, scored output and mode."]
    lines += [
        "- `summary.csv`: one row per model, scored output and mode (the tables)."
    ]
    lines += [
        f"- `{figure_file(name, paper_terms)}`: {figure_caption(name, paper_terms)}"
        for name in figures
    ]
    lines += [f"- `{name}`: {about}" for name, about in (files or {}).items()]
    Path(path).write_text("\n".join(lines) + "\n", encoding="utf-8")


def _parallel_line(config: StudyConfig, scheduler: str | None) -> str:
    where = f"dask scheduler {scheduler}" if scheduler else "local joblib"
    return f"Parallel: {where}, n_jobs={config.n_jobs} (evaluation and restarts)."


def _study_setup(
    config: StudyConfig, data: Bunch, scheduler: str | None, timings: Mapping
) -> list[str]:
    peaks = data.candidate_peaks
    chosen = ", ".join(f"#{i} (peak |X| = {peaks[i]:.4g} m)" for i in data.train_index)
    test_peak = np.mean(np.max(np.abs(data.test.displacement), axis=1))
    z0 = data.oscillator.get_params()["z0"]
    settings = {k: v for k, v in asdict(config).items() if k != "estimator_params"}
    lines = [
        f"Configuration: {settings}"
        + (
            f", estimator overrides {dict(config.estimator_params)}"
            if config.estimator_params
            else ""
        )
        + (f", quick-run training settings {_QUICK_PARAMS}" if config.quick else "")
        + ".",
        f"Seeds (from seed={config.seed}): {data.seeds}.",
        f"Oscillator and excitation: the paper's parameters "
        f"{data.oscillator.get_params()}, r0 = {data.r0:.6g} (calibrated so that "
        f"E[max|X|] = 2 z0 = {2 * z0:g} m).",
        f"Records: {config.n_samples} samples at dt = {config.dt:g} s.",
        f"Training: {config.n_train} record(s) of typical amplitude, the "
        f"candidate(s) nearest the median peak |X| = {np.median(peaks):.4g} m "
        f"of {peaks.size} candidates: {chosen}.",
        f"Validation: {config.n_val} record(s) (early stopping, restart selection).",
        f"Test: N_s = {config.test_size} unseen realisations (mean peak |X| = "
        f"{test_peak:.4g} m).",
        _parallel_line(config, scheduler),
        f"Software: {_versions()}.",
        f"Machine: {_machine()}.",
        "Wall time: "
        + ", ".join(f"{k} {v:.1f} s" for k, v in timings.items())
        + f" (total {sum(timings.values()):.1f} s before the report).",
    ]
    warned = {n: w for n, w in data.get("fit_warnings", {}).items() if w}
    lines += [f"Warnings while fitting {n}: {'; '.join(w)}" for n, w in warned.items()]
    if any("white misfit" in x for w in warned.values() for x in w):
        lines.append(
            "The study's records carry no measurement noise: a white misfit "
            "above is the excitation between the samples of the decimated records."
        )
    return lines


def _hysteresis_lines(loops: Bunch) -> list[str]:
    if not loops.state:
        return ["No model has a hidden state to compare with the hysteretic one."]
    lines = ["![Hysteresis](hysteresis.png)", ""]
    if loops.state_correlation:
        lines.append(
            "Estimated unmeasured ISSM states against the true hysteretic Z "
            "(free run, test realisation 0, affine map fitted for display): "
            + ", ".join(
                f"{k} |r| = {v:.3f}" for k, v in loops.state_correlation.items()
            )
            + "."
        )
    if loops.state:
        lines.append(
            "One panel per ISSM: its estimated hidden state against its simulated "
            "displacement, over the true hysteretic state in grey. Models without "
            "a hidden state (the TDLs, the linear model) have no hysteretic "
            "state to draw."
        )
    return lines
