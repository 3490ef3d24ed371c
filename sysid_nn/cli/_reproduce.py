"""``sysid-nn reproduce``: the paper's study."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from sysid_nn.cli._common import (
    _add_output_flags,
    _add_parallel,
    _check_output,
    _command,
)

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
        help="CI-sized run (about 15 s on 2 cores once the kernels are "
        "compiled; a first run compiles them, 1-2 minutes): 5 test "
        "realisations, one restart per network",
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
