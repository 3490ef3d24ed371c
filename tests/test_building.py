"""Tests of the multi-storey shear building and its data generator."""

import pickle

import numpy as np
import pytest
import scipy.signal
from sklearn.base import clone

from sysid_nn import HystereticOscillator, ShearBuilding
from sysid_nn.excitation import paper_excitation

DT = 0.01


def _hand_stiffness(k):
    """Tridiagonal storey stiffness matrix, written out for 3 storeys."""
    k1, k2, k3 = k
    return np.array([[k1 + k2, -k2, 0.0], [-k2, k2 + k3, -k3], [0.0, -k3, k3]])


def _zoh_linear_reference(modes, ground, dt):
    """Exact zero-order-hold response of the linear building (displacements)."""
    n = modes.mass_matrix.shape[0]
    minv = np.linalg.inv(modes.mass_matrix)
    a = np.block(
        [
            [np.zeros((n, n)), np.eye(n)],
            [-minv @ modes.stiffness_matrix, -minv @ modes.damping_matrix],
        ]
    )
    b = np.concatenate([np.zeros(n), -np.ones(n)])[:, None]
    ad, bd, *_ = scipy.signal.cont2discrete(
        (a, b, np.eye(2 * n), np.zeros((2 * n, 1))), dt, method="zoh"
    )
    x = np.zeros(2 * n)
    out = np.empty((ground.size, n))
    for k, g in enumerate(ground):
        out[k] = x[:n]
        x = ad @ x + bd[:, 0] * g
    return out


# ---------------------------------------------------------- one storey
def test_one_storey_is_the_hysteretic_oscillator():
    osc = HystereticOscillator(zeta=0.03, alpha=0.2, beta=0.6, gamma=0.4, n=1.5)
    building = ShearBuilding(
        n_storeys=1,
        mass=1.0,
        stiffness=osc.omega0**2,
        zeta=osc.zeta,
        alpha=osc.alpha,
        beta=osc.beta,
        gamma=osc.gamma,
        n=osc.n,
        z0=osc.z0,
        r0=0.08,
    )
    rec = building.generate(2, n_samples=1500, random_state=3)
    ref = osc.simulate(-rec.ground_acceleration, DT)
    peak = np.abs(ref.displacement).max()
    assert np.abs(ref.hysteretic).max() > 0.9 * osc.z0  # it yields
    np.testing.assert_allclose(
        rec.displacement[..., 0], ref.displacement, rtol=0, atol=1e-12 * peak
    )
    np.testing.assert_allclose(
        rec.hysteretic[..., 0], ref.hysteretic, rtol=0, atol=1e-12 * osc.z0
    )
    np.testing.assert_allclose(rec.drift, rec.displacement)
    # The same seed and strength give the oscillator's excitation, negated.
    osc_rec = osc.set_params(r0=0.08).generate(2, n_samples=1500, random_state=3)
    np.testing.assert_array_equal(rec.ground_acceleration, -osc_rec.excitation)


# ---------------------------------------------------------- linear limit
def test_modal_properties_solve_the_eigenproblem_of_m_and_k():
    mass = np.array([2.0, 1.5, 1.0])
    k = np.array([900.0, 700.0, 400.0])
    modes = ShearBuilding(mass=mass, stiffness=k).modal_properties()
    stiff = _hand_stiffness(k)
    np.testing.assert_allclose(modes.stiffness_matrix, stiff)
    omega2 = np.sort(np.linalg.eigvals(np.linalg.solve(np.diag(mass), stiff)).real)
    np.testing.assert_allclose(modes.omega**2, omega2, rtol=1e-12)
    np.testing.assert_allclose(modes.frequency, modes.omega / (2 * np.pi))
    phi = modes.mode_shapes
    np.testing.assert_allclose(phi.T @ np.diag(mass) @ phi, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(stiff @ phi, np.diag(mass) @ phi * omega2, atol=1e-9)
    assert np.all(phi[-1] > 0)
    assert modes.linear_order == 6


def test_modal_damping_gives_every_mode_its_ratio():
    zeta = [0.02, 0.05, 0.1]
    modes = ShearBuilding(mass=[2.0, 1.5, 1.0], zeta=zeta).modal_properties()
    minv = np.linalg.inv(modes.mass_matrix)
    a = np.block(
        [
            [np.zeros((3, 3)), np.eye(3)],
            [-minv @ modes.stiffness_matrix, -minv @ modes.damping_matrix],
        ]
    )
    poles = np.linalg.eigvals(a)
    poles = poles[poles.imag > 0]
    poles = poles[np.argsort(np.abs(poles))]
    np.testing.assert_allclose(np.abs(poles), modes.omega, rtol=1e-10)
    np.testing.assert_allclose(-poles.real / np.abs(poles), zeta, rtol=1e-10)


def test_linear_limit_matches_exact_zoh_discretisation():
    building = ShearBuilding(mass=[2.0, 1.5, 1.0], stiffness=[900, 700, 400], alpha=1)
    ground = -paper_excitation(2000, DT, r0=0.2, random_state=0)
    res = building.simulate(ground, DT)
    ref = _zoh_linear_reference(building.modal_properties(), ground, DT)
    # RK4 truncation (4 substeps, omega h up to 0.12) is about 5e-7 of the peak.
    np.testing.assert_allclose(
        res.displacement, ref, rtol=0, atol=2e-6 * np.abs(ref).max()
    )


def test_free_decay_follows_the_mode_and_its_damping():
    building = ShearBuilding(stiffness=[900.0, 700.0, 400.0], zeta=0.04, alpha=1.0)
    modes = building.modal_properties()
    t = np.arange(1500) * DT
    for j in range(3):
        phi, w = modes.mode_shapes[:, j], modes.omega[j]
        state0 = np.concatenate([0.01 * phi, np.zeros(6)])
        res = building.simulate(np.zeros(t.size), DT, initial_state=state0)
        wd = w * np.sqrt(1 - 0.04**2)
        q = np.exp(-0.04 * w * t) * (
            np.cos(wd * t) + 0.04 / np.sqrt(1 - 0.04**2) * np.sin(wd * t)
        )
        np.testing.assert_allclose(
            res.displacement, 0.01 * np.outer(q, phi), rtol=0, atol=1e-6
        )


def test_undamped_linear_building_conserves_energy():
    building = ShearBuilding(zeta=0.0, alpha=1.0)
    modes = building.modal_properties()
    state0 = np.concatenate([[0.01, -0.02, 0.03], np.zeros(6)])
    res = building.simulate(np.zeros(1000), DT, initial_state=state0)
    x, v = res.displacement, res.velocity
    energy = 0.5 * np.einsum("ti,ij,tj->t", v, modes.mass_matrix, v) + 0.5 * np.einsum(
        "ti,ij,tj->t", x, modes.stiffness_matrix, x
    )
    # RK4 loses about 2e-5 of the energy in 10 s here (its truncation).
    np.testing.assert_allclose(energy, energy[0], rtol=5e-5)


def test_hysteresis_dissipates_energy_without_viscous_damping():
    building = ShearBuilding(zeta=0.0, alpha=0.1)
    state0 = np.concatenate([np.zeros(3), [0.5, 1.0, 1.5], np.zeros(3)])
    res = building.simulate(np.zeros(3000), DT, initial_state=state0)
    kinetic = 0.5 * np.sum(res.velocity**2, axis=1)  # unit masses
    # Yielding storeys take energy out of the motion: late velocities are small.
    assert np.abs(res.drift).max() > 2 * building.z0
    assert kinetic[-500:].max() < 0.1 * kinetic[0]


# ---------------------------------------------------------- outputs
def test_absolute_acceleration_is_relative_plus_ground():
    building = ShearBuilding(r0=0.15, n_substeps=8)
    rec = building.generate(1, n_samples=3000, dt=0.002, random_state=0)
    v, acc, ag = rec.velocity[0], rec.acceleration[0], rec.ground_acceleration[0]
    # Central differences of the relative velocity, plus the ground motion
    # held over the step on each side.
    dv = (v[2:] - v[:-2]) / (2 * 0.002)
    approx = dv + 0.5 * (ag[1:-1] + ag[:-2])[:, None]
    np.testing.assert_allclose(acc[1:-1], approx, rtol=0, atol=2e-2 * np.abs(acc).max())


def test_drift_and_hysteretic_state_follow_the_storeys():
    building = ShearBuilding(r0=0.2)
    rec = building.generate(2, n_samples=1500, random_state=1)
    x = rec.displacement
    np.testing.assert_allclose(rec.drift[..., 0], x[..., 0])
    np.testing.assert_allclose(rec.drift[..., 1:], np.diff(x, axis=-1))
    assert np.abs(rec.hysteretic).max() <= building.z0 * (1 + 1e-9)
    assert np.abs(rec.hysteretic).max() > 0.9 * building.z0
    # Each storey's z is the Bouc-Wen element driven by that storey's drift.
    element = HystereticOscillator(beta=building.beta, gamma=building.gamma)
    for i in range(3):
        z = element.hysteretic_state(rec.drift[..., i])
        np.testing.assert_allclose(
            rec.hysteretic[..., i], z, rtol=0, atol=5e-3 * building.z0
        )


def test_per_storey_parameters_act_on_their_own_storey():
    # Storey 2 is linear (alpha = 1): its loop parameters cannot matter.
    ground = -paper_excitation(1000, DT, r0=0.2, random_state=2)
    a = ShearBuilding(alpha=[0.1, 1.0, 0.3], beta=[0.5, 0.5, 0.5]).simulate(ground, DT)
    b = ShearBuilding(alpha=[0.1, 1.0, 0.3], beta=[0.5, 0.9, 0.5]).simulate(ground, DT)
    c = ShearBuilding(alpha=[0.1, 1.0, 0.3], beta=[0.9, 0.5, 0.5]).simulate(ground, DT)
    np.testing.assert_array_equal(a.displacement, b.displacement)
    assert not np.array_equal(a.hysteretic[:, 1], b.hysteretic[:, 1])
    assert np.abs(a.displacement - c.displacement).max() > 1e-4


@pytest.mark.parametrize(
    "outputs", [None, "drift", ("acceleration", "hysteretic"), ["displacement"]]
)
def test_output_selection_and_shapes(outputs):
    building = ShearBuilding(n_storeys=4, r0=0.1)
    rec = building.generate(3, n_samples=200, random_state=0, outputs=outputs)
    expected = (
        ("acceleration", "drift", "displacement", "velocity", "hysteretic")
        if outputs is None
        else ((outputs,) if isinstance(outputs, str) else tuple(outputs))
    )
    assert set(rec) == {"t", "ground_acceleration", "r0", "dt", "frame", *expected}
    for name in expected:
        assert rec[name].shape == (3, 200, 4)
    single = building.simulate(rec.ground_acceleration[1], DT, outputs=outputs)
    assert set(single) == {"t", *expected}
    for name in expected:
        assert single[name].shape == (200, 4)
        np.testing.assert_array_equal(single[name], rec[name][1])


def test_frame_has_one_row_per_sample_and_one_column_per_storey():
    rec = ShearBuilding(n_storeys=2, r0=0.1).generate(
        2, n_samples=50, random_state=0, outputs=("drift", "velocity"), as_frame=True
    )
    frame = rec.frame
    assert list(frame.columns) == [
        "realization",
        "t",
        "ground_acceleration",
        "drift_1",
        "drift_2",
        "velocity_1",
        "velocity_2",
    ]
    assert frame.shape == (100, 7)
    row = frame.iloc[50 + 7]  # realisation 1, sample 7
    assert row.realization == 1 and row.t == pytest.approx(7 * DT)
    assert row.drift_2 == rec.drift[1, 7, 1]
    assert row.ground_acceleration == rec.ground_acceleration[1, 7]


# ---------------------------------------------------------- randomness
def test_same_seed_same_records_other_seed_other_records():
    building = ShearBuilding(r0=0.1)
    a = building.generate(2, n_samples=300, random_state=7)
    b = building.generate(2, n_samples=300, random_state=7)
    c = building.generate(2, n_samples=300, random_state=8)
    np.testing.assert_array_equal(a.acceleration, b.acceleration)
    assert not np.allclose(a.acceleration, c.acceleration)
    rng = np.random.RandomState(7)
    np.testing.assert_array_equal(
        building.generate(2, n_samples=300, random_state=rng).acceleration,
        a.acceleration,
    )


def test_vectorised_realisations_equal_individual_ones():
    building = ShearBuilding(r0=0.2)
    ground = -paper_excitation(800, DT, r0=0.2, n_realizations=3, random_state=4)
    state0 = np.random.RandomState(0).uniform(-0.01, 0.01, (3, 9))
    together = building.simulate(ground, DT, initial_state=state0)
    for r in range(3):
        alone = building.simulate(ground[r], DT, initial_state=state0[r])
        for name in ("acceleration", "displacement", "velocity", "hysteretic"):
            np.testing.assert_array_equal(together[name][r], alone[name])
    assert together.displacement[0, 0] == pytest.approx(state0[0, :3])


def test_starts_from_rest_and_the_last_input_acts_on_no_sample():
    building = ShearBuilding(r0=0.2)
    ground = -paper_excitation(300, DT, r0=0.2, random_state=5)
    res = building.simulate(ground, DT)
    assert np.all(res.displacement[0] == 0) and np.all(res.acceleration[0] == 0)
    changed = ground.copy()
    changed[-1] += 100.0
    np.testing.assert_array_equal(
        building.simulate(changed, DT).displacement, res.displacement
    )


# ---------------------------------------------------------- calibration
def test_calibration_meets_its_target_on_its_records():
    building = ShearBuilding()
    r0 = building.calibrate_r0(n_realizations=30, target=1.5, random_state=3)
    check = building.set_params(r0=r0)
    ground = -paper_excitation(2000, DT, r0=r0, n_realizations=30, random_state=3)
    drift = check.simulate(ground, DT, outputs="drift").drift
    ductility = np.abs(drift).max(axis=(1, 2)) / check.z0
    assert ductility.mean() == pytest.approx(1.5, rel=1e-3)
    # A stronger target needs a stronger ground motion.
    assert building.calibrate_r0(n_realizations=30, target=2.5, random_state=3) > r0


def test_generate_calibrates_when_asked():
    building = ShearBuilding(n_storeys=2)
    r0 = building.calibrate_r0()
    rec = building.generate(1, n_samples=100, random_state=0)
    assert rec.r0 == r0
    rec_fixed = building.set_params(r0=r0).generate(1, n_samples=100, random_state=0)
    np.testing.assert_array_equal(rec.acceleration, rec_fixed.acceleration)


def test_clone_and_pickle_keep_per_storey_parameters():
    building = ShearBuilding(n_storeys=2, mass=[2.0, 1.0], alpha=[0.1, 0.5], r0=0.1)
    ground = -paper_excitation(300, DT, r0=0.1, random_state=0)
    expected = building.simulate(ground, DT).acceleration
    for copy in (clone(building), pickle.loads(pickle.dumps(building))):
        np.testing.assert_array_equal(copy.simulate(ground, DT).acceleration, expected)
    taller = clone(building).set_params(n_storeys=4, mass=1.0, alpha=0.1)
    assert taller.simulate(ground, DT).acceleration.shape == (300, 4)


# ---------------------------------------------------------- validation
@pytest.mark.parametrize(
    ("params", "match"),
    [
        ({"n_storeys": 0}, "n_storeys"),
        ({"mass": [1.0, 1.0]}, r"mass must be a scalar or have one value per storey"),
        ({"stiffness": [400.0, -1.0, 400.0]}, r"stiffness\[1\]"),
        ({"mass": "heavy"}, "mass must be a real number or one value per storey"),
        ({"alpha": 1.5}, "alpha"),
        ({"zeta": 1.0}, "zeta"),
        ({"beta": [0.5, -0.1, 0.5]}, "beta must be >= 0 .* storey 2"),
        ({"n": 2.0, "beta": 0.1, "gamma": -0.5}, "beta \\+ gamma"),
        ({"z0": 0.0}, "z0"),
        ({"omega_s": -1.0}, "omega_s"),
        ({"t1": 5.0, "t2": 4.0}, "t2"),
        ({"r0": "strong"}, "r0"),
        ({"n_substeps": 0}, "n_substeps"),
    ],
)
def test_invalid_parameters_name_the_argument(params, match):
    with pytest.raises(ValueError, match=match):
        ShearBuilding(**params).generate(1, n_samples=10, random_state=0)


def test_invalid_call_arguments_name_the_argument():
    building = ShearBuilding(r0=0.1)
    with pytest.raises(ValueError, match="outputs must name"):
        building.simulate(np.zeros(10), DT, outputs="floor")
    with pytest.raises(ValueError, match="outputs must name"):
        building.generate(1, n_samples=10, outputs=())
    with pytest.raises(ValueError, match="initial_state must have shape"):
        building.simulate(np.zeros(10), DT, initial_state=np.zeros(6))
    with pytest.raises(ValueError, match="ground_acceleration"):
        building.simulate(np.full(10, np.nan), DT)
    with pytest.raises(ValueError, match="dt"):
        building.simulate(np.zeros(10), 0.0)
