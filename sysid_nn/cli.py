"""The ``sysid-nn`` command: a thin shell over the public API.

One sub-command per task, each built by an ``_add_<command>`` function and
run by a ``_run_<command>(args) -> int`` function, so new commands plug in
without touching the others::

    sysid-nn generate --n-realizations 5 --out sysid_nn_records.csv
    sysid-nn reproduce --quick --out sysid_nn_results
    sysid-nn fit records.csv --input excitation --output displacement \\
        --split-by realization --save model.joblib
    sysid-nn validate --model model.joblib new_records.csv --out validation

Exit status: 0 on success, 2 for bad arguments (argparse's usage message for
syntax, one ``sysid-nn: error: ...`` line for values that parse but make no
sense), 1 when input cannot be read or output cannot be written, 130 when
interrupted. Errors are one line, never a traceback.
"""

from __future__ import annotations

import argparse
import re
import sys
import time
import warnings
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


# -------------------------------------------------------------------- reproduce
# StudyConfig names its fields in errors; the user typed these options.
_OPTION_OF_FIELD = {
    "n_test": "--n-test",
    "n_train": "--training-records",
    "seed": "--seed",
    "n_jobs": "--n-jobs",
}


def _add_reproduce(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "reproduce",
        help="run the paper's section-4 study and write figures, tables, report",
        description=(
            "Generate seeded training, validation and test records of the "
            "hysteretic oscillator, fit the paper's TDL and ISSM networks, the "
            "linear baseline and the toolbox's defaults, evaluate one-step "
            "prediction and free-run simulation on unseen realisations and "
            "write figs 4.1-4.7, a hysteresis plot, results.csv, summary.csv "
            "and report.md into --out."
        ),
    )
    p.add_argument(
        "--out",
        type=Path,
        default=Path("sysid_nn_results"),
        metavar="DIR",
        help="output directory (default: sysid_nn_results)",
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
    p.add_argument("--seed", type=int, default=0, help="master seed (default: 0)")
    p.add_argument(
        "--training-records",
        type=int,
        default=1,
        metavar="K",
        dest="n_train",
        help="training records of typical amplitude (default: 1)",
    )
    _add_parallel(p)
    p.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help="dask.distributed scheduler to run on (needs the 'distributed' extra)",
    )
    _add_output_flags(p)
    p.set_defaults(func=_run_reproduce)


def _add_output_flags(p: argparse.ArgumentParser) -> None:
    p.add_argument("--overwrite", action="store_true", help="replace an existing --out")
    p.add_argument("--quiet", action="store_true", help="no progress bars or summary")


def _add_parallel(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--n-jobs",
        type=int,
        default=None,
        metavar="N",
        help="parallel jobs (joblib: -1 = all cores; default: serial)",
    )


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
        field = message.split(" ", 1)[0]
        if field in _OPTION_OF_FIELD:
            message = _OPTION_OF_FIELD[field] + message[len(field) :]
        raise ValueError(message) from None


def _run_reproduce(args: argparse.Namespace) -> int:
    from sysid_nn.study import run_study

    config = _study_config(args)
    start = time.perf_counter()
    study = run_study(
        config,
        args.out,
        overwrite=args.overwrite,
        scheduler=args.scheduler,
        progress=not args.quiet,
    )
    if not args.quiet:
        _print_summary(study.summary)
        print(
            f"wrote {args.out}/report.md, results.csv, summary.csv and figures "
            f"in {time.perf_counter() - start:.0f} s"
        )
    return 0


def _print_summary(summary) -> None:
    table = summary.pivot_table(
        index="label", columns="mode", values="nrmse_median", sort=False
    )
    table.columns = [f"{mode} NRMSE (median)" for mode in table.columns]
    print(table.to_string(float_format=lambda v: f"{v:.4g}"))


# ---------------------------------------------------------------- fit, validate
_MODELS = ("tdl", "issm")


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
        "as written by `sysid-nn generate`)",
    )


def _add_fit(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "fit",
        help="fit a TDL or ISSM network to measured records and save it",
        description=(
            "Fit a recurrent network to your own records: named excitation "
            "(--input) and response (--output) columns of CSV or parquet "
            "files, one experiment per file (or per --split-by group). The "
            "fitted model is saved with joblib for `sysid-nn validate`."
        ),
    )
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
        help="response column (repeat for several; the first is scored)",
    )
    p.add_argument(
        "--model",
        choices=_MODELS,
        default="tdl",
        help="network (default tdl; prefer issm for measured, noisy records: "
        "0.01 %% output noise already costs the tdl its gain over linear)",
    )
    p.add_argument("--dt", type=_positive_float, default=0.01, help="sample spacing, s")
    p.add_argument(
        "--hidden",
        type=_hidden,
        default=None,
        metavar="SIZES",
        help="hidden layer sizes, e.g. 9 or 9,9; 0 for the linear model",
    )
    p.add_argument("--output-lags", type=_positive_int, default=None, metavar="N")
    p.add_argument("--input-lags", type=_positive_int, default=None, metavar="N")
    p.add_argument("--n-states", type=_positive_int, default=None, metavar="N")
    p.add_argument("--focus", choices=("simulation", "prediction"), default=None)
    p.add_argument("--n-init", type=_positive_int, default=None, metavar="N")
    p.add_argument("--max-iter", type=_positive_int, default=None, metavar="N")
    p.add_argument("--seed", type=_seed, default=0, help="random seed (default: 0)")
    _add_parallel(p)
    p.add_argument(
        "--val",
        action="append",
        type=Path,
        default=None,
        metavar="FILE",
        help=(
            "validation records for selecting the weights (repeat for several); "
            "without them the last file, or the tail of a single one, is held out"
        ),
    )
    p.add_argument("--save", type=Path, required=True, metavar="FILE")
    p.set_defaults(func=_run_fit)


def _read_records(
    files: Sequence[Path], columns: Sequence[str], split_by: str | None
) -> dict[str, list]:
    """``{column: [one array per experiment]}`` from the files."""
    import pandas as pd

    records: dict[str, list] = {c: [] for c in columns}
    for path in files:
        try:
            if path.suffix.lower() == ".csv":
                frame = pd.read_csv(path)
            else:
                frame = pd.read_parquet(path)
        except (OSError, ImportError) as exc:
            raise _ReadError(f"cannot read {path}: {_reason(exc)}") from None
        wanted = [*columns, *([split_by] if split_by else [])]
        missing = [c for c in wanted if c not in frame.columns]
        if missing:
            raise ValueError(
                f"{path} has no column(s) {', '.join(map(repr, missing))}; its "
                f"columns are {', '.join(map(repr, frame.columns))}."
            )
        groups = frame.groupby(split_by, sort=True) if split_by else [(None, frame)]
        for _, part in groups:
            for c in columns:
                records[c].append(part[c].to_numpy(dtype=float))
    return records


class _ReadError(Exception):
    """Input that cannot be read: exit status 1."""


def _reason(exc: BaseException) -> str:
    return getattr(exc, "strerror", None) or str(exc)


def _run_fit(args: argparse.Namespace) -> int:
    import joblib
    from sklearn.utils import Bunch

    from sysid_nn import ISSMRegressor, TDLRegressor, __version__
    from sysid_nn.study import StudyModel

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
    estimator = cls(**params, random_state=args.seed, n_jobs=args.n_jobs)
    inputs, outputs = tuple(args.input), tuple(args.output)
    records = _read_records(args.files, [*inputs, *outputs], args.split_by)
    label = f"{args.model.upper()} ({', '.join(f'{k}={v}' for k, v in params.items())})"
    model = StudyModel(
        label if params else args.model.upper(), estimator, inputs, outputs
    )
    X, y = model.arrays(records)
    validation = {}
    if args.val:
        X_val, y_val = model.arrays(
            _read_records(args.val, [*inputs, *outputs], args.split_by)
        )
        validation = {"X_val": X_val, "y_val": y_val}
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        estimator.fit(X, y, **validation)
        score = estimator.score(X, y)
    # One line per distinct warning, not Python's two-line source excerpt.
    for message in dict.fromkeys(str(w.message).splitlines()[0] for w in caught):
        print(f"{_PROG}: warning: {message}", file=sys.stderr)
    bundle = Bunch(
        model=model,
        dt=args.dt,
        files=[str(f) for f in args.files],
        split_by=args.split_by,
        sysid_nn_version=__version__,
    )
    try:
        joblib.dump(bundle, args.save)
    except OSError as exc:
        return _fail(f"cannot write {args.save}: {_reason(exc)}")
    print(
        f"fitted {model.label} on {len(X)} experiment(s) in "
        f"{estimator.fit_time_:.1f} s; free-run R^2 on them "
        f"{score:.4f}; saved to {args.save}"
    )
    return 0


def _add_validate(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "validate",
        help="residual tests, error statistics and figures of a saved model",
        description=(
            "Run a model saved by `sysid-nn fit` on validation records: "
            "one-step prediction and free-run simulation, residual tests, "
            "eq. 19-20 statistics, figures and report.md in --out."
        ),
    )
    p.add_argument(
        "--model",
        type=Path,
        required=True,
        metavar="FILE",
        help="model saved by `sysid-nn fit --save`",
    )
    _data_arguments(p)
    p.add_argument("--out", type=Path, required=True, metavar="DIR")
    p.add_argument(
        "--dt",
        type=_positive_float,
        default=None,
        help="sample spacing, s (default: the one given to fit)",
    )
    p.add_argument("--max-lag", type=_positive_int, default=25, metavar="M")
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
    _add_output_flags(p)
    p.set_defaults(func=_run_validate)


def _band_level(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not 0.0 < value < 1.0:
        raise argparse.ArgumentTypeError(
            f"expected a level between 0 and 1 (e.g. 0.95), got {text!r}"
        )
    return value


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

    try:
        bundle = joblib.load(path)
    except OSError as exc:
        raise _ReadError(f"cannot read {path}: {_reason(exc)}") from None
    except Exception as exc:  # unpickling garbage raises anything
        raise _ReadError(f"cannot read {path} as a saved model: {exc}") from None
    if not (hasattr(bundle, "get") and bundle.get("model") is not None):
        raise _ReadError(f"{path} was not written by `sysid-nn fit --save`.")
    return bundle


def _run_validate(args: argparse.Namespace) -> int:
    from sysid_nn.study import run_validation

    bundle = _load_model(args.model)
    model = bundle.model
    records = _read_records(args.files, [*model.inputs, *model.outputs], args.split_by)
    dt = args.dt if args.dt is not None else bundle.dt
    result = run_validation(
        model,
        records,
        args.out,
        dt=dt,
        overwrite=args.overwrite,
        max_lag=args.max_lag,
        n_jobs=args.n_jobs,
        setup=[
            f"Model: {args.model}, fitted on {', '.join(bundle.files)}.",
            f"Validation data: {', '.join(map(str, args.files))}"
            + (f", split by {args.split_by!r}." if args.split_by else "."),
        ],
        progress=not args.quiet,
    )
    if not args.quiet:
        _print_summary(result.summary)
        print(f"wrote {args.out}/report.md, results.csv, summary.csv and figures")
    if args.band is not None:
        coverage = _write_bands(model, records, args.out, dt, args.band)
        if not args.quiet:
            print(
                f"{100 * args.band:g} % prediction band of the free run covers "
                f"{100 * coverage:.1f} % of the samples (band.csv, band_<k>.png)"
            )
    return 0


# ------------------------------------------------------------------------ main
_COMMANDS: tuple[Callable[[argparse._SubParsersAction], None], ...] = (
    _add_generate,
    _add_reproduce,
    _add_fit,
    _add_validate,
)


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
        Exit status: 0 on success, 1 when input cannot be read or output
        cannot be written (or exists, without ``--overwrite``), 2 for bad
        arguments (argparse exits with status 2 itself for syntax errors),
        130 when interrupted.

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
        print(f"{_PROG}: error: {_one_line(exc)}", file=sys.stderr)
        return 2
    except FileExistsError as exc:
        if exc.filename is None:  # the study's refusal to replace --out
            return _fail(
                f"{args.out} exists; pass --overwrite to replace it, or choose "
                "another --out."
            )
        return _fail(f"cannot write {exc.filename}: {_reason(exc)}")
    except (_ReadError, ConnectionError) as exc:
        return _fail(_one_line(exc))
    except OSError as exc:
        where = f" {exc.filename}" if exc.filename else ""
        return _fail(f"cannot write{where}: {_reason(exc)}")
    except ImportError as exc:
        return _fail(_one_line(exc))
    except KeyboardInterrupt:
        print(f"{_PROG}: interrupted; nothing was written", file=sys.stderr)
        return 130


def _one_line(exc: BaseException) -> str:
    return re.sub(r"\s+", " ", str(exc)).strip()
