"""The warnings of the estimators, the version stamp of fitted ones, and the
error for a readout given something other than one network."""

from __future__ import annotations

import inspect
import warnings
from pathlib import Path

__all__ = ["DivergenceWarning", "InconsistentVersionWarning"]


class DivergenceWarning(UserWarning):
    """A free-run simulation left the range of the training data.

    The simulation is stopped at the first sample whose output is not finite
    or exceeds a large multiple of the training output range; that sample and
    all later ones of the sequence are returned as NaN.

    Examples
    --------
    >>> import warnings
    >>> from sysid_nn import DivergenceWarning
    >>> issubclass(DivergenceWarning, UserWarning)
    True
    """


class InconsistentVersionWarning(UserWarning):
    """A fitted model was saved by another version of sysid_nn.

    Raised on unpickling an estimator (or loading a model saved by
    ``sysid-nn fit --save``) whose stamped version differs from the one
    installed: the stored weights may be laid out or interpreted
    differently. Refit the model with the installed version, or install the
    version that saved it. ``saved_version`` and ``current_version`` hold
    the two, as in scikit-learn's warning of this name.

    Parameters
    ----------
    what : str
        What was saved, as the message names it.
    saved_version : str or None
        The version stamped into it (None: saved before stamps existed).
    current_version : str
        The installed version.

    Examples
    --------
    >>> from sysid_nn import InconsistentVersionWarning
    >>> w = InconsistentVersionWarning("a model", "0.0.1", "0.1.0")
    >>> w.saved_version, issubclass(InconsistentVersionWarning, UserWarning)
    ('0.0.1', True)
    """

    def __init__(self, what: str, saved_version, current_version: str) -> None:
        self.what = what
        self.saved_version = saved_version
        self.current_version = current_version

    def __str__(self) -> str:
        saved = (
            "an unknown version"
            if self.saved_version is None
            else f"version {self.saved_version}"
        )
        return (
            f"{self.what} was saved by sysid_nn {saved}; this is version "
            f"{self.current_version}. It may load wrongly or predict differently: "
            "refit it with this version, or install the version that saved it."
        )


def version_stamp() -> str:
    """The installed version, as stamped into a fitted estimator."""
    from sysid_nn import __version__

    return __version__


def check_version(saved, what: str) -> None:
    """Warn :class:`InconsistentVersionWarning` when ``saved`` is not ours."""
    current = version_stamp()
    if saved != current:
        warnings.warn(
            InconsistentVersionWarning(what, saved, current),
            stacklevel=user_stacklevel(),
        )


#: The package's folder: frames of files below it are the package's own.
_PACKAGE = str(Path(__file__).resolve().parent)


def user_stacklevel() -> int:
    """``stacklevel`` for :func:`warnings.warn` that names the user's line.

    The number of frames from the function that warns to the first one
    outside the package (the caller of ``fit``, ``simulate``, ...), however
    deep the warning is raised: one estimator may fit another (the ISSM's
    TDL start), so a fixed count points into the package. Call it as the
    argument of ``warnings.warn``.
    """
    frame = inspect.currentframe()
    level = 0
    try:
        while frame is not None and frame.f_code.co_filename.startswith(_PACKAGE):
            frame = frame.f_back
            level += 1
    finally:
        del frame
    return level


def not_a_network(estimator) -> TypeError:
    """The error for a readout or an export given ``estimator``, which is
    not a ``TDLRegressor`` or an ``ISSMRegressor``. An ensemble's (known by
    its class name: the foundation imports no estimator) names what to pass
    instead.

    Examples
    --------
    >>> not_a_network(1.0)
    TypeError('estimator must be a TDLRegressor or an ISSMRegressor, got float.')
    """
    kind = type(estimator).__name__
    if kind == "EnsembleRegressor":
        return TypeError(
            "estimator must be a TDLRegressor or an ISSMRegressor, got an "
            "EnsembleRegressor: its median is not one network; pass the "
            "network fitted to it (fit with distil=True, then network_) or "
            "a member (estimators_[k])."
        )
    return TypeError(
        f"estimator must be a TDLRegressor or an ISSMRegressor, got {kind}."
    )
