"""Shared machinery of the recurrent-network estimators.

:class:`_RecurrentRegressorBase` holds everything the TDL and ISSM networks
have in common: input validation for one sequence or a list of sequences,
internal standardisation, the staged training loop (one-step fit, multiple
shooting, free run), the three solvers, random restarts, validation
selection, divergence handling and the ``predict``/``simulate``/``score``
methods. A subclass supplies the structure: how a sequence is laid out for
its kernels, the initial parameters, and the kernels themselves.
"""

from __future__ import annotations

import functools
import numbers
import threading
import time
import warnings
from contextlib import contextmanager
from dataclasses import dataclass
from itertools import pairwise

import numpy as np
import threadpoolctl
from joblib import Parallel, delayed
from sklearn.base import BaseEstimator, RegressorMixin
from sklearn.exceptions import ConvergenceWarning
from sklearn.utils import check_array, check_random_state
from sklearn.utils._param_validation import Interval, StrOptions
from sklearn.utils.validation import _check_feature_names, check_is_fitted

from sysid_nn import _progress, _uncertainty
from sysid_nn._estimator_docs import document_estimator
from sysid_nn._progress import report_stage
from sysid_nn._record_checks import check_sampling, trim_padding
from sysid_nn._schedule import HALVING_AFTER, stage_data, survivors
from sysid_nn._solvers import _SOLVERS, _EarlyStop, _Objective
from sysid_nn._state_estimation import (
    _FULL_BAND,
    _segments,
    fit_initial_condition,
    noise_band,
    noise_variance,
)
from sysid_nn._validation import check_same_width

__all__ = ["DivergenceWarning"]

#: A free run whose standardised output exceeds this multiple of the largest
#: standardised training output is declared divergent.
_DIVERGENCE_FACTOR = 100.0
#: Share of ``max_iter`` spent on the one-step stage and on each multiple-
#: shooting stage of the simulation schedule (100 and 40 of 150).
_ONE_STEP_SHARE = 2.0 / 3.0
_SHOOTING_SHARE = 4.0 / 15.0
_FREE_RUN = np.iinfo(np.int64).max // 4
#: The stages before the last end when Levenberg-Marquardt's cost stalls over
#: this many accepted steps (see ``sysid_nn._solvers._solve_lm``), not only at
#: their budget. Measured on the accuracy benchmark and an 11 x 7200 sample
#: record set, the stages still gained 1-30 % per 10 steps at their budget, so
#: this rarely ends them; a looser threshold (5 %) made the ISSM less accurate.
_STALL_STEPS = 10
#: ``fit`` warns when the estimated output noise makes up more than this share
#: of the spread of the outputs' second difference. Measured on the oscillator
#: at 100 samples per period: at a share of 0.05 (0.01 % noise) the TDL lost
#: its gain over the linear model with one record (0.985 against 0.035 from
#: clean records) and kept most of it with five (0.079 against 0.012).
_NOISY_DIFFERENCE = 0.02
#: Free-state shooting skips segments shorter than this: with three fitted
#: initial outputs per 20 or 50 samples the states absorb the fit (measured
#: on the oscillator at 1 % noise, five records: 0.13 with a 50-sample stage
#: first, 0.034 without).
_MIN_FREE_SEGMENT = 100
#: ``shooting="auto"`` fits segment states only where the estimated noise
#: is below this share of the outputs' spread. A larger estimate is the
#: linear model's misfit of a strong nonlinearity at coarse sampling (0.28
#: on a noise-free test system), which the one-step schedule handles; on
#: the field's benchmarks the estimate is 0.001-0.016.
_MAX_NOISE_SHARE = 0.1
#: The noise warning suggests decimating records with more samples per
#: period than this (measured at 1 % noise: 200 samples per period decimated
#: to 20 took the TDL's free-run NRMSE from 0.99 to 0.12, the ISSM's from
#: 0.50 to 0.050).
_DECIMATE_NOISY = 40.0

# BLAS thread limits are process-wide: fits running in threads of one process
# (the threading backend, in-process dask workers, GridSearchCV with threads)
# share one limit, set by the first to enter and restored by the last to
# leave. A limit per thread would be lifted under the others by the first to
# finish, and their results would then depend on timing (multi-threaded BLAS
# rounds differently). threadpoolctl >= 3.8 lets only one thread change
# OpenBLAS limits: the control is released after each restore, so that the
# next fit can take it from whichever thread it runs in.
_BLAS_LOCK = threading.Lock()
_BLAS_USERS = 0
_BLAS_LIMIT = None


def _release_blas_control() -> None:
    controller = getattr(threadpoolctl, "OpenBLASController", None)
    release = getattr(controller, "clear_controlling_thread", None)
    if release is not None:
        release(force=True)


@contextmanager
def _single_threaded_blas():
    """BLAS single-threaded in this process while any fit runs in it."""
    global _BLAS_USERS, _BLAS_LIMIT
    with _BLAS_LOCK:
        if _BLAS_USERS == 0:
            _release_blas_control()
            _BLAS_LIMIT = threadpoolctl.threadpool_limits(limits=1, user_api="blas")
        _BLAS_USERS += 1
    try:
        yield
    finally:
        with _BLAS_LOCK:
            _BLAS_USERS -= 1
            if _BLAS_USERS == 0:
                _release_blas_control()
                _BLAS_LIMIT.restore_original_limits()
                _release_blas_control()
                _BLAS_LIMIT = None


class DivergenceWarning(UserWarning):
    """A free-run simulation left the range of the training data.

    The simulation is stopped at the first sample whose output is not finite
    or exceeds a large multiple of the training output range; that sample and
    all later ones of the sequence are returned as NaN.

    Examples
    --------
    >>> import warnings
    >>> from sysid_nn import DivergenceWarning
    >>> issubclass(DivergenceWarning, UserWarning)
    True
    """


@dataclass
class _Data:
    """Standardised sequences stacked for the kernels.

    Sequence ``s`` occupies rows ``starts[s]:starts[s + 1]`` of ``Y`` and
    ``U``; its first ``h`` rows are history (initial conditions).
    """

    Y: np.ndarray
    U: np.ndarray
    starts: np.ndarray
    h: int
    #: Leading modelled rows left out of a validation score (see ``scored``).
    skip: int = 0

    @property
    def modelled(self) -> np.ndarray:
        """Row indices of the modelled (non-history) rows."""
        return np.concatenate(
            [
                np.arange(a + self.h, b)
                for a, b in zip(self.starts[:-1], self.starts[1:], strict=True)
            ]
        )

    @property
    def scored(self) -> np.ndarray:
        """Modelled rows that count in a validation score."""
        return self.modelled[self.skip :]


# --------------------------------------------------------------------------
# input handling
# --------------------------------------------------------------------------
def _as_sequence_list(X, name: str):
    """Return ``(list_of_arrays, given_as_list)``; reject mixtures."""
    if isinstance(X, (list, tuple)):
        if len(X) == 0:
            raise ValueError(
                f"{name} is an empty list; pass at least one sequence "
                "(a 2-D array of shape (n_samples, n_features))."
            )
        first = X[0]
        if np.isscalar(first) or (
            isinstance(first, (list, tuple)) and np.isscalar(first[0])
        ):
            # A plain nested list is one array, as in scikit-learn.
            return [X], False
        return list(X), True
    return [X], False


@contextmanager
def _naming_sequence(where: str, as_list: bool):
    """Prefix an error about one sequence of a list with its place, ``X[i]``."""
    try:
        yield
    except ValueError as exc:
        if as_list:
            raise ValueError(f"{where}: {exc}") from exc
        raise


def _float_array(a, name: str, where: str, as_list: bool) -> np.ndarray:
    """``a`` as a float64 array of any dimension; errors name the sequence."""
    with _naming_sequence(where, as_list):
        return check_array(
            a,
            dtype=np.float64,
            ensure_2d=False,
            ensure_all_finite=False,
            input_name=name,
        )


def _check_finite(a: np.ndarray, name: str, index: int | None, as_list: bool) -> None:
    bad = ~np.isfinite(a)
    if bad.any():
        sample = int(np.argwhere(bad)[0][0])
        kind = "NaN" if np.isnan(a[bad]).any() else "inf"
        where = f"{name}[{index}]" if as_list else name
        raise ValueError(
            f"Input {where} contains {kind} (first at sample {sample}); "
            "remove or interpolate non-finite values before fitting or predicting."
        )


class _RecurrentRegressorBase(RegressorMixin, BaseEstimator):
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

    # ------------------------------------------------------------------ tags
    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.target_tags.required = True
        tags.target_tags.multi_output = True
        # Rows are time steps of one experiment, not independent samples: a
        # free-run score on shuffled tabular data means nothing.
        tags.regressor_tags.poor_score = True
        return tags

    # ------------------------------------------------------- structure hooks
    def _history_length(self) -> int:  # pragma: no cover - abstract
        raise NotImplementedError

    def _prepare_structure(
        self, data: _Data, val: _Data | None = None
    ) -> None:  # pragma: no cover
        """Fix data-dependent structure and the linear starting point.

        ``val`` are the validation records, when there are any.
        """
        raise NotImplementedError

    def _initial_params(
        self, rng: np.random.RandomState
    ) -> np.ndarray:  # pragma: no cover
        raise NotImplementedError

    def _run(
        self, w, data: _Data, seg_len: int, want_jac, keep_state: bool = True
    ):  # pragma: no cover
        """Return ``(Yhat, jac, diverged, state_for_gradient)``.

        ``jac`` is None for ``want_jac=False``, the full Jacobian of the
        modelled outputs for ``True`` and the normal equations ``(J'J, J'(Yhat
        - Y))`` for ``"normal"``. Without ``keep_state`` the state holds no
        per-row arrays and cannot serve :meth:`_gradient`.
        """
        raise NotImplementedError

    def _gradient(
        self, w, data: _Data, seg_len: int, state
    ) -> np.ndarray:  # pragma: no cover
        raise NotImplementedError

    def _run_horizon(
        self, w, data: _Data, horizon: int
    ) -> np.ndarray:  # pragma: no cover
        raise NotImplementedError

    def _history(
        self, n_seq: int, initial
    ) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover
        """Standardised history rows ``(Y_hist, U_hist)`` for every sequence."""
        raise NotImplementedError

    def _penalty_mask(self) -> np.ndarray:  # pragma: no cover
        raise NotImplementedError

    def __setstate__(self, state):
        # joblib may restore arrays as read-only memory maps; numba compiles a
        # separate specialisation for read-only arrays, so keep plain copies.
        for key, value in state.items():
            if isinstance(value, np.ndarray) and not value.flags.writeable:
                state[key] = np.array(value)
        super().__setstate__(state)

    # --------------------------------------------------------- validation
    def _validate_Xy(self, X, y=None, *, reset: bool, y_required: bool):
        """Validate one sequence or a list of them.

        Returns ``(X_list, y_list or None, given_as_list, y_was_1d)``.
        """
        name = type(self).__name__
        if y_required and y is None:
            raise ValueError(
                f"{name} requires y to be passed, but the target y is None."
            )
        X_list, as_list = _as_sequence_list(X, "X")
        if y is not None:
            y_list, y_as_list = _as_sequence_list(y, "y")
            if y_as_list != as_list:
                raise ValueError(
                    "X and y must both be arrays (one sequence) or both be lists "
                    f"of arrays (several sequences); got X as a "
                    f"{'list' if as_list else 'array'} and y as a "
                    f"{'list' if y_as_list else 'array'}."
                )
            if len(y_list) != len(X_list):
                raise ValueError(
                    f"X and y must hold the same number of sequences; got "
                    f"{len(X_list)} and {len(y_list)}."
                )
        Xs, ys, y_1d = [], [], None
        for i, Xi in enumerate(X_list):
            where = f"X[{i}]" if as_list else "X"
            arr = _float_array(Xi, "X", where, as_list)
            if arr.ndim == 1:
                # scikit-learn's message prints the whole array and suggests
                # reshape(1, -1), which would make a record one time step.
                raise ValueError(
                    f"{where} must be 2-D (n_samples, n_inputs); got a 1-D array of "
                    f"shape {arr.shape}. Reshape your data: a single input is "
                    f"one column, {where}.reshape(-1, 1)."
                )
            # Names as scikit-learn checks them: the first sequence of a fit
            # sets them, every other sequence must match.
            with _naming_sequence(where, as_list):
                _check_feature_names(self, Xi, reset=reset and i == 0)
            Xi = arr
            _check_finite(Xi, "X", i, as_list)
            Xs.append(Xi)
            if y is not None:
                yi = _float_array(y_list[i], "y", f"y[{i}]", as_list)
                if yi.ndim not in (1, 2):
                    raise ValueError(
                        f"y must be 1-D (n_samples,) or 2-D (n_samples, n_outputs); "
                        f"got {yi.ndim} dimensions."
                    )
                this_1d = yi.ndim == 1
                if y_1d is None:
                    y_1d = this_1d
                yi = yi.reshape(len(yi), -1)
                _check_finite(yi, "y", i, as_list)
                if len(yi) != len(Xi):
                    where = f" in sequence {i}" if as_list else ""
                    raise ValueError(
                        f"X and y must have the same number of samples{where}; got "
                        f"{len(Xi)} and {len(yi)}."
                    )
                ys.append(yi)
        n_features = check_same_width(Xs, "X", "features")
        if reset:
            self.n_features_in_ = n_features
        elif n_features != self.n_features_in_:
            raise ValueError(
                f"X has {n_features} features, but {name} is expecting "
                f"{self.n_features_in_} features as input."
            )
        if ys:
            n_outputs = check_same_width(ys, "y", "outputs")
            if not reset and n_outputs != self.n_outputs_:
                raise ValueError(
                    f"y has {n_outputs} outputs, but {name} was fitted with "
                    f"{self.n_outputs_}."
                )
        return Xs, (ys if y is not None else None), as_list, bool(y_1d)

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

    def _check_lengths(self, Xs, min_length: int, what: str = "X") -> None:
        for i, Xi in enumerate(Xs):
            if len(Xi) < min_length:
                seq = f"sequence {i} of {what}" if len(Xs) > 1 else what
                raise ValueError(
                    f"{seq} has {len(Xi)} sample{'s' if len(Xi) != 1 else ''}; "
                    f"{type(self).__name__} needs at least {min_length} samples "
                    f"per sequence: with these settings it reads {min_length - 1} "
                    "past samples to model one. Use longer records or a smaller "
                    "structure (fewer lags or states, a shorter input_delay)."
                )

    # ------------------------------------------------------------ scaling
    def _stack(self, Xs, ys, initial=None, initial_inputs=None) -> _Data:
        """Standardise and stack sequences, with their history rows.

        ``initial_inputs`` (validated by :meth:`_check_initial_inputs`)
        replaces the zero excitation of the last history rows.
        """
        h = self._history_length()
        Yh, Uh = self._history(len(Xs), initial)
        if initial_inputs is not None:
            Uh = [u.copy() for u in Uh]
            for s, past in enumerate(initial_inputs):
                k = min(len(past), h)
                if k:
                    Uh[s][h - k :] = (
                        past[len(past) - k :] - self._x_mean
                    ) / self._x_scale
        n_out = self.n_outputs_
        rows = [h + len(Xi) for Xi in Xs]
        starts = np.concatenate([[0], np.cumsum(rows)]).astype(np.int64)
        Y = np.zeros((starts[-1], n_out))
        U = np.empty((starts[-1], self.n_features_in_))
        for s, Xi in enumerate(Xs):
            a = starts[s]
            Y[a : a + h] = Yh[s]
            U[a : a + h] = Uh[s]
            U[a + h : starts[s + 1]] = (Xi - self._x_mean) / self._x_scale
            if ys is not None:
                Y[a + h : starts[s + 1]] = (ys[s] - self._y_mean) / self._y_scale
        return _Data(Y=Y, U=U, starts=starts, h=h)

    def _unstack(self, Yhat: np.ndarray, data: _Data, as_list: bool, y_1d: bool):
        out = []
        for a, b in zip(data.starts[:-1], data.starts[1:], strict=True):
            yi = Yhat[a + data.h : b] * self._y_scale + self._y_mean
            out.append(yi[:, 0] if y_1d else yi)
        return out if as_list else out[0]

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
        skip = 0
        if X_val is not None:
            Xv, yv, _, _ = self._validate_Xy(X_val, y_val, reset=False, y_required=True)
            Xv, yv = trim_padding(Xv, yv, min_len, "X_val")
            _mean_scale(np.concatenate(Xv), "X_val")
            _mean_scale(np.concatenate(yv), "y_val")
        elif self.early_stopping:
            Xs, ys, Xv, yv, skip = self._split_validation(Xs, ys, min_len)
        else:
            Xv = yv = None
        self._check_lengths(Xs, min_len)
        if Xv is not None:
            self._check_lengths(Xv, min_len, "X_val")

        Xc, yc = np.concatenate(Xs), np.concatenate(ys)
        self._x_mean, self._x_scale = _mean_scale(Xc, "X")
        self._y_mean, self._y_scale = _mean_scale(yc, "y")
        train = self._stack(Xs, ys)
        val = self._stack(Xv, yv) if Xv is not None else None
        if val is not None:
            val.skip = skip
        self._bound = _DIVERGENCE_FACTOR * max(1.0, np.abs(train.Y).max())
        modelled = _segments(train.starts, train.h)
        spp, advice = check_sampling(type(self).__name__, train.Y, modelled)
        self._check_noise(train, spp, advice)
        # The initial fit and the selection use BLAS too; see _single_threaded_blas.
        with _single_threaded_blas():
            self._prepare_structure(train, val)

            rng = check_random_state(self.random_state)
            n_runs = self._n_restarts()
            seeds = rng.randint(np.iinfo(np.int32).max, size=n_runs)
            start = time.perf_counter()
            # Successive halving (see sysid_nn._schedule): every restart runs
            # the first stages, the better half by its score the rest.
            n_stages = len(self._stages())
            halving = n_runs > 1 and n_stages > HALVING_AFTER
            restarts = [_Restart(k, seed) for k, seed in enumerate(seeds)]
            cut = HALVING_AFTER if halving else n_stages
            results = self._run_restarts(train, val, restarts, cut)
            if halving:
                kept = survivors([run.score for _, run in results])
                going_on = [results[k][0] for k in kept]
                done = self._run_restarts(train, val, going_on, n_stages)
                for k, result in zip(kept, done, strict=True):
                    results[k] = result
            runs = [run for _, run in results]
            best = min(range(len(runs)), key=lambda k: runs[k].score)
            chosen = runs[best]
            if not np.all(np.isfinite(chosen.w)):
                raise ValueError(
                    "The solver produced non-finite weights. Check the data for "
                    "extreme values or reduce the learning problem (fewer lags)."
                )
            self.coefs_ = chosen.w
            if not np.isfinite(chosen.score):
                self.coefs_ = self._fallback(chosen.w, train, val)
            self.n_iter_ = chosen.n_iter
            self.loss_ = chosen.loss
            self.best_validation_score_ = -chosen.val_loss if val is not None else None
            self.restart_scores_ = np.array([-r.score for r in runs])
            self.fit_time_ = time.perf_counter() - start
            self._after_fit(train, val)
            _uncertainty.fit_covariance(self, train)
        if not chosen.converged:
            warnings.warn(
                f"{type(self).__name__} stopped after max_iter={self.max_iter} "
                "iterations of its last training stage before reaching tol="
                f"{self.tol}. Increase max_iter or loosen tol.",
                ConvergenceWarning,
                stacklevel=2,
            )
        return self

    def _hidden_layers(self) -> tuple:
        """``hidden_layer_sizes`` as a tuple; an int is one layer (MLPRegressor)."""
        sizes = self.hidden_layer_sizes
        return tuple(sizes) if np.iterable(sizes) else (sizes,)

    def _check_noise(self, train: _Data, spp: float = np.nan, advice: str = "") -> None:
        """Estimate the output noise; warn where it swamps the fine structure.

        At fine sampling the dynamics show in the second difference of the
        outputs (the TDL reads the hysteretic state from it, the ISSM's
        one-step stage fits to it), a small fraction of the outputs. White
        noise on the records enters that difference six-fold in variance.
        With ``spp`` (samples per period) above ``_DECIMATE_NOISY``, the
        warning adds ``advice`` on decimating the records. The estimate also
        sets what depends on it: ``shooting_``, ``alpha_`` and the band edge
        the free-state schedule low-passes the records at.
        """
        var = noise_variance(train.Y, train.U, train.starts, train.h, self.input_delay)
        self.output_noise_std_ = np.sqrt(var) * self._y_scale
        modelled = _segments(train.starts, train.h)
        d2 = np.concatenate([np.diff(train.Y[a:b], 2, axis=0) for a, b in modelled])
        # The noise's share of the second difference's spread (at most 1).
        ratio = (
            np.sqrt(np.minimum(6.0 * var / np.maximum(d2.var(axis=0), 1e-300), 1))
            if len(d2) >= 2
            else np.zeros_like(var)
        )
        noisy = bool(np.any(ratio > _NOISY_DIFFERENCE))
        # Read by starts that are biased under such noise (the ISSM's).
        self._noisy_outputs = noisy
        edge = noise_band(train.Y, train.starts, train.h, var) if noisy else 0.5
        self._band_edge = edge
        # Free-state shooting needs a band where the outputs clear the noise,
        # and noise, not the broadband misfit of the linear model to a strong
        # nonlinearity at coarse sampling, which the one-step schedule handles.
        noise = noisy and bool(np.all(var < _MAX_NOISE_SHARE**2))
        self.shooting_ = self._choose_shooting(noise and edge < _FULL_BAND * 0.5)
        auto = self.alpha == "auto"
        self.alpha_ = self._auto_alpha() if auto else float(self.alpha)
        if self._noise_sensitive() and noisy and self.shooting_ != "free":
            k = int(np.argmax(ratio))
            warnings.warn(
                f"The training outputs of {type(self).__name__} carry white noise of "
                f"about {100 * np.sqrt(var[k]):.2g} % of their spread (output {k}; "
                "estimated from a linear one-step model's residuals, an upper "
                "estimate: fast variation no linear model explains counts too), "
                f"which is {100 * ratio[k]:.0f} % of the spread of their second "
                "difference, where the dynamics show at this sampling ratio. "
                "Networks trained on such records may lose their advantage over "
                "the linear model: measure more outputs (velocity as well as "
                "displacement, for the ISSM), use more records, train the TDL "
                "with shooting='auto' or 'free', or see the user guide's "
                "pitfalls page on measured records."
                + (
                    f" These records have about {spp:.0f} samples per period, "
                    "where the second difference is a small part of the "
                    f"output. {advice}"
                    if spp > _DECIMATE_NOISY and advice
                    else ""
                ),
                UserWarning,
                stacklevel=3,
            )

    def _noise_sensitive(self) -> bool:
        """Whether noise on the outputs' second difference costs this model."""
        return True

    def _independent_segments(self) -> bool:
        """Whether each shooting segment restarts from measured data alone.

        Then a stage's loss is a sum over segments, and the stages before
        the last may see a subset of them (:func:`_schedule.stage_data
        <sysid_nn._schedule.stage_data>`).
        """
        return True

    def _fallback(self, w: np.ndarray, train: _Data, val: _Data | None):
        """The linear starting model when every restart's free run diverged.

        Returns ``w`` unchanged when the starting model diverges too; warns
        :class:`DivergenceWarning` either way.
        """
        start = self._initial_params(np.random.RandomState(0))
        finite = all(
            not (
                self._run(start, data, _FREE_RUN, False, keep_state=False)[2] >= 0
            ).any()
            for data in (train, val)
            if data is not None
        )
        warnings.warn(
            f"Every restart of {type(self).__name__} gave a free run that diverged "
            "on the validation (or training) records"
            + (
                "; the model falls back to the linear starting model."
                if finite
                else ", and so does the linear starting model; simulations may "
                "return NaN."
            )
            + " Check the records for outliers, zero-padded or clipped stretches, "
            "and records of very different amplitude.",
            DivergenceWarning,
            stacklevel=3,
        )
        return start if finite else w

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

        Returns ``(X_train, y_train, X_val, y_val, skip)``. A tail block is
        validated by a free run over its whole record, from rest, of which
        only the last ``n - skip`` samples count: a run started cold in the
        middle of the motion would judge the weights by a transient.
        """
        if len(Xs) >= 3:
            n_val = max(1, round(self.validation_fraction * len(Xs)))
            return Xs[:-n_val], ys[:-n_val], Xs[-n_val:], ys[-n_val:], 0
        n = len(Xs[-1])
        n_val = round(self.validation_fraction * n)
        if n_val < 1 or n - n_val < min_len:
            # Too short to split: no validation selection.
            return Xs, ys, None, None, 0
        head = [*Xs[:-1], Xs[-1][:-n_val]]
        yhead = [*ys[:-1], ys[-1][:-n_val]]
        return head, yhead, [Xs[-1]], [ys[-1]], n - n_val

    def _n_restarts(self) -> int:
        """Number of training runs from different random starts."""
        return self.n_init

    def _final_segment(self) -> int:
        """Segment length of the loss that selection and ``loss_`` judge by."""
        return 1 if self.focus == "prediction" else _FREE_RUN

    def _stages(self) -> list[tuple[int, int]]:
        """``(segment length, iterations)`` of each training stage."""
        if self.focus == "prediction":
            return [(1, self.max_iter)]
        one = max(1, round(_ONE_STEP_SHARE * self.max_iter))
        shoot = max(1, round(_SHOOTING_SHARE * self.max_iter))
        if self.shooting_ == "free":
            # No stage reads measured outputs as regressors; the one-step
            # budget goes to the longer free-state segments.
            segs = [s for s in sorted(self.shooting_segments) if s >= _MIN_FREE_SEGMENT]
            return [(int(s), 2 * shoot) for s in segs] + [(_FREE_RUN, self.max_iter)]
        stages = [(1, one)]
        stages += [(int(s), shoot) for s in sorted(self.shooting_segments)]
        stages.append((_FREE_RUN, self.max_iter))
        return stages

    def _stage_objective(self, data: _Data, seg: int, mask, n_res: int, alpha):
        """The objective of a stage on segments of ``seg`` samples of ``data``."""
        if self.shooting_ == "free" and 1 < seg < _FREE_RUN:
            return self._free_state_objective(data, seg, mask, n_res, alpha)
        return _Objective(self, data, seg, mask, n_res, alpha=alpha)

    def _free_state_objective(self, data, seg, mask, n_res, alpha):  # pragma: no cover
        raise NotImplementedError

    def _choose_shooting(self, noisy: bool) -> str:
        """How shooting segments start: ``"measured"`` or ``"free"`` (fitted).

        Networks without free-state shooting always restart from the
        measured outputs.
        """
        return "measured"

    def _auto_alpha(self) -> float:
        """The weight penalty of ``alpha="auto"``."""
        return 0.0

    def _run_restarts(self, train, val, restarts, stop):
        """Run every restart up to stage ``stop``, in parallel.

        Returns ``(restart, run)`` pairs in the order of ``restarts``.
        """
        return Parallel(n_jobs=self.n_jobs if len(restarts) > 1 else None)(
            delayed(self._fit_one)(train, val, restart, stop) for restart in restarts
        )

    def _fit_one(self, train: _Data, val: _Data | None, restart, stop: int):
        """One restart through the stages before ``stop``; see ``_fit_stages``."""
        # The linear algebra here is small (tens to hundreds of weights):
        # threaded BLAS only spins, and restarts already run in parallel.
        with _single_threaded_blas():
            return self._fit_stages(train, val, restart, stop)

    def _fit_stages(self, train, val, restart, stop):
        """Run ``restart`` from its next stage up to stage ``stop``.

        Every stage but the last sees the records :func:`_schedule.stage_data
        <sysid_nn._schedule.stage_data>` selects. Returns ``(restart, run)``:
        the advanced :class:`_Restart` and the :class:`_Run` it would give if
        it ended here (best validation weights and the selection score).
        """
        mask = self._penalty_mask()
        n_res = len(train.modelled) * self.n_outputs_
        stages = self._stages()
        final_seg = self._final_segment()
        if restart.w is None:
            restart.rng = np.random.RandomState(restart.seed)
            restart.w = self._initial_params(restart.rng)
            restart.tracker = _Tracker(self, val, final_seg, restart.w)
        tracker, w, k = restart.tracker, restart.w, restart.k
        tracker.est = self  # not the copy a worker process unpickled
        for i_stage in range(restart.stage, stop):
            seg, iters = stages[i_stage]
            last = i_stage == len(stages) - 1
            tracker.patience = self.n_iter_no_change if last else None
            # Patience counts the last stage's own steps: steps of earlier
            # stages without improvement must not end it before it starts.
            tracker.since_best = 0
            subset = not last and self._independent_segments()
            data = stage_data(train, seg, restart.rng) if subset else train
            n_data = len(data.modelled) * self.n_outputs_
            # The penalty stays relative to the whole record.
            alpha = self.alpha_ * (n_data / n_res)
            objective = self._stage_objective(data, seg, mask, n_data, alpha)
            theta = objective.start(w)
            if not np.isfinite(objective.loss(theta)):
                continue  # the stage diverges from here on: skip it
            stall = None if last else _STALL_STEPS
            theta, nit, ok = _SOLVERS[self.solver](
                objective, theta, iters, self.tol, objective.track(tracker), stall
            )
            w = objective.weights(theta)
            restart.n_iter += nit
            if last:
                restart.converged = ok or tracker.stopped
            report_stage(
                self,
                (k, self._n_restarts()),
                (i_stage, len(stages)),
                f"segment {'free run' if seg == _FREE_RUN else seg}",
                nit,
                functools.partial(objective.loss, theta),
                tracker.best_loss,
            )
        restart.w, restart.stage = w, max(stop, restart.stage)
        if val is not None:
            w = tracker.best_w
            val_loss = tracker.best_loss
        else:
            val_loss = np.nan
        loss = _Objective(self, train, final_seg, mask, n_res).loss(w)
        score = val_loss if val is not None else loss
        run = _Run(
            w,
            loss,
            val_loss,
            score if np.isfinite(score) else np.inf,
            restart.n_iter,
            restart.converged,
        )
        return restart, run

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
        data = self._stack(Xs, None, initial, past)
        Yhat, J, diverged = self._free_run(data, initial, return_std)
        self._warn_divergence(diverged, as_list)
        y_sim = self._unstack(Yhat, data, as_list, self._y_1d)
        if not return_std:
            return y_sim
        std = _uncertainty.output_std(
            self, Yhat, J, data, as_list, self._y_1d, interval
        )
        return y_sim, std

    def _free_run(self, data: _Data, initial, want_jac: bool = False):
        """Free run of the fitted model from the initial conditions in ``data``.

        Returns ``(Yhat, J or None, diverged)``.
        """
        Yhat, J, diverged, _ = self._run(
            self.coefs_, data, _FREE_RUN, want_jac, keep_state=False
        )
        return Yhat, J, diverged

    def _initial_units(self) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover
        """``(offset, scale)`` shaped like an initial condition (for ``v``).

        The initial-condition fit works on ``v = (initial - offset) / scale``,
        standardised units.
        """
        raise NotImplementedError

    def _initial_guess(self, y0: np.ndarray) -> np.ndarray:  # pragma: no cover
        """Initial condition at rest at the measured output ``y0`` (user units)."""
        raise NotImplementedError

    def _estimate_initial(self, Xs, y_init, as_list: bool, past) -> list:
        """Initial conditions fitted to the measured start of each sequence.

        For each sequence, the initial condition (``initial_outputs`` or
        ``initial_state``) whose free run best fits ``y_init`` over the
        first ``len(y_init)`` samples, by least squares (see
        :func:`~sysid_nn._state_estimation.fit_initial_condition`).
        """
        windows = self._per_sequence(y_init, len(Xs), as_list, "y_init")
        offset, scale = self._initial_units()
        out = []
        for i, (Xi, yw) in enumerate(zip(Xs, windows, strict=True)):
            where = f"y_init[{i}]" if as_list else "y_init"
            yw = np.asarray(yw, dtype=np.float64)
            yw = yw.reshape(len(yw), -1) if yw.ndim else yw.reshape(1, 1)
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
            v = fit_initial_condition(residuals, v0)
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
            from zero initial conditions is returned (section 4.4); this is
            what :meth:`score` and scikit-learn's model selection see.
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

    def score(self, X, y, sample_weight=None):
        """Coefficient of determination R^2 of the free-run simulation.

        The model is simulated from the excitation alone (zero initial
        conditions) and compared with the measured response over all samples
        of all sequences. A diverged simulation scores ``-inf``.

        Parameters
        ----------
        X : array-like of shape (n_samples, n_inputs) or list of such
            Excitation.
        y : array-like of shape (n_samples,) or (n_samples, n_outputs), or list
            Measured response.
        sample_weight : array-like of shape (n_samples,), default=None
            Sample weights (one array only).

        Returns
        -------
        score : float
            R^2 averaged uniformly over outputs.
        """
        from sklearn.metrics import r2_score

        y_pred = self.predict(X)
        y_true = (
            np.concatenate(y)
            if isinstance(y, (list, tuple)) and not np.isscalar(y[0])
            else y
        )
        y_pred = np.concatenate(y_pred) if isinstance(y_pred, list) else y_pred
        if not np.all(np.isfinite(y_pred)):
            return -np.inf
        return r2_score(y_true, y_pred, sample_weight=sample_weight)

    def _initial_layout(self) -> tuple[tuple[int, ...], str, str]:
        """Shape of one sequence's initial conditions, its count and meaning.

        The two strings complete the error message of :meth:`_check_initial`.
        """
        raise NotImplementedError  # pragma: no cover - abstract

    def _check_initial(self, initial, n_seq: int, as_list: bool, name: str):
        """The initial conditions of every sequence, as arrays of their shape."""
        if initial is None:
            return None
        shape, count, meaning = self._initial_layout()
        out = []
        for i, init in enumerate(self._per_sequence(initial, n_seq, as_list, name)):
            a = np.asarray(init, dtype=np.float64)
            if a.size != np.prod(shape) or not np.all(np.isfinite(a)):
                where = f"{name}[{i}]" if as_list else name
                raise ValueError(
                    f"{where} must hold {count} finite values ({meaning}); got "
                    f"shape {a.shape}."
                )
            out.append(a.reshape(shape))
        return out

    @staticmethod
    def _per_sequence(values, n_seq: int, as_list: bool, name: str) -> list:
        """``values`` as a list with one entry per sequence, or a clear error."""
        items = list(values) if as_list else [values]
        if len(items) != n_seq:
            raise ValueError(
                f"{name} must hold one array per sequence; got {len(items)} for "
                f"{n_seq} sequences."
            )
        return items

    def _check_initial_inputs(self, initial_inputs, n_seq: int, as_list: bool):
        """Validate the excitation before the first sample of each sequence.

        One 2-D array ``(k, n_inputs)`` per sequence (1-D allowed for one
        input), oldest first; only the last rows the lags reach are used,
        and missing older rows are zero excitation.
        """
        if initial_inputs is None:
            return None
        pasts = self._per_sequence(initial_inputs, n_seq, as_list, "initial_inputs")
        out = []
        for i, past in enumerate(pasts):
            a = np.asarray(past, dtype=np.float64)
            if a.ndim == 1 and self.n_features_in_ == 1:
                a = a[:, None]
            where = f"initial_inputs[{i}]" if as_list else "initial_inputs"
            if a.ndim != 2 or a.shape[1] != self.n_features_in_:
                raise ValueError(
                    f"{where} must have shape (n_past_samples, {self.n_features_in_}) "
                    f"(the excitation before the first sample, oldest first); got "
                    f"shape {a.shape}."
                )
            if not np.all(np.isfinite(a)):
                raise ValueError(f"{where} contains NaN or inf; pass finite values.")
            out.append(a)
        return out

    def _warn_divergence(
        self,
        diverged: np.ndarray,
        as_list: bool,
        what: str = "free run",
        stacklevel: int = 4,
    ) -> None:
        for s, t in enumerate(diverged):
            if t >= 0:
                where = f"sequence {s}, " if as_list else ""
                warnings.warn(
                    f"The {what} of {type(self).__name__} diverged at {where}sample "
                    f"{t}: its output left {_DIVERGENCE_FACTOR:g} times the training "
                    "range. Values from there on are NaN.",
                    DivergenceWarning,
                    stacklevel=stacklevel,
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


def _mean_scale(a: np.ndarray, name: str) -> tuple[np.ndarray, np.ndarray]:
    """Mean and scale of every column, for standardising.

    Computed on the columns divided by a power of two near their peak, which
    is exact and safe from over- and underflow. A varying column whose
    squared deviations overflow float64 when summed, or underflow, cannot be
    standardised (the network and every score would be NaN, or blind to it):
    both raise a ValueError naming ``name``. A constant column (variance
    within the rounding error of the mean, the rule of scikit-learn's
    ``StandardScaler``) is divided by its level where that exceeds 1, so
    that its rounding noise stays negligible, and left unscaled otherwise.
    """
    peak = np.max(np.abs(a), axis=0)
    # At most the peak, so that it is finite; |a / unit| < 2.
    unit = np.ldexp(1.0, np.frexp(peak)[1] - 1)
    rel = a / unit
    rel_mean, rel_var = rel.mean(axis=0), rel.var(axis=0)
    n, eps = len(a), np.finfo(np.float64).eps
    constant = rel_var <= n * eps * rel_var + (n * eps * rel_mean) ** 2
    with np.errstate(over="ignore", under="ignore"):
        mean, scale = unit * rel_mean, unit * np.sqrt(rel_var)
        squares = scale**2
        overflow = ~constant & ~np.isfinite(n * squares)
    underflow = ~constant & (squares < np.finfo(np.float64).tiny)
    for bad, problem in (
        (overflow, "reaches {:.3g}: its variance overflows float64"),
        (underflow, "varies by only {:.3g}: float64 cannot square that"),
    ):
        if bad.any():
            j = int(np.flatnonzero(bad)[0])
            size = peak[j] if bad is overflow else np.ptp(a[:, j])
            raise ValueError(
                f"{name} cannot be standardised: column {j} "
                f"{problem.format(size)}. Rescale {name} (e.g. express it in "
                "other units) before fitting."
            )
    scale[constant] = np.maximum(1.0, peak[constant])
    return mean, scale


@dataclass
class _Run:
    w: np.ndarray
    loss: float
    val_loss: float
    score: float
    n_iter: int
    converged: bool


@dataclass
class _Restart:
    """One restart's progress through the training schedule.

    ``stage`` is the next stage to run; ``rng`` draws the initial weights,
    then each stage's subset of the records (see :mod:`sysid_nn._schedule`).
    """

    k: int
    seed: int
    w: np.ndarray | None = None
    tracker: _Tracker | None = None
    rng: np.random.RandomState | None = None
    n_iter: int = 0
    converged: bool = True
    stage: int = 0


class _Tracker:
    """Keeps the weights with the best validation loss seen after each step."""

    def __init__(self, est, val: _Data | None, seg: int, w0: np.ndarray):
        self.est, self.val, self.seg = est, val, seg
        self.best_w = w0.copy()
        self.best_loss = np.inf
        self.patience = None
        self.since_best = 0
        self.stopped = False
        self.progress = _progress.StepReporter(est)
        self(w0)

    def __call__(self, w) -> None:
        if self.val is None:
            self.progress(np.inf)
            return
        Yhat, _, diverged, _ = self.est._run(
            w, self.val, self.seg, False, keep_state=False
        )
        rows = self.val.scored
        loss = np.inf
        if not (diverged >= 0).any():
            e = Yhat[rows] - self.val.Y[rows]
            loss = float(np.mean(e * e))
        self.progress(min(loss, self.best_loss))
        if loss < self.best_loss:
            self.best_loss, self.best_w, self.since_best = loss, w.copy(), 0
        else:
            self.since_best += 1
            if self.patience is not None and self.since_best >= self.patience:
                self.stopped = True
                raise _EarlyStop
