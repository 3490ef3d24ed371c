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
and warns above the range where the defaults were measured to work.
"""

from __future__ import annotations

import warnings

import numpy as np
from scipy.signal import welch

from sysid_nn._exceptions import user_stacklevel

#: Samples per fundamental period up to which the defaults were measured to
#: handle clean records of the hysteretic oscillator (benchmarks/
#: bench_records.py: both networks from 20 to 200; at 400 the TDL still, the
#: displacement-only ISSM not). ``fit`` warns above it.
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
            stacklevel=user_stacklevel(),
        )
    return Xs, ys


def samples_per_period(Y: np.ndarray, segments) -> float:
    """Samples per period of the dominant oscillation of the outputs.

    The peak of the power spectrum of the outputs' first difference (each
    column scaled to unit power, averaged over the sequences ``Y[a:b]`` of
    ``segments``): differencing keeps slow drift and offsets, which measured
    displacements carry, from posing as the fundamental. ``nan`` if the
    records are too short or constant, or if the peak lies below
    ``_MIN_PERIODS`` periods per analysis window: that is a slow motion,
    not a resolved oscillation (the EMPS positioning stage reads as about
    7000 samples per period, and decimating it by 12 made both networks
    worse: TDL 0.0157 to 0.0248 m, ISSM 0.0105 to 0.0277 m).

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
    if k < _MIN_PERIODS:
        return float("nan")  # no oscillation resolved: a slow motion
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


#: Decimation keeps at least this many samples of the shortest record (the
#: paper's records have 2000).
_MIN_DECIMATED_LENGTH = 2000
#: Periods of the dominant oscillation an analysis window must hold for it to
#: count as one.
_MIN_PERIODS = 4


def decimation_advice(spp: float, shortest: int) -> str:
    """How to decimate records of ``spp`` samples per period, as a sentence.

    The factor aims at ``_TARGET_SAMPLES_PER_PERIOD`` samples per period and
    keeps ``_MIN_DECIMATED_LENGTH`` samples of the ``shortest`` record; ``""``
    where that leaves no factor of two or more.

    Examples
    --------
    >>> decimation_advice(170.0, 7200).split(": ")[-1]
    'scipy.signal.resample_poly(a, 1, 3, axis=0) on X and y.'
    >>> decimation_advice(7000.0, 24000).split(": ")[-1]  # keeps 2000 samples
    'scipy.signal.resample_poly(a, 1, 12, axis=0) on X and y.'
    >>> decimation_advice(170.0, 3000)
    ''
    """
    k = min(round(spp / _TARGET_SAMPLES_PER_PERIOD), shortest // _MIN_DECIMATED_LENGTH)
    if k < 2:
        return ""  # too few samples per period, or too short a record
    return (
        "Decimate excitation and response alike, with an anti-aliasing filter, "
        f"by about {k} (to some {spp / k:.0f} samples per period): "
        f"scipy.signal.resample_poly(a, 1, {k}, axis=0) on X and y."
    )


def check_sampling(name: str, Y: np.ndarray, segments) -> tuple[float, str]:
    """Samples per period of the outputs, and how to decimate them.

    Warns when they lie above what the defaults were measured to handle.
    Returns ``(spp, advice)`` (``nan`` and ``""`` when it cannot be told).
    """
    spp = samples_per_period(Y, segments)
    if np.isnan(spp):
        return spp, ""
    advice = decimation_advice(spp, min(b - a for a, b in segments))
    if spp > _MAX_SAMPLES_PER_PERIOD:
        todo = advice or "Longer records would allow decimating them."
        warnings.warn(
            f"The training outputs of {name} vary with a dominant period of "
            f"about {spp:.0f} samples (the peak of their spectrum), above the "
            f"{_MAX_SAMPLES_PER_PERIOD:g} the defaults were measured to handle: "
            "the lags and shooting segments, counted in samples, then span a "
            "small part of a period, and the dynamics show only in tiny "
            f"differences between samples. {todo} See the user guide's "
            "pitfalls page on measured records.",
            UserWarning,
            stacklevel=user_stacklevel(),
        )
    return spp, advice
