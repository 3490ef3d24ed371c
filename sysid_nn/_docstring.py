"""Docstring text shared by several public functions, written once."""

from __future__ import annotations

import inspect
import re
import textwrap
from collections.abc import Callable
from typing import Any, TypeVar

_Documented = TypeVar("_Documented", bound=Callable[..., Any])


def insert_docs(**shared: str) -> Callable[[_Documented], _Documented]:
    """Return a decorator that fills ``%(name)s`` lines of a docstring.

    A line holding only the placeholder ``%(name)s`` is replaced by the text
    ``shared[name]`` (written without indentation, e.g. numpydoc parameter
    entries), indented like the placeholder; ``%`` elsewhere is left alone.

    Parameters
    ----------
    **shared : str
        Text for every placeholder name.

    Returns
    -------
    callable
        Decorator returning the function with its docstring filled.

    Examples
    --------
    >>> @insert_docs(seed="seed : int\\n    Random seed.")
    ... def draw(seed):
    ...     '''Draw a number.
    ...
    ...     Parameters
    ...     ----------
    ...     %(seed)s
    ...     '''
    >>> print(draw.__doc__)
    Draw a number.
    <BLANKLINE>
    Parameters
    ----------
    seed : int
        Random seed.
    <BLANKLINE>
    """

    def fill(match: re.Match) -> str:
        return textwrap.indent(textwrap.dedent(shared[match[2]]), match[1])

    def decorate(func: _Documented) -> _Documented:
        # Work on the cleaned text: Python 3.13 dedents docstrings itself.
        doc = inspect.cleandoc(func.__doc__ or "")
        func.__doc__ = re.sub(r"^( *)%\((\w+)\)s$", fill, doc, flags=re.M) + "\n"
        return func

    return decorate
