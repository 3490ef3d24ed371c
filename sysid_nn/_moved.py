"""Old module paths of the private modules that moved into groups.

Models pickled before the move name their classes by the old paths
(``sysid_nn._layout.MLPLayout``); an import hook maps each old path to the
module that now holds it, so those files keep loading.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys
from types import ModuleType

#: Group of each moved module.
MOVED = {
    **dict.fromkeys(("_data", "_record_checks", "_validation"), "_records"),
    **dict.fromkeys(
        (
            "_schedule",
            "_solvers",
            "_shooting",
            "_training",
            "_selection",
            "_order",
            "_diagnosis",
            "_layout",
            "_state_estimation",
            "_subspace",
            "_innovation",
            "_issm_start",
            "_progress",
        ),
        "_engine",
    ),
    **dict.fromkeys(
        ("_base", "_tdl", "_issm", "_issm_realisation", "_estimator_docs"),
        "_estimators",
    ),
    **dict.fromkeys(
        ("_correlation_tests", "_uncertainty", "_sensitivity"), "_analysis"
    ),
}


class _Alias(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Finds ``sysid_nn.<old>`` and loads it as ``sysid_nn.<group>.<old>``."""

    def find_spec(self, fullname, path=None, target=None):
        package, _, name = fullname.rpartition(".")
        if package != "sysid_nn" or name not in MOVED:
            return None
        return importlib.util.spec_from_loader(fullname, self)

    def create_module(self, spec) -> ModuleType:
        name = spec.name.rpartition(".")[2]
        return importlib.import_module(f"sysid_nn.{MOVED[name]}.{name}")

    def exec_module(self, module: ModuleType) -> None:
        # The module was executed under its new name already.
        pass


def install() -> None:
    """Put the alias finder on ``sys.meta_path`` once."""
    if not any(isinstance(f, _Alias) for f in sys.meta_path):
        sys.meta_path.append(_Alias())
