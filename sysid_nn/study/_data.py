"""The study's records: training, validation and test realisations."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from sklearn.utils import Bunch

from sysid_nn import HystereticOscillator
from sysid_nn.study._config import StudyConfig, _check_int

# Names and units of the record fields for figure axes: eq. 13-15 are written
# per unit mass, so the excitation F is a force per unit mass, in m/s^2.
_NAMES = {
    "excitation": "excitation F",
    "displacement": "displacement X",
    "velocity": "velocity Ẋ",
    "hysteretic": "hysteretic state Z",
}
_UNITS = {
    "excitation": "m/s²",
    "displacement": "m",
    "velocity": "m/s",
    "hysteretic": "m",
}


def select_typical(peaks: Sequence[float], k: int) -> np.ndarray:
    """Return the indices of the ``k`` records whose peak is nearest the median.

    Parameters
    ----------
    peaks : sequence of float
        Peak absolute displacement of every candidate record.
    k : int
        Number of records to choose, ``1 <= k <= len(peaks)``.

    Returns
    -------
    ndarray of int
        Sorted indices; ties go to the lower index.

    Examples
    --------
    >>> from sysid_nn.study import select_typical
    >>> select_typical([0.01, 0.05, 0.02, 0.03, 0.02], 2).tolist()
    [2, 4]
    """
    peaks = np.asarray(peaks, dtype=float)
    _check_int(k, "k", 1, "Choose at least one record.")
    if k > peaks.size:
        raise ValueError(f"k={k} exceeds the {peaks.size} candidate records.")
    distance = np.abs(peaks - np.median(peaks))
    return np.sort(np.argsort(distance, kind="stable")[:k])


def _records(rec: Bunch, index: Any = slice(None)) -> Bunch:
    """The study's record fields of a generated Bunch, rows ``index``."""
    return Bunch(
        excitation=rec.excitation[index],
        displacement=rec.displacement[index],
        velocity=rec.velocity[index],
        hysteretic=rec.hysteretic[index],
    )


def generate_data(config: StudyConfig) -> Bunch:
    """Training, validation and test records of the hysteretic oscillator.

    The oscillator and excitation have the paper's parameters (section 4.1,
    ``r0`` calibrated so that ``E[max|X|] = 2 z0``). Training records are
    chosen by :func:`select_typical` from ``config.candidates`` records;
    validation and test records are drawn from their own seeds.

    Parameters
    ----------
    config : StudyConfig
        Seeds, numbers of records, their length and sampling step.

    Returns
    -------
    Bunch
        ``train``, ``validation``, ``test``: Bunches of ``excitation,
        displacement, velocity, hysteretic`` arrays of shape
        ``(n_records, n_samples)``; ``t``, ``dt``, ``r0``, ``seeds``,
        ``candidate_peaks`` (peak ``|X|`` of every candidate),
        ``train_index`` (the chosen candidates), ``oscillator``,
        ``natural_period`` (``2 pi / omega0``, s) and the fields' ``names``
        and ``units`` (for figure axes).

    Examples
    --------
    >>> from sysid_nn.study import StudyConfig, generate_data
    >>> data = generate_data(StudyConfig(n_test=2, n_samples=600, n_candidates=3))
    >>> data.train.displacement.shape, data.test.excitation.shape
    ((1, 600), (2, 600))
    """
    seeds = config.seeds()
    osc = HystereticOscillator()

    def draw(n: int, seed: int) -> Bunch:
        return osc.generate(
            n, n_samples=config.n_samples, dt=config.dt, random_state=seed
        )

    pool = draw(config.candidates, seeds["train"])
    peaks = np.max(np.abs(pool.displacement), axis=1)
    chosen = select_typical(peaks, config.n_train)
    return Bunch(
        train=_records(pool, chosen),
        validation=_records(draw(config.n_val, seeds["validation"])),
        test=_records(draw(config.test_size, seeds["test"])),
        t=pool.t,
        dt=float(config.dt),
        r0=float(pool.r0),
        seeds=seeds,
        candidate_peaks=peaks,
        train_index=chosen,
        oscillator=osc,
        natural_period=2 * np.pi / osc.omega0,
        names=dict(_NAMES),
        units=dict(_UNITS),
    )
