"""Error measures, the paper's error statistics and model-selection scorers.

Everything here accepts one sequence (an array) or several experiments (a
list of arrays, see the data conventions of the package): errors of a list
are pooled over all its samples, never averaged per sequence first.

A free-run simulation that diverged is returned by the estimators as NaN
from the time of divergence on. The measures below never drop such samples
silently: NaN propagates into :func:`nrmse`, :func:`fit_percent`,
:func:`r2` and :func:`error_statistics` (which also counts the divergent
realisations), and the scorers turn a non-finite score into a documented
penalty so that model selection ranks a divergent candidate last.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import pandas as pd

from sysid_nn._docstrings import fill_doc
from sysid_nn._records._sequences import as_sequence_list, check_paired

__all__ = [
    "ErrorStatistics",
    "error_statistics",
    "fit_percent",
    "make_prediction_scorer",
    "make_simulation_scorer",
    "nrmse",
    "r2",
    "simulation_scorer",
]

MultiOutput = Literal["uniform_average", "raw_values"]


def _pooled_pair(y_true: Any, y_pred: Any) -> tuple[np.ndarray, np.ndarray]:
    """Validate ``y_true``/``y_pred`` and stack all sequences sample-wise."""
    true, _ = as_sequence_list(y_true, "y_true")
    pred, _ = as_sequence_list(y_pred, "y_pred")
    check_paired(true, pred, "y_true", "y_pred")
    if true[0].shape[1] != pred[0].shape[1]:
        raise ValueError(
            f"y_true has {true[0].shape[1]} outputs but y_pred has "
            f"{pred[0].shape[1]}; they must have the same columns."
        )
    return np.concatenate(true), np.concatenate(pred)


def _aggregate(values: np.ndarray, multioutput: MultiOutput) -> float | np.ndarray:
    if multioutput == "raw_values":
        return values
    if multioutput == "uniform_average":
        return float(np.mean(values))
    raise ValueError(
        f"multioutput must be 'uniform_average' or 'raw_values'; got {multioutput!r}."
    )


# ----------------------------------------------------------------------------
# Error measures
# ----------------------------------------------------------------------------
#: The parameters every error measure takes, documented once.
_MEASURE_PARAMETERS = """\
Parameters
----------
y_true, y_pred : array-like or list of array-like
    Measured and model outputs, ``(n_samples,)`` or
    ``(n_samples, n_outputs)``, or lists of such sequences.
multioutput : {"uniform_average", "raw_values"}, default="uniform_average"
    Average over outputs, or return one value per output."""


@fill_doc(parameters=_MEASURE_PARAMETERS)
def nrmse(
    y_true: Any, y_pred: Any, *, multioutput: MultiOutput = "uniform_average"
) -> float | np.ndarray:
    """Root-mean-square error normalised by the standard deviation of ``y_true``.

    ``NRMSE = sqrt(mean((y - yhat)^2)) / std(y)`` per output column, with the
    population standard deviation (``ddof=0``). Predicting the mean of ``y``
    gives 1, a perfect model 0. For a list of sequences the means and the
    standard deviation run over all samples of all sequences.

    %(parameters)s

    Returns
    -------
    float or ndarray of shape (n_outputs,)
        NaN if ``y_pred`` contains NaN (a diverged free run) for that output.

    Examples
    --------
    >>> nrmse([1.0, 2.0, 3.0, 4.0], [1.0, 2.0, 3.0, 5.0])
    0.4472...
    >>> nrmse([[0.0, 1.0], [2.0, 3.0]], [[0.0, 1.0], [2.0, 3.0]])
    0.0
    """
    true, pred = _pooled_pair(y_true, y_pred)
    rmse = np.sqrt(np.mean((true - pred) ** 2, axis=0))
    with np.errstate(divide="ignore", invalid="ignore"):
        values = rmse / np.std(true, axis=0)
    return _aggregate(values, multioutput)


@fill_doc(parameters=_MEASURE_PARAMETERS)
def fit_percent(
    y_true: Any, y_pred: Any, *, multioutput: MultiOutput = "uniform_average"
) -> float | np.ndarray:
    """Fit in percent, ``100 (1 - ||y - yhat|| / ||y - mean(y)||)``.

    The usual system-identification fit (equal to ``100 (1 - NRMSE)``):
    100 is perfect, 0 is no better than the mean, negative is worse.

    %(parameters)s

    Returns
    -------
    float or ndarray of shape (n_outputs,)
        NaN propagates from ``y_pred``.

    Examples
    --------
    >>> fit_percent([1.0, 2.0, 3.0, 4.0], [1.0, 2.0, 3.0, 5.0])
    55.27...
    """
    values = 100.0 * (1.0 - nrmse(y_true, y_pred, multioutput="raw_values"))
    return _aggregate(values, multioutput)


@fill_doc(parameters=_MEASURE_PARAMETERS)
def r2(
    y_true: Any, y_pred: Any, *, multioutput: MultiOutput = "uniform_average"
) -> float | np.ndarray:
    """Coefficient of determination pooled over all samples of all sequences.

    ``1 - SSE / SST`` per output, as scikit-learn's ``r2_score`` but
    accepting lists of sequences and letting NaN propagate instead of raising.

    %(parameters)s

    Returns
    -------
    float or ndarray of shape (n_outputs,)
        1 for a perfect model, 0 for the mean; NaN propagates from ``y_pred``.

    Examples
    --------
    >>> r2([[1.0], [2.0], [3.0]], [[1.0], [2.0], [4.0]])
    0.5
    """
    values = 1.0 - nrmse(y_true, y_pred, multioutput="raw_values") ** 2
    return _aggregate(values, multioutput)


_METRICS: dict[str, tuple[Callable[..., Any], float]] = {
    # name -> (metric, sign that makes greater better)
    "nrmse": (nrmse, -1.0),
    "fit_percent": (fit_percent, 1.0),
    "r2": (r2, 1.0),
}


# ----------------------------------------------------------------------------
# Error statistics of the paper (eq. 19-20)
# ----------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class ErrorStatistics:
    """Averaged mean and standard deviation of errors over realisations.

    Attributes
    ----------
    mu : float
        ``mu_Ns`` of eq. 19, the average over realisations of each
        realisation's time-mean error.
    sigma : float
        ``sigma_Ns`` of eq. 20, the root of the average over realisations of
        each realisation's time-mean squared deviation from its own mean.
    means : ndarray of shape (n_realizations,)
        Time mean ``mu_j`` of every realisation.
    stds : ndarray of shape (n_realizations,)
        Time standard deviation of every realisation about ``mu_j``.
    n_samples : ndarray of shape (n_realizations,)
        Number of samples of every realisation.
    divergent : ndarray of bool, shape (n_realizations,)
        Realisations that contain NaN (diverged runs); their mean and std
        are NaN and so are ``mu`` and ``sigma``.
    dt : float
        Sampling step of the errors.
    method : str
        Quadrature rule of the time integrals.

    Examples
    --------
    >>> stats = error_statistics([[0.0, 2.0], [1.0, 1.0]])
    >>> stats.summary.tolist()
    [1.0, 0.7071067811865476, 2.0, 0.0]
    """

    mu: float
    sigma: float
    means: np.ndarray
    stds: np.ndarray
    n_samples: np.ndarray
    divergent: np.ndarray
    dt: float
    method: str

    @property
    def n_realizations(self) -> int:
        """Number of realisations ``N_s``."""
        return int(self.means.size)

    @property
    def n_divergent(self) -> int:
        """Number of realisations that contain NaN."""
        return int(self.divergent.sum())

    @property
    def summary(self) -> pd.Series:
        """``mu``, ``sigma``, ``N_s`` and the number of divergent realisations."""
        return pd.Series(
            {
                "mu": self.mu,
                "sigma": self.sigma,
                "n_realizations": self.n_realizations,
                "n_divergent": self.n_divergent,
            }
        )

    def to_frame(self) -> pd.DataFrame:
        """Return the per-realisation statistics.

        Returns
        -------
        pandas.DataFrame
            One row per realisation, columns ``mean, std, n_samples,
            duration, divergent``.
        """
        return pd.DataFrame(
            {
                "mean": self.means,
                "std": self.stds,
                "n_samples": self.n_samples,
                "duration": self.n_samples * self.dt,
                "divergent": self.divergent,
            },
            index=pd.RangeIndex(self.n_realizations, name="realization"),
        )


def _time_mean(x: np.ndarray, method: str) -> float:
    """``1/T integral x dt`` over one realisation by the chosen rule."""
    if method == "rectangle" or x.size == 1:
        return float(np.mean(x))
    # Trapezoid over the span (n-1) dt, normalised by that span; dt cancels.
    return float((np.sum(x) - 0.5 * (x[0] + x[-1])) / (x.size - 1))


def error_statistics(
    errors: Any,
    dt: float = 1.0,
    *,
    method: Literal["rectangle", "trapezoid"] = "rectangle",
) -> ErrorStatistics:
    """Averaged mean ``mu_Ns`` and standard deviation ``sigma_Ns`` (eq. 19-20).

    For ``N_s`` realisations ``eps_j(t)`` of the error (e.g. measured minus
    predicted displacement):

    * ``mu_j = 1/(N dt) integral eps_j(t) dt``, the time mean of realisation j;
    * ``mu_Ns = 1/N_s sum_j mu_j`` (eq. 19);
    * ``sigma_Ns = sqrt(1/N_s sum_j 1/(N dt) integral (eps_j(t) - mu_j)^2 dt)``
      (eq. 20). The paper writes the subtracted mean as ``mu_{N_j}``; it is
      read here as realisation j's own time mean ``mu_j``, so ``sigma_Ns`` is
      the root-mean-square of the per-realisation standard deviations.

    The integrals over the record of ``N`` samples are evaluated as sample
    means (rectangle rule, so ``1/(N dt) integral ... dt = mean``) or, with
    ``method="trapezoid"``, by the trapezoidal rule over ``(N - 1) dt``. In
    both cases ``dt`` cancels; it only sets the reported durations.

    Parameters
    ----------
    errors : array-like of shape (n_realizations, n_samples) or list of 1-D
        One row per realisation (as produced by
        ``HystereticOscillator.generate``), or a list of 1-D arrays of
        possibly different lengths.
    dt : float, default=1.0
        Sampling step, > 0.
    method : {"rectangle", "trapezoid"}, default="rectangle"
        Quadrature rule for the time integrals.

    Returns
    -------
    ErrorStatistics
        ``mu``, ``sigma``, per-realisation ``means``/``stds`` and
        ``to_frame()``. A realisation containing NaN (a diverged run) is
        flagged in ``divergent``; NaN then propagates into ``mu`` and
        ``sigma`` rather than being dropped.

    Examples
    --------
    >>> stats = error_statistics([[1.0, 3.0], [0.0, 0.0, 6.0]], dt=0.01)
    >>> float(stats.mu), round(float(stats.sigma), 4)
    (2.0, 2.1213)
    >>> stats.to_frame()["mean"].tolist()
    [2.0, 2.0]
    """
    if not (np.isscalar(dt) and np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be a positive finite number; got {dt!r}.")
    if method not in ("rectangle", "trapezoid"):
        raise ValueError(f"method must be 'rectangle' or 'trapezoid'; got {method!r}.")
    if isinstance(errors, (list, tuple)):
        rows = [np.asarray(e, dtype=float) for e in errors]
    else:
        arr = np.asarray(errors, dtype=float)
        if arr.ndim == 1:
            arr = arr[None, :]
        if arr.ndim != 2:
            raise ValueError(
                "errors must be 2-D (n_realizations, n_samples) or a list of "
                f"1-D arrays; got shape {arr.shape}."
            )
        rows = list(arr)
    if not rows:
        raise ValueError("errors holds no realisation; pass at least one.")
    for j, row in enumerate(rows):
        if row.ndim != 1 or row.size == 0:
            raise ValueError(
                f"errors[{j}] must be a non-empty 1-D array; got shape {row.shape}."
            )
    means = np.array([_time_mean(row, method) for row in rows])
    variances = np.array(
        [_time_mean((row - m) ** 2, method) for row, m in zip(rows, means, strict=True)]
    )
    return ErrorStatistics(
        mu=float(np.mean(means)),
        sigma=float(np.sqrt(np.mean(variances))),
        means=means,
        stds=np.sqrt(variances),
        n_samples=np.array([row.size for row in rows]),
        divergent=np.array([bool(np.isnan(row).any()) for row in rows]),
        dt=float(dt),
        method=method,
    )


# ----------------------------------------------------------------------------
# Scorers for GridSearchCV and friends
# ----------------------------------------------------------------------------
class _SequenceScorer:
    """Scorer ``(estimator, X, y) -> float`` on a simulation or a prediction.

    A plain callable in scikit-learn's scorer protocol; greater is better.
    """

    def __init__(
        self,
        metric: str,
        horizon: int | None,
        divergence_score: float,
    ) -> None:
        if metric not in _METRICS:
            raise ValueError(
                f"metric must be one of {sorted(_METRICS)}; got {metric!r}."
            )
        if horizon is not None and (
            isinstance(horizon, bool)
            or not isinstance(horizon, (int, np.integer))
            or horizon < 1
        ):
            raise ValueError(f"horizon must be an integer >= 1; got {horizon!r}.")
        self.metric = metric
        self.horizon = horizon
        self.divergence_score = float(divergence_score)

    def __call__(self, estimator: Any, X: Any, y: Any) -> float:
        if self.horizon is None:
            y_model = estimator.simulate(X)
        else:
            y_model = estimator.predict(X, y, horizon=self.horizon)
        func, sign = _METRICS[self.metric]
        y_list, _ = as_sequence_list(y, "y")
        model_list, _ = as_sequence_list(y_model, "model output")
        # A 1-D model output for a single-output y is the same thing.
        score = sign * func(y_list, model_list)
        return float(score) if np.isfinite(score) else self.divergence_score

    def __repr__(self) -> str:
        if self.horizon is None:
            return f"make_simulation_scorer(metric={self.metric!r})"
        return f"make_prediction_scorer(horizon={self.horizon}, metric={self.metric!r})"


def make_simulation_scorer(
    metric: Literal["nrmse", "r2", "fit_percent"] = "nrmse",
    *,
    divergence_score: float = -np.inf,
) -> Callable[[Any, Any, Any], float]:
    """Scorer of the free-run simulation ``estimator.simulate(X)`` against ``y``.

    Parameters
    ----------
    metric : {"nrmse", "r2", "fit_percent"}, default="nrmse"
        Error measure, pooled over all sequences of ``X``/``y``. Scores are
        "greater is better": the NRMSE scorer returns ``-nrmse``.
    divergence_score : float, default=-inf
        Returned when the score is not finite, i.e. when the simulation
        diverged (NaN samples). ``-inf`` ranks the candidate last in
        ``GridSearchCV`` (which then warns that some scores are non-finite);
        pass a large finite penalty such as ``-1e6`` to avoid that warning.

    Returns
    -------
    callable
        ``scorer(estimator, X, y) -> float``, usable as ``scoring=`` in
        ``GridSearchCV`` and ``cross_val_score``; ``X``/``y`` may be arrays or
        lists of sequences.

    Examples
    --------
    >>> import numpy as np
    >>> class Echo:
    ...     def simulate(self, X):
    ...         return X[:, 0]
    >>> X = np.arange(4.0)[:, None]
    >>> scorer = make_simulation_scorer()
    >>> scorer(Echo(), X, np.arange(4.0))
    -0.0
    """
    return _SequenceScorer(metric, None, divergence_score)


def make_prediction_scorer(
    horizon: int = 1,
    metric: Literal["nrmse", "r2", "fit_percent"] = "nrmse",
    *,
    divergence_score: float = -np.inf,
) -> Callable[[Any, Any, Any], float]:
    """Scorer of the ``horizon``-step-ahead prediction ``estimator.predict(X, y)``.

    Parameters
    ----------
    horizon : int, default=1
        Prediction horizon passed as ``estimator.predict(X, y, horizon=...)``.
    metric : {"nrmse", "r2", "fit_percent"}, default="nrmse"
        As in :func:`make_simulation_scorer`.
    divergence_score : float, default=-inf
        Returned when the score is not finite.

    Returns
    -------
    callable
        ``scorer(estimator, X, y) -> float``, greater is better.

    Examples
    --------
    >>> import numpy as np
    >>> class Persistence:
    ...     def predict(self, X, y, *, horizon=1):
    ...         return np.concatenate([np.zeros(horizon), y[:-horizon]])
    >>> y = np.arange(6.0)
    >>> make_prediction_scorer(horizon=1, metric="r2")(Persistence(), y[:, None], y)
    0.7142...
    """
    return _SequenceScorer(metric, horizon, divergence_score)


#: Negative NRMSE of the free-run simulation (``make_simulation_scorer()``).
simulation_scorer = make_simulation_scorer()
