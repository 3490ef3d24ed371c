"""Continuing the chosen weights on the validation records too (``refit``).

Validation records choose the restart and the step where training stops,
and the weights never learn from them. With ``refit=True`` the last stage of
the schedule continues from the chosen weights on the training and
validation records together (Goodfellow, Bengio & Courville 2016, section
7.8: after early stopping, train on all the data). How far is set by an
inner validation, as their algorithm 7.2 sets it by a held-out part: the
same continuation on the training records and the first half of every
validation record, judged on the second halves in continuation of the first
(:func:`refit`). The step it judges best is taken on all the records only
where it beats the chosen weights there by more than ``_SIGNIFICANT``
standard errors (:func:`~sysid_nn._engine._selection.validation_advantage`),
and kept only where the continued weights' free run stays finite and fits
the training records no worse than ``_LINEAR_FIT_MARGIN`` times the chosen
weights' (more data, not other data: on the EMPS benchmark, the validation
record passed as ``X_val`` 10 samples after four fifths, a TDL continued on
it fitted the training record 6.7 times worse and tested at 20.6 against
5.5 mm); otherwise the chosen weights stay.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sysid_nn._engine._selection import (
    _LINEAR_FIT_MARGIN,
    _SIGNIFICANT,
    validation_advantage,
    validation_loss,
)
from sysid_nn._engine._solvers import _SOLVERS, _EarlyStop, _Objective
from sysid_nn._records._data import _Data

__all__ = ["Refit", "refit"]


@dataclass(kw_only=True)
class Refit:
    """The outcome of :func:`refit`."""

    #: The weights returned: the chosen ones, or continued on all records.
    w: np.ndarray
    #: Accepted steps taken on all the records (0: the chosen weights stay).
    steps: int
    #: The inner validation loss (standardised mean squared error of the
    #: validation records' second halves) at the chosen weights and after
    #: each accepted step of the inner continuation.
    losses: np.ndarray
    #: Standard errors by which the inner validation's best step beat the
    #: chosen weights (nan where the best was the chosen weights).
    advantage: float
    #: The final objective of ``w`` on the training and validation records.
    loss: float
    #: The continued weights' final objective on the training records over
    #: the chosen weights' (nan where no step was taken on all the records).
    training_ratio: float


def _continue(est, data: _Data, w: np.ndarray, observe) -> np.ndarray:
    """The last stage's objective on ``data`` minimised from ``w``, within
    ``max_iter``; ``observe(w)`` sees the weights after every accepted step
    and may end the run by raising :class:`_EarlyStop`. Returns the last
    accepted weights."""
    seg, _ = est._stages()[-1]
    n_res = len(data.modelled) * est.n_outputs_
    objective = est._stage_objective(data, seg, est._penalty_mask(), n_res, est.alpha_)
    last = [w]

    def step(weights):
        last[0] = np.array(weights, copy=True)  # the solver's array moves on
        observe(last[0])

    theta = objective.start(w)
    _SOLVERS[est.solver](
        objective, theta, est.max_iter, est.tol, objective.track(step), None
    )
    return last[0]


def refit(
    est, w: np.ndarray, train: _Data, inner: _Data, judged: _Data, whole: _Data
) -> Refit:
    """Continue ``w`` on ``whole`` as far as the inner validation says.

    ``train``: the training records; ``inner``: those and the first half
    of every validation record; ``judged``: the validation records, judged
    after that half (``lead``); ``whole``: the training and validation
    records together.
    """
    seg = est._final_segment()  # as the restarts were judged
    losses, kept = [validation_loss(est, w, judged, seg)], [w]

    def judge(weights):
        losses.append(validation_loss(est, weights, judged, seg))
        kept.append(weights)  # a copy (see _continue)

    _continue(est, inner, w, judge)
    best = int(np.argmin(losses))  # the first of equals: 0 keeps ``w``
    advantage = np.nan
    steps = 0
    if best > 0:
        advantage = validation_advantage(est, kept[best], w, judged, seg)
        if advantage > _SIGNIFICANT:
            steps = best
    out = w
    if steps:
        taken = [0]

        def count(_):
            taken[0] += 1
            if taken[0] >= steps:
                raise _EarlyStop

        out = _continue(est, whole, w, count)
        steps = taken[0]  # fewer where the stage converged before them

    def objective(data):
        n_res = len(data.modelled) * est.n_outputs_
        return _Objective(est, data, seg, est._penalty_mask(), n_res).loss

    on_whole = objective(whole)
    loss = on_whole(out)
    ratio = np.nan
    if steps:
        on_train = objective(train)
        ratio = on_train(out) / on_train(w)
        # ``not <=``: a run that diverged (nan) is not kept either.
        if not (np.isfinite(loss) and ratio <= _LINEAR_FIT_MARGIN):
            out, steps, loss = w, 0, on_whole(w)
    return Refit(
        w=out,
        steps=steps,
        losses=np.asarray(losses),
        advantage=advantage,
        loss=loss,
        training_ratio=ratio,
    )
