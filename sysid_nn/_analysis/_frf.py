"""Frequency response of an identified model at small amplitude, and of data.

The model's frequency response function (FRF) is that of its linearisation
at rest (see :mod:`sysid_nn._analysis._modal`): with the state map
``s(t) = A s(t-1) + Q(q) u(t)`` (``Q`` the input's way into the state,
delays included) and the outputs ``C s``, ``H(z) = C (I - A / z)^-1 Q(z)``
evaluated on the unit circle ``z = exp(2 pi i f dt)``. The data's FRF is
Welch's H1 estimate, ``S_yu S_uu^-1``, with the ordinary coherence.
"""

from __future__ import annotations

import numbers

import numpy as np
import pandas as pd
from scipy.signal import csd
from scipy.stats import norm

from sysid_nn._analysis._modal import (
    _check_arguments,
    _document_readout,
    _Linearisation,
    _start_guess,
    _weight_derivatives,
)
from sysid_nn._records._sequences import as_sequence_list, check_paired
from sysid_nn._records._validation import check_positive_int

__all__ = ["frequency_response"]


def _response(lin: _Linearisation, A, j, z: np.ndarray, gain: np.ndarray):
    """``H(z)`` of shape ``(n_freq, n_outputs, n_inputs)`` in the user's units."""
    eye = np.eye(lin.n)
    Q = np.stack([lin.residue_factor(j, zi) for zi in z])
    state = np.linalg.solve(eye - A[None] / z[:, None, None], Q)
    return (lin.C @ state) * gain


def _check_n_freq(n_freq) -> int:
    if check_positive_int(n_freq, "n_freq") < 2:
        raise ValueError(
            f"n_freq must be an integer >= 2, the number of frequencies from 0 to "
            f"the Nyquist frequency; got {n_freq!r}."
        )
    return int(n_freq)


def _welch(X, y, est, dt: float, nperseg):
    """Frequencies, H1 ``(n_freq, p, m)``, coherence ``(n_freq, p, m)``, nperseg.

    The cross spectra are averaged over the segments of all records, so
    that every record counts by its length.
    """
    Xs, _ = as_sequence_list(X, "X", allow_nan=False)
    ys, _ = as_sequence_list(y, "y", allow_nan=False)
    check_paired(Xs, ys, "X", "y")
    m, p = est.n_features_in_, est.n_outputs_
    if Xs[0].shape[1] != m or ys[0].shape[1] != p:
        raise ValueError(
            f"X and y must have the model's {m} input and {p} output columns; got "
            f"{Xs[0].shape[1]} and {ys[0].shape[1]}."
        )
    shortest = min(len(x) for x in Xs)
    if nperseg is None:
        nperseg = min(256, shortest)
    if (
        isinstance(nperseg, bool)
        or not isinstance(nperseg, numbers.Integral)
        or not 8 <= nperseg <= shortest
    ):
        raise ValueError(
            f"nperseg must be an integer from 8 to the shortest record's length "
            f"({shortest} samples), the Welch segment length; got {nperseg!r}."
        )
    nperseg = int(nperseg)
    n_freq = nperseg // 2 + 1
    Suu = np.zeros((n_freq, m, m), dtype=complex)
    Syu = np.zeros((n_freq, p, m), dtype=complex)
    Syy = np.zeros((n_freq, p))
    fs = 1.0 / dt

    def spectrum(a, b):
        # E[conj(A) B], b against the reference a.
        return csd(a, b, fs=fs, nperseg=nperseg)[1]

    for x, yy in zip(Xs, ys, strict=True):
        weight = len(x)
        for k in range(m):
            for i in range(m):
                Suu[:, k, i] += weight * spectrum(x[:, k], x[:, i])
            for i in range(p):
                Syu[:, i, k] += weight * spectrum(x[:, k], yy[:, i])
        for i in range(p):
            Syy[:, i] += weight * spectrum(yy[:, i], yy[:, i]).real
    # S_uy = S_uu H^T, so H1 = (S_uu^-1 S_uy)^T, frequency by frequency.
    h1 = np.linalg.solve(Suu, Syu.transpose(0, 2, 1)).transpose(0, 2, 1)
    suu = np.real(np.diagonal(Suu, axis1=1, axis2=2))
    with np.errstate(invalid="ignore", divide="ignore"):
        coherence = np.abs(Syu) ** 2 / (Syy[:, :, None] * suu[:, None, :])
    freq = np.fft.rfftfreq(nperseg, dt)
    return freq, h1, coherence, nperseg


@_document_readout
def frequency_response(
    estimator,
    dt,
    X=None,
    y=None,
    *,
    n_freq: int = 512,
    level: float = 0.95,
    nperseg: int | None = None,
) -> pd.DataFrame:
    """Frequency response of a fitted model at small amplitude, and of data.

    The model's frequency response function (FRF) is that of its
    linearisation at rest, the one :func:`modal_parameters` reads the modes
    of and :func:`to_dlti` returns: ``H(z) = C (I - A / z)^-1 Q(z)`` on the
    unit circle ``z = exp(2 pi i f dt)``, ``f`` in Hz, from the excitation
    to the outputs in the user's units. For the linear model
    (``hidden_layer_sizes=()``) it is the model's exact FRF; for a network,
    its response to excitations small enough to keep it near its rest. The
    band on the magnitude propagates the weights' covariance
    ``coefs_covariance_`` (see :ref:`uncertainty`) by the delta method, the
    derivatives of ``|H|`` in the weights by central differences of the
    linearisation (relative step 1e-6, the rest found again for each), as
    for the intervals of :func:`modal_parameters` and under the same
    assumptions.

    Given records ``X`` and ``y``, the data's FRF is estimated beside it:
    Welch's H1, ``S_yu S_uu^-1`` (Hann windows of ``nperseg`` samples, half
    overlapping, the spectra of the records averaged with their lengths as
    weights),
    with the ordinary coherence ``|S_yu|^2 / (S_uu S_yy)`` of each
    output-input pair. The model's FRF is then evaluated on Welch's grid.

    Parameters
    ----------
    %(estimator_dt)s
    X : array-like or list of array-like, optional
        Excitation records, of shape ``(n_samples, n_features_in_)`` each.
    y : array-like or list of array-like, optional
        Measured outputs, paired with ``X``.
    n_freq : int, default=512
        Number of frequencies, evenly spaced from 0 to the Nyquist frequency
        ``1 / (2 dt)`` inclusive, without data. With data the grid is
        Welch's, ``nperseg // 2 + 1`` frequencies over the same range.
    level : float, default=0.95
        Probability of the two-sided Gaussian band.
    nperseg : int, optional
        Welch segment length in samples; by default 256 or the shortest
        record's length, whichever is smaller.

    Returns
    -------
    frf : pandas.DataFrame
        One row per frequency and output-input pair, sorted by output,
        input and frequency: ``frequency_hz``; ``output`` and ``input``,
        the column indices; ``response`` (complex), ``magnitude``,
        ``magnitude_low``, ``magnitude_high`` (the band, its lower end at
        least 0) and ``phase_deg`` (in (-180, 180]) of the model; with
        data, ``h1`` (complex), ``h1_magnitude``, ``h1_phase_deg`` and
        ``coherence``. ``attrs`` holds ``dt``, ``level`` and ``nperseg``
        (None without data).

    See Also
    --------
    modal_parameters : The modes of the same linearisation.
    to_dlti : The linearisation as a state-space system.
    sysid_nn.plotting.plot_frequency_response : Draws the table.

    Examples
    --------
    A linear ARX model of a resonance at ``z = 0.9 exp(+-0.3i)`` (4.8 Hz at
    100 Hz sampling), fitted to a record with 5 % output noise:

    >>> import numpy as np
    >>> from scipy.signal import freqz, lfilter
    >>> from sysid_nn import TDLRegressor, frequency_response
    >>> rng = np.random.default_rng(0)
    >>> u = rng.standard_normal((2000, 1))
    >>> b, a = [0.0, 1.0], [1.0, -2 * 0.9 * np.cos(0.3), 0.81]
    >>> y = lfilter(b, a, u[:, 0])
    >>> y = y + 0.05 * y.std() * rng.standard_normal(2000)
    >>> model = TDLRegressor(output_lags=2, input_lags=1, hidden_layer_sizes=(),
    ...                      early_stopping=False, n_init=1,
    ...                      random_state=0).fit(u, y)
    >>> frf = frequency_response(model, 0.01, u, y, nperseg=128)
    >>> float(frf.frequency_hz[frf.magnitude.idxmax()])
    4.6875
    >>> _, truth = freqz(b, a, worN=frf.frequency_hz, fs=100)
    >>> bool(np.all((frf.magnitude_low <= abs(truth))
    ...             & (abs(truth) <= frf.magnitude_high)))
    True
    >>> coherent = frf.coherence > 0.9
    >>> bool(np.allclose(frf.h1[coherent], truth[coherent], rtol=0.1))
    True
    """
    dt = _check_arguments(estimator, dt, level)
    if (X is None) != (y is None):
        raise ValueError(
            "X and y must be given together (the records the data's FRF is "
            "estimated from) or both left None."
        )
    if X is None:
        if nperseg is not None:
            raise ValueError(
                f"nperseg sets the Welch segments of the records X and y; got "
                f"nperseg={nperseg!r} without them. Pass X and y, or drop nperseg."
            )
        freq = np.linspace(0.0, 0.5 / dt, _check_n_freq(n_freq))
    else:
        freq, h1, coherence, nperseg = _welch(X, y, estimator, dt, nperseg)
    lin = _Linearisation(estimator)
    w = np.asarray(estimator.coefs_, dtype=np.float64)
    A, j, rest = lin.state_matrix(w, _start_guess(estimator, lin))
    z = np.exp(2j * np.pi * freq * dt)
    gain = estimator._y_scale[:, None] / estimator._x_scale[None, :]
    H = _response(lin, A, j, z, gain)
    cov = np.asarray(estimator.coefs_covariance_)
    dmag = _weight_derivatives(
        lin, w, cov, rest, lambda A, j: np.abs(_response(lin, A, j, z, gain))
    )
    with np.errstate(invalid="ignore"):
        sd = np.sqrt(np.einsum("...i,ij,...j->...", dmag, cov, dmag))
    half = norm.ppf(0.5 + 0.5 * level) * sd
    mag = np.abs(H)
    p, m = H.shape[1:]
    # Long format: output, input and frequency as the slowest to fastest axes.
    out, inp, fr = np.meshgrid(np.arange(p), np.arange(m), freq, indexing="ij")

    def flat(a):
        return np.moveaxis(a, 0, -1).ravel()

    table = pd.DataFrame(
        {
            "frequency_hz": fr.ravel(),
            "output": out.ravel(),
            "input": inp.ravel(),
            "response": flat(H),
            "magnitude": flat(mag),
            "magnitude_low": flat(np.maximum(mag - half, 0.0)),
            "magnitude_high": flat(mag + half),
            "phase_deg": flat(np.angle(H, deg=True)),
        }
    )
    if X is not None:
        table["h1"] = flat(h1)
        table["h1_magnitude"] = flat(np.abs(h1))
        table["h1_phase_deg"] = flat(np.angle(h1, deg=True))
        table["coherence"] = flat(coherence)
    table.attrs.update(dt=dt, level=float(level), nperseg=nperseg)
    return table
