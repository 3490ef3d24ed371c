"""Is a shear building's order visible in its records?

A linear shear building of ``n`` storeys has ``2 n`` states. This script
generates records of :class:`sysid_nn.ShearBuilding` with 3 and 5 storeys,
linear (``alpha=1``) and with its default hysteresis, with and without
measurement noise, takes the absolute floor accelerations (or the floor
displacements) as outputs and the ground acceleration as input, and prints
the singular values of the subspace step's projected block-Hankel matrix
(the projection that ``sysid_nn._engine._subspace.subspace_model`` factorises to
choose its states). The order shows as the gap after the ``2 n``-th value:
the table gives the largest ratio ``s_k / s_{k+1}`` and where it falls, and
the ratio at ``k = 2 n``. Writes ``results_building_order.md`` next to itself.

Usage::

    python benchmarks/bench_building_order.py
"""

from __future__ import annotations

import platform
import time
from pathlib import Path

import numpy as np

from sysid_nn import ShearBuilding
from sysid_nn._engine._subspace import HORIZON, _windows

HERE = Path(__file__).resolve().parent
MD = HERE / "results_building_order.md"
SEED = 0
N_RECORDS = 10
N_SAMPLES = 2000
#: Singular values printed per case.
N_SHOWN = 14


def projection_singular_values(Y, U, horizon=HORIZON):
    """Singular values of the oblique projection the subspace step factorises."""
    past, u_future, y_future = _windows(Y, U, horizon)
    design = np.vstack([past, u_future])
    coef = np.linalg.lstsq(design.T, y_future.T, rcond=None)[0].T
    return np.linalg.svd(coef[:, : past.shape[0]] @ past, compute_uv=False)


def case(n_storeys, alpha, output, noise):
    building = ShearBuilding(n_storeys=n_storeys, alpha=alpha)
    # The hysteretic buildings' calibrated strength, also for the linear ones,
    # so that both see the same ground motions.
    r0 = ShearBuilding(n_storeys=n_storeys).calibrate_r0()
    rec = building.set_params(r0=r0).generate(
        N_RECORDS, N_SAMPLES, random_state=SEED, outputs=output
    )
    y = rec[output]
    rng = np.random.default_rng(SEED)
    y = y + noise * y.std(axis=(0, 1)) * rng.standard_normal(y.shape)
    U = [g[:, None] for g in rec.ground_acceleration]
    return projection_singular_values(list(y), U)


def main():
    rows = []
    for n_storeys in (3, 5):
        for alpha, label in ((1.0, "linear"), (0.1, "hysteretic")):
            for output in ("acceleration", "displacement"):
                for noise in (0.0, 0.02):
                    start = time.process_time()
                    sv = case(n_storeys, alpha, output, noise)
                    cpu = time.process_time() - start
                    ratios = sv[:N_SHOWN] / sv[1 : N_SHOWN + 1]
                    k_gap = int(np.argmax(ratios)) + 1
                    rows.append(
                        (
                            n_storeys,
                            label,
                            output,
                            noise,
                            sv[:N_SHOWN] / sv[0],
                            k_gap,
                            ratios[k_gap - 1],
                            ratios[2 * n_storeys - 1],
                            cpu,
                        )
                    )
                    print(
                        f"{n_storeys} storeys, {label}, {output}, noise {noise:.0%}: "
                        f"largest gap after {k_gap} (x{ratios[k_gap - 1]:.3g}), "
                        f"after {2 * n_storeys}: x{ratios[2 * n_storeys - 1]:.3g}",
                        flush=True,
                    )
    write(rows)


def write(rows):
    lines = [
        "# Order of a shear building in the subspace step's singular values",
        "",
        "`python benchmarks/bench_building_order.py`: "
        f"{N_RECORDS} records of {N_SAMPLES} samples at 0.01 s per case "
        f"(`ShearBuilding`, default parameters, `random_state={SEED}`, the "
        "hysteretic building's calibrated strength for both the linear and "
        "the hysteretic one); input the ground acceleration, outputs every "
        "floor's absolute acceleration or displacement, optionally with white "
        "measurement noise of the given fraction of each output's standard "
        f"deviation; past and future horizon {HORIZON} samples. A linear "
        "building of n storeys has 2n states. Machine: "
        f"{platform.machine()}, Python {platform.python_version()}.",
        "",
        "| storeys | building | output | noise | largest gap after | its ratio "
        "| ratio s_2n / s_2n+1 | CPU s |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for n, label, output, noise, _, k_gap, gap, at_true, cpu in rows:
        lines.append(
            f"| {n} | {label} | {output} | {noise:.0%} | {k_gap} | {gap:.3g} "
            f"| {at_true:.3g} | {cpu:.1f} |"
        )
    lines += [
        "",
        f"Singular values s_1 .. s_{N_SHOWN}, divided by s_1:",
        "",
    ]
    for n, label, output, noise, sv, *_ in rows:
        values = " ".join(f"{v:.2e}" for v in sv)
        lines.append(f"- {n} storeys, {label}, {output}, noise {noise:.0%}: {values}")
    MD.write_text("\n".join(lines) + "\n")
    print(f"wrote {MD}")


if __name__ == "__main__":
    main()
