"""The recurrent-network estimators' common class: what a fit and a call do.

:class:`_RecurrentRegressorBase` is the estimator: parameters, the order of
a fit (check and split the records, standardise, diagnose, prepare the
structure, train, keep the result) and the calls on a fitted model
(``predict``, ``simulate``, ``score``). The parts live elsewhere, each by
name:

* the data layer, :mod:`sysid_nn._records._data`: sequence checks, scaling, stacking;
* the record diagnosis, :mod:`sysid_nn._engine._diagnosis`: the estimates the
  ``"auto"`` settings decide by, and the noise warning;
* the schedule, :mod:`sysid_nn._engine._schedule`: the stages, their data, halving;
* the training driver, :mod:`sysid_nn._engine._training`: restarts, the choice
  among them, the fallback, the histories;
* the structure: the subclass (:mod:`~sysid_nn._estimators._tdl`,
  :mod:`~sysid_nn._estimators._issm`)
  supplies its kernels, starting weights and initial conditions through the
  hooks below, and its weight layout through :mod:`sysid_nn._engine._layout`;
* the state estimator, :mod:`sysid_nn._engine._state_estimation`: initial
  conditions fitted to a measured window (``y_init``).

A fit is atomic: when it fails or is interrupted, the estimator's
attributes are restored to what they were before it.
"""

from __future__ import annotations

import dataclasses
import numbers
import warnings
from abc import ABCMeta, abstractmethod
from itertools import pairwise

import numpy as np
from sklearn.base import BaseEstimator, RegressorMixin
from sklearn.exceptions import ConvergenceWarning
from sklearn.utils._param_validation import Interval, StrOptions
from sklearn.utils.validation import check_is_fitted

from sysid_nn._analysis import _uncertainty
from sysid_nn._engine._diagnosis import (
    RecordDiagnosis,
    diagnose_records,
    warn_white_misfit,
)
from sysid_nn._engine._layout import MLPLayout
from sysid_nn._engine._order import select_order
from sysid_nn._engine._refit import refit
from sysid_nn._engine._schedule import training_stages
from sysid_nn._engine._solvers import _Objective
from sysid_nn._engine._state_estimation import (
    _RUN_IN,
    estimator_rest_check,
    fit_initial_condition,
    origin_conditions,
    run_in_origin,
)
from sysid_nn._engine._training import (
    _REFINE_BUDGET,
    _single_threaded_blas,
    fit_stages,
    train,
)
from sysid_nn._estimators._estimator_docs import document_estimator
from sysid_nn._exceptions import (
    DivergenceWarning,
    check_version,
    user_stacklevel,
    version_stamp,
)
from sysid_nn._records._data import (
    _FREE_RUN,
    _Data,
    _mean_scale,
    _SequenceIO,
    is_sequence_list,
)
from sysid_nn._records._record_checks import trim_padding

__all__ = ["DivergenceWarning"]

#: A free run whose standardised output exceeds this multiple of the largest
#: standardised training output is declared divergent.
_DIVERGENCE_FACTOR = 100.0
#: Evaluations per unknown the initial-state fit of ``y_init`` may take, ten
#: times the solver's default of 100: the TDL's six output lags on the
#: Wiener-Hammerstein test window (nearly flat along some combinations of
#: the lag values) converged after 1593 (0.5 s) and stopped at the default 600.
_USER_START_EVALUATIONS = 1000


def after_run_in(diverged: np.ndarray, leads: np.ndarray) -> np.ndarray:
    """Divergence indices counted from the user's first sample.

    ``diverged`` counts from the start of each run, ``leads`` is the run-in
    before the user's samples (see ``_from_rest``); a divergence within the
    run-in is reported at the first sample, and -1 (none) stays -1.

    Examples
    --------
    >>> after_run_in(np.array([-1, 8200, 100]), np.array([8192, 8192, 8192]))
    array([-1,  8,  0])
    """
    return np.where(diverged >= 0, np.maximum(diverged - leads, 0), -1)


class _RecordsRegressorTags:
    """The scikit-learn tags of a regressor of measured records (not public):
    a target is required and may have several outputs."""

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.target_tags.required = True
        tags.target_tags.multi_output = True
        # Rows are time steps of one experiment, not independent samples: a
        # free-run score on shuffled tabular data means nothing.
        tags.regressor_tags.poor_score = True
        return tags


class _RecurrentRegressorBase(
    _RecordsRegressorTags, RegressorMixin, _SequenceIO, BaseEstimator, metaclass=ABCMeta
):
    """Base class of the recurrent-network regressors (not public).

    :class:`~sklearn.base.RegressorMixin` sits here, below this class in the
    method order: its ``score`` of the raw predictions gives way to the
    free-run :meth:`score`, and its regressor tags are set before ours.
    """

    _parameter_constraints: dict = {
        "hidden_layer_sizes": [
            "array-like",
            Interval(numbers.Integral, 1, None, closed="left"),
        ],
        "activation": [StrOptions({"logistic", "tanh"})],
        "input_delay": [Interval(numbers.Integral, 0, None, closed="left")],
        "focus": [StrOptions({"prediction", "simulation"})],
        "shooting_segments": ["array-like"],
        "solver": [StrOptions({"lm", "lbfgs", "slsqp"})],
        "alpha": [Interval(numbers.Real, 0, None, closed="left"), StrOptions({"auto"})],
        "max_iter": [Interval(numbers.Integral, 1, None, closed="left")],
        "tol": [Interval(numbers.Real, 0, None, closed="left")],
        "n_init": [Interval(numbers.Integral, 1, None, closed="left")],
        "early_stopping": ["boolean"],
        "validation_fraction": [Interval(numbers.Real, 0, 1, closed="neither")],
        "n_iter_no_change": [Interval(numbers.Integral, 1, None, closed="left")],
        "refit": ["boolean"],
        "random_state": ["random_state"],
        "verbose": ["verbose"],
        "n_jobs": [None, numbers.Integral],
    }

    def _store_parameters(self, arguments: dict) -> None:
        """Store every constructor argument, untouched, under its name.

        ``arguments`` is the ``locals()`` of the estimator's ``__init__``,
        whose explicit signature scikit-learn reads the parameters from.
        """
        for name in self._get_param_names():
            setattr(self, name, arguments[name])

    # ------------------------------------------------------- structure hooks
    @abstractmethod
    def _history_length(self) -> int: ...

    @abstractmethod
    def _prepare_structure(self, data: _Data, val: _Data | None = None) -> None:
        """Fix data-dependent structure and the linear starting point.

        ``val`` are the validation records, when there are any.
        """

    @abstractmethod
    def _initial_params(self, rng: np.random.RandomState) -> np.ndarray: ...

    @abstractmethod
    def _run(self, w, data: _Data, seg_len: int, want_jac, keep_state: bool = True):
        """Return ``(Yhat, jac, diverged, state_for_gradient)``.

        ``jac`` is None for ``want_jac=False``, the full Jacobian of the
        modelled outputs for ``True`` and the normal equations ``(J'J, J'(Yhat
        - Y))`` for ``"normal"``. Without ``keep_state`` the state holds no
        per-row arrays and cannot serve :meth:`_gradient`.
        """

    @abstractmethod
    def _gradient(self, w, data: _Data, seg_len: int, state) -> np.ndarray: ...

    @abstractmethod
    def _run_horizon(self, w, data: _Data, horizon: int) -> np.ndarray: ...

    @abstractmethod
    def _history(self, n_seq: int, initial) -> tuple[np.ndarray, np.ndarray]:
        """Standardised history rows ``(Y_hist, U_hist)`` for every sequence."""

    def _layout(self) -> MLPLayout:
        """Where each weight sits in ``coefs_`` (see ``sysid_nn._engine._layout``)."""
        return MLPLayout(self._sizes_, self._bypass())

    def _penalty_mask(self) -> np.ndarray:
        """The weights ``alpha`` penalises."""
        return self._layout().penalty_mask()

    def __setstate__(self, state):
        # joblib may restore arrays as read-only memory maps; numba compiles a
        # separate specialisation for read-only arrays, so keep plain copies.
        for key, value in state.items():
            if isinstance(value, np.ndarray) and not value.flags.writeable:
                state[key] = np.array(value)
        if "coefs_" in state:
            # Fitted: stamped with the version that fitted it (none before
            # the stamp existed).
            check_version(state.get("_sysid_nn_version"), f"This {type(self).__name__}")
        super().__setstate__(state)

    # --------------------------------------------------------- validation
    def _lag_reach(self) -> int:
        """Past samples read to model one sample, the starting fit's included.

        A structure whose linear start looks further back than its own
        recurrence overrides this.
        """
        return self._history_length()

    def _min_samples(self) -> int:
        """Shortest sequence ``fit`` accepts: the lag reach and one to model.

        Every fitted equation needs its whole reach inside the record; a
        shorter record leaves the starting fit without data.
        """
        return self._lag_reach() + 1

    # ------------------------------------------------------------ fitting
    def fit(self, X, y, *, X_val=None, y_val=None):
        """Fit the network to one or several measured sequences.

        Parameters
        ----------
        X : array-like of shape (n_samples, n_inputs) or list of such
            Excitation. A list holds one array per experiment; recurrences
            restart at the start of each.
        y : array-like of shape (n_samples,) or (n_samples, n_outputs), or list
            Measured response, one array per experiment.
        X_val, y_val : array-like or list, default=None
            Validation sequences for selecting the weights (early stopping).
            Without them and with ``early_stopping=True``, whole sequences
            (or the tail of a single sequence) are held out.

        Returns
        -------
        self : object
            The fitted estimator.
        """
        saved = dict(self.__dict__)
        # The last fit's attributes go (a refit must not keep any of them);
        # attributes set from outside a fit stay.
        for name in saved.get("_fit_attributes", ()):
            del self.__dict__[name]
        kept = set(self.__dict__)
        try:
            self._fit(X, y, X_val=X_val, y_val=y_val)
        except BaseException:
            # Atomic: a failed or interrupted fit leaves the estimator as it
            # was, fitted or not.
            self.__dict__.clear()
            self.__dict__.update(saved)
            raise
        new = [name for name in self.__dict__ if name not in kept]
        self._fit_attributes = (*new, "_fit_attributes")
        return self

    def _fit(self, X, y, *, X_val=None, y_val=None):
        """The fit proper, on an unfitted copy (see :meth:`fit`)."""
        self._validate_params()
        self._validate_structure_params()
        Xs, ys, _, y_1d = self._validate_Xy(X, y, reset=True, y_required=True)
        self.n_outputs_ = ys[0].shape[1]
        self._y_1d = y_1d
        self._validate_outputs()
        if (X_val is None) != (y_val is None):
            raise ValueError(
                "X_val and y_val must be given together; got only "
                f"{'X_val' if X_val is not None else 'y_val'}."
            )
        min_len = self._min_samples()
        Xs, ys = trim_padding(Xs, ys, min_len, "X")
        lead = 0
        if X_val is not None:
            Xv, yv, _, _ = self._validate_Xy(X_val, y_val, reset=False, y_required=True)
            Xv, yv = trim_padding(Xv, yv, min_len, "X_val")
            _mean_scale(np.concatenate(Xv), "X_val")
            _mean_scale(np.concatenate(yv), "y_val")
        elif self.early_stopping:
            Xs, ys, Xv, yv, lead = self._split_validation(Xs, ys, min_len)
        else:
            Xv = yv = None
        self._check_lengths(Xs, min_len)
        if Xv is not None:
            self._check_lengths(Xv, min_len, "X_val")

        Xc, yc = np.concatenate(Xs), np.concatenate(ys)
        self._x_mean, self._x_scale = _mean_scale(Xc, "X")
        self._y_mean, self._y_scale = _mean_scale(yc, "y")
        train_data, val = self._stack_fit_records(Xs, ys, Xv, yv, lead > 0)
        with _single_threaded_blas():
            self._choose_order(train_data, val)
        if self._history_length() != train_data.h:
            # The chosen lags reach further back than the provisional ones.
            train_data, val = self._stack_fit_records(Xs, ys, Xv, yv, lead > 0)
        self._bound = _DIVERGENCE_FACTOR * max(1.0, np.abs(train_data.Y).max())
        self._diagnose(train_data)
        # The initial fit and the selection use BLAS too; see _single_threaded_blas.
        with _single_threaded_blas():
            self._prepare_structure(train_data, val)
            result = train(self, train_data, val)
            val = result.validation  # as judged (burn-in, fitted start)
            self._keep_training(result, val)
            tail = lead > 0
            fitted = self._refit(train_data, Xs, ys, Xv, yv, tail, val) or train_data
            self._after_fit(fitted, val)
            _uncertainty.fit_covariance(self, fitted)
            modelled = fitted.Y[fitted.modelled]
            self._y_range = (modelled.min(axis=0), modelled.max(axis=0))
            self._find_rest(fitted)
        self._sysid_nn_version = version_stamp()
        chosen = result.run
        skipped = [i for i, stage in enumerate(chosen.history) if stage.skipped]
        if skipped:
            # Counted from 1, as the progress lines count them.
            counted = ", ".join(str(i + 1) for i in skipped)
            warnings.warn(
                f"{type(self).__name__} skipped training stage"
                f"{'s' if len(skipped) > 1 else ''} {counted} of "
                f"{len(chosen.history)} of the chosen restart: the free run "
                "diverged from the weights the stage started at, so its loss was "
                "not finite. The weights come from the stages before "
                f"(skipped_stages_ = {skipped}, counted from 0).",
                ConvergenceWarning,
                stacklevel=user_stacklevel(),
            )
        if not chosen.converged:
            budget = f"max_iter={self.max_iter}"
            if result.chosen is not None and result.chosen == result.refined:
                budget = f"{_REFINE_BUDGET} times max_iter={self.max_iter}"
            warnings.warn(
                f"{type(self).__name__} stopped after {budget} iterations of "
                "its last training stage before reaching tol="
                f"{self.tol}. Increase max_iter or loosen tol.",
                ConvergenceWarning,
                stacklevel=user_stacklevel(),
            )
        return self

    def _refit(
        self, train: _Data, Xs, ys, Xv, yv, tail: bool, val: _Data | None
    ) -> _Data | None:
        """Continue the chosen weights on the validation records too
        (``refit``; see :mod:`sysid_nn._engine._refit`).

        ``train``: the training records ``Xs``, ``ys`` stacked; ``val``: the
        validation records ``Xv``, ``yv`` as judged; ``tail``: ``Xv`` is the
        held-out tail of the last training record. Sets ``refit_steps_``,
        ``refit_losses_``, ``refit_advantage_`` and ``refit_training_ratio_``;
        returns the records the weights were last trained on (the training
        and validation records), or None where there was no refit.
        """
        self.refit_steps_ = self.refit_losses_ = self.refit_advantage_ = None
        self.refit_training_ratio_ = None
        if not self.refit or val is None:
            return None
        # Half of every validation record joins the inner training records.
        half = (len(Xv[0]) if tail else min(len(x) for x in Xv)) // 2
        if half < self._min_samples():
            self.refit_steps_ = 0  # too little held out to halve
            return None
        if tail:  # the held-out tail continues the last training record
            X_last = np.concatenate([Xs[-1], Xv[0]])
            y_last = np.concatenate([ys[-1], yv[0]])
            lead = len(Xs[-1]) + half
            inner = self._stack([*Xs[:-1], X_last[:lead]], [*ys[:-1], y_last[:lead]])
            judged = dataclasses.replace(self._stack([X_last], [y_last]), lead=lead)
            whole = self._stack([*Xs[:-1], X_last], [*ys[:-1], y_last])
        else:
            inner = self._stack(
                [*Xs, *(x[:half] for x in Xv)], [*ys, *(y[:half] for y in yv)]
            )
            judged = dataclasses.replace(
                self._stack(Xv, yv),
                lead=half,
                burn=val.burn,
                start_window=val.start_window,
            )
            whole = self._stack([*Xs, *Xv], [*ys, *yv])
        done = refit(self, self.coefs_, train, inner, judged, whole)
        self.coefs_ = done.w
        self.refit_steps_ = done.steps
        self.refit_losses_ = done.losses
        self.refit_advantage_ = done.advantage
        self.refit_training_ratio_ = done.training_ratio
        if done.steps:
            self.loss_ = done.loss
        return whole if done.steps else None

    def _stack_fit_records(self, Xs, ys, Xv, yv, tail: bool = False):
        """The training and validation records stacked.

        ``tail``: the validation record is the tail of the last training
        record (see ``_split_validation``).
        """
        train = self._stack(Xs, ys)
        val = self._stack(Xv, yv) if Xv is not None else None
        if tail:
            val = dataclasses.replace(val, tail=True)
        return train, val

    def _choose_order(self, train: _Data, val: _Data | None) -> None:
        """The order of an ``"auto"`` structure, read from the records.

        One rule for both networks (:func:`sysid_nn._engine._order.select_order`),
        scored on ``val`` (``train`` when there is none); its evidence is
        kept in ``order_selection_``.
        """
        self.__dict__.pop("order_selection_", None)  # from an earlier fit
        if not self._order_from_data():
            return
        self.order_selection_ = select_order(
            self,
            train,
            train if val is None else val,
            self._weights_at_order,
            between=self._orders_between,
        )
        self._set_order(int(self.order_selection_.n_states))

    #: Whether the orders between the short-records limit and the
    #: evidence's are candidates (see ``_order.short_record_cap``).
    _orders_between = False

    def _order_from_data(self) -> bool:
        """Whether the structure's order is ``"auto"``."""
        return False

    @abstractmethod
    def _set_order(self, n_states: int) -> None:
        """Fix the structure for an order of ``n_states`` states."""

    @abstractmethod
    def _weights_at_order(self, n_states: int) -> int:
        """Weights of the network at an order of ``n_states`` states."""

    def _keep_training(self, result, val: _Data | None) -> None:
        """The fitted attributes of a :class:`~sysid_nn._engine._training.Training`."""
        chosen = result.run
        with_validation = val is not None
        self.validation_burn_in_ = None if val is None else val.burn
        self.validation_start_window_ = None if val is None else val.start_window
        self.validation_continues_record_ = None if val is None else val.lead > 0
        self.coefs_ = result.w
        self.fallback_ = result.fallback
        self.n_iter_ = chosen.n_iter
        self.loss_ = chosen.loss
        self.best_validation_score_ = -chosen.val_loss if with_validation else None
        self.restart_scores_ = np.array([-r.criterion for r in result.runs])
        self.restart_losses_ = np.array([r.loss for r in result.runs])
        self.restart_bounded_ = np.array(result.bounded, dtype=bool)
        self.restart_checks_ = np.asarray(result.checks, dtype=bool)
        self.restart_excursions_ = np.asarray(result.excursions, dtype=float)
        self.restart_self_oscillating_ = np.array(result.self_oscillating, dtype=bool)
        self.n_restarts_ = len(result.runs)
        self.restart_batches_ = result.batches
        self.best_restart_ = result.chosen
        self.refined_restart_ = result.refined
        self.refinement_advantage_ = result.refinement_advantage
        self.closed_form_restarts_ = list(result.closed_form)
        self.selected_ = result.selected
        lin = None if result.linear is None else result.linear.run
        # The linear model in the network's own weights, for the
        # non-linearity test (sysid_nn.nonlinearity_test).
        self._linear_coefs = None if lin is None else result.linear.w.copy()
        self.linear_score_ = (
            None
            if lin is None
            else (-lin.criterion if np.isfinite(lin.criterion) else -np.inf)
        )
        self.linear_loss_ = None if lin is None else lin.loss
        self.best_stage_ = chosen.best_stage
        self.training_history_ = [
            [dataclasses.replace(stage) for stage in run.history] for run in result.runs
        ]
        self.loss_curve_ = [x for stage in chosen.history for x in stage.loss]
        self.validation_scores_ = (
            [-x for stage in chosen.history for x in stage.validation]
            if with_validation
            else None
        )
        self.skipped_stages_ = [
            i for i, stage in enumerate(chosen.history) if stage.skipped
        ]
        self.fit_time_ = result.fit_time

    # ----------------------------------------------------- readable weights
    @property
    def layer_coefs_(self) -> list[np.ndarray]:
        """Weight matrix of each layer, shape ``(n_in, n_out)``.

        As :class:`~sklearn.neural_network.MLPRegressor`'s ``coefs_``: layer
        ``i`` maps its input ``a`` to ``a @ layer_coefs_[i] +
        layer_intercepts_[i]``, in standardised units (the network's inputs
        are described under ``coefs_``). Copies of parts of ``coefs_``.
        """
        check_is_fitted(self, "coefs_")
        return [W.T.copy() for W, _ in self._layout().matrices(self.coefs_)]

    @property
    def layer_intercepts_(self) -> list[np.ndarray]:
        """Bias vector of each layer, shape ``(n_out,)`` (see ``layer_coefs_``)."""
        check_is_fitted(self, "coefs_")
        return [b.copy() for _, b in self._layout().matrices(self.coefs_)]

    @property
    def linear_coef_(self) -> np.ndarray | None:
        """The linear part beside the network, shape ``(n_outputs, n_in)``.

        The TDL's bypass or the ISSM's ``[A B K]`` acting on the network's
        input (its output is added to the network's); None without one
        (``hidden_layer_sizes=()`` is linear throughout: its only layer is
        the linear model).
        """
        check_is_fitted(self, "coefs_")
        W = self._layout().bypass_matrix(self.coefs_)
        return None if W is None else W.copy()

    def _hidden_layers(self) -> tuple:
        """``hidden_layer_sizes`` as a tuple; an int is one layer (MLPRegressor)."""
        sizes = self.hidden_layer_sizes
        return tuple(sizes) if np.iterable(sizes) else (sizes,)

    def _diagnose(self, train: _Data) -> RecordDiagnosis:
        """Estimate, decide: what the records say, and the settings it sets.

        The estimates (:func:`sysid_nn._engine._diagnosis.diagnose_records`) set
        ``shooting_`` and ``alpha_`` here and the ISSM's start in its
        ``_prepare_structure``; the warning comes from
        :func:`sysid_nn._engine._diagnosis.warn_white_misfit`.
        """
        diagnosis = diagnose_records(type(self).__name__, train, self.input_delay)
        self._diagnosis = diagnosis
        self._band_edge = diagnosis.band_edge
        self.shooting_ = self._choose_shooting(diagnosis.free_states_help)
        auto = self.alpha == "auto"
        self.alpha_ = self._auto_alpha() if auto else float(self.alpha)
        scale = self._y_scale
        self.output_noise_std_ = np.sqrt(diagnosis.noise_variance) * scale
        self.one_step_misfit_share_ = diagnosis.misfit_share
        self.one_step_misfit_correlation_ = diagnosis.misfit_correlation
        self.one_step_misfit_explained_ = diagnosis.misfit_explained
        self.samples_per_period_ = diagnosis.samples_per_period
        self.band_edge_ = diagnosis.band_edge
        self.white_misfit_ = bool(diagnosis.white_misfit.any())
        if self._noise_sensitive() and self.shooting_ != "free":
            warn_white_misfit(self, diagnosis, self._noise_advice())
        return diagnosis

    def _noise_advice(self) -> str:
        """What to change about the fit when noise swamps the records."""
        return ""

    def _noise_sensitive(self) -> bool:
        """Whether noise on the outputs' second difference costs this model."""
        return True

    def _independent_segments(self) -> bool:
        """Whether each shooting segment restarts from measured data alone.

        Then a stage's loss is a sum over segments, and the stages before
        the last may see a subset of them (:func:`_schedule.stage_data
        <sysid_nn._engine._schedule.stage_data>`).
        """
        return True

    def _validate_structure_params(self) -> None:
        if not all(
            isinstance(n, numbers.Integral) and not isinstance(n, bool) and n > 0
            for n in self._hidden_layers()
        ):
            raise ValueError(
                "hidden_layer_sizes must be a positive integer (one hidden layer) "
                "or a tuple of positive integers (or () for the linear model); bools "
                f"are not sizes. Got {self.hidden_layer_sizes!r}."
            )
        segs = tuple(self.shooting_segments)
        if not all(isinstance(n, numbers.Integral) and n > 1 for n in segs):
            raise ValueError(
                "shooting_segments must be a tuple of integers > 1 (segment "
                f"lengths in samples, or () for none); got {self.shooting_segments!r}."
            )

    def _validate_outputs(self) -> None:
        """Hook for output-count checks (ISSM: ``n_states >= n_outputs``)."""

    def _after_fit(self, train: _Data, val: _Data | None) -> None:
        """Hook run once the weights are chosen."""

    def _split_validation(self, Xs, ys, min_len):
        """Hold out whole sequences, or the tail block of a single one.

        Returns ``(X_train, y_train, X_val, y_val, lead)``, ``lead`` the
        samples of the record before a tail block (0 for whole sequences).
        A tail block is a validation record of its own, judged as one
        passed as ``X_val``: from rest, after the burn-in or from the
        fitted start that :func:`~sysid_nn._engine._selection.linear_candidate`
        sets. (Judged as the continuation of a free run over the training
        part, it could not see a network that never forgets its initial
        state: on Silverbox, ``random_state=1`` chose one that tested at
        7.4 mV from rest and 0.24 mV from a fitted start, where the tail
        from rest chose one of 0.32 mV.) The exception is a tail too short
        for the response to its wrong start to die out, of a record that
        starts at rest, or, for a TDL, of any record: there the
        continuation is a run from rest, or from the record's first
        measured outputs (see ``linear_candidate``).
        """
        if len(Xs) >= 3:
            n_val = max(1, round(self.validation_fraction * len(Xs)))
            return Xs[:-n_val], ys[:-n_val], Xs[-n_val:], ys[-n_val:], 0
        n = len(Xs[-1])
        n_val = round(self.validation_fraction * n)
        if n_val < min_len or n - n_val < min_len:
            # Too short to split: no validation selection.
            return Xs, ys, None, None, 0
        head = [*Xs[:-1], Xs[-1][:-n_val]]
        yhead = [*ys[:-1], ys[-1][:-n_val]]
        return head, yhead, [Xs[-1][-n_val:]], [ys[-1][-n_val:]], n - n_val

    def _n_restarts(self) -> int:
        """Number of training runs from different random starts."""
        return self.n_init

    def _final_segment(self) -> int:
        """Segment length of the loss that selection and ``loss_`` judge by."""
        return 1 if self.focus == "prediction" else _FREE_RUN

    def _stages(self) -> list[tuple[int, int]]:
        """``(segment length, iterations)`` of each training stage."""
        return training_stages(
            self.focus, self.shooting_, self.shooting_segments, self.max_iter
        )

    def _stage_objective(self, data: _Data, seg: int, mask, n_res: int, alpha):
        """The objective of a stage on segments of ``seg`` samples of ``data``."""
        return _Objective(self, data, seg, mask, n_res, alpha=alpha)

    def _choose_shooting(self, free_states_help: bool) -> str:
        """How shooting segments start: ``"measured"`` or ``"free"`` (fitted).

        Networks without free-state shooting always restart from the
        measured outputs.
        """
        return "measured"

    def _auto_alpha(self) -> float:
        """The weight penalty of ``alpha="auto"``."""
        return 0.0

    def _estimates_start(self) -> bool:
        """Whether a run's initial state holds more than measured outputs."""
        return False

    def _fitted_start(self, w: np.ndarray, data: _Data, window: int) -> _Data:
        """``data`` with initial states fitted to each sequence's first
        ``window`` modelled rows (see ``_estimates_start``): here the
        measured history rows already are the whole initial condition."""
        return data

    def _closed_form_fits(self, *, for_network: bool) -> list[tuple[int, np.ndarray]]:
        """Weights of a model without hidden layers fitted in closed form:
        candidates of the linear model as they are, untrained (see
        :func:`~sysid_nn._engine._selection.linear_candidate`), each with
        the restart whose linear start it belongs to. ``for_network``: as
        a network's linear candidate, not the estimator's own fit."""
        return []

    def _linear_start_restarts(self) -> list[int]:
        """One restart index per distinct linear start (see ``_fit_one``)."""
        return [0]

    def _fit_one(self, train: _Data, val: _Data | None, restart, stop: int):
        """One restart through the stages before ``stop`` (see
        :func:`sysid_nn._engine._training.fit_stages`); a structure may override it
        to give a restart its own start."""
        # The linear algebra here is small (tens to hundreds of weights):
        # threaded BLAS only spins, and restarts already run in parallel.
        with _single_threaded_blas():
            return self._fit_stages(train, val, restart, stop)

    def _fit_stages(self, train: _Data, val: _Data | None, restart, stop: int):
        """See :func:`sysid_nn._engine._training.fit_stages`."""
        return fit_stages(self, train, val, restart, stop)

    # ----------------------------------------------------------- predicting
    def _simulate(
        self,
        X,
        initial,
        initial_name: str,
        initial_inputs=None,
        return_std=False,
        interval="prediction",
        y_init=None,
    ):
        check_is_fitted(self, "coefs_")
        Xs, _, as_list, _ = self._validate_Xy(X, reset=False, y_required=False)
        self._check_lengths(Xs, 1)
        initial = self._check_initial(initial, len(Xs), as_list, initial_name)
        past = self._check_initial_inputs(initial_inputs, len(Xs), as_list)
        if y_init is not None:
            if initial is not None:
                raise ValueError(
                    f"Give either {initial_name} or y_init, not both: y_init "
                    f"estimates the {initial_name} from measured outputs."
                )
            initial = self._estimate_initial(Xs, y_init, as_list, past)
        at_rest = initial is None and past is None
        Xs, leads, initial, past = self._from_rest(Xs, at_rest, initial, past)
        data = self._stack(Xs, None, initial, past)
        Yhat, J, diverged = self._free_run(data, initial, return_std)
        self._warn_divergence(after_run_in(diverged, leads), as_list)
        y_sim = self._unstack(Yhat, data, True, self._y_1d)
        y_sim = [y[k:] for y, k in zip(y_sim, leads, strict=True)]
        if not return_std:
            return y_sim if as_list else y_sim[0]
        std = _uncertainty.output_std(self, Yhat, J, data, True, self._y_1d, interval)
        std = [s[k:] for s, k in zip(std, leads, strict=True)]
        return (y_sim, std) if as_list else (y_sim[0], std[0])

    def _from_rest(self, Xs: list, at_rest: bool, initial=None, past=None) -> tuple:
        """The sequences preceded by the run-in that brings the model to rest.

        Only when ``at_rest`` (no initial conditions given) and the model
        starts at its rest or on its cycle (see :meth:`_run_in`). The run-in
        is run with each sequence, not replaced by its end state, so that
        the weights' uncertainty reaches the rest too. Returns the
        sequences, the run-in length of each and the initial conditions and
        excitation before the first sample (``initial``, ``past``): those
        given, or where the run-in starts.
        """
        start, origin = self._run_in() if at_rest else ("zero", None)
        lead = _RUN_IN if start != "zero" else 0
        Xs = [np.concatenate([np.zeros((lead, Xi.shape[1])), Xi]) for Xi in Xs]
        if origin is not None:  # a run-in from the training record's end
            initial, past = origin_conditions(origin, len(Xs))
        return Xs, np.full(len(Xs), lead, dtype=np.int64), initial, past

    def _find_rest(self, fitted: _Data) -> None:
        """``rest_check_`` and ``rest_output_`` of the weights, and where
        their run-in starts: see
        :func:`~sysid_nn._engine._state_estimation.run_in_origin`."""
        self._run_in_from, *found = run_in_origin(self, fitted)
        self.rest_check_ = estimator_rest_check(self, tuple(found))
        self.rest_output_ = self.rest_check_.output
        self._rest_weights = self.coefs_.copy()  # whose rest that is

    def _run_in(self) -> tuple[str, tuple | None]:
        """Where a free run without initial conditions starts (``"rest"``,
        ``"cycle"`` or ``"zero"``) and the initial conditions ``(initial,
        initial_inputs)`` (user units) its run-in starts from, None for zero:
        ``rest_check_`` for the fitted weights, found again for weights
        changed since."""
        if not hasattr(self, "_y_range"):
            return "zero", None  # fitted before the range was kept: no rest
        fitted = np.array_equal(self.coefs_, self._rest_weights)
        check = self.rest_check_ if fitted else estimator_rest_check(self)
        # ("training" only where the run-in from there found a rest or a
        # cycle; files saved before have no run_in_from.)
        led = check.get("run_in_from") == "training"
        return check.start, (self._run_in_from if led else None)

    @abstractmethod
    def _conditions_at(self, Yhat, state, data: _Data, s: int) -> np.ndarray:
        """The initial condition (``initial``, user units) that continues the
        run ``(Yhat, state)`` of :meth:`_run` after the end of sequence ``s``."""

    def _free_run(self, data: _Data, initial, want_jac: bool = False, w=None):
        """Free run of the fitted model (or of the weights ``w``) from the
        initial conditions in ``data``.

        Returns ``(Yhat, J or None, diverged)``.
        """
        w = self.coefs_ if w is None else w
        Yhat, J, diverged, _ = self._run(w, data, _FREE_RUN, want_jac, keep_state=False)
        return Yhat, J, diverged

    @abstractmethod
    def _initial_units(self) -> tuple[np.ndarray, np.ndarray]:
        """``(offset, scale)`` shaped like an initial condition (for ``v``).

        The initial-condition fit works on ``v = (initial - offset) / scale``,
        standardised units.
        """

    @abstractmethod
    def _initial_guess(self, y0: np.ndarray) -> np.ndarray:
        """Initial condition at rest at the measured output ``y0`` (user units)."""

    def _estimate_initial(self, Xs, y_init, as_list: bool, past) -> list:
        """Initial conditions fitted to the measured start of each sequence.

        For each sequence, the initial condition (``initial_outputs`` or
        ``initial_state``) whose free run best fits ``y_init`` over the
        first ``len(y_init)`` samples, by least squares (see
        :func:`~sysid_nn._engine._state_estimation.fit_initial_condition`).
        """
        windows = self._per_sequence(y_init, len(Xs), as_list, "y_init")
        offset, scale = self._initial_units()
        out = []
        for i, (Xi, yw) in enumerate(zip(Xs, windows, strict=True)):
            where = f"y_init[{i}]" if as_list else "y_init"
            yw = np.asarray(yw, dtype=np.float64)
            if yw.size == 0:
                raise ValueError(
                    f"{where} is empty: the initial state is fitted to the "
                    "measured outputs over the first samples of X. Pass at least "
                    "one sample, or leave y_init out to start from rest."
                )
            yw = yw.reshape(len(yw), -1) if yw.ndim else yw.reshape(1, 1)
            bad = ~np.isfinite(yw)
            if bad.any():
                kind = "NaN" if np.isnan(yw[bad]).any() else "inf"
                raise ValueError(
                    f"{where} contains {kind} (first at sample "
                    f"{int(np.argwhere(bad)[0][0])}): the initial state is fitted "
                    "to every value of the window. Shorten the window to end "
                    "before it, or interpolate the missing values."
                )
            if (
                yw.shape[1] != self.n_outputs_
                or not 1 <= len(yw) <= len(Xi)
                or not np.all(np.isfinite(yw))
            ):
                raise ValueError(
                    f"{where} must hold the measured outputs over the first "
                    f"samples of X: shape (n_window, {self.n_outputs_}) with 1 <= "
                    f"n_window <= {len(Xi)}, finite values; got shape "
                    f"{np.shape(windows[i])}."
                )
            Xw = Xi[: len(yw)]
            pw = None if past is None else [past[i]]
            target = (yw - self._y_mean) / self._y_scale

            def residuals(v, Xw=Xw, pw=pw, target=target):
                init = [offset + scale * v.reshape(offset.shape)]
                data = self._stack([Xw], None, init, pw)
                Yhat, _, _ = self._free_run(data, init)
                return (Yhat[data.h :] - target).ravel()

            v0 = ((self._initial_guess(yw[0]) - offset) / scale).ravel()
            v, success, message = fit_initial_condition(
                residuals, v0, max_nfev=_USER_START_EVALUATIONS * len(v0)
            )
            if not success:
                warnings.warn(
                    f"The initial state fitted to {where} did not converge "
                    f"({message}); the simulation starts from the best state "
                    "found. Check the window for outliers, or lengthen it.",
                    ConvergenceWarning,
                    stacklevel=user_stacklevel(),
                )
            out.append(offset + scale * v.reshape(offset.shape))
        return out

    @document_estimator
    def predict(self, X, y=None, *, horizon=1, return_std=False, interval="prediction"):
        """Predict the response, from measured outputs when they are given.

        Parameters
        ----------
        %(excitation)s
        y : array-like of shape (n_samples,) or (n_samples, n_outputs), or list, \
default=None
            Measured response. With it, the ``horizon``-step-ahead prediction
            is returned: every value uses measurements up to ``t - horizon``
            (``horizon=1`` is the one-step predictor of the paper, section
            4.3). Without it nothing is measured and the free-run simulation
            from rest is returned (section 4.4; see :meth:`simulate`); this
            is what :meth:`score` and scikit-learn's model selection see.
        horizon : int, default=1
            Prediction horizon in samples (only used with ``y``).
        return_std : bool, default=False
            Also return the standard deviation of every sample (delta
            method, see :ref:`uncertainty`); available for the free run and
            for ``horizon=1``.
        interval : {"prediction", "confidence"}, default="prediction"
            What the standard deviation is of (only used with
            ``return_std``): ``"prediction"``, a new measurement (weight
            uncertainty plus the residual noise variance of the training
            records, ``one_step_noise_variance_`` with ``y``,
            ``noise_variance_`` without); ``"confidence"``, the model output
            (weight uncertainty only).

        Returns
        -------
        y_pred : ndarray or list of ndarray
            Same shape as ``y`` (or as the training targets); a list for a
            list.
        y_std : ndarray or list of ndarray
            Standard deviation of each value of ``y_pred``, same shape; only
            with ``return_std=True``.
        """
        if (
            isinstance(horizon, bool)
            or not isinstance(horizon, numbers.Integral)
            or horizon < 1
        ):
            raise ValueError(f"horizon must be a positive integer; got {horizon!r}.")
        if y is None:
            return self._simulate(
                X, None, "initial", return_std=return_std, interval=interval
            )
        check_is_fitted(self, "coefs_")
        if return_std and horizon != 1:
            raise ValueError(
                f"return_std=True is available for horizon=1 and for the free run "
                f"(y=None); got horizon={horizon}."
            )
        Xs, ys, as_list, y_1d = self._validate_Xy(X, y, reset=False, y_required=True)
        self._check_lengths(Xs, 1)
        data = self._stack(Xs, ys)
        Yhat = self._run_horizon(self.coefs_, data, int(horizon))
        self._mark_out_of_range(Yhat, data, as_list, f"{horizon}-step prediction")
        y_pred = self._unstack(Yhat, data, as_list, y_1d)
        if not return_std:
            return y_pred
        J = self._run(self.coefs_, data, 1, True, keep_state=False)[1]
        std = _uncertainty.output_std(
            self, Yhat, J, data, as_list, y_1d, interval, one_step=True
        )
        return y_pred, std

    @document_estimator
    def score(self, X, y, sample_weight=None):
        """Coefficient of determination R^2 of the free-run simulation.

        The model is simulated from the excitation alone (from rest, as
        :meth:`simulate` does) and compared with the measured response over
        all samples of all sequences.

        %(score)s
        """
        return free_run_r2(self.predict(X), y, sample_weight)

    @abstractmethod
    def _initial_layout(self) -> tuple[tuple[int, ...], str, str]:
        """Shape of one sequence's initial conditions, its count and meaning.

        The two strings complete the error message of :meth:`_check_initial`.
        """

    def _warn_divergence(
        self, diverged: np.ndarray, as_list: bool, what: str = "free run"
    ) -> None:
        for s, t in enumerate(diverged):
            if t >= 0:
                where = f"sequence {s}, " if as_list else ""
                warnings.warn(
                    f"The {what} of {type(self).__name__} diverged at {where}sample "
                    f"{t}: its output left {_DIVERGENCE_FACTOR:g} times the training "
                    "range. Values from there on are NaN.",
                    DivergenceWarning,
                    stacklevel=user_stacklevel(),
                )

    def _mark_out_of_range(self, Yhat, data: _Data, as_list: bool, what: str):
        """NaN from the first value beyond the divergence bound, with a warning.

        The predictors with measured outputs have no guard inside their
        kernels; nothing out of range may reach the user silently.
        """
        diverged = np.full(len(data.starts) - 1, -1, dtype=np.int64)
        for s, (a, b) in enumerate(pairwise(data.starts)):
            block = Yhat[a + data.h : b]
            bad = np.flatnonzero(~np.all(np.abs(block) <= self._bound, axis=1))
            if bad.size:
                diverged[s] = bad[0]
                block[bad[0] :] = np.nan
        self._warn_divergence(diverged, as_list, what)


def free_run_r2(y_pred, y, sample_weight=None) -> float:
    """R^2 of a free run ``y_pred`` against the measured ``y`` over all
    samples of all sequences; ``-inf`` where the run is not finite."""
    from sklearn.metrics import r2_score

    y_true = np.concatenate(y) if is_sequence_list(y) else y
    y_pred = np.concatenate(y_pred) if isinstance(y_pred, list) else y_pred
    if not np.all(np.isfinite(y_pred)):
        return -np.inf
    return r2_score(y_true, y_pred, sample_weight=sample_weight)
