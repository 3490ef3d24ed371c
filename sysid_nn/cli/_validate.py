"""``sysid-nn validate``: residual tests, scores and figures of a saved model."""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

from sysid_nn.cli._common import (
    _PROG,
    _add_output_flags,
    _add_parallel,
    _bounded,
    _check_output,
    _command,
    _InputError,
    _positive_float,
    _positive_int,
    _reason,
    _score_lines,
    _scores,
)
from sysid_nn.cli._records import (
    _DT_TOLERANCE,
    _data_arguments,
    _read_records,
    _Records,
    _resolve_dt,
    _units,
)


def _add_validate(sub: argparse._SubParsersAction) -> None:
    p = _command(sub, "validate", _run_validate)
    p.add_argument(
        "--model",
        type=Path,
        required=True,
        metavar="FILE",
        help="model saved by `sysid-nn fit --save` or sysid_nn.save_model",
    )
    p.add_argument(
        "--trust-pickle",
        action="store_true",
        help="also load a pickle (joblib) model file, as earlier versions saved; "
        "unpickling runs any code the file holds, so only for files you trust",
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
        "--y-init",
        type=_positive_int,
        default=None,
        metavar="N",
        help="start each record's free run from its first N measured samples "
        "(the initial conditions whose free run fits them best), for records "
        "that do not start at rest, and score it after them (default: from the "
        "model's rest)",
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
    p.add_argument(
        "--series",
        choices=("csv", "parquet", "none"),
        default="csv",
        help="file format of series.<format> in --out: every record with the "
        "model's one-step predictions and free runs (parquet needs pyarrow)",
    )
    _add_parallel(p)
    _add_output_flags(p, "--out directory")


_band_level = _bounded(
    float, lambda v: 0 < v < 1, "a level between 0 and 1 (e.g. 0.95)"
)


def _load_model(path: Path, trusted: bool = False):
    from sysid_nn._saved import _read_bundle

    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", UserWarning)
            bundle = _read_bundle(path, trusted=trusted)
    except OSError as exc:
        raise _InputError(f"cannot read {path}: {_reason(exc)}") from None
    except ValueError as exc:
        raise _InputError(str(exc)) from None
    for w in caught:  # version stamp, pickle: one line, not a source excerpt
        print(f"{_PROG}: warning: {w.message}", file=sys.stderr)
    return bundle


def _check_max_lag(max_lag: int, records: _Records, y_init: int = 0) -> None:
    """The residual tests' lags fit the shortest record (after ``--y-init``)."""
    from sysid_nn._analysis._correlation_tests import max_lag_bound

    lengths = records.lengths()
    shortest = min(range(len(lengths)), key=lengths.__getitem__)
    bound = max_lag_bound(lengths[shortest] - y_init)
    after = f" after the first {y_init} (--y-init)" if y_init else ""
    if max_lag > bound:
        fix = (
            f"use --max-lag {bound} or less"
            if bound >= 1
            else f"the residual tests need records of at least 12 samples{after}"
        )
        raise ValueError(
            f"--max-lag {max_lag} needs records of at least {2 * max_lag + 10} "
            f"samples{after}, but {records.origins[shortest]} has "
            f"{lengths[shortest]}; {fix}."
        )


def _run_validate(args: argparse.Namespace) -> int:
    from sysid_nn._analysis._sensitivity import chaos_hint
    from sysid_nn._compile import prepare_kernels
    from sysid_nn.study import run_validation
    from sysid_nn.study._run import _WIDE_BAND, describe_non_finite, wide_band_warning

    bundle = _load_model(args.model, args.trust_pickle)
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
        args.sep,
        args.decimal,
    )
    dt = _resolve_dt(args.dt, records, fallback=bundle.dt)
    if bundle.dt is not None and abs(dt - bundle.dt) > _DT_TOLERANCE * bundle.dt:
        raise _InputError(
            f"{records.dt_origin or '--dt'} gives dt = {dt:g} s, but {args.model} "
            f"was fitted at dt = {bundle.dt:g} s; a model only applies at the "
            "step it was identified at: resample the records."
        )
    y_init = args.y_init or 0
    _check_max_lag(args.max_lag, records, y_init)
    series = None if args.series == "none" else args.series
    if series == "parquet":
        from sysid_nn.study._run import _check_parquet

        _check_parquet()  # before the long work
    prepare_kernels(show=not args.quiet)  # before the first run of the model
    X_all, _ = model.arrays(records.columns)
    hint = chaos_hint(model.estimator, max(X_all, key=len))
    if hint:
        print(f"{_PROG}: warning: {hint}", file=sys.stderr)
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
            f"Model: {args.model}"
            + (f", fitted on {', '.join(bundle.files)}." if bundle.files else "."),
            f"Validation data: {', '.join(map(str, args.files))}"
            + (f", split by {args.split_by!r}." if args.split_by else "."),
            *([f"Warning: {hint[0].upper()}{hint[1:]}"] if hint else []),
        ],
        progress=not args.quiet,
        series=series,
        band=args.band,
        y_init=y_init,
    )
    for entry in result.non_finite:
        record = f"{records.origins[entry.record]}"
        warning = describe_non_finite(entry, record)
        print(f"{_PROG}: warning: {warning}", file=sys.stderr)
    if result.band_width is not None and result.band_width > _WIDE_BAND:
        warning = wide_band_warning(result.band_width)
        print(f"{_PROG}: warning: {warning}", file=sys.stderr)
    if not args.quiet:
        X, y = model.arrays(records.columns)
        start = (
            f"from their first {y_init} measured samples, scored after them"
            if y_init
            else "from rest"
        )
        print(
            f"{model.label} on {len(X)} experiment(s) at dt = {dt:g} s, free runs "
            f"{start} (NRMSE pooled over the experiments):"
        )
        scores = _scores(model.estimator, X, y, y_init=y_init)
        print("\n".join(_score_lines(scores, model.outputs, units)))
        network = getattr(model.estimator, "network_", None)
        if network is not None:  # saved by `fit --members N --distil`
            print(
                "The network fitted to the median (network_, whose modes the "
                "report gives), on the same records:"
            )
            scores = _scores(network, X, y, y_init=y_init)
            print("\n".join(_score_lines(scores, model.outputs, units)))
        written = "results.csv, summary.csv" + (f", series.{series}" if series else "")
        print(f"wrote {result.out_dir}/report.md, {written} and figures")
        if args.band is not None:
            print(
                f"{100 * args.band:g} % prediction band of the free run covers "
                f"{100 * result.band_coverage:.1f} % of the samples; its standard "
                f"deviation is on average {result.band_width:.2g} times the "
                "output's (band.csv, band_<k>.png)"
            )
    return 0
