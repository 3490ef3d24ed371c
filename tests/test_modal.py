"""Modal parameters, backbone and non-linearity test of fitted models."""

import copy
import warnings

import numpy as np
import pytest
from scipy.signal import lfilter

from sysid_nn import (
    HystereticOscillator,
    ISSMRegressor,
    ShearBuilding,
    TDLRegressor,
    backbone,
    instantaneous_frequency,
    modal_parameters,
    nonlinearity_test,
)

DT = 0.01
# Two modes of known discrete poles: 2 Hz at 3 % and 7 Hz at 5 % damping.
MODES = [(2.0, 0.03), (7.0, 0.05)]


def _poles(modes, dt):
    out = []
    for f, zeta in modes:
        w = 2 * np.pi * f
        s = -zeta * w + 1j * w * np.sqrt(1 - zeta**2)
        out += [np.exp(s * dt), np.exp(np.conj(s) * dt)]
    return np.array(out)


def _arx_records(n, noise=0.0, seed=0):
    """A fourth-order ARX with the poles of MODES: input, output."""
    rng = np.random.default_rng(seed)
    a = np.real(np.poly(_poles(MODES, DT)))
    u = rng.standard_normal(n)
    y = lfilter([0.0, 1.0, 0.5], a, u)
    # Equation noise, white: the ARX model stays the true structure.
    y = y + lfilter([1.0], a, noise * y.std() * rng.standard_normal(n))
    return u[:, None], y


def _linear_tdl(X, y):
    return TDLRegressor(
        output_lags=4,
        input_lags=2,
        hidden_layer_sizes=(),
        focus="prediction",
        n_init=1,
        random_state=0,
    ).fit(X, y)


@pytest.fixture(scope="module")
def arx_model():
    return _linear_tdl(*_arx_records(600))


def test_known_poles_exactly(arx_model):
    modes = modal_parameters(arx_model, DT)
    assert list(modes.kind) == ["structural", "structural"]
    np.testing.assert_allclose(modes.frequency_hz, [2.0, 7.0], rtol=1e-8)
    np.testing.assert_allclose(modes.damping_ratio, [0.03, 0.05], rtol=1e-8)
    # Noise-free records: the weights are exact, the intervals collapse.
    np.testing.assert_allclose(modes.frequency_hz_high, modes.frequency_hz, rtol=1e-6)
    assert modes.attrs["dt"] == DT


def test_frequency_scales_with_dt(arx_model):
    """The same poles at twice the sampling interval: half the frequency."""
    slow = modal_parameters(arx_model, 2 * DT)
    np.testing.assert_allclose(slow.frequency_hz, [1.0, 3.5], rtol=1e-8)
    np.testing.assert_allclose(slow.damping_ratio, [0.03, 0.05], rtol=1e-8)


@pytest.mark.parametrize("dt", [0.0, -0.01, np.nan, np.inf, "0.01", True, None])
def test_dt_validated(arx_model, dt):
    with pytest.raises(ValueError, match="dt must be"):
        modal_parameters(arx_model, dt)


def test_level_validated(arx_model):
    with pytest.raises(ValueError, match="level must be"):
        modal_parameters(arx_model, DT, level=95)


def test_unfitted_rejected():
    from sklearn.exceptions import NotFittedError

    with pytest.raises(NotFittedError):
        modal_parameters(TDLRegressor(), DT)


def test_delta_method_matches_finite_differences():
    """The intervals' gradient against re-reading perturbed weights."""
    model = _linear_tdl(*_arx_records(800, noise=0.05, seed=3))
    modes = modal_parameters(model, DT)
    w = model.coefs_
    grad = np.zeros((2, 2, len(w)))  # (quantity, mode, weight)
    for k in range(len(w)):
        h = 1e-6 * max(1.0, abs(w[k]))
        rows = []
        for sign in (1, -1):
            shifted = copy.copy(model)
            shifted.coefs_ = w.copy()
            shifted.coefs_[k] += sign * h
            m = modal_parameters(shifted, DT)
            rows.append(m[["frequency_hz", "damping_ratio"]].to_numpy().T)
        grad[:, :, k] = (rows[0] - rows[1]) / (2 * h)
    cov = model.coefs_covariance_
    sd = np.sqrt(np.einsum("qmi,ij,qmj->qm", grad, cov, grad))
    half = np.array(
        [
            modes.frequency_hz_high - modes.frequency_hz,
            modes.damping_ratio_high - modes.damping_ratio,
        ]
    )
    np.testing.assert_allclose(half, 1.959963984540054 * sd, rtol=1e-4)
    assert np.all(sd > 0)


def test_intervals_shrink_and_cover():
    """Wider with less data; the 95 % interval holds the truth most times."""
    widths = {}
    hits, n_rep = 0, 20
    for n in (400, 3200):
        w = []
        for seed in range(n_rep if n == 400 else 3):
            modes = modal_parameters(_linear_tdl(*_arx_records(n, 0.1, seed)), DT)
            w.append(modes.frequency_hz_high[0] - modes.frequency_hz_low[0])
            if n == 400:
                hits += modes.frequency_hz_low[0] <= 2.0 <= modes.frequency_hz_high[0]
        widths[n] = np.median(w)
    # Eight times the data: the width shrinks about sqrt(8) times.
    assert 2.0 < widths[400] / widths[3200] < 4.5
    assert hits >= 16


def _model_of_poles(poles):
    """The linear TDL fitted to an ARX system of the given poles (exact)."""
    u = np.random.default_rng(0).standard_normal(800)[:, None]
    y = lfilter([0.0, 1.0], np.real(np.poly(poles)), u[:, 0])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a mode near Nyquist looks like noise
        return TDLRegressor(
            output_lags=len(poles),
            input_lags=1,
            hidden_layer_sizes=(),
            n_init=1,
            random_state=0,
        ).fit(u, y)


def test_numerical_modes_marked():
    """A first-order lag beside one mode: a real pole, not structural."""
    modes = modal_parameters(_model_of_poles(np.r_[_poles(MODES[:1], DT), 0.5]), DT)
    assert list(modes.kind) == ["structural", "real"]
    assert list(modes.structural) == [True, False]
    np.testing.assert_allclose(modes.frequency_hz[0], 2.0, rtol=1e-6)
    # The real pole z = 0.5: s = log(0.5) / dt, critically damped.
    np.testing.assert_allclose(modes.frequency_hz[1], -np.log(0.5) / DT / (2 * np.pi))
    np.testing.assert_allclose(modes.damping_ratio[1], 1.0)


def test_nyquist_mode_marked():
    modes = modal_parameters(
        _model_of_poles(_poles([(2.0, 0.03), (45.0, 0.02)], DT)), DT
    )
    assert list(modes.kind) == ["structural", "nyquist"]
    assert list(modes.structural) == [True, False]


@pytest.fixture(scope="module")
def building_records():
    building = ShearBuilding(alpha=1.0, r0=0.16)
    rec = building.generate(2, n_samples=1500, dt=0.02, random_state=0,
                            outputs="acceleration")  # fmt: skip
    X = [g[:, None] for g in rec.ground_acceleration]
    return building.modal_properties(), X, list(rec.acceleration)


@pytest.mark.parametrize("cls", [TDLRegressor, ISSMRegressor])
def test_building_modes_and_shapes(building_records, cls):
    truth, X, y = building_records
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = cls(hidden_layer_sizes=(), n_init=1, random_state=0).fit(X, y)
    modes = modal_parameters(model, 0.02)
    found = modes[modes.structural]
    assert len(found) == 3
    np.testing.assert_allclose(found.frequency_hz, truth.frequency, rtol=1e-3)
    np.testing.assert_allclose(found.damping_ratio, truth.damping_ratio, rtol=0.05)
    # Absolute floor accelerations move in the building's mode shapes.
    shapes = found[["shape_0", "shape_1", "shape_2"]].to_numpy()
    expected = (
        truth.mode_shapes
        / truth.mode_shapes[np.argmax(np.abs(truth.mode_shapes), axis=0), range(3)]
    )
    np.testing.assert_allclose(shapes, expected.T, atol=0.02)


# -------------------------------------------------------------- backbone
def test_backbone_generator_small_amplitude():
    """A linear oscillator's backbone is its natural frequency and damping.

    At 20 % damping the damped frequency is 2 % lower than the natural
    one: the reading must give the natural one, and the damping ratio
    relative to it.
    """
    osc = HystereticOscillator(r0=0.06, alpha=1.0, zeta=0.2)
    curve = backbone(osc, DT, amplitudes=[0.001, 0.002])
    np.testing.assert_allclose(curve.frequency_hz, 1.0, rtol=5e-3)
    np.testing.assert_allclose(curve.damping_ratio, 0.2, rtol=5e-3)


def test_backbone_of_linear_model_is_its_mode(arx_model):
    """A linear model's backbone is flat, at its modal_parameters values."""
    curve = backbone(arx_model, DT, amplitudes=[0.5, 1.0, 2.0])
    np.testing.assert_allclose(curve.frequency_hz, 2.0, rtol=5e-3)
    np.testing.assert_allclose(curve.damping_ratio, 0.03, rtol=0.1)


def test_backbone_softens_with_amplitude():
    curve = backbone(
        HystereticOscillator(r0=0.06), DT, amplitudes=[0.001, 0.003, 0.006]
    )
    assert np.all(np.diff(curve.frequency_hz) < 0)
    assert np.all(np.diff(curve.damping_ratio) > 0)


def test_backbone_arguments(arx_model):
    with pytest.raises(ValueError, match="amplitudes must be given"):
        backbone(HystereticOscillator(r0=0.06), DT)
    with pytest.raises(ValueError, match="amplitudes must be positive"):
        backbone(arx_model, DT, amplitudes=[-1.0])
    with pytest.raises(ValueError, match="output must be"):
        backbone(arx_model, DT, output=1)
    with pytest.raises(ValueError, match="dt must be"):
        backbone(arx_model, 0.0)


# ---------------------------------------------------- non-linearity test
@pytest.fixture(scope="module")
def oscillator_fit():
    """A network fitted to four oscillator records, and two held out."""
    rec = HystereticOscillator(r0=0.06).generate(6, random_state=0)
    X, y = [f[:, None] for f in rec.excitation], list(rec.displacement)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        net = TDLRegressor(n_init=1, random_state=0).fit(X[:4], y[:4])
    return net, X, y


def test_nonlinearity_detected(oscillator_fit):
    net, X, y = oscillator_fit
    result = nonlinearity_test(net, X[4:], y[4:])
    assert result.pvalue < 0.01
    assert result.statistic > 2.3
    assert "significantly better" in result.verdict
    # The evidence is the two models' own free-run errors.
    lin = copy.copy(net)
    lin.coefs_ = net._linear_coefs
    scale2 = net._y_scale[0] ** 2
    for model, loss in (
        (net, result.mean_loss_network),
        (lin, result.mean_loss_linear),
    ):
        err = np.concatenate(
            [model.simulate(x) - t for x, t in zip(X[4:], y[4:], strict=True)]
        )
        np.testing.assert_allclose(loss, np.mean(err**2) / scale2, rtol=1e-10)
    assert result.n_samples == 2 * len(y[4])


def test_nonlinearity_not_found_on_linear_system():
    rec = HystereticOscillator(r0=0.06, alpha=1.0).generate(6, random_state=1)
    rng = np.random.default_rng(0)
    X = [f[:, None] for f in rec.excitation]
    y = [d + 0.02 * d.std() * rng.standard_normal(len(d)) for d in rec.displacement]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        net = TDLRegressor(hidden_layer_sizes=(4,), n_init=1, max_iter=30,
                           random_state=0).fit(X[:4], y[:4])  # fmt: skip
        lin = TDLRegressor(hidden_layer_sizes=(), n_init=1, random_state=0).fit(
            X[:4], y[:4]
        )
    # Against an independently fitted linear model, so that the two differ.
    result = nonlinearity_test(net, X[4:], y[4:], linear_model=lin)
    assert result.mean_loss_network != result.mean_loss_linear
    assert result.pvalue > 0.05
    assert "does not simulate" in result.verdict


def test_instantaneous_frequency_drops_in_strong_shaking(oscillator_fit):
    net, X, y = oscillator_fit
    track = instantaneous_frequency(net, X[4], DT)
    assert len(track) == len(y[4])
    np.testing.assert_allclose(track.t[1] - track.t[0], DT)
    rest = modal_parameters(net, DT)
    f_rest = rest[rest.structural].frequency_hz.iloc[0]
    # The run starts at rest: the rest's mode.
    np.testing.assert_allclose(track.frequency_hz[0], f_rest, rtol=1e-3)
    # Around the largest displacement (2-3 times the yield) it has softened.
    peak = int(np.argmax(np.abs(y[4])))
    assert np.nanmean(track.frequency_hz[peak - 50 : peak + 50]) < 0.9 * f_rest


def test_instantaneous_frequency_arguments(arx_model):
    with pytest.raises(ValueError, match="X must be one record"):
        instantaneous_frequency(arx_model, np.zeros((10, 2)), DT)
    with pytest.raises(ValueError, match="dt must be"):
        instantaneous_frequency(arx_model, np.zeros((10, 1)), -1.0)


def test_nonlinearity_one_sided(oscillator_fit):
    """A linear model is no evidence against a better network: p near one."""
    net, X, y = oscillator_fit
    lin = copy.copy(net)
    lin.coefs_ = net._linear_coefs
    lin._linear_coefs = None
    result = nonlinearity_test(lin, X[4:], y[4:], linear_model=net)
    assert result.statistic < -2.3
    assert result.pvalue > 0.99


def test_nonlinearity_arguments(oscillator_fit, arx_model):
    _, X, y = oscillator_fit
    with pytest.raises(ValueError, match="linear_model="):
        nonlinearity_test(arx_model, X[0], y[0])
    with pytest.raises(ValueError, match="level must be"):
        nonlinearity_test(arx_model, X[0], y[0], linear_model=arx_model, level=5)
    with pytest.raises(ValueError, match="burn_in"):
        nonlinearity_test(arx_model, X[0], y[0], linear_model=arx_model, burn_in=-1)
