"""Models saved by ``sysid-nn fit --save``, loaded in Python."""

from __future__ import annotations

import os
from typing import Any


def _read_bundle(path: str | os.PathLike) -> Any:
    """The saved bundle, its version stamp checked (a warning if it differs)."""
    import joblib

    from sysid_nn._exceptions import check_version

    try:
        bundle = joblib.load(path)
    except OSError:
        raise
    except Exception as exc:  # unpickling garbage raises anything
        raise ValueError(f"cannot read {path} as a saved model: {exc}") from None
    if not (hasattr(bundle, "get") and bundle.get("model") is not None):
        raise ValueError(f"{path} was not written by `sysid-nn fit --save`.")
    check_version(bundle.get("sysid_nn_version"), str(path))
    return bundle


def load_model(path: str | os.PathLike, *, with_info: bool = False) -> Any:
    """Load a model saved by ``sysid-nn fit --save``.

    Parameters
    ----------
    path : str or path-like
        The file written by ``sysid-nn fit ... --save FILE``.
    with_info : bool, default=False
        Also return what the command knew about the records.

    Returns
    -------
    estimator : TDLRegressor or ISSMRegressor
        The fitted estimator, ready for ``predict`` and ``simulate``; its
        ``X`` columns are the ``--input`` columns in the order given, its
        outputs the ``--output`` columns.
    info : Bunch
        Only with ``with_info=True``: ``inputs`` and ``outputs`` (column
        names), ``dt`` (sampling step, s), ``units`` (``{column: unit}``),
        ``files`` (training files), ``split_by`` and ``sysid_nn_version``
        (the version that saved it).

    Raises
    ------
    ValueError
        The file is not a model saved by ``sysid-nn fit``.

    Warns
    -----
    InconsistentVersionWarning
        The file was saved by another version of sysid_nn.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> from sysid_nn import load_model
    >>> from sysid_nn.cli import main
    >>> folder = pathlib.Path(tempfile.mkdtemp())
    >>> main(["generate", "--n-realizations", "2", "--n-samples", "300", "--r0",
    ...       "0.05", "--out", str(folder / "r.csv")])  # doctest: +ELLIPSIS
    wrote 2 realisation(s) ...
    0
    >>> main(["fit", str(folder / "r.csv"), "--split-by", "realization", "--input",
    ...       "excitation", "--output", "displacement", "--hidden", "0", "--quiet",
    ...       "--save", str(folder / "m.joblib")])  # doctest: +ELLIPSIS
    fitted ...
    0
    >>> model, info = load_model(folder / "m.joblib", with_info=True)
    >>> type(model).__name__, info.inputs, info.dt
    ('TDLRegressor', ('excitation',), 0.01)
    """
    from sklearn.utils import Bunch

    bundle = _read_bundle(path)
    study_model = bundle.model
    if not with_info:
        return study_model.estimator
    info = Bunch(
        inputs=tuple(study_model.inputs),
        outputs=tuple(study_model.outputs),
        dt=bundle.get("dt"),
        units=dict(bundle.get("units", {})),
        files=list(bundle.get("files", [])),
        split_by=bundle.get("split_by"),
        sysid_nn_version=bundle.get("sysid_nn_version"),
    )
    return study_model.estimator, info
