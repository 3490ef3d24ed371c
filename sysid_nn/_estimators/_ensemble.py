"""Fits of one network on different held-out shares and seeds, combined.

A single fit to a short record depends on draws a user does not see: the
seed of its restarts and which samples validate it (on Cascaded Tanks the
default ISSM's median test error is 0.54 V holding out a fifth of the
record, 0.77 / 0.68 V holding out 15 / 25 %). :class:`EnsembleRegressor`
fits the network several times, each member on its own seed and held-out
share, and returns the pointwise median of the members' runs, which moves
much less with those draws than any one member
(``benchmarks/results_ensemble.md``).
"""

from __future__ import annotations

import numbers
import warnings

import numpy as np
from sklearn.base import BaseEstimator, RegressorMixin, clone
from sklearn.utils import check_random_state
from sklearn.utils._param_validation import HasMethods, Interval
from sklearn.utils.validation import check_is_fitted

from sysid_nn._estimators._base import _RecordsRegressorTags, free_run_r2
from sysid_nn._estimators._estimator_docs import document_estimator

__all__ = ["EnsembleRegressor"]


class EnsembleRegressor(_RecordsRegressorTags, RegressorMixin, BaseEstimator):
    """Fits of one network on several seeds and held-out shares, combined.

    Each member is a clone of ``estimator`` with its own ``random_state``
    and, where the validation records are held out of the training records
    (no ``X_val``), its own ``validation_fraction``. :meth:`simulate` and
    :meth:`predict` return the median over the members at every sample, so
    one member that went astray moves the result little. It costs
    ``n_members`` fits.

    Parameters
    ----------
    estimator : TDLRegressor or ISSMRegressor, default=None
        The network the members are clones of; None: ``ISSMRegressor()``.
        Its ``random_state`` and ``validation_fraction`` are replaced per
        member; its ``n_jobs`` runs each member's restarts in parallel.
    n_members : int, default=8
        Number of fits.
    validation_fractions : sequence of float, default=(0.15, 0.2, 0.25, 0.3)
        Held-out shares of the training records, taken in turn by the
        members (member ``k`` holds out ``validation_fractions[k % len]``;
        see ``validation_fraction`` of the estimator). Not used where
        ``X_val`` is given: the members then differ by their seeds only.
    random_state : int, RandomState instance or None, default=None
        Draws the members' seeds.

    Attributes
    ----------
    estimators_ : list of estimators
        The fitted members.
    member_random_states_ : list of int
        Each member's ``random_state``.
    member_validation_fractions_ : list of float or None
        Each member's held-out share; None where ``X_val`` was given.
    n_features_in_ : int
        Number of excitation channels.

    See Also
    --------
    TDLRegressor, ISSMRegressor : the networks fitted.

    Notes
    -----
    The median of the members' runs is not itself a network: the structural
    readouts (:func:`~sysid_nn.modal_parameters`, :func:`~sysid_nn.backbone`),
    the bands (``return_std``), saving and export apply to the members
    (``estimators_``). Over ``random_state`` 0-4, single default ISSM fits
    holding out 15-30 % of the record tested at 0.53-1.13 V on the Cascaded
    Tanks benchmark and 1.9-10.1 mm on EMPS, ensembles of eight at
    0.54-0.57 V and 2.2-2.8 mm (``benchmarks/results_ensemble.md``).

    Examples
    --------
    >>> import numpy as np
    >>> from sysid_nn import EnsembleRegressor, TDLRegressor
    >>> u = np.random.default_rng(0).standard_normal((300, 1))
    >>> y = np.convolve(u[:, 0], [0.0, 0.5, 0.25])[:300]
    >>> net = TDLRegressor(output_lags=1, input_lags=2, hidden_layer_sizes=(),
    ...                    n_init=1, max_iter=5)
    >>> ensemble = EnsembleRegressor(net, n_members=3, random_state=0).fit(u, y)
    >>> ensemble.member_validation_fractions_
    [0.15, 0.2, 0.25]
    >>> ensemble.simulate(u).shape
    (300,)
    """

    _parameter_constraints: dict = {
        "estimator": [None, HasMethods(["fit", "simulate", "predict"])],
        "n_members": [Interval(numbers.Integral, 1, None, closed="left")],
        "validation_fractions": ["array-like"],
        "random_state": ["random_state"],
    }

    def __init__(
        self,
        estimator=None,
        *,
        n_members: int = 8,
        validation_fractions=(0.15, 0.2, 0.25, 0.3),
        random_state=None,
    ):
        self.estimator = estimator
        self.n_members = n_members
        self.validation_fractions = validation_fractions
        self.random_state = random_state

    def fit(self, X, y, *, X_val=None, y_val=None):
        """Fit the members.

        Parameters
        ----------
        X : array-like of shape (n_samples, n_inputs) or list of such
            Excitation, one array per experiment.
        y : array-like of shape (n_samples,) or (n_samples, n_outputs), or list
            Measured response, one array per experiment.
        X_val, y_val : array-like or list, default=None
            Validation sequences, the same for every member.

        Returns
        -------
        self : object
            The fitted ensemble.
        """
        self._validate_params()
        fractions = [float(f) for f in np.ravel(self.validation_fractions)]
        if not fractions or not all(0.0 < f < 1.0 for f in fractions):
            raise ValueError(
                "validation_fractions must hold at least one share strictly "
                f"between 0 and 1; got {self.validation_fractions!r}."
            )
        if self.estimator is None:
            from sysid_nn._estimators._issm import ISSMRegressor

            base = ISSMRegressor()
        else:
            base = self.estimator
        rng = check_random_state(self.random_state)
        seeds = rng.randint(np.iinfo(np.int32).max, size=self.n_members)
        members, shares = [], []
        for k, seed in enumerate(seeds):
            share = None if X_val is not None else fractions[k % len(fractions)]
            params = {"random_state": int(seed)}
            if share is not None:
                params["validation_fraction"] = share
            member = clone(base).set_params(**params)
            members.append(member.fit(X, y, X_val=X_val, y_val=y_val))
            shares.append(share)
        self.estimators_ = members
        self.member_random_states_ = [int(s) for s in seeds]
        self.member_validation_fractions_ = shares
        self.n_features_in_ = members[0].n_features_in_
        return self

    def simulate(self, X, **kwargs):
        """Free-run simulation: the median of the members' at every sample.

        Parameters
        ----------
        X : array-like of shape (n_samples, n_inputs) or list of such
            Excitation.
        **kwargs
            Passed to every member's ``simulate`` (initial conditions,
            ``y_init``); not ``return_std``.

        Returns
        -------
        y_sim : ndarray or list of ndarray
            As the members' ``simulate``. A sample where some members'
            runs are not finite is the median of the others.
        """
        check_is_fitted(self, "estimators_")
        if kwargs.pop("return_std", False):
            raise ValueError(
                "return_std is not available for an ensemble: the bands are "
                "the members' (estimators_[k].simulate(X, return_std=True))."
            )
        return _median([m.simulate(X, **kwargs) for m in self.estimators_])

    def predict(self, X, y=None, *, horizon=1):
        """The median of the members' predictions at every sample.

        Parameters
        ----------
        X : array-like of shape (n_samples, n_inputs) or list of such
            Excitation.
        y : array-like or list, default=None
            Measured response: the ``horizon``-step-ahead prediction; without
            it, the free run (:meth:`simulate`), what :meth:`score` sees.
        horizon : int, default=1
            Prediction horizon in samples (only with ``y``).

        Returns
        -------
        y_pred : ndarray or list of ndarray
            As the members' ``predict``.
        """
        check_is_fitted(self, "estimators_")
        return _median([m.predict(X, y, horizon=horizon) for m in self.estimators_])

    @document_estimator
    def score(self, X, y, sample_weight=None):
        """Coefficient of determination R^2 of the free-run simulation.

        The median of the members' free runs from rest (:meth:`simulate`),
        compared with the measured response over all samples of all
        sequences.

        %(score)s
        """
        return free_run_r2(self.predict(X), y, sample_weight)


def _median(runs: list):
    """The pointwise median of the members' runs (arrays, or lists of
    arrays), leaving out the values that are not finite."""
    if isinstance(runs[0], list):
        return [_median(list(parts)) for parts in zip(*runs, strict=True)]
    stacked = np.stack([np.asarray(r, dtype=float) for r in runs])
    stacked[~np.isfinite(stacked)] = np.nan
    with warnings.catch_warnings():
        # A sample where every member's run diverged stays NaN.
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nanmedian(stacked, axis=0)
