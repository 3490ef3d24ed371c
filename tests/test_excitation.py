"""Tests of the excitation processes against theory (paper eq. 16-18)."""

import numpy as np
import pytest
import scipy.integrate
import scipy.signal

from sysid_nn.excitation import (
    broken_line_white_noise,
    kanai_tajimi,
    kanai_tajimi_spectrum,
    kanai_tajimi_variance,
    modulation,
    multisine,
    paper_excitation,
)

S0 = 1.0 / (2.0 * np.pi)


# ------------------------------------------------------------------ modulation
def test_modulation_key_values():
    r = modulation([0.0, 3.0, 15.0], r0=2.5, t1=3.0, t2=15.0)
    np.testing.assert_allclose(r, [0.0, 2.5, 1.25], rtol=1e-14, atol=0)


def test_modulation_matches_eq18_and_peaks_at_t1():
    t1, t2, r0 = 2.0, 9.0, 0.7
    t = np.linspace(0.01, 40.0, 4000)
    eq18 = r0 * np.exp(
        -np.log(2) * (t / t1 - np.log(t / t1) - 1) / (t2 / t1 - np.log(t2 / t1) - 1)
    )
    r = modulation(t, r0=r0, t1=t1, t2=t2)
    np.testing.assert_allclose(r, eq18, rtol=1e-12)
    assert abs(t[np.argmax(r)] - t1) < 0.011
    assert modulation(-1.0) == 0.0
    # Continuous and increasing at t = 0 (slowly: r ~ t**0.29 for these t1, t2).
    assert 0 < modulation(1e-12) < modulation(1e-9) < 0.01


@pytest.mark.parametrize(("t1", "t2", "name"), [(3.0, 2.0, "t2"), (-1.0, 2.0, "t1")])
def test_modulation_bad_times(t1, t2, name):
    with pytest.raises(ValueError, match=name):
        modulation([1.0], t1=t1, t2=t2)


# ------------------------------------------------------------------ white noise
@pytest.mark.parametrize("dt", [0.01, 0.002])
def test_broken_line_variance_and_low_frequency_density(dt):
    w = broken_line_white_noise(4000, dt, n_realizations=100, random_state=0)
    assert w.shape == (100, 4000)
    # Ordinates: variance 1/dt (relative MC standard error 0.22 %).
    assert w.var() * dt == pytest.approx(1.0, rel=0.01)
    # Welch gives the one-sided density per Hz; the two-sided density per
    # rad/s is that divided by 4 pi. Low band: below a tenth of Nyquist.
    f, p = scipy.signal.welch(w, fs=1 / dt, nperseg=256, detrend=False, axis=-1)
    low = (f > 0) & (f < 0.05 / dt)
    s_low = p[:, low].mean() / (4 * np.pi)
    # ~100 x 31 x 10 averaged periodogram ordinates: MC error well below 1 %.
    assert s_low == pytest.approx(S0, rel=0.03)


def test_broken_line_interpolated_process_has_unit_intensity():
    # The continuous broken line (linear interpolation between the ordinates)
    # must have the low-frequency density 1/(2 pi), not only the ordinates.
    dt, up = 0.01, 8
    w = broken_line_white_noise(2000, dt, n_realizations=100, random_state=1)
    t = np.arange(2000) * dt
    fine_t = np.arange(0, t[-1], dt / up)
    fine = np.array([np.interp(fine_t, t, row) for row in w])
    f, p = scipy.signal.welch(fine, fs=up / dt, nperseg=2048, detrend=False, axis=-1)
    low = (f > 0) & (f < 5.0)
    assert p[:, low].mean() / (4 * np.pi) == pytest.approx(S0, rel=0.03)
    # Above the ordinate rate the interpolated spectrum rolls off (sinc^4).
    high = (f > 0.9 / dt) & (f < 1.1 / dt)
    assert p[:, high].mean() / (4 * np.pi) < 0.01 * S0


def test_broken_line_reproducible():
    a = broken_line_white_noise(50, 0.01, random_state=3)
    b = broken_line_white_noise(50, 0.01, random_state=3)
    c = broken_line_white_noise(50, 0.01, random_state=4)
    assert a.shape == (50,)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


# ---------------------------------------------------------------- Kanai-Tajimi
def test_kanai_tajimi_exact_for_piecewise_linear_input():
    zs, ws, dt, n = 0.5, 30.0, 0.01, 600
    w = broken_line_white_noise(n, dt, n_realizations=3, random_state=0)
    t = np.arange(n) * dt
    r = modulation(t, r0=0.3)
    f = kanai_tajimi(w, dt, zeta_s=zs, omega_s=ws, r=r)
    sys = ([[0, 1], [-(ws**2), -2 * zs * ws]], [[0], [1]], [[ws**2, 2 * zs * ws]], 0)
    for i in range(3):
        # lsim with interp=True is exact for a linearly interpolated input.
        _, ref, _ = scipy.signal.lsim(sys, -r * w[i], t, interp=True)
        np.testing.assert_allclose(f[i], ref, rtol=0, atol=1e-10 * np.abs(ref).max())
    # 1-D input gives the same as a row of the 2-D input.
    np.testing.assert_allclose(kanai_tajimi(w[1], dt, r=r), f[1], rtol=1e-13)


def test_kanai_tajimi_closed_form_variance_matches_spectrum_integral():
    for zs, ws in [(0.5, 30.0), (0.2, 10.0), (0.9, 5.0)]:
        num, _ = scipy.integrate.quad(
            lambda o, zs=zs, ws=ws: float(kanai_tajimi_spectrum(o, zs, ws)),
            -np.inf,
            np.inf,
            limit=500,
        )
        assert kanai_tajimi_variance(zs, ws) == pytest.approx(num, rel=1e-6)
    assert kanai_tajimi_variance() == pytest.approx(30.0)
    # Broken-line input: the sampled variance tends to the white-noise one.
    assert kanai_tajimi_variance(dt=1e-4) == pytest.approx(30.0, rel=2e-3)
    assert kanai_tajimi_variance(dt=0.01) < kanai_tajimi_variance()


def test_kanai_tajimi_stationary_variance_and_spectrum_vs_theory():
    dt, n, n_real = 0.01, 4000, 100
    w = broken_line_white_noise(n, dt, n_realizations=n_real, random_state=2)
    f = kanai_tajimi(w, dt)[:, 100:]  # drop the 1 s start-up transient
    # Correlation time ~1/(zeta_s omega_s) = 7 samples: ~5e4 independent
    # values, relative MC error of the variance ~0.6 %.
    assert f.var() == pytest.approx(kanai_tajimi_variance(dt=dt), rel=0.025)
    freq, p = scipy.signal.welch(f, fs=1 / dt, nperseg=512, detrend=False, axis=-1)
    s_sim = p.mean(axis=0) / (4 * np.pi)
    band = (freq > 0.2) & (freq < 15.0)
    s_theory = kanai_tajimi_spectrum(2 * np.pi * freq[band], dt=dt)
    # Each averaged ordinate has ~100 x 14 segments: MC error ~3 %.
    np.testing.assert_allclose(s_sim[band], s_theory, rtol=0.12)
    assert np.mean(s_sim[band] / s_theory) == pytest.approx(1.0, abs=0.02)


def test_kanai_tajimi_bad_input():
    w = np.ones((2, 10))
    w[1, 3] = np.nan
    with pytest.raises(ValueError, match="w"):
        kanai_tajimi(w, 0.01)
    with pytest.raises(ValueError, match="w must be 1-D or 2-D"):
        kanai_tajimi(np.ones((2, 2, 10)), 0.01)
    with pytest.raises(ValueError, match="dt"):
        kanai_tajimi(np.ones(10), 0.0)
    with pytest.raises(ValueError, match="r must have one value"):
        kanai_tajimi(np.ones(10), 0.01, r=np.ones(9))
    with pytest.raises(ValueError, match="zeta_s"):
        kanai_tajimi(np.ones(10), 0.01, zeta_s=-0.5)
    with pytest.raises(ValueError, match="omega_s"):
        kanai_tajimi(np.ones(10), 0.01, omega_s=0.0)


# ------------------------------------------------------------------- multisine
def test_multisine_flat_band_and_rms():
    n, dt = 1000, 0.01
    u = multisine(n, dt, 2.0, 10.0, rms=3.0, n_realizations=4, random_state=0)
    assert u.shape == (4, n)
    np.testing.assert_allclose(np.sqrt(np.mean(u**2, axis=1)), 3.0, rtol=1e-12)
    amp = np.abs(np.fft.rfft(u, axis=-1))
    freqs = np.fft.rfftfreq(n, dt)
    band = (freqs >= 2.0) & (freqs <= 10.0)
    np.testing.assert_allclose(amp[:, band], amp[0, band][0], rtol=1e-10)
    assert amp[:, ~band].max() < 1e-10 * amp.max()
    # Random phases: different realisations, reproducible.
    assert not np.allclose(u[0], u[1])
    np.testing.assert_array_equal(
        u, multisine(n, dt, 2.0, 10.0, rms=3.0, n_realizations=4, random_state=0)
    )


def test_multisine_bad_band():
    with pytest.raises(ValueError, match="f_max"):
        multisine(100, 0.01, 2.0, 80.0)
    with pytest.raises(ValueError, match="widen the band"):
        multisine(100, 0.01, 1.01, 1.02)
    with pytest.raises(ValueError, match="rms"):
        multisine(100, 0.01, 1.0, 5.0, rms=-1.0)


# ------------------------------------------------------------ paper excitation
def test_paper_excitation_composition_and_linearity():
    dt, n = 0.01, 1500
    f1 = paper_excitation(n, dt, r0=1.0, n_realizations=3, random_state=7)
    f2 = paper_excitation(n, dt, r0=0.25, n_realizations=3, random_state=7)
    np.testing.assert_allclose(f2, 0.25 * f1, rtol=1e-12, atol=1e-14)
    w = broken_line_white_noise(n, dt, n_realizations=3, random_state=7)
    r = modulation(np.arange(n) * dt)
    np.testing.assert_allclose(f1, kanai_tajimi(w, dt, r=r), rtol=1e-12, atol=1e-14)
    f3 = paper_excitation(n, dt, n_realizations=3, random_state=8)
    assert not np.allclose(f1, f3)


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"n_samples": 0}, "n_samples"),
        ({"n_realizations": 0}, "n_realizations"),
        ({"dt": -0.01}, "dt"),
        ({"r0": float("nan")}, "r0"),
        ({"t1": 20.0}, "t2"),
    ],
)
def test_paper_excitation_bad_arguments(kwargs, name):
    args = {"n_samples": 100, "dt": 0.01, "n_realizations": 2} | kwargs
    with pytest.raises(ValueError, match=name):
        paper_excitation(**args)
