"""The training schedule: which data each stage sees, which restarts go on.

A simulation-focused fit runs every restart through a sequence of stages
(:func:`training_stages`): a one-step stage,
multiple-shooting stages on segments of growing length, and the free run.
Each stage minimises its least-squares objective with the chosen solver
(:mod:`sysid_nn._engine._solvers`); the weights with the best validation free run
seen after any step are kept. Two rules here make the cost follow the
information in the records rather than their length:

* **Stages on a subset of segments** (:func:`stage_data`). Where the
  segments restart from measured data alone (the TDL network; see
  ``_independent_segments``), the losses of the one-step and shooting stages
  are sums over segments, so every stage but the last is evaluated on a
  fixed random selection of blocks of whole segments worth about
  ``STAGE_SAMPLES`` samples, drawn from the restart's random state.
  Records up to twice that length are used whole, so they train exactly as
  without the rule. The last stage (the free run) and every validation run
  see all the data. The state-space network's stages see all the data: its
  unmeasured states carry over from one segment to the next.
* **Successive halving of the restarts** (:func:`survivors`). All restarts
  run the first ``HALVING_AFTER`` stages; only the better half by the
  selection criterion (the validation loss, or without validation data the
  training loss of the final objective) runs the remaining stages. The
  restart with the best criterion is chosen, as without the rule.

:func:`sysid_nn._engine._training.train` drives the restarts and the halving;
:func:`sysid_nn._engine._training.fit_stages` runs one restart through a range of
stages.
"""

from __future__ import annotations

import dataclasses
from itertools import pairwise
from typing import TYPE_CHECKING

import numpy as np

from sysid_nn._records._data import _FREE_RUN

if TYPE_CHECKING:  # pragma: no cover
    from sysid_nn._records._data import _Data

#: Samples a stage before the last is evaluated on: about 200 fundamental
#: periods at 150 samples per period. Records of up to twice as many samples
#: are used whole: there a subset would save less than half of a stage's cost
#: for a changed objective (see the user guide's training page).
STAGE_SAMPLES = 30_000
#: Shortest block of a stage's subset, in samples; a block is a whole number
#: of the stage's segments.
BLOCK_SAMPLES = 1_000
#: Stages that every restart runs before the worse half stops (by default
#: the one-step stage and the two shortest shooting stages). Against two,
#: measured on eight systems: gains on EMPS, Wiener-Hammerstein, the
#: oscillator and a measured arm, one EMPS fit of twenty lost (the pitfalls
#: page's table of constants).
HALVING_AFTER = 3
#: Share of ``max_iter`` spent on the one-step stage and on each multiple-
#: shooting stage of the simulation schedule (100 and 40 of 150).
_ONE_STEP_SHARE = 2.0 / 3.0
_SHOOTING_SHARE = 4.0 / 15.0
#: Free-state shooting skips segments shorter than this: with three fitted
#: initial outputs per 20 or 50 samples the states absorb the fit.
_MIN_FREE_SEGMENT = 100


def training_stages(
    focus: str, shooting: str, segments, max_iter: int
) -> list[tuple[int, int]]:
    """``(segment length, iterations)`` of each training stage.

    ``focus="prediction"``: one one-step stage. ``"simulation"``: a
    one-step stage, a multiple-shooting stage per length of ``segments``
    (shortest first) and the free run; with ``shooting="free"`` (fitted
    segment states) no stage reads measured outputs as regressors, and the
    one-step budget goes to the segments of at least ``_MIN_FREE_SEGMENT``
    samples.

    Examples
    --------
    >>> training_stages("simulation", "measured", (20, 100), 150)[:3]
    [(1, 100), (20, 40), (100, 40)]
    >>> training_stages("prediction", "measured", (20,), 150)
    [(1, 150)]
    """
    if focus == "prediction":
        return [(1, max_iter)]
    one = max(1, round(_ONE_STEP_SHARE * max_iter))
    shoot = max(1, round(_SHOOTING_SHARE * max_iter))
    if shooting == "free":
        kept = [s for s in sorted(segments) if s >= _MIN_FREE_SEGMENT]
        return [(int(s), 2 * shoot) for s in kept] + [(_FREE_RUN, max_iter)]
    stages = [(1, one)]
    stages += [(int(s), shoot) for s in sorted(segments)]
    stages.append((_FREE_RUN, max_iter))
    return stages


def stage_data(data: _Data, seg: int, rng: np.random.RandomState) -> _Data:
    """The records a stage with segments of ``seg`` samples is evaluated on.

    ``data`` itself when it models at most twice :data:`STAGE_SAMPLES` rows.
    Otherwise every sequence is cut into blocks of a whole number of
    segments (at least :data:`BLOCK_SAMPLES` samples; the last block of a
    sequence may be shorter), and blocks drawn at random without replacement
    until they hold ``STAGE_SAMPLES`` rows are stacked as sequences of their
    own, each with the measured rows before it as its history. A block
    starts where a segment of the whole record starts, so for the TDL
    network every segment's errors are the same as in the whole record.

    Examples
    --------
    >>> import numpy as np
    >>> from sysid_nn._records._data import _Data
    >>> def record(n):
    ...     return _Data(Y=np.zeros((n, 1)), U=np.zeros((n, 1)),
    ...                  starts=np.array([0, n]), h=3)
    >>> sub = stage_data(record(10 * STAGE_SAMPLES), 100, np.random.RandomState(0))
    >>> n_sub = len(sub.modelled)
    >>> STAGE_SAMPLES <= n_sub < STAGE_SAMPLES + BLOCK_SAMPLES, sub.h
    (True, 3)
    >>> short = record(2 * STAGE_SAMPLES)
    >>> stage_data(short, 100, np.random.RandomState(0)) is short
    True
    """
    h = data.h
    n_modelled = int(data.starts[-1] - data.starts[0]) - h * (len(data.starts) - 1)
    if n_modelled <= 2 * STAGE_SAMPLES:
        return data
    length = seg * -(-BLOCK_SAMPLES // seg)
    blocks = np.array(
        [
            (t, min(t + length, b))
            for a, b in pairwise(data.starts)
            for t in range(a + h, b, length)
        ]
    )
    order = rng.permutation(len(blocks))
    held = np.cumsum(blocks[order, 1] - blocks[order, 0])
    picked = blocks[np.sort(order[: np.searchsorted(held, STAGE_SAMPLES) + 1])]
    rows = np.concatenate([np.arange(t - h, e) for t, e in picked])
    starts = np.concatenate([[0], np.cumsum(picked[:, 1] - picked[:, 0] + h)])
    return dataclasses.replace(
        data, Y=data.Y[rows], U=data.U[rows], starts=starts.astype(np.int64)
    )


def survivors(scores) -> list[int]:
    """Indices of the restarts that run the stages after :data:`HALVING_AFTER`.

    The better half (rounded up) by ``scores`` (lower is better; ties keep
    the earlier restart), in restart order.

    Examples
    --------
    >>> survivors([0.3, 0.1, 0.2, 0.4])
    [1, 2]
    >>> survivors([0.3, 0.1, 0.2])
    [1, 2]
    >>> survivors([0.3])
    [0]
    """
    ranked = np.argsort(np.asarray(scores, dtype=float), kind="stable")
    return sorted(int(k) for k in ranked[: -(-len(ranked) // 2)])
