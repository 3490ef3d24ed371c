"""The ``sysid-nn`` command: a thin shell over the public API.

One sub-command per task, each built by an ``_add_<command>`` function and
run by a ``_run_<command>(args) -> int`` function, so new commands plug in
without touching the others::

    sysid-nn generate --n-realizations 5 --out sysid_nn_records.csv
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

__all__ = ["main"]

_PROG = "sysid-nn"
_FRAME_WRITERS = {".csv": "to_csv", ".parquet": "to_parquet"}


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected an integer >= 1, got {text!r}"
        ) from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1, got {text!r}")
    return value


def _seed(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected an integer >= 0, got {text!r}"
        ) from None
    if not 0 <= value < 2**32:
        raise argparse.ArgumentTypeError(
            f"expected an integer in [0, 2**32), got {text!r}"
        )
    return value


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected a number > 0, got {text!r}"
        ) from None
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"expected a finite number > 0, got {text!r}")
    return value


def _frame_path(text: str) -> Path:
    path = Path(text)
    if path.suffix.lower() not in _FRAME_WRITERS:
        raise argparse.ArgumentTypeError(
            f"{text!r} must end in {' or '.join(_FRAME_WRITERS)} (the format is taken "
            f"from the suffix)"
        )
    return path


# --------------------------------------------------------------------- generate
def _add_generate(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "generate",
        help="simulate records of the hysteretic oscillator (paper section 4.1)",
        description=(
            "Simulate the Bouc-Wen oscillator under the paper's modulated "
            "Kanai-Tajimi excitation and write a tidy table with columns "
            "realization, t, excitation, displacement, velocity, hysteretic."
        ),
    )
    p.add_argument("--n-realizations", type=_positive_int, default=25, metavar="N")
    p.add_argument("--n-samples", type=_positive_int, default=2000, metavar="N")
    p.add_argument("--dt", type=_positive_float, default=0.01, help="sample spacing, s")
    p.add_argument("--seed", type=_seed, default=0, help="random seed (default: 0)")
    p.add_argument(
        "--r0",
        type=_positive_float,
        default=None,
        help="excitation strength (default: calibrated so E[max|X|] = 2 z0)",
    )
    p.add_argument(
        "--out",
        type=_frame_path,
        required=True,
        metavar="FILE",
        help=".csv or .parquet",
    )
    p.set_defaults(func=_run_generate)


def _run_generate(args: argparse.Namespace) -> int:
    # Imported here so that `sysid-nn --help` does not load numba.
    from sysid_nn import HystereticOscillator

    osc = HystereticOscillator(r0="calibrate" if args.r0 is None else args.r0)
    rec = osc.generate(
        args.n_realizations,
        n_samples=args.n_samples,
        dt=args.dt,
        random_state=args.seed,
        as_frame=True,
    )
    writer = _FRAME_WRITERS[args.out.suffix.lower()]
    try:
        if writer == "to_csv":
            rec.frame.to_csv(args.out, index=False)
        else:
            rec.frame.to_parquet(args.out, index=False)
    except ImportError as exc:
        return _fail(f"cannot write {args.out}: {exc}")
    except OSError as exc:
        return _fail(f"cannot write {args.out}: {exc.strerror or exc}")
    print(
        f"wrote {args.n_realizations} realisation(s) x {args.n_samples} samples "
        f"(dt={args.dt:g} s, r0={rec.r0:.6g}) to {args.out}"
    )
    return 0


# ------------------------------------------------------------------------ main
_COMMANDS: tuple[Callable[[argparse._SubParsersAction], None], ...] = (_add_generate,)


def _fail(message: str) -> int:
    print(f"{_PROG}: error: {message}", file=sys.stderr)
    return 1


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
        description="Identification of non-linear structures with recurrent networks.",
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
        Exit status: 0 on success, 1 when the output cannot be written, 2 for
        bad arguments (argparse exits with status 2 itself).

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
    except ValueError as exc:
        # The API's messages name the argument and the fix: one line, no traceback.
        print(f"{_PROG} {args.command}: error: {exc}", file=sys.stderr)
        return 2
