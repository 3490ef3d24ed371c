"""Training progress of the recurrent estimators (``verbose``), on stderr.

On a terminal each restart gets a tqdm bar that advances by training stage;
anywhere else (a log file, a pipe, a notebook's captured stream) every stage
is one plain line, with no carriage returns to garble the log. Restarts that
run in joblib worker processes report from there the same way.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import Any

# One open bar per restart of the process that trains it.
_BARS: dict[int, Any] = {}


def _interactive() -> bool:
    isatty = getattr(sys.stderr, "isatty", None)
    try:
        return bool(isatty and isatty())
    except ValueError:  # a closed stream
        return False


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
        Index of the restart (from 0) and number of restarts.
    stage : tuple of int
        Index of the stage just finished (from 0) and number of stages.
    segment : str
        What the stage trains on (one-step, segment length, free run).
    n_iter : int
        Iterations the stage took.
    loss : callable
        Returns the training loss after the stage (evaluated only when
        something is reported: it costs a pass over the data).
    validation : float
        Best validation loss so far.
    """
    verbose = int(estimator.verbose)
    if verbose <= 0:
        return
    name = type(estimator).__name__
    (restart, n_restarts), (stage, n_stages) = restart, stage
    loss = loss()
    line = (
        f"[{name}] restart {restart + 1}/{n_restarts} stage {stage + 1}/{n_stages} "
        f"({segment}): {n_iter} iterations, loss {loss:.3e}, "
        f"validation {validation:.3e}"
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
            desc=f"{name} restart {restart + 1}/{n_restarts}",
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
