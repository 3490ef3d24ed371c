"""Fits of one network on different held-out shares and seeds, combined.

A single fit to a short record depends on draws a user does not see: the
seed of its restarts and which samples validate it (on Cascaded Tanks the
default ISSM's median test error is 0.54 V holding out a fifth of the
record, 0.77 / 0.68 V holding out 15 / 25 %). :class:`EnsembleRegressor`
fits the network several times, each member on its own seed and held-out
share, and returns the pointwise median of the members' runs, which moves
much less with those draws than any one member
(``benchmarks/results_ensemble.md``). A member whose free run misses the
records it was fitted to far more than most members' do is left out of the
median: on EMPS, members holding out the last 25-30 % of the record can
miss that record, and the test record, three to seven times worse than the
rest.

The median is not itself a network. With ``distil=True`` the ensemble also
trains one network to reproduce it (``network_``), in the manner of model
compression (Bucilua, Caruana and Niculescu-Mizil, 2006): a clone of the
estimator fitted to the median's free runs over the training records and
over excitations like them, and validated on further such excitations.
"""

from __future__ import annotations

import numbers
import warnings

import numpy as np
from sklearn.base import BaseEstimator, RegressorMixin, clone
from sklearn.utils import check_random_state
from sklearn.utils._param_validation import HasMethods, Interval
from sklearn.utils.validation import check_is_fitted

from sysid_nn._engine._selection import like_record
from sysid_nn._estimators._base import _RecordsRegressorTags, free_run_r2
from sysid_nn._estimators._estimator_docs import document_estimator
from sysid_nn._exceptions import user_stacklevel
from sysid_nn._records._data import is_sequence_list

__all__ = ["EnsembleRegressor"]

#: Errors over the fitted records (scaled by the outputs' spread) below this
#: are rounding: members that fit the records exactly differ by less.
_ROUNDING_ERROR = 1e-9

#: Draws of excitations like the training records the distilled network is
#: trained on, besides the records themselves, and validated on
#: (``benchmarks/results_ensemble.md``, "One network distilled").
_DISTIL_TRAINING_DRAWS = 4
_DISTIL_VALIDATION_DRAWS = 2

#: Members that part this many times more under the draws than on the
#: records leave the median there undetermined: warned. Measured 0.7-2.4 on
#: Cascaded Tanks, 1.0-1.6 on a lightly damped chain, 19-30 on EMPS, whose
#: networks tested at 2.2-20.4 mm against the ensembles' 1.9-3.2.
_DISAGREEMENT_WARNING = 5.0

#: Networks fitted to the median, each on its own seed, until one fits the
#: records as a member must to enter the median.
_NETWORK_ATTEMPTS = 3

#: What ``distil=True`` fits; a fit without it drops them, so a network
#: fitted to an earlier fit's median never stands for this one.
_NETWORK_ATTRIBUTES = (
    "network_",
    "network_record_error_",
    "network_record_errors_",
    "network_median_error_",
    "draw_disagreement_",
)


class EnsembleRegressor(_RecordsRegressorTags, RegressorMixin, BaseEstimator):
    """Fits of one network on several seeds and held-out shares, combined.

    Each member is a clone of ``estimator`` with its own ``random_state``
    and, where the validation records are held out of the training records
    (no ``X_val``), its own ``validation_fraction``. :meth:`simulate` and
    :meth:`predict` return the median over the members at every sample, so
    one member that went astray moves the result little. Members whose free
    run from rest over the fitted records (the training records whole and
    ``X_val``, the same for every member) misses them by more than
    ``max_error_ratio`` times the lower quartile of the members' errors are
    left out of the median (``members_used_``). It costs ``n_members`` fits.

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
    max_error_ratio : float or None, default=3.0
        A member enters the median only where its free run's root-mean-square
        error over the fitted records (``member_record_errors_``) is at most
        this multiple of the members' lower quartile (of eight members, the
        second best: one member that fits the records exceptionally well
        does not set the level); None: every member enters.
    distil : bool, default=False
        Also fit one network to the median (``network_``): a clone of
        ``estimator`` trained on the median's free runs from rest over the
        training records, ``X_val`` and four excitations like every training
        record (its Fourier phases drawn anew, the amplitude spectrum, mean
        and range kept), and validated on two more such draws; fitted again
        on another seed (up to three times) where it misses the records
        more than ``max_error_ratio`` allows a member. It costs about as
        much as a fit to five times the training records. The structural
        readouts, the bands, saving and export apply to it.
    random_state : int, RandomState instance or None, default=None
        Draws the members' seeds, and the distilled network's seed and
        excitations.

    Attributes
    ----------
    estimators_ : list of estimators
        The fitted members.
    member_random_states_ : list of int
        Each member's ``random_state``.
    member_validation_fractions_ : list of float or None
        Each member's held-out share; None where ``X_val`` was given.
    member_record_errors_ : ndarray of shape (n_members,)
        Each member's error over the fitted records: the root-mean-square
        error of its free run from rest over the training records and
        ``X_val``, each output scaled by its standard deviation there;
        ``inf`` where the run is not finite.
    members_used_ : ndarray of bool of shape (n_members,)
        Which members enter the median (see ``max_error_ratio``).
    network_ : TDLRegressor or ISSMRegressor
        With ``distil=True``: the network fitted to the median.
    network_record_error_ : float
        With ``distil=True``: ``network_``'s error over the fitted records,
        measured as ``member_record_errors_``.
    network_record_errors_ : ndarray of shape (n_attempts,)
        With ``distil=True``: the error over the fitted records of every
        network fitted to the median, in turn on new seeds until one was
        within ``max_error_ratio`` times the members' lower quartile (at
        most three); ``network_`` is the one of the smallest (warned where
        none was within).
    network_median_error_ : float
        With ``distil=True``: how far ``network_``'s free runs are from the
        median's on the excitations it was validated on (root-mean-square
        difference, each output scaled by the median's standard deviation).
    draw_disagreement_ : float
        With ``distil=True``: how much more the members' free runs part from
        the median on those excitations than on the fitted records (the
        members' median distance there over here). Near 1 the draws are
        as determined as the records; far above it the median under them is
        one of several the records allow, and ``network_`` copies it
        (warned above 5).
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
    (``estimators_``), or, with ``distil=True``, to the network fitted to
    the median (``network_``). Over ``random_state`` 0-4, single default ISSM fits
    holding out 15-30 % of the record tested at 0.53-1.13 V on the Cascaded
    Tanks benchmark and 1.9-10.1 mm on EMPS, ensembles of eight at
    0.54-0.57 V and 1.9-3.2 mm (``benchmarks/results_ensemble.md``).

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
    >>> distilled = EnsembleRegressor(net, n_members=3, distil=True,
    ...                               random_state=0).fit(u, y)
    >>> type(distilled.network_).__name__
    'TDLRegressor'
    """

    _parameter_constraints: dict = {
        "estimator": [None, HasMethods(["fit", "simulate", "predict"])],
        "n_members": [Interval(numbers.Integral, 1, None, closed="left")],
        "validation_fractions": ["array-like"],
        "max_error_ratio": [None, Interval(numbers.Real, 1, None, closed="left")],
        "distil": ["boolean"],
        "random_state": ["random_state"],
    }

    def __init__(
        self,
        estimator=None,
        *,
        n_members: int = 8,
        validation_fractions=(0.15, 0.2, 0.25, 0.3),
        max_error_ratio: float | None = 3.0,
        distil: bool = False,
        random_state=None,
    ):
        self.estimator = estimator
        self.n_members = n_members
        self.validation_fractions = validation_fractions
        self.max_error_ratio = max_error_ratio
        self.distil = distil
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
        # Every member judged on the same data: the records whole (each
        # member's held-out part included) and X_val.
        records = [(X, y)] if X_val is None else [(X, y), (X_val, y_val)]
        errors = np.array([_record_error(m, records) for m in members])
        self.member_record_errors_ = errors
        self.members_used_ = _used(errors, self.max_error_ratio)
        for name in _NETWORK_ATTRIBUTES:
            self.__dict__.pop(name, None)
        if self.distil:
            # Drawn after the members' seeds: distilling changes no member.
            attempts = rng.randint(np.iinfo(np.int32).max, size=_NETWORK_ATTEMPTS)
            self._fit_network(base, X, X_val, [int(s) for s in attempts], records)
        return self

    def _fit_network(self, base, X, X_val, seeds: list, records: list) -> None:
        """Fit ``network_`` to the median's free runs (see ``distil``): a
        network on each of ``seeds`` in turn until one fits ``records`` as
        a member must to enter the median; the best of them kept."""
        given, given_y, train, train_y, val, val_y = self._distillation_records(
            X, X_val, seeds[0]
        )
        level = np.quantile(self.member_record_errors_, 0.25, method="lower")
        networks, errors = [], []
        for seed in seeds:
            network = clone(base).set_params(random_state=seed)
            network.fit(given + train, given_y + train_y, X_val=val, y_val=val_y)
            networks.append(network)
            errors.append(_record_error(network, records))
            if _within(errors[-1], level, self.max_error_ratio):
                break
        self.network_record_errors_ = np.array(errors)
        best = int(np.argmin(self.network_record_errors_))
        self.network_ = networks[best]
        self.network_record_error_ = errors[best]
        self.network_median_error_ = _run_error(self.network_, val, val_y)
        if not _within(errors[best], level, self.max_error_ratio):
            warnings.warn(
                f"The network fitted to the ensemble's median (network_) fits "
                f"the records {errors[best] / max(level, _ROUNDING_ERROR):.1f} "
                f"times worse than the members' lower quartile after "
                f"{len(errors)} attempts (network_record_errors_), more than "
                "max_error_ratio allows a member. Use the ensemble's median, "
                "or a member.",
                UserWarning,
                stacklevel=user_stacklevel(),
            )

    def _distillation_records(self, X, X_val, seed: int) -> tuple:
        """The excitations ``network_`` is trained and validated on, with
        the median's free runs over them: ``(given, given_y, train,
        train_y, val, val_y)``; ``given`` are the fitted records. Sets
        ``draw_disagreement_`` from the members' runs the medians are made
        of."""
        records = _as_records(X)
        rng = np.random.default_rng(seed)
        draws = [
            [like_record(x, rng) for x in records]
            for _ in range(_DISTIL_TRAINING_DRAWS + _DISTIL_VALIDATION_DRAWS)
        ]
        used = self._used_members()
        given = records + ([] if X_val is None else _as_records(X_val))
        # A draw under which the median diverges is left out; the records
        # themselves cannot be.
        kept, given_y, given_runs = _finite_medians(used, given)
        train, train_y, _ = _finite_medians(
            used, [x for d in draws[:_DISTIL_TRAINING_DRAWS] for x in d]
        )
        val, val_y, val_runs = _finite_medians(
            used, [x for d in draws[_DISTIL_TRAINING_DRAWS:] for x in d]
        )
        if not val or len(kept) < len(given):
            raise ValueError(
                "distil=True needs the median's free runs to be finite over "
                "the fitted records and excitations like them; every member "
                "diverged there (member_record_errors_). Fit with "
                "distil=False, or give longer records or another estimator."
            )
        self.draw_disagreement_ = _distance(val_runs, val_y) / max(
            _distance(given_runs, given_y), _ROUNDING_ERROR
        )
        if self.draw_disagreement_ > _DISAGREEMENT_WARNING:
            warnings.warn(
                "The members of the ensemble part "
                f"{self.draw_disagreement_:.1f} times more under excitations "
                "like the training records than on the records themselves "
                "(draw_disagreement_): the records do not determine the "
                "median there, and network_, fitted to it, may test unlike "
                "the ensemble. Use the ensemble's median, or a member.",
                UserWarning,
                stacklevel=user_stacklevel(),
            )
        return given, given_y, train, train_y, val, val_y

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
        return _median([m.simulate(X, **kwargs) for m in self._used_members()])

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
        runs = [m.predict(X, y, horizon=horizon) for m in self._used_members()]
        return _median(runs)

    def _used_members(self) -> list:
        # Files saved before members_used_ existed: every member.
        used = getattr(self, "members_used_", None)
        if used is None:
            return list(self.estimators_)
        return [m for m, u in zip(self.estimators_, used, strict=True) if u]

    @document_estimator
    def score(self, X, y, sample_weight=None):
        """Coefficient of determination R^2 of the free-run simulation.

        The median of the members' free runs from rest (:meth:`simulate`),
        compared with the measured response over all samples of all
        sequences.

        %(score)s
        """
        return free_run_r2(self.predict(X), y, sample_weight)


def one_network(model):
    """The network that stands for ``model``'s structure: ``model`` itself,
    or an ensemble's ``network_`` (the median is no network, so it has no
    modes of its own).

    Raises
    ------
    ValueError
        For an ensemble fitted without ``distil=True``, saying how to get
        one network.

    Examples
    --------
    >>> import numpy as np
    >>> from sysid_nn import EnsembleRegressor, TDLRegressor
    >>> rng = np.random.default_rng(0)
    >>> u = rng.standard_normal((300, 1))
    >>> y = np.convolve(u[:, 0], [0.0, 0.5, 0.25])[:300]
    >>> net = TDLRegressor(hidden_layer_sizes=(), n_init=1, max_iter=5)
    >>> ensemble = EnsembleRegressor(net, n_members=2, random_state=0).fit(u, y)
    >>> one_network(ensemble)
    Traceback (most recent call last):
    ...
    ValueError: the model is the median of 2 networks, ...
    >>> distilled = ensemble.set_params(distil=True).fit(u, y)
    >>> one_network(distilled) is distilled.network_
    True
    """
    if not isinstance(model, EnsembleRegressor):
        return model
    network = getattr(model, "network_", None)
    if network is None:
        raise ValueError(
            f"the model is the median of {len(model.estimators_)} networks, "
            "which is not one network and has no modes of its own. Fit it with "
            "distil=True (`sysid-nn fit --members N --distil`) for one network "
            "fitted to the median (network_), or read a member's "
            "(estimators_[k])."
        )
    return network


def _as_records(X) -> list:
    """``X`` as a list of float arrays, one per record."""
    records = X if is_sequence_list(X) else [X]
    return [np.asarray(x, dtype=float) for x in records]


def _finite_medians(members: list, records: list) -> tuple[list, list, list]:
    """The records over which the members' median free run is finite, those
    medians (the ensemble's :meth:`~EnsembleRegressor.simulate`), and the
    members' runs over each of them."""
    runs = [[m.simulate(x) for m in members] for x in records]
    medians = [_median(r) for r in runs]
    kept = [k for k, r in enumerate(medians) if np.all(np.isfinite(r))]
    return (
        [records[k] for k in kept],
        [medians[k] for k in kept],
        [runs[k] for k in kept],
    )


def _record_error(member, records) -> float:
    """Root-mean-square error of ``member``'s free runs from rest over
    ``records`` (``(X, y)`` pairs), each output scaled by its standard
    deviation over them; ``inf`` where a run is not finite."""
    runs, measured = [], []
    for X, y in records:
        with np.errstate(all="ignore"):
            run = member.simulate(X)
        pairs = zip(run, y, strict=True) if is_sequence_list(y) else [(run, y)]
        for r, m in pairs:
            runs.append(r)
            measured.append(m)
    return _run_error_of(runs, measured)


def _run_error(network, records: list, targets: list) -> float:
    """:func:`_record_error` of ``network`` against ``targets`` over the
    excitations ``records``."""
    with np.errstate(all="ignore"):
        runs = [network.simulate(x) for x in records]
    return _run_error_of(runs, targets)


def _distance(runs: list, targets: list) -> float:
    """The members' median :func:`_run_error_of` against ``targets``;
    ``runs[i][k]``: member ``k``'s run over record ``i``."""
    errors = [_run_error_of([r[k] for r in runs], targets) for k in range(len(runs[0]))]
    return float(np.median(errors))


def _run_error_of(runs: list, targets: list) -> float:
    """Root-mean-square difference of ``runs`` from ``targets`` (lists of
    arrays), each output scaled by the targets' standard deviation; ``inf``
    where a run is not finite."""
    errors, measured = [], []
    for r, m in zip(runs, targets, strict=True):
        m = np.asarray(m, dtype=float)
        m = m.reshape(m.shape[0], -1)
        errors.append(np.asarray(r, dtype=float).reshape(m.shape) - m)
        measured.append(m)
    error, measured = np.concatenate(errors), np.concatenate(measured)
    if not np.all(np.isfinite(error)):
        return np.inf
    scale = measured.std(axis=0)
    scale[scale == 0] = 1.0
    return float(np.sqrt(np.mean((error / scale) ** 2)))


def _used(errors: np.ndarray, ratio: float | None) -> np.ndarray:
    """The members within ``ratio`` times the lower quartile of ``errors``
    (a member's own error, at least :data:`_ROUNDING_ERROR`); all where
    ``ratio`` is None or that quartile is not finite.

    Examples
    --------
    >>> _used(np.array([0.5, 1.0, 2.5, 3.5, 9.0, np.inf]), 3.0)
    array([ True,  True,  True, False, False, False])
    >>> _used(np.array([0.1, 1.0, 1.2, 2.0, 2.5, 2.7, 3.0, 3.5]), 3.0)
    array([ True,  True,  True,  True,  True,  True,  True, False])
    >>> _used(np.array([np.inf, np.inf]), 3.0)
    array([ True,  True])
    >>> _used(np.array([1e-16, 5e-16]), 3.0)  # exact fits, up to rounding
    array([ True,  True])
    """
    level = np.quantile(errors, 0.25, method="lower")
    return np.array([_within(e, level, ratio) for e in errors], dtype=bool)


def _within(error: float, level: float, ratio: float | None) -> bool:
    """Whether ``error`` is within ``ratio`` times ``level`` (at least
    :data:`_ROUNDING_ERROR`); always where ``ratio`` is None or ``level``
    is not finite."""
    if ratio is None or not np.isfinite(level):
        return True
    return bool(error <= ratio * max(level, _ROUNDING_ERROR))


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
