"""Progress on stderr: estimators' training stages, and any long loop.

On a terminal progress is a tqdm bar; anywhere else (a log file, a pipe, a
notebook's captured stream) every step is one plain line, with no carriage
returns to garble the log. :func:`report_stage` reports the recurrent
estimators' training (``verbose``; restarts that run in joblib worker
processes report from there the same way); :func:`track` wraps the long
loops of the study (fitting, evaluating, figures).

Display only, not part of any estimator's API: the study reaches it through
``sysid_nn.study._progress`` so that both decide terminal-or-not the same way.
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable, Iterable, Iterator
from typing import Any

# One open bar per restart of the process that trains it.
_BARS: dict[int, Any] = {}

#: Within a training stage, at most one progress line per this many seconds:
#: on a long record one stage can take minutes.
STEP_SECONDS = 30.0


def _interactive() -> bool:
    isatty = getattr(sys.stderr, "isatty", None)
    try:
        return bool(isatty and isatty())
    except ValueError:  # a closed stream
        return False


def track(items: Iterable, total: int, desc: str, show: bool) -> Iterator:
    """Iterate over ``items``, showing progress on stderr when ``show``.

    Parameters
    ----------
    items : iterable
        What to iterate over.
    total : int
        Number of items.
    desc : str
        What the loop does (``"fitting"``, ``"figures"``, ...).
    show : bool
        False: no output at all.

    Returns
    -------
    iterator
        The items unchanged: on a terminal through a tqdm bar that disappears
        when done, elsewhere followed by one line per item,
        ``"<desc>: <i>/<total> (<seconds> s)"``.
    """
    if not show:
        return iter(items)
    if _interactive():
        from tqdm.auto import tqdm

        return iter(tqdm(items, total=total, desc=desc, leave=False, file=sys.stderr))
    return _lines(items, total, desc)


def _lines(items: Iterable, total: int, desc: str) -> Iterator:
    start = time.perf_counter()
    for i, item in enumerate(items, 1):
        yield item  # the line follows the work done with the item
        elapsed = time.perf_counter() - start
        print(f"{desc}: {i}/{total} ({elapsed:.1f} s)", file=sys.stderr, flush=True)


def report_stage(
    estimator: Any,
    restart: tuple[int, int],
    stage: tuple[int, int],
    segment: str,
    n_iter: int,
    loss: Callable[[], float],
    validation: float,
) -> None:
    """Report one finished training stage of one restart, if ``verbose``.

    Parameters
    ----------
    estimator : estimator
        The estimator being trained; its ``verbose`` decides: 0 (or False)
        nothing, 1 (or True) a bar per restart on a terminal and one line
        per stage elsewhere, 2 or more one line per stage everywhere.
    restart : tuple of int
        Index of the restart (from 0) and number of restarts; an index past
        them is the refinement of the linear model.
    stage : tuple of int
        Index of the stage just finished (from 0) and number of stages.
    segment : str
        What the stage trains on (one-step, segment length, free run).
    n_iter : int
        Iterations the stage took.
    loss : callable
        Returns the training loss after the stage (evaluated only when
        something is reported: it costs a pass over the data); not finite
        for a skipped stage.
    validation : float
        Best validation loss so far.
    """
    verbose = int(estimator.verbose)
    if verbose <= 0:
        return
    name = type(estimator).__name__
    (restart, n_restarts), (stage, n_stages) = restart, stage
    who = (
        f"restart {restart + 1}/{n_restarts}"
        if restart < n_restarts
        else "refinement of the linear model"
    )
    loss = loss()
    # A stage whose starting loss is not finite was skipped (see the
    # estimator's warning, which counts stages from 1 as these lines do).
    done = (
        f"{n_iter} iterations, loss {loss:.3e}"
        if math.isfinite(loss)
        else "skipped: the free run diverged from the weights it started at"
    )
    line = (
        f"[{name}] {who} stage {stage + 1}/{n_stages} "
        f"({segment}): {done}, validation {validation:.3e}"
    )
    if not _interactive():
        print(line, file=sys.stderr, flush=True)
        return
    from tqdm.auto import tqdm

    bar = _BARS.get(restart)
    if bar is None or stage == 0:
        if bar is not None:
            bar.close()
        bar = _BARS[restart] = tqdm(
            total=n_stages,
            desc=f"{name} {who}",
            unit="stage",
            leave=True,
        )
    if verbose >= 2:
        bar.write(line, file=sys.stderr)
    bar.set_postfix_str(f"loss {loss:.3e}, validation {validation:.3e}")
    bar.update(stage + 1 - bar.n)
    if stage + 1 >= n_stages:
        bar.close()
        del _BARS[restart]


class StepReporter:
    """Lines while a restart trains: its accepted steps so far, now and then.

    Stages end with :func:`report_stage`; on a long record one stage can run
    for minutes, so the training loop calls this after every accepted step
    and, if the estimator is ``verbose``, a line is written at most every
    :data:`STEP_SECONDS`. The first call sees the starting weights and is
    not counted as a step. Wall-clock time, so that a restart moved to another
    process or machine keeps counting from its start.

    Parameters
    ----------
    estimator : estimator
        The estimator being trained; its ``verbose`` decides whether to write.
    """

    def __init__(self, estimator: Any) -> None:
        self.name = type(estimator).__name__
        self.verbose = int(estimator.verbose)
        self.start = self.last = time.time()
        self.steps = -1  # the first call sees the starting weights

    def __call__(self, validation: float) -> None:
        """Count one accepted step; ``validation`` is the best validation loss."""
        self.steps += 1
        now = time.time()
        if self.verbose <= 0 or self.steps <= 0 or now - self.last < STEP_SECONDS:
            return
        self.last = now
        line = (
            f"[{self.name}] training: {self.steps} steps of this restart in "
            f"{now - self.start:.0f} s"
        )
        if validation < float("inf"):
            line += f", best validation {validation:.3e}"
        if _interactive():
            from tqdm.auto import tqdm

            tqdm.write(line, file=sys.stderr)
        else:
            print(line, file=sys.stderr, flush=True)
