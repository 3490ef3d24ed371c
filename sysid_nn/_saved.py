"""Model files that run no code when read: :func:`save_model`, :func:`load_model`.

A model file is a zip archive of one JSON document (``model.json``: the
format's name and version, what the model maps, and the estimator's
attributes as a tree of tagged values) and the estimator's arrays as
``.npy`` files, read with ``allow_pickle=False``. Reading builds only the
types named in ``_ESTIMATORS`` and ``_DATACLASSES`` and plain containers;
any other tag is refused. Pickles (joblib files, the format of earlier
versions) are recognised by their first bytes and unpickled only when the
caller trusts them.
"""

from __future__ import annotations

import dataclasses
import inspect
import io
import json
import math
import os
import warnings
import zipfile
from typing import Any

import numpy as np

from sysid_nn._exceptions import not_a_network

__all__ = ["load_model", "save_model"]

#: Name and version of the file format; a reader refuses newer versions.
_FORMAT = "sysid_nn-model"
_FORMAT_VERSION = 1
_HEADER = "model.json"

#: First bytes of a pickle (protocol 2 and later) and of joblib's
#: compressed files (zlib at any level, its older zlib, gzip, bz2, xz, lzma,
#: lz4).
_PICKLE_MAGIC = (
    *(b"\x80" + bytes([p]) for p in range(2, 6)),
    *(b"x" + bytes([level]) for level in (0x01, 0x5E, 0x9C, 0xDA)),
    b"ZF",
    b"\x1f\x8b",
    b"BZh",
    b"\xfd7zXZ\x00",
    b"]\x00\x00",
    b'\x04"M\x18',
)
_ZIP_MAGIC = b"PK\x03\x04"

_INFO_KEYS = ("inputs", "outputs", "dt", "units", "files", "split_by", "label")


def _estimators() -> dict[str, type]:
    """The estimator classes a model file may hold, by the name it stores."""
    from sysid_nn._estimators._ensemble import EnsembleRegressor
    from sysid_nn._estimators._issm import ISSMRegressor
    from sysid_nn._estimators._tdl import TDLRegressor

    return {
        "TDLRegressor": TDLRegressor,
        "ISSMRegressor": ISSMRegressor,
        "EnsembleRegressor": EnsembleRegressor,
    }


def check_network(estimator: Any, *, ensemble: bool = False) -> None:
    """Raise unless ``estimator`` is a fitted ``TDLRegressor`` or
    ``ISSMRegressor``, or, with ``ensemble``, a fitted ``EnsembleRegressor``
    of them (a model file holds one; an ONNX graph does not)."""
    from sklearn.utils.validation import check_is_fitted

    from sysid_nn._estimators._ensemble import EnsembleRegressor

    kind = type(estimator)
    if kind is EnsembleRegressor and not ensemble:
        raise not_a_network(estimator)
    if kind not in _estimators().values():
        if not ensemble:
            raise not_a_network(estimator)
        raise TypeError(
            "estimator must be a TDLRegressor, an ISSMRegressor or an "
            f"EnsembleRegressor, got {kind.__name__}."
        )
    check_is_fitted(estimator, "estimators_" if kind is EnsembleRegressor else "coefs_")


def _dataclasses() -> dict[str, type]:
    """The dataclasses fitted attributes hold, by the name the file stores."""
    from sysid_nn._engine._diagnosis import RecordDiagnosis
    from sysid_nn._engine._training import StageHistory

    return {"RecordDiagnosis": RecordDiagnosis, "StageHistory": StageHistory}


# ----------------------------------------------------------------- writing
class _Encoder:
    """Attributes to JSON-able tagged values; arrays to numbered ``.npy``."""

    def __init__(self) -> None:
        self.arrays: list[np.ndarray] = []
        self.dataclasses = {cls: name for name, cls in _dataclasses().items()}
        self.estimators = {cls: name for name, cls in _estimators().items()}

    def array(self, value: np.ndarray, where: str) -> int:
        if value.dtype.hasobject:
            raise TypeError(f"{where} is an array of Python objects; cannot save it.")
        self.arrays.append(value)
        return len(self.arrays) - 1

    def __call__(self, value: Any, where: str) -> Any:
        from sklearn.utils import Bunch

        # numpy scalars before Python's: np.float64 is a float.
        if isinstance(value, np.generic):
            return {"t": "scalar", "a": self.array(np.asarray(value), where)}
        if value is None or isinstance(value, (bool, int, str)):
            return value
        if isinstance(value, float):
            return value if math.isfinite(value) else {"t": "float", "v": repr(value)}
        if isinstance(value, np.ndarray):
            return {"t": "array", "a": self.array(value, where)}
        if isinstance(value, list):
            return [self(v, f"{where}[{i}]") for i, v in enumerate(value)]
        if isinstance(value, tuple) and not hasattr(value, "_fields"):
            items = [self(v, f"{where}[{i}]") for i, v in enumerate(value)]
            return {"t": "tuple", "v": items}
        if isinstance(value, dict) and all(isinstance(k, str) for k in value):
            tag = "bunch" if isinstance(value, Bunch) else "dict"
            return {"t": tag, "v": self.mapping(value, where)}
        if type(value) in self.estimators:  # e.g. the ISSM's TDL start, tdl_
            return {
                "t": "estimator",
                "name": self.estimators[type(value)],
                "v": self.mapping(value.__dict__, where),
            }
        if type(value) in self.dataclasses:
            fields = {f.name: getattr(value, f.name) for f in dataclasses.fields(value)}
            return {
                "t": "dataclass",
                "name": self.dataclasses[type(value)],
                "v": self.mapping(fields, where),
            }
        raise TypeError(
            f"{where} is a {type(value).__module__}.{type(value).__qualname__}, "
            "which a model file cannot hold."
        )

    def mapping(self, value: dict, where: str) -> dict:
        return {k: self(v, f"{where}[{k!r}]") for k, v in value.items()}


def _write(path: str | os.PathLike, estimator: Any, info: dict) -> None:
    """Write ``estimator`` and ``info`` (see ``_INFO_KEYS``) to ``path``."""
    from sysid_nn import __version__

    check_network(estimator, ensemble=True)
    encode = _Encoder()
    header = {
        "format": _FORMAT,
        "format_version": _FORMAT_VERSION,
        "sysid_nn_version": __version__,
        "info": info,
        "estimator": encode(estimator, type(estimator).__name__),
    }
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as archive:
        archive.writestr(_HEADER, json.dumps(header, allow_nan=False, indent=1))
        for i, array in enumerate(encode.arrays):
            buffer = io.BytesIO()
            np.save(buffer, array, allow_pickle=False)
            archive.writestr(f"arrays/{i}.npy", buffer.getvalue())


def save_model(
    estimator: Any,
    path: str | os.PathLike,
    *,
    inputs: list[str] | tuple[str, ...] | None = None,
    outputs: list[str] | tuple[str, ...] | None = None,
    dt: float | None = None,
    units: dict[str, str] | None = None,
) -> None:
    """Save a fitted estimator to a file that runs no code when read.

    The file holds the estimator's parameters and fitted attributes as data
    (JSON and numpy arrays in a zip archive), so that :func:`load_model`
    builds the estimator back without unpickling anything; ``predict`` and
    ``simulate`` of the loaded estimator are bit-identical to the saved
    one's. ``sysid-nn fit --save`` writes the same format; a file saved
    with ``inputs``, ``outputs`` and ``dt`` goes to ``sysid-nn validate
    --model`` as one from the command line does.

    Parameters
    ----------
    estimator : TDLRegressor, ISSMRegressor or EnsembleRegressor
        A fitted estimator (an ensemble is saved with its members).
    path : str or path-like
        The file to write (replaced if it exists); ``.sysid`` is the
        suggested extension.
    inputs, outputs : sequence of str, default=None
        Names of the excitation and output columns, in the order of ``X``'s
        columns and of the outputs; ``sysid-nn validate`` reads these
        columns from the records. Needed there, not in Python.
    dt : float, default=None
        Sampling step (s) of the records the model was fitted to;
        ``sysid-nn validate`` refuses records at another step.
    units : dict of str to str, default=None
        Units of the columns, for reports (``{column: unit}``).

    Raises
    ------
    TypeError
        ``estimator`` is not a TDL, ISSM or ensemble regressor, or holds an attribute
        of a type the format cannot hold.
    NotFittedError
        ``estimator`` is not fitted.
    ValueError
        ``inputs`` or ``outputs`` do not match the estimator's columns.

    See Also
    --------
    load_model : Read the file back.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> import numpy as np
    >>> from sysid_nn import TDLRegressor, save_model, load_model
    >>> rng = np.random.default_rng(0)
    >>> u = rng.standard_normal((200, 1))
    >>> y = np.convolve(u[:, 0], [0.0, 0.5, 0.25])[:200]
    >>> model = TDLRegressor(output_lags=1, input_lags=2, hidden_layer_sizes=(),
    ...                      n_init=1, random_state=0).fit(u, y)
    >>> path = pathlib.Path(tempfile.mkdtemp()) / "model.sysid"
    >>> save_model(model, path, inputs=["force"], outputs=["displacement"],
    ...            dt=0.01)
    >>> loaded = load_model(path)
    >>> bool(np.array_equal(loaded.simulate(u), model.simulate(u)))
    True
    """
    info: dict[str, Any] = dict.fromkeys(_INFO_KEYS)
    counts = (
        ("inputs", inputs, "n_features_in_"),
        ("outputs", outputs, "n_outputs_"),
    )
    for name, names, attribute in counts:
        if names is None:
            continue
        names = [names] if isinstance(names, str) else list(names)
        expected = getattr(estimator, attribute, None)
        if not all(isinstance(n, str) for n in names) or (
            expected is not None and len(names) != expected
        ):
            raise ValueError(
                f"{name} must be {expected} column name(s) (the estimator's "
                f"{attribute}), got {names!r}."
            )
        info[name] = names
    if dt is not None:
        if not (isinstance(dt, (int, float)) and 0 < dt < math.inf):
            raise ValueError(f"dt must be a finite number > 0 (seconds), got {dt!r}.")
        info["dt"] = float(dt)
    info["units"] = {str(k): str(v) for k, v in (units or {}).items()}
    _write(path, estimator, info)


# ----------------------------------------------------------------- reading
class _Decoder:
    """Tagged values back to attributes; only the whitelisted types."""

    def __init__(self, archive: zipfile.ZipFile, where: str) -> None:
        self.archive, self.where = archive, where
        self.dataclasses = _dataclasses()
        self.estimators = _estimators()

    def array(self, index: Any) -> np.ndarray:
        try:
            with self.archive.open(f"arrays/{int(index)}.npy") as f:
                return np.load(io.BytesIO(f.read()), allow_pickle=False)
        except (KeyError, ValueError, TypeError) as exc:
            raise self.broken(f"array {index!r}: {exc}") from None

    def broken(self, what: str) -> ValueError:
        return ValueError(f"{self.where} is damaged or not a model file ({what}).")

    def __call__(self, value: Any) -> Any:
        if value is None or isinstance(value, (bool, int, float, str)):
            return value
        if isinstance(value, list):
            return [self(v) for v in value]
        if not isinstance(value, dict):
            raise self.broken(f"unexpected {type(value).__name__}")
        tag = value.get("t")
        if tag == "array":
            return self.array(value.get("a"))
        if tag == "scalar":
            return self.array(value.get("a"))[()]
        if tag == "float" and value.get("v") in ("inf", "-inf", "nan"):
            return float(value["v"])
        if tag == "tuple" and isinstance(value.get("v"), list):
            return tuple(self(v) for v in value["v"])
        if tag in ("dict", "bunch"):
            from sklearn.utils import Bunch

            items = self.mapping(value.get("v"))
            return Bunch(**items) if tag == "bunch" else items
        if tag == "dataclass" and value.get("name") in self.dataclasses:
            cls = self.dataclasses[value["name"]]
            fields = self.mapping(value.get("v"))
            known = {f.name: f for f in dataclasses.fields(cls)}
            if set(fields) != set(known):
                raise self.broken(f"fields of {value['name']}")
            obj = cls(**{k: v for k, v in fields.items() if known[k].init})
            for k, v in fields.items():
                if not known[k].init:
                    object.__setattr__(obj, k, v)
            return obj
        if tag == "estimator" and value.get("name") in self.estimators:
            cls = self.estimators[value["name"]]
            estimator = cls.__new__(cls)
            # The attributes as saved; no __setstate__ (the version is
            # checked once, for the file).
            estimator.__dict__.update(self.mapping(value.get("v")))
            # A parameter added since the file was written takes its
            # default, which is how the model was fitted.
            for name, parameter in inspect.signature(cls).parameters.items():
                if name not in estimator.__dict__:
                    setattr(estimator, name, parameter.default)
            return estimator
        raise self.broken(f"unknown type {tag!r}")

    def mapping(self, value: Any) -> dict:
        if not isinstance(value, dict):
            raise self.broken("expected a mapping")
        return {str(k): self(v) for k, v in value.items()}


def _read(path: str | os.PathLike) -> tuple[Any, dict, str | None]:
    """Estimator, info and saving version of a model file (not a pickle)."""
    where = str(path)
    try:
        archive = zipfile.ZipFile(path)
    except zipfile.BadZipFile:
        raise ValueError(f"{where} is damaged or not a model file.") from None
    with archive:
        decode = _Decoder(archive, where)
        try:
            header = json.loads(archive.read(_HEADER))
        except (KeyError, ValueError, RecursionError):
            raise ValueError(
                f"{where} is a zip archive but not a model file (no readable "
                f"{_HEADER})."
            ) from None
        if not isinstance(header, dict) or header.get("format") != _FORMAT:
            raise ValueError(f"{where} is not a model file of sysid_nn.")
        version = header.get("format_version")
        if not isinstance(version, int) or version > _FORMAT_VERSION:
            raise ValueError(
                f"{where} has model file format version {version!r}, written by "
                f"sysid_nn {header.get('sysid_nn_version')}; this sysid_nn reads "
                f"versions up to {_FORMAT_VERSION}. Upgrade sysid_nn to load it."
            )
        try:
            estimator = decode(header.get("estimator"))
        except RecursionError:
            raise decode.broken("nested too deeply") from None
        if type(estimator) not in _estimators().values():
            raise decode.broken("no estimator")
        info = header.get("info") or {}
        if not (isinstance(info, dict) and _valid_info(info)):
            raise decode.broken("info")
        version = header.get("sysid_nn_version")
        return estimator, info, version if isinstance(version, str) else None


def _valid_info(info: dict) -> bool:
    """Whether ``info`` holds what :func:`save_model` writes, of its types."""

    def names(value) -> bool:
        return value is None or (
            isinstance(value, list) and all(isinstance(v, str) for v in value)
        )

    units = info.get("units") or {}
    dt = info.get("dt")
    return (
        names(info.get("inputs"))
        and names(info.get("outputs"))
        and names(info.get("files"))
        and (dt is None or (isinstance(dt, (int, float)) and 0 < dt < math.inf))
        and isinstance(units, dict)
        and all(isinstance(v, str) for v in units.values())
        and all(
            isinstance(info.get(k), (str, type(None))) for k in ("split_by", "label")
        )
    )


def _kind(path: str | os.PathLike) -> str:
    """``"model"``, ``"pickle"`` or ``"other"``, from the file's first bytes.

    A text file whose first characters happen to match a compressor's
    magic bytes (``x^``, ``BZh``) is "other": pickles and compressed data
    are binary.
    """
    with open(path, "rb") as f:
        head = f.read(1024)
    if head.startswith(_ZIP_MAGIC):
        return "model"
    if not head.startswith(_PICKLE_MAGIC):
        return "other"
    try:
        text = b"\x00" not in head and bool(head.decode("utf-8"))
    except UnicodeDecodeError:
        text = False
    return "other" if text else "pickle"


def _is_model_file(path: str | os.PathLike) -> bool:
    """Whether ``path`` is a file ``sysid-nn fit --save`` may replace."""
    try:
        kind = _kind(path)
        if kind == "model":
            _read(path)
    except (OSError, ValueError):
        return False
    return kind != "other"


def _read_pickle(path: str | os.PathLike) -> tuple[Any, dict, str | None]:
    """A trusted pickle: a ``sysid-nn fit --save`` bundle or a bare estimator."""
    import joblib

    warnings.warn(
        f"{path} is a pickle; loading it ran any code it contains. Load pickles "
        "only from sources you trust, and save the model again with "
        "sysid_nn.save_model (a format that runs no code).",
        UserWarning,
        stacklevel=4,
    )
    try:
        bundle = joblib.load(path)
    except OSError:
        raise
    except Exception as exc:  # unpickling garbage raises anything
        raise ValueError(f"cannot read {path} as a saved model: {exc}") from None
    if type(bundle) in _estimators().values():
        return bundle, {}, getattr(bundle, "_sysid_nn_version", None)
    if not (hasattr(bundle, "get") and bundle.get("model") is not None):
        raise ValueError(f"{path} was not written by `sysid-nn fit --save`.")
    model = bundle.model
    info = {
        "inputs": list(model.inputs),
        "outputs": list(model.outputs),
        "dt": bundle.get("dt"),
        "units": dict(bundle.get("units", {})),
        "files": list(bundle.get("files", [])),
        "split_by": bundle.get("split_by"),
        "label": model.label,
    }
    return model.estimator, info, bundle.get("sysid_nn_version")


def _load(path: str | os.PathLike, trusted: bool, flag: str):
    """Estimator, info (all of ``_INFO_KEYS``) and saving version of ``path``."""
    from sysid_nn._exceptions import check_version

    kind = _kind(path)
    if kind == "pickle" and not trusted:
        raise ValueError(
            f"{path} is a pickle (a joblib file, as sysid-nn fit --save wrote "
            "before), and unpickling runs any code the file contains; it was not "
            f"read. If you trust its source, pass {flag}, then save the model "
            "again with sysid_nn.save_model."
        )
    if kind == "other":
        raise ValueError(
            f"{path} is not a model file (one written by sysid_nn.save_model or "
            "`sysid-nn fit --save`)."
        )
    estimator, info, version = _read_pickle(path) if kind == "pickle" else _read(path)
    info = {key: info.get(key) for key in _INFO_KEYS}
    check_version(version, str(path))
    return estimator, info, version


def _read_bundle(path: str | os.PathLike, *, trusted: bool = False) -> Any:
    """What ``sysid-nn validate`` needs of a model file, as a Bunch.

    ``model`` (a :class:`~sysid_nn.study.StudyModel`), ``dt``, ``units``,
    ``files``, ``split_by`` and ``sysid_nn_version``.
    """
    from sklearn.utils import Bunch

    from sysid_nn.study import StudyModel

    estimator, info, version = _load(path, trusted, "--trust-pickle")
    if not (info["inputs"] and info["outputs"]):
        raise ValueError(
            f"{path} does not name the model's input and output columns; save it "
            "with sysid_nn.save_model(model, path, inputs=[...], outputs=[...], "
            "dt=...)."
        )
    label = info["label"] or type(estimator).__name__.removesuffix("Regressor")
    model = StudyModel(label, estimator, tuple(info["inputs"]), tuple(info["outputs"]))
    return Bunch(
        model=model,
        dt=info["dt"],
        units=dict(info["units"] or {}),
        files=list(info["files"] or []),
        split_by=info["split_by"],
        sysid_nn_version=version,
    )


def load_model(
    path: str | os.PathLike, *, trusted: bool = False, with_info: bool = False
) -> Any:
    """Load a model saved by :func:`save_model` or ``sysid-nn fit --save``.

    Reading runs no code from the file: it holds data only (see
    :func:`save_model`). Pickles — joblib files, as ``sysid-nn fit --save``
    wrote in earlier versions — are recognised by their first bytes and
    refused before anything is unpickled, unless ``trusted=True``.

    Parameters
    ----------
    path : str or path-like
        The model file.
    trusted : bool, default=False
        Also load a pickle (joblib) file. Unpickling runs any code the file
        contains: pass True only for files from a source you trust, then
        save the model again with :func:`save_model`.
    with_info : bool, default=False
        Also return what the file says about the records.

    Returns
    -------
    estimator : TDLRegressor or ISSMRegressor
        The fitted estimator, ready for ``predict`` and ``simulate``; its
        ``X`` columns are the ``inputs`` in the order saved, its outputs the
        ``outputs``.
    info : Bunch
        Only with ``with_info=True``: ``inputs`` and ``outputs`` (column
        names, or None if not saved), ``dt`` (sampling step, s, or None),
        ``units`` (``{column: unit}``), ``files`` (training files),
        ``split_by`` and ``sysid_nn_version`` (the version that saved it).

    Raises
    ------
    ValueError
        The file is a pickle and ``trusted`` is False; or it is not a model
        file, or was written in a newer version of the format.

    Warns
    -----
    UserWarning
        A pickle was loaded (``trusted=True``).
    InconsistentVersionWarning
        The file was saved by another version of sysid_nn.

    See Also
    --------
    save_model : Write a model file.

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
    ...       "--save", str(folder / "m.sysid")])
    0
    >>> model, info = load_model(folder / "m.sysid", with_info=True)
    >>> type(model).__name__, info.inputs, info.dt
    ('TDLRegressor', ('excitation',), 0.01)
    """
    from sklearn.utils import Bunch

    estimator, info, version = _load(path, trusted, "trusted=True")
    if not with_info:
        return estimator
    names = {
        key: None if info[key] is None else tuple(info[key])
        for key in ("inputs", "outputs")
    }
    return estimator, Bunch(
        **names,
        dt=info["dt"],
        units=dict(info["units"] or {}),
        files=list(info["files"] or []),
        split_by=info["split_by"],
        sysid_nn_version=version,
    )
