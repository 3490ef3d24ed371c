"""Confidence and prediction bands of identified models.

Both estimators return the standard deviation of every predicted or
simulated sample with ``return_std=True`` (scikit-learn's
``GaussianProcessRegressor`` convention): ``y_sim, y_std =
model.simulate(X, return_std=True)``. This module turns such a pair into an
interval at a chosen level, measures how often measurements fall inside it,
and estimates the spread of an ensemble of refitted models as a check of the
delta method behind ``return_std``.

The delta method (see the user guide, :ref:`uncertainty`) assumes that the
model structure can represent the system, that the residuals of the final
training objective are stationary (their autocorrelation is accounted for by
a Bartlett long-run covariance), that the fitted weights minimise the
training loss, and that the outputs are close to linear in the weights over
the spread of the weights. :func:`ensemble_std` assumes none of the last
two: it refits the model and looks at the spread of the refitted models.
"""

from __future__ import annotations

import numbers

import numpy as np
from joblib import Parallel, delayed
from scipy.stats import norm
from sklearn.base import clone
from sklearn.utils import check_random_state

from sysid_nn._records._data import is_sequence_list

__all__ = ["ensemble_std", "interval_coverage", "normal_interval"]


def _as_list(values):
    """``(list_of_arrays, given_as_list)``, by the estimators' list rule."""
    if is_sequence_list(values):
        return [np.asarray(v, dtype=np.float64) for v in values], True
    return [np.asarray(values, dtype=np.float64)], False


def _check_level(level) -> float:
    if not isinstance(level, numbers.Real) or not 0.0 < level < 1.0:
        raise ValueError(
            f"level must be a probability strictly between 0 and 1 (e.g. 0.95 "
            f"for a 95 % interval); got {level!r}."
        )
    return float(level)


def normal_interval(mean, std, level=0.95):
    """Return the lower and upper bounds of a two-sided Gaussian interval.

    ``mean -/+ z * std`` with ``z`` the ``(1 + level) / 2`` quantile of the
    standard normal distribution (1.96 for 95 %).

    Parameters
    ----------
    mean : array-like or list of array-like
        Predicted or simulated values, as returned by ``predict`` or
        ``simulate``.
    std : array-like or list of array-like
        Their standard deviations, as returned with ``return_std=True``;
        same shapes as ``mean`` (or broadcastable to them, e.g. one value
        per output).
    level : float, default=0.95
        Probability that the interval holds the true value, if the errors
        are Gaussian.

    Returns
    -------
    lower, upper : ndarray or list of ndarray
        Bounds of the interval, shaped like ``mean`` (a list for a list).

    Examples
    --------
    >>> import numpy as np
    >>> from sysid_nn.uncertainty import normal_interval
    >>> lower, upper = normal_interval(np.zeros(3), np.ones(3), level=0.95)
    >>> np.round(upper, 2)
    array([1.96, 1.96, 1.96])
    """
    z = norm.ppf(0.5 + 0.5 * _check_level(level))
    means, as_list = _as_list(mean)
    stds, std_list = _as_list(std)
    if std_list != as_list or len(stds) != len(means):
        raise ValueError(
            "mean and std must both be arrays or both be lists of the same "
            "length, as returned by predict or simulate with return_std=True."
        )
    lower, upper = [], []
    for i, (m, s) in enumerate(zip(means, stds, strict=True)):
        try:
            same = np.broadcast_shapes(m.shape, s.shape) == m.shape
        except ValueError:
            same = False
        if not same:
            where = f"[{i}]" if as_list else ""
            raise ValueError(
                f"std{where} must have the shape of mean{where} (or broadcast "
                f"to it); got {s.shape} and {m.shape}."
            )
        lower.append(m - z * s)
        upper.append(m + z * s)
    return (lower, upper) if as_list else (lower[0], upper[0])


def interval_coverage(y_true, lower, upper):
    """Return the share of measured samples that lie inside an interval.

    Samples where a bound is NaN (after a diverged run) count as outside.

    Parameters
    ----------
    y_true : array-like or list of array-like
        Measured values.
    lower, upper : array-like or list of array-like
        Bounds of the interval, shaped like ``y_true`` (for example from
        :func:`normal_interval`); ``lower <= upper`` wherever both are
        numbers.

    Returns
    -------
    coverage : float
        Share of all samples (of all sequences and outputs) with ``lower <=
        y_true <= upper``; a calibrated 95 % interval covers about 0.95.

    Raises
    ------
    ValueError
        Shapes that differ, or ``lower > upper`` somewhere (a mean and a
        standard deviation passed as the bounds).

    Examples
    --------
    >>> import numpy as np
    >>> from sysid_nn.uncertainty import interval_coverage
    >>> y = np.array([0.0, 1.0, 2.0, 3.0])
    >>> float(interval_coverage(y, y - 0.5, np.array([0.5, 1.5, 2.5, 2.5])))
    0.75
    """
    ys, _ = _as_list(y_true)
    lows, _ = _as_list(lower)
    ups, _ = _as_list(upper)
    if not len(ys) == len(lows) == len(ups):
        raise ValueError(
            "y_true, lower and upper must hold the same number of sequences; "
            f"got {len(ys)}, {len(lows)} and {len(ups)}."
        )
    inside = n = 0
    for y, lo, up in zip(ys, lows, ups, strict=True):
        y = y.reshape(lo.shape) if y.size == lo.size else y
        if not y.shape == lo.shape == up.shape:
            raise ValueError(
                f"y_true, lower and upper must have the same shapes; got "
                f"{y.shape}, {lo.shape} and {up.shape}."
            )
        crossed = np.flatnonzero(lo > up)  # NaN bounds compare False: allowed
        if crossed.size:
            raise ValueError(
                f"lower exceeds upper at {crossed.size} of {lo.size} samples (the "
                f"first at flat index {crossed[0]}); pass the interval's bounds, "
                "e.g. interval_coverage(y, *normal_interval(mean, std, 0.95)), "
                "not a mean and a standard deviation."
            )
        inside += int(np.sum((lo <= y) & (y <= up)))
        n += y.size
    return inside / n


def _fit_member(estimator, X, y, seed):
    member = clone(estimator)
    member.set_params(random_state=int(seed), n_init=1)
    return member.fit(X, y)


def ensemble_std(
    estimator,
    X,
    y,
    X_new,
    *,
    method="bootstrap",
    n_members=8,
    tol=0.5,
    n_jobs=None,
    random_state=None,
):
    """Mean and spread of the free runs of an ensemble of refitted models.

    A check of the delta method behind ``return_std=True`` where the model is
    far from linear in its weights: ``n_members`` copies of ``estimator``
    (each with one restart, ``n_init=1``) are fitted and simulated on
    ``X_new``, in parallel with joblib.

    * ``method="bootstrap"``: each member is fitted to experiments drawn with
      replacement from the training records (a bootstrap by experiment).
      Assumes the experiments are independent draws from one population and
      that there are enough of them (five or more) for the resampling to
      vary the fit; the spread covers the weights, not the measurement noise.
    * ``method="restarts"``: each member is fitted to all records from a
      different random start; members whose final training loss exceeds the
      best by more than the share ``tol`` are discarded (local minima, not
      uncertainty). Measures only how far the optimisation lands from
      itself: an under-estimate of the weight uncertainty, which a linear
      model (a single minimum) shows as zero spread.

    Parameters
    ----------
    estimator : TDLRegressor or ISSMRegressor
        The model to refit (unfitted or fitted; its parameters are used).
    X : list of array-like
        Training excitations, one array per experiment (one array is allowed
        with ``method="restarts"``).
    y : list of array-like
        Training responses.
    X_new : array-like or list of array-like
        Excitation of the records to simulate.
    method : {"bootstrap", "restarts"}, default="bootstrap"
        How the members differ.
    n_members : int, default=8
        Number of members fitted.
    tol : float, default=0.5
        With ``method="restarts"``, members with a training loss above
        ``(1 + tol)`` times the best are left out.
    n_jobs : int, default=None
        Parallel fits (joblib semantics).
    random_state : int, RandomState instance or None, default=None
        Seeds the resampling and the members' starts.

    Returns
    -------
    mean : ndarray or list of ndarray
        Mean of the members' free runs on ``X_new``, shaped like
        ``simulate(X_new)``.
    std : ndarray or list of ndarray
        Their standard deviation (``ddof=1``); compare with
        ``simulate(X_new, return_std=True, interval="confidence")``.
        Diverged members are left out sample by sample.

    Examples
    --------
    >>> import numpy as np
    >>> from scipy.signal import lfilter
    >>> from sysid_nn import TDLRegressor
    >>> from sysid_nn.uncertainty import ensemble_std
    >>> rng = np.random.default_rng(0)
    >>> X = [rng.standard_normal((200, 1)) for _ in range(5)]
    >>> y = [lfilter([0, 0.5], [1, -0.5], u[:, 0]) + 0.05 * rng.standard_normal(200)
    ...      for u in X]
    >>> model = TDLRegressor(output_lags=1, input_lags=1, hidden_layer_sizes=(),
    ...                      early_stopping=False)
    >>> mean, std = ensemble_std(model, X, y, X[0], n_members=4, random_state=0)
    >>> mean.shape, bool(np.all(std > 0))
    ((200,), True)
    """
    if method not in ("bootstrap", "restarts"):
        raise ValueError(
            f"method must be 'bootstrap' (resample experiments) or 'restarts' "
            f"(random starts); got {method!r}."
        )
    if not isinstance(n_members, numbers.Integral) or n_members < 2:
        raise ValueError(
            f"n_members must be an integer >= 2 (a spread needs two members); "
            f"got {n_members!r}."
        )
    if not isinstance(tol, numbers.Real) or tol < 0:
        raise ValueError(f"tol must be a non-negative share; got {tol!r}.")
    rng = check_random_state(random_state)
    seeds = rng.randint(np.iinfo(np.int32).max, size=n_members)
    if method == "bootstrap":
        if not isinstance(X, (list, tuple)) or len(X) < 2:
            raise ValueError(
                "method='bootstrap' resamples experiments: pass X and y as lists "
                "of at least two (better five or more) records, or use "
                "method='restarts'."
            )
        draws = [rng.randint(len(X), size=len(X)) for _ in range(n_members)]
        jobs = [
            ([X[i] for i in d], [y[i] for i in d], seed)
            for d, seed in zip(draws, seeds, strict=True)
        ]
    else:
        jobs = [(X, y, seed) for seed in seeds]
    members = Parallel(n_jobs=n_jobs)(
        delayed(_fit_member)(estimator, Xm, ym, seed) for Xm, ym, seed in jobs
    )
    if method == "restarts":
        losses = np.array([m.loss_ for m in members])
        best = np.min(losses)
        members = [
            m
            for m, loss in zip(members, losses, strict=True)
            if loss <= (1.0 + tol) * best
        ]
    runs = [member.simulate(X_new) for member in members]
    as_list = isinstance(runs[0], list)
    runs = runs if as_list else [[r] for r in runs]
    means, stds = [], []
    for s in range(len(runs[0])):
        stack = np.stack([r[s] for r in runs])
        if len(stack) < 2:
            means.append(stack[0])
            stds.append(np.zeros_like(stack[0]))
            continue
        means.append(np.nanmean(stack, axis=0))
        stds.append(np.nanstd(stack, axis=0, ddof=1))
    return (means, stds) if as_list else (means[0], stds[0])
