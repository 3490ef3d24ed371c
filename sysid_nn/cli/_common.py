"""What every command shares: errors, option types, safe outputs, help text."""

from __future__ import annotations

import argparse
import errno
import math
import os
import re
import sys
import tempfile
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

_PROG = "sysid-nn"


class _InputError(Exception):
    """An input that cannot be read, or whose contents do not fit: exit 1."""


class _OutputError(Exception):
    """An output that cannot, or may not, be written: exit 1."""


class _HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Every default in ``--help``; options without one say what happens."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        if action.default is None or action.default is False:
            return action.help
        if "default" in (action.help or ""):
            return action.help
        return super()._get_help_string(action)


# ---------------------------------------------------------------- arguments
def _bounded(
    cast: Callable[[str], Any], accept: Callable[[Any], bool], expected: str
) -> Callable[[str], Any]:
    """An argparse ``type``: ``cast`` the text, keep it if ``accept`` says so."""

    def parse(text: str) -> Any:
        try:
            value = cast(text)
        except ValueError:
            value = None
        if value is None or not accept(value):
            raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}")
        return value

    parse.__name__ = expected  # argparse names the type in some messages
    return parse


_positive_int = _bounded(int, lambda v: v >= 1, "an integer >= 1")
_seed = _bounded(int, lambda v: 0 <= v < 2**32, "an integer in [0, 2**32)")
_positive_float = _bounded(float, lambda v: 0 < v < math.inf, "a finite number > 0")


def _add_parallel(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--n-jobs",
        type=int,
        default=None,
        metavar="N",
        help="parallel jobs (joblib: -1 = all cores; default: serial)",
    )


def _add_output_flags(p: argparse.ArgumentParser, what: str) -> None:
    p.add_argument(
        "--overwrite",
        action="store_true",
        help=f"replace an existing {what} (never one of the inputs)",
    )
    p.add_argument(
        "--quiet",
        action="store_true",
        help="no progress or summary: nothing but warnings and errors (stderr)",
    )


# ------------------------------------------------------------------ outputs
def _check_output(
    path: Path,
    option: str,
    *,
    overwrite: bool,
    inputs: Sequence[Path] = (),
    directory: bool = False,
) -> None:
    """Refuse, before any long work, an output that would lose data or fail.

    ``path`` may not be (or, for a ``directory``, hold) one of ``inputs``,
    even with ``overwrite``; it may exist only with ``overwrite`` (and an
    existing directory only if it is a previous output: empty or with a
    ``report.md``); and its directory must be writable.
    """
    target = path.resolve()
    for source in inputs:
        held = source.resolve()
        if (
            held == target
            or (directory and target in held.parents)
            or (path.exists() and source.exists() and os.path.samefile(path, source))
        ):
            raise _OutputError(
                f"{option} {path} would overwrite the input file {source}; choose "
                f"another {option}."
            )
    if path.exists():
        if directory != path.is_dir():
            kind = "a directory" if directory else "a file"
            raise _OutputError(f"cannot write {path}: {option} must be {kind}.")
        if not overwrite:
            raise _OutputError(
                f"{path} exists; pass --overwrite to replace it, or choose another "
                f"{option}."
            )
        if directory and any(path.iterdir()) and not (path / "report.md").is_file():
            raise _OutputError(
                f"{path} does not look like an output of {_PROG} (no report.md); "
                f"--overwrite replaces only those. Choose another {option}."
            )
    parent = target.parent
    if directory:  # missing parents are created: the nearest existing one counts
        while not parent.exists() and parent != parent.parent:
            parent = parent.parent
    try:
        if not parent.exists():
            raise FileNotFoundError(errno.ENOENT, "no such directory", parent)
        if not parent.is_dir():
            raise NotADirectoryError(errno.ENOTDIR, "a file is in the way", parent)
        tempfile.TemporaryFile(dir=parent).close()
    except OSError as exc:
        raise _OutputError(f"cannot write {path}: {_reason(exc)}") from None


def _write_atomic(path: Path, write: Callable[[Path], None]) -> None:
    """``write`` a temporary file beside ``path``, then move it in place."""
    fd, name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.close(fd)
    tmp = Path(name)
    try:
        mask = os.umask(0)
        os.umask(mask)
        os.chmod(tmp, 0o666 & ~mask)  # mkstemp's file is private; outputs are not
        write(tmp)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def _reason(exc: BaseException) -> str:
    return getattr(exc, "strerror", None) or str(exc)


# One line for the command list, a paragraph for the command's --help.
_ABOUT = {
    "generate": (
        "simulate records of the hysteretic oscillator (paper section 4.1)",
        "Simulate the Bouc-Wen oscillator under the paper's modulated "
        "Kanai-Tajimi excitation and write a tidy table with columns "
        "realization, t, excitation, displacement, velocity, hysteretic. "
        "Fit or validate on it with --split-by realization.",
    ),
    "reproduce": (
        "run the paper's section-4 study and write figures, tables, report",
        "Generate seeded training, validation and test records of the "
        "hysteretic oscillator, fit the paper's TDL and ISSM networks, the "
        "linear baseline and the toolbox's defaults, evaluate one-step "
        "prediction and free-run simulation on unseen realisations and "
        "write figs 4.1-4.7, a hysteresis plot, results.csv, summary.csv "
        "and report.md into --out.",
    ),
    "fit": (
        "fit a TDL or ISSM network to measured records and save it",
        "Fit a recurrent network to your own records: named excitation "
        "(--input) and response (--output) columns of CSV or parquet "
        "files, one experiment per file (or per --split-by group). The "
        "fitted model is saved with joblib for `sysid-nn validate`. The "
        "closing line scores the model on the validation records that chose "
        "its weights.",
    ),
    "validate": (
        "residual tests, error statistics and figures of a saved model",
        "Run a model saved by `sysid-nn fit` on validation records: "
        "one-step prediction and free-run simulation, residual tests, "
        "error statistics, figures, the predicted and simulated series "
        "and report.md in --out; the scores of every output are printed "
        "under its column name.",
    ),
    "modal": (
        "natural frequencies, damping ratios and mode shapes of a saved model",
        "Print the modes of a model saved by `sysid-nn fit`, from its "
        "linearisation at rest: natural frequency and damping ratio with "
        "their intervals (propagated from the weights' covariance), and with "
        "several outputs the mode shape under each output's column name. "
        "Numerical modes (real poles, near Nyquist, unobservable) are left "
        "out unless --all.",
    ),
}


def _command(
    sub: argparse._SubParsersAction, name: str, run: Callable[[argparse.Namespace], int]
) -> argparse.ArgumentParser:
    """The sub-parser of command ``name``, run by ``run``."""
    summary, description = _ABOUT[name]
    p = sub.add_parser(
        name, help=summary, description=description, formatter_class=_HelpFormatter
    )
    p.set_defaults(func=run)
    return p


# ------------------------------------------------------------------- scores
def _scores(estimator, X, y, *, tail: float | None = None, y_init: int = 0) -> dict:
    """Pooled NRMSE and RMSE per output, one-step and free run.

    ``tail`` scores only that last share of each record (the free run still
    starts from rest at its beginning); ``y_init`` starts the free runs from
    each record's first ``y_init`` measured samples and scores them after.
    """
    import numpy as np

    from sysid_nn.metrics import nrmse

    scores = {}
    for mode in ("prediction", "simulation"):
        start = y_init if mode == "simulation" else 0
        y_hat = [
            estimator.predict(x, y_k)
            if mode == "prediction"
            else estimator.simulate(x, y_init=y_k[:start] if start else None)
            for x, y_k in zip(X, y, strict=True)
        ]
        cut = [start] * len(y)
        if tail is not None:
            cut = [len(y_k) - round(tail * len(y_k)) for y_k in y]
        true = [y_k[c:] for y_k, c in zip(y, cut, strict=True)]
        pred = [p[c:] for p, c in zip(y_hat, cut, strict=True)]
        values = np.atleast_1d(nrmse(true, pred, multioutput="raw_values"))
        spread = np.atleast_1d(np.std(np.concatenate(true), axis=0))
        scores[mode] = (values, values * spread)
    return scores


def _score_lines(scores: Mapping, outputs: Sequence[str], units: Mapping) -> list:
    """One line per output: NRMSE and RMSE (in the output's unit) per mode."""
    lines = []
    for j, column in enumerate(outputs):
        unit = f" {units[column]}" if column in units else ""
        parts = [
            f"{mode} NRMSE {nrmse[j]:.4g} (RMSE {rmse[j]:.4g}{unit})"
            for mode, (nrmse, rmse) in scores.items()
        ]
        lines.append(f"  {column}: " + ", ".join(parts))
    return lines


def _fail(message: BaseException | str) -> int:
    print(f"{_PROG}: error: {_one_line(message)}", file=sys.stderr)
    return 1


def _one_line(message: BaseException | str) -> str:
    return re.sub(r"\s+", " ", str(message)).strip()
