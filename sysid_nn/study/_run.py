"""Running a study or a validation end to end into an output directory."""

from __future__ import annotations

import contextlib
import errno
import os
import secrets
import shutil
import tempfile
import time
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path

import numpy as np
import pandas as pd
from joblib import parallel_backend
from sklearn.utils import Bunch

from sysid_nn._compile import prepare_kernels
from sysid_nn.study._config import StudyConfig
from sysid_nn.study._data import generate_data
from sysid_nn.study._figures import (
    LONG_RECORD,
    _figures,
    _label,
    figure_file,
    fit_titles,
    hysteresis_loops,
    show_long_record,
)
from sysid_nn.study._models import StudyModel, fit_models
from sysid_nn.study._progress import _progress
from sysid_nn.study._report import (
    _hysteresis_lines,
    _machine,
    _study_setup,
    _versions,
    write_report,
)
from sysid_nn.study._scoring import evaluate, summarize
from sysid_nn.study._structure import structure_lines


@contextlib.contextmanager
def _staged_directory(out_dir: str | os.PathLike, overwrite: bool) -> Iterator[Path]:
    """A temporary directory next to ``out_dir``, moved in place on success.

    An interrupted or failed run leaves nothing behind; an existing
    ``out_dir`` is replaced only with ``overwrite=True``.
    """
    out = Path(out_dir)
    if out.exists() and not overwrite:
        raise FileExistsError(
            f"output directory {str(out)!r} exists; pass overwrite=True to "
            "replace it, or choose another directory."
        )
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
    except FileExistsError as exc:  # a file where a parent directory should be
        raise NotADirectoryError(
            errno.ENOTDIR, "a file is in the way of the output directory", exc.filename
        ) from None
    # mkdir (not mkdtemp, which makes it private) so the result gets the
    # usual permissions; the random suffix keeps concurrent runs apart.
    tmp = out.parent / f".{out.name}.partial-{secrets.token_hex(6)}"
    tmp.mkdir()
    try:
        yield tmp
        if out.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{out.name}.old-", dir=out.parent))
            os.replace(out, old / out.name)
            os.replace(tmp, out)
            shutil.rmtree(old)
        else:
            os.replace(tmp, out)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


@contextlib.contextmanager
def _joblib_backend(scheduler: str | None) -> Iterator[None]:
    if scheduler is None:
        yield
        return
    try:
        from dask.distributed import Client
    except ImportError as exc:  # pragma: no cover - the extra is not installed
        raise ImportError(
            "scheduler needs dask.distributed; install it with "
            "`pip install sysid_nn[distributed]`."
        ) from exc
    try:
        client = Client(scheduler)
    except OSError as exc:  # unreachable or refusing: say which address
        raise ConnectionError(
            f"cannot connect to the dask scheduler {scheduler!r}: {exc}"
        ) from exc
    with client, parallel_backend("dask"):
        yield


def _write_outputs(
    tmp: Path,
    models: Mapping[str, StudyModel],
    data: Bunch,
    evaluation: Bunch,
    loops: Bunch | None,
    progress: bool,
    renamed: Mapping[str, str] | None = None,
) -> tuple[pd.DataFrame, list[str]]:
    summary = summarize(evaluation, models)
    # A user's records are records, not realisations of the study's process.
    evaluation.results.rename(columns=renamed or {}).to_csv(
        tmp / "results.csv", index=False
    )
    summary.rename(columns=renamed or {}).to_csv(tmp / "summary.csv", index=False)
    builders = _figures(models, data, evaluation, loops)
    paper = data.get("paper_terms", True)
    for name, build in _progress(builders.items(), len(builders), "figures", progress):
        fig = build()
        fit_titles(fig)
        fig.savefig(tmp / figure_file(name, paper), dpi=90)
    return summary, list(builders)


def _output_labels(data: Bunch, evaluation: Bunch) -> dict[str, str]:
    return {field: _label(data, field) for field in evaluation.outputs}


def run_study(
    config: StudyConfig | None = None,
    out_dir: str | os.PathLike = "sysid_nn_results",
    *,
    overwrite: bool = False,
    scheduler: str | None = None,
    progress: bool = False,
) -> Bunch:
    """Run the whole section-4 study and write its figures, tables and report.

    Writes into ``out_dir``: the figures of :data:`FIGURES` (PNG),
    ``results.csv`` (one row per realisation, model and mode, see
    :func:`evaluate`), ``summary.csv`` (:func:`summarize`) and ``report.md``.
    Everything is written to a temporary directory next to ``out_dir`` and
    moved in place at the end, so an interrupted run leaves no half-written
    results.

    Parameters
    ----------
    config : StudyConfig, optional
        Default ``StudyConfig()``: the full study.
    out_dir : path-like, default="sysid_nn_results"
        Output directory; its parents are created.
    overwrite : bool, default=False
        Replace an existing ``out_dir``; otherwise it is an error.
    scheduler : str, optional
        Address of a ``dask.distributed`` scheduler: the evaluation and the
        restarts run on its workers (``joblib.parallel_backend("dask")``);
        needs the ``distributed`` extra. The results are the same.
    progress : bool, default=False
        Progress bars on stderr.

    Returns
    -------
    Bunch
        ``out_dir`` (Path), ``results``, ``summary``, ``models``, ``data``,
        ``evaluation``, ``timings`` (seconds per step).

    Raises
    ------
    FileExistsError
        ``out_dir`` exists and ``overwrite`` is False (checked first).
    OSError
        ``out_dir`` cannot be written.

    Examples
    --------
    The full study takes minutes (see ``benchmarks/results_study.md``);
    ``StudyConfig(quick=True)`` well under one. An existing directory is
    refused before any work:

    >>> import tempfile
    >>> from sysid_nn.study import StudyConfig, run_study
    >>> run_study(StudyConfig(quick=True), tempfile.mkdtemp())
    Traceback (most recent call last):
    ...
    FileExistsError: output directory '...' exists; pass overwrite=True to ...
    """
    config = StudyConfig() if config is None else config
    timings: dict[str, float] = {}

    @contextlib.contextmanager
    def timed(step: str) -> Iterator[None]:
        start = time.perf_counter()
        yield
        timings[step] = time.perf_counter() - start

    # Compiling the kernels on a first run is announced, and timed apart from
    # the fits (it is not their cost).
    compile_seconds = prepare_kernels(show=progress)
    if compile_seconds:
        timings["kernel compilation (first run only)"] = compile_seconds
    with _staged_directory(out_dir, overwrite) as tmp:
        with _joblib_backend(scheduler):
            with timed("generate"):
                data = generate_data(config)
            with timed("fit"):
                models = fit_models(data, config, progress=progress)
            with timed("evaluate"):
                evaluation = evaluate(models, data, config, progress=progress)
        with timed("figures and tables"):
            loops = hysteresis_loops(models, data, evaluation)
            summary, figures = _write_outputs(
                tmp, models, data, evaluation, loops, progress
            )
        write_report(
            tmp / "report.md",
            summary,
            title="Section-4 study of Kirkegaard, Nielsen & Hansen (1995)",
            setup=_study_setup(config, data, scheduler, timings),
            models=models,
            figures=figures,
            extra={"Hysteresis": _hysteresis_lines(loops)},
            output_labels=_output_labels(data, evaluation),
            alpha=config.alpha,
            max_lag=config.max_lag,
        )
    return Bunch(
        out_dir=Path(out_dir),
        results=evaluation.results,
        summary=summary,
        models=models,
        data=data,
        evaluation=evaluation,
        timings=timings,
    )


def run_validation(
    model: StudyModel,
    records: Mapping[str, Sequence[np.ndarray]],
    out_dir: str | os.PathLike,
    *,
    dt: float,
    overwrite: bool = False,
    max_lag: int = 25,
    alpha: float = 0.05,
    n_jobs: int | None = None,
    units: Mapping[str, str] | None = None,
    setup: Sequence[str] = (),
    progress: bool = False,
    series: str | None = "csv",
    band: float | None = None,
    y_init: int = 0,
) -> Bunch:
    """Validate a fitted model on measured records: the study's report on them.

    Prediction and simulation of every record, residual tests, eq. 19-20
    statistics, figs 4.2-4.7 and ``report.md``, written like
    :func:`run_study` (staged, then moved in place). Every output of the
    model is scored, tabulated and drawn under its field name (with its unit
    when ``units`` gives one).

    Parameters
    ----------
    model : StudyModel
        Fitted estimator with the record fields it maps.
    records : dict of str to sequence of 1-D arrays
        One entry per field (``model.inputs`` and ``model.outputs``), each
        a list with one array per experiment.
    out_dir : path-like
        Output directory.
    dt : float
        Sampling step of the records.
    overwrite : bool, default=False
        Replace an existing ``out_dir``.
    max_lag, alpha : int, float
        Residual tests' largest lag and significance level.
    n_jobs : int, optional
        Parallel jobs over records.
    units : dict of str to str, optional
        Unit of each record field, e.g. ``{"force": "N", "x": "m"}``, shown
        on the figures' axes (and in the error statistics' axis).
    setup : sequence of str
        Extra lines for the report's setup section (e.g. file names).
    progress : bool, default=False
        Progress bars on stderr.
    series : {"csv", "parquet"} or None, default="csv"
        Also write the records with the model's one-step predictions and
        free runs, ``series.csv`` or ``series.parquet`` (needs pyarrow):
        one row per sample with ``record``, ``t`` (s), the inputs and, per
        output ``y``, the columns ``y``, ``y_predicted`` and ``y_simulated``.
    band : float, optional
        Also draw each record's free run with its prediction band at this
        level (e.g. 0.95), ``band_<k>.png``, and write the share of samples
        inside it per record, ``band.csv``.
    y_init : int, default=0
        Start every record's free run from its first ``y_init`` measured
        samples (the initial conditions whose free run fits them best, see
        the estimators' ``simulate``) instead of from the model's rest, for
        records that do not start at rest; the free runs (and bands) are
        scored and tested after those samples. The report says which start
        was used.

    Returns
    -------
    Bunch
        ``out_dir``, ``results``, ``summary``, ``evaluation``, ``series``
        (the series' DataFrame, or None), ``band_coverage`` (the pooled
        share of samples inside the band, or None) and ``band_width`` (the
        band's mean standard deviation over the output's standard deviation,
        of the widest output, or None; above 1 the band is flagged as too
        wide for its coverage to mean much) and ``non_finite``: one Bunch
        (``record``, ``mode``, ``output``, ``sample``) per record, mode and
        output whose predictions or free run turned non-finite (diverged),
        from ``sample`` (counted from 0) on; the report lists them.

    Examples
    --------
    >>> from sysid_nn import HystereticOscillator
    >>> from sysid_nn.study import StudyModel, run_validation
    >>> import tempfile, pathlib
    >>> from sysid_nn import TDLRegressor
    >>> rec = HystereticOscillator(r0=0.05).generate(2, n_samples=300, random_state=0)
    >>> records = {"force": list(rec.excitation), "x": list(rec.displacement)}
    >>> model = StudyModel("ARX", TDLRegressor(hidden_layer_sizes=(), n_init=1),
    ...                    ("force",), ("x",))
    >>> _ = model.estimator.fit(*model.arrays(records))
    >>> out = pathlib.Path(tempfile.mkdtemp()) / "validation"
    >>> report = run_validation(model, records, out, dt=0.01, max_lag=10,
    ...                         units={"force": "m/s²", "x": "m"})
    >>> sorted(p.name for p in out.glob("*.csv"))
    ['results.csv', 'series.csv', 'summary.csv']
    """
    # The residual tests' lags are checked against these records, not the study's.
    shortest = min(len(x) for x in records[model.inputs[0]])
    config = StudyConfig(
        n_jobs=n_jobs,
        max_lag=max_lag,
        alpha=alpha,
        n_samples=shortest,
        paper_tdl_step=model.step,
    )
    if series not in ("csv", "parquet", None):
        raise ValueError(f"series must be 'csv', 'parquet' or None; got {series!r}.")
    if series == "parquet":
        _check_parquet()
    models = {model.label: model}
    # A user's records: plain names, no paper's notation or figure numbers.
    data = Bunch(
        test=records,
        dt=float(dt),
        units=dict(units or {}),
        record_name="record",
        paper_terms=False,
    )
    prepare_kernels(show=progress)
    with _staged_directory(out_dir, overwrite) as tmp:
        evaluation = evaluate(
            models,
            data,
            config,
            outputs=model.outputs,
            progress=progress,
            y_init=y_init,
        )
        non_finite = _non_finite(evaluation, model.label)
        renamed = {"realization": "record", "n_realizations": "n_records"}
        summary, figures = _write_outputs(
            tmp, models, data, evaluation, None, progress, renamed
        )
        files = {}
        table = coverage = width = None
        if series is not None:
            table = _series(model, records, evaluation, float(dt))
            if series == "csv":
                table.to_csv(tmp / "series.csv", index=False)
            else:
                table.to_parquet(tmp / "series.parquet", index=False)
            files[f"series.{series}"] = (
                "every record with the model's one-step predictions "
                "(`<output>_predicted`) and free runs (`<output>_simulated`)."
            )
        if band is not None:
            coverage, width = _write_bands(model, records, tmp, float(dt), band, y_init)
            files["band.csv"] = (
                f"share of samples inside the {100 * band:g} % prediction band of "
                f"the free run, per record (pooled: {100 * coverage:.1f} %), and "
                "the band's mean standard deviation over the output's."
                + (f" {wide_band_warning(width)}" if width > _WIDE_BAND else "")
            )
            files["band_<k>.png"] = (
                "free run of record k with its prediction band, over the "
                "measured response."
            )
        n = summary["n_realizations"].iloc[0]
        X, y = model.arrays(records)
        structure = structure_lines(model.estimator, X, y, float(dt))
        write_report(
            tmp / "report.md",
            summary,
            title=f"Validation of {model.label}",
            setup=[
                *setup,
                f"{n} record(s) at dt = {dt:g} s; residual tests with "
                f"max_lag={max_lag}, alpha={alpha}.",
                _start_line(y_init),
                f"Software: {_versions()}.",
                f"Machine: {_machine()}.",
            ],
            models=models,
            figures=figures,
            output_labels=_output_labels(data, evaluation),
            alpha=alpha,
            records="records",
            max_lag=max_lag,
            paper_terms=False,
            files=files,
            extra={
                "The structure": structure,
                **(
                    {"Warnings": [f"- {describe_non_finite(b)}" for b in non_finite]}
                    if non_finite
                    else {}
                ),
            },
        )
    return Bunch(
        out_dir=Path(out_dir),
        results=evaluation.results,
        summary=summary,
        evaluation=evaluation,
        series=table,
        band_coverage=coverage,
        band_width=width,
        non_finite=non_finite,
    )


#: A band whose standard deviation exceeds the output's own is flagged: it
#: is no narrower than the spread of the output about its mean (an NRMSE of
#: 1), so it covers most samples whatever the model does.
_WIDE_BAND = 1.0


def _band_width(y: list, std: list) -> np.ndarray:
    """Per output: the band's mean standard deviation over the output's."""
    Y, S = np.concatenate(y), np.concatenate(std)
    spread = Y.std(axis=0)
    return np.nanmean(S, axis=0) / np.where(spread > 0, spread, np.nan)


def _start_line(y_init: int) -> str:
    """How the free runs started, for the report."""
    if not y_init:
        return (
            "Free runs start from rest: the model's settled state under zero "
            "excitation before each record."
        )
    return (
        f"Free runs start from each record's first {y_init} measured samples: "
        "the initial conditions whose free run fits them best; the free runs are "
        "scored and tested after those samples."
    )


def _write_bands(
    model, records, out: Path, dt: float, level: float, y_init: int = 0
) -> tuple[float, float]:
    """Free runs with their prediction bands: figures, band.csv, the pooled
    coverage and the widest band's width (see :func:`_band_width`), after
    the first ``y_init`` samples when the runs start from them."""
    import matplotlib.pyplot as plt

    from sysid_nn.plotting import plot_band
    from sysid_nn.uncertainty import interval_coverage, normal_interval

    X, y = model.arrays(records)
    start = {"y_init": [yk[:y_init] for yk in y]} if y_init else {}
    mean, std = model.estimator.simulate(X, return_std=True, **start)
    rows, bounds, stds = [], [], []
    for k, (yk, mk, sk) in enumerate(zip(y, mean, std, strict=True)):
        yk, mk, sk = (np.reshape(a, (len(a), -1)) for a in (yk, mk, sk))
        lower, upper = normal_interval(mk, sk, level)
        scored = slice(y_init, None)
        bounds.append((yk[scored], lower[scored], upper[scored]))
        stds.append(sk[scored])
        rows.append(
            {
                "record": k,
                "coverage": interval_coverage(*bounds[-1]),
                "band_std_over_output_std": float(
                    np.max(_band_width([bounds[-1][0]], [stds[-1]]))
                ),
            }
        )
        t = dt * model.step * np.arange(len(yk))
        ax = plot_band(t, mk[:, 0], sk[:, 0], level=level, label="simulated")
        ax.plot(t, yk[:, 0], "k-", linewidth=0.6, label="measured")
        ax.set_xlabel("time [s]")
        ax.set_ylabel(model.outputs[0])
        ax.legend()
        if len(yk) > LONG_RECORD:
            show_long_record(ax, t, yk[:, 0], mk[:, 0], sk[:, 0])
        ax.figure.savefig(out / f"band_{k}.png", dpi=90)
        plt.close(ax.figure)
    pd.DataFrame(rows).to_csv(out / "band.csv", index=False)
    coverage = interval_coverage(*(list(b) for b in zip(*bounds, strict=True)))
    width = _band_width([b[0] for b in bounds], stds)
    return coverage, float(np.max(width))


def _non_finite(evaluation: Bunch, label: str) -> list[Bunch]:
    """Where the model's predictions or free run first turned non-finite."""
    found = []
    for mode in ("prediction", "simulation"):
        for field in evaluation.outputs:
            for j, e in enumerate(evaluation.errors[label, mode, field]):
                bad = np.flatnonzero(~np.isfinite(e))
                if bad.size:
                    found.append(
                        Bunch(record=j, mode=mode, output=field, sample=int(bad[0]))
                    )
    return found


def describe_non_finite(entry: Bunch, record: str | None = None) -> str:
    """A sentence on one entry of :func:`_non_finite`."""
    what = "one-step predictions" if entry.mode == "prediction" else "free run"
    where = record or f"record {entry.record}"
    advice = (
        "a one-step predictor that diverges on measured outputs has an "
        "unstable innovation filter (ISSM) or met outputs far outside its "
        "training range; check the record there"
        if entry.mode == "prediction"
        else "the model's free run left the range of its training outputs"
    )
    return (
        f"The {what} of {entry.output!r} on {where} are not finite from sample "
        f"{entry.sample} (counted from 0) on: {advice}. The scores of this record "
        "count it as diverged."
    )


def wide_band_warning(width: float) -> str:
    """What a band wider than the output's spread means for its coverage."""
    return (
        f"The band is wide: its standard deviation is on average {width:.2g} "
        "times the output's, so its coverage says little about the model (a "
        "band as wide as the output's own spread covers most samples whatever "
        "the model does); the free run's errors and the bands' inputs (noise "
        "and weight uncertainty) tell more."
    )


def _check_parquet() -> None:
    try:
        import pyarrow  # noqa: F401
    except ImportError:
        raise ImportError(
            "series='parquet' needs pyarrow (pip install pyarrow); or write CSV."
        ) from None


_SERIES_MODES = (("prediction", "predicted"), ("simulation", "simulated"))


def _series(
    model: StudyModel, records: Mapping[str, Sequence[np.ndarray]], evaluation, dt
) -> pd.DataFrame:
    """Every record with the model's one-step predictions and free runs."""
    frames = []
    for j in range(len(records[model.inputs[0]])):
        (X,), (y,) = model.arrays(records, [j])
        y = y.reshape(len(y), -1)
        columns = {"record": j, "t": dt * model.step * np.arange(len(y))}
        columns |= {f: X[:, i] for i, f in enumerate(model.inputs)}
        for k, field in enumerate(model.outputs):
            columns[field] = y[:, k]
            for mode, suffix in (
                ("prediction", "predicted"),
                ("simulation", "simulated"),
            ):
                e = evaluation.errors[model.label, mode, field][j]
                columns[f"{field}_{suffix}"] = y[:, k] - np.reshape(e, len(y))
        frames.append(pd.DataFrame(columns))
    return pd.concat(frames, ignore_index=True)
