"""``sysid-nn validate``: residual tests, scores and figures of a saved model."""

from __future__ import annotations

import argparse
from pathlib import Path

from sysid_nn.cli._common import (
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

    try:
        bundle = joblib.load(path)
    except OSError as exc:
        raise _InputError(f"cannot read {path}: {_reason(exc)}") from None
    except Exception as exc:  # unpickling garbage raises anything
        raise _InputError(f"cannot read {path} as a saved model: {exc}") from None
    if not (hasattr(bundle, "get") and bundle.get("model") is not None):
        raise _InputError(f"{path} was not written by `sysid-nn fit --save`.")
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
        args.sep,
        args.decimal,
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
