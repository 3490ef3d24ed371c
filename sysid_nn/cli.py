"""The ``sysid-nn`` command: a thin shell over the public API.

One sub-command per task, each built by an ``_add_<command>`` function and
run by a ``_run_<command>(args) -> int`` function, so new commands plug in
without touching the others::

    sysid-nn generate --n-realizations 5 --out sysid_nn_records.csv
    sysid-nn reproduce --quick --out sysid_nn_results
    sysid-nn fit records.csv --input excitation --output displacement \\
        --split-by realization --save model.joblib
    sysid-nn validate --model model.joblib new_records.csv --out validation

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
import errno
import math
import os
import re
import sys
import tempfile
import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

__all__ = ["main"]

_PROG = "sysid-nn"
_FRAME_SUFFIXES = (".csv", ".parquet")
#: Sample times may jitter by this share of the step (printed, rounded times).
_DT_TOLERANCE = 0.01
#: Column names taken as the time axis (in seconds) unless --time-column says.
_TIME_NAMES = re.compile(
    r"(t|time)(_s|_sec|\s*\[\s*s\s*\]|\s*\(\s*s\s*\))?", flags=re.IGNORECASE
)
#: ``name [unit]`` or ``name (unit)``: units read from column names.
_UNIT_IN_NAME = re.compile(r".*?[\[(]\s*([^\])]+?)\s*[\])]\s*")


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


def _frame_path(text: str) -> Path:
    path = Path(text)
    if path.suffix.lower() not in _FRAME_SUFFIXES:
        raise argparse.ArgumentTypeError(
            f"{text!r} must end in {' or '.join(_FRAME_SUFFIXES)} (the format is "
            f"taken from the suffix)"
        )
    return path


def _unit_pair(text: str) -> tuple[str, str]:
    column, sep, unit = text.partition("=")
    if not (sep and column and unit):
        raise argparse.ArgumentTypeError(f"expected COLUMN=UNIT, got {text!r}")
    return column, unit


def _hidden(text: str) -> tuple[int, ...]:
    """``9`` or ``9,9``; ``0`` (or empty) is the linear model."""
    try:
        sizes = tuple(int(v) for v in text.split(",") if v.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected layer sizes like 9 or 9,9 (0 for linear), got {text!r}"
        ) from None
    if any(v < 0 for v in sizes):
        raise argparse.ArgumentTypeError(f"layer sizes must be >= 0, got {text!r}")
    return tuple(v for v in sizes if v > 0)


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
    p.add_argument("--quiet", action="store_true", help="no progress or summary")


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


# ------------------------------------------------------------------ records
@dataclass
class _Records:
    """Columns of the experiments read from files, and where each came from."""

    columns: dict[str, list]
    origins: list[str] = field(default_factory=list)
    dt: float | None = None
    dt_origin: str = ""

    def lengths(self) -> list[int]:
        return [len(a) for a in next(iter(self.columns.values()))]


def _data_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "files",
        nargs="+",
        type=_frame_path,
        metavar="FILE",
        help=".csv or .parquet files, one experiment each (see --split-by)",
    )
    p.add_argument(
        "--split-by",
        default=None,
        metavar="COLUMN",
        help="column that splits a file into experiments (e.g. realization, "
        "as written by `sysid-nn generate`); default: one experiment per file",
    )
    p.add_argument(
        "--time-column",
        default="auto",
        metavar="COLUMN",
        help="column of sample times in seconds, from which dt is inferred and "
        "checked to be uniform; 'auto' takes a column named t or time (also "
        "t_s, 'time [s]', ...), 'none' ignores the files' times",
    )
    p.add_argument(
        "--units",
        action="append",
        type=_unit_pair,
        default=[],
        metavar="COLUMN=UNIT",
        help="unit of a column (repeat for several); default: read from column "
        "names like 'displacement [m]', else none",
    )


def _read_frame(path: Path):
    import pandas as pd

    try:
        if path.suffix.lower() == ".csv":
            return pd.read_csv(path)
        return pd.read_parquet(path)
    except (OSError, ImportError) as exc:
        raise _InputError(f"cannot read {path}: {_reason(exc)}") from None
    except ValueError as exc:  # a parser's complaint about the contents
        raise _InputError(f"cannot read {path}: {_one_line(exc)}") from None


def _time_column(frame, requested: str, path: Path) -> str | None:
    if requested == "none":
        return None
    if requested != "auto":
        if requested not in frame.columns:
            raise _InputError(
                f"{path} has no time column {requested!r} (--time-column); its "
                f"columns are {', '.join(map(repr, frame.columns))}."
            )
        return requested
    found = [c for c in frame.columns if _TIME_NAMES.fullmatch(str(c).strip())]
    return found[0] if found else None


def _numbers(frame, column: str, where: str):
    """Finite float values of a column, or an error naming file, column and row."""
    import numpy as np
    import pandas as pd

    raw = frame[column]
    values = pd.to_numeric(raw, errors="coerce").to_numpy(dtype=float)
    bad = np.flatnonzero(~np.isfinite(values))
    if bad.size:
        row = bad[0]
        value = raw.iloc[row]
        shown = "an empty or NaN cell" if pd.isna(value) else repr(str(value))
        raise _InputError(
            f"{where}, column {column!r}: {bad.size} value(s) that are not finite "
            f"numbers, the first {shown} in data row {frame.index[row] + 1}."
            " Remove or fill them first."
        )
    return values


def _sample_step(t, frame, column: str, where: str, split_by: str | None) -> float:
    """The uniform step of sample times ``t``, or an error that says why not."""
    import numpy as np

    steps = np.diff(t)
    if steps.size == 0:
        raise _InputError(f"{where}: one sample only; an experiment needs more.")
    back = np.flatnonzero(steps <= 0)
    if back.size and split_by is None:
        row = back[0] + 1
        hint = (
            "pass --split-by with the column that numbers the experiments"
            if not (groups := _numbering_columns(frame, back, column))
            else f"pass --split-by {groups[0]}"
        )
        raise _InputError(
            f"{where}: time column {column!r} restarts at data row "
            f"{frame.index[row] + 1} (t = {t[row]:g} after {t[row - 1]:g}), so the "
            f"file holds several experiments one after the other; {hint}."
        )
    dt = float(np.median(steps))
    off = np.flatnonzero(np.abs(steps - dt) > _DT_TOLERANCE * dt)
    if dt <= 0 or off.size:
        row = off[0] + 1 if off.size else 1
        raise _InputError(
            f"{where}: the sample times in column {column!r} are not uniform "
            f"(median step {dt:g} s, but {steps[row - 1]:g} s before data row "
            f"{frame.index[row] + 1}); the networks need a constant step: resample "
            "the record, or pass --time-column none and --dt."
        )
    return dt


def _numbering_columns(frame, restarts, time_column: str) -> list[str]:
    """Columns whose value changes exactly where the time restarts."""
    import numpy as np

    found = []
    for c in frame.columns:
        if c == time_column:
            continue
        values = frame[c].to_numpy()
        if np.array_equal(np.flatnonzero(values[1:] != values[:-1]), restarts):
            found.append(c)
    return found


def _read_records(
    files: Sequence[Path],
    columns: Sequence[str],
    split_by: str | None,
    time_column: str = "auto",
) -> _Records:
    """The columns of every experiment in the files, checked, and their dt."""
    records = _Records({c: [] for c in columns})
    for path in files:
        frame = _read_frame(path)
        wanted = [*columns, *([split_by] if split_by else [])]
        missing = [c for c in wanted if c not in frame.columns]
        if missing:
            raise _InputError(
                f"{path} has no column(s) {', '.join(map(repr, missing))}; its "
                f"columns are {', '.join(map(repr, frame.columns))}."
            )
        t_col = _time_column(frame, time_column, path)
        groups = frame.groupby(split_by, sort=True) if split_by else [(None, frame)]
        for key, part in groups:
            where = f"{path}" + (f" ({split_by} = {key})" if split_by else "")
            for c in columns:
                records.columns[c].append(_numbers(part, c, where))
            records.origins.append(where)
            if t_col is None:
                continue
            dt = _sample_step(
                _numbers(part, t_col, where), part, t_col, where, split_by
            )
            if records.dt is None:
                records.dt, records.dt_origin = dt, f"column {t_col!r} of {where}"
            elif abs(dt - records.dt) > _DT_TOLERANCE * records.dt:
                raise _InputError(
                    f"{where} is sampled at dt = {dt:g} s but "
                    f"{records.dt_origin} at {records.dt:g} s; resample to one step."
                )
    return records


def _resolve_dt(
    given: float | None, records: _Records, fallback=None, source: str = "--dt"
) -> float:
    """dt from ``--dt`` (or ``source``) and the files' times, which must agree."""
    found = records.dt
    if given is not None and found is not None:
        if abs(given - found) > _DT_TOLERANCE * found:
            raise _InputError(
                f"{source} {given:g} disagrees with the sample times in "
                f"{records.dt_origin} (dt = {found:g} s); leave --dt out, or pass "
                "--time-column none to ignore the files' times."
            )
        return given
    if given is not None or found is not None:
        return given if given is not None else found
    if fallback is not None:
        return fallback
    raise ValueError(
        f"no time column in {records.origins[0]} to infer the sample spacing "
        "from; give it with --dt (seconds), or name the column with --time-column."
    )


def _units(columns: Sequence[str], given: Sequence[tuple[str, str]]) -> dict:
    """``{column: unit}``: ``--units`` first, then units in the column names."""
    explicit = dict(given)
    unknown = sorted(set(explicit) - set(columns))
    if unknown:
        raise ValueError(
            f"--units names column(s) {', '.join(map(repr, unknown))} that are "
            f"neither input nor output; those are {', '.join(map(repr, columns))}."
        )
    units = {}
    for c in columns:
        match = _UNIT_IN_NAME.fullmatch(c)
        unit = explicit.get(c) or (match.group(1) if match else None)
        if unit:
            units[c] = unit
    return units


def _check_columns(
    inputs: Sequence[str], outputs: Sequence[str], split_by: str | None
) -> None:
    """Each column plays one role: input, output or experiment number."""
    roles = [("--input", c) for c in inputs] + [("--output", c) for c in outputs]
    if split_by:
        roles.append(("--split-by", split_by))
    seen: dict[str, str] = {}
    for option, column in roles:
        if column in seen:
            same = "twice" if seen[column] == option else f"and {seen[column]}"
            raise ValueError(
                f"column {column!r} is given as {option} {same}; each column can "
                "be one input, one output or the experiment number, not more."
            )
        seen[column] = option


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
        "closing line scores the model on held-out records.",
    ),
    "validate": (
        "residual tests, error statistics and figures of a saved model",
        "Run a model saved by `sysid-nn fit` on validation records: "
        "one-step prediction and free-run simulation, residual tests, "
        "eq. 19-20 statistics, figures and report.md in --out; the "
        "scores of every output are printed under its column name.",
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


# ---------------------------------------------------------------- generate
def _add_generate(sub: argparse._SubParsersAction) -> None:
    p = _command(sub, "generate", _run_generate)
    p.add_argument(
        "--n-realizations", type=_positive_int, default=25, metavar="N", help="records"
    )
    p.add_argument(
        "--n-samples", type=_positive_int, default=2000, metavar="N", help="per record"
    )
    p.add_argument("--dt", type=_positive_float, default=0.01, help="sample spacing, s")
    p.add_argument("--seed", type=_seed, default=0, help="random seed")
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
    p.add_argument(
        "--overwrite", action="store_true", help="replace an existing --out file"
    )


def _run_generate(args: argparse.Namespace) -> int:
    # Imported here so that `sysid-nn --help` does not load numba.
    from sysid_nn import HystereticOscillator

    _check_output(args.out, "--out", overwrite=args.overwrite)
    osc = HystereticOscillator(r0="calibrate" if args.r0 is None else args.r0)
    rec = osc.generate(
        args.n_realizations,
        n_samples=args.n_samples,
        dt=args.dt,
        random_state=args.seed,
        as_frame=True,
    )
    if args.out.suffix.lower() == ".csv":
        _write_atomic(args.out, lambda tmp: rec.frame.to_csv(tmp, index=False))
    else:
        _write_atomic(args.out, lambda tmp: rec.frame.to_parquet(tmp, index=False))
    print(
        f"wrote {args.n_realizations} realisation(s) x {args.n_samples} samples "
        f"(dt={args.dt:g} s, r0={rec.r0:.6g}) to {args.out}"
    )
    return 0


# --------------------------------------------------------------- reproduce
# StudyConfig names its fields in errors; the user typed these options.
_OPTION_OF_FIELD = {
    "n_test": "--n-test",
    "n_train": "--training-records",
    "seed": "--seed",
    "n_jobs": "--n-jobs",
}


def _add_reproduce(sub: argparse._SubParsersAction) -> None:
    p = _command(sub, "reproduce", _run_reproduce)
    p.add_argument(
        "--out",
        type=Path,
        default=Path("sysid_nn_results"),
        metavar="DIR",
        help="output directory",
    )
    p.add_argument(
        "--quick",
        action="store_true",
        help="CI-sized run (under a minute): 5 test realisations, one restart "
        "per network",
    )
    p.add_argument(
        "--n-test",
        type=int,
        default=None,
        metavar="N",
        help="unseen test realisations (default: 25, or 5 with --quick)",
    )
    p.add_argument("--seed", type=int, default=0, help="master seed")
    p.add_argument(
        "--training-records",
        type=int,
        default=1,
        metavar="K",
        dest="n_train",
        help="training records of typical amplitude",
    )
    _add_parallel(p)
    p.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help="dask.distributed scheduler to run on (needs the 'distributed' "
        "extra; default: local joblib)",
    )
    _add_output_flags(p, "--out directory")


def _study_config(args: argparse.Namespace):
    from sysid_nn.study import StudyConfig

    try:
        return StudyConfig(
            seed=args.seed,
            n_train=args.n_train,
            n_test=args.n_test,
            quick=args.quick,
            n_jobs=args.n_jobs,
        )
    except ValueError as exc:
        message = str(exc)
        name = message.split(" ", 1)[0]
        if name in _OPTION_OF_FIELD:
            message = _OPTION_OF_FIELD[name] + message[len(name) :]
        raise ValueError(message) from None


def _run_reproduce(args: argparse.Namespace) -> int:
    from sysid_nn.study import run_study

    config = _study_config(args)
    _check_output(args.out, "--out", overwrite=args.overwrite, directory=True)
    start = time.perf_counter()
    study = run_study(
        config,
        args.out,
        overwrite=args.overwrite,
        scheduler=args.scheduler,
        progress=not args.quiet,
    )
    if not args.quiet:
        _print_study_summary(study.summary)
        print(
            f"wrote {args.out}/report.md, results.csv, summary.csv and figures "
            f"in {time.perf_counter() - start:.0f} s"
        )
    return 0


def _print_study_summary(summary) -> None:
    table = summary.pivot_table(
        index="label", columns="mode", values="nrmse_median", sort=False
    )
    table.columns = [f"{mode} NRMSE (median)" for mode in table.columns]
    print(table.to_string(float_format=lambda v: f"{v:.4g}"))


# ------------------------------------------------------------ fit, validate
_MODELS = ("tdl", "issm")


def _add_fit(sub: argparse._SubParsersAction) -> None:
    p = _command(sub, "fit", _run_fit)
    _data_arguments(p)
    p.add_argument(
        "--input",
        action="append",
        required=True,
        metavar="COLUMN",
        help="excitation column (repeat for several)",
    )
    p.add_argument(
        "--output",
        action="append",
        required=True,
        metavar="COLUMN",
        help="response column (repeat for several)",
    )
    p.add_argument(
        "--model",
        choices=_MODELS,
        default="tdl",
        help="network; prefer issm for measured, noisy records: 0.01 %% output "
        "noise already costs the tdl its gain over linear",
    )
    p.add_argument(
        "--dt",
        type=_positive_float,
        default=None,
        help="sample spacing, s (default: inferred from the files' time column; "
        "required without one)",
    )
    p.add_argument(
        "--hidden",
        type=_hidden,
        default=None,
        metavar="SIZES",
        help="hidden layer sizes, e.g. 9 or 9,9; 0 for the linear model "
        "(default for this and the options below: the estimator's own, see "
        "TDLRegressor and ISSMRegressor)",
    )
    for option, about in (
        ("--output-lags", "past outputs fed back (tdl)"),
        ("--input-lags", "past inputs seen (tdl)"),
        ("--n-states", "states, at least one per output (issm)"),
        ("--n-init", "random restarts, the best kept"),
        ("--max-iter", "iterations per training stage"),
    ):
        p.add_argument(
            option, type=_positive_int, default=None, metavar="N", help=about
        )
    p.add_argument(
        "--focus",
        choices=("simulation", "prediction"),
        default=None,
        help="free-run or one-step errors minimised",
    )
    p.add_argument("--seed", type=_seed, default=0, help="random seed")
    _add_parallel(p)
    p.add_argument(
        "--val",
        action="append",
        type=_frame_path,
        default=None,
        metavar="FILE",
        help=(
            "validation records: select the weights and are scored at the end "
            "(repeat for several); default: the last experiment is held out, or "
            "with a single one the last share of it (the estimator's "
            "validation_fraction)"
        ),
    )
    p.add_argument("--save", type=Path, required=True, metavar="FILE", help="model")
    _add_output_flags(p, "--save file")
    p.add_argument(
        "--verbose",
        action="store_true",
        help="one line per restart and training stage with its losses, also on "
        "a terminal (default: a progress bar there, these lines elsewhere)",
    )


def _estimator(args: argparse.Namespace):
    """The estimator the options describe, and the options it was given."""
    from sysid_nn import ISSMRegressor, TDLRegressor

    options = {
        "hidden_layer_sizes": args.hidden,
        "focus": args.focus,
        "n_init": args.n_init,
        "max_iter": args.max_iter,
    }
    if args.model == "tdl":
        cls = TDLRegressor
        options |= {"output_lags": args.output_lags, "input_lags": args.input_lags}
        wrong = (("--n-states", args.n_states),)
    else:
        cls = ISSMRegressor
        options |= {"n_states": args.n_states}
        wrong = ("--output-lags", args.output_lags), ("--input-lags", args.input_lags)
    for flag, value in wrong:
        if value is not None:
            raise ValueError(
                f"{flag} does not apply to --model {args.model}; leave it out."
            )
    params = {k: v for k, v in options.items() if v is not None}
    verbose = 0 if args.quiet else 2 if args.verbose else 1
    estimator = cls(**params, random_state=args.seed, n_jobs=args.n_jobs)
    return estimator.set_params(verbose=verbose), params


def _holdout(records: _Records, val: _Records | None):
    """Training and held-out experiment indices; None: the estimator's tail."""
    n = len(records.origins)
    if val is not None or n == 1:
        return list(range(n)), None
    return list(range(n - 1)), [n - 1]


def _scores(estimator, X, y, *, tail: float | None = None) -> dict:
    """Pooled NRMSE and RMSE per output, one-step and free run.

    ``tail`` scores only that last share of each record (the free run still
    starts from rest at its beginning).
    """
    import numpy as np

    from sysid_nn.metrics import nrmse

    scores = {}
    for mode in ("prediction", "simulation"):
        y_hat = [
            estimator.predict(x, y_k) if mode == "prediction" else estimator.simulate(x)
            for x, y_k in zip(X, y, strict=True)
        ]
        true, pred = list(y), y_hat
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


def _run_fit(args: argparse.Namespace) -> int:
    import joblib
    from sklearn.utils import Bunch

    from sysid_nn import __version__
    from sysid_nn.study import StudyModel

    inputs, outputs = tuple(args.input), tuple(args.output)
    _check_columns(inputs, outputs, args.split_by)
    units = _units([*inputs, *outputs], args.units)
    estimator, params = _estimator(args)
    sources = [*args.files, *(args.val or [])]
    _check_output(args.save, "--save", overwrite=args.overwrite, inputs=sources)
    read = (args.split_by, args.time_column)
    records = _read_records(args.files, [*inputs, *outputs], *read)
    val = _read_records(args.val, [*inputs, *outputs], *read) if args.val else None
    dt = _resolve_dt(args.dt, records)
    if val is not None:
        _resolve_dt(dt, val, source="the training files' dt")
    label = f"{args.model.upper()} ({', '.join(f'{k}={v}' for k, v in params.items())})"
    model = StudyModel(
        label if params else args.model.upper(), estimator, inputs, outputs
    )
    X, y = model.arrays(records.columns)
    train, held = _holdout(records, val)
    if val is not None:
        X_val, y_val = model.arrays(val.columns)
        held_names = val.origins
    elif held is not None:
        X_val, y_val = [X[j] for j in held], [y[j] for j in held]
        held_names = [records.origins[j] for j in held]
    else:
        X_val = y_val = None
    X_fit, y_fit = [X[j] for j in train], [y[j] for j in train]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        _fit(estimator, X_fit, y_fit, X_val, y_val, sources, inputs, outputs)
        if X_val is not None:
            scores = _scores(estimator, X_val, y_val)
            where = f"{len(X_val)} held-out experiment(s) ({', '.join(held_names)})"
        elif estimator.best_validation_score_ is not None:
            share = estimator.get_params()["validation_fraction"]
            scores = _scores(estimator, X, y, tail=share)
            where = (
                f"the held-out last {share:.0%} of {records.origins[0]} (free run "
                "from the record's start)"
            )
        else:  # too short to hold anything out: say so, score what there is
            scores = _scores(estimator, X, y)
            where = "nothing (the record is too short to hold a part out)"
    # One line per distinct warning, not Python's two-line source excerpt.
    for message in dict.fromkeys(str(w.message).splitlines()[0] for w in caught):
        print(f"{_PROG}: warning: {message}", file=sys.stderr)
    bundle = Bunch(
        model=model,
        dt=dt,
        units=units,
        files=[str(f) for f in args.files],
        split_by=args.split_by,
        sysid_nn_version=__version__,
    )

    def dump(tmp: Path) -> None:
        with open(tmp, "wb") as f:
            joblib.dump(bundle, f)

    _write_atomic(args.save, dump)
    print(
        f"fitted {model.label} in {estimator.fit_time_:.1f} s: trained on "
        f"{len(X_fit)} experiment(s), validated on {where} (dt = {dt:g} s); "
        f"saved to {args.save}. "
        + (
            "Held-out scores:"
            if estimator.best_validation_score_ is not None
            else "Scores on the training data:"
        )
    )
    print("\n".join(_score_lines(scores, outputs, units)))
    return 0


def _fit(estimator, X, y, X_val, y_val, files, inputs, outputs) -> None:
    """``estimator.fit``; an error about the data names the files and columns."""
    try:
        estimator.fit(X, y, X_val=X_val, y_val=y_val)
    except ValueError as exc:
        # Errors about a parameter start with its name: bad arguments (exit 2).
        first = re.split(r"\W", str(exc), maxsplit=1)[0]
        if isinstance(exc, TypeError) or first in estimator.get_params():
            raise
        raise _InputError(
            f"cannot fit to {', '.join(map(str, files))}"
            f" (inputs {', '.join(map(repr, inputs))}, outputs "
            f"{', '.join(map(repr, outputs))}): {_one_line(exc)}"
        ) from None


def _add_validate(sub: argparse._SubParsersAction) -> None:
    p = _command(sub, "validate", _run_validate)
    p.add_argument(
        "--model",
        type=Path,
        required=True,
        metavar="FILE",
        help="model saved by `sysid-nn fit --save`",
    )
    _data_arguments(p)
    p.add_argument("--out", type=Path, required=True, metavar="DIR", help="directory")
    p.add_argument(
        "--dt",
        type=_positive_float,
        default=None,
        help="sample spacing, s (default: inferred from the files' time column, "
        "else the one the model was fitted at)",
    )
    p.add_argument(
        "--max-lag",
        type=_positive_int,
        default=25,
        metavar="M",
        help="largest lag of the residual tests; at most (shortest record - 10) / 2",
    )
    p.add_argument(
        "--band",
        type=_band_level,
        default=None,
        metavar="LEVEL",
        help="also draw each record's free run with its prediction band at this "
        "level (e.g. 0.95) and report the share of samples inside it "
        "(band.csv, band_<k>.png in --out)",
    )
    _add_parallel(p)
    _add_output_flags(p, "--out directory")


_band_level = _bounded(
    float, lambda v: 0 < v < 1, "a level between 0 and 1 (e.g. 0.95)"
)


def _write_bands(model, records, out: Path, dt: float, level: float) -> float:
    """Free runs with their prediction bands: figures, band.csv, pooled coverage."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    import pandas as pd

    from sysid_nn.plotting import plot_band
    from sysid_nn.uncertainty import interval_coverage, normal_interval

    X, y = model.arrays(records)
    mean, std = model.estimator.simulate(X, return_std=True)
    rows, bounds = [], []
    for k, (yk, mk, sk) in enumerate(zip(y, mean, std, strict=True)):
        yk, mk, sk = (np.reshape(a, (len(a), -1)) for a in (yk, mk, sk))
        lower, upper = normal_interval(mk, sk, level)
        bounds.append((yk, lower, upper))
        rows.append({"record": k, "coverage": interval_coverage(yk, lower, upper)})
        t = dt * np.arange(len(yk))
        ax = plot_band(t, mk[:, 0], sk[:, 0], level=level, label="simulated")
        ax.plot(t, yk[:, 0], "k-", linewidth=0.6, label="measured")
        ax.set_xlabel("time [s]")
        ax.set_ylabel(model.outputs[0])
        ax.legend()
        ax.figure.savefig(out / f"band_{k}.png", dpi=90)
        plt.close(ax.figure)
    pd.DataFrame(rows).to_csv(out / "band.csv", index=False)
    return interval_coverage(*(list(b) for b in zip(*bounds, strict=True)))


def _load_model(path: Path):
    import joblib

    from sysid_nn._exceptions import check_version

    try:
        bundle = joblib.load(path)
    except OSError as exc:
        raise _InputError(f"cannot read {path}: {_reason(exc)}") from None
    except Exception as exc:  # unpickling garbage raises anything
        raise _InputError(f"cannot read {path} as a saved model: {exc}") from None
    if not (hasattr(bundle, "get") and bundle.get("model") is not None):
        raise _InputError(f"{path} was not written by `sysid-nn fit --save`.")
    check_version(bundle.get("sysid_nn_version"), f"the model in {path}")
    return bundle


def _check_max_lag(max_lag: int, records: _Records) -> None:
    # The residual tests need the lags and as many samples again, plus a margin.
    lengths = records.lengths()
    shortest = min(range(len(lengths)), key=lengths.__getitem__)
    if lengths[shortest] < 2 * max_lag + 10:
        raise ValueError(
            f"--max-lag {max_lag} needs records of at least {2 * max_lag + 10} "
            f"samples, but {records.origins[shortest]} has {lengths[shortest]}; "
            f"use --max-lag {max(1, (lengths[shortest] - 10) // 2)} or less."
        )


def _run_validate(args: argparse.Namespace) -> int:
    from sysid_nn.study import run_validation

    bundle = _load_model(args.model)
    model = bundle.model
    sources = [args.model, *args.files]
    _check_output(
        args.out, "--out", overwrite=args.overwrite, inputs=sources, directory=True
    )
    records = _read_records(
        args.files,
        [*model.inputs, *model.outputs],
        args.split_by,
        args.time_column,
    )
    dt = _resolve_dt(args.dt, records, fallback=bundle.dt)
    if abs(dt - bundle.dt) > _DT_TOLERANCE * bundle.dt:
        raise _InputError(
            f"{records.dt_origin or '--dt'} gives dt = {dt:g} s, but {args.model} "
            f"was fitted at dt = {bundle.dt:g} s; a model only applies at the "
            "step it was identified at: resample the records."
        )
    _check_max_lag(args.max_lag, records)
    units = bundle.get("units", {}) | _units(
        [*model.inputs, *model.outputs], args.units
    )
    result = run_validation(
        model,
        records.columns,
        args.out,
        dt=dt,
        overwrite=args.overwrite,
        max_lag=args.max_lag,
        n_jobs=args.n_jobs,
        units=units,
        setup=[
            f"Model: {args.model}, fitted on {', '.join(bundle.files)}.",
            f"Validation data: {', '.join(map(str, args.files))}"
            + (f", split by {args.split_by!r}." if args.split_by else "."),
        ],
        progress=not args.quiet,
    )
    if not args.quiet:
        X, y = model.arrays(records.columns)
        print(
            f"{model.label} on {len(X)} experiment(s) at dt = {dt:g} s "
            "(NRMSE pooled over the experiments):"
        )
        print(
            "\n".join(
                _score_lines(_scores(model.estimator, X, y), model.outputs, units)
            )
        )
        print(f"wrote {result.out_dir}/report.md, results.csv, summary.csv and figures")
    if args.band is not None:
        coverage = _write_bands(model, records.columns, result.out_dir, dt, args.band)
        if not args.quiet:
            print(
                f"{100 * args.band:g} % prediction band of the free run covers "
                f"{100 * coverage:.1f} % of the samples (band.csv, band_<k>.png)"
            )
    return 0


# -------------------------------------------------------------------- main
_COMMANDS: tuple[Callable[[argparse._SubParsersAction], None], ...] = (
    _add_generate,
    _add_reproduce,
    _add_fit,
    _add_validate,
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


def _fail(message: BaseException | str) -> int:
    print(f"{_PROG}: error: {_one_line(message)}", file=sys.stderr)
    return 1


def _one_line(message: BaseException | str) -> str:
    return re.sub(r"\s+", " ", str(message)).strip()
