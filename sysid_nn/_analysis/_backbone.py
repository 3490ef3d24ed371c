"""Equivalent frequency and damping against response amplitude (backbone).

The model (or a generator, for reference) is driven by one period of a sine
strong enough to reach beyond the largest amplitude asked for, and its free
decay is analysed by the Hilbert transform: the analytic signal's phase
gives the damped period and its envelope the amplitude and decay rate, over
whole periods as the decay passes each amplitude.
"""

from __future__ import annotations

import math
import numbers

import numpy as np
import pandas as pd
from scipy.signal import butter, hilbert, sosfiltfilt

from sysid_nn._analysis._modal import (
    _check_dt,
    check_fitted_network,
    modal_parameters,
)

__all__ = ["backbone"]

#: The excitation is one period of a sine at the first mode's frequency: a
#: pulse of one sign left the hysteretic oscillator with a permanent set
#: larger than its oscillation; a longer burst tuned to the linear mode
#: made the response a non-monotonic function of the strength as the
#: structure softened out of tune.
_BURST_CYCLES = 1
#: The free decay's first reading is at this multiple of the largest
#: amplitude asked for...
_OVERSHOOT = 1.2
#: ... and the record runs until the linear decay reaches this share of
#: the smallest, plus :data:`_MARGIN_CYCLES` periods at each end.
_UNDERSHOOT = 0.5
_MARGIN_CYCLES = 4
#: Longest simulated record, in samples.
_MAX_SAMPLES = 2**17
#: Steps of the burst's strength, and their factor.
_MAX_STEPS = 16
_STEP = 1.25
#: Half periods per analysis window.
_SPAN = 2
#: Strength of a generator's probing burst (its excitation's units): far
#: below the yield of the generators' defaults.
_PROBE = 1e-4


def _generator_sim(gen, dt, output, response):
    """``(simulate(F), probe, f1, zeta1, f2)`` of a HystereticOscillator or
    ShearBuilding: the probe's strength, the first mode's frequency and
    damping ratio, the second mode's frequency (None with one)."""
    if hasattr(gen, "modal_properties"):
        modes = gen.modal_properties()
        f = modes.frequency
        names = (response,)

        def sim(F):
            return gen.simulate(F, dt, outputs=names)[response][:, output]

        second = float(f[1]) if len(f) > 1 else None
        return sim, _PROBE, float(f[0]), float(modes.damping_ratio[0]), second

    def sim(F):
        return getattr(gen.simulate(F, dt), response)

    params = gen._physical_params()
    return sim, _PROBE, params["omega0"] / (2 * math.pi), params["zeta"], None


def _model_sim(est, dt, output, input):
    """``(simulate(F), probe, f1, zeta1, f2)`` of a fitted network (burst on
    ``input``; the probe's strength a hundredth of the input's spread)."""
    modes = modal_parameters(est, dt)
    modes = modes[modes.structural]
    if not len(modes) or not modes.damping_ratio.iloc[0] > 0:
        raise ValueError(
            "The model's linearisation at rest has no decaying structural mode "
            "(see sysid_nn.modal_parameters): it has no free decay to analyse."
        )
    m = est.n_features_in_

    def sim(F):
        X = np.zeros((len(F), m))
        X[:, input] = F
        y = est.simulate(X)
        return y if y.ndim == 1 else y[:, output]

    second = float(modes.frequency_hz.iloc[1]) if len(modes) > 1 else None
    f1, zeta1 = float(modes.frequency_hz.iloc[0]), float(modes.damping_ratio.iloc[0])
    return sim, 0.01 * float(est._x_scale[input]), f1, zeta1, second


def _centred(y: np.ndarray) -> np.ndarray:
    """``y`` minus its midline, the centre of each pair of successive extrema.

    A yielding structure takes a permanent set while it decays; a band-pass
    filter turns that step into an oscillation of its own that beats with
    the decay, the midline follows it.
    """
    d = np.diff(y)
    ext = np.flatnonzero(np.sign(d[1:]) * np.sign(d[:-1]) < 0) + 1
    if len(ext) < 3:
        return y - y.mean()
    mid_t = 0.5 * (ext[1:] + ext[:-1])
    mid_y = 0.5 * (y[ext[1:]] + y[ext[:-1]])
    return y - np.interp(np.arange(len(y)), mid_t, mid_y)


def _band(y, dt, f1, f2):
    """The envelope and unwrapped phase of ``y`` low-passed below mode 2."""
    nyq = 0.5 / dt
    high = math.sqrt(f1 * f2) if f2 is not None else 2.0 * f1
    if high < 0.9 * nyq:
        y = sosfiltfilt(butter(4, high / nyq, output="sos"), y)
    analytic = hilbert(_centred(y))
    return np.abs(analytic), np.unwrap(np.angle(analytic))


def _decay(sim, s0, dt, f1, zeta1, f2, amplitudes):
    """The readings of the free decay whose first reading is above them all.

    Returns ``(amp, f_n, zeta, strength)`` (see :func:`_windows`): the
    burst's strength grows until the first reading's amplitude is
    :data:`_OVERSHOOT` times the largest asked for, or stops growing.
    """
    period = 1.0 / f1
    lead = round(_MARGIN_CYCLES * period / dt)
    burst = round(_BURST_CYCLES * period / dt)
    a_max, a_min = float(np.max(amplitudes)), float(np.min(amplitudes))
    ratio = _OVERSHOOT * a_max / (_UNDERSHOOT * a_min)
    decay = math.log(ratio) / (max(zeta1, 1e-4) * 2 * math.pi * f1)
    n = lead + burst + round(decay / dt) + 2 * lead
    if n > _MAX_SAMPLES:
        raise ValueError(
            f"The free decay from {a_max:.3g} to {a_min:.3g} at the linear "
            f"damping ratio {zeta1:.3g} takes more than {_MAX_SAMPLES} samples "
            "of dt; narrow the range of amplitudes."
        )
    shape = np.sin(2 * math.pi * f1 * dt * np.arange(burst))
    start = lead + burst  # the free decay

    def run(strength):
        F = np.zeros(n)
        F[lead:start] = strength * shape
        y = np.asarray(sim(F), dtype=np.float64)
        if not np.all(np.isfinite(y)):
            return None, np.nan
        env, phase = _band(y, dt, f1, f2)
        read = _windows(env, phase, dt, start, n - lead)
        return read, (read[0][0] if len(read[0]) else 0.0)

    # A weak burst first, where the response is linear in the strength,
    # then stronger ones in steps until the first reading passes the
    # target: a yielding structure's first reading grows ever more slowly
    # with the strength, and falls once the burst throws it far beyond
    # yield (its decay is then a drift); the last reading that still grew
    # is kept.
    target = _OVERSHOOT * a_max
    _, first = run(s0)
    if not first > 0:
        raise ValueError(
            "The burst gave no free decay to read: the output does not oscillate."
        )
    strength = s0 * target / first
    kept = None
    for _ in range(_MAX_STEPS):
        read, first = run(strength)
        if not first > 0 or (kept is not None and first <= kept[0][0][0]):
            break
        kept = (read, strength)
        if first >= target:
            break
        strength *= _STEP
    if kept is None:
        raise ValueError(
            "The burst gave no free decay to read: the free run diverged or "
            "does not oscillate after it."
        )
    return (*kept[0], kept[1])


def _windows(env, phase, dt, start, stop):
    """Amplitude, natural frequency and damping ratio along the free decay.

    The analytic signal's phase cuts the decay into half periods; over each
    window of two of them (a whole period, so that the ripple a
    non-sinusoidal wave leaves on the envelope averages out) the mean
    envelope is the amplitude and the window's length the damped period,
    and the slope of the log amplitude between the windows half a period
    before and after is the decay rate.
    """
    t = np.arange(len(env)) * dt
    ph = np.maximum.accumulate(phase[start:stop])
    levels = np.arange(np.ceil(ph[0] / np.pi), np.floor(ph[-1] / np.pi) + 1) * np.pi
    bounds = np.interp(levels, ph, t[start:stop])
    if len(bounds) < 5:
        return np.empty(0), np.empty(0), np.empty(0)
    lo, hi = bounds[:-_SPAN], bounds[_SPAN:]
    cum = np.concatenate([[0.0], np.cumsum(env[:-1] + env[1:]) * 0.5 * dt])
    area = np.interp(hi, t, cum) - np.interp(lo, t, cum)
    amp, mid, wd = area / (hi - lo), 0.5 * (lo + hi), _SPAN * np.pi / (hi - lo)
    log_a = np.log(amp)
    sigma = -(log_a[2:] - log_a[:-2]) / (mid[2:] - mid[:-2])
    wn = np.hypot(wd[1:-1], sigma)
    return amp[1:-1], wn / (2 * np.pi), sigma / wn


def _read(amp, f_n, zeta, amplitudes) -> np.ndarray:
    """``(frequency, damping)`` where the decay first falls through each amplitude.

    Linear interpolation in log amplitude; NaN outside the decay's range.
    """
    out = np.full((len(amplitudes), 2), np.nan)
    if not len(amp):
        return out
    a = np.log(amp)
    first = np.minimum.accumulate(a)
    keep = np.r_[True, first[1:] < first[:-1]]
    x = a[keep][::-1]  # rising, as np.interp needs
    for i, value in enumerate(np.log(amplitudes)):
        if x[0] <= value <= x[-1]:
            out[i, 0] = np.interp(value, x, f_n[keep][::-1])
            out[i, 1] = np.interp(value, x, zeta[keep][::-1])
    return out


def backbone(
    estimator,
    dt,
    amplitudes=None,
    *,
    output: int = 0,
    input: int = 0,
    response: str = "displacement",
) -> pd.DataFrame:
    """Equivalent natural frequency and damping of the first mode against amplitude.

    The model is driven from rest by one period of a sine at its first
    mode's frequency (from :func:`~sysid_nn.modal_parameters`) on one
    input, strong enough that its free decay starts at twice the largest
    amplitude, and the decay of one output is analysed by the Hilbert
    transform (``scipy.signal.hilbert``): low-passed below the second mode
    (zero-phase Butterworth at the geometric mean of the first two modes'
    frequencies, or twice the first), its midline (the centre of successive
    extrema: a yielding structure takes a permanent set) removed, the
    analytic signal's phase cuts the decay into half periods. Over each
    whole period, sliding by half periods, the mean envelope is the
    amplitude and the period's length gives the damped circular frequency
    ``omega_d``; the slope of the log amplitude between the periods half a
    period before and after gives the decay rate ``sigma``. The equivalent
    natural frequency is ``hypot(omega_d, sigma) / (2 pi)`` and the damping
    ratio ``sigma / hypot(omega_d, sigma)``, read at each amplitude by
    linear interpolation in log amplitude where the decay first passes it:
    at small amplitude those of :func:`~sysid_nn.modal_parameters`, at
    larger ones those of the equivalent linear system (a yielding structure
    softens, its hysteresis damps).

    A free decay cannot stay at an amplitude where the structure loses most
    of it in one period: on the hysteretic oscillator (yield at ``z0``) the
    decay is read up to about ``0.6 z0``; larger amplitudes are NaN.

    The same analysis of a generator's own equations gives the reference:
    ``estimator`` may be a :class:`~sysid_nn.HystereticOscillator` or a
    :class:`~sysid_nn.ShearBuilding` (the burst is its excitation or ground
    acceleration).

    Parameters
    ----------
    estimator : TDLRegressor, ISSMRegressor, HystereticOscillator or ShearBuilding
        A fitted model, or a generator.
    dt : float
        Sampling interval in seconds (of the model's training records).
    amplitudes : array-like of float, default=None
        Response amplitudes (the envelope of the output about its midline,
        in its units) at which to read the frequency and damping. Default,
        for a fitted model: ten from 2 % to 20 % of the training output's
        range (from its lowest to its highest value); required for a
        generator.
    output : int, default=0
        The output analysed (a model's column, or a building's floor or
        storey, bottom first).
    input : int, default=0
        The model input the burst acts on.
    response : str, default="displacement"
        For a generator only: the response analysed (``"displacement"`` or
        ``"velocity"`` of the oscillator; any output of
        :meth:`~sysid_nn.ShearBuilding.simulate`).

    Returns
    -------
    curve : pandas.DataFrame
        One row per amplitude, ascending: ``amplitude``, ``frequency_hz``,
        ``damping_ratio`` (NaN where the free decay does not pass the
        amplitude a period clear of its start). ``attrs`` holds ``dt``, the
        burst's ``strength`` (amplitude of the sine, in the input's units)
        and frequency ``burst_hz``.

    See Also
    --------
    sysid_nn.modal_parameters : The modes of the linearisation at rest.
    sysid_nn.plotting.plot_backbone : Draws the curve.

    Examples
    --------
    The oscillator's own backbone softens with amplitude (yield at 0.01 m):

    >>> from sysid_nn import HystereticOscillator, backbone
    >>> curve = backbone(HystereticOscillator(r0=0.06), 0.01,
    ...                  amplitudes=[0.002, 0.004, 0.006])
    >>> curve.frequency_hz.round(3).tolist()
    [0.977, 0.96, 0.946]
    >>> bool(curve.damping_ratio.is_monotonic_increasing)
    True
    """
    dt = _check_dt(dt)
    generator = hasattr(estimator, "_physical_params") or hasattr(
        estimator, "modal_properties"
    )
    if generator:
        if amplitudes is None:
            raise ValueError(
                "amplitudes must be given for a generator: response amplitudes in "
                "the units of the analysed response (e.g. [0.005, 0.01, 0.02] m)."
            )
        sim, s0, f1, zeta1, f2 = _generator_sim(estimator, dt, output, response)
    else:
        check_fitted_network(estimator)
        for name, value, limit in (
            ("output", output, estimator.n_outputs_),
            ("input", input, estimator.n_features_in_),
        ):
            if (
                isinstance(value, bool)
                or not isinstance(value, numbers.Integral)
                or not 0 <= value < limit
            ):
                raise ValueError(
                    f"{name} must be the index of one of the model's {limit} "
                    f"{name}s (0 to {limit - 1}); got {value!r}."
                )
        sim, s0, f1, zeta1, f2 = _model_sim(estimator, dt, output, input)
        if amplitudes is None:
            low, high = estimator._y_range
            spread = float((high - low)[output] * estimator._y_scale[output])
            amplitudes = spread * np.linspace(0.02, 0.2, 10)
    amps = np.sort(np.asarray(amplitudes, dtype=np.float64).ravel())
    if not amps.size or not np.all(np.isfinite(amps)) or np.any(amps <= 0):
        raise ValueError(
            f"amplitudes must be positive finite response amplitudes; got "
            f"{amplitudes!r}."
        )
    amp, f_n, zeta, strength = _decay(sim, s0, dt, f1, zeta1, f2, amps)
    read = _read(amp, f_n, zeta, amps)
    curve = pd.DataFrame(
        {"amplitude": amps, "frequency_hz": read[:, 0], "damping_ratio": read[:, 1]}
    )
    curve.attrs.update(dt=dt, strength=strength, burst_hz=f1)
    return curve
