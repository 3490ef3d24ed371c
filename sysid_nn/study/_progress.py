"""Progress of the study's long steps (stderr, off by default).

The study uses only public names of the package, with two exceptions:
progress display (``sysid_nn._engine._progress``) is shared with the estimators'
training progress, so that a terminal gets bars and a log or pipe gets plain
lines, decided in one place (display only, no estimator API); and the runs
compile the kernels first (``sysid_nn._compile``), so that a first run's
compilation is announced and not booked as fit time.
"""

from __future__ import annotations

from sysid_nn._engine._progress import track as _progress

__all__ = ["_progress"]
