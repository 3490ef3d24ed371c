"""Scoring the models on unseen realisations: residual tests, NRMSE, eq. 19-20."""

from __future__ import annotations

import warnings
from collections.abc import Mapping
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


def _evaluate_record(
    j: int,
    models: Mapping[str, StudyModel],
    records: Mapping[str, Any],
    dt: float,
    config: StudyConfig,
) -> tuple[list[dict], dict[tuple[str, str], np.ndarray], dict]:
    """All models and modes on record ``j``: rows, scored errors, analyses.

    ``config`` gives the residual tests' ``max_lag`` and ``alpha``.
    """
    rows, errors, analyses = [], {}, {}
    for name, model in models.items():
        (X,), (y,) = model.arrays(records, [j])
        y0 = y if y.ndim == 1 else y[:, 0]
        for mode in MODES:
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
                )
            e = np.asarray(analysis.residuals)
            e = e if e.ndim == 1 else e[:, 0]
            stats = error_statistics(e, dt * model.step)
            # One verdict per test: every input must pass, the smallest p counts.
            tests = (
                analysis.summary.query("sequence == 0 and output == 0")
                .groupby("test")
                .agg(p_value=("p_value", "min"), passed=("passed", "all"))
            )
            row = {
                "realization": j,
                "model": name,
                "mode": mode,
                "dt": dt * model.step,
                "nrmse": float(nrmse(y0, y0 - e)),
                "fit_percent": float(fit_percent(y0, y0 - e)),
                "mean": float(stats.means[0]),
                "std": float(stats.stds[0]),
                "divergent": bool(stats.divergent[0]),
            }
            for test in _TESTS:
                row[f"{test}_p"] = float(tests.loc[test, "p_value"])
                row[f"{test}_passed"] = bool(tests.loc[test, "passed"])
            rows.append(row)
            errors[name, mode] = e
            analyses[name, mode] = analysis
    return rows, errors, analyses


def evaluate(
    models: Mapping[str, StudyModel],
    data: Bunch,
    config: StudyConfig,
    *,
    records: str = "test",
    progress: bool = False,
) -> Bunch:
    """One-step prediction and free-run simulation on unseen realisations.

    For every record, model and mode (:data:`MODES`) the residuals of the
    first output (displacement) are tested (whiteness and input
    cross-correlation, figs 4.3-4.4) and scored; over all records the
    averaged mean ``mu_Ns`` and standard deviation ``sigma_Ns`` of eq. 19-20
    are computed. Records run in parallel with joblib (``config.n_jobs``,
    or the active joblib backend, e.g. dask).

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
    progress : bool, default=False
        Show a progress bar (stderr).

    Returns
    -------
    Bunch
        ``results``: DataFrame with one row per realisation, model and mode,
        columns ``realization, model, mode, dt, nrmse, fit_percent, mean,
        std, divergent`` and ``<test>_p``, ``<test>_passed`` for the tests
        ``whiteness, cross_positive, cross_negative``; ``statistics``:
        ``{mode: {model: ErrorStatistics}}`` (eq. 19-20); ``errors``:
        ``{(model, mode): list of error arrays}``; ``analyses``: the
        :class:`~sysid_nn.residuals.ResidualAnalysis` of the first record,
        ``{(model, mode): analysis}``; ``max_lag`` and ``alpha`` of the tests.

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
    >>> sorted(evaluation.statistics["simulation"])
    ['linear (OE)']
    """
    recs = data[records]
    n = len(recs[next(iter(models.values())).inputs[0]])
    task = delayed(_evaluate_record)
    args = (models, recs, data.dt, config)
    # Outside a joblib backend context None means serial; inside (dask) the
    # context's own setting applies.
    parallel = Parallel(n_jobs=config.n_jobs, return_as="generator")
    outputs = list(
        _progress(parallel(task(j, *args) for j in range(n)), n, "evaluating", progress)
    )
    results = pd.DataFrame([row for rows, _, _ in outputs for row in rows])
    errors = {key: [out[1][key] for out in outputs] for key in outputs[0][1]}
    statistics = {
        mode: {
            models[name].label: error_statistics(
                errors[name, mode], data.dt * models[name].step
            )
            for name in models
        }
        for mode in MODES
    }
    return Bunch(
        results=results,
        statistics=statistics,
        errors=errors,
        analyses=outputs[0][2],
        max_lag=config.max_lag,
        alpha=config.alpha,
    )


def summarize(evaluation: Bunch, models: Mapping[str, StudyModel]) -> pd.DataFrame:
    """Per model and mode: NRMSE, fit, eq. 19-20 statistics, test pass rates.

    Parameters
    ----------
    evaluation : Bunch
        From :func:`evaluate`.
    models : dict of str to StudyModel
        The evaluated models (for their labels).

    Returns
    -------
    pandas.DataFrame
        One row per model and mode with ``model, label, mode, n_realizations,
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
    for name, model in models.items():
        for mode in MODES:
            r = evaluation.results.query("model == @name and mode == @mode")
            stats = evaluation.statistics[mode][model.label]
            row = {
                "model": name,
                "label": model.label,
                "mode": mode,
                "n_realizations": stats.n_realizations,
                "n_divergent": stats.n_divergent,
                "nrmse_median": float(r["nrmse"].fillna(np.inf).median()),
                "nrmse_mean": float(r["nrmse"].mean()),
                "fit_percent_median": float(r["fit_percent"].fillna(-np.inf).median()),
                "mu_Ns": stats.mu,
                "sigma_Ns": stats.sigma,
            }
            for test in _TESTS:
                row[f"{test}_pass_rate"] = float(r[f"{test}_passed"].mean())
            rows.append(row)
    return pd.DataFrame(rows)
