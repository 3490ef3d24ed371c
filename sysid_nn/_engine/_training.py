"""The training driver: restarts through the stages, halving, choice, fallback.

:func:`train` runs a fit's restarts on a model structure, the estimator
that supplies the structure hooks (``_initial_params``, ``_run``,
``_stages``, ``_stage_objective``, ...; see
:class:`~sysid_nn._estimators._base._RecurrentRegressorBase`):

* every restart draws its starting weights and runs the stages of the
  schedule (:mod:`sysid_nn._engine._schedule`) with the estimator's solver
  (:mod:`sysid_nn._engine._solvers`), each stage on the objective the structure
  gives it (:func:`fit_stages`); a :class:`_Tracker` keeps the weights with
  the best validation loss seen after any step, and the histories;
* successive halving (:func:`~sysid_nn._engine._schedule.survivors`) lets the better
  half of the restarts run the last stages;
* :func:`choose_restart` picks the restart whose weights are returned;
* :func:`fallback` replaces a choice whose free run diverged.

The result is a :class:`Training`; the estimator turns it into its fitted
attributes.
"""

from __future__ import annotations

import copy
import functools
import threading
import time
import warnings
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np
import threadpoolctl
from joblib import Parallel, delayed
from sklearn.utils import check_random_state

from sysid_nn._engine import _progress, _selection
from sysid_nn._engine._progress import report_stage
from sysid_nn._engine._schedule import HALVING_AFTER, stage_data, survivors
from sysid_nn._engine._solvers import _SOLVERS, _EarlyStop, _Objective
from sysid_nn._exceptions import DivergenceWarning, user_stacklevel
from sysid_nn._records._data import _FREE_RUN, _Data

#: The stages before the last end when Levenberg-Marquardt's cost stalls over
#: this many accepted steps (see ``sysid_nn._engine._solvers._solve_lm``), not only at
#: their budget (measured in the user guide's training page).
_STALL_STEPS = 10
#: The hidden weights of the linear model's refinement start at this share of
#: their random draw: on Cascaded Tanks (seeds 0-3) 0.1 gave test errors of
#: 0.53-0.55 V, 0.01 0.59, 0.03 0.55-0.60, 0.3 0.53-0.60 V.
_REFINE_SCALE = 0.1
#: ... and its one stage gets this many times ``max_iter`` (it ends earlier
#: where validation stalls, as any last stage): on Wiener-Hammerstein the
#: TDL's refinement still improved after 150 and 300 steps and stopped at
#: 515 (test 2.74 / 2.31 / 2.08 mV, 17 / 35 / 64 CPU-seconds).
_REFINE_BUDGET = 5
#: Where no restart fits the training records better than the linear model
#: (see :func:`sysid_nn._engine._selection.fits_better`), this many more
#: batches of ``n_init`` restarts run before it is returned: on the EMPS
#: benchmark one TDL restart in four reached the basin of the fits that test
#: at 5.3 mm (training free-run loss 0.0015 against the linear model's
#: 0.013), and ``random_state=2`` had none of its four there (13.8 mm, the
#: linear model; measured with the restarts halved after two stages, after
#: three one of its four gets there).
_EXTRA_BATCHES = 1

# BLAS thread limits are process-wide: fits running in threads of one process
# (the threading backend, in-process dask workers, GridSearchCV with threads)
# share one limit, set by the first to enter and restored by the last to
# leave. A limit per thread would be lifted under the others by the first to
# finish, and their results would then depend on timing (multi-threaded BLAS
# rounds differently). threadpoolctl >= 3.8 lets only one thread change
# OpenBLAS limits: the control is released after each restore, so that the
# next fit can take it from whichever thread it runs in.
_BLAS_LOCK = threading.Lock()
_BLAS_USERS = 0
_BLAS_LIMIT = None


def _release_blas_control() -> None:
    controller = getattr(threadpoolctl, "OpenBLASController", None)
    release = getattr(controller, "clear_controlling_thread", None)
    if release is not None:
        release(force=True)


@contextmanager
def _single_threaded_blas():
    """BLAS single-threaded in this process while any fit runs in it."""
    global _BLAS_USERS, _BLAS_LIMIT
    with _BLAS_LOCK:
        if _BLAS_USERS == 0:
            _release_blas_control()
            _BLAS_LIMIT = threadpoolctl.threadpool_limits(limits=1, user_api="blas")
        _BLAS_USERS += 1
    try:
        yield
    finally:
        with _BLAS_LOCK:
            _BLAS_USERS -= 1
            if _BLAS_USERS == 0:
                _release_blas_control()
                _BLAS_LIMIT.restore_original_limits()
                _release_blas_control()
                _BLAS_LIMIT = None


@dataclass
class StageHistory:
    """What one stage of one restart did.

    ``loss``: the stage objective after each accepted step (standardised
    units, penalty included); ``validation``: the validation loss of the
    final objective for the weights before the stage's first step and after
    each accepted one (empty without validation data); ``skipped``: the
    stage did not run because its starting loss was not finite.
    """

    segment: int
    n_iter: int = 0
    loss: list = field(default_factory=list)
    validation: list = field(default_factory=list)
    skipped: bool = False


@dataclass(kw_only=True, slots=True)
class _Run:
    """What one restart (or the linear model) gives if it ends here."""

    #: The weights it would return (its best by validation, if any).
    w: np.ndarray
    #: Final objective on the training records (mean squared, standardised).
    loss: float
    #: Validation loss of ``w`` (NaN without validation records).
    val_loss: float
    #: What restarts are compared by: ``val_loss``, or ``loss`` without
    #: validation records; ``inf`` where that is not finite.
    criterion: float
    n_iter: int
    converged: bool
    history: list
    #: The stage of ``history`` whose step gave ``w``.
    best_stage: int


@dataclass
class _Restart:
    """One restart's progress through the training schedule.

    ``stage`` is the next stage to run; ``rng`` draws the initial weights,
    then each stage's subset of the records (see :mod:`sysid_nn._engine._schedule`).
    """

    k: int
    seed: int
    w: np.ndarray | None = None
    tracker: _Tracker | None = None
    rng: np.random.RandomState | None = None
    n_iter: int = 0
    converged: bool = True
    stage: int = 0
    history: list = field(default_factory=list)


class _Tracker:
    """Keeps the weights with the best validation loss seen after each step.

    Also writes the stage histories: ``stage`` is the
    :class:`StageHistory` the steps are booked to.
    """

    def __init__(self, est, val: _Data | None, seg: int, w0: np.ndarray):
        self.est, self.val, self.seg = est, val, seg
        self.best_w = self.start_w = w0.copy()
        self.best_loss = np.inf
        self.best_stage = 0
        self.stage_index = 0
        self.stage: StageHistory | None = None
        self.first_loss = np.inf
        self.patience = None
        self.since_best = 0
        self.stopped = False
        self.progress = _progress.StepReporter(est)
        self(w0)

    def note_loss(self, loss: float) -> None:
        """Book the stage objective after an accepted step (called by solvers)."""
        if self.stage is not None:
            self.stage.loss.append(float(loss))

    def __call__(self, w) -> None:
        if self.val is None:
            self.progress(np.inf)
            return
        loss = _selection.validation_loss(self.est, w, self.val, self.seg)
        if self.stage is not None:
            self.stage.validation.append(loss)
        else:
            self.first_loss = loss
        self.progress(min(loss, self.best_loss))
        if loss < self.best_loss:
            self.best_loss, self.best_w, self.since_best = loss, w.copy(), 0
            self.best_stage = self.stage_index
        else:
            self.since_best += 1
            if self.patience is not None and self.since_best >= self.patience:
                self.stopped = True
                raise _EarlyStop


@dataclass(kw_only=True)
class Training:
    """The outcome of :func:`train`.

    ``runs`` holds every restart's result in restart order; ``chosen`` is
    the index of the one returned; ``w`` its weights (after a fallback, the
    fallback's); ``fallback`` says which fallback, if any, replaced them.
    """

    runs: list
    chosen: int
    w: np.ndarray
    fallback: str | None
    fit_time: float
    #: ``"restart"``, or ``"linear"`` when the linear model was returned.
    selected: str = "restart"
    #: The linear model (None where it is no candidate): its run, and the
    #: restart whose linear start it was trained from.
    linear: _selection.LinearCandidate | None = None
    #: The chosen run (a restart's, or the linear model's).
    chosen_run: _Run | None = None
    #: Per run, whether its free run stays bounded at twice the training
    #: amplitude (see :func:`sysid_nn._engine._selection.bounded_beyond_range`).
    bounded: list = field(default_factory=list)
    #: Per run, which bound checks it passed: the constant-input check, twice
    #: the amplitude, excitations like the training records' (see
    #: :func:`sysid_nn._engine._selection.choose`).
    checks: np.ndarray | None = None
    #: Per run, its constant-input excursion over its bound (see
    #: :func:`sysid_nn._engine._selection.excursion_ratios`).
    excursions: np.ndarray | None = None
    #: Per run, whether it self-oscillates under the median excitation held
    #: (see :func:`sysid_nn._engine._selection.self_oscillating`).
    self_oscillating: list = field(default_factory=list)
    #: The index of the run that refined the linear model (None without one;
    #: see :func:`refine_linear`).
    refined: int | None = None
    #: How many standard errors the best restart validated better than the
    #: refinement, where the two were compared (see
    #: :func:`sysid_nn._engine._selection.choose`); None where not.
    refinement_advantage: float | None = None
    #: The indices of the runs that are closed-form fits of a linear model,
    #: untrained (see :func:`sysid_nn._engine._selection.closed_form_runs`).
    closed_form: list = field(default_factory=list)
    #: The validation records as they were judged (burn-in and fitted
    #: start set from the linear model), or None.
    validation: _Data | None = None
    #: Batches of restarts run: a second where no run of the first fitted
    #: the training records better than the linear model (see
    #: :data:`_EXTRA_BATCHES`).
    batches: int = 1

    @property
    def run(self) -> _Run:
        return (
            self.chosen_run if self.chosen_run is not None else self.runs[self.chosen]
        )


def train(est, train_data: _Data, val: _Data | None) -> Training:
    """Run every restart of ``est`` through its schedule and choose one.

    Successive halving (see :mod:`sysid_nn._engine._schedule`): every restart runs
    the first stages, the better half by its criterion the rest.
    """
    rng = check_random_state(est.random_state)
    n_runs = est._n_restarts()
    seeds = rng.randint(np.iinfo(np.int32).max, size=n_runs)
    refine_seed = int(rng.randint(np.iinfo(np.int32).max))
    start = time.perf_counter()
    n_stages = len(est._stages())
    halving = n_runs > 1 and n_stages > HALVING_AFTER

    def new_restart(k: int) -> _Restart:  # the linear model's runs
        return _Restart(k, int(seeds[0]))

    # The linear model every network must beat; it also sets the burn-in
    # of validation records simulated from rest (see sysid_nn._engine._selection).
    linear = _selection.linear_candidate(est, train_data, val, new_restart)
    if linear is not None and val is not None:
        val = _selection.judged_records(
            val, linear.burn, linear.start_window, linear.continuation
        )
    elif val is not None and not est._hidden_layers():
        # A linear model is judged as the networks are, from its own start.
        w0 = est._initial_params(np.random.RandomState(0))
        val = _selection.judged_from(est, est, w0, train_data, val)
    runs = run_batch(est, train_data, val, seeds, halving)
    closed_form = []
    if not est._hidden_layers():
        # A linear model: its closed-form fits are candidates as they are.
        fits = _selection.closed_form_runs(
            est, train_data, val, new_restart, est._closed_form_fits(for_network=False)
        )
        closed_form = list(range(len(runs), len(runs) + len(fits)))
        runs += [run for run, _ in fits]
    refined = None
    if linear is not None:
        refined = len(runs)
        runs.append(refine_linear(est, train_data, val, linear, refined, refine_seed))
    batches = 1
    while True:
        retry = batches <= _EXTRA_BATCHES and linear is not None
        best, chosen, selected, bounded, excursions, cycling, checks, advantage = (
            choose_restart(
                est, train_data, val, runs, linear, closed_form, retry, refined
            )
        )
        if (
            not retry
            or selected != "linear"
            or _selection.fits_better(runs, bounded, linear)
        ):
            break
        # No network fitted the training records better than the linear
        # model: another batch of restarts, on seeds drawn after the first
        # batch's (whose fits stay as they were).
        more = rng.randint(np.iinfo(np.int32).max, size=n_runs)
        runs += run_batch(est, train_data, val, more, halving)
        batches += 1
    if not np.all(np.isfinite(chosen.w)):
        raise ValueError(
            "The solver produced non-finite weights. Check the data for "
            "extreme values or reduce the learning problem (fewer lags)."
        )
    w, used = chosen.w, None
    if not np.isfinite(chosen.criterion):
        w, used = fallback(est, chosen.w, train_data, val)
    return Training(
        runs=runs,
        chosen=best,
        w=w,
        fallback=used,
        fit_time=time.perf_counter() - start,
        selected=selected,
        linear=linear,
        chosen_run=chosen,
        bounded=bounded,
        checks=checks,
        excursions=excursions,
        self_oscillating=cycling,
        refined=refined,
        refinement_advantage=advantage,
        closed_form=closed_form,
        validation=val,
        batches=batches,
    )


def run_batch(est, train_data, val, seeds, halving: bool) -> list:
    """The runs of one batch of restarts, one per seed, through the stages.

    With ``halving``, every restart runs the first :data:`HALVING_AFTER`
    stages and the better half by its criterion the rest (see
    :func:`~sysid_nn._engine._schedule.survivors`). Restart ``k`` of a batch
    starts as restart ``k`` of any other (the ISSM's linear start).
    """
    n_stages = len(est._stages())
    restarts = [_Restart(k, int(seed)) for k, seed in enumerate(seeds)]
    cut = HALVING_AFTER if halving else n_stages
    results = run_restarts(est, train_data, val, restarts, cut)
    if halving:
        kept = survivors([run.criterion for _, run in results])
        going_on = [results[k][0] for k in kept]
        done = run_restarts(est, train_data, val, going_on, n_stages)
        for k, result in zip(kept, done, strict=True):
            results[k] = result
    return [run for _, run in results]


def refine_linear(est, train_data, val, linear, k: int, seed: int) -> _Run:
    """The trained linear model refined as a network: restart ``k``.

    The network starts at the linear model (output weights zero, its linear
    part the linear model's), with hidden weights of :data:`_REFINE_SCALE`
    times their usual random draw, and runs the last stage of the schedule
    only (the final objective, with :data:`_REFINE_BUDGET` times its
    budget), as the best linear approximation starts a
    polynomial non-linear state-space model (Paduart et al., 2010). The
    restarts' own schedule starts at the linear start, not at the trained
    linear model, and their one-step stage can leave the free run's basin:
    on the Cascaded Tanks benchmark every restart of seeds 0-2 fitted its
    training record worse than the linear model, while this one fitted it
    better on all (test error 0.53-0.54 V against the linear model's 0.64).
    """
    rng = np.random.RandomState(seed)
    w = linear.w.copy()
    drawn = np.zeros_like(w)
    layout = est._layout()
    layout.draw_weights(drawn, rng, est.activation)
    for layer in layout.layers[:-1]:
        w[layer.weights] = _REFINE_SCALE * drawn[layer.weights]
    refiner = copy.copy(est)  # its own budget, the rest shared
    refiner.max_iter = _REFINE_BUDGET * est.max_iter
    n_stages = len(refiner._stages())
    restart = _Restart(k, seed, w=w, rng=rng, stage=n_stages - 1)
    return refiner._fit_one(train_data, val, restart, n_stages)[1]


def choose_restart(
    est,
    train_data,
    val,
    runs: list,
    linear,
    closed_form=(),
    retry: bool = False,
    refined: int | None = None,
):
    """The run whose weights ``fit`` returns: ``(index, run, selected,
    bounded, excursions, cycling, checks, advantage)``, ``bounded`` whether each
    run's free run stays bounded, ``excursions`` its constant-input
    excursion over its bound, ``cycling`` whether it self-oscillates under
    the median excitation held, ``advantage`` the best restart's over the
    refinement (or None), ``checks`` which bound checks each run passed.

    Among the restarts whose free run stays bounded beyond the training
    range, the one with the lowest criterion (the validation loss of its
    best weights, or without validation data its training loss on the final
    objective; a diverged one has ``inf``; the first of equal ones), if
    it beats the linear model; else the linear model (``index`` None,
    ``selected`` ``"linear"``). See :func:`sysid_nn._engine._selection.choose`.
    """
    chosen, selected, *evidence = _selection.choose(
        est, train_data, val, runs, linear, closed_form, retry, refined
    )
    index = next((k for k, r in enumerate(runs) if r is chosen), None)
    return index, chosen, selected, *evidence


def fallback(est, w: np.ndarray, train_data: _Data, val: _Data | None):
    """The linear starting model when every restart's free run diverged.

    Returns ``(weights, which)``: the linear start and ``"linear_start"``,
    or ``w`` unchanged and ``"none"`` when the linear start diverges too;
    warns :class:`~sysid_nn.DivergenceWarning` either way.
    """
    start = est._initial_params(np.random.RandomState(0))
    finite = all(
        not (est._run(start, data, _FREE_RUN, False, keep_state=False)[2] >= 0).any()
        for data in (train_data, val)
        if data is not None
    )
    warnings.warn(
        f"Every restart of {type(est).__name__} gave a free run that diverged "
        "on the validation (or training) records"
        + (
            "; the model falls back to the linear starting model."
            if finite
            else ", and so does the linear starting model; simulations may return NaN."
        )
        + " Check the records for outliers, zero-padded or clipped stretches, "
        "and records of very different amplitude.",
        DivergenceWarning,
        stacklevel=user_stacklevel(),
    )
    return (start, "linear_start") if finite else (w, "none")


def run_restarts(est, train_data, val, restarts, stop):
    """Run every restart up to stage ``stop``, in parallel.

    Returns ``(restart, run)`` pairs in the order of ``restarts``.
    """
    return Parallel(n_jobs=est.n_jobs if len(restarts) > 1 else None)(
        delayed(est._fit_one)(train_data, val, restart, stop) for restart in restarts
    )


def fit_stages(est, train_data, val, restart, stop):
    """Run ``restart`` from its next stage up to stage ``stop``.

    Every stage but the last sees the records :func:`_schedule.stage_data
    <sysid_nn._engine._schedule.stage_data>` selects. Returns ``(restart, run)``:
    the advanced :class:`_Restart` and the :class:`_Run` it would give if
    it ended here (best validation weights and the selection criterion).
    """
    mask = est._penalty_mask()
    n_res = len(train_data.modelled) * est.n_outputs_
    stages = est._stages()
    final_seg = est._final_segment()
    if restart.w is None:
        restart.rng = np.random.RandomState(restart.seed)
        restart.w = est._initial_params(restart.rng)
    if restart.tracker is None:  # a restart's start (its own, or given)
        restart.tracker = _Tracker(est, val, final_seg, restart.w)
    tracker, w, k = restart.tracker, restart.w, restart.k
    tracker.est = est  # not the copy a worker process unpickled
    for i_stage in range(restart.stage, stop):
        seg, iters = stages[i_stage]
        last = i_stage == len(stages) - 1
        record = StageHistory(int(min(seg, _FREE_RUN)))
        restart.history.append(record)
        # Indices into the restart's own history (the refinement's starts late).
        tracker.stage, tracker.stage_index = record, len(restart.history) - 1
        tracker.patience = est.n_iter_no_change if last else None
        # Patience counts the last stage's own steps: steps of earlier
        # stages without improvement must not end it before it starts.
        tracker.since_best = 0
        subset = not last and est._independent_segments()
        data = stage_data(train_data, seg, restart.rng) if subset else train_data
        n_data = len(data.modelled) * est.n_outputs_
        # The penalty stays relative to the whole record.
        alpha = est.alpha_ * (n_data / n_res)
        objective = est._stage_objective(data, seg, mask, n_data, alpha)
        theta = objective.start(w)
        start_loss = objective.loss(theta)
        segment = f"segment {'free run' if seg == _FREE_RUN else seg}"
        where = (k, est._n_restarts()), (i_stage, len(stages)), segment
        if not np.isfinite(start_loss):
            record.skipped = True  # the stage diverges from here on
            report_stage(est, *where, 0, lambda: np.inf, tracker.best_loss)
            continue
        record.loss.append(float(start_loss))
        if val is not None:
            record.validation.append(
                tracker.first_loss if i_stage == 0 else _last_validation(restart)
            )
        stall = None if last else _STALL_STEPS
        theta, nit, ok = _SOLVERS[est.solver](
            objective, theta, iters, est.tol, objective.track(tracker), stall
        )
        w = objective.weights(theta)
        record.n_iter = nit
        restart.n_iter += nit
        if last:
            restart.converged = ok or tracker.stopped
        report_stage(
            est,
            *where,
            nit,
            functools.partial(objective.loss, theta),
            tracker.best_loss,
        )
    tracker.stage = None
    restart.w, restart.stage = w, max(stop, restart.stage)
    best_stage = max(len(restart.history) - 1, 0)
    if val is not None:
        w = tracker.best_w
        val_loss = tracker.best_loss
        best_stage = tracker.best_stage
    else:
        val_loss = np.nan
    final = _Objective(est, train_data, final_seg, mask, n_res)
    loss = final.loss(w)
    if val is None:
        # Judged on the training records alone, a run ends no worse than
        # where it started (a linear start: the closed-form fit that the
        # stages could not improve or whose free run they could not run).
        start_loss = final.loss(tracker.start_w)
        if start_loss < loss or not np.isfinite(loss):
            w, loss, best_stage = tracker.start_w.copy(), start_loss, 0
    criterion = val_loss if val is not None else loss
    run = _Run(
        w=w,
        loss=loss,
        val_loss=val_loss,
        criterion=criterion if np.isfinite(criterion) else np.inf,
        n_iter=restart.n_iter,
        converged=restart.converged,
        history=list(restart.history),
        best_stage=best_stage,
    )
    return restart, run


def _last_validation(restart: _Restart) -> float:
    """The validation loss the last stage that ran ended with."""
    for record in reversed(restart.history[:-1]):
        if record.validation:
            return record.validation[-1]
    return restart.tracker.first_loss
