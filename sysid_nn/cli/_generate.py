"""``sysid-nn generate``: records of the hysteretic oscillator."""

from __future__ import annotations

import argparse

from sysid_nn.cli._common import (
    _check_output,
    _command,
    _positive_float,
    _positive_int,
    _seed,
    _write_atomic,
)
from sysid_nn.cli._records import _frame_path


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
