"""Whether a fitted model's free run depends on its start: a chaos check.

On a chaotic system two free runs that start a hair apart part ways within a
few dozen periods, so a free run scored against a measured record is
compared with one trajectory out of many equally right ones: its NRMSE says
nothing about the model (even the true equations score above 1). The check
runs the model's free run twice, the second with its first input sample
nudged by a millionth of the input's spread (a perturbation of its initial
state), and measures how far apart the two runs end up. It sees the
sensitivity of the fitted model, not of the system: a model fitted to a
chaotic record that settled into a non-chaotic response passes unnoticed.
"""

from __future__ import annotations

from typing import Any

import numpy as np

#: Relative size of the nudge to the first input sample.
NUDGE = 1e-6
#: Runs further apart than this share of the output's spread over the last
#: quarter of the record have parted ways: the nudge grew ten-thousandfold
#: (models fitted to a chaotic record: 0.08-0.29 when they are sensitive;
#: to periodic and hysteretic records: 1e-5 or less; see the pitfalls page).
PARTED = 0.01


def free_run_divergence(estimator: Any, X: Any) -> float:
    """How far apart two free runs end up whose starts differ by a nudge.

    Parameters
    ----------
    estimator : fitted estimator
        Anything with ``simulate(X)``.
    X : array-like of shape (n_samples, n_inputs)
        Excitation of one record.

    Returns
    -------
    float
        RMS difference of the two runs over the last quarter of the record,
        over the standard deviation of the first run (per output, the
        largest); about ``1e-6`` or less for a model that forgets its start,
        of order 1 for one whose runs part ways. NaN when a run diverged.
    """
    X = np.asarray(X, dtype=float)
    X = X.reshape(len(X), -1)
    nudged = X.copy()
    nudged[0] += NUDGE * np.maximum(np.std(X, axis=0), np.finfo(float).tiny)
    first = np.reshape(estimator.simulate(X), (len(X), -1))
    second = np.reshape(estimator.simulate(nudged), (len(X), -1))
    if not (np.all(np.isfinite(first)) and np.all(np.isfinite(second))):
        return float("nan")
    tail = slice(len(X) - max(1, len(X) // 4), None)
    spread = np.std(first, axis=0)
    if not np.any(spread > 0):
        return 0.0
    gap = np.sqrt(np.mean((second[tail] - first[tail]) ** 2, axis=0))
    return float(np.max(gap[spread > 0] / spread[spread > 0]))


def chaos_hint(estimator: Any, X: Any) -> str | None:
    """A warning text when the model's free runs part ways, else None.

    Parameters
    ----------
    estimator : fitted estimator
        Anything with ``simulate(X)``.
    X : array-like of shape (n_samples, n_inputs)
        Excitation of one record (the longest at hand).

    Returns
    -------
    str or None
    """
    divergence = free_run_divergence(estimator, X)
    if not divergence > PARTED:  # a NaN (diverged run) is no evidence either way
        return None
    return (
        f"the fitted model's free run depends on its start: two runs whose "
        f"starts differ by {NUDGE:g} of the input's spread end {divergence:.2g} "
        "output spreads apart (as on a chaotic system). Free-run scores such as "
        "the simulation NRMSE then compare one of many equally right "
        "trajectories with the record and say little about the model; judge it "
        "by its one-step and few-step predictions instead."
    )
