"""Reading the user's records: files, columns, sample times and units."""

from __future__ import annotations

import argparse
import csv
import re
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from sysid_nn.cli._common import _InputError, _one_line, _reason

_FRAME_SUFFIXES = (".csv", ".parquet")
#: Sample times may jitter by this share of the step (printed, rounded times).
_DT_TOLERANCE = 0.01
#: Column names taken as the time axis (in seconds) unless --time-column says.
_TIME_NAMES = re.compile(
    r"(t|time)(_s|_sec|\s*\[\s*s\s*\]|\s*\(\s*s\s*\))?", flags=re.IGNORECASE
)
#: ``name [unit]`` or ``name (unit)``: units read from column names.
_UNIT_IN_NAME = re.compile(r".*?[\[(]\s*([^\])]+?)\s*[\])]\s*")


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
        "--sep",
        default="auto",
        metavar="CHAR",
        help="field separator of .csv files; 'auto' takes the one of ',', ';' "
        "and tab found most often in the header line",
    )
    p.add_argument(
        "--decimal",
        default="auto",
        metavar="CHAR",
        help="decimal mark of .csv files; 'auto' is ',' in files separated by "
        "';' or tabs whose numbers hold commas (e.g. 0,25), else '.'",
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


_SEPARATORS = (",", ";", "\t")
#: A number written with a decimal comma, e.g. ``-0,25`` or ``3,1e-4``.
_DECIMAL_COMMA = re.compile(r"[-+]?\d+,\d+([eE][-+]?\d+)?")


def _csv_format(path: Path, sep: str, decimal: str) -> tuple[str, str, list[str]]:
    """Separator and decimal mark of a CSV file (``auto``: sniffed) and its header.

    Lab exports often separate by ``;`` and write decimal commas; the header
    line and the first data line tell.
    """
    try:
        with open(path, newline="", encoding="utf-8-sig") as f:
            lines = [f.readline(), f.readline()]
    except (OSError, UnicodeDecodeError) as exc:
        raise _InputError(f"cannot read {path}: {_reason(exc)}") from None
    header, first = (line.rstrip("\r\n") for line in lines)
    if sep == "auto":
        counts = [header.count(c) for c in _SEPARATORS]
        sep = _SEPARATORS[counts.index(max(counts))] if max(counts) else ","
    if decimal == "auto":
        cells = first.split(sep)
        comma = sep != "," and any(_DECIMAL_COMMA.fullmatch(c.strip()) for c in cells)
        decimal = "," if comma else "."
    if sep == decimal:
        raise _InputError(
            f"cannot read {path}: the separator and the decimal mark are both "
            f"{sep!r}; give them with --sep and --decimal."
        )
    names = next(csv.reader([header], delimiter=sep)) if header else []
    return sep, decimal, [n.strip() for n in names]


def _read_frame(path: Path, sep: str = "auto", decimal: str = "auto"):
    import pandas as pd

    try:
        if path.suffix.lower() == ".csv":
            sep, decimal, names = _csv_format(path, sep, decimal)
            twice = sorted({n for n in names if names.count(n) > 1})
            if twice:
                raise _InputError(
                    f"{path} names column(s) {', '.join(map(repr, twice))} more "
                    "than once in its header; rename them so that each column "
                    "has its own name."
                )
            frame = pd.read_csv(path, sep=sep, decimal=decimal)
            frame.attrs["csv_format"] = (sep, decimal)
            return frame
        return pd.read_parquet(path)
    except (OSError, ImportError) as exc:
        raise _InputError(f"cannot read {path}: {_reason(exc)}") from None
    except ValueError as exc:  # a parser's complaint about the contents
        raise _InputError(
            f"cannot read {path}: {_one_line(exc)} (a .csv file separated by "
            "';' or tabs, or with decimal commas, is read with --sep and "
            "--decimal)"
        ) from None


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


def _numbers(frame, column: str, where: str, *, time: bool = False):
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
            f"numbers, the first {shown} in data row {frame.index[row] + 1}. "
            + _cell_advice(frame, raw, column, time=time)
        )
    return values


def _cell_advice(frame, raw, column: str, *, time: bool) -> str:
    """How to read a column whose cells are not numbers."""
    import numpy as np
    import pandas as pd

    text = raw.dropna().astype(str).str.strip()
    if time and len(text) > 1:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # format guessing
            stamps = pd.to_datetime(text, errors="coerce")
        if stamps.notna().all():
            steps = np.diff(stamps.to_numpy()).astype("timedelta64[ns]")
            dt = np.median(steps.astype(np.float64)) / 1e9
            return (
                f"The column holds dates and times, not seconds: pass "
                f"--time-column none --dt {dt:g} (the step in seconds)."
            )
    sep, decimal = frame.attrs.get("csv_format", (None, None))
    if decimal == "." and text.str.fullmatch(_DECIMAL_COMMA.pattern).any():
        return "The numbers look like decimal commas: pass --decimal ','."
    if any(c in str(column) for c in _SEPARATORS if c != sep) and sep is not None:
        return "The file looks separated by another character: pass --sep."
    return "Remove or fill them first."


def _sample_step(t, frame, column: str, where: str, split_by: str | None) -> float:
    """The uniform step of sample times ``t``, or an error that says why not."""
    import numpy as np

    steps = np.diff(t)
    if steps.size == 0:
        raise _InputError(f"{where}: one sample only; an experiment needs more.")
    back = np.flatnonzero(steps <= 0)
    if back.size > steps.size // 2:  # mostly backwards: not several experiments
        raise _InputError(
            f"{where}: time column {column!r} runs backwards (t = {t[1]:g} after "
            f"{t[0]:g} in the first data rows); sort the file by time, or pass "
            "--time-column none and --dt if the rows are in time order."
        )
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
    sep: str = "auto",
    decimal: str = "auto",
) -> _Records:
    """The columns of every experiment in the files, checked, and their dt."""
    records = _Records({c: [] for c in columns})
    for path in files:
        frame = _read_frame(path, sep, decimal)
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
            part.attrs.update(frame.attrs)  # the CSV format, for advice
            where = f"{path}" + (f" ({split_by} = {key})" if split_by else "")
            for c in columns:
                records.columns[c].append(_numbers(part, c, where))
            records.origins.append(where)
            if t_col is None:
                continue
            t = _numbers(part, t_col, where, time=True)
            dt = _sample_step(t, part, t_col, where, split_by)
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


def _check_columns_vary(
    records: _Records, inputs: Sequence[str], outputs: Sequence[str]
) -> None:
    """Refuse a column that holds one value in every experiment.

    An input that never changes excites nothing; an output that never
    changes has no response to model (and standardising it divides by 0).
    """
    import numpy as np

    roles = [(c, "input", "excitation") for c in inputs]
    roles += [(c, "output", "response") for c in outputs]
    for column, role, meaning in roles:
        values = np.concatenate(records.columns[column])
        if values.size and np.all(values == values[0]):
            what = (
                "the model cannot learn the response to an input that never changes"
                if role == "input"
                else "there is no response to model"
            )
            raise _InputError(
                f"{role} column {column!r} holds the single value {values[0]:g} in "
                f"every experiment ({', '.join(records.origins)}): {what}; "
                f"check that --{role} names the {meaning} column."
            )
