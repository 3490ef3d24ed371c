"""Tests of the hysteretic oscillator (paper eq. 13-15) and its data generator."""

import numpy as np
import pytest
import scipy.signal
from sklearn.base import clone

from sysid_nn.excitation import multisine, paper_excitation
from sysid_nn.oscillator import HystereticOscillator

DT = 0.01


def _zoh_linear_reference(osc, force, dt, state0=(0.0, 0.0)):
    """Exact zero-order-hold response of the linear SDOF system (alpha = 1)."""
    w0, z = osc.omega0, osc.zeta
    a = [[0.0, 1.0], [-(w0**2), -2 * z * w0]]
    ad, bd, *_ = scipy.signal.cont2discrete(
        (np.array(a), np.array([[0.0], [1.0]]), np.eye(2), np.zeros((2, 1))),
        dt,
        method="zoh",
    )
    x = np.array(state0, dtype=float)
    out = np.empty((force.size, 2))
    for k, f in enumerate(force):
        out[k] = x
        x = ad @ x + bd[:, 0] * f
    return out


# ---------------------------------------------------------------- linear limit
def test_linear_limit_matches_exact_zoh_discretisation():
    osc = HystereticOscillator(alpha=1.0)
    force = paper_excitation(2000, DT, r0=0.05, random_state=0)
    res = osc.simulate(force, DT)
    ref = _zoh_linear_reference(osc, force, DT)
    scale = np.abs(ref).max(axis=0)
    np.testing.assert_allclose(
        res.displacement, ref[:, 0], rtol=0, atol=5e-8 * scale[0]
    )
    np.testing.assert_allclose(res.velocity, ref[:, 1], rtol=0, atol=5e-8 * scale[1])
    # With alpha = 1, Z does not enter the motion; it still follows eq. 15.
    assert np.abs(res.hysteretic).max() <= osc.z0


def test_rk4_converges_with_fourth_order_in_the_substep():
    # A coarse sample step so that the RK4 error is far above round-off.
    dt = 0.05
    force = multisine(400, dt, 0.1, 2.0, rms=1.0, random_state=1)
    ref = _zoh_linear_reference(HystereticOscillator(alpha=1.0), force, dt)[:, 0]
    errors = [
        np.abs(
            HystereticOscillator(alpha=1.0, n_substeps=m)
            .simulate(force, dt)
            .displacement
            - ref
        ).max()
        for m in (1, 2, 4, 8)
    ]
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    np.testing.assert_allclose(orders, 4.0, atol=0.25)


def test_default_substeps_accurate_for_the_hysteretic_oscillator():
    force = paper_excitation(2000, DT, r0=0.06, n_realizations=10, random_state=2)
    ref = HystereticOscillator(n_substeps=64).simulate(force, DT).displacement
    res = HystereticOscillator().simulate(force, DT).displacement
    assert np.abs(res - ref).max() < 1e-4 * np.abs(ref).max()


def test_initial_state_free_vibration():
    osc = HystereticOscillator(alpha=1.0, zeta=0.05)
    res = osc.simulate(np.zeros(500), DT, initial_state=[0.02, 0.0, 0.0])
    ref = _zoh_linear_reference(osc, np.zeros(500), DT, state0=(0.02, 0.0))
    np.testing.assert_allclose(res.displacement, ref[:, 0], atol=1e-10)
    # One row of initial states per realisation, or one broadcast to all.
    two = osc.simulate(
        np.zeros((2, 50)), DT, initial_state=[[0.01, 0, 0], [0.02, 0, 0]]
    )
    np.testing.assert_allclose(two.displacement[:, 0], [0.01, 0.02])
    both = osc.simulate(np.zeros((2, 50)), DT, initial_state=[0.01, 0, 0])
    np.testing.assert_array_equal(both.displacement[0], both.displacement[1])


def test_simulate_rows_are_independent_realisations():
    osc = HystereticOscillator()
    force = paper_excitation(800, DT, r0=0.08, n_realizations=3, random_state=3)
    res = osc.simulate(force, DT)
    assert (
        res.displacement.shape == res.velocity.shape == res.hysteretic.shape == (3, 800)
    )
    one = osc.simulate(force[1], DT)
    assert one.displacement.shape == (800,)
    np.testing.assert_array_equal(one.displacement, res.displacement[1])
    # The state at t_0 is the initial state, F[k] acts on [t_k, t_k+1).
    assert res.displacement[:, 0].tolist() == [0.0, 0.0, 0.0]
    np.testing.assert_allclose(res.t, np.arange(800) * DT)


# ----------------------------------------------------------- physical hysteresis
@pytest.mark.parametrize(
    ("beta", "gamma", "n", "bound"),
    [
        (0.5, 0.5, 1.0, 1.0),
        (0.8, 0.2, 2.0, 1.0),
        (0.1, 0.9, 1.0, 1.0),
        (0.3, 0.2, 1.0, 2.0),
    ],
)
def test_hysteretic_variable_bounded_by_yield_level(beta, gamma, n, bound):
    # |Z| saturates at z0 (beta + gamma)^(-1/n) under strong excitation.
    osc = HystereticOscillator(beta=beta, gamma=gamma, n=n)
    force = paper_excitation(2000, DT, r0=0.5, n_realizations=5, random_state=4)
    z = osc.simulate(force, DT).hysteretic
    assert np.abs(z).max() <= bound * osc.z0 * (1 + 1e-9)
    assert np.abs(z).max() > 0.95 * bound * osc.z0  # yielding is reached


@pytest.mark.parametrize(
    ("beta", "gamma", "n"),
    [
        (0.5, 0.5, 1.0),
        (0.9, 0.1, 1.0),
        (0.25, 0.75, 1.0),
        (0.5, 0.5, 3.0),
        (0.42, -0.58, 1.0),
    ],
)
@pytest.mark.parametrize("amplitude", [0.3, 1.0, 3.0])
def test_closed_loops_dissipate_positive_energy(beta, gamma, n, amplitude):
    # Slow sinusoidal force (0.2 Hz against a 1 Hz oscillator, amplitude in
    # units of the yield force) with enough viscous damping that the response
    # settles on a periodic orbit; the last cycle is then a (nearly) closed
    # loop in the (X, Z) plane. Small loops close slowly (Bouc-Wen drift), so
    # the enclosed area is compared with the closure gap.
    osc = HystereticOscillator(beta=beta, gamma=gamma, n=n, zeta=0.2)
    period = 500  # samples of 0.01 s
    k = np.arange(40 * period + 1)
    force = amplitude * osc.omega0**2 * osc.z0 * np.sin(2 * np.pi * k / period)
    res = osc.simulate(force, DT)
    x, v, z = (
        a[-period - 1 :] for a in (res.displacement, res.velocity, res.hysteretic)
    )
    gap = abs(x[-1] - x[0])
    assert gap < 5e-3 * np.ptp(x)
    loop = np.sum(0.5 * (z[1:] + z[:-1]) * np.diff(x))
    assert loop > 20 * np.abs(z).max() * gap  # positive, beyond the closure error
    # Energy balance over the cycle (identity of eq. 13, up to quadrature):
    # input work = kinetic + elastic storage + viscous + hysteretic work.
    w0, a = osc.omega0, osc.alpha
    work_in = np.sum(force[-period - 1 : -1] * np.diff(x))  # F held on each step
    kinetic = 0.5 * (v[-1] ** 2 - v[0] ** 2)
    elastic = 0.5 * a * w0**2 * (x[-1] ** 2 - x[0] ** 2)
    viscous = 2 * osc.zeta * w0 * np.sum(0.5 * (v[1:] + v[:-1]) * np.diff(x))
    hysteretic = w0**2 * (1 - a) * loop
    assert work_in == pytest.approx(kinetic + elastic + viscous + hysteretic, rel=1e-3)


def test_alpha_one_and_beta_zero_are_non_hysteretic():
    # beta = gamma = 0: Z = X, elastic; the loop encloses no area.
    osc = HystereticOscillator(beta=0.0, gamma=0.0, zeta=0.2)
    k = np.arange(3000)
    res = osc.simulate(np.sin(2 * np.pi * k / 500), DT)
    np.testing.assert_allclose(res.hysteretic, res.displacement, atol=1e-12)


# ------------------------------------------------------------ physical mapping
def _benchmark_rk4(u, dt, n_sub, m, c, k, a, b, g, d, nu):
    """Direct RK4 of m y'' + c y' + k y + z = u, z' = a y' - b (g|y'||z|^(nu-1) z
    + d y'|z|^nu), u held on each sample interval."""

    def rhs(s, f):
        y, yd, z = s
        az = np.abs(z) ** nu
        zd = a * yd - b * (g * np.abs(yd) * np.sign(z) * az + d * yd * az)
        return np.array([yd, (f - c * yd - k * y - z) / m, zd])

    s = np.zeros(3)
    out = np.empty((u.size, 3))
    h = dt / n_sub
    for i, f in enumerate(u):
        out[i] = s
        for _ in range(n_sub):
            k1 = rhs(s, f)
            k2 = rhs(s + 0.5 * h * k1, f)
            k3 = rhs(s + 0.5 * h * k2, f)
            k4 = rhs(s + h * k3, f)
            s = s + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return out


@pytest.mark.parametrize(
    "params",
    [
        # Noel & Schoukens (2016) benchmark parameters.
        {"mass": 2.0, "c": 10.0, "k": 5e4, "alpha": 5e4, "beta": 1e3, "gamma": 0.8,
         "delta": -1.1, "nu": 1.0},
        # A softening variant with nu = 2 (exercises the |z|^nu scaling).
        {"mass": 1.5, "c": 4.0, "k": 2e4, "alpha": 6e4, "beta": 2.0, "gamma": 0.6,
         "delta": 0.3, "nu": 2.0},
    ],
)  # fmt: skip
def test_from_physical_matches_benchmark_ode(params):
    dt = 1 / 750  # the benchmark's sampling rate
    u = multisine(1500, dt, 5.0, 150.0, rms=50.0, random_state=5)
    osc = HystereticOscillator.from_physical(**params, n_substeps=2)
    res = osc.simulate(u / params["mass"], dt)
    ref = _benchmark_rk4(u, dt, 2, *params.values())
    # The excitation drives the element into its non-linear range.
    nonlinear = ref[:, 2] - params["alpha"] * ref[:, 0]
    assert np.abs(nonlinear).max() > 0.01 * np.abs(ref[:, 2]).max()
    np.testing.assert_allclose(
        res.displacement, ref[:, 0], rtol=0, atol=1e-9 * np.abs(ref[:, 0]).max()
    )
    np.testing.assert_allclose(
        res.velocity, ref[:, 1], rtol=0, atol=1e-9 * np.abs(ref[:, 1]).max()
    )
    np.testing.assert_allclose(
        params["alpha"] * res.hysteretic,
        ref[:, 2],
        rtol=0,
        atol=1e-9 * np.abs(ref[:, 2]).max(),
    )


def test_from_physical_benchmark_values():
    osc = HystereticOscillator.from_physical()
    assert osc.omega0 == pytest.approx(np.sqrt(1e5 / 2))
    assert osc.zeta == pytest.approx(10 / (2 * 2 * np.sqrt(1e5 / 2)))
    assert osc.alpha == pytest.approx(0.5)
    assert (osc.beta, osc.gamma) == pytest.approx((0.8 / 1.9, -1.1 / 1.9))
    assert osc.z0 == pytest.approx(1 / 1900)
    assert osc.n == 1.0
    with pytest.raises(ValueError, match="beta \\* gamma"):
        HystereticOscillator.from_physical(gamma=-0.8)
    with pytest.raises(ValueError, match="mass"):
        HystereticOscillator.from_physical(mass=0.0)


# --------------------------------------------------------------- calibration
def test_default_calibration_reaches_twice_z0_on_fresh_realisations():
    osc = HystereticOscillator()
    r0 = osc.calibrate_r0()
    assert 0.05 < r0 < 0.07
    # Cached and deterministic.
    assert osc.calibrate_r0() == r0
    assert HystereticOscillator(r0="calibrate").generate(1, random_state=0).r0 == r0
    # Fresh realisations (another seed): the calibration and this check each
    # carry ~1.3 % Monte Carlo error (peak coefficient of variation ~0.26).
    rec = HystereticOscillator(r0=r0).generate(400, random_state=12345)
    mean_peak = np.abs(rec.displacement).max(axis=1).mean()
    assert mean_peak == pytest.approx(2 * osc.z0, rel=0.06)


def test_calibration_reproducible_and_target_monotone():
    osc = HystereticOscillator()
    kw = {"n_realizations": 40, "n_samples": 1000}
    a = osc.calibrate_r0(**kw, random_state=np.random.RandomState(7))
    b = osc.calibrate_r0(**kw, random_state=np.random.RandomState(7))
    assert a == b
    low = osc.calibrate_r0(**kw, target=osc.z0, random_state=7)
    assert low < osc.calibrate_r0(**kw, random_state=7)
    # The calibrated r0 solves the Monte Carlo equation it was built from.
    rec = osc.set_params(r0=low).generate(40, n_samples=1000, random_state=7)
    assert np.abs(rec.displacement).max(axis=1).mean() == pytest.approx(
        osc.z0, rel=1e-3
    )


# ---------------------------------------------------------------- generation
def test_generate_reproducible_and_consistent():
    osc = HystereticOscillator(r0=0.06)
    a = osc.generate(3, n_samples=700, random_state=0, as_frame=True)
    b = osc.generate(3, n_samples=700, random_state=0)
    c = osc.generate(3, n_samples=700, random_state=1)
    for name in ("excitation", "displacement", "velocity", "hysteretic"):
        assert a[name].shape == (3, 700)
        np.testing.assert_array_equal(a[name], b[name])
        assert not np.allclose(a[name], c[name])
    assert a.r0 == 0.06 and a.dt == DT and b.frame is None
    np.testing.assert_allclose(a.t, np.arange(700) * DT)
    np.testing.assert_array_equal(
        a.excitation,
        paper_excitation(700, DT, r0=0.06, n_realizations=3, random_state=0),
    )
    sim = osc.simulate(a.excitation, DT)
    np.testing.assert_array_equal(sim.displacement, a.displacement)
    frame = a.frame
    assert list(frame.columns) == [
        "realization", "t", "excitation", "displacement", "velocity", "hysteretic"
    ]  # fmt: skip
    assert len(frame) == 3 * 700
    row = frame[(frame.realization == 2)].iloc[123]
    assert row.t == pytest.approx(123 * DT)
    assert row.displacement == a.displacement[2, 123]


def test_parameters_sklearn_style():
    osc = HystereticOscillator(alpha=0.1, r0=0.04)
    assert osc.get_params()["alpha"] == 0.1
    assert clone(osc).get_params() == osc.get_params()
    assert HystereticOscillator(z0=-1.0).z0 == -1.0  # stored untouched, checked in use


# ---------------------------------------------------------------- bad input
@pytest.mark.parametrize(
    ("params", "name"),
    [
        ({"alpha": 1.5}, "alpha"),
        ({"alpha": -0.1}, "alpha"),
        ({"z0": 0.0}, "z0"),
        ({"omega0": -1.0}, "omega0"),
        ({"n": 0.0}, "n"),
        ({"zeta": -0.01}, "zeta"),
        ({"beta": -0.1}, "beta"),
        ({"beta": 0.2, "gamma": -0.5, "n": 2.0}, "gamma"),
        ({"n_substeps": 0}, "n_substeps"),
        ({"z0": float("nan")}, "z0"),
    ],
)
def test_bad_physical_parameters(params, name):
    osc = HystereticOscillator(**params)
    with pytest.raises(ValueError, match=name):
        osc.simulate(np.zeros(10), DT)
    with pytest.raises(ValueError, match=name):
        osc.generate(1, n_samples=10)


@pytest.mark.parametrize(
    ("params", "name"),
    [
        ({"r0": "auto"}, "r0"),
        ({"r0": -1.0}, "r0"),
        ({"t1": 20.0}, "t2"),
        ({"omega_s": 0.0}, "omega_s"),
        ({"zeta_s": -1.0}, "zeta_s"),
    ],
)
def test_bad_excitation_parameters(params, name):
    with pytest.raises(ValueError, match=name):
        HystereticOscillator(**params).generate(1, n_samples=10)


def test_bad_simulate_and_generate_arguments():
    osc = HystereticOscillator(r0=0.05)
    bad = np.zeros(10)
    bad[4] = np.nan
    with pytest.raises(ValueError, match="F contains 1 NaN"):
        osc.simulate(bad, DT)
    with pytest.raises(ValueError, match="F"):
        osc.simulate(np.array([0.0, np.inf]), DT)
    with pytest.raises(ValueError, match="F must be 1-D or 2-D"):
        osc.simulate(np.zeros((2, 2, 10)), DT)
    with pytest.raises(ValueError, match="dt"):
        osc.simulate(np.zeros(10), 0.0)
    with pytest.raises(ValueError, match="initial_state"):
        osc.simulate(np.zeros((2, 10)), DT, initial_state=np.zeros(4))
    with pytest.raises(ValueError, match="n_realizations"):
        osc.generate(0)
    with pytest.raises(ValueError, match="n_samples"):
        osc.generate(2, n_samples=-5)
    with pytest.raises(ValueError, match="dt"):
        osc.generate(2, dt=-0.01)
    with pytest.raises(ValueError, match="target"):
        osc.calibrate_r0(target=0.0)
    # A wrong type is reported the same way (also a TypeError).
    with pytest.raises(ValueError, match="n_realizations must be an integer"):
        osc.generate(2.5)
    with pytest.raises(TypeError, match="dt must be a real number"):
        osc.simulate(np.zeros(10), "0.01")


def test_hysteretic_state_follows_the_displacement_history():
    osc = HystereticOscillator(r0=0.06)
    rec = osc.generate(2, n_samples=800, random_state=3)
    z = osc.hysteretic_state(rec.displacement)
    assert z.shape == rec.displacement.shape
    # The same law as the simulator: its Z is reproduced from its X alone.
    np.testing.assert_allclose(z, rec.hysteretic, atol=1e-3 * osc.z0)
    # Rate-independent: the same path at another pace gives the same Z.
    x = rec.displacement[0]
    slow = np.interp(np.arange(2 * x.size - 1) / 2, np.arange(x.size), x)
    np.testing.assert_allclose(osc.hysteretic_state(slow)[::2], z[0], atol=1e-6)
    np.testing.assert_array_equal(osc.hysteretic_state(x), z[0])
    with pytest.raises(ValueError, match="displacement"):
        osc.hysteretic_state([0.0, np.nan])
