"""Tapped-delay-line recurrent network (paper section 3.1, eq. 4-6)."""

from __future__ import annotations

import numbers
from math import comb

import numpy as np
from sklearn.utils._param_validation import Interval, StrOptions

from sysid_nn._engine import _least_squares as least_squares
from sysid_nn._engine._issm_start import ARX_LAGS, order_lags
from sysid_nn._engine._layout import MLPLayout
from sysid_nn._engine._least_squares import with_intercept
from sysid_nn._engine._order import tdl_auto_width
from sysid_nn._engine._shooting import _FreeStateObjective
from sysid_nn._engine._state_estimation import lowpass
from sysid_nn._estimators._base import _RecurrentRegressorBase
from sysid_nn._estimators._estimator_docs import document_estimator
from sysid_nn._kernels._mlp import ACTIVATIONS, n_hidden
from sysid_nn._kernels._recurrence import SYRK, jacobian_buffers, jacobian_result
from sysid_nn._kernels._tdl import tdl_gradient, tdl_predict_horizon, tdl_run
from sysid_nn._records._data import _FREE_RUN, _Data

__all__ = ["TDLRegressor"]

#: The weight penalty of ``alpha="auto"`` with free segment states (chosen
#: on the accuracy benchmark; see the user guide's training page).
_NOISY_ALPHA = 0.03


#: The TDL's linear start may not let any mode grow more than this factor
#: over the longest training record (see ``TDLRegressor._stable_arx``): an
#: integrating structure keeps its pole near one, a cancelled pair put
#: outside the unit circle by least squares is cut (see the training page).
_ARX_GROWTH = 10.0


@document_estimator
class TDLRegressor(_RecurrentRegressorBase):
    """Multilayer perceptron fed back its own outputs through a tapped delay line.

    The network of eq. 4 of Kirkegaard, Nielsen & Hansen (1995),

    .. math::

        \\hat y(t) = G\\big(\\hat y(t-1), \\dots, \\hat y(t-n_a),\\;
        F(t-n_k), \\dots, F(t-n_k-n_b+1);\\, w\\big),

    with ``G`` a multilayer perceptron (sigmoid hidden layers, linear output),
    optionally plus a linear bypass. Training uses exact recurrent gradients:
    forward sensitivities (eq. 6 carried through the delay line) give the
    full Jacobian for the least-squares solver, an adjoint pass the gradient
    for the quasi-Newton solvers.

    The defaults are the setting that identified the hysteretic oscillator
    best on unseen realisations (see the accuracy benchmark): the lags read
    from the data (three output and three excitation lags there), lags seen
    in difference coordinates, a linear
    bypass started at the least-squares ARX fit, free-run ("simulation")
    focus reached through one-step and multiple-shooting stages, with
    validation selection over four restarts. The paper's network is
    ``TDLRegressor(output_lags=6, input_lags=5, hidden_layer_sizes=(9,),
    activation="logistic", linear_bypass=False, lag_representation="delays")``.
    ``hidden_layer_sizes=()`` is the linear ARX / output-error model.

    Parameters
    ----------
    output_lags : int or "auto", default="auto"
        Number of past outputs fed back (``n_a``, "n" in eq. 4). ``"auto"``
        spreads the order :class:`ISSMRegressor`'s ``n_states="auto"`` reads
        from the data over the outputs, ``ceil(n_states / n_outputs)`` lags
        and at least 3, the lags of the ISSM's ARX start (3 for the paper's
        oscillator, 6 on the Silverbox and Wiener-Hammerstein benchmarks);
        the evidence is kept in ``order_selection_``.
    input_lags : int or "auto", default="auto"
        Number of excitation samples seen (``n_b``, "m" in eq. 4); ``"auto"``
        as for ``output_lags``, the same number.
    input_delay : int, default=1
        Delay ``n_k`` of the newest excitation sample; 0 gives direct
        feed-through of ``F(t)``.
    hidden_layer_sizes : "auto", int or tuple of int, default=(9,)
        Sizes of the hidden layers (an int is one layer, as in
        ``MLPRegressor``); ``()`` gives the linear model. ``"auto"``: one
        layer of three units per fed-back output value (``output_lags_``
        times the number of outputs), at least 7.
    activation : {"tanh", "logistic"}, default="tanh"
        Hidden-layer activation; the paper uses the logistic sigmoid (eq. 2).
    linear_bypass : bool, default=True
        Add a linear map from the lagged signals to the output beside the
        network, started at the least-squares ARX fit with the network's
        output weights at zero, so training starts from the best linear model.
    lag_representation : {"differences", "delays"}, default="differences"
        How the hidden layer sees the fed-back outputs: the plain delays, or
        ``y(t-1)`` and its backward differences up to order ``n_a - 1``, each
        scaled to unit standard deviation. A fixed linear map that folds back
        into ordinary TDL weights; at small sampling steps the differences
        make the slow hysteretic state visible to the network.
    focus : {"simulation", "prediction"}, default="simulation"
        What training minimises: one-step prediction errors, or free-run
        simulation errors (reached through a one-step stage and multiple
        shooting on segments of growing length, then the full free run).
    shooting_segments : tuple of int, default=(20, 100, 400)
        Segment lengths (samples) of the multiple-shooting stages of the
        simulation focus; ``()`` goes from the one-step fit straight to the
        free run.
    shooting : {"auto", "measured", "free"}, default="auto"
        How the simulation schedule treats measured outputs. ``"measured"``:
        a one-step stage, then shooting segments restarted from the measured
        outputs. ``"free"``, for noisy records: no stage takes measured
        outputs as exact regressors; the linear start and the segments'
        starting values come from the records low-passed to the band where
        the outputs clear the noise, and every segment's initial outputs are
        fitted with the weights (multiple shooting on the segments of
        ``shooting_segments`` of at least 100 samples, then the free run).
        ``"auto"`` chooses ``"free"`` when a linear one-step model's misfit
        is broadband (above 2 % of the spread of the outputs' second
        difference, ``one_step_misfit_share_``) while staying below 10 % of
        the outputs' spread, a band of the spectrum clears it
        (``band_edge_``), the focus is ``"simulation"`` and the solver
        ``"lm"``: white measurement noise at fine sampling, or dynamics the
        lags do not resolve at coarse sampling (see the user guide's
        training page). The choice is in ``shooting_``.
    alpha : float or "auto", default="auto"
        L2 penalty on the network weights (not on biases or the bypass),
        scaled like scikit-learn's ``MLPRegressor``. ``"auto"``: none with
        the one-step schedule (``shooting_ == "measured"``), 0.03 with free
        segment states, where the output-error loss alone lets the network
        fit one noisy record at the cost of unseen ones (see the user guide's
        pitfalls page). The value used is in ``alpha_``.
    %(training_parameters)s

    Attributes
    ----------
    coefs_ : ndarray
        Flat parameter vector (network weights and biases, then the bypass).
    output_lags_ : int
        Number of past outputs fed back (``output_lags`` with ``"auto"``
        resolved).
    input_lags_ : int
        Number of excitation samples seen (``input_lags`` with ``"auto"``
        resolved).
    order_selection_ : Bunch
        With ``"auto"`` lags only: the evidence for the order, as
        :class:`ISSMRegressor`'s ``order_selection_`` (``n_states`` is the
        order the lags hold); drawn by
        :func:`~sysid_nn.plotting.plot_order_selection`.
    n_features_in_ : int
        Number of excitation channels.
    n_outputs_ : int
        Number of outputs.
    n_iter_ : int
        Solver iterations of the chosen restart over all stages.
    loss_ : float
        Final training loss of the chosen restart (free run for simulation
        focus), in standardised units (after a ``refit``, of the weights
        returned on the training and validation records together).
    %(selection_attributes)s
    shooting_ : {"measured", "free"}
        How the shooting segments started (see ``shooting``).
    alpha_ : float
        The weight penalty used (see ``alpha``).
    coefs_covariance_ : ndarray of shape (n_coefs, n_coefs)
        Delta-method covariance of ``coefs_`` (standardised units), from the
        Jacobian of the final training objective; see :ref:`uncertainty`.
    %(variance_attributes)s

    See Also
    --------
    ISSMRegressor : Neural innovation state-space model.

    Examples
    --------
    A linear ARX system, identified by the linear model:

    >>> import numpy as np
    >>> from scipy.signal import lfilter
    >>> from sysid_nn import TDLRegressor
    >>> rng = np.random.default_rng(0)
    >>> u = rng.standard_normal((300, 1))
    >>> y = lfilter([0.0, 0.5], [1.0, -1.5, 0.7], u[:, 0])
    >>> arx = TDLRegressor(output_lags=2, input_lags=1, hidden_layer_sizes=(),
    ...                    n_init=1, random_state=0).fit(u, y)
    >>> float(np.round(arx.score(u, y), 6))
    1.0
    """

    _parameter_constraints: dict = {
        **_RecurrentRegressorBase._parameter_constraints,
        "output_lags": [
            Interval(numbers.Integral, 1, None, closed="left"),
            StrOptions({"auto"}),
        ],
        "input_lags": [
            Interval(numbers.Integral, 1, None, closed="left"),
            StrOptions({"auto"}),
        ],
        "hidden_layer_sizes": [
            "array-like",
            Interval(numbers.Integral, 1, None, closed="left"),
            StrOptions({"auto"}),
        ],
        "linear_bypass": ["boolean"],
        "lag_representation": [StrOptions({"differences", "delays"})],
        "shooting": [StrOptions({"auto", "measured", "free"})],
    }

    def __init__(
        self,
        output_lags="auto",
        input_lags="auto",
        input_delay=1,
        hidden_layer_sizes=(9,),
        activation="tanh",
        linear_bypass=True,
        lag_representation="differences",
        focus="simulation",
        shooting_segments=(20, 100, 400),
        shooting="auto",
        alpha="auto",
        solver="lm",
        max_iter=150,
        tol=1e-8,
        n_init=4,
        early_stopping=True,
        validation_fraction=0.2,
        n_iter_no_change=10,
        refit=False,
        random_state=None,
        verbose=False,
        n_jobs=None,
    ):
        self._store_parameters(locals())

    # -------------------------------------------------------------- public
    @document_estimator
    def simulate(
        self,
        X,
        *,
        initial_outputs=None,
        initial_inputs=None,
        y_init=None,
        return_std=False,
        interval="prediction",
    ):
        """Free-run simulation from the excitation alone (paper section 4.4).

        Parameters
        ----------
        %(excitation)s
        initial_outputs : array-like of shape (n_lags, n_outputs) or \
(n_lags,), or list of such, default=None
            Measured outputs just before the first sample, oldest first;
            ``n_lags`` is the fitted ``output_lags_``.
            Default: the model at rest, the outputs its free run settles at
            under zero excitation (the excitation assumed before the first
            sample), found by running it over 8192 samples of zero
            excitation first; a model that does not settle there (an
            integrating or self-oscillating one) or settles outside the range
            of the training outputs starts from zero outputs, as in the paper.
            ``np.zeros((output_lags_, n_outputs))`` gives the paper's start
            always.
        initial_inputs : array-like of shape (n_past, n_inputs), or list of \
such, default=None
            Measured excitation just before the first sample, oldest first
            (1-D for one input). Default: zero excitation before the start.
            Give it with ``initial_outputs`` to continue a record from the
            middle of the motion; only the last ``input_delay + input_lags_ -
            1`` rows are used.
        y_init : array-like of shape (n_window, n_outputs), or list, default=None
            Measured outputs over the first ``n_window`` samples of ``X`` (the
            state-initialisation window; 1-D for one output), for a record
            that starts from an unknown state. The initial outputs are
            estimated from them: the ones whose free run fits the window best
            in the least-squares sense, an output-error fit of
            ``output_lags_`` values that averages out white measurement noise
            (measured outputs taken as ``initial_outputs`` would carry the
            noise into the run). The
            whole record is simulated from the estimate; score it after the
            window. Not together with ``initial_outputs``.
        %(simulation_std)s

        Examples
        --------
        >>> import numpy as np
        >>> from sysid_nn import TDLRegressor
        >>> u = np.sin(np.linspace(0, 20, 200))[:, None]
        >>> y = np.convolve(u[:, 0], [0.0, 0.5, 0.25])[:200]
        >>> model = TDLRegressor(output_lags=1, input_lags=2, hidden_layer_sizes=(),
        ...                      n_init=1, random_state=0).fit(u, y)
        >>> model.simulate(u).shape
        (200,)

        A record that starts in motion, its start estimated from the first
        50 measured samples:

        >>> late = model.simulate(u[100:], y_init=y[100:150])
        >>> bool(np.allclose(late[50:], y[150:], atol=1e-3))
        True
        """
        return self._simulate(
            X,
            initial_outputs,
            "initial_outputs",
            initial_inputs,
            return_std=return_std,
            interval=interval,
            y_init=y_init,
        )

    # ---------------------------------------------------------- structure
    def _history_length(self) -> int:
        return max(self.output_lags_, self.input_delay + self.input_lags_ - 1)

    def _validate_outputs(self) -> None:
        # Provisional "auto" lags (those of p + 2 states, the reach the
        # record checks read); chosen from the data in _choose_order.
        self._set_order(self.n_outputs_ + 2)

    def _order_from_data(self) -> bool:
        return "auto" in (self.output_lags, self.input_lags)

    def _lags_at_order(self, n_states: int) -> tuple[int, int]:
        """Output and input lags at an order of ``n_states`` (the "auto" ones)."""
        lags = order_lags(n_states, self.n_outputs_)
        return tuple(
            lags if given == "auto" else int(given)
            for given in (self.output_lags, self.input_lags)
        )

    def _set_order(self, n_states: int) -> None:
        self.output_lags_, self.input_lags_ = self._lags_at_order(n_states)

    def _weights_at_order(self, n_states: int) -> int:
        na, nb = self._lags_at_order(n_states)
        return MLPLayout(self._sizes(na, nb), self._bypass()).n_params

    def _hidden_layers(self, na: int | None = None) -> tuple:
        """Hidden sizes; ``"auto"`` scales with ``na`` output lags (the fitted)."""
        if not (
            isinstance(self.hidden_layer_sizes, str)
            and self.hidden_layer_sizes == "auto"
        ):
            return super()._hidden_layers()
        if na is None:
            na = getattr(self, "output_lags_", ARX_LAGS)
        return (tdl_auto_width(na, getattr(self, "n_outputs_", 1)),)

    def _sizes(self, na: int | None = None, nb: int | None = None) -> np.ndarray:
        """Layer sizes, with the fitted lags unless ``na`` and ``nb`` are given."""
        na = self.output_lags_ if na is None else na
        nb = self.input_lags_ if nb is None else nb
        n_reg = na * self.n_outputs_ + nb * self.n_features_in_
        return np.array(
            [n_reg, *self._hidden_layers(na), self.n_outputs_], dtype=np.int64
        )

    def _bypass(self) -> bool:
        # Without hidden layers the network is linear already.
        return bool(self.linear_bypass) and len(self._hidden_layers()) > 0

    def _history(self, n_seq, initial):
        h = self._history_length()
        y0 = np.broadcast_to(-self._y_mean / self._y_scale, (h, self.n_outputs_)).copy()
        u0 = np.broadcast_to(-self._x_mean / self._x_scale, (h, self.n_features_in_))
        Yh = [y0.copy() for _ in range(n_seq)]
        if initial is not None:
            for s, init in enumerate(initial):
                Yh[s][h - self.output_lags_ :] = (init - self._y_mean) / self._y_scale
        return Yh, [u0] * n_seq

    def _conditions_at(self, Yhat, state, data, s):
        a, b = data.starts[s], data.starts[s + 1]
        Y = np.r_[data.Y[a : a + data.h], Yhat[a + data.h : b]]
        return Y[len(Y) - self.output_lags_ :] * self._y_scale + self._y_mean

    def _initial_layout(self):
        shape = (self.output_lags_, self.n_outputs_)
        count = f"output_lags_ x n_outputs = {shape}"
        return shape, count, "the last measured outputs, oldest first"

    def _initial_units(self):
        shape = (self.output_lags_, 1)
        return np.tile(self._y_mean, shape), np.tile(self._y_scale, shape)

    def _initial_guess(self, y0):
        return np.tile(y0, (self.output_lags_, 1))

    def _regressors(self, data: _Data, rows: np.ndarray | None = None) -> np.ndarray:
        """One-step regressor matrix ``phi`` of ``rows`` (by default the
        modelled rows; measured y)."""
        rows = data.modelled if rows is None else rows
        na, nb, nk = self.output_lags_, self.input_lags_, self.input_delay
        blocks = [data.Y[rows - i] for i in range(1, na + 1)]
        blocks += [data.U[rows - nk - i] for i in range(nb)]
        return np.hstack(blocks)

    def _noise_advice(self) -> str:
        if self.shooting == "measured":
            return "train with shooting='free' (or 'auto'), "
        if self.solver != "lm" or self.focus != "simulation":
            return (
                "fitted segment states (shooting='auto' or 'free') need "
                "solver='lm' and focus='simulation'; "
            )
        return ""

    def _choose_shooting(self, free_states_help: bool) -> str:
        # Segment states are fitted by Levenberg-Marquardt's eliminated step,
        # in the simulation schedule's shooting stages.
        supported = self.solver == "lm" and self.focus == "simulation"
        if self.shooting == "free" and not supported:
            raise ValueError(
                "shooting='free' fits segment states with Levenberg-Marquardt "
                "in the simulation schedule; it needs solver='lm' and "
                f"focus='simulation', got solver={self.solver!r} and "
                f"focus={self.focus!r}. Use shooting='measured' or 'auto'."
            )
        if self.shooting == "auto":
            return "free" if free_states_help and supported else "measured"
        return self.shooting

    def _auto_alpha(self) -> float:
        return _NOISY_ALPHA if self.shooting_ == "free" else 0.0

    def _stage_objective(self, data: _Data, seg: int, mask, n_res: int, alpha):
        # Free-state shooting fits each segment's initial lags beside the
        # weights (``shooting="free"``); the other stages are the base's.
        if self.shooting_ == "free" and 1 < seg < _FREE_RUN:
            return _FreeStateObjective(
                self,
                data,
                seg,
                mask,
                n_res,
                self.output_lags_,
                self._smooth_train,
                alpha,
            )
        return super()._stage_objective(data, seg, mask, n_res, alpha)

    def _independent_segments(self) -> bool:
        # Free-state stages start their segments from the low-passed whole
        # records; they see the whole records, not subsets.
        return self.shooting_ == "measured"

    def _after_fit(self, train, val) -> None:
        self._smooth_train = None  # a copy of the records: not kept

    def _prepare_structure(self, data: _Data, val: _Data | None = None) -> None:
        self._smooth_train = None
        measured = data
        if self.shooting_ == "free":
            # The linear start and the lag scaling from the band where the
            # outputs clear the noise: at fine sampling the measured second
            # difference is mostly noise.
            Y, U = lowpass(data.Y, data.U, data.starts, data.h, self._band_edge)
            data = self._smooth_train = _Data(Y=Y, U=U, starts=data.starts, h=data.h)
        na, p = self.output_lags_, self.n_outputs_
        n_reg = na * p + self.input_lags_ * self.n_features_in_
        S = np.eye(n_reg)
        phi = self._regressors(data)
        if self.lag_representation == "differences":
            # Row (d, k): backward difference of order d of output k at t-1.
            for d in range(na):
                row = np.zeros(na)
                for m in range(d + 1):
                    row[m] = (-1) ** m * comb(d, m)
                for k in range(p):
                    S[d * p + k, :] = 0.0
                    S[d * p + k, k : na * p : p] = row
            spread = (phi @ S.T).std(axis=0)
            spread[spread < 1e-12] = 1.0
            S[: na * p] /= spread[: na * p, None]
        self._S = np.ascontiguousarray(S)
        self._sizes_ = self._sizes()
        self._act = ACTIVATIONS[self.activation]
        longest = int(np.max(np.diff(data.starts))) - data.h
        self._arx = self._stable_arx(phi @ S.T, data.Y[data.modelled], longest)
        # The linear model's closed-form fit: least squares on the measured
        # records, on the rows whose lags are all measured (as the ISSM's
        # ARX start). The networks' start above also regresses on a
        # record's first rows, whose lags read the rest state of the history
        # rows, and on low-passed records under free shooting: on a flexible
        # arm's acceleration record that starts in motion (614 samples, 6
        # lags) it had spectral radius 1.017, so its output lags were cut to
        # 4, against 0.998 here. (Started so, the networks moved: Cascaded
        # Tanks' TDL from 1.03 to 0.59 V, Silverbox's from 0.43 to 0.55 mV
        # with one fit of five at 40.8; see the training guide.)
        rows = measured.measured_rows(data.h)
        if len(rows) <= n_reg:  # too short: every modelled row
            rows = measured.modelled
        arx_phi = self._regressors(measured, rows)
        self._arx_measured = self._stable_arx(arx_phi @ S.T, measured.Y[rows], longest)

    def _stable_arx(self, Z: np.ndarray, target: np.ndarray, n: int) -> np.ndarray:
        """Least-squares ARX fit (with intercept) in network coordinates, stable.

        On records a lower order fits exactly (noise-free, or a structure
        of fewer states than lags), least squares is free to add a pole
        and a zero that cancel, and it may put them outside the unit
        circle: the one-step fit is exact, the free run diverges from
        rounding, and every training stage after it is skipped. The
        output lags are then cut, highest first, down to none (a finite
        impulse response, always stable), until no mode grows more than
        ``_ARX_GROWTH``-fold over ``n`` samples, the longest record: an
        integrating structure keeps its pole at one.
        """
        na, p = self.output_lags_, self.n_outputs_
        n_cols = Z.shape[1] + 1
        for k in range(na, -1, -1):
            # Columns of output lags beyond k (plain lags, or differences of
            # order k and more, which read lags beyond k) are left out.
            keep = np.r_[np.arange(k * p), np.arange(na * p, Z.shape[1])]
            theta = np.zeros((n_cols, p))
            fit, _ = least_squares.solve(
                (with_intercept(Z[rows][:, keep]), target[rows])
                for rows in least_squares.row_blocks(len(Z))
            )
            theta[np.r_[keep, n_cols - 1]] = fit
            if n * np.log(self._arx_radius(theta) + 1e-300) <= np.log(_ARX_GROWTH):
                break
        return theta

    def _arx_radius(self, theta: np.ndarray) -> float:
        """Spectral radius of the block companion matrix of an ARX fit."""
        na, p = self.output_lags_, self.n_outputs_
        lags = (self._S.T @ theta[:-1])[: na * p]  # plain lag coefficients
        C = np.eye(na * p, k=-p)
        C[:p] = lags.T
        return float(np.max(np.abs(np.linalg.eigvals(C))))

    def _initial_params(self, rng):
        return self._weights_at(self._arx, rng)

    def _closed_form_fits(self, *, for_network: bool) -> list[tuple[int, np.ndarray]]:
        # The least-squares ARX fit to the measured records' measured rows.
        if self._hidden_layers():
            return []
        return [(0, self._weights_at(self._arx_measured, np.random.RandomState(0)))]

    def _weights_at(self, arx: np.ndarray, rng) -> np.ndarray:
        """Network weights drawn by ``rng``, the linear part at ``arx``."""
        layout = self._layout()
        w = np.zeros(layout.n_params)
        layout.draw_weights(w, rng, self.activation)
        theta_L, theta_b = arx[:-1].T, arx[-1]
        out = layout.layers[-1]
        if len(layout.layers) == 1:
            w[out.weights] = theta_L.ravel()
            w[out.biases] = theta_b
        elif self._bypass():
            # Start exactly at the ARX model: network silent, bypass = ARX.
            w[out.weights] = 0.0
            w[out.biases] = theta_b
            w[layout.bypass] = theta_L.ravel()
        return w

    def _network(self) -> tuple:
        """The fixed arguments of the kernels: layer sizes, activation,
        bypass flag and lag transform."""
        return self._sizes_, self._act, self._bypass(), self._S

    def _lags(self) -> tuple[int, int, int]:
        return self.output_lags_, self.input_lags_, self.input_delay

    def _run(self, w, data, seg_len, want_jac, keep_state=True):
        n_rows, n_out = data.Y.shape[0], self.n_outputs_
        n_mod = n_rows - data.h * (len(data.starts) - 1)  # modelled rows
        mode, J, JtJ, Jtr = jacobian_buffers(
            want_jac, n_mod * n_out, (self.output_lags_ + 1) * n_out, len(w)
        )
        Yhat = np.empty_like(data.Y)
        kept = n_rows if keep_state else 0
        Z = np.empty((kept, self._S.shape[0]))
        A = np.empty((kept, max(1, n_hidden(self._sizes_))))
        diverged = np.empty(len(data.starts) - 1, dtype=np.int64)
        net, lags = self._network(), self._lags()
        tdl_run(w, *net, data.Y, data.U, data.starts, data.h, *lags,
                min(seg_len, _FREE_RUN), self._bound, mode,
                Yhat, J, Z, A, JtJ, Jtr, SYRK, diverged)  # fmt: skip
        return Yhat, jacobian_result(mode, J, JtJ, Jtr), diverged, (Yhat, Z, A)

    def _gradient(self, w, data, seg_len, state):
        Yhat, Z, A = state
        grad = np.zeros(len(w))
        tdl_gradient(w, *self._network(), data.Y, data.starts, data.h,
                     self.output_lags_, seg_len, Yhat, Z, A, grad)  # fmt: skip
        return grad

    def _run_horizon(self, w, data, horizon):
        Yhat = np.empty_like(data.Y)
        tdl_predict_horizon(w, *self._network(), data.Y, data.U, data.starts,
                            data.h, *self._lags(), horizon, Yhat)  # fmt: skip
        return Yhat
