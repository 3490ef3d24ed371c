"""Checks of measured training records that no model structure can absorb.

Zero-padded ends
----------------
Field records come zero-padded to a common length: the recorder stops, and
the rest of the record is exactly zero in both the excitation and the
response although the structure was still moving. No dynamic model produces
a response that stops dead, so a fit to the padded stretch learns a wrong
model (measured on building-like records: the displacement-only ISSM's
free-run NRMSE went from 0.07 to 1.05). The padding is left out of training,
with a warning.

Sampling ratio
--------------
The default lags and shooting segments are counted in samples, so what they
span of the structure's motion depends on how finely it is sampled. ``fit``
estimates the samples per fundamental period from the outputs' spectrum
and warns outside the range where the defaults were measured to work.
"""

from __future__ import annotations

import warnings

import numpy as np
from scipy.signal import welch

#: Samples per fundamental period the defaults were measured to handle on
#: clean records of the hysteretic oscillator (benchmarks/bench_records.py:
#: both networks from 20 to 200; at 400 the TDL still, the displacement-only
#: ISSM not). ``fit`` warns outside this range; the lower end is where the
#: fundamental nears the Nyquist frequency (2).
_MIN_SAMPLES_PER_PERIOD = 5.0
_MAX_SAMPLES_PER_PERIOD = 250.0
#: A trailing stretch counts as padding from this many samples on: a single
#: exact zero in every column is a coincidence, a run of them is not.
_MIN_PADDING = 2


def padded_length(X: np.ndarray, y: np.ndarray) -> int:
    """Length of the trailing stretch that is exactly zero in ``X`` and ``y``.

    Examples
    --------
    >>> import numpy as np
    >>> X = np.array([[1.0], [2.0], [0.0], [0.0]])
    >>> y = np.array([[0.5], [0.1], [0.0], [0.0]])
    >>> padded_length(X, y)
    2
    """
    nonzero = np.flatnonzero(np.any(X != 0, axis=1) | np.any(y != 0, axis=1))
    return len(X) - (int(nonzero[-1]) + 1 if nonzero.size else 0)


def trim_padding(Xs: list, ys: list, min_len: int, what: str) -> tuple[list, list]:
    """The sequences without their zero-padded ends, with a warning.

    A sequence keeps at least ``min_len`` samples (the shortest any fit
    accepts). ``what`` names the sequences in the warning (``"X"`` or
    ``"X_val"``).
    """
    Xs, ys, cut = list(Xs), list(ys), []
    for i, (Xi, yi) in enumerate(zip(Xs, ys, strict=True)):
        k = min(padded_length(Xi, yi), len(Xi) - min_len)
        if k >= _MIN_PADDING:
            Xs[i], ys[i] = Xi[: len(Xi) - k], yi[: len(yi) - k]
            cut.append(f"sequence {i}: the last {k} of {len(Xi)} samples")
    if cut:
        warnings.warn(
            f"The training records ({what}, y) end in stretches where excitation "
            "and response are both exactly zero, as records zero-padded to a "
            f"common length do ({'; '.join(cut)}). A structure's response "
            "does not stop dead when its record does, so these stretches are "
            "left out of training. Models are fitted to the rest; cut the "
            "padding off yourself to silence this warning.",
            UserWarning,
            stacklevel=4,
        )
    return Xs, ys


def samples_per_period(Y: np.ndarray, segments) -> float:
    """Samples per period of the dominant oscillation of the outputs.

    The peak of the power spectrum of the outputs' first difference (each
    column scaled to unit power, averaged over the sequences ``Y[a:b]`` of
    ``segments``): differencing keeps slow drift and offsets, which measured
    displacements carry, from posing as the fundamental. A peak in the
    lowest frequency bin gives a lower bound. ``nan`` if the records are
    too short or constant.

    Examples
    --------
    >>> import numpy as np
    >>> t = np.arange(4000)
    >>> y = np.sin(2 * np.pi * t / 170)[:, None]
    >>> round(samples_per_period(y, [(0, 4000)]))
    170
    """
    diffs = [np.diff(Y[a:b], axis=0) for a, b in segments if b - a > 16]
    if not diffs:
        return float("nan")
    n = min(8192, min(len(d) for d in diffs))
    power = 0.0
    for d in diffs:
        f, P = welch(d, nperseg=n, axis=0, detrend="constant")
        total = P.sum(axis=0)
        power = power + np.where(total > 0, P / np.maximum(total, 1e-300), 0).sum(1)
    if not np.any(power[1:] > 0):
        return float("nan")
    k = 1 + int(np.argmax(power[1:]))
    peak = f[k]
    if k + 1 < len(f):
        # A parabola through the log power of the peak bin and its
        # neighbours places the peak between bins.
        left, mid, right = np.log(np.maximum(power[k - 1 : k + 2], 1e-300))
        curve = left - 2 * mid + right
        if curve < 0:
            peak += 0.5 * (left - right) / curve * (f[1] - f[0])
    return 1.0 / peak


#: Samples per period that decimation should aim at: the second difference
#: is then a tenth of the signal, not a thousandth (measured, 1 % output noise,
#: 200 samples per period: TDL free-run NRMSE 0.99, ISSM 0.50; decimated to
#: 20: 0.12 and 0.050).
_TARGET_SAMPLES_PER_PERIOD = 20.0


def decimation_advice(spp: float) -> str:
    """How to decimate records with ``spp`` samples per period, as a sentence."""
    k = max(2, round(spp / _TARGET_SAMPLES_PER_PERIOD))
    return (
        "Decimate excitation and response alike, with an anti-aliasing filter, "
        f"by about {k} (to some {_TARGET_SAMPLES_PER_PERIOD:g} samples per "
        f"period): scipy.signal.resample_poly(a, 1, {k}, axis=0) on X and on y."
    )


def check_sampling(name: str, Y: np.ndarray, segments) -> float:
    """Samples per period of the outputs; warn far outside what the defaults handle."""
    spp = samples_per_period(Y, segments)
    if np.isnan(spp) or _MIN_SAMPLES_PER_PERIOD <= spp <= _MAX_SAMPLES_PER_PERIOD:
        return spp
    if spp > _MAX_SAMPLES_PER_PERIOD:
        advice = (
            "The lags and shooting segments, counted in samples, then span a "
            "small part of a period, and the dynamics show only in tiny "
            f"differences between samples. {decimation_advice(spp)}"
        )
    else:
        advice = (
            "The fundamental is then close to the Nyquist frequency and the "
            "records barely resolve it: sample more finely, or low-pass the "
            "records below the fundamental's second harmonic."
        )
    warnings.warn(
        f"The training outputs of {name} oscillate with about {spp:.0f} samples "
        "per period (the peak of their spectrum), outside the "
        f"{_MIN_SAMPLES_PER_PERIOD:g} to {_MAX_SAMPLES_PER_PERIOD:g} the defaults "
        f"were measured to handle. {advice} See the user guide's pitfalls page "
        "on measured records.",
        UserWarning,
        stacklevel=4,
    )
    return spp
