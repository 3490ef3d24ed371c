"""The paper's section-4 study as plain functions (figs 4.1-4.7, eq. 19-20).

Kirkegaard, Nielsen & Hansen (1995) identify a Bouc-Wen hysteretic
oscillator with a tapped-delay-line (TDL) and an innovation state-space
(ISSM) network, then judge them by one-step prediction (4.3) and free-run
simulation (4.4) on realisations not used in training: residual
correlation tests (figs 4.3-4.4) and the averaged error statistics
``mu_Ns``, ``sigma_Ns`` of eq. 19-20 over 25 realisations (figs 4.5, 4.7).

The study here repeats that protocol with five models side by side: the
paper's two networks, the linear baseline and the toolbox's default TDL and
ISSM. It is built from the public API only, in four steps that can be run
and inspected one by one::

    config = StudyConfig(seed=0)
    data = generate_data(config)            # training, validation, test records
    models = fit_models(data, config)       # {name: StudyModel}
    evaluation = evaluate(models, data, config)
    evaluation.results                      # one row per realisation, model, mode

or all at once, writing figures, tables and a report::

    run_study(config, "sysid_nn_results")

Everything random is seeded from ``config.seed``; the tables are identical
whether the evaluation runs serially, on local processes or on a dask
cluster.
"""

from __future__ import annotations

import contextlib
import errno
import os
import platform
import secrets
import shutil
import tempfile
import time
import warnings
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from importlib import metadata
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np
import pandas as pd
from joblib import Parallel, delayed, parallel_backend
from sklearn.utils import Bunch

import sysid_nn
from sysid_nn import HystereticOscillator, ISSMRegressor, TDLRegressor
from sysid_nn.metrics import error_statistics, fit_percent, nrmse
from sysid_nn.plotting import panel_figure
from sysid_nn.residuals import analyze_residuals

__all__ = [
    "FIGURES",
    "MODES",
    "PAPER_ISSM",
    "PAPER_MODELS",
    "PAPER_TDL",
    "StudyConfig",
    "StudyModel",
    "evaluate",
    "fit_models",
    "generate_data",
    "hysteresis_loops",
    "model_specs",
    "run_study",
    "run_validation",
    "select_typical",
    "summarize",
    "write_report",
]

#: The two ways a model is used on unseen data: paper sections 4.3 and 4.4.
MODES = ("prediction", "simulation")

#: Names of the study's models, in the order they are shown.
PAPER_MODELS = ("tdl_paper", "issm_paper", "linear", "tdl", "issm")

#: The paper's TDL network (section 4.2): 6 displacement and 5 excitation
#: lags, 9 logistic hidden nodes, no bypass, plain delays, trained one step
#: ahead; ``TDLRegressor(**PAPER_TDL)``. The paper fits it at dt = 0.03 s.
PAPER_TDL = MappingProxyType(
    {
        "output_lags": 6,
        "input_lags": 5,
        "hidden_layer_sizes": (9,),
        "activation": "logistic",
        "linear_bypass": False,
        "lag_representation": "delays",
        "focus": "prediction",
    }
)

#: The paper's ISSM network (section 4.2): 3 states, 7 logistic hidden
#: nodes, no linear part, trained on the innovations;
#: ``ISSMRegressor(**PAPER_ISSM)`` with displacement and velocity measured.
PAPER_ISSM = MappingProxyType(
    {
        "n_states": 3,
        "hidden_layer_sizes": (7,),
        "activation": "logistic",
        "linear_part": False,
        "focus": "prediction",
    }
)

# Residual tests of figs 4.3-4.4 whose pass rates are reported.
_TESTS = ("whiteness", "cross_positive", "cross_negative")

# Reduced training for the CI-sized run (still every figure and table).
_QUICK_PARAMS = {"n_init": 1}


# ----------------------------------------------------------------------------
# Configuration
# ----------------------------------------------------------------------------
def _check_int(value: Any, name: str, low: int, hint: str) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{name} must be an integer; got {value!r}. {hint}")
    if value < low:
        raise ValueError(f"{name} must be >= {low}; got {value}. {hint}")


@dataclass(frozen=True)
class StudyConfig:
    """Settings of the section-4 study.

    Parameters
    ----------
    seed : int, default=0
        Master seed in ``[0, 2**32)``; the seeds of the training, validation
        and test records and of the networks' initial weights are drawn from
        it (:class:`numpy.random.SeedSequence`) and stated in the report.
    n_train : int, default=1
        Training records ``K``. They are the ``K`` records whose peak
        displacement is nearest the median of ``n_candidates`` generated
        ones: records of typical amplitude, so that no model has to
        extrapolate far (a small record makes every model extrapolate).
    n_val : int, default=2
        Validation records (early stopping and restart selection).
    n_test : int or None, default=None
        Unseen test realisations ``N_s``; None gives the paper's 25, or 5
        with ``quick``.
    n_candidates : int or None, default=None
        Records generated to choose the training records from; None gives
        ``max(10, 3 * n_train)``.
    n_samples : int, default=2000
        Samples per record (the paper's 20 s at ``dt = 0.01`` s).
    dt : float, default=0.01
        Sampling step of the records, s.
    paper_tdl_step : int, default=3
        The paper's TDL sees every ``paper_tdl_step``-th sample (0.03 s).
    models : tuple of str, default=PAPER_MODELS
        Which of ``"tdl_paper", "issm_paper", "linear", "tdl", "issm"`` to
        run (see :func:`model_specs`).
    quick : bool, default=False
        CI-sized run: 5 test realisations unless ``n_test`` is given, one
        restart per network instead of four.
    n_jobs : int or None, default=None
        Parallel jobs of the Monte Carlo evaluation and of the networks'
        restarts (joblib semantics).
    max_lag : int, default=25
        Largest lag of the residual correlation tests.
    alpha : float, default=0.05
        Significance level of the residual tests (95 % bands as in the paper).
    estimator_params : dict, default={}
        Overrides of the estimators' parameters: ``{"all": {...}}`` for every
        model, ``{name: {...}}`` for one (applied after ``"all"``), e.g.
        ``{"all": {"max_iter": 5, "n_init": 1}}`` for a tiny run.

    Examples
    --------
    >>> config = StudyConfig(seed=1, quick=True)
    >>> config.test_size, config.candidates
    (5, 10)
    >>> StudyConfig(n_test=0)
    Traceback (most recent call last):
    ...
    ValueError: n_test must be >= 1; got 0. Evaluate on at least one test ...
    """

    seed: int = 0
    n_train: int = 1
    n_val: int = 2
    n_test: int | None = None
    n_candidates: int | None = None
    n_samples: int = 2000
    dt: float = 0.01
    paper_tdl_step: int = 3
    models: tuple[str, ...] = PAPER_MODELS
    quick: bool = False
    n_jobs: int | None = None
    max_lag: int = 25
    alpha: float = 0.05
    estimator_params: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        _check_int(self.seed, "seed", 0, "Use a seed in [0, 2**32).")
        if self.seed >= 2**32:
            raise ValueError(f"seed must be < 2**32; got {self.seed}.")
        _check_int(self.n_train, "n_train", 1, "Train on at least one record.")
        _check_int(self.n_val, "n_val", 1, "Early stopping needs a validation record.")
        if self.n_test is not None:
            _check_int(
                self.n_test, "n_test", 1, "Evaluate on at least one test record."
            )
        if self.n_candidates is not None:
            _check_int(
                self.n_candidates,
                "n_candidates",
                self.n_train,
                "Generate at least n_train candidate records.",
            )
        step = self.paper_tdl_step
        _check_int(step, "paper_tdl_step", 1, "The paper's TDL uses 3.")
        # The residual tests need more samples than lags on the coarsest grid.
        _check_int(
            self.n_samples,
            "n_samples",
            step * (2 * self.max_lag + 10),
            "Use longer records or a smaller max_lag.",
        )
        if not (np.isfinite(self.dt) and self.dt > 0):
            raise ValueError(f"dt must be a finite number > 0; got {self.dt!r}.")
        if isinstance(self.models, str) or not self.models:
            raise ValueError(
                f"models must be a non-empty tuple of names from {PAPER_MODELS}; "
                f"got {self.models!r}."
            )
        unknown = [m for m in self.models if m not in PAPER_MODELS]
        if unknown or len(set(self.models)) != len(self.models):
            raise ValueError(
                f"models must hold distinct names from {PAPER_MODELS}; got "
                f"{tuple(self.models)!r}."
            )
        object.__setattr__(self, "models", tuple(self.models))
        if self.n_jobs is not None:
            _check_int(self.n_jobs, "n_jobs", -(2**31), "Use None, -1 or >= 1.")
            if self.n_jobs == 0:
                raise ValueError("n_jobs must not be 0; use None, -1 or >= 1.")
        _check_int(self.max_lag, "max_lag", 1, "The paper uses 25.")
        if not 0 < self.alpha < 1:
            raise ValueError(f"alpha must be in (0, 1); got {self.alpha!r}.")
        bad = set(self.estimator_params) - {"all", *PAPER_MODELS}
        if bad:
            raise ValueError(
                f"estimator_params keys must be 'all' or model names from "
                f"{PAPER_MODELS}; got {sorted(bad)}."
            )

    @property
    def test_size(self) -> int:
        """Number of test realisations actually used."""
        if self.n_test is not None:
            return self.n_test
        return 5 if self.quick else 25

    @property
    def candidates(self) -> int:
        """Number of candidate records the training records are chosen from."""
        if self.n_candidates is not None:
            return self.n_candidates
        return max(10, 3 * self.n_train)

    def seeds(self) -> dict[str, int]:
        """Derived seeds of the records and of the networks' weights.

        Returns
        -------
        dict
            ``{"train", "validation", "test", "weights"}`` to ints.

        Examples
        --------
        >>> sorted(StudyConfig(seed=0).seeds())
        ['test', 'train', 'validation', 'weights']
        """
        states = np.random.SeedSequence(self.seed).generate_state(4)
        names = ("train", "validation", "test", "weights")
        return {n: int(s) for n, s in zip(names, states, strict=True)}


# ----------------------------------------------------------------------------
# Data
# ----------------------------------------------------------------------------
def select_typical(peaks: Sequence[float], k: int) -> np.ndarray:
    """Return the indices of the ``k`` records whose peak is nearest the median.

    Parameters
    ----------
    peaks : sequence of float
        Peak absolute displacement of every candidate record.
    k : int
        Number of records to choose, ``1 <= k <= len(peaks)``.

    Returns
    -------
    ndarray of int
        Sorted indices; ties go to the lower index.

    Examples
    --------
    >>> select_typical([0.01, 0.05, 0.02, 0.03, 0.02], 2).tolist()
    [2, 4]
    """
    peaks = np.asarray(peaks, dtype=float)
    _check_int(k, "k", 1, "Choose at least one record.")
    if k > peaks.size:
        raise ValueError(f"k={k} exceeds the {peaks.size} candidate records.")
    distance = np.abs(peaks - np.median(peaks))
    return np.sort(np.argsort(distance, kind="stable")[:k])


def _records(rec: Bunch, index: Any = slice(None)) -> Bunch:
    """The study's record fields of a generated Bunch, rows ``index``."""
    return Bunch(
        excitation=rec.excitation[index],
        displacement=rec.displacement[index],
        velocity=rec.velocity[index],
        hysteretic=rec.hysteretic[index],
    )


def generate_data(config: StudyConfig) -> Bunch:
    """Training, validation and test records of the hysteretic oscillator.

    The oscillator and excitation have the paper's parameters (section 4.1,
    ``r0`` calibrated so that ``E[max|X|] = 2 z0``). Training records are
    chosen by :func:`select_typical` from ``config.candidates`` records;
    validation and test records are drawn from their own seeds.

    Parameters
    ----------
    config : StudyConfig
        Seeds, numbers of records, their length and sampling step.

    Returns
    -------
    Bunch
        ``train``, ``validation``, ``test``: Bunches of ``excitation,
        displacement, velocity, hysteretic`` arrays of shape
        ``(n_records, n_samples)``; ``t``, ``dt``, ``r0``, ``seeds``,
        ``candidate_peaks`` (peak ``|X|`` of every candidate),
        ``train_index`` (the chosen candidates) and ``oscillator``.

    Examples
    --------
    >>> data = generate_data(StudyConfig(n_test=2, n_samples=600, n_candidates=3))
    >>> data.train.displacement.shape, data.test.excitation.shape
    ((1, 600), (2, 600))
    """
    seeds = config.seeds()
    osc = HystereticOscillator()

    def draw(n: int, seed: int) -> Bunch:
        return osc.generate(
            n, n_samples=config.n_samples, dt=config.dt, random_state=seed
        )

    pool = draw(config.candidates, seeds["train"])
    peaks = np.max(np.abs(pool.displacement), axis=1)
    chosen = select_typical(peaks, config.n_train)
    return Bunch(
        train=_records(pool, chosen),
        validation=_records(draw(config.n_val, seeds["validation"])),
        test=_records(draw(config.test_size, seeds["test"])),
        t=pool.t,
        dt=float(config.dt),
        r0=float(pool.r0),
        seeds=seeds,
        candidate_peaks=peaks,
        train_index=chosen,
        oscillator=osc,
    )


# ----------------------------------------------------------------------------
# Models
# ----------------------------------------------------------------------------
@dataclass
class StudyModel:
    """An estimator with the record fields it maps and its sampling step.

    Parameters
    ----------
    label : str
        Name shown in figures and tables.
    estimator : estimator
        A TDL or ISSM regressor (fitted after :func:`fit_models`).
    inputs : tuple of str
        Record fields fed as excitation columns.
    outputs : tuple of str
        Record fields modelled; the first one is scored.
    step : int, default=1
        The model sees every ``step``-th sample.

    Examples
    --------
    >>> import numpy as np
    >>> from sysid_nn import TDLRegressor
    >>> m = StudyModel("TDL", TDLRegressor(), ("excitation",), ("displacement",), 2)
    >>> records = {"excitation": np.ones((1, 6)), "displacement": np.ones((1, 6))}
    >>> X, y = m.arrays(records)
    >>> X[0].shape, y[0].shape
    ((3, 1), (3,))
    """

    label: str
    estimator: Any
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    step: int = 1

    def arrays(
        self, records: Mapping[str, Any], index: Iterable[int] | None = None
    ) -> tuple[list[np.ndarray], list[np.ndarray]]:
        """Estimator inputs and outputs of records, as lists of sequences.

        Parameters
        ----------
        records : mapping of field name to 2-D array or list of 1-D arrays
            One row (or list item) per record.
        index : iterable of int, optional
            Records to take; all by default.

        Returns
        -------
        X : list of ndarray of shape (n_samples, n_inputs)
            Excitation of every record, one column per input field.
        y : list of ndarray of shape (n_samples,) or (n_samples, n_outputs)
            Modelled outputs of every record (1-D for a single output).
        """
        if index is None:
            index = range(len(records[self.inputs[0]]))
        cut = slice(None, None, self.step)
        X, y = [], []
        for j in index:
            X.append(np.column_stack([records[f][j][cut] for f in self.inputs]))
            out = np.column_stack([records[f][j][cut] for f in self.outputs])
            y.append(out[:, 0] if out.shape[1] == 1 else out)
        return X, y


def model_specs(config: StudyConfig) -> dict[str, StudyModel]:
    """Unfitted models of the study, by name.

    ``tdl_paper``: the paper's TDL (6 displacement and 5 excitation lags, 9
    logistic hidden nodes, prediction focus) on every third sample;
    ``issm_paper``: the paper's ISSM (3 states, 7 logistic hidden nodes,
    prediction focus, no linear part) with displacement and velocity
    measured; ``linear``: the linear output-error baseline
    (``hidden_layer_sizes=()``); ``tdl`` and ``issm``: the toolbox's
    defaults (ISSM with displacement and velocity measured).

    Parameters
    ----------
    config : StudyConfig
        ``models`` selects, ``quick``, ``n_jobs`` and ``estimator_params``
        adjust the estimators; the weights are seeded from ``config.seed``.

    Returns
    -------
    dict of str to StudyModel
        The selected models, unfitted, in the order of ``config.models``.

    Examples
    --------
    >>> specs = model_specs(StudyConfig(models=("tdl_paper", "linear")))
    >>> {name: (m.label, m.step) for name, m in specs.items()}
    {'tdl_paper': ('TDL (paper)', 3), 'linear': ('linear (OE)', 1)}
    """
    force, disp, both = ("excitation",), ("displacement",), ("displacement", "velocity")
    table: dict[str, tuple[str, Any, dict, tuple[str, ...], int]] = {
        "tdl_paper": (
            "TDL (paper)",
            TDLRegressor,
            PAPER_TDL,
            disp,
            config.paper_tdl_step,
        ),
        "issm_paper": ("ISSM (paper)", ISSMRegressor, PAPER_ISSM, both, 1),
        "linear": ("linear (OE)", TDLRegressor, {"hidden_layer_sizes": ()}, disp, 1),
        "tdl": ("TDL (default)", TDLRegressor, {}, disp, 1),
        "issm": ("ISSM (default)", ISSMRegressor, {}, both, 1),
    }
    weights_seed = config.seeds()["weights"]
    specs = {}
    for name in config.models:
        label, cls, params, outputs, step = table[name]
        params = {
            **params,
            **(_QUICK_PARAMS if config.quick else {}),
            **config.estimator_params.get("all", {}),
            **config.estimator_params.get(name, {}),
            "random_state": weights_seed,
            "n_jobs": config.n_jobs,
        }
        specs[name] = StudyModel(label, cls(**params), force, outputs, step)
    return specs


def _progress(items: Iterable, total: int, desc: str, show: bool) -> Iterator:
    from tqdm.auto import tqdm

    return iter(tqdm(items, total=total, desc=desc, disable=not show, leave=False))


def fit_models(
    data: Bunch, config: StudyConfig, *, progress: bool = False
) -> dict[str, StudyModel]:
    """Fit every model of :func:`model_specs` on the training records.

    Parameters
    ----------
    data : Bunch
        From :func:`generate_data`.
    config : StudyConfig
        Which models, their settings and seeds (:func:`model_specs`).
    progress : bool, default=False
        Show a progress bar (stderr).

    Returns
    -------
    dict of str to StudyModel
        Fitted models; warnings raised while fitting (e.g. not converged) are
        kept in ``data.fit_warnings[name]`` as text.

    Examples
    --------
    >>> config = StudyConfig(models=("linear",), n_samples=600, n_test=2,
    ...                      n_candidates=3, max_lag=10,
    ...                      estimator_params={"all": {"n_init": 1}})
    >>> data = generate_data(config)
    >>> models = fit_models(data, config)
    >>> models["linear"].estimator.n_features_in_
    1
    """
    specs = model_specs(config)
    data.fit_warnings = {}
    for name, model in _progress(specs.items(), len(specs), "fitting", progress):
        X, y = model.arrays(data.train)
        X_val, y_val = model.arrays(data.validation)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            model.estimator.fit(X, y, X_val=X_val, y_val=y_val)
        data.fit_warnings[name] = sorted(
            {f"{w.category.__name__}: {str(w.message).splitlines()[0]}" for w in caught}
        )
    return specs


# ----------------------------------------------------------------------------
# Evaluation
# ----------------------------------------------------------------------------
def _evaluate_record(
    j: int,
    models: Mapping[str, StudyModel],
    records: Mapping[str, Any],
    dt: float,
    max_lag: int,
    alpha: float,
) -> tuple[list[dict], dict[tuple[str, str], np.ndarray], dict]:
    """All models and modes on record ``j``: rows, scored errors, analyses."""
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
                    max_lag=max_lag,
                    alpha=alpha,
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
        ``{(model, mode): analysis}``.

    Examples
    --------
    >>> config = StudyConfig(models=("linear",), n_samples=600, n_test=2,
    ...                      n_candidates=3, max_lag=10,
    ...                      estimator_params={"all": {"n_init": 1}})
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
    args = (models, recs, data.dt, config.max_lag, config.alpha)
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
        results=results, statistics=statistics, errors=errors, analyses=outputs[0][2]
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
    >>> config = StudyConfig(models=("linear",), n_samples=600, n_test=2,
    ...                      n_candidates=3, max_lag=10,
    ...                      estimator_params={"all": {"n_init": 1}})
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


# ----------------------------------------------------------------------------
# Figures
# ----------------------------------------------------------------------------
def _model_grid(model: StudyModel, n: int, dt: float) -> np.ndarray:
    return np.arange(n) * dt * model.step


def _response_figure(models, data, evaluation, mode, title) -> Any:
    from sysid_nn.plotting import plot_response

    fig, axes = panel_figure(len(models))
    for ax, (name, model) in zip(axes, models.items(), strict=True):
        (_,), (y,) = model.arrays(data.test, [0])
        y0 = y if y.ndim == 1 else y[:, 0]
        e = evaluation.errors[name, mode][0]
        t = _model_grid(model, y0.size, data.dt)
        plot_response(t, y0, y0 - e, label=model.label, ax=ax)
        ax.set_title(f"{title}: {model.label}, test realisation 0", fontsize=9)
    return fig


def _correlation_figure(models, data, evaluation, kind) -> Any:
    from sysid_nn.plotting import plot_autocorrelation, plot_cross_correlation

    plot, results = {
        "acf": (plot_autocorrelation, "whiteness"),
        "ccf": (plot_cross_correlation, "cross_correlation"),
    }[kind]
    fig, axes = panel_figure(len(models))
    for ax, (name, model) in zip(axes, models.items(), strict=True):
        analysis = evaluation.analyses[name, "prediction"]
        found = getattr(analysis, results).get((0, 0))
        if found is None:
            ax.text(0.5, 0.5, f"{model.label}: prediction diverged", ha="center")
            continue
        plot(found, dt=data.dt * model.step, title=model.label, ax=ax)
    return fig


def _statistics_figure(evaluation, mode, title) -> Any:
    from sysid_nn.plotting import plot_error_statistics

    fig, (ax,) = panel_figure(1, row_height=3.6)
    plot_error_statistics(evaluation.statistics[mode], title=title, ax=ax)
    return fig


def _hysteretic_state(x: np.ndarray, osc: Any, substeps: int = 4) -> np.ndarray:
    """Bouc-Wen state ``Z`` (eq. 15) driven by a displacement history from rest.

    Eq. 15 is rate-independent (``dZ/dX`` depends on ``Z`` and the sign of
    ``dX`` only), so the true hysteretic element can follow any displacement
    history, a model's simulation included; integrated in ``X`` by RK4 on
    ``substeps`` pieces of every sample step.
    """
    p = osc.get_params()
    beta, gamma, n = (
        p["beta"] / p["z0"] ** p["n"],
        p["gamma"] / p["z0"] ** p["n"],
        p["n"],
    )

    def slope(z: float, dx: float) -> float:
        s = dx * z
        sign = 1.0 if s > 0 else (-1.0 if s < 0 else 0.0)
        return 1.0 - (beta * sign + gamma) * abs(z) ** n

    z = np.zeros(x.size)
    for k in range(1, x.size):
        h, zk = (x[k] - x[k - 1]) / substeps, z[k - 1]
        for _ in range(substeps):
            k1 = slope(zk, h)
            k2 = slope(zk + 0.5 * h * k1, h)
            k3 = slope(zk + 0.5 * h * k2, h)
            k4 = slope(zk + h * k3, h)
            zk += h * (k1 + 2 * k2 + 2 * k3 + k4) / 6
        z[k] = zk
    return z


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
    >>> config = StudyConfig(models=("linear",), n_samples=600, n_test=2,
    ...                      n_candidates=3, max_lag=10,
    ...                      estimator_params={"all": {"n_init": 1}})
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
        e = evaluation.errors[name, "simulation"][0]
        x_m = x[cut] - e
        if not np.all(np.isfinite(x_m)):
            continue
        z_x = _hysteretic_state(x_m, data.oscillator)
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


def _hysteresis_figure(loops: Bunch) -> Any:
    from sysid_nn.plotting import plot_hysteresis

    fig, (top, bottom) = panel_figure(2, row_height=3.6)
    x, g, z = loops.truth
    plot_hysteresis(x, g, label="true g", models=loops.force, ax=top)
    top.set_title(
        "Restoring force g = αX + (1-α)Z along the true and the simulated "
        "displacements, test realisation 0",
        fontsize=9,
    )
    plot_hysteresis(
        x, z, label="true Z", models=loops.state, ylabel="hysteretic state Z", ax=bottom
    )
    bottom.set_title(
        "Hysteretic state: truth and the ISSMs' estimated states", fontsize=9
    )
    return fig


#: Figure files of a study directory, in the paper's order.
FIGURES = {
    "fig4_1_training_data.png": "Training data (fig. 4.1)",
    "fig4_2_prediction.png": "One-step prediction on a test realisation (fig. 4.2)",
    "fig4_3_residual_autocorrelation.png": (
        "Autocorrelation of prediction errors (fig. 4.3)"
    ),
    "fig4_4_residual_cross_correlation.png": (
        "Cross-correlation of prediction errors and input (fig. 4.4)"
    ),
    "fig4_5_prediction_error_statistics.png": (
        "μ_Ns and σ_Ns of prediction errors (fig. 4.5)"
    ),
    "fig4_6_simulation.png": "Free-run simulation on a test realisation (fig. 4.6)",
    "fig4_7_simulation_error_statistics.png": (
        "μ_Ns and σ_Ns of simulation errors (fig. 4.7)"
    ),
    "hysteresis.png": "Hysteresis loops: truth and models' simulations",
}


def _figures(models, data, evaluation, loops) -> dict[str, Callable[[], Any]]:
    """Figure builders by file name; those needing absent data are left out."""
    from sysid_nn.plotting import plot_records

    def training() -> Any:
        _, axes = panel_figure(2)
        t = np.arange(data.train.excitation.shape[1]) * data.dt
        return plot_records(t, data.train.excitation, data.train.displacement, ax=axes)

    names = list(FIGURES)
    builders = {
        names[1]: lambda: _response_figure(
            models, data, evaluation, "prediction", "Prediction"
        ),
        names[2]: lambda: _correlation_figure(models, data, evaluation, "acf"),
        names[3]: lambda: _correlation_figure(models, data, evaluation, "ccf"),
        names[4]: lambda: _statistics_figure(
            evaluation, "prediction", FIGURES[names[4]]
        ),
        names[5]: lambda: _response_figure(
            models, data, evaluation, "simulation", "Simulation"
        ),
        names[6]: lambda: _statistics_figure(
            evaluation, "simulation", FIGURES[names[6]]
        ),
    }
    if "train" in data:
        builders[names[0]] = training
    if loops is not None:
        builders[names[7]] = lambda: _hysteresis_figure(loops)
    return {name: builders[name] for name in names if name in builders}


# ----------------------------------------------------------------------------
# Report
# ----------------------------------------------------------------------------
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


def _glance(summary: pd.DataFrame) -> pd.DataFrame:
    """Rows = models, columns = the numbers a reader compares with the paper."""
    by = summary.set_index(["model", "mode"])
    linear = by["nrmse_median"].get(("linear", "simulation"))
    rows = []
    for name in dict.fromkeys(summary["model"]):
        p, s = by.loc[(name, "prediction")], by.loc[(name, "simulation")]
        row = {
            "model": p["label"],
            "NRMSE pred. (median)": p["nrmse_median"],
            "NRMSE sim. (median)": s["nrmse_median"],
        }
        if linear is not None:
            row["sim. / linear"] = s["nrmse_median"] / linear
        row |= {
            "μ_Ns pred.": p["mu_Ns"],
            "σ_Ns pred.": p["sigma_Ns"],
            "μ_Ns sim.": s["mu_Ns"],
            "σ_Ns sim.": s["sigma_Ns"],
            "white (pred.)": _percent(p["whiteness_pass_rate"]),
            "uncorrelated with input (pred.)": _percent(p["cross_positive_pass_rate"]),
            "diverged (pred./sim.)": (
                f"{p['n_divergent']}/{s['n_divergent']} of {s['n_realizations']}"
            ),
        }
        rows.append(row)
    return pd.DataFrame(rows)


def _mode_table(summary: pd.DataFrame, mode: str) -> pd.DataFrame:
    cols = {
        "label": "model",
        "n_realizations": "N_s",
        "nrmse_median": "NRMSE median",
        "nrmse_mean": "NRMSE mean",
        "fit_percent_median": "fit % median",
        "mu_Ns": "μ_Ns (eq. 19)",
        "sigma_Ns": "σ_Ns (eq. 20)",
        "whiteness_pass_rate": "whiteness passed",
        "cross_positive_pass_rate": "cross τ>0 passed",
        "cross_negative_pass_rate": "cross τ<0 passed",
    }
    frame = summary.query("mode == @mode")[list(cols)].rename(columns=cols)
    for c in ("whiteness passed", "cross τ>0 passed", "cross τ<0 passed"):
        frame[c] = frame[c].map(_percent)
    return frame


def _non_default_params(estimator: Any) -> str:
    defaults = type(estimator)().get_params()
    skip = {"random_state", "n_jobs", "verbose"}
    changed = {
        k: v
        for k, v in estimator.get_params().items()
        if k not in skip and v != defaults[k]
    }
    return ", ".join(f"{k}={v!r}" for k, v in changed.items()) or "defaults"


def _versions() -> str:
    names = ["numpy", "scipy", "scikit-learn", "statsmodels", "pandas", "numba"]
    names += ["joblib", "matplotlib", "dask", "distributed"]
    found = [f"sysid_nn {sysid_nn.__version__}"]
    for name in names:
        with contextlib.suppress(metadata.PackageNotFoundError):
            found.append(f"{name} {metadata.version(name)}")
    return ", ".join(found)


def _machine() -> str:
    return (
        f"{platform.platform()}, Python {platform.python_version()}, "
        f"{os.cpu_count()} logical CPUs ({platform.machine()})"
    )


def _findings(summary: pd.DataFrame) -> list[str]:
    sim = summary.query("mode == 'simulation'").set_index("model")
    lines = []
    best = sim["nrmse_median"].idxmin()
    lines.append(
        f"Best simulator on unseen realisations: {sim.loc[best, 'label']} "
        f"(median free-run NRMSE {_fmt(sim.loc[best, 'nrmse_median'])})."
    )
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
) -> None:
    """Write ``report.md``: setup, tables laid out as the paper's figures, files.

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

    Examples
    --------
    >>> import tempfile, pathlib
    >>> config = StudyConfig(models=("linear",), n_samples=600, n_test=2,
    ...                      n_candidates=3, max_lag=10,
    ...                      estimator_params={"all": {"n_init": 1}})
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
                "fit time [s]": round(float(getattr(est, "fit_time_", np.nan)), 1),
            }
        )
    lines = [f"# {title}", ""]
    lines += ["## Results at a glance", "", _md_table(_glance(summary)), ""]
    lines += [
        "NRMSE: root-mean-square error of the displacement over its standard "
        "deviation (0 perfect, 1 no better than its mean); `sim. / linear`: "
        "median free-run NRMSE relative to the linear baseline. μ_Ns and σ_Ns "
        "(eq. 19-20) are in the displacement's units, averaged over the N_s "
        "test realisations as in figs 4.5 and 4.7. Residual tests at the 95 % "
        "level on every realisation (figs 4.3-4.4).",
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
    lines += [f"- {line}" for line in _findings(summary)] + [""]
    lines += ["## Setup", ""] + [f"- {line}" for line in setup] + [""]
    first = next(iter(FIGURES))
    if first in has:
        lines += [f"![{FIGURES[first]}]({first})", ""]
    lines += ["### Models", "", _md_table(pd.DataFrame(rows)), ""]
    for heading, mode, figs in (
        ("One-step prediction (section 4.3)", "prediction", [1, 2, 3, 4]),
        ("Free-run simulation (section 4.4)", "simulation", [5, 6]),
    ):
        lines += [f"## {heading}", "", _md_table(_mode_table(summary, mode)), ""]
        for i in figs:
            name = list(FIGURES)[i]
            if name in has:
                lines += [f"![{FIGURES[name]}]({name})", ""]
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
    lines += ["- `results.csv`: one row per realisation, model and mode."]
    lines += ["- `summary.csv`: one row per model and mode (the tables above)."]
    lines += [f"- `{name}`: {FIGURES[name]}" for name in figures]
    Path(path).write_text("\n".join(lines) + "\n", encoding="utf-8")


# ----------------------------------------------------------------------------
# Output directory
# ----------------------------------------------------------------------------
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
) -> tuple[pd.DataFrame, list[str]]:
    summary = summarize(evaluation, models)
    evaluation.results.to_csv(tmp / "results.csv", index=False)
    summary.to_csv(tmp / "summary.csv", index=False)
    builders = _figures(models, data, evaluation, loops)
    for name, build in _progress(builders.items(), len(builders), "figures", progress):
        build().savefig(tmp / name, dpi=90)
    return summary, list(builders)


def _parallel_line(config: StudyConfig, scheduler: str | None) -> str:
    where = f"dask scheduler {scheduler}" if scheduler else "local joblib"
    return f"Parallel: {where}, n_jobs={config.n_jobs} (evaluation and restarts)."


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
    return lines


def _hysteresis_lines(loops: Bunch) -> list[str]:
    lines = ["![Hysteresis loops](hysteresis.png)", ""]
    if loops.state_correlation:
        lines.append(
            "Estimated unmeasured ISSM states against the true hysteretic Z "
            "(free run, test realisation 0, affine map fitted for display): "
            + ", ".join(
                f"{k} |r| = {v:.3f}" for k, v in loops.state_correlation.items()
            )
            + "."
        )
    lines.append(
        "Restoring force of the models: the true hysteretic element (eq. 15) "
        "driven by each model's simulated displacement."
    )
    return lines


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
    setup: Sequence[str] = (),
    progress: bool = False,
) -> Bunch:
    """Validate a fitted model on measured records: the study's report on them.

    Prediction and simulation of every record, residual tests, eq. 19-20
    statistics, figs 4.2-4.7 and ``report.md``, written like
    :func:`run_study` (staged, then moved in place).

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
    setup : sequence of str
        Extra lines for the report's setup section (e.g. file names).
    progress : bool, default=False
        Progress bars on stderr.

    Returns
    -------
    Bunch
        ``out_dir``, ``results``, ``summary``, ``evaluation``.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> from sysid_nn import TDLRegressor
    >>> rec = HystereticOscillator(r0=0.05).generate(2, n_samples=300, random_state=0)
    >>> records = {"force": list(rec.excitation), "x": list(rec.displacement)}
    >>> model = StudyModel("ARX", TDLRegressor(hidden_layer_sizes=(), n_init=1),
    ...                    ("force",), ("x",))
    >>> _ = model.estimator.fit(*model.arrays(records))
    >>> out = pathlib.Path(tempfile.mkdtemp()) / "validation"
    >>> report = run_validation(model, records, out, dt=0.01, max_lag=10)
    >>> sorted(p.name for p in out.glob("*.csv"))
    ['results.csv', 'summary.csv']
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
    models = {"model": model}
    data = Bunch(test=records, dt=float(dt))
    with _staged_directory(out_dir, overwrite) as tmp:
        evaluation = evaluate(models, data, config, progress=progress)
        summary, figures = _write_outputs(tmp, models, data, evaluation, None, progress)
        n = summary["n_realizations"].iloc[0]
        write_report(
            tmp / "report.md",
            summary,
            title=f"Validation of {model.label}",
            setup=[
                *setup,
                f"{n} record(s) at dt = {dt:g} s; residual tests with "
                f"max_lag={max_lag}, alpha={alpha}.",
                f"Software: {_versions()}.",
                f"Machine: {_machine()}.",
            ],
            models=models,
            figures=figures,
        )
    return Bunch(
        out_dir=Path(out_dir),
        results=evaluation.results,
        summary=summary,
        evaluation=evaluation,
    )
