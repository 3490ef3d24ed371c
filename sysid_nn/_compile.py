"""Compiling the kernels once, announced, before anything is timed.

numba compiles a kernel at its first call and caches the result on disk (see
:mod:`sysid_nn._kernels`). On a fresh installation that first call takes a
minute or more on 2 cores, and would be booked as the first fit's time. The
command line and the study call :func:`prepare_kernels` first: when the cache
does not yet hold the kernels of these sources, it says so on stderr,
compiles them with a progress display by running tiny fits of both networks,
and leaves a marker beside the cache so later runs skip all of it.
"""

from __future__ import annotations

import os
import sys
import time
import warnings

import numba
from numba.core import config as _numba_config

from sysid_nn._engine._progress import track
from sysid_nn._kernels import cache_dir, sources_digest


def _marker() -> str:
    """The file whose presence says the cache holds these kernels."""
    root = _numba_config.CACHE_DIR or cache_dir()
    version = f"numba{numba.__version__}-py{sys.version_info[0]}{sys.version_info[1]}"
    return os.path.join(root, f"ready-{sources_digest()[:16]}-{version}")


def kernels_ready() -> bool:
    """Whether the kernels of these sources were compiled into the cache."""
    return os.path.exists(_marker())


def _steps() -> list:
    """Tiny runs that call every kernel with the argument types of real use."""
    import numpy as np

    from sysid_nn import HystereticOscillator, ISSMRegressor, TDLRegressor

    rec = HystereticOscillator(r0=0.05).generate(2, n_samples=120, random_state=0)
    X = [f[:, None] for f in rec.excitation]
    y = [
        np.column_stack([d, v])
        for d, v in zip(rec.displacement, rec.velocity, strict=True)
    ]
    y1 = [yk[:, :1] for yk in y]

    def use(est, outputs):
        est.fit(X[:1], outputs[:1], X_val=X[1:], y_val=outputs[1:])
        est.simulate(X[1], return_std=True)
        est.simulate(X[1], y_init=outputs[1][:10])
        est.predict(X[1], outputs[1], return_std=True)
        est.predict(X[1], outputs[1], horizon=3)

    small = {"hidden_layer_sizes": (2,), "max_iter": 3, "n_init": 1}
    return [
        lambda: HystereticOscillator().hysteretic_state(rec.displacement),
        lambda: use(TDLRegressor(**small, shooting="measured", random_state=0), y1),
        lambda: use(TDLRegressor(**small, shooting="free", random_state=0), y1),
        lambda: use(ISSMRegressor(**small, random_state=0), y1),
        lambda: use(ISSMRegressor(**small, random_state=0), y),
    ]


def prepare_kernels(show: bool = True) -> float:
    """Compile the kernels now if the cache does not hold them yet.

    Parameters
    ----------
    show : bool, default=True
        Announce the compilation on stderr, with its progress.

    Returns
    -------
    float
        Seconds spent compiling; 0.0 when the cache already held the kernels.
    """
    if kernels_ready():
        return 0.0
    start = time.perf_counter()
    if show:
        print(
            "sysid-nn: compiling the numerical kernels, once per installation "
            f"(about 1-2 minutes on 2 cores; cached in {os.path.dirname(_marker())})",
            file=sys.stderr,
            flush=True,
        )
    steps = _steps()
    # The tiny fits stop early and warn; only their compiled code matters.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for step in track(steps, len(steps), "compiling kernels", show):
            step()
    try:
        with open(_marker(), "w") as f:
            f.write(f"{sources_digest()}\n")
    except OSError:  # an unwritable cache: compiled again next time
        pass
    return time.perf_counter() - start
