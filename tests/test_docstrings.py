"""Docstrings of the public API follow the numpydoc standard.

Every name in ``__all__`` of the public modules, and every public method and
property of the public classes, is validated with
:func:`numpydoc.validate.validate` against the checks listed in ``CHECKS``.
A public module whose file does not exist yet is not collected at all; a
module whose file exists must import.
"""

from __future__ import annotations

import dataclasses
import importlib
import inspect
from pathlib import Path

import numpydoc.validate as numpydoc_validate
import pytest

PACKAGE_DIR = Path(__file__).resolve().parents[1] / "sysid_nn"

PUBLIC_MODULES = [
    "sysid_nn",
    "sysid_nn.excitation",
    "sysid_nn.oscillator",
    "sysid_nn.building",
    "sysid_nn.residuals",
    "sysid_nn.metrics",
    "sysid_nn.plotting",
    "sysid_nn.study",
    "sysid_nn.uncertainty",
    "sysid_nn.datasets",
]

# The numpydoc checks enforced on every public object.
CHECKS = {
    # General layout.
    "GL02",  # closing quotes on their own line
    "GL03",  # no double blank lines
    "GL05",  # no tabs
    "GL06",  # unknown section
    "GL07",  # sections in the wrong order
    "GL08",  # no docstring
    "GL09",  # deprecation note misplaced
    "GL10",  # malformed reST directive
    # Summary line.
    "SS01",  # no summary
    "SS02",  # summary starts with a capital letter
    "SS03",  # summary ends with a period
    "SS04",  # summary without leading whitespace
    "SS05",  # summary in the infinitive ("Return", not "Returns")
    "SS06",  # summary on a single line
    # Parameters.
    "PR01",  # parameter not documented
    "PR02",  # documented parameter that does not exist
    "PR03",  # parameters in the wrong order
    "PR04",  # parameter without type
    "PR05",  # parameter type ending with a period
    "PR06",  # "integer"/"boolean"/"string" instead of int/bool/str
    "PR07",  # parameter without description
    "PR08",  # parameter description not starting with a capital letter
    "PR09",  # parameter description not ending with a period
    "PR10",  # missing space around the colon
    # Returns and yields.
    "RT01",  # no Returns section although something is returned
    "RT03",  # return value without description
    "RT04",  # return description not starting with a capital letter
    "RT05",  # return description not ending with a period
    "YD01",  # no Yields section in a generator
    # Examples: required for module-level functions and classes (not methods).
    "EX01",
}
CHECKS_NOT_FOR_METHODS = {"EX01"}


def _is_own(obj) -> bool:
    """Whether ``obj`` is defined in the package (not inherited from a library)."""
    target = obj.fget if isinstance(obj, property) else obj
    target = getattr(target, "__func__", target)
    return (getattr(target, "__module__", None) or "").startswith("sysid_nn")


def _public_members(cls) -> list[str]:
    """Public methods and properties of ``cls`` written in this package."""
    names = []
    for name, _ in inspect.getmembers(cls):
        if name.startswith("_"):
            continue
        raw = inspect.getattr_static(cls, name)
        if isinstance(raw, (staticmethod, classmethod)):
            raw = raw.__func__
        if not (inspect.isfunction(raw) or isinstance(raw, property)):
            continue
        if _is_own(raw):
            names.append(name)
    return names


def _objects_to_validate(module_name: str) -> tuple[list[tuple[str, bool]], list[str]]:
    """Import paths to validate in ``module_name`` and names that do not import.

    Each path comes with a flag telling whether it is a method or property.
    """
    module = importlib.import_module(module_name)
    paths = []
    broken = []
    for name in module.__all__:
        path = f"{module_name}.{name}"
        try:
            obj = getattr(module, name)
        except (AttributeError, ImportError) as exc:
            broken.append(f"{path}: cannot be imported ({exc})")
            continue
        if inspect.isclass(obj):
            paths.append((path, False))
            paths += [(f"{path}.{member}", True) for member in _public_members(obj)]
        elif inspect.isroutine(obj):
            paths.append((path, False))
        # Other objects (constants, scorer instances) carry no docstring of
        # their own; they are described in their module's docstring.
    return paths, broken


def _documented_attributes(path: str) -> set[str]:
    doc = numpydoc_validate.Validator(numpydoc_validate.get_doc_object(_resolve(path)))
    return {p.name.split(":")[0].strip() for p in doc.doc["Attributes"]}


def _resolve(path: str):
    module_name, _, rest = path.partition(".")
    obj = importlib.import_module(module_name)
    for part in rest.split("."):
        try:
            obj = getattr(obj, part)
        except AttributeError:
            obj = importlib.import_module(f"{obj.__name__}.{part}")
    return obj


def _errors(path: str, is_method: bool) -> list[tuple[str, str]]:
    checks = CHECKS - CHECKS_NOT_FOR_METHODS if is_method else CHECKS
    result = numpydoc_validate.validate(path)
    errors = [(code, msg) for code, msg in result["errors"] if code in checks]
    obj = _resolve(path)
    if inspect.isclass(obj) and dataclasses.is_dataclass(obj):
        # A dataclass documents its fields once, under "Attributes"; they are
        # its constructor parameters, so they count as documented.
        attributes = _documented_attributes(path)
        fields = {f.name for f in dataclasses.fields(obj) if f.init}
        documented_fields = fields & attributes
        if documented_fields == fields:
            errors = [(code, msg) for code, msg in errors if code != "PR01"]
    return errors


# Modules without a Python API of their own to document.
NOT_API_MODULES = {"sysid_nn.cli", "sysid_nn.__main__"}


def test_every_public_module_is_checked():
    on_disk = {
        f"sysid_nn.{path.stem}"
        for path in PACKAGE_DIR.glob("*.py")
        if not path.stem.startswith("_")
    } | {
        f"sysid_nn.{path.parent.name}"
        for path in PACKAGE_DIR.glob("*/__init__.py")
        if not path.parent.name.startswith("_")
    }
    unchecked = sorted(on_disk - set(PUBLIC_MODULES) - NOT_API_MODULES)
    assert not unchecked, f"public modules missing from PUBLIC_MODULES: {unchecked}"


@pytest.mark.parametrize("module_name", PUBLIC_MODULES)
def test_module_imports_and_all_resolves(module_name):
    module = importlib.import_module(module_name)
    assert module.__doc__, f"{module_name} has no module docstring"
    names = getattr(module, "__all__", None)
    assert names, f"{module_name} defines no __all__"
    unresolved = []
    for name in names:
        try:
            getattr(module, name)
        except AttributeError as exc:
            unresolved.append(f"{name} ({exc})")
    assert not unresolved, f"{module_name}.__all__ lists missing names: {unresolved}"


@pytest.mark.parametrize("module_name", PUBLIC_MODULES)
def test_docstrings_follow_numpydoc(module_name):
    paths, report = _objects_to_validate(module_name)
    for path, is_method in paths:
        for code, msg in _errors(path, is_method):
            report.append(f"{path}: {code} {msg}")
    assert not report, (
        f"{len(report)} numpydoc defect(s) in {module_name}:\n" + "\n".join(report)
    )
