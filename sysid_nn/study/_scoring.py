"""Scoring the models on unseen realisations: residual tests, NRMSE, eq. 19-20."""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import pandas as pd
from joblib import Parallel, delayed
from sklearn.utils import Bunch

from sysid_nn.metrics import error_statistics, fit_percent, nrmse
from sysid_nn.residuals import analyze_residuals
from sysid_nn.study._config import _TESTS, MODES, StudyConfig
from sysid_nn.study._models import StudyModel
from sysid_nn.study._progress import _progress


def _scored(model: StudyModel, outputs: Sequence[str] | None) -> list[tuple[int, str]]:
    """``(column, field)`` of the model's outputs that are scored."""
    if outputs is None:  # the first output, the study's displacement
        return [(0, model.outputs[0])]
    return [(k, field) for k, field in enumerate(model.outputs) if field in outputs]


def _evaluate_record(
    j: int,
    models: Mapping[str, StudyModel],
    records: Mapping[str, Any],
    dt: float,
    config: StudyConfig,
    outputs: Sequence[str] | None,
    y_init: int = 0,
) -> tuple[list[dict], dict[tuple[str, str, str], np.ndarray], dict]:
    """All models, scored outputs and modes on record ``j``.

    Returns the table rows, the scored errors and the residual analyses;
    ``config`` gives the residual tests' ``max_lag`` and ``alpha``. With
    ``y_init`` the free runs start from the record's first ``y_init``
    measured samples and are scored after them.
    """
    rows, errors, analyses = [], {}, {}
    for name, model in models.items():
        (X,), (y,) = model.arrays(records, [j])
        y = y.reshape(len(y), -1)
        for mode in MODES:
            start = y_init if mode == "simulation" else 0
            # Divergence is recorded in the table, not warned about per run.
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                analysis = analyze_residuals(
                    model.estimator,
                    X,
                    y,
                    mode=mode,
                    max_lag=config.max_lag,
                    alpha=config.alpha,
                    nonlinear=False,
                    y_init=start,
                )
            analyses[name, mode] = analysis
            residuals = np.asarray(analysis.residuals).reshape(len(y), -1)
            for k, field in _scored(model, outputs):
                e, y_k = residuals[start:, k], y[start:, k]
                stats = error_statistics(e, dt * model.step)
                # One verdict per test: every input must pass, the smallest p counts.
                tests = (
                    analysis.summary.query("sequence == 0 and output == @k")
                    .groupby("test")
                    .agg(p_value=("p_value", "min"), passed=("passed", "all"))
                )
                row = {
                    "realization": j,
                    "model": name,
                    "output": field,
                    "mode": mode,
                    "dt": dt * model.step,
                    "nrmse": float(nrmse(y_k, y_k - e)),
                    "fit_percent": float(fit_percent(y_k, y_k - e)),
                    "mean": float(stats.means[0]),
                    "std": float(stats.stds[0]),
                    "divergent": bool(stats.divergent[0]),
                }
                for test in _TESTS:
                    row[f"{test}_p"] = float(tests.loc[test, "p_value"])
                    row[f"{test}_passed"] = bool(tests.loc[test, "passed"])
                rows.append(row)
                errors[name, mode, field] = residuals[:, k]
    return rows, errors, analyses


def evaluate(
    models: Mapping[str, StudyModel],
    data: Bunch,
    config: StudyConfig,
    *,
    records: str = "test",
    outputs: Sequence[str] | None = None,
    progress: bool = False,
    y_init: int = 0,
) -> Bunch:
    """One-step prediction and free-run simulation on unseen realisations.

    For every record, model, scored output and mode (:data:`MODES`) the
    residuals are tested (whiteness and input cross-correlation, figs
    4.3-4.4) and scored; over all records the averaged mean ``mu_Ns`` and
    standard deviation ``sigma_Ns`` of eq. 19-20 are computed. Records run
    in parallel with joblib (``config.n_jobs``, or the active joblib
    backend, e.g. dask).

    Parameters
    ----------
    models : dict of str to StudyModel
        Fitted models, e.g. from :func:`fit_models`.
    data : Bunch
        From :func:`generate_data`, or any Bunch with a ``records`` entry
        holding the models' fields and a ``dt``.
    config : StudyConfig
        ``n_jobs``, ``max_lag`` and ``alpha`` are used.
    records : str, default="test"
        Which entry of ``data`` to evaluate on.
    outputs : sequence of str, optional
        Record fields to score, each for every model that has it among its
        outputs; default each model's first output (in the study the
        displacement, which every model has).
    progress : bool, default=False
        Show a progress bar (stderr).
    y_init : int, default=0
        Start every free run from the record's first ``y_init`` measured
        samples (the estimator's ``simulate(X, y_init=...)``) instead of
        from rest; the free runs are scored and tested after them.

    Returns
    -------
    Bunch
        ``results``: DataFrame with one row per realisation, model, scored
        output and mode, columns ``realization, model, output, mode, dt,
        nrmse, fit_percent, mean, std, divergent`` and ``<test>_p``,
        ``<test>_passed`` for the tests ``whiteness, cross_positive,
        cross_negative``; ``statistics``: ``{mode: {output: {model label:
        ErrorStatistics}}}`` (eq. 19-20); ``errors``: ``{(model, mode,
        output): list of error arrays}``; ``analyses``: the
        :class:`~sysid_nn.residuals.ResidualAnalysis` of the first record,
        ``{(model, mode): analysis}``; ``outputs``: the scored fields, in
        order; ``max_lag`` and ``alpha`` of the tests.

    Examples
    --------
    >>> from sysid_nn.study import StudyConfig, fit_models, generate_data
    >>> from sysid_nn.study import evaluate
    >>> config = StudyConfig(models=("linear",), n_samples=600, n_test=2, max_lag=10,
    ...                      n_candidates=3, estimator_params={"all": {"n_init": 1}})
    >>> data = generate_data(config)
    >>> models = fit_models(data, config)
    >>> evaluation = evaluate(models, data, config)
    >>> evaluation.results[["realization", "model", "mode"]].values.tolist()
    [[0, 'linear', 'prediction'], [0, 'linear', 'simulation'], \
[1, 'linear', 'prediction'], [1, 'linear', 'simulation']]
    >>> {k: sorted(v) for k, v in evaluation.statistics["simulation"].items()}
    {'displacement': ['linear (OE)']}
    """
    recs = data[records]
    n = len(recs[next(iter(models.values())).inputs[0]])
    scored = list(
        dict.fromkeys(f for m in models.values() for _, f in _scored(m, outputs))
    )
    if not scored:
        raise ValueError(
            f"outputs={outputs!r} names none of the models' outputs "
            f"{sorted({f for m in models.values() for f in m.outputs})}."
        )
    task = delayed(_evaluate_record)
    args = (models, recs, data.dt, config, outputs, y_init)
    # Outside a joblib backend context None means serial; inside (dask) the
    # context's own setting applies.
    parallel = Parallel(n_jobs=config.n_jobs, return_as="generator")
    outputs = list(
        _progress(parallel(task(j, *args) for j in range(n)), n, "evaluating", progress)
    )
    results = pd.DataFrame([row for rows, _, _ in outputs for row in rows])
    errors = {key: [out[1][key] for out in outputs] for key in outputs[0][1]}
    # Free runs from a measured window are scored after it.
    starts = {mode: y_init if mode == "simulation" else 0 for mode in MODES}
    statistics = {
        mode: {
            field: {
                m.label: error_statistics(
                    [e[starts[mode] :] for e in errors[name, mode, field]],
                    data.dt * m.step,
                )
                for name, m in models.items()
                if (name, mode, field) in errors
            }
            for field in scored
        }
        for mode in MODES
    }
    return Bunch(
        results=results,
        statistics=statistics,
        errors=errors,
        analyses=outputs[0][2],
        outputs=scored,
        max_lag=config.max_lag,
        alpha=config.alpha,
    )


def summarize(evaluation: Bunch, models: Mapping[str, StudyModel]) -> pd.DataFrame:
    """Per model, output and mode: NRMSE, fit, eq. 19-20, test pass rates.

    Parameters
    ----------
    evaluation : Bunch
        From :func:`evaluate`.
    models : dict of str to StudyModel
        The evaluated models (for their labels).

    Returns
    -------
    pandas.DataFrame
        One row per model, scored output and mode with ``model, label,
        output, mode, n_realizations,
        n_divergent, nrmse_median, nrmse_mean, fit_percent_median, mu_Ns,
        sigma_Ns`` and ``<test>_pass_rate``. A diverged run counts as an
        infinite NRMSE in the median and is left out of the means.

    Examples
    --------
    >>> from sysid_nn.study import StudyConfig, fit_models, generate_data
    >>> from sysid_nn.study import evaluate, summarize
    >>> config = StudyConfig(models=("linear",), n_samples=600, n_test=2, max_lag=10,
    ...                      n_candidates=3, estimator_params={"all": {"n_init": 1}})
    >>> data = generate_data(config)
    >>> models = fit_models(data, config)
    >>> summary = summarize(evaluate(models, data, config), models)
    >>> summary[["label", "mode", "n_realizations"]].values.tolist()
    [['linear (OE)', 'prediction', 2], ['linear (OE)', 'simulation', 2]]
    """
    rows = []
    results = evaluation.results
    for name, model in models.items():
        for _, field in _scored(model, evaluation.outputs):
            for mode in MODES:
                r = results.query(
                    "model == @name and output == @field and mode == @mode"
                )
                stats = evaluation.statistics[mode][field][model.label]
                row = {
                    "model": name,
                    "label": model.label,
                    "output": field,
                    "mode": mode,
                    "n_realizations": stats.n_realizations,
                    "n_divergent": stats.n_divergent,
                    "nrmse_median": float(r["nrmse"].fillna(np.inf).median()),
                    "nrmse_mean": float(r["nrmse"].mean()),
                    "fit_percent_median": float(
                        r["fit_percent"].fillna(-np.inf).median()
                    ),
                    "mu_Ns": stats.mu,
                    "sigma_Ns": stats.sigma,
                }
                for test in _TESTS:
                    row[f"{test}_pass_rate"] = float(r[f"{test}_passed"].mean())
                rows.append(row)
    return pd.DataFrame(rows)
