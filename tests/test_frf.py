"""Frequency response of fitted models and of their records."""

import warnings

import numpy as np
import pytest
from scipy.signal import coherence as scipy_coherence
from scipy.signal import cont2discrete, csd, freqz, lfilter, welch

from sysid_nn import ISSMRegressor, TDLRegressor, frequency_response, to_dlti

DT = 0.02
# A single-degree-of-freedom oscillator: 2 Hz, 5 % damping, sampled at 50 Hz.
F_N, ZETA = 2.0, 0.05
W_N = 2 * np.pi * F_N
B, A = (
    np.ravel(c)
    for c in cont2discrete(([1.0], [1.0, 2 * ZETA * W_N, W_N**2]), DT, "zoh")[:2]
)
#: The frequency of the continuous system's peak amplitude, in Hz.
F_PEAK = F_N * np.sqrt(1 - 2 * ZETA**2)


def _records(n, noise=0.0, seed=0):
    """White-noise excitation and the oscillator's response, with white noise
    of ``noise`` times its standard deviation added."""
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n)
    y = lfilter(B, A, u)
    return u[:, None], y + noise * y.std() * rng.standard_normal(n)


def _linear_tdl(X, y):
    return TDLRegressor(
        output_lags=2,
        input_lags=2,
        hidden_layer_sizes=(),
        early_stopping=False,
        n_init=1,
        random_state=0,
    ).fit(X, y)


@pytest.fixture(scope="module")
def model():
    # Noise-free records: the linear model is the true system.
    return _linear_tdl(*_records(2000))


@pytest.fixture(scope="module")
def noisy_model():
    return _linear_tdl(*_records(2000, noise=0.01))


def _truth(freq_hz, dt=DT):
    return freqz(B, A, worN=np.asarray(freq_hz), fs=1 / dt)[1]


def _dlti_response(system, freq_hz):
    """``C (zI - A)^-1 B + D`` of a state-space ``dlti``, shape (n_freq, p, m)."""
    eye = np.eye(len(system.A))
    return np.array(
        [
            system.C @ np.linalg.solve(z * eye - system.A, system.B) + system.D
            for z in np.exp(2j * np.pi * np.asarray(freq_hz) * DT)
        ]
    )


def test_model_frf_is_the_true_transfer_function(model):
    frf = frequency_response(model, DT, n_freq=101)
    assert len(frf) == 101
    assert frf.frequency_hz.iloc[-1] == pytest.approx(0.5 / DT)
    truth = _truth(frf.frequency_hz)
    np.testing.assert_allclose(frf.response, truth, rtol=1e-6)
    np.testing.assert_allclose(frf.magnitude, np.abs(truth), rtol=1e-6)
    np.testing.assert_allclose(
        frf.phase_deg, np.angle(frf.response, deg=True), atol=1e-9
    )
    # The same linearisation as the exported state-space system.
    H = _dlti_response(to_dlti(model, dt=DT), frf.frequency_hz)
    np.testing.assert_allclose(frf.response, H[:, 0, 0], rtol=1e-8, atol=1e-12)


def test_peak_at_the_resonance_in_hz(model):
    # A 2 pi or a dt mistake moves the peak far from 2 Hz.
    frf = frequency_response(model, DT, n_freq=1001)
    peak = frf.frequency_hz[frf.magnitude.idxmax()]
    assert peak == pytest.approx(F_PEAK, abs=0.03)
    # The same model read at half the sampling interval: twice the frequency.
    frf = frequency_response(model, DT / 2, n_freq=1001)
    assert frf.frequency_hz[frf.magnitude.idxmax()] == pytest.approx(
        2 * F_PEAK, abs=0.06
    )


def test_h1_matches_truth_where_coherent():
    X, y = _records(20000, noise=0.05, seed=1)
    model = _linear_tdl(X, y)
    frf = frequency_response(model, DT, X, y, nperseg=1024)
    assert frf.attrs["nperseg"] == 1024
    assert len(frf) == 513
    np.testing.assert_allclose(frf.frequency_hz, np.fft.rfftfreq(1024, DT))
    truth = _truth(frf.frequency_hz)
    coherent = frf.coherence > 0.95
    # Around and below the resonance (the response falls off above it).
    assert coherent.sum() > 50
    assert (np.abs(frf.frequency_hz[coherent] - F_PEAK) < 0.2).any()
    np.testing.assert_allclose(frf.h1[coherent], truth[coherent], rtol=0.1)
    assert frf.h1_magnitude.to_numpy() == pytest.approx(np.abs(frf.h1))
    # Noise lowers the coherence most where the response is weakest.
    weak = frf.magnitude < np.quantile(frf.magnitude, 0.1)
    assert frf.coherence[weak].mean() < frf.coherence[frf.magnitude.idxmax()]
    assert frf.coherence.min() >= 0.0 and frf.coherence.max() <= 1.0 + 1e-12


def test_h1_and_coherence_are_welch_estimates(model):
    X, y = _records(3000, noise=0.3, seed=2)
    frf = frequency_response(model, DT, X, y, nperseg=256)
    _, puy = csd(X[:, 0], y, fs=1 / DT, nperseg=256)
    _, puu = welch(X[:, 0], fs=1 / DT, nperseg=256)
    np.testing.assert_allclose(frf.h1, puy / puu, rtol=1e-10)
    _, coherence = scipy_coherence(X[:, 0], y, fs=1 / DT, nperseg=256)
    np.testing.assert_allclose(frf.coherence, coherence, rtol=1e-10)
    # A list of records: the spectra are averaged, so the same record twice
    # changes nothing.
    twice = frequency_response(model, DT, [X, X], [y, y], nperseg=256)
    np.testing.assert_allclose(twice.h1, frf.h1, rtol=1e-12)
    # Records of different lengths count by their lengths.
    short = slice(0, 1000)
    both = frequency_response(model, DT, [X[short], X], [y[short], y], nperseg=256)
    _, puy_short = csd(X[short, 0], y[short], fs=1 / DT, nperseg=256)
    _, puu_short = welch(X[short, 0], fs=1 / DT, nperseg=256)
    expected = (puy_short + 3 * puy) / (puu_short + 3 * puu)
    np.testing.assert_allclose(both.h1, expected, rtol=1e-10)


def test_band_positive_and_shrinks_with_more_data():
    widths = []
    for n in (1000, 8000):
        model = _linear_tdl(*_records(n, noise=0.2, seed=3))
        frf = frequency_response(model, DT, n_freq=64, level=0.95)
        width = frf.magnitude_high - frf.magnitude_low
        assert (width > 0).all()
        assert (frf.magnitude_low <= frf.magnitude).all()
        assert (frf.magnitude <= frf.magnitude_high).all()
        # Symmetric about the magnitude where it stays above zero.
        np.testing.assert_allclose(
            (frf.magnitude - frf.magnitude_low)[frf.magnitude_low > 0],
            (width / 2)[frf.magnitude_low > 0],
        )
        widths.append(width.mean())
    # The standard error goes as 1 / sqrt(n): about half with 8 times the data.
    assert widths[1] < 0.6 * widths[0]
    assert widths[1] > 0.15 * widths[0]


def test_band_follows_level(noisy_model):
    wide = frequency_response(noisy_model, DT, n_freq=16, level=0.99)
    narrow = frequency_response(noisy_model, DT, n_freq=16, level=0.5)
    ratio = (wide.magnitude_high - wide.magnitude) / (
        narrow.magnitude_high - narrow.magnitude
    )
    np.testing.assert_allclose(ratio, 2.5758 / 0.6745, rtol=1e-3)


def test_issm_multi_output_pairs():
    rng = np.random.default_rng(4)
    u = rng.standard_normal((800, 1))
    y1 = lfilter(B, A, u[:, 0])
    y = np.c_[y1, 0.5 * y1]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        issm = ISSMRegressor(
            n_states=2, hidden_layer_sizes=(), n_init=1, max_iter=30, random_state=0
        ).fit(u, y)
    frf = frequency_response(issm, DT, n_freq=8)
    assert len(frf) == 16
    assert list(frf.output.unique()) == [0, 1] and list(frf.input.unique()) == [0]
    first = frf[frf.output == 0].response.to_numpy()
    second = frf[frf.output == 1].response.to_numpy()
    H = _dlti_response(to_dlti(issm, dt=DT), np.linspace(0, 0.5 / DT, 8))
    np.testing.assert_allclose(first, H[:, 0, 0], rtol=1e-7, atol=1e-12)
    np.testing.assert_allclose(second, H[:, 1, 0], rtol=1e-7, atol=1e-12)


def test_arguments_validated(model):
    X, y = _records(200)
    with pytest.raises(ValueError, match="dt must be"):
        frequency_response(model, 0)
    with pytest.raises(ValueError, match="level must be"):
        frequency_response(model, DT, level=1.5)
    with pytest.raises(ValueError, match="n_freq must be"):
        frequency_response(model, DT, n_freq=1)
    with pytest.raises(ValueError, match="X and y must be given together"):
        frequency_response(model, DT, X)
    with pytest.raises(ValueError, match="nperseg sets"):
        frequency_response(model, DT, nperseg=64)
    with pytest.raises(ValueError, match=r"nperseg must be .*\(200 samples\)"):
        frequency_response(model, DT, X, y, nperseg=400)
    with pytest.raises(ValueError, match="X has 200 samples but y has 100"):
        frequency_response(model, DT, X, y[:100])
    with pytest.raises(ValueError, match="1 input and 1 output"):
        frequency_response(model, DT, np.c_[X, X], y)
    with pytest.raises(TypeError, match="estimator must be"):
        frequency_response(object(), DT)


def test_plot_draws_the_table(model):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from sysid_nn.plotting import plot_frequency_response

    X, y = _records(1000, noise=0.1, seed=5)
    frf = frequency_response(model, DT, X, y, nperseg=128)
    fig = plot_frequency_response(frf)
    top, bottom = fig.axes
    h1, magnitude, low, high = top.lines
    np.testing.assert_allclose(h1.get_ydata(), frf.h1_magnitude)
    np.testing.assert_allclose(magnitude.get_ydata(), frf.magnitude)
    np.testing.assert_allclose(low.get_ydata(), frf.magnitude_low)
    np.testing.assert_allclose(high.get_ydata(), frf.magnitude_high)
    np.testing.assert_allclose(bottom.lines[0].get_ydata(), frf.coherence)
    assert top.get_yscale() == "log"
    plt.close(fig)
    # From the estimator, without data: the phase below.
    fig = plot_frequency_response(model, DT)
    np.testing.assert_allclose(
        fig.axes[1].lines[0].get_ydata(),
        frequency_response(model, DT).phase_deg,
    )
    plt.close(fig)
    with pytest.raises(ValueError, match="dt must be given"):
        plot_frequency_response(model)
    with pytest.raises(ValueError, match="output=1, input=0 is not a pair"):
        plot_frequency_response(frf, output=1)
