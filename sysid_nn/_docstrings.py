"""Docstring sections that several objects share, written once."""

from __future__ import annotations

import inspect


def fill_doc(**sections: str):
    """Replace every ``%(name)s`` in the decorated object's docstring.

    The docstring is cleaned first (Python 3.13 dedents docstrings itself),
    so a section is written without indentation and may span several lines.

    Parameters
    ----------
    **sections : str
        The text of every placeholder, by name.

    Returns
    -------
    callable
        A decorator for a function or class.

    Examples
    --------
    >>> @fill_doc(unit="Seconds.")
    ... def f():
    ...     '''Time.
    ...
    ...     %(unit)s
    ...     '''
    >>> f.__doc__
    'Time.\\n\\nSeconds.\\n'
    """

    def decorate(obj):
        doc = inspect.cleandoc(obj.__doc__)
        for name, text in sections.items():
            doc = doc.replace(f"%({name})s", text)
        obj.__doc__ = doc + "\n"
        return obj

    return decorate
