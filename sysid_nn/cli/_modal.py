"""``sysid-nn modal``: the modes of a saved model, with their intervals."""

from __future__ import annotations

import argparse
from pathlib import Path

from sysid_nn.cli._common import _bounded, _command, _InputError, _positive_float
from sysid_nn.cli._records import _DT_TOLERANCE

_level = _bounded(float, lambda v: 0 < v < 1, "a level between 0 and 1 (e.g. 0.95)")


def _add_modal(sub: argparse._SubParsersAction) -> None:
    p = _command(sub, "modal", _run_modal)
    p.add_argument(
        "model", type=Path, metavar="MODEL", help="model saved by `sysid-nn fit --save`"
    )
    p.add_argument(
        "--dt",
        type=_positive_float,
        default=None,
        help="sample spacing, s (default: the one the model was fitted at; "
        "given, it must agree with it)",
    )
    p.add_argument(
        "--level",
        type=_level,
        default=0.95,
        help="probability of the intervals (default: 0.95)",
    )
    p.add_argument(
        "--all",
        action="store_true",
        help="also list the numerical modes (real poles, near Nyquist, unobservable)",
    )


def modal_table(modes, outputs, *, show_all: bool = False) -> str:
    """The modes as printed: intervals in brackets, shapes under output names.

    Examples
    --------
    >>> import pandas as pd
    >>> modes = pd.DataFrame({
    ...     "frequency_hz": [1.5], "frequency_hz_low": [1.4],
    ...     "frequency_hz_high": [1.6], "damping_ratio": [0.02],
    ...     "damping_ratio_low": [0.01], "damping_ratio_high": [0.03],
    ...     "kind": ["structural"], "structural": [True]})
    >>> modes.attrs["level"] = 0.95
    >>> print(modal_table(modes, ("drift",)))
     mode  frequency [Hz]  95 % interval  damping ratio   95 % interval
        1          1.5000 [1.4000, 1.6000]         0.0200 [0.0100, 0.0300]
    """
    shown = modes if show_all else modes[modes.structural]
    level = round(100 * modes.attrs.get("level", 0.95), 6)
    shapes = [c for c in modes.columns if c.startswith("shape_")]
    head = f"{'mode':>5}  {'frequency [Hz]':>14}  {f'{level:g} % interval':>13}"
    head += f"  {'damping ratio':>13}   {f'{level:g} % interval':>13}"
    names = outputs[: len(shapes)]
    widths = [max(10, len(name)) for name in names]
    head += "".join(f"  {name:>{w}}" for name, w in zip(names, widths, strict=True))
    if show_all:
        head += "  kind"
    lines = [head]
    for k, row in enumerate(shown.itertuples(index=False), start=1):
        line = (
            f"{k:>5}  {row.frequency_hz:>14.4f} "
            f"[{row.frequency_hz_low:.4f}, {row.frequency_hz_high:.4f}]"
            f"  {row.damping_ratio:>13.4f} "
            f"[{row.damping_ratio_low:.4f}, {row.damping_ratio_high:.4f}]"
        )
        line += "".join(
            f"  {getattr(row, c):>{w}.3f}" for c, w in zip(shapes, widths, strict=True)
        )
        if show_all:
            line += f"  {row.kind}"
        lines.append(line)
    if len(lines) == 1:
        lines.append(
            "  (no structural mode: run with --all to list the numerical ones)"
        )
    return "\n".join(lines)


def _run_modal(args: argparse.Namespace) -> int:
    from sysid_nn._analysis._modal import modal_parameters
    from sysid_nn._estimators._ensemble import one_network
    from sysid_nn.cli._validate import _load_model

    bundle = _load_model(args.model)
    dt = bundle.dt if args.dt is None else args.dt
    if abs(dt - bundle.dt) > _DT_TOLERANCE * bundle.dt:
        raise _InputError(
            f"--dt {dt:g} s, but {args.model} was fitted at dt = {bundle.dt:g} s; "
            "a model's modes are those of the step it was identified at: leave "
            "--dt out."
        )
    model = bundle.model
    try:
        network = one_network(model.estimator)
    except ValueError as exc:
        raise _InputError(f"{args.model}: {exc}") from None
    of = ""
    if network is not model.estimator:
        of = (
            f", the network fitted to the median of "
            f"{len(model.estimator.estimators_)} (network_)"
        )
    modes = modal_parameters(network, dt, level=args.level)
    print(f"Modes of {args.model}{of} (dt = {dt:g} s), linearised at rest:")
    print(modal_table(modes, tuple(model.outputs), show_all=args.all))
    return 0
