"""Estimates of what was not measured: output noise and initial states.

* :func:`noise_variance`: the white output-noise level of training records,
  from the records alone; ``fit`` warns when it swamps the fine structure of
  the outputs that the one-step stage reads the dynamics from.
* :func:`noise_band` and :func:`lowpass`: the band where the outputs stand
  clear of that noise, and the records filtered to it: the noise-robust
  schedule's linear start and segment states come from them.
* :func:`fit_initial_condition`: the initial condition of a fitted model
  whose free run best fits a measured window (``simulate(X, y_init=...)``).
* :func:`rest_check`: where a fitted model settles under zero excitation,
  the rest its free runs start from when no initial conditions are given,
  and the evidence for it.
"""

from __future__ import annotations

from itertools import pairwise

import numpy as np
from sklearn.utils import Bunch

from sysid_nn._engine import _least_squares as least_squares
from sysid_nn._engine._least_squares import with_intercept
from sysid_nn._records._data import _FREE_RUN, _Data

#: Output and input lags of the linear one-step model whose residuals give
#: the noise level.
_NOISE_LAGS = 3


def _segments(starts: np.ndarray, h: int):
    """``(first_modelled_row, end)`` of every stacked sequence."""
    return [(a + h, b) for a, b in pairwise(starts)]


def noise_variance(Y: np.ndarray, U: np.ndarray, starts, h: int, delay: int):
    """White output-noise variance of each output column, from the data alone.

    The variance part of :func:`one_step_misfit`.

    Returns
    -------
    var : ndarray of shape (n_outputs,)
    """
    return one_step_misfit(Y, U, starts, h, delay)[0]


def one_step_misfit(Y: np.ndarray, U: np.ndarray, starts, h: int, delay: int):
    """Misfit of a linear one-step model: its noise reading and its colour.

    A least-squares ARX model with ``_NOISE_LAGS`` output and input lags is
    fitted to the stacked sequences (rows ``starts[s] + h:starts[s + 1]`` of
    sequence ``s``). With white noise ``v`` on the outputs its residual is
    ``A(q) v`` plus the model error, so ``var(residual) / sum(a_i^2)`` is an
    estimate of ``var(v)`` (an upper one: the model error counts as noise).
    The lag-1 autocorrelation of the residual tells the two apart: ``A(q) v``
    alternates from sample to sample (a negative or small correlation), the
    error of a smooth response that the lags do not resolve varies slowly
    (a large positive one).

    Returns
    -------
    var : ndarray of shape (n_outputs,)
    correlation : ndarray of shape (n_outputs,)
        Lag-1 autocorrelation of the residual within the sequences (0 when
        it cannot be told).
    explained : ndarray of shape (n_outputs,)
        Share of the residual's variance that squares and cubes of the
        regressors explain by least squares: large for the misfit of a
        static non-linearity of the regressors, small for white noise.
    """
    na = nb = _NOISE_LAGS
    first = max(na, delay + nb - 1)
    rows = np.concatenate(
        [np.arange(a + first, b) for a, b in _segments(starts, h) if b - a > first]
        or [np.empty(0, dtype=np.int64)]
    ).astype(np.int64)
    p = Y.shape[1]
    if len(rows) <= (na * p + nb * U.shape[1] + 1) * 2:
        return np.zeros(p), np.zeros(p), np.zeros(p)

    def regressors(r):
        lagged = [Y[r - i] for i in range(1, na + 1)]
        return np.hstack(lagged + [U[r - delay - j] for j in range(nb)])

    blocks = list(least_squares.row_blocks(len(rows)))
    theta, _ = least_squares.solve(
        (with_intercept(regressors(rows[s])), Y[rows[s]]) for s in blocks
    )
    resid = np.vstack(
        [Y[rows[s]] - with_intercept(regressors(rows[s])) @ theta for s in blocks]
    )
    var = np.empty(p)
    for k in range(p):
        a = theta[k : na * p : p, k]  # own-output AR coefficients
        var[k] = resid[:, k].var() / (1.0 + float(a @ a))
    # Pairs of neighbouring samples of one sequence.
    pair = np.flatnonzero(np.diff(rows) == 1)
    centred = resid - resid.mean(axis=0)
    num = np.sum(centred[pair] * centred[pair + 1], axis=0)
    den = np.sum(centred * centred, axis=0)
    correlation = np.divide(num, den, out=np.zeros(p), where=den > 0)
    # The share of the residual that squares and cubes of the regressors
    # explain: a non-linearity's misfit is a function of them, white
    # measurement noise is not.

    def curved(r):
        lagged = regressors(r)
        return np.hstack([with_intercept(lagged), lagged**2, lagged**3])

    n_curved = 3 * (na * p + nb * U.shape[1]) + 1
    if len(rows) > 2 * n_curved:
        _, products = least_squares.solve((curved(rows[s]), resid[s]) for s in blocks)
        # The rest has zero mean (the intercept): its variance is its
        # mean square.
        explained = 1.0 - np.divide(
            np.diag(products) / len(rows),
            den / len(rows),
            out=np.ones(p),
            where=den > 0,
        )
    else:
        explained = np.zeros(p)
    return var, correlation, explained


#: The outputs' band ends at the highest frequency where their spectrum
#: stands this many times above the white-noise floor (see the user guide's
#: training page for how it was chosen).
_BAND_MARGIN = 10.0
#: Band edges above this share of the Nyquist frequency leave records as
#: they are.
_FULL_BAND = 0.9


def noise_band(Y: np.ndarray, starts, h: int, var: np.ndarray) -> float:
    """Highest frequency (cycles per sample) where an output clears the noise.

    The Welch periodogram of each output, averaged over the sequences
    (weighted by length), against the floor ``2 var`` of white noise of
    variance ``var`` (one-sided, unit sampling rate). Returns the largest
    band edge over the outputs, at most the Nyquist frequency 0.5.
    """
    from scipy.signal import welch

    segs = [(a, b) for a, b in _segments(starts, h) if b - a > 8]
    if not segs:
        return 0.5
    n_per = min(512, min(b - a for a, b in segs))
    edge = 0.0
    for k in range(Y.shape[1]):
        spectra = [welch(Y[a:b, k], nperseg=n_per)[1] for a, b in segs]
        power = np.average(spectra, axis=0, weights=[b - a for a, b in segs])
        freqs = np.fft.rfftfreq(n_per)
        above = np.flatnonzero(power > _BAND_MARGIN * 2.0 * var[k])
        edge = max(edge, freqs[above[-1]] if len(above) else freqs[1])
    return float(edge)


def lowpass(Y: np.ndarray, U: np.ndarray, starts, h: int, edge: float):
    """``(Y, U)`` with every sequence's modelled rows low-passed at ``edge``.

    Zero-phase fourth-order Butterworth (``sosfiltfilt``), the same on the
    excitation, so that a linear relation between them survives; copies,
    unchanged when ``edge`` is near the Nyquist frequency.
    """
    from scipy.signal import butter, sosfiltfilt

    Y, U = Y.copy(), U.copy()
    if edge >= _FULL_BAND * 0.5:
        return Y, U
    sos = butter(4, edge / 0.5, output="sos")
    for a, b in _segments(starts, h):
        pad = min(3 * (2 * len(sos) + 1), b - a - 1)
        if pad > 0:
            Y[a:b] = sosfiltfilt(sos, Y[a:b], axis=0, padlen=pad)
            U[a:b] = sosfiltfilt(sos, U[a:b], axis=0, padlen=pad)
    return Y, U


#: Residual given to the initial-condition fit for samples of a diverged run.
_DIVERGED_RESIDUAL = 1e3


def fit_initial_condition(
    residuals, v0: np.ndarray, max_nfev: int | None = None
) -> tuple[np.ndarray, bool, str]:
    """Initial condition whose free run best fits a measured window.

    ``residuals(v)`` returns the free-run errors over the window started from
    the (standardised) initial condition ``v``; NaN where the run diverged.
    This is an output-error fit of the few initial values (consistent under
    white output noise), solved by least squares with a finite-difference
    Jacobian from the rest-like guess ``v0``, in at most ``max_nfev``
    evaluations (default: the solver's, 100 per unknown). Returns ``(v, success,
    message)``: the solver's result, whether it reports convergence, and why
    not.
    """
    from scipy.optimize import least_squares

    def finite(v):
        r = residuals(v)
        return np.where(np.isfinite(r), r, _DIVERGED_RESIDUAL)

    # Fewer measured values than unknowns: Levenberg-Marquardt needs at
    # least as many; the trust-region method finds a minimum-norm step.
    method = "trf" if len(finite(v0)) < len(v0) else "lm"
    result = least_squares(finite, v0, method=method, max_nfev=max_nfev)
    return result.x, bool(result.success), result.message


#: Samples of constant excitation that bring a fitted model to rest before a
#: free run (:func:`rest_check`), the last of them over which its output
#: must stay constant, and by how much it may change there (standardised).
_RUN_IN = 8192
_SETTLED_TAIL = 2048
_SETTLED_TOL = 1e-6
#: A model still moving is on a sustained cycle where the band its output
#: covers over the run-in's last ``_SETTLED_TAIL`` samples and over the
#: ``_SETTLED_TAIL`` before agree, each edge within this share of the band's
#: width: a drift moves the band by its width, a decay narrows it (measured
#: on Silverbox, EMPS and Cascaded Tanks fits: ``rest_check``).
_CYCLE_TOL = 0.1


def rest_check(free_run, n_inputs: int, y_range) -> Bunch:
    """Where a fitted model settles under zero excitation, and the evidence.

    A network's zero state is not its rest: its maps have biases, so a free
    run from zero starts with a transient of the model's own that the
    system, at rest, does not have (on Silverbox tens of millivolts over the
    first hundred samples). The rest of a model is where its free run
    settles under zero excitation, the excitation a free run assumes before
    the first sample: free runs start after ``_RUN_IN`` samples of it. No
    rest where the output still moves over the run-in's last
    ``_SETTLED_TAIL`` samples (an integrating or self-oscillating model),
    diverged, or settled outside ``y_range``, the range of the training
    outputs (zero excitation outside the training excitation, whose rest the
    model extrapolates: on Cascaded Tanks the linear model's rest is -6 V,
    the training outputs span 2.9-10 V); free runs then start from zero as
    in the paper.

    One exception: a model on a sustained cycle within ``y_range`` (the band
    its output covers over the last ``_SETTLED_TAIL`` samples is the band of
    the ``_SETTLED_TAIL`` before, each edge within ``_CYCLE_TOL`` of its
    width) has no rest, but the end of the run-in is a state it keeps
    returning to, and free runs start there (``"cycle"``). From zero, such
    a model starts with its own transient: a Silverbox ISSM circling 1.4 mV
    wide tested at 16.7 mV on the arrow from zero and 0.68 mV after the
    run-in. A drifting model (an integrator's) moves its band by its width
    and a settling one narrows it: both still start from zero.

    ``free_run(X)`` returns the standardised free-run output of one sequence
    from the zero initial conditions and whether it diverged; ``y_range``
    is ``(lowest, highest)`` standardised training output, per output.
    Returns a Bunch (standardised units) with ``output`` (the rest, or
    None), ``start`` (``"rest"``, ``"cycle"`` or ``"zero"``), ``reason``
    (one sentence), ``end`` (the output at the end of the run-in; NaN where
    it diverged), ``change`` (per output, the largest distance from ``end``
    over the run-in's last ``_SETTLED_TAIL`` samples; inf where it
    diverged), ``diverged`` and ``cycling`` (on a sustained cycle, within
    ``y_range`` or not).

    Examples
    --------
    >>> import numpy as np
    >>> def drifting(X):  # an integrator under zero excitation
    ...     return np.linspace(0.0, 1.0, len(X))[:, None], False
    >>> check = rest_check(drifting, 1, (np.array([-2.0]), np.array([2.0])))
    >>> check.start, check.reason
    ('zero', 'still moving over the last 2048 samples of the run-in')
    >>> def circling(X):  # a self-oscillating model
    ...     return 0.1 * np.sin(0.3 * np.arange(len(X)))[:, None], False
    >>> rest_check(circling, 1, (np.array([-2.0]), np.array([2.0]))).start
    'cycle'
    """
    Y, diverged = free_run(np.zeros((_RUN_IN, n_inputs)))
    tail = Y[-_SETTLED_TAIL:]
    end = tail[-1].copy()
    with np.errstate(invalid="ignore"):
        change = np.max(np.abs(tail - end), axis=0)
    diverged = bool(diverged) or not np.all(np.isfinite(tail))
    start, cycling = "zero", False
    if diverged:
        end, change = np.full_like(end, np.nan), np.full_like(end, np.inf)
        reason = "the run-in under zero excitation diverged"
    elif not np.all(change <= _SETTLED_TOL):
        reason = f"still moving over the last {_SETTLED_TAIL} samples of the run-in"
        cycling = _on_cycle(Y[-2 * _SETTLED_TAIL : -_SETTLED_TAIL], tail)
        inside = np.all(
            (y_range[0] <= tail.min(axis=0)) & (tail.max(axis=0) <= y_range[1])
        )
        if cycling and inside:
            start = "cycle"
            reason = (
                f"on a sustained cycle within the range of the training outputs "
                f"over the last {2 * _SETTLED_TAIL} samples of the run-in"
            )
        elif cycling:
            reason = (
                f"on a sustained cycle beyond the range of the training outputs "
                f"over the last {2 * _SETTLED_TAIL} samples of the run-in"
            )
    elif not np.all((y_range[0] <= end) & (end <= y_range[1])):
        reason = "settled outside the range of the training outputs"
    else:
        start, reason = "rest", "settled within the range of the training outputs"
    return Bunch(
        output=end.copy() if start == "rest" else None,
        start=start,
        reason=reason,
        end=end,
        change=change,
        diverged=diverged,
        cycling=cycling,
    )


def free_run_from(est, w: np.ndarray, origin=None, level=0.0):
    """``free_run(X)`` of :func:`rest_check` for ``est`` with the weights
    ``w``: the standardised free run of one sequence ``X`` (user units),
    shifted by the excitation ``level``, from the initial conditions
    ``origin`` (``(initial, initial_inputs)`` in the user's units, as
    :meth:`simulate` takes them; None: zero), and whether it diverged."""
    initial, past = origin_conditions(origin, 1)

    def free_run(X):
        data = est._stack([X + level], None, initial, past)
        Yhat, _, diverged = est._free_run(data, initial, w=w)
        return Yhat[data.h :], bool(diverged[0] >= 0)

    return free_run


def origin_conditions(origin, n_seq: int) -> tuple:
    """``(initial, initial_inputs)``, one of each per sequence, of ``n_seq``
    sequences starting from ``origin`` (see :func:`free_run_from`);
    ``(None, None)`` for the zero state."""
    if origin is None:
        return None, None
    return [origin[0]] * n_seq, [origin[1]] * n_seq


def _on_cycle(before: np.ndarray, last: np.ndarray) -> bool:
    """Whether two windows of a run cover the same band.

    Per output, each edge of the band of ``last`` lies within ``_CYCLE_TOL``
    of the width of the band of ``before`` from its edge: a sustained
    cycle, neither drifting nor decaying.
    """
    lo, hi = before.min(axis=0), before.max(axis=0)
    width = hi - lo
    same = (np.abs(last.min(axis=0) - lo) <= _CYCLE_TOL * width) & (
        np.abs(last.max(axis=0) - hi) <= _CYCLE_TOL * width
    )
    return bool(np.all(same))


def training_end(est, data: _Data) -> tuple | None:
    """The initial conditions ``(initial, initial_inputs)`` (user units)
    where the fitted ``est``'s free run over the longest record of ``data``,
    from the record's own start, ends; None where it diverged."""
    s = _longest(data)
    Yhat, _, diverged, state = est._run(
        est.coefs_, data, _FREE_RUN, False, keep_state=False
    )
    if diverged[s] >= 0:
        return None
    end = int(data.starts[s + 1])
    past = data.U[end - data.h : end] * est._x_scale + est._x_mean
    return est._conditions_at(Yhat, state, data, s), past


def _longest(data: _Data) -> int:
    return int(np.argmax(np.diff(data.starts)))


def _check_from(est, origin) -> Bunch:
    """:func:`rest_check` of ``est``'s weights with the run-in from ``origin``
    (see :func:`free_run_from`)."""
    run = free_run_from(est, est.coefs_, origin)
    return rest_check(run, est.n_features_in_, est._y_range)


def run_in_origin(est, data: _Data) -> tuple:
    """Where the fitted ``est``'s run-in starts, and the evidence.

    From where its free run over the longest record of ``data`` ends
    (:func:`training_end`) where the run-in from there finds a rest or a
    cycle and the run-in from the zero state does not, or finds another
    rest (a network can have two, and the zero state need not lie in the
    basin of the system's) and the free run over that record started there
    fits it better (an integrator's rests are a continuum: the training
    record's end is one of them but not where its records start). From
    the zero state otherwise: a model with one rest, or one cycle, reaches
    it from there, as before. Returns the origin (None: the zero state),
    the :func:`rest_check` of the run-in from it, and a Bunch:
    ``training_start`` (the start the run-in from the training record's
    end found, None where that free run diverged), ``training_end_output``
    (its output at the end of that run-in, standardised) and
    ``record_losses`` (the mean squared standardised misfit of the record's
    free run from the zero state's run-in and from the training end's, or
    None where they were not compared).
    """
    origin = training_end(est, data)
    led = None if origin is None else _check_from(est, origin)
    evidence = Bunch(
        training_start=None if led is None else led.start,
        training_end_output=None if led is None else led.end,
        record_losses=None,
    )
    if led is None or led.start == "zero":
        return None, _check_from(est, None), evidence
    zero = _check_from(est, None)
    if zero.start == "zero":
        return origin, led, evidence
    same = zero.start == led.start and (
        zero.start == "cycle" or np.all(np.abs(zero.end - led.end) <= _SETTLED_TOL)
    )
    if same:
        return None, zero, evidence
    s = _longest(data)
    a, b = data.starts[s] + data.h, data.starts[s + 1]
    X = data.U[a:b] * est._x_scale + est._x_mean
    losses = []
    for start in (None, origin):
        Y, diverged = free_run_from(est, est.coefs_, start)(
            np.concatenate([np.zeros((_RUN_IN, X.shape[1])), X])
        )
        misfit = np.mean((Y[_RUN_IN:] - data.Y[a:b]) ** 2)
        losses.append(np.inf if diverged else float(misfit))
    evidence.record_losses = tuple(losses)
    if losses[1] < losses[0]:
        return origin, led, evidence
    return None, zero, evidence


def estimator_rest_check(est, found: tuple | None = None) -> Bunch:
    """:func:`rest_check` of ``est``'s current weights, in the user's units
    (``rest_check_``), with where its run-in starts.

    ``found``: the check and evidence :func:`run_in_origin` returned for
    the fitted weights, whose origin is ``est._run_in_from``. Without it
    (weights changed since), the run-in starts from ``est._run_in_from``
    where that finds a rest or a cycle, else from the zero state.
    """
    origin = getattr(est, "_run_in_from", None)
    if found is None:
        led = None if origin is None else _check_from(est, origin)
        from_training = led is not None and led.start != "zero"
        check = led if from_training else _check_from(est, None)
        evidence = Bunch(
            training_start=None, training_end_output=None, record_losses=None
        )
    else:
        (check, evidence), from_training = found, origin is not None
    mean, scale = est._y_mean, est._y_scale
    low, high = est._y_range
    end = evidence.training_end_output
    return Bunch(
        start=check.start,
        reason=check.reason,
        cycling=check.cycling,
        output=None if check.output is None else check.output * scale + mean,
        end=check.end * scale + mean,
        change=check.change * scale,
        tolerance=_SETTLED_TOL * scale,
        training_range=(low * scale + mean, high * scale + mean),
        run_in=_RUN_IN,
        run_in_from="training" if from_training else "zero",
        training_start=evidence.training_start,
        training_end_output=None if end is None else end * scale + mean,
        record_losses=evidence.record_losses,
    )
