"""The ``sysid-nn`` command: a thin shell over the public API.

One sub-command per task, each in its own module (``_generate``,
``_reproduce``, ``_fit``, ``_validate``, ``_modal``) with an ``_add_<command>`` function
that builds its parser and a ``_run_<command>(args) -> int`` function that
runs it, so new commands plug in without touching the others; ``_records``
reads the user's files and ``_common`` holds what every command shares::

    sysid-nn generate --n-realizations 5 --out sysid_nn_records.csv
    sysid-nn reproduce --quick --out sysid_nn_results
    sysid-nn fit records.csv --input excitation --output displacement \\
        --split-by realization --save model.joblib
    sysid-nn validate --model model.joblib new_records.csv --out validation
    sysid-nn modal model.joblib

Every command that writes refuses to replace an existing output without
``--overwrite``, never writes over one of its own input files, checks that the
destination is writable before any long work and writes atomically (a
temporary file or directory beside the destination, moved in place at the
end), so an interrupted run leaves the old output or none.

Exit status: 0 on success; 1 when an input cannot be read or its contents do
not fit (the message names the file and the column), or an output cannot or
may not be written; 2 for bad arguments (argparse's usage message for syntax,
one ``sysid-nn: error: ...`` line for values that parse but make no sense);
130 when interrupted. Errors are one line, never a traceback.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence

from sysid_nn.cli._common import (
    _PROG,
    _fail,
    _InputError,
    _OutputError,
    _reason,
)
from sysid_nn.cli._fit import _add_fit
from sysid_nn.cli._generate import _add_generate
from sysid_nn.cli._modal import _add_modal
from sysid_nn.cli._reproduce import _add_reproduce
from sysid_nn.cli._validate import _add_validate

__all__ = ["main"]

# -------------------------------------------------------------------- main
_COMMANDS: tuple[Callable[[argparse._SubParsersAction], None], ...] = (
    _add_generate,
    _add_reproduce,
    _add_fit,
    _add_validate,
    _add_modal,
)


def build_parser() -> argparse.ArgumentParser:
    """Argument parser of the ``sysid-nn`` command, one sub-parser per command.

    Returns
    -------
    argparse.ArgumentParser

    Examples
    --------
    >>> build_parser().parse_args(["generate", "--out", "r.csv"]).n_realizations
    25
    """
    from sysid_nn import __version__

    parser = argparse.ArgumentParser(
        prog=_PROG,
        description="Identification of non-linear structures with recurrent "
        "networks. Exit status: 0 success; 1 an input cannot be read or does "
        "not fit, or an output cannot or may not be written; 2 bad arguments; "
        "130 interrupted.",
    )
    parser.add_argument(
        "--version", action="version", version=f"%(prog)s {__version__}"
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for add in _COMMANDS:
        add(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``sysid-nn`` command line.

    Parameters
    ----------
    argv : sequence of str or None, default=None
        Arguments without the program name; ``None`` reads ``sys.argv[1:]``.

    Returns
    -------
    int
        Exit status: 0 on success; 1 when an input cannot be read or its
        contents do not fit, or an output cannot be written, exists (without
        ``--overwrite``) or is one of the inputs; 2 for bad arguments
        (argparse exits with status 2 itself for syntax errors); 130 when
        interrupted.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> out = pathlib.Path(tempfile.mkdtemp()) / "records.csv"
    >>> main(["generate", "--n-realizations", "2", "--n-samples", "100",
    ...       "--r0", "0.05", "--out", str(out)])
    wrote 2 realisation(s) x 100 samples (dt=0.01 s, r0=0.05) to ...records.csv
    0
    """
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except (_InputError, _OutputError, ConnectionError, ImportError) as exc:
        return _fail(exc)
    except ValueError as exc:
        # The API's messages name the argument and the fix: one line, no traceback.
        _fail(exc)
        return 2
    except FileExistsError as exc:  # another process created the output meanwhile
        return _fail(f"{exc.filename or 'the output'} exists; pass --overwrite.")
    except OSError as exc:
        where = f" {exc.filename}" if exc.filename else ""
        return _fail(f"cannot write{where}: {_reason(exc)}")
    except KeyboardInterrupt:
        print(f"{_PROG}: interrupted; nothing was written", file=sys.stderr)
        return 130
