"""Excitation processes for the hysteretic oscillator (paper section 4.1).

The paper drives the oscillator with unit-intensity Gaussian white noise
``W(t)`` made as a Ruiz-Penzien broken-line process, amplitude-modulated by
``r(t)`` (eq. 18) and filtered through a Kanai-Tajimi soil filter (eq. 16-17).
This module provides each stage, their theoretical second moments for tests
and calibration, and a random-phase multisine as an alternative excitation.

Conventions: time runs along the last axis, ``t_k = k * dt`` for
``k = 0, ..., n_samples - 1``; a function that takes ``n_realizations=None``
returns a 1-D array, an integer gives one row per realisation.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg
import scipy.signal
from numpy.typing import ArrayLike
from sklearn.utils import check_random_state

from sysid_nn._docstrings import fill_doc
from sysid_nn._records._validation import (
    check_finite_array,
    check_positive,
    check_positive_int,
    check_real,
)

__all__ = [
    "broken_line_white_noise",
    "kanai_tajimi",
    "kanai_tajimi_spectrum",
    "kanai_tajimi_variance",
    "modulation",
    "multisine",
    "paper_excitation",
]

#: Two-sided spectral density of unit-intensity white noise:
#: E[W(t) W(t + tau)] = delta(tau).
UNIT_INTENSITY_S0 = 1.0 / (2.0 * np.pi)


# Parameters shared by several functions, documented once.
_FILTER_PARAMETERS = """\
zeta_s : float, default=0.5
    Damping ratio of the filter.
omega_s : float, default=30.0
    Circular eigenfrequency of the filter in rad/s.
s0 : float, default=1/(2 pi)
    Two-sided spectral density of the input white noise.
dt : float or None, default=None
    Ordinate spacing of a broken-line input; ``None`` for ideal white noise.
""".rstrip("\n")
_RECORD_PARAMETERS = """\
n_realizations : int or None, default=None
    Number of independent records; ``None`` returns a single 1-D record.
random_state : int, RandomState instance or None, default=None
    Seed or generator, converted with :func:`sklearn.utils.check_random_state`.
""".rstrip("\n")
_document_filter = fill_doc(filter_parameters=_FILTER_PARAMETERS)
_document_records = fill_doc(record_parameters=_RECORD_PARAMETERS)


def _check_t1_t2(t1: float, t2: float) -> tuple[float, float]:
    t1 = check_positive(t1, "t1")
    t2 = check_positive(t2, "t2")
    if t2 <= t1:
        raise ValueError(
            f"t2 must be larger than t1 (t2 is when the intensity has dropped to half "
            f"after its maximum at t1), got t1={t1!r}, t2={t2!r}; pass t2 > t1."
        )
    return t1, t2


def _shape(n_samples: int, n_realizations: int | None) -> tuple[int, ...]:
    # None keeps the 1-D shape of a single record, an int adds a row axis.
    n_samples = check_positive_int(n_samples, "n_samples")
    if n_realizations is None:
        return (n_samples,)
    return (check_positive_int(n_realizations, "n_realizations"), n_samples)


def modulation(
    t: ArrayLike, r0: float = 1.0, t1: float = 3.0, t2: float = 15.0
) -> np.ndarray:
    """Deterministic modulation function r(t) of Saragoni & Hart (paper eq. 18).

    .. math::

        r(t) = r_0 \\exp\\left(-\\ln 2\\,
        \\frac{t/t_1 - \\ln(t/t_1) - 1}{t_2/t_1 - \\ln(t_2/t_1) - 1}\\right)

    It rises from ``r(0) = 0`` (the limit ``t -> 0+``) to its maximum
    ``r(t1) = r0`` and decays to ``r(t2) = r0 / 2``. It is evaluated in the
    equivalent form ``r0 (t/t1)**c exp(-c (t/t1 - 1))`` with
    ``c = ln 2 / (t2/t1 - ln(t2/t1) - 1)``, which is exact at ``t = 0``.
    Times ``t <= 0`` (before the excitation starts) give 0.

    Parameters
    ----------
    t : array-like of float
        Times in seconds.
    r0 : float, default=1.0
        Maximum intensity (the strength of the excitation), ``r0 >= 0``.
    t1 : float, default=3.0
        Time of maximum intensity, ``t1 > 0``.
    t2 : float, default=15.0
        Time at which the intensity has dropped to half its maximum, ``t2 > t1``.

    Returns
    -------
    ndarray of float
        ``r(t)``, same shape as ``t``.

    Examples
    --------
    >>> from sysid_nn.excitation import modulation
    >>> modulation([0.0, 3.0, 15.0], r0=2.0)
    array([0., 2., 1.])
    """
    r0 = check_positive(r0, "r0", allow_zero=True)
    t1, t2 = _check_t1_t2(t1, t2)
    t = check_finite_array(t, "t", ndim=(0, 1, 2), min_samples=0)
    c = np.log(2.0) / (t2 / t1 - np.log(t2 / t1) - 1.0)
    u = np.maximum(t / t1, 0.0)
    # u**c is 0 at u = 0, the limit of eq. 18; no log(0) is evaluated.
    return r0 * u**c * np.exp(-c * (u - 1.0))


@_document_records
def broken_line_white_noise(
    n_samples: int,
    dt: float,
    n_realizations: int | None = None,
    random_state: int | np.random.RandomState | None = None,
) -> np.ndarray:
    """Unit-intensity Gaussian white noise as a Ruiz-Penzien broken-line process.

    The process is made of independent zero-mean Gaussian ordinates at the
    sample times ``t_k = k dt``, linearly interpolated in between. Its
    autocovariance (averaged over the phase of the grid) integrates to
    ``sigma**2 dt``, so its two-sided spectral density at low frequency is
    ``sigma**2 dt / (2 pi)``. Choosing ``sigma**2 = 1 / dt`` gives the
    spectral density ``1 / (2 pi)`` of unit-intensity white noise
    (``E[W(t) W(t + tau)] = delta(tau)``) independently of ``dt``; above
    about ``1 / (4 dt)`` Hz the spectrum rolls off as ``sinc(omega dt / 2)**4``.

    Only the ordinates are returned; the linear interpolation between them is
    what :func:`kanai_tajimi` integrates exactly.

    Parameters
    ----------
    n_samples : int
        Number of ordinates (sample times).
    dt : float
        Spacing of the ordinates in seconds.
    %(record_parameters)s

    Returns
    -------
    ndarray of shape (n_samples,) or (n_realizations, n_samples)
        The ordinates, of variance ``1 / dt``.

    Examples
    --------
    >>> from sysid_nn.excitation import broken_line_white_noise
    >>> w = broken_line_white_noise(100_000, 0.01, random_state=0)
    >>> round(float(w.var() * 0.01), 2)
    1.0
    """
    shape = _shape(n_samples, n_realizations)
    dt = check_positive(dt, "dt")
    rng = check_random_state(random_state)
    return rng.standard_normal(shape) / np.sqrt(dt)


def _foh_matrices(
    dt: float, zeta_s: float, omega_s: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Exact first-order-hold discretisation of the Kanai-Tajimi filter.

    With state x = (U, U') and an input u linear on [t_k, t_k+1], the matrix
    exponential of the augmented system [[A, B, 0], [0, 0, 1/dt], [0, 0, 0]]
    gives x_{k+1} = Phi x_k + G0 u_k + G1 u_{k+1}; F = C x.
    """
    a = np.array([[0.0, 1.0], [-(omega_s**2), -2.0 * zeta_s * omega_s]])
    b = np.array([0.0, 1.0])
    m = np.zeros((4, 4))
    m[:2, :2] = a
    m[:2, 2] = b
    m[2, 3] = 1.0 / dt
    e = scipy.linalg.expm(m * dt)
    phi, g_level, g_ramp = e[:2, :2], e[:2, 2], e[:2, 3]
    # u(t) = u_k + (u_{k+1} - u_k) (t - t_k) / dt
    g0 = g_level - g_ramp
    g1 = g_ramp
    c = np.array([omega_s**2, 2.0 * zeta_s * omega_s])
    return phi, g0, g1, c


def _check_filter(zeta_s: float, omega_s: float) -> tuple[float, float]:
    return check_positive(zeta_s, "zeta_s"), check_positive(omega_s, "omega_s")


def kanai_tajimi(
    w: ArrayLike,
    dt: float,
    zeta_s: float = 0.5,
    omega_s: float = 30.0,
    r: ArrayLike | None = None,
) -> np.ndarray:
    """Kanai-Tajimi filtered excitation F(t) (paper eq. 16-17).

    Solves ``U'' + 2 zeta_s omega_s U' + omega_s**2 U = -r(t) W(t)`` from rest
    (``U(0) = U'(0) = 0``) and returns
    ``F = 2 zeta_s omega_s U' + omega_s**2 U`` at the sample times. The input
    ``-r W`` is taken as linear between its sample values (the broken-line
    process; for the modulated input this linearises the slowly varying
    ``r(t)`` over one step), and for such an input the result is exact: the
    linear two-state filter is discretised with a first-order hold (matrix
    exponential of the augmented system) and run as a recursive filter along
    the last axis of every row at once.

    Parameters
    ----------
    w : array-like of shape (n_samples,) or (n_realizations, n_samples)
        Ordinates of the white noise W at ``t_k = k dt``.
    dt : float
        Sample spacing in seconds.
    zeta_s : float, default=0.5
        Damping ratio of the soil layer, ``> 0``.
    omega_s : float, default=30.0
        Circular eigenfrequency of the soil layer in rad/s, ``> 0``.
    r : array-like of shape (n_samples,) or None, default=None
        Modulation ``r(t_k)`` (see :func:`modulation`); ``None`` means
        ``r = 1`` (stationary input).

    Returns
    -------
    ndarray, same shape as ``w``
        The excitation F at the sample times; ``F[..., 0] = 0``.

    Examples
    --------
    A unit step input gives a force that settles at the static value 1:

    >>> import numpy as np
    >>> from sysid_nn.excitation import kanai_tajimi
    >>> f = kanai_tajimi(-np.ones(400), 0.01)
    >>> round(float(f[-1]), 6)
    1.0
    """
    w = check_finite_array(w, "w", ndim=(1, 2))
    dt = check_positive(dt, "dt")
    zeta_s, omega_s = _check_filter(zeta_s, omega_s)
    u = -w
    if r is not None:
        r = check_finite_array(r, "r", ndim=1)
        if r.shape[0] != w.shape[-1]:
            raise ValueError(
                f"r must have one value per sample of w ({w.shape[-1]}), got "
                f"{r.shape[0]}; evaluate the modulation at the sample times of w."
            )
        u = u * r
    phi, g0, g1, c = _foh_matrices(dt, zeta_s, omega_s)
    # F = H0(z) u + H1(z) v with v the input with its first sample removed:
    # x_{k+1} = Phi x_k + G0 u_k + G1 u_{k+1} from x_0 = 0 (derivation in
    # _foh_matrices); both are proper transfer functions with one denominator.
    b0, den = scipy.signal.ss2tf(phi, g0[:, None], c[None, :], np.zeros((1, 1)))
    b1, _ = scipy.signal.ss2tf(
        phi, g1[:, None], (c @ phi)[None, :], np.array([[c @ g1]])
    )
    v = u.copy()
    v[..., 0] = 0.0
    f = scipy.signal.lfilter(b0[0], den, u, axis=-1) + scipy.signal.lfilter(
        b1[0], den, v, axis=-1
    )
    # H0 has a one-step delay and v starts at 0, so F[0] = C x_0 = 0 exactly;
    # a rounding residue there is removed for clarity.
    f[..., 0] = 0.0
    return f


@_document_filter
def kanai_tajimi_spectrum(
    omega: ArrayLike,
    zeta_s: float = 0.5,
    omega_s: float = 30.0,
    s0: float = UNIT_INTENSITY_S0,
    dt: float | None = None,
) -> np.ndarray:
    """Two-sided auto-spectral density of the stationary Kanai-Tajimi excitation.

    .. math::

        S_{FF}(\\omega) = S_0\\,
        \\frac{\\omega_s^4 + 4\\zeta_s^2\\omega_s^2\\omega^2}
        {(\\omega_s^2 - \\omega^2)^2 + 4\\zeta_s^2\\omega_s^2\\omega^2}

    for white noise ``W`` of two-sided spectral density ``s0`` and ``r = 1``.
    With ``dt`` given, the input is the broken-line process of
    :func:`broken_line_white_noise` (phase-averaged), whose spectrum carries
    the extra factor ``sinc(omega dt / 2)**4``.

    Parameters
    ----------
    omega : array-like of float
        Circular frequencies in rad/s.
    %(filter_parameters)s

    Returns
    -------
    ndarray of float
        ``S_FF(omega)``, same shape as ``omega``.

    Examples
    --------
    >>> from sysid_nn.excitation import kanai_tajimi_spectrum
    >>> float(kanai_tajimi_spectrum(0.0, s0=1.0))
    1.0
    """
    zeta_s, omega_s = _check_filter(zeta_s, omega_s)
    s0 = check_positive(s0, "s0")
    omega = check_finite_array(omega, "omega", ndim=(0, 1, 2), min_samples=0)
    w2 = omega**2
    damp = 4.0 * zeta_s**2 * omega_s**2 * w2
    s = s0 * (omega_s**4 + damp) / ((omega_s**2 - w2) ** 2 + damp)
    if dt is not None:
        dt = check_positive(dt, "dt")
        s = s * np.sinc(omega * dt / (2.0 * np.pi)) ** 4
    return s


@_document_filter
def kanai_tajimi_variance(
    zeta_s: float = 0.5,
    omega_s: float = 30.0,
    s0: float = UNIT_INTENSITY_S0,
    dt: float | None = None,
) -> float:
    """Stationary variance of the Kanai-Tajimi excitation F for ``r = 1``.

    Without ``dt``, the closed form for ideal white noise of two-sided
    spectral density ``s0``: with ``E[U^2] = pi s0 / (2 zeta_s omega_s^3)``,
    ``E[U'^2] = pi s0 / (2 zeta_s omega_s)`` and ``E[U U'] = 0``,

    .. math::

        \\sigma_F^2 = \\pi S_0 \\omega_s \\frac{1 + 4\\zeta_s^2}{2\\zeta_s}

    (``omega_s (1 + 4 zeta_s**2) / (4 zeta_s)`` for unit intensity; 30 for
    the paper's filter). With ``dt``, the exact variance at the sample times
    of :func:`kanai_tajimi` driven by :func:`broken_line_white_noise` (ordinate
    variance ``2 pi s0 / dt``), from the discrete Lyapunov equation of the
    first-order-hold recursion. It is lower (27.56 instead of 30 at
    ``dt = 0.01`` for the paper's filter) because the broken line carries less
    power at high frequency, where this filter does not cut off.

    Parameters
    ----------
    %(filter_parameters)s

    Returns
    -------
    float
        The stationary variance of F.

    Examples
    --------
    >>> from sysid_nn.excitation import kanai_tajimi_variance
    >>> kanai_tajimi_variance()
    30.0
    >>> round(kanai_tajimi_variance(dt=0.01), 2)
    27.56
    """
    zeta_s, omega_s = _check_filter(zeta_s, omega_s)
    s0 = check_positive(s0, "s0")
    if dt is None:
        return float(np.pi * s0 * omega_s * (1.0 + 4.0 * zeta_s**2) / (2.0 * zeta_s))
    dt = check_positive(dt, "dt")
    phi, g0, g1, c = _foh_matrices(dt, zeta_s, omega_s)
    # y_k = (x_k, u_k): y_{k+1} = A y_k + B u_{k+1}, u iid of variance 2 pi s0 / dt.
    a = np.zeros((3, 3))
    a[:2, :2] = phi
    a[:2, 2] = g0
    b = np.array([g1[0], g1[1], 1.0])
    p = scipy.linalg.solve_discrete_lyapunov(
        a, np.outer(b, b) * (2.0 * np.pi * s0 / dt)
    )
    return float(c @ p[:2, :2] @ c)


@_document_records
def multisine(
    n_samples: int,
    dt: float,
    f_min: float,
    f_max: float,
    rms: float = 1.0,
    n_realizations: int | None = None,
    random_state: int | np.random.RandomState | None = None,
) -> np.ndarray:
    """Random-phase multisine with a flat amplitude spectrum.

    Every frequency of the FFT grid ``k / (n_samples dt)`` in
    ``[f_min, f_max]`` (the DC and Nyquist bins excluded, they cannot carry a
    random phase) gets unit amplitude and an independent phase uniform on
    ``[0, 2 pi)``; the record is one period and is scaled to the given RMS.

    Parameters
    ----------
    n_samples : int
        Number of samples (one period).
    dt : float
        Sample spacing in seconds.
    f_min, f_max : float
        Frequency band in Hz, ``0 <= f_min <= f_max <= 1 / (2 dt)``.
    rms : float, default=1.0
        Root-mean-square value of each record, ``> 0``.
    %(record_parameters)s

    Returns
    -------
    ndarray of shape (n_samples,) or (n_realizations, n_samples)
        The multisine, one row per realisation, with the requested RMS.

    Examples
    --------
    >>> import numpy as np
    >>> from sysid_nn.excitation import multisine
    >>> u = multisine(1000, 0.01, 0.5, 5.0, rms=2.0, random_state=0)
    >>> round(float(np.sqrt(np.mean(u**2))), 12)
    2.0
    """
    shape = _shape(n_samples, n_realizations)
    dt = check_positive(dt, "dt")
    f_min = check_positive(f_min, "f_min", allow_zero=True)
    f_max = check_positive(f_max, "f_max")
    rms = check_positive(rms, "rms")
    nyquist = 0.5 / dt
    if f_min > f_max or f_max > nyquist:
        raise ValueError(
            f"f_min and f_max must satisfy 0 <= f_min <= f_max <= 1/(2 dt) = "
            f"{nyquist:g} Hz, got f_min={f_min!r}, f_max={f_max!r}; adjust the band."
        )
    n = shape[-1]
    freqs = np.fft.rfftfreq(n, dt)
    bins = np.flatnonzero((freqs >= f_min) & (freqs <= f_max))
    bins = bins[(bins > 0) & ~((n % 2 == 0) & (bins == n // 2))]
    if bins.size == 0:
        raise ValueError(
            f"no FFT frequency (resolution {1.0 / (n * dt):g} Hz) lies in "
            f"[f_min, f_max] = [{f_min:g}, {f_max:g}] Hz; widen the band or "
            f"increase n_samples."
        )
    rng = check_random_state(random_state)
    phases = rng.uniform(0.0, 2.0 * np.pi, size=(*shape[:-1], bins.size))
    spectrum = np.zeros((*shape[:-1], freqs.size), dtype=complex)
    spectrum[..., bins] = np.exp(1j * phases)
    u = np.fft.irfft(spectrum, n=n, axis=-1)
    return u * (rms / np.sqrt(np.mean(u**2, axis=-1, keepdims=True)))


@_document_records
def paper_excitation(
    n_samples: int,
    dt: float,
    r0: float = 1.0,
    t1: float = 3.0,
    t2: float = 15.0,
    zeta_s: float = 0.5,
    omega_s: float = 30.0,
    n_realizations: int | None = None,
    random_state: int | np.random.RandomState | None = None,
) -> np.ndarray:
    """The paper's earthquake-like excitation: W -> r(t) W -> Kanai-Tajimi -> F.

    Composes :func:`broken_line_white_noise`, :func:`modulation` and
    :func:`kanai_tajimi` (paper eq. 16-18). The result is linear in ``r0``:
    ``paper_excitation(..., r0=a)`` equals ``a`` times the ``r0=1`` record
    for the same ``random_state``.

    Parameters
    ----------
    n_samples : int
        Number of samples.
    dt : float
        Sample spacing in seconds.
    r0 : float, default=1.0
        Maximum intensity of the modulation, ``>= 0``.
    t1, t2 : float, default=3.0, 15.0
        Time of maximum intensity and of half intensity, ``0 < t1 < t2``.
    zeta_s, omega_s : float, default=0.5, 30.0
        Damping ratio and circular eigenfrequency (rad/s) of the soil filter.
    %(record_parameters)s

    Returns
    -------
    ndarray of shape (n_samples,) or (n_realizations, n_samples)
        The excitation F at ``t_k = k dt``.

    Examples
    --------
    >>> from sysid_nn.excitation import paper_excitation
    >>> f = paper_excitation(2000, 0.01, n_realizations=3, random_state=0)
    >>> f.shape
    (3, 2000)
    """
    r0 = check_real(r0, "r0")
    w = broken_line_white_noise(n_samples, dt, n_realizations, random_state)
    r = modulation(np.arange(w.shape[-1]) * dt, r0=r0, t1=t1, t2=t2)
    return kanai_tajimi(w, dt, zeta_s=zeta_s, omega_s=omega_s, r=r)
