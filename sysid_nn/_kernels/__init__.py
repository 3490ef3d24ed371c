"""Compiled (numba) kernels: pure functions on float64 arrays and ints.

The kernels are compiled with ``cache=True``. numba would put the cache files
in a ``__pycache__`` folder beside each module, that is inside the installed
package: pip does not know those files, so they outlive ``pip uninstall`` and
the folder they leave turns into a namespace package that shadows a later
(editable) install. Importing this package first registers a cache locator
that keeps the compiled kernels of *this package only* in a per-user cache
directory (``~/.cache/sysid_nn/numba`` on Linux, the platform's equivalent
elsewhere); ``NUMBA_CACHE_DIR``, when set, is respected as numba does. Other
libraries' numba caching is unchanged.

The cache is keyed by the kernels' source text, not by where the package is
installed: a regular and an editable install of the same sources share one
set of compiled kernels, and a change to any kernel module recompiles them
all (a kernel inlines functions of the other modules, which numba's per-file
check would miss).
"""

from __future__ import annotations

import functools
import hashlib
import os
import tempfile

from numba.core import caching as _caching
from numba.core import config as _numba_config
from numba.misc.appdirs import AppDirs

_HERE = os.path.dirname(os.path.abspath(__file__))


def cache_dir() -> str:
    """Directory of the kernels' numba cache.

    Returns
    -------
    str
        ``<user cache directory>/sysid_nn/numba``: ``$XDG_CACHE_HOME`` or
        ``~/.cache`` on Linux, ``~/Library/Caches`` on macOS,
        ``%LOCALAPPDATA%`` on Windows.
    """
    root = AppDirs(appname="sysid_nn", appauthor=False).user_cache_dir
    return os.path.join(root, "numba")


class _UserCacheLocator(_caching._SourceFileBackedLocatorMixin, _caching._CacheLocator):
    """numba cache locator for the modules of this package, outside the package."""

    def __init__(self, py_func, py_file, root: str) -> None:
        self._py_file = py_file
        self._lineno = py_func.__code__.co_firstlineno
        self._cache_path = os.path.join(root, self.get_suitable_cache_subpath(py_file))

    def get_cache_path(self) -> str:
        return self._cache_path

    @classmethod
    def get_suitable_cache_subpath(cls, py_file) -> str:
        # One folder wherever the package is installed (numba's default hashes
        # the install path, so each install would compile its own copy).
        return "kernels"

    def get_source_stamp(self) -> str:
        return sources_digest()

    @classmethod
    def from_function(cls, py_func, py_file):
        path = os.path.abspath(py_file)
        if os.path.dirname(path) != _HERE or _numba_config.CACHE_DIR:
            return None  # another library's function, or the user chose a folder
        # An unwritable cache directory (read-only home, sandbox) falls back to
        # a private temporary one, never to numba's in-package default.
        for root in (cache_dir, _private_tmp):
            locator = cls(py_func, py_file, root())
            try:
                locator.ensure_cache_path()
            except OSError:
                continue
            return locator
        return None


@functools.lru_cache(maxsize=1)
def sources_digest() -> str:
    """Digest of the text of every kernel module (the cache's freshness key).

    Returns
    -------
    str
        SHA-256 hex digest over the ``.py`` files of this package, in name order.
    """
    digest = hashlib.sha256()
    for name in sorted(os.listdir(_HERE)):
        if name.endswith(".py"):
            with open(os.path.join(_HERE, name), "rb") as f:
                digest.update(name.encode() + b"\0" + f.read())
    return digest.hexdigest()


_TMP: list[str] = []


def _private_tmp() -> str:
    if not _TMP:
        _TMP.append(tempfile.mkdtemp(prefix="sysid_nn-numba-"))
    return _TMP[0]


def _register() -> None:
    # numba tries its locators in order; ours goes first and declines every
    # file that is not one of this package's kernel modules.
    # (``CacheImpl`` was ``_CacheImpl`` before numba 0.61.)
    impl = getattr(_caching, "CacheImpl", None) or _caching._CacheImpl
    locators = impl._locator_classes
    if _UserCacheLocator not in locators:
        locators.insert(0, _UserCacheLocator)


_register()
