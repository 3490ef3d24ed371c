"""Multi-storey shear building with Bouc-Wen storey springs under ground motion.

:class:`ShearBuilding` is the multi-degree-of-freedom sibling of
:class:`~sysid_nn.oscillator.HystereticOscillator`: ``n_storeys`` floor masses
joined by storey springs with the oscillator's Bouc-Wen hysteresis, shaken at
the base by the same earthquake-like ground motion (modulated, Kanai-Tajimi
filtered white noise). Its linear limit has ``2 n_storeys`` states, so it
gives the identification of a structure's order a known answer.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Sequence

import numpy as np
import pandas as pd
import scipy.linalg
from numpy.typing import ArrayLike
from sklearn.utils import Bunch, check_random_state

from sysid_nn import excitation as _exc
from sysid_nn._kernels._building import simulate_shear_building
from sysid_nn._records._validation import (
    InvalidArgumentError,
    check_finite_array,
    check_in_range,
    check_positive,
    check_positive_int,
    check_real,
)
from sysid_nn.oscillator import _GroundMotionStructure

__all__ = ["ShearBuilding"]

#: Names of the responses :meth:`ShearBuilding.simulate` can return.
OUTPUTS = ("acceleration", "drift", "displacement", "velocity", "hysteretic")

# Settings of the default calibration (20 s records at 0.01 s, as the oscillator's).
_CAL_N_REALIZATIONS = 200
_CAL_N_SAMPLES = 2000
_CAL_DT = 0.01
_CAL_SEED = 0
_CAL_TARGET = 2.0

_STOREY = ("mass", "stiffness", "alpha", "beta", "gamma", "n", "z0")


class ShearBuilding(_GroundMotionStructure):
    """Shear building with a Bouc-Wen hysteretic spring in every storey.

    Floor ``i = 1..N`` (``N = n_storeys``, floor 1 the lowest) has mass
    ``m_i`` and displacement ``x_i`` relative to the ground (``x_0 = 0``).
    Storey ``i`` joins floor ``i - 1`` to floor ``i``; its drift
    ``d_i = x_i - x_{i-1}`` drives the oscillator's Bouc-Wen element
    (see :class:`~sysid_nn.oscillator.HystereticOscillator`) with its own
    parameters, and the storey force is

    .. math::

        s_i = k_i\\,(\\alpha_i d_i + (1 - \\alpha_i) z_i), \\qquad
        \\dot z_i = \\dot d_i - \\frac{\\beta_i |\\dot d_i| |z_i|^{n_i-1} z_i
        + \\gamma_i \\dot d_i |z_i|^{n_i}}{z_{0,i}^{n_i}} .

    Under the ground acceleration ``a_g``,

    .. math::

        M \\ddot x + C \\dot x + f_s(x, z) = -M \\mathbf{1}\\, a_g ,
        \\qquad f_{s,i} = s_i - s_{i+1} \\; (s_{N+1} = 0),

    with ``M = diag(m)`` and the classical modal damping matrix
    ``C = M Phi diag(2 zeta_j omega_j) Phi^T M`` built from the mass-normalised
    modes ``Phi`` and circular frequencies ``omega_j`` of the pre-yield
    stiffness ``K`` (eigenproblem ``K phi = omega^2 M phi``), so that every
    linear mode has damping ratio ``zeta_j``. The absolute floor accelerations
    ``x'' + a_g = -M^{-1} (C x' + f_s)`` depend on the state only (no direct
    feed-through of ``a_g``).

    The state is ``(x, x', z)``: ``3 N`` values. With ``alpha = 1`` the building
    is linear and ``2 N`` states describe it (:meth:`modal_properties`); each
    hysteretic storey adds one. With ``n_storeys=1``, ``mass=1``,
    ``stiffness=omega0**2`` and the same loop parameters the building is the
    :class:`~sysid_nn.oscillator.HystereticOscillator` with ``F = -a_g``.

    The defaults give a three-storey frame with equal floors and storeys,
    fundamental frequency 1.42 Hz (higher modes 3.97 and 5.74 Hz), 2 %
    damping in every mode, and a post-yield stiffness of 10 %. The ground
    motion of :meth:`generate` is the oscillator's (see
    :func:`sysid_nn.excitation.paper_excitation`) with strength ``r0``
    calibrated so that the mean peak storey ductility
    ``E[max_i max_t |d_i(t)| / z0_i]`` is 2 over 20 s records
    (:meth:`calibrate_r0`; the oscillator's rule ``E[max|X|] = 2 z0``). For
    the defaults this gives ``r0 = 0.158`` (peak ground accelerations about
    2.5); in 200 records the weakest just reach the yield drift (peak
    ductility 1.1), the median reaches 1.9 and the strongest 3.4, always in
    the first storey.

    Parameters
    ----------
    n_storeys : int, default=3
        Number of storeys (and floors), ``>= 1``.
    mass : float or array-like of shape (n_storeys,), default=1.0
        Floor masses, bottom to top, ``> 0``. Units are the user's: with
        masses in kg and stiffnesses in N/m, displacements are in m.
    stiffness : float or array-like of shape (n_storeys,), default=400.0
        Pre-yield storey stiffnesses ``k_i``, bottom to top, ``> 0``.
    zeta : float or array-like of shape (n_storeys,), default=0.02
        Modal damping ratio of every mode, or one per mode (lowest frequency
        first), ``>= 0`` and ``< 1``.
    alpha : float or array-like of shape (n_storeys,), default=0.1
        Ratio of post-yield to pre-yield storey stiffness, in ``[0, 1]``;
        ``alpha = 1`` switches the hysteresis off.
    beta, gamma : float or array-like of shape (n_storeys,), default=0.5
        Bouc-Wen loop parameters, as in the oscillator (``beta >= 0``;
        ``beta + gamma >= 0`` when ``n > 1``).
    n : float or array-like of shape (n_storeys,), default=1.0
        Smoothness of the elastic-plastic transition, ``> 0``.
    z0 : float or array-like of shape (n_storeys,), default=0.01
        Yield drift scale of each storey, ``> 0``; with ``beta + gamma = 1``
        ``|z_i| <= z0_i``.
    zeta_s, omega_s, t1, t2 : float, default=0.5, 30.0, 3.0, 15.0
        Kanai-Tajimi filter and modulation of the ground motion of
        :meth:`generate`, as in the oscillator.
    r0 : "calibrate" or float, default="calibrate"
        Strength of the ground motion of :meth:`generate`. ``"calibrate"``
        runs :meth:`calibrate_r0` with its defaults (cached per parameter
        set); a float skips it.
    n_substeps : int, default=4
        Classical RK4 steps per sample, as in the oscillator.

    See Also
    --------
    sysid_nn.oscillator.HystereticOscillator : The single-storey case.

    Examples
    --------
    >>> from sysid_nn import ShearBuilding
    >>> building = ShearBuilding(r0=0.16)
    >>> rec = building.generate(2, n_samples=1000, random_state=0)
    >>> rec.acceleration.shape                   # realisations, samples, floors
    (2, 1000, 3)
    >>> modes = building.modal_properties()
    >>> modes.frequency.round(2), modes.linear_order
    (array([1.42, 3.97, 5.74]), 6)
    """

    def __init__(
        self,
        n_storeys: int = 3,
        mass: float | ArrayLike = 1.0,
        stiffness: float | ArrayLike = 400.0,
        zeta: float | ArrayLike = 0.02,
        alpha: float | ArrayLike = 0.1,
        beta: float | ArrayLike = 0.5,
        gamma: float | ArrayLike = 0.5,
        n: float | ArrayLike = 1.0,
        z0: float | ArrayLike = 0.01,
        zeta_s: float = 0.5,
        omega_s: float = 30.0,
        t1: float = 3.0,
        t2: float = 15.0,
        r0: str | float = "calibrate",
        n_substeps: int = 4,
    ) -> None:
        self.n_storeys = n_storeys
        self.mass = mass
        self.stiffness = stiffness
        self.zeta = zeta
        self.alpha = alpha
        self.beta = beta
        self.gamma = gamma
        self.n = n
        self.z0 = z0
        self.zeta_s = zeta_s
        self.omega_s = omega_s
        self.t1 = t1
        self.t2 = t2
        self.r0 = r0
        self.n_substeps = n_substeps

    # ------------------------------------------------------------------ checks
    def _per_storey(self, name: str, check) -> np.ndarray:
        """Parameter ``name`` as one checked float per storey (or per mode)."""
        n_storeys = check_positive_int(self.n_storeys, "n_storeys")
        value = getattr(self, name)
        if isinstance(value, numbers.Real) and not isinstance(value, bool):
            return np.full(n_storeys, check(value, name))
        if isinstance(value, bool | str) or not isinstance(
            value, Sequence | np.ndarray | pd.Series
        ):
            raise InvalidArgumentError(
                f"{name} must be a real number or one value per storey "
                f"(length {n_storeys}), got {value!r} of type {type(value).__name__}."
            )
        arr = np.asarray(value)
        if arr.shape != (n_storeys,):
            raise ValueError(
                f"{name} must be a scalar or have one value per storey, shape "
                f"({n_storeys},) for n_storeys={n_storeys}, got shape {arr.shape}; "
                f"pass a scalar to use the same value in every storey."
            )
        return np.array([check(v.item(), f"{name}[{i}]") for i, v in enumerate(arr)])

    def _storey_params(self) -> dict[str, np.ndarray]:
        """Validated per-storey parameters, as float arrays of length n_storeys."""
        p = {
            "mass": self._per_storey("mass", check_positive),
            "stiffness": self._per_storey("stiffness", check_positive),
            "alpha": self._per_storey(
                "alpha", lambda v, nm: check_in_range(v, nm, 0.0, 1.0)
            ),
            "beta": self._per_storey("beta", check_real),
            "gamma": self._per_storey("gamma", check_real),
            "n": self._per_storey("n", check_positive),
            "z0": self._per_storey("z0", check_positive),
        }
        for i in range(len(p["beta"])):
            beta, gamma, n = p["beta"][i], p["gamma"][i], p["n"][i]
            if beta < 0:
                raise ValueError(
                    f"beta must be >= 0 in every storey, got beta={beta!r} in storey "
                    f"{i + 1}: a negative beta makes hysteresis loops generate energy; "
                    f"pass beta >= 0 (beta = 0 is non-linear elastic)."
                )
            if n > 1 and beta + gamma < 0:
                raise ValueError(
                    f"beta + gamma must be >= 0 where n > 1, got beta={beta!r}, "
                    f"gamma={gamma!r}, n={n!r} in storey {i + 1}: z would become "
                    f"infinite at a finite drift; raise gamma or use n <= 1."
                )
        return p

    def _damping_ratios(self) -> np.ndarray:
        return self._per_storey(
            "zeta",
            lambda v, nm: check_in_range(v, nm, 0.0, 1.0, closed=(True, False)),
        )

    # ---------------------------------------------------------- linear model
    def modal_properties(self) -> Bunch:
        """Linear (pre-yield) matrices, natural frequencies and mode shapes.

        Solves ``K phi = omega^2 M phi`` for the pre-yield stiffness matrix
        ``K`` (storey stiffnesses ``k_i``, tridiagonal) and ``M = diag(m)``.
        The linear building (``alpha = 1``, or small motions) has
        ``2 n_storeys`` states: a displacement and a velocity per mode.

        Returns
        -------
        Bunch
            ``omega`` (rad/s) and ``frequency`` (Hz), ascending, shape
            (n_storeys,); ``mode_shapes`` (n_storeys, n_storeys), column
            ``j`` the mass-normalised mode ``j`` (``Phi^T M Phi = I``, sign
            such that the top floor moves positively); ``damping_ratio`` per
            mode; ``mass_matrix``, ``stiffness_matrix``, ``damping_matrix``;
            ``linear_order`` (``2 n_storeys``).

        Examples
        --------
        >>> import numpy as np
        >>> from sysid_nn import ShearBuilding
        >>> modes = ShearBuilding(n_storeys=2, stiffness=100.0).modal_properties()
        >>> modes.omega.round(3)                 # sqrt(100 (3 -+ sqrt 5) / 2)
        array([ 6.18, 16.18])
        >>> bool(np.allclose(modes.mode_shapes.T @ modes.mass_matrix
        ...                  @ modes.mode_shapes, np.eye(2)))
        True
        """
        p = self._storey_params()
        zeta = self._damping_ratios()
        k = p["stiffness"]
        n = len(k)
        stiff = np.diag(k + np.append(k[1:], 0.0))
        if n > 1:
            stiff -= np.diag(k[1:], 1) + np.diag(k[1:], -1)
        mass = np.diag(p["mass"])
        omega2, shapes = scipy.linalg.eigh(stiff, mass)
        shapes *= np.where(shapes[-1] < 0, -1.0, 1.0)
        omega = np.sqrt(omega2)
        # Classical modal damping: Phi^T C Phi = diag(2 zeta omega).
        mphi = mass @ shapes
        damping = mphi @ np.diag(2.0 * zeta * omega) @ mphi.T
        return Bunch(
            omega=omega,
            frequency=omega / (2.0 * math.pi),
            mode_shapes=shapes,
            damping_ratio=zeta,
            mass_matrix=mass,
            stiffness_matrix=stiff,
            damping_matrix=damping,
            linear_order=2 * n,
        )

    # -------------------------------------------------------------- simulation
    def _outputs(self, outputs: str | Sequence[str] | None) -> tuple[str, ...]:
        if outputs is None:
            return OUTPUTS
        names = (outputs,) if isinstance(outputs, str) else tuple(outputs)
        bad = [o for o in names if o not in OUTPUTS]
        if bad or not names:
            raise ValueError(
                f"outputs must name one or more of {', '.join(OUTPUTS)} (or be None "
                f"for all), got {outputs!r}."
            )
        return names

    def simulate(
        self,
        ground_acceleration: ArrayLike,
        dt: float,
        initial_state: ArrayLike | None = None,
        outputs: str | Sequence[str] | None = None,
    ) -> Bunch:
        """Response of the building to a given ground acceleration.

        ``ground_acceleration[..., k]`` is held constant on
        ``[t_k, t_{k+1})`` (zero-order hold) and the equations of motion are
        integrated with classical 4th-order Runge-Kutta, ``n_substeps`` steps
        per sample. Sample ``k`` of the result is the state at ``t_k = k dt``;
        the state at ``t_0`` is ``initial_state`` (at rest by default). Rows
        are independent realisations.

        Parameters
        ----------
        ground_acceleration : array-like, 1-D or 2-D
            Ground acceleration ``a_g``, finite (e.g. a recorded
            accelerogram): shape (n_samples,), or (n_realizations, n_samples)
            for several records at once.
        dt : float
            Sample spacing in seconds, ``> 0``.
        initial_state : array-like, 1-D or 2-D, default=None
            Floor displacements, velocities and hysteretic states
            ``(x, x', z)`` at ``t_0``, shape (3 n_storeys,) or
            (n_realizations, 3 n_storeys); ``None`` is rest.
        outputs : str, sequence of str or None, default=None
            Responses to return, among ``"acceleration"`` (absolute floor
            accelerations), ``"drift"`` (inter-storey drifts),
            ``"displacement"`` and ``"velocity"`` (floors relative to the
            ground) and ``"hysteretic"`` (``z``); ``None`` returns all.

        Returns
        -------
        Bunch
            ``t`` (n_samples,) and every selected output, of shape
            (n_samples, n_storeys) for a 1-D ground acceleration, else
            (n_realizations, n_samples, n_storeys): one column per floor or
            storey, bottom first.

        Examples
        --------
        >>> import numpy as np
        >>> from sysid_nn import ShearBuilding
        >>> building = ShearBuilding(alpha=1.0, zeta=0.5)   # linear, well damped
        >>> res = building.simulate(-np.ones(1000), dt=0.01, outputs="drift")
        >>> res.drift[-1] * 400.0   # static: storey i carries floors i..3
        array([3., 2., 1.])
        """
        ground = check_finite_array(ground_acceleration, "ground_acceleration")
        dt = check_positive(dt, "dt")
        names = self._outputs(outputs)
        p = self._storey_params()
        modes = self.modal_properties()
        n_sub = self._substeps()
        n = len(p["mass"])
        rows = np.atleast_2d(ground)
        n_real = rows.shape[0]
        if initial_state is None:
            state0 = np.zeros((n_real, 3 * n))
        else:
            state0 = check_finite_array(initial_state, "initial_state")
            if state0.shape[-1] != 3 * n or (
                state0.ndim == 2 and state0.shape[0] not in (1, n_real)
            ):
                raise ValueError(
                    f"initial_state must have shape ({3 * n},) or ({n_real}, {3 * n}) "
                    f"(x, x', z of every floor per realisation), got {state0.shape}."
                )
            state0 = np.ascontiguousarray(np.broadcast_to(state0, (n_real, 3 * n)))
        z0n = p["z0"] ** p["n"]
        disp, vel, hyst, acc = simulate_shear_building(
            rows,
            dt,
            n_sub,
            1.0 / p["mass"],
            modes.damping_matrix,
            p["stiffness"] * p["alpha"],
            p["stiffness"] * (1.0 - p["alpha"]),
            p["beta"] / z0n,
            p["gamma"] / z0n,
            p["n"],
            state0,
        )
        drift = np.diff(disp, axis=-1, prepend=0.0)
        found = {
            "acceleration": acc,
            "drift": drift,
            "displacement": disp,
            "velocity": vel,
            "hysteretic": hyst,
        }
        res = Bunch(t=np.arange(ground.shape[-1]) * dt)
        for name in names:
            res[name] = found[name][0] if ground.ndim == 1 else found[name]
        return res

    # ------------------------------------------------------------- calibration
    def _calibration_key(self) -> tuple:
        p = self._storey_params()
        return (
            self.modal_properties().damping_matrix.tobytes(),
            tuple(tuple(p[k]) for k in _STOREY),
        )

    def _mean_peak(self, force: np.ndarray, dt: float) -> float:
        # The mean over records of the peak storey ductility; the ground
        # acceleration is -F, as in generate.
        drift = self.simulate(-force, dt, outputs="drift").drift
        z0 = self._storey_params()["z0"]
        return float(np.mean(np.max(np.abs(drift) / z0, axis=(1, 2))))

    def calibrate_r0(
        self,
        n_realizations: int = _CAL_N_REALIZATIONS,
        n_samples: int = _CAL_N_SAMPLES,
        dt: float = _CAL_DT,
        target: float = _CAL_TARGET,
        random_state: int | np.random.RandomState | None = _CAL_SEED,
    ) -> float:
        """Ground-motion strength ``r0`` giving a mean peak storey ductility ``target``.

        The ductility of a record is ``max_i max_t |d_i(t)| / z0_i``, the
        largest drift of any storey in units of its yield drift scale. As in
        :meth:`HystereticOscillator.calibrate_r0
        <sysid_nn.oscillator.HystereticOscillator.calibrate_r0>`, the
        ``n_realizations`` ground motions are drawn once with ``r0 = 1``
        (common random numbers) and the scale solving
        ``mean ductility = target`` is found by bracketing and Brent's
        method, so the result is a deterministic function of the parameters
        and ``random_state``; its Monte Carlo error is about
        ``0.25 / sqrt(n_realizations)`` relative (2 % for the default 200).
        Results for an integer ``random_state`` are cached per parameter set.

        Parameters
        ----------
        n_realizations : int, default=200
            Number of Monte Carlo records.
        n_samples : int, default=2000
            Record length in samples (20 s at 0.01 s).
        dt : float, default=0.01
            Sample spacing in seconds.
        target : float, default=2.0
            Target mean peak storey ductility, ``> 0``.
        random_state : int, RandomState instance or None, default=0
            Seed of the Monte Carlo records.

        Returns
        -------
        float
            The calibrated ``r0``.

        Examples
        --------
        >>> from sysid_nn import ShearBuilding
        >>> round(ShearBuilding().calibrate_r0(n_realizations=20), 3)
        0.159
        """
        return self._calibrated_r0(
            n_realizations=n_realizations,
            n_samples=n_samples,
            dt=dt,
            target=target,
            random_state=random_state,
        )

    # -------------------------------------------------------------- generation
    def generate(
        self,
        n_realizations: int,
        n_samples: int = 2000,
        dt: float = 0.01,
        random_state: int | np.random.RandomState | None = None,
        outputs: str | Sequence[str] | None = None,
        as_frame: bool = False,
    ) -> Bunch:
        """Generate records of the building under earthquake-like ground motion.

        Each realisation draws the oscillator's excitation (broken-line white
        noise, modulated by ``r(t)`` with strength ``r0``, Kanai-Tajimi
        filtered; :func:`sysid_nn.excitation.paper_excitation`), takes it as
        the ground acceleration ``a_g = -F`` (the oscillator's ``F`` is the
        force per unit mass ``-a_g``) and integrates the building from rest
        (:meth:`simulate`). With ``r0="calibrate"`` the strength comes from
        :meth:`calibrate_r0` with its defaults, whatever ``n_samples`` and
        ``dt`` are.

        Parameters
        ----------
        n_realizations : int
            Number of independent records.
        n_samples : int, default=2000
            Samples per record.
        dt : float, default=0.01
            Sample spacing in seconds.
        random_state : int, RandomState instance or None, default=None
            Seed of the ground motion; the same seed gives identical records.
        outputs : str, sequence of str or None, default=None
            Responses to return (see :meth:`simulate`); ``None`` returns all.
        as_frame : bool, default=False
            Also return a pandas DataFrame in ``frame``.

        Returns
        -------
        Bunch
            ``t`` (n_samples,); ``ground_acceleration``
            (n_realizations, n_samples); every selected output of shape
            (n_realizations, n_samples, n_storeys), so that
            ``list(rec.acceleration)`` is one ``y`` per experiment; ``r0`` and
            ``dt``; ``frame``: ``None``, or with ``as_frame=True`` a DataFrame
            with one row per realisation and sample and columns
            ``realization, t, ground_acceleration`` and ``<output>_<i>`` for
            every selected output and floor or storey ``i = 1..n_storeys``.

        Examples
        --------
        >>> from sysid_nn import ShearBuilding
        >>> rec = ShearBuilding(r0=0.16).generate(
        ...     2, n_samples=500, random_state=0, outputs="drift", as_frame=True)
        >>> rec.drift.shape, rec.frame.shape
        ((2, 500, 3), (1000, 6))
        >>> list(rec.frame.columns)
        ['realization', 't', 'ground_acceleration', 'drift_1', 'drift_2', 'drift_3']
        """
        n_realizations = check_positive_int(n_realizations, "n_realizations")
        n_samples = check_positive_int(n_samples, "n_samples")
        dt = check_positive(dt, "dt")
        names = self._outputs(outputs)
        self._storey_params()  # fail on bad parameters before calibrating
        self._damping_ratios()
        e = self._excitation_params()
        r0 = self._resolved_r0()
        ground = -_exc.paper_excitation(
            n_samples,
            dt,
            r0=r0,
            n_realizations=n_realizations,
            random_state=check_random_state(random_state),
            **e,
        )
        rec = self.simulate(ground, dt, outputs=names)
        rec.update(ground_acceleration=ground, r0=r0, dt=dt, frame=None)
        if as_frame:
            rec.frame = _frame(rec, names)
        return rec


def _frame(rec: Bunch, names: tuple[str, ...]) -> pd.DataFrame:
    n_real, n_samp = rec.ground_acceleration.shape
    columns = {
        "realization": np.repeat(np.arange(n_real), n_samp),
        "t": np.tile(rec.t, n_real),
        "ground_acceleration": rec.ground_acceleration.ravel(),
    }
    for name in names:
        values = rec[name].reshape(n_real * n_samp, -1)
        for i in range(values.shape[1]):
            columns[f"{name}_{i + 1}"] = values[:, i]
    return pd.DataFrame(columns)
