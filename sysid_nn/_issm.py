"""Neural innovation state-space model (paper section 3.2, eq. 7-12)."""

from __future__ import annotations

import numbers
import warnings
from itertools import pairwise
from math import ceil

import numpy as np
from sklearn.base import RegressorMixin
from sklearn.utils import Bunch
from sklearn.utils._param_validation import Interval, StrOptions
from sklearn.utils.validation import check_is_fitted

from sysid_nn._base import (
    _FREE_RUN,
    _Data,
    _document_training_parameters,
    _RecurrentRegressorBase,
)
from sysid_nn._kernels._issm import issm_gradient, issm_predict_horizon, issm_run
from sysid_nn._kernels._mlp import ACTIVATIONS, n_hidden, n_params
from sysid_nn._kernels._recurrence import SYRK, jacobian_buffers, jacobian_result
from sysid_nn._solvers import _Objective, _solve_lm
from sysid_nn._tdl import TDLRegressor
from sysid_nn._uncertainty import output_std

__all__ = ["ISSMRegressor", "UnstablePredictorWarning"]

#: Output and input lags of the ARX model the linear part starts from, and
#: of the TDL network an ``init="tdl"`` model starts from.
_ARX_LAGS = 3
#: Solver iterations spent refitting the innovation weights after a
#: simulation-focused fit.
_INNOVATION_REFIT_ITERS = 40
#: Factors tried on the innovation weights, largest first, until the one-step
#: predictor is stable (0 makes it the free run, stable with the simulator).
_INNOVATION_SHRINKS = (1.0, 0.5, 0.25, 0.125, 0.0625, 0.0)
#: A more shrunk innovation gain is preferred while its one-step validation
#: loss stays within this factor of the best.
_INNOVATION_MARGIN = 1.2


class UnstablePredictorWarning(UserWarning):
    """The one-step predictor of a fitted ISSM is not stable.

    The innovation form ``Phi(t) - K(t) H`` of eq. 10 has spectral radius of
    at least one along the training trajectory (or the one-step predictor left
    the training range there): one-step and k-step predictions may drift away
    from the measurements instead of tracking them.

    Examples
    --------
    >>> from sysid_nn import UnstablePredictorWarning
    >>> issubclass(UnstablePredictorWarning, UserWarning)
    True
    """


class _NoTracker:
    """Stands in for the validation tracker where no selection is wanted."""

    stopped = False

    def __call__(self, w) -> None:
        pass


class _Restricted:
    """A stage objective seen through a subset ``idx`` of the weights."""

    def __init__(self, objective: _Objective, w: np.ndarray, idx: np.ndarray):
        self.objective, self.w, self.idx = objective, w.copy(), idx

    def _full(self, v):
        self.w[self.idx] = v
        return self.w

    def residuals(self, v):
        return self.objective.residuals(self._full(v))

    def normal_equations(self, v):
        # Those of the subset are the rows and columns of the whole problem's.
        JtJ, Jtr = self.objective.normal_equations(self._full(v))
        return JtJ[np.ix_(self.idx, self.idx)], Jtr[self.idx]

    def loss(self, v):
        return self.objective.loss(self._full(v))


@_document_training_parameters
class ISSMRegressor(RegressorMixin, _RecurrentRegressorBase):
    """Recurrent network modelling a non-linear innovation state-space model.

    The network of eq. 7-8 of Kirkegaard, Nielsen & Hansen (1995),

    .. math::

        x(t) = G\\big(x(t-1),\\, F(t-n_k),\\, E(t-1);\\, w\\big), \\qquad
        y(t) = H x(t) + E(t), \\quad H = [I_p\\; 0],

    where the first ``p`` states are the measured outputs (the columns of
    ``y``) and the others are unmeasured states the network invents (the
    hysteretic component in the paper's example). ``G`` is a multilayer
    perceptron, by default beside a linear state-space part

    .. math:: x(t) = A x(t-1) + B F(t-n_k) + K E(t-1) + \\mathrm{MLP}(\\cdot).

    In prediction mode the innovations ``E(t-1) = y(t-1) - H x(t-1)`` are fed
    back and the model is a one-step predictor (an extended Kalman filter
    whose transition and gain are ``Phi(t)`` and ``K(t)`` of eq. 12); in
    simulation mode ``E = 0``. Training uses exact recurrent gradients: the
    forward sensitivities of eq. 10 give the full Jacobian for the
    least-squares solver, an adjoint pass the gradient for the quasi-Newton
    solvers.

    **Starting point.** The linear part starts exactly at a linear model
    fitted to the data: a least-squares ARX model (three output and three
    input lags, at the given delay, on the standardised data) in observer
    form, put in fixed
    state coordinates in which the measured outputs are the first ``p``
    states and each remaining state is a remaining ARX direction,
    decorrelated from the outputs (least-squares residual), taken in order of
    variance along the training data (principal components) and scaled to
    unit variance, with zero at their mean where the training records start
    (the rest state for records starting at rest). When ``n_states`` is
    smaller than the ARX order, the directions of least variance are
    dropped; when larger, the ARX gets more lags (``ceil(n_states / p)``).
    ``A``, ``B`` and ``c`` are then fitted by least squares to these states
    with ``K = A H^T``, the gain that feeds the measured outputs in place of
    the measured states (the ARX predictor's own gain, or a free
    least-squares one, gave an unstable reduced predictor on the hysteretic
    oscillator). The network's output weights start at zero, so
    training starts at the linear model; ``hidden_layer_sizes=()`` is the
    linear innovation model itself.

    **Stable predictor.** Simulation-focused training barely constrains the
    weights acting on the innovations (they do not enter the free run). After
    such a fit they are refitted on the one-step prediction error, starting
    from the gain that substitutes the measured outputs for the measured
    states (``K = A H^T`` for the linear part), which leaves the free run
    unchanged. The spectral radius of the mean of ``Phi(t) - K(t) H`` along
    the training trajectory is stored in ``predictor_spectral_radius_``; a
    value of one or more (or a one-step predictor that diverges on the
    training data) warns :class:`UnstablePredictorWarning`.

    The defaults are the setting that identified the hysteretic oscillator
    best on unseen realisations: the linear part at the ARX-derived model,
    measured outputs as states plus one unmeasured state, free-run
    ("simulation") focus reached through a one-step stage and multiple
    shooting (measured states reset at each segment start), validation
    selection over four restarts. The paper's network is
    ``ISSMRegressor(n_states=3, hidden_layer_sizes=(7,), focus="prediction",
    linear_part=False, activation="logistic")``.

    Parameters
    ----------
    n_states : int or None, default=None
        Number of states ``n``, at least the number of outputs ``p``.
        ``None`` uses ``p + 2``: two states beyond the measured ones (4 for
        displacement and velocity measured, 3 for displacement alone). On the
        hysteretic oscillator with displacement and velocity measured, 4
        states halved the free-run error of the paper's 3 (accuracy
        benchmark).
    input_delay : int, default=1
        Delay ``n_k`` of the excitation seen by the network; 0 gives direct
        feed-through of ``F(t)``.
    hidden_layer_sizes : int or tuple of int, default=(7,)
        Sizes of the hidden layers (an int is one layer, as in
        ``MLPRegressor``); ``()`` gives the linear innovation model.
    activation : {"tanh", "logistic"}, default="tanh"
        Hidden-layer activation; the paper uses the logistic sigmoid (eq. 2).
    linear_part : bool, default=True
        Add the linear state-space part ``A x + B F + K E`` beside the network,
        started at the ARX-derived model with the network's output weights at
        zero. ``False`` is the paper's plain network, started at random.
    init : {"arx", "tdl"}, default="arx"
        Where training starts. ``"arx"``: the linear part at the ARX-derived
        model above, trained through the schedule of ``focus``. ``"tdl"``: a
        :class:`TDLRegressor` (three output and three excitation lags, the
        hidden layers, activation and training parameters of this model) is
        trained on the same records and realised exactly in state space, with
        the past outputs and excitation as the unmeasured states; then only
        the innovation gain is refitted. The free run is the TDL network's,
        the one-step predictor an innovation model. ``n_states`` is then
        ``3 p + 2 n_inputs`` (5 for displacement alone), ``linear_part`` must
        be True (it shifts the past values), and ``hidden_layer_sizes=(9,)``
        gives the default TDL network. With displacement alone measured and
        little measurement noise, this start identified the hysteretic
        oscillator better than ``"arx"``; with noisy records ``"arx"`` is the
        robust choice (accuracy benchmark). To start a free run in the middle
        of a record, take ``initial_state`` from :meth:`predict_states` on the
        record so far: zeros in the unmeasured states are past outputs of
        zero here.
    focus : {"simulation", "prediction"}, default="simulation"
        What training minimises: one-step prediction errors (innovations fed
        back), or free-run simulation errors (reached through a one-step
        stage and multiple shooting on segments of growing length, then the
        full free run).
    shooting_segments : tuple of int, default=(20, 100, 400)
        Segment lengths (samples) of the multiple-shooting stages of the
        simulation focus; at each segment start the measured states restart
        from the measured outputs while the unmeasured ones carry over.
    alpha : float, default=0.0
        L2 penalty on the network weights (not on biases or the linear part).
    %(training_parameters)s

    Attributes
    ----------
    coefs_ : ndarray
        Flat parameter vector (network weights and biases, then the linear
        part ``[A B K]``).
    n_states_ : int
        Number of states used.
    n_features_in_ : int
        Number of excitation channels.
    n_outputs_ : int
        Number of measured outputs ``p``.
    linear_model_ : Bunch
        The linear starting model ``A, B, K, c`` in the internal state
        coordinates (standardised units).
    tdl_ : TDLRegressor
        With ``init="tdl"`` only: the fitted TDL network the model realises.
        The unmeasured states after sample ``t`` are then ``y(t-1), y(t-2),
        F(t-n_k), F(t-n_k-1)`` (each over all channels) in the user's units,
        each divided by its standard deviation on the training data.
    predictor_spectral_radius_ : float
        Spectral radius of the mean of ``Phi(t) - K(t) H`` along the one-step
        predictor's training trajectory (``inf`` if it diverged); below one
        for a stable predictor.
    n_iter_ : int
        Solver iterations of the chosen restart over all stages.
    loss_ : float
        Final training loss of the chosen restart, in standardised units.
    best_validation_score_ : float or None
        Negative validation mean squared error (standardised) of the chosen
        weights.
    restart_scores_ : ndarray
        Negative selection loss of every restart.
    fit_time_ : float
        Seconds spent in training.
    coefs_covariance_ : ndarray of shape (n_coefs, n_coefs)
        Delta-method covariance of ``coefs_`` (standardised units): from the
        Jacobian of the final training objective, the innovation weights
        refitted after a simulation-focused fit from the one-step Jacobian,
        and with ``init="tdl"`` the TDL network's covariance mapped through
        the realisation; see :ref:`uncertainty`.
    n_effective_params_ : float
        Effective number of weights the data determine (the trace of the
        hat matrix), used to correct the residual variances.
    noise_variance_ : ndarray of shape (n_outputs,)
        Residual variance of the free run on the training records (user's
        units), corrected for ``n_effective_params_``.
    one_step_noise_variance_ : ndarray of shape (n_outputs,)
        The same for the one-step predictor.
    feature_names_in_ : ndarray
        Column names of ``X`` when it was a DataFrame.

    See Also
    --------
    TDLRegressor : Tapped-delay-line recurrent network.

    Examples
    --------
    A linear system with one output, identified by the linear innovation
    model and simulated from the excitation alone:

    >>> import numpy as np
    >>> from scipy.signal import lfilter
    >>> from sysid_nn import ISSMRegressor
    >>> rng = np.random.default_rng(0)
    >>> u = rng.standard_normal((400, 1))
    >>> y = lfilter([0.0, 0.5], [1.0, -1.5, 0.7], u[:, 0])
    >>> model = ISSMRegressor(n_states=2, hidden_layer_sizes=(), n_init=1,
    ...                       random_state=0).fit(u, y)
    >>> float(np.round(model.score(u, y), 4))
    1.0
    >>> model.predict_states(u, y).states.shape
    (400, 2)
    """

    _parameter_constraints: dict = {
        **_RecurrentRegressorBase._parameter_constraints,
        "n_states": [None, Interval(numbers.Integral, 1, None, closed="left")],
        "linear_part": ["boolean"],
        "init": [StrOptions({"arx", "tdl"})],
    }

    def __init__(
        self,
        n_states=None,
        input_delay=1,
        hidden_layer_sizes=(7,),
        activation="tanh",
        linear_part=True,
        init="arx",
        focus="simulation",
        shooting_segments=(20, 100, 400),
        alpha=0.0,
        solver="lm",
        max_iter=150,
        tol=1e-8,
        n_init=4,
        early_stopping=True,
        validation_fraction=0.2,
        n_iter_no_change=30,
        random_state=None,
        verbose=False,
        n_jobs=None,
    ):
        self.n_states = n_states
        self.input_delay = input_delay
        self.hidden_layer_sizes = hidden_layer_sizes
        self.activation = activation
        self.linear_part = linear_part
        self.init = init
        self.focus = focus
        self.shooting_segments = shooting_segments
        self.alpha = alpha
        self.solver = solver
        self.max_iter = max_iter
        self.tol = tol
        self.n_init = n_init
        self.early_stopping = early_stopping
        self.validation_fraction = validation_fraction
        self.n_iter_no_change = n_iter_no_change
        self.random_state = random_state
        self.verbose = verbose
        self.n_jobs = n_jobs

    def __sklearn_tags__(self):
        return self._recurrent_tags(super().__sklearn_tags__())

    # RegressorMixin (left of the base) would score the raw predictions;
    # the free-run R^2 with its divergence handling is the base's.
    score = _RecurrentRegressorBase.score

    # -------------------------------------------------------------- public
    def simulate(
        self,
        X,
        *,
        initial_state=None,
        initial_inputs=None,
        return_std=False,
        interval="prediction",
    ):
        """Free-run simulation from the excitation alone (paper section 4.4).

        The innovations are zero throughout (``E = 0``).

        Parameters
        ----------
        X : array-like of shape (n_samples, n_inputs) or list of such
            Excitation.
        initial_state : array-like of shape (n_states,), or list of such, \
default=None
            State just before the first sample: the measured outputs in the
            user's units, then the unmeasured states in the internal
            coordinates (as returned by :meth:`predict_states`). Default:
            zero outputs and the unmeasured states at rest, as in the paper.
        initial_inputs : array-like of shape (n_past, n_inputs), or list of \
such, default=None
            Measured excitation just before the first sample, oldest first
            (1-D for one input). Default: zero excitation before the start.
            Only the last ``input_delay`` rows are used.
        return_std : bool, default=False
            Also return the standard deviation of every sample (delta
            method, see :ref:`uncertainty`).
        interval : {"prediction", "confidence"}, default="prediction"
            What the standard deviation is of (only used with
            ``return_std``): ``"prediction"``, a new measurement (weight
            uncertainty plus ``noise_variance_``); ``"confidence"``, the
            model output (weight uncertainty only).

        Returns
        -------
        y_sim : ndarray or list of ndarray
            Simulated response; NaN from a sample where the run diverged (a
            :class:`~sysid_nn.DivergenceWarning` says where).
        y_std : ndarray or list of ndarray
            Standard deviation of each value of ``y_sim``, same shape; only
            with ``return_std=True``.
        """
        data, X0, as_list = self._prepare_call(X, None, initial_state, initial_inputs)
        Yhat, J, diverged, _ = self._run_from(
            self.coefs_, data, _FREE_RUN, return_std, X0
        )
        self._warn_divergence(diverged, as_list, stacklevel=3)
        y_sim = self._unstack(Yhat, data, as_list, self._y_1d)
        if not return_std:
            return y_sim
        std = output_std(self, Yhat, J, data, as_list, self._y_1d, interval)
        return y_sim, std

    def predict_states(self, X, y=None, *, initial_state=None) -> Bunch | list[Bunch]:
        """All states and the linearisation of eq. 12 along a trajectory.

        With measured outputs ``y`` the trajectory is the one-step predictor
        (innovations fed back, an extended Kalman filter); without, it is the
        free run from the excitation alone.

        Parameters
        ----------
        X : array-like of shape (n_samples, n_inputs) or list of such
            Excitation.
        y : array-like of shape (n_samples,) or (n_samples, n_outputs), or list, \
default=None
            Measured outputs.
        initial_state : array-like of shape (n_states,), or list of such, \
default=None
            State before the first sample, as for :meth:`simulate`.

        Returns
        -------
        result : Bunch or list of Bunch
            One per sequence, with ``states`` (n_samples, n_states): the
            measured states in the user's output units, the unmeasured ones in
            the internal coordinates (unit variance on the training data);
            ``Phi`` (n_samples, n_states, n_states): ``d x(t) / d x(t-1)``;
            ``K`` (n_samples, n_states, n_outputs): ``d x(t) / d E(t-1)``, the
            EKF transition and gain in the same units. Rows after a
            divergence are NaN.
        """
        data, X0, as_list = self._prepare_call(X, y, initial_state)
        seg = 1 if y is not None else _FREE_RUN
        _, _, diverged, state = self._run_from(self.coefs_, data, seg, False, X0, True)
        self._warn_divergence(diverged, as_list, stacklevel=3)
        Xs, D = state[0], state[3]
        n, p, m = self.n_states_, self.n_outputs_, self.n_features_in_
        scale = np.ones(n)
        scale[:p] = self._y_scale
        Xs = Xs.copy()
        Xs[:, :p] = Xs[:, :p] * self._y_scale + self._y_mean
        # Back to the user's units: x_user = S x, e_user = S_p e.
        Phi = D[:, :, :n] * scale[:, None] / scale[None, :]
        K = D[:, :, n + m :] * scale[:, None] / self._y_scale[None, :]
        out = []
        for s, (a, b) in enumerate(pairwise(data.starts)):
            rows = slice(a + data.h, b)
            bad = diverged[s]
            Phi_s, K_s = Phi[rows].copy(), K[rows].copy()
            if bad >= 0:
                Phi_s[bad:] = np.nan
                K_s[bad:] = np.nan
            out.append(Bunch(states=Xs[rows], Phi=Phi_s, K=K_s))
        return out if as_list else out[0]

    # ---------------------------------------------------------- structure
    def _history_length(self) -> int:
        return max(1, self.input_delay)

    def _arx_lags(self) -> int:
        """Lags of the ARX fit the linear start is realised from."""
        return max(_ARX_LAGS, ceil(self.n_states_ / self.n_outputs_))

    def _lag_reach(self) -> int:
        # The linear start reads further back than the recurrence: the ARX
        # fit, or the TDL network with _ARX_LAGS lags.
        lags = _ARX_LAGS if self.init == "tdl" else self._arx_lags()
        return max(self._history_length(), lags, self.input_delay + lags - 1)

    def _validate_outputs(self) -> None:
        p = self.n_outputs_
        if self.init == "tdl":
            self._validate_tdl_start()
            return
        if self.n_states is not None and self.n_states < p:
            raise ValueError(
                f"n_states={self.n_states} is smaller than the number of measured "
                f"outputs (y has {p} columns). The measured outputs are the first "
                f"states (H = [I 0]); set n_states >= {p}, or None for "
                f"n_outputs + 2."
            )
        self.n_states_ = int(self.n_states) if self.n_states is not None else p + 2

    def _sizes(self) -> np.ndarray:
        n = self.n_states_
        n_z = n + self.n_features_in_ + self.n_outputs_
        return np.array([n_z, *self._hidden_layers(), n], dtype=np.int64)

    def _bypass(self) -> bool:
        # Without hidden layers the network is the linear part already.
        return bool(self.linear_part) and len(self._hidden_layers()) > 0

    def _history(self, n_seq, initial):
        h = self._history_length()
        y0 = -self._y_mean / self._y_scale
        u0 = np.broadcast_to(-self._x_mean / self._x_scale, (h, self.n_features_in_))
        Yh = []
        for s in range(n_seq):
            ys = (
                y0
                if initial is None
                else (initial[s][: self.n_outputs_] - self._y_mean) / self._y_scale
            )
            Yh.append(np.broadcast_to(ys, (h, self.n_outputs_)).copy())
        return Yh, [u0] * n_seq

    def _check_initial(self, initial, n_seq, as_list, name):
        if initial is None:
            return None
        inits = self._per_sequence(initial, n_seq, as_list, name)
        out = []
        for i, init in enumerate(inits):
            a = np.asarray(init, dtype=np.float64).ravel()
            if a.shape != (self.n_states_,) or not np.all(np.isfinite(a)):
                where = f"{name}[{i}]" if as_list else name
                raise ValueError(
                    f"{where} must hold n_states = {self.n_states_} finite values "
                    "(the measured outputs in your units, then the unmeasured "
                    f"states); got shape {np.shape(init)}."
                )
            out.append(a)
        return out

    def _initial_states(self, data: _Data, initial=None) -> np.ndarray:
        """``X0`` of every sequence: measured part from the history rows."""
        X0 = np.zeros((len(data.starts) - 1, self.n_states_))
        X0[:, : self.n_outputs_] = data.Y[data.starts[:-1] + data.h - 1]
        if initial is not None:
            X0[:, self.n_outputs_ :] = np.array([s[self.n_outputs_ :] for s in initial])
        return X0

    def _prepare_call(self, X, y, initial, initial_inputs=None):
        """Validate and stack a prediction call; returns ``(data, X0, as_list)``."""
        check_is_fitted(self, "coefs_")
        Xs, ys, as_list, _ = self._validate_Xy(X, y, reset=False, y_required=False)
        self._check_lengths(Xs, 1)
        initial = self._check_initial(initial, len(Xs), as_list, "initial_state")
        past = self._check_initial_inputs(initial_inputs, len(Xs), as_list)
        data = self._stack(Xs, ys, initial, past)
        return data, self._initial_states(data, initial), as_list

    # ------------------------------------------------- starting from a TDL
    def fit(self, X, y, *, X_val=None, y_val=None):
        # init="tdl" trains a TDL network on the same records first; it needs
        # them as given, before standardisation and stacking.
        self._fit_records = (X, y, X_val, y_val)
        if hasattr(self, "tdl_"):
            del self.tdl_  # from an earlier fit: it must not outlive it
        try:
            super().fit(X, y, X_val=X_val, y_val=y_val)
        finally:
            del self._fit_records
        if self.init == "tdl":
            # The training was the TDL's: report its restarts and effort.
            self.n_iter_ = self.tdl_.n_iter_
            self.restart_scores_ = self.tdl_.restart_scores_
            self.fit_time_ += self.tdl_.fit_time_
        return self

    fit.__doc__ = _RecurrentRegressorBase.fit.__doc__

    def _validate_tdl_start(self) -> None:
        p, m = self.n_outputs_, self.n_features_in_
        n = p * _ARX_LAGS + m * (_ARX_LAGS - 1)
        if self.n_states is not None and self.n_states != n:
            raise ValueError(
                f'init="tdl" realises a TDL network with {_ARX_LAGS} output and '
                f"{_ARX_LAGS} input lags in state space, which takes n_states = "
                f"{n} here ({_ARX_LAGS} x {p} outputs + {_ARX_LAGS - 1} x {m} "
                f"inputs); got n_states={self.n_states}. Use n_states=None."
            )
        if not self.linear_part and self._hidden_layers():
            raise ValueError(
                'init="tdl" needs linear_part=True: the states holding past '
                "outputs and inputs are shifted by the linear part."
            )
        self.n_states_ = n

    def _start_tdl(self) -> TDLRegressor:
        """The TDL network an ``init="tdl"`` model starts from, unfitted.

        It gets every parameter the two estimators share (structure and
        training); the lags are the TDL defaults the realisation assumes.
        """
        shared = set(self._get_param_names()) & set(TDLRegressor._get_param_names())
        return TDLRegressor(
            output_lags=_ARX_LAGS,
            input_lags=_ARX_LAGS,
            **{name: getattr(self, name) for name in sorted(shared)},
        )

    def _realise_tdl(self, tdl: TDLRegressor) -> tuple[np.ndarray, Bunch]:
        """Weights with which this model runs exactly as the fitted ``tdl``.

        The state after sample ``t`` is ``[y(t), y(t-1), ..., y(t-n_a+1),
        F(t-n_k), ..., F(t-n_k-n_b+2)]``: the measured outputs in this model's
        standardised units, the past outputs and excitation in the user's
        units divided by their scale (zero at rest). The TDL's regressor is
        then an affine map ``phi = M z + phi0`` of the network input ``z =
        [x(t-1), F(t-n_k), E(t-1)]``, with the innovations added to the newest
        output (the one-step predictor sees the measured output there); the
        older lags are shifted by the linear part. Returns the weights and
        the linear part ``A, B, K, c``.
        """
        p, m, n = self.n_outputs_, self.n_features_in_, self.n_states_
        na, nb = tdl.output_lags, tdl.input_lags
        nz = n + m + p
        sy, my, sx, mx = self._y_scale, self._y_mean, self._x_scale, self._x_mean
        ty, tmy, tx, tmx = tdl._y_scale, tdl._y_mean, tdl._x_scale, tdl._x_mean
        y_states = np.arange(p, na * p)  # y(t-1), ..., y(t-na+1)
        u_states = np.arange(na * p, n)  # F(t-nk), ..., F(t-nk-nb+2)
        u_in, e_in = np.arange(n, n + m), np.arange(n + m, nz)
        M, phi0 = np.zeros((na * p + nb * m, nz)), np.zeros(na * p + nb * m)
        ky, kx = np.tile(np.arange(p), na - 1), np.tile(np.arange(m), nb - 1)
        # Newest output: the state (plus innovation) in this model's units.
        M[np.arange(p), np.arange(p)] = sy / ty
        M[np.arange(p), e_in] = sy / ty
        phi0[:p] = (my - tmy) / ty
        M[y_states, y_states] = sy[ky] / ty[ky]
        phi0[y_states] = -tmy[ky] / ty[ky]
        # Newest excitation from the input, older ones from the states.
        rows = na * p + np.arange(m)
        M[rows, u_in] = sx / tx
        phi0[rows] = (mx - tmx) / tx
        rows = na * p + m + np.arange(len(u_states))
        M[rows, u_states] = sx[kx] / tx[kx]
        phi0[rows] = -tmx[kx] / tx[kx]
        T, t0 = tdl._S @ M, tdl._S @ phi0  # the TDL network's input = T z + t0

        # The linear part: the TDL output in rows :p, shifts below. y(t-1)
        # is the newest output (state plus innovation) back in user units.
        L, c = np.zeros((n, nz)), np.zeros(n)
        if na > 1:
            L[np.arange(p, 2 * p), np.arange(p)] = 1.0
            L[np.arange(p, 2 * p), e_in] = 1.0
            c[p : 2 * p] = my / sy
            L[y_states[p:], y_states[:-p]] = 1.0
        if nb > 1:
            L[u_states[:m], u_in] = 1.0
            c[u_states[:m]] = mx / sx
            L[u_states[m:], u_states[:-m]] = 1.0
        gain = ty / sy  # the TDL's standardised output in this model's units
        c[:p] = (tmy - my) / sy
        w_tdl, sizes = tdl.coefs_, tdl._sizes_
        layers, end = tdl._layer_slices()
        if tdl._bypass():
            bypass = w_tdl[end:].reshape(p, -1)
            L[:p] = gain[:, None] * (bypass @ T)
            c[:p] += gain * (bypass @ t0)
        w = np.zeros(n_params(self._sizes_, self._bypass()))
        if len(layers) == 1:  # the linear TDL: its map is the linear part
            W, b = w_tdl[layers[0][0]].reshape(p, -1), w_tdl[layers[0][1]]
            L[:p] = gain[:, None] * (W @ T)
            c[:p] += gain * (W @ t0 + b)
            w[: L.size], w[L.size :] = L.ravel(), c
            return w, self._linear_blocks(L, c)
        mine, my_end = self._layers()
        for i, ((ws, bs), (w_off, b_off, n_out, _)) in enumerate(
            zip(layers, mine, strict=True)
        ):
            W, b = w_tdl[ws].reshape(sizes[i + 1], sizes[i]), w_tdl[bs]
            if i == 0:
                W, b = W @ T, b + W @ t0
            if i == len(layers) - 1:
                W = np.vstack([gain[:, None] * W, np.zeros((n - p, W.shape[1]))])
                b = c + np.concatenate([gain * b, np.zeros(n - p)])
            w[w_off:b_off], w[b_off : b_off + n_out] = W.ravel(), b
        w[my_end:] = L.ravel()
        return w, self._linear_blocks(L, c)

    def _linear_blocks(self, L: np.ndarray, c: np.ndarray) -> Bunch:
        n, m = self.n_states_, self.n_features_in_
        return Bunch(A=L[:, :n], B=L[:, n : n + m], K=L[:, n + m :], c=c)

    # ------------------------------------------------ linear starting point
    def _arx(self, data: _Data, lags: int):
        """Least-squares ARX fit ``y(t) = sum A_i y(t-i) + sum B_j u(t-nk-j) + c``.

        Only rows whose lags lie in the measured part of a sequence are used.
        Returns ``(A_list, B_list, c, rows)``.
        """
        p, nk = self.n_outputs_, self.input_delay
        rows = []
        for a, b in pairwise(data.starts):
            first = a + data.h + max(lags, nk + lags - 1)
            rows.append(np.arange(first, b))
        rows = np.concatenate(rows)
        phi = self._arx_regressors(data, rows, lags)
        theta = np.zeros((phi.shape[1] + 1, p))
        if len(rows):
            design = np.hstack([phi, np.ones((len(rows), 1))])
            theta, *_ = np.linalg.lstsq(design, data.Y[rows], rcond=None)
        m = self.n_features_in_
        A = [theta[i * p : (i + 1) * p].T for i in range(lags)]
        B = [theta[lags * p + j * m : lags * p + (j + 1) * m].T for j in range(lags)]
        return A, B, theta[-1], rows

    def _arx_regressors(self, data: _Data, rows: np.ndarray, lags: int) -> np.ndarray:
        nk = self.input_delay
        blocks = [data.Y[rows - i] for i in range(1, lags + 1)]
        blocks += [data.U[rows - nk - j] for j in range(lags)]
        return np.hstack(blocks) if blocks else np.empty((len(rows), 0))

    def _prepare_structure(self, data: _Data) -> None:
        self._sizes_ = self._sizes()
        self._act = ACTIVATIONS[self.activation]
        if self.init == "tdl":
            X, y, X_val, y_val = self._fit_records
            self.tdl_ = self._start_tdl().fit(X, y, X_val=X_val, y_val=y_val)
            self._tdl_weights, self.linear_model_ = self._realise_tdl(self.tdl_)
            return
        p, n, nk = self.n_outputs_, self.n_states_, self.input_delay
        lags = self._arx_lags()
        A_i, B_j, c, rows = self._arx(data, lags)
        # Observer-form ARX states along the data: block i is the part of
        # the prediction of y(t + i) already fixed by data up to t - 1, so
        # block 0 is the one-step prediction yhat(t).
        xi = np.zeros((len(rows), lags * p))
        for i in range(lags):
            for j in range(i, lags):
                xi[:, i * p : (i + 1) * p] += data.Y[rows - 1 - j + i] @ A_i[j].T
                xi[:, i * p : (i + 1) * p] += data.U[rows - nk - j + i] @ B_j[j].T
        xi[:, :p] += c
        x = xi @ self._state_coordinates(xi, p, n).T
        # Zero of the unmeasured states: their mean where the training
        # records start (the rest state for records that start at rest).
        first = np.flatnonzero(np.diff(rows, prepend=-2) != 1)
        x[:, p:] -= x[first, p:].mean(axis=0)
        self.linear_model_ = self._fit_linear_model(data, rows, x)

    def _fit_linear_model(self, data: _Data, rows: np.ndarray, x: np.ndarray):
        """Least-squares linear innovation model on the ARX-derived states.

        ``x(t) = A [y(t-1); x_u(t-1)] + B u(t-nk) + c`` with ``x_u`` the
        unmeasured states, i.e. ``K = A H^T`` in
        ``x(t) = A x(t-1) + B u(t-nk) + K e(t-1) + c``.
        """
        p, n, m = self.n_outputs_, self.n_states_, self.n_features_in_
        pairs = np.flatnonzero(np.diff(rows) == 1) + 1
        t = rows[pairs]
        # K = A H^T: the one-step predictor feeds the measured outputs in
        # place of the measured states. A free least-squares K made the
        # reduced predictor unstable on the hysteretic oscillator.
        design = np.hstack(
            [
                data.Y[t - 1],
                x[pairs - 1, p:],
                data.U[t - self.input_delay],
                np.ones((len(t), 1)),
            ]
        )
        theta = np.zeros((design.shape[1], n))
        if len(t):
            theta, *_ = np.linalg.lstsq(design, x[pairs], rcond=None)
        A, B = theta[:n].T, theta[n : n + m].T
        K = A[:, :p].copy()
        return Bunch(A=A, B=B, K=K, c=theta[-1])

    @staticmethod
    def _state_coordinates(xi: np.ndarray, p: int, n: int) -> np.ndarray:
        """Fixed map ``x = T xi`` from observer-form to model states.

        The first ``p`` states are the predicted outputs themselves; the
        others are the remaining observer-form directions with the part
        explained by the outputs removed (least-squares residual), ordered by
        variance along the training data and scaled to unit variance.
        Directions beyond ``n`` are dropped.
        """
        N = xi.shape[1]
        T = np.zeros((n, N))
        T[:p, :p] = np.eye(p)
        if len(xi) > 1:
            centred = xi - xi.mean(axis=0)
            out, rest = centred[:, :p], centred[:, p:]
            C, *_ = np.linalg.lstsq(out, rest, rcond=None)  # rest ~ out @ C
            resid = rest - out @ C
        else:
            C, resid = np.zeros((p, N - p)), np.zeros((1, N - p))
        var, V = np.linalg.eigh(resid.T @ resid / max(1, len(resid)))
        var, V = var[::-1][: n - p], V[:, ::-1][:, : n - p]
        # Directions the data barely excite (an ARX of higher order than the
        # system) keep a bounded scale instead of blowing up.
        total = float(np.var(xi, axis=0).sum()) if len(xi) > 1 else 1.0
        var = np.maximum(var, max(1e-8 * var.max(initial=0.0), 1e-12 * total, 1e-300))
        W = V.T / np.sqrt(var)[:, None]
        T[p:, p:] = W
        T[p:, :p] = -W @ C.T
        return T

    def _layers(self):
        """``(weight_offset, bias_offset, n_out, n_in)`` per layer; bypass offset."""
        sizes, layers, pos = self._sizes_, [], 0
        for n_in, n_out in pairwise(sizes):
            layers.append((pos, pos + n_in * n_out, int(n_out), int(n_in)))
            pos += n_in * n_out + n_out
        return layers, pos

    def _input_columns(self, cols) -> np.ndarray:
        """Indices of the weights acting on network inputs ``cols``.

        Those of the first layer and of the linear part, row by row.
        """
        layers, end = self._layers()
        w0, _, n_out, n_z = layers[0]
        cols = np.asarray(cols)
        idx = [w0 + j * n_z + cols for j in range(n_out)]
        if self._bypass():
            idx += [end + j * n_z + cols for j in range(self.n_states_)]
        return np.concatenate(idx)

    def _innovation_index(self) -> np.ndarray:
        n, m, p = self.n_states_, self.n_features_in_, self.n_outputs_
        return self._input_columns(np.arange(n + m, n + m + p))

    def _n_restarts(self) -> int:
        # A TDL start is deterministic: the restarts were the TDL's.
        return 1 if self.init == "tdl" else self.n_init

    def _stages(self):
        # A TDL start is trained already; only the innovation gain is refitted.
        return [] if self.init == "tdl" else super()._stages()

    def _initial_params(self, rng):
        if self.init == "tdl":
            return self._tdl_weights.copy()
        sizes = self._sizes_
        layers, end = self._layers()
        w = np.zeros(n_params(sizes, self._bypass()))
        lin = self.linear_model_
        L = np.hstack([lin.A, lin.B, lin.K])
        if len(layers) == 1:
            w[: L.size] = L.ravel()
            w[L.size :] = lin.c
            return w
        gain = 2.0 if self.activation == "logistic" else 1.0
        for w_off, b_off, n_out, n_in in layers:
            bound = gain * np.sqrt(6.0 / (n_in + n_out))
            w[w_off:b_off] = rng.uniform(-bound, bound, n_out * n_in)
        if self.linear_part:
            # Start exactly at the linear model: network output silent.
            w_off, b_off, n_out, _ = layers[-1]
            w[w_off:b_off] = 0.0
            w[b_off : b_off + n_out] = lin.c
            w[end:] = L.ravel()
        return w

    def _penalty_mask(self):
        layers, _ = self._layers()
        mask = np.zeros(n_params(self._sizes_, self._bypass()), dtype=bool)
        if len(layers) > 1:
            for w_off, b_off, _, _ in layers:
                mask[w_off:b_off] = True
        return mask

    # ------------------------------------------------------------ kernels
    def _run(self, w, data, seg_len, want_jac, keep_state=True):
        X0 = self._initial_states(data)
        return self._run_from(w, data, seg_len, want_jac, X0, keep_state=keep_state)

    def _run_from(
        self, w, data, seg_len, want_jac, X0, want_lin=False, keep_state=True
    ):
        n_rows, n, p = data.Y.shape[0], self.n_states_, self.n_outputs_
        n_z = int(self._sizes_[0])
        n_mod = n_rows - data.h * (len(data.starts) - 1)  # modelled rows
        mode, J, JtJ, Jtr = jacobian_buffers(want_jac, n_mod * p, 0, len(w))
        Xs = np.empty((n_rows, n))
        kept = n_rows if keep_state else 0
        Z = np.empty((kept, n_z))
        A = np.empty((kept, max(1, n_hidden(self._sizes_))))
        D = np.empty((n_rows if want_lin else 0, n, n_z))
        diverged = np.empty(len(data.starts) - 1, dtype=np.int64)
        issm_run(
            w, self._sizes_, self._act, self._bypass(), data.Y, data.U, data.starts,
            data.h, self.input_delay, X0, min(seg_len, _FREE_RUN), self._bound,
            mode, want_lin, Xs, J, Z, A, D, JtJ, Jtr, SYRK, diverged,
        )  # fmt: skip
        Yhat = np.ascontiguousarray(Xs[:, :p])
        jac = jacobian_result(mode, J, JtJ, Jtr)
        return Yhat, jac, diverged, (Xs, Z, A, D)

    def _gradient(self, w, data, seg_len, state):
        Xs, Z, A, _ = state
        grad = np.zeros(len(w))
        issm_gradient(
            w, self._sizes_, self._act, self._bypass(), data.Y, data.U, data.starts,
            data.h, min(seg_len, _FREE_RUN), Xs, Z, A, grad,
        )  # fmt: skip
        return grad

    def _run_horizon(self, w, data, horizon):
        X0 = self._initial_states(data)
        _, _, _, (Xp, _, _, _) = self._run_from(w, data, 1, False, X0, keep_state=False)
        Yhat = np.empty_like(data.Y)
        issm_predict_horizon(
            w, self._sizes_, self._act, self._bypass(), data.U, data.starts, data.h,
            self.input_delay, horizon, X0, Xp, Yhat,
        )  # fmt: skip
        return Yhat

    # ---------------------------------------------------- stable predictor
    def _after_fit(self, train: _Data, val: _Data | None) -> None:
        if self.focus == "simulation":
            self.coefs_ = self._refit_innovations(self.coefs_, train, val)
        rho = self._predictor_radius(self.coefs_, train)
        self.predictor_spectral_radius_ = rho
        if not rho < 1.0:
            warnings.warn(
                f"The one-step predictor of this {type(self).__name__} is not "
                f"stable: the innovation form Phi(t) - K(t) H has spectral radius "
                f"{rho:.4g} >= 1 along the training data. One-step and k-step "
                "predictions may drift from the measurements; use "
                'focus="prediction", linear_part=True or more training data.',
                UnstablePredictorWarning,
                stacklevel=3,
            )

    def _substitution_gain(self, w: np.ndarray) -> np.ndarray:
        """Weights on ``E`` copied from those on the measured states.

        The network then sees ``x[:p] + e = y`` in place of the measured
        states: the one-step predictor becomes the model run on measured
        outputs, as in multiple shooting (``K = A H^T`` for the linear part).
        """
        w = w.copy()
        measured = self._input_columns(np.arange(self.n_outputs_))
        w[self._innovation_index()] = w[measured]
        return w

    def _refit_innovations(
        self, w: np.ndarray, train: _Data, val: _Data | None
    ) -> np.ndarray:
        """Refit the weights on ``E`` to the one-step loss.

        They do not enter the free run, which therefore stays unchanged. A
        version of the gain counts only if its one-step predictor also stays
        finite on the validation data, when there are any.
        """
        mask = self._penalty_mask()

        def one_step(data: _Data) -> _Objective:
            return _Objective(self, data, 1, mask, len(data.modelled) * self.n_outputs_)

        objective = one_step(train)
        idx = self._innovation_index()
        candidates = [self._substitution_gain(w), w]
        start = min(candidates, key=objective.loss)
        if np.isfinite(objective.loss(start)):
            sub = _Restricted(objective, start, idx)
            v, _, _ = _solve_lm(
                sub, start[idx], _INNOVATION_REFIT_ITERS, self.tol, _NoTracker()
            )
            refit = start.copy()
            refit[idx] = v
            candidates.insert(0, refit)
        # Selection keeps the one-step predictor stable: the innovation
        # weights of each candidate are shrunk towards zero (where the
        # predictor is the free run) in steps; a version counts if its
        # innovation form is stable along the training data and its one-step
        # predictor stays finite on the validation data. A refit to noisy
        # records can be stable on them and still diverge on others; dropping
        # the innovations altogether would leave the one-step predictor no
        # better than the free run.
        check = one_step(val) if val is not None else None
        stable = []
        for candidate in candidates:
            for shrink in _INNOVATION_SHRINKS:
                shrunk = candidate.copy()
                shrunk[idx] *= shrink
                if self._predictor_radius(shrunk, train) < 1.0 and (
                    check is None or np.isfinite(check.loss(shrunk))
                ):
                    stable.append((objective.loss(shrunk), shrink, shrunk))
        if not stable:
            return candidates[0]
        best = min(loss for loss, _, _ in stable)
        if not np.isfinite(best):
            return stable[0][2]
        # The most shrunk version within a margin of the best: a predictor at
        # the edge of stability on a few records diverges on others.
        near = [entry for entry in stable if entry[0] <= _INNOVATION_MARGIN * best]
        return min(near, key=lambda entry: (entry[1], entry[0]))[2]

    def _predictor_radius(self, w: np.ndarray, data: _Data) -> float:
        """Spectral radius of the mean ``Phi(t) - K(t) H`` of the one-step predictor."""
        X0 = self._initial_states(data)
        _, _, diverged, state = self._run_from(w, data, 1, False, X0, True)
        if (diverged >= 0).any():
            return np.inf
        n, m, p = self.n_states_, self.n_features_in_, self.n_outputs_
        D = state[3][data.modelled]
        M = D[:, :, :n].mean(axis=0)
        M[:, :p] -= D[:, :, n + m :].mean(axis=0)
        return float(np.max(np.abs(np.linalg.eigvals(M))))
