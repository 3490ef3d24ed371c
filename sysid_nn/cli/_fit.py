"""``sysid-nn fit``: a network fitted to the user's records, saved."""

from __future__ import annotations

import argparse
import re
import sys
import time
import warnings
from pathlib import Path

from sysid_nn.cli._common import (
    _PROG,
    _add_output_flags,
    _add_parallel,
    _check_output,
    _command,
    _InputError,
    _one_line,
    _OutputError,
    _positive_float,
    _positive_int,
    _score_lines,
    _scores,
    _seed,
    _write_atomic,
)
from sysid_nn.cli._records import (
    _check_columns,
    _check_columns_vary,
    _data_arguments,
    _frame_path,
    _read_records,
    _Records,
    _resolve_dt,
    _units,
)

# ------------------------------------------------------------ fit, validate
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
        help="network; both stay well ahead of the linear "
        "model at 0.1-3 %% output noise, best with several records; issm "
        "also takes a second measured output (e.g. velocity) well (see the "
        "user guide's pitfalls page)",
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
    p.add_argument(
        "--refit",
        action="store_true",
        help="once the weights are chosen, continue training them on the "
        "validation records too, as far as an inner validation on their halves "
        "says (refit=True; pays where the validation records are further "
        "experiments like the training ones)",
    )
    p.add_argument(
        "--members",
        type=_positive_int,
        default=1,
        metavar="N",
        help="fit N networks, each on its own seed and, with one experiment and "
        "no --val, its own held-out share (15, 20, 25, 30 %% in turn), and save "
        "the median of their runs (EnsembleRegressor): one answer instead of a "
        "draw, at N times the cost (default: 1, one network)",
    )
    p.add_argument(
        "--distil",
        action="store_true",
        help="with --members: also fit one network to the median's free runs "
        "over the records and excitations like them (distil=True), saved with "
        "the median as its network_, which `modal` and the report's structure "
        "read; it costs a fit to five times the records (up to three where a "
        "network misses the records)",
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
    p.add_argument(
        "--save",
        type=Path,
        required=True,
        metavar="FILE",
        help="model file (e.g. model.sysid; data only, no code: see "
        "sysid_nn.load_model)",
    )
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
        "refit": True if args.refit else None,
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


def _ensemble(estimator, members: int, seed: int, distil: bool):
    """``estimator`` itself for one member, else an ensemble of ``members``
    of its clones, seeded by ``seed``, with one network fitted to its median
    if ``distil``."""
    if members == 1:
        if distil:
            raise ValueError(
                "--distil fits one network to the median of several: give "
                "--members N with N of at least 2 (e.g. --members 8), or leave "
                "--distil out."
            )
        return estimator
    from sysid_nn import EnsembleRegressor

    return EnsembleRegressor(
        estimator, n_members=members, distil=distil, random_state=seed
    )


def _holdout(records: _Records, val: _Records | None):
    """Training and held-out experiment indices; None: the estimator's tail."""
    n = len(records.origins)
    if val is not None or n == 1:
        return list(range(n)), None
    return list(range(n - 1)), [n - 1]


def _run_fit(args: argparse.Namespace) -> int:
    from sysid_nn._analysis._sensitivity import chaos_hint
    from sysid_nn._compile import prepare_kernels
    from sysid_nn._saved import _write
    from sysid_nn.study import StudyModel

    inputs, outputs = tuple(args.input), tuple(args.output)
    _check_columns(inputs, outputs, args.split_by)
    units = _units([*inputs, *outputs], args.units)
    estimator, params = _estimator(args)
    fitted = _ensemble(estimator, args.members, args.seed, args.distil)
    sources = [*args.files, *(args.val or [])]
    _check_output(args.save, "--save", overwrite=args.overwrite, inputs=sources)
    _check_replaces_model(args.save)
    read = (args.split_by, args.time_column, args.sep, args.decimal)
    records = _read_records(args.files, [*inputs, *outputs], *read)
    val = _read_records(args.val, [*inputs, *outputs], *read) if args.val else None
    _check_columns_vary(records, inputs, outputs)
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
    prepare_kernels(show=not args.quiet)  # a first run's compiling is no fit time
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        started = time.perf_counter()
        _fit(fitted, X_fit, y_fit, X_val, y_val, sources, inputs, outputs)
        fit_time = time.perf_counter() - started  # members and network_ too
        # The fitted networks; the first stands for all in the checks that
        # hold for each (an ensemble's members share structure and records).
        networks = getattr(fitted, "estimators_", [fitted])
        network, ensemble = networks[0], len(networks) > 1
        _check_enough_samples(network, X_fit, args.files)
        # Each member held out its own share: no part was held out of all.
        own_shares = (
            ensemble and X_val is None and network.best_validation_score_ is not None
        )
        if X_val is not None:
            scores = _scores(fitted, X_val, y_val)
            where = f"{len(X_val)} experiment(s) ({', '.join(held_names)})"
        elif own_shares:
            scores = _scores(fitted, X, y)
            shares = sorted(set(fitted.member_validation_fractions_))
            where = (
                f"each member's own last {shares[0]:.0%}-{shares[-1]:.0%} of "
                f"{records.origins[0]}"
            )
        elif network.best_validation_score_ is not None:
            share = network.get_params()["validation_fraction"]
            scores = _scores(network, X, y, tail=share)
            where = (
                f"the last {share:.0%} of {records.origins[0]} (free run from the "
                "record's start)"
            )
        else:  # too short to hold anything out: say so, score what there is
            scores = _scores(network, X, y)
            where = "nothing (the record is too short to hold a part out)"
    # One line per distinct warning, not Python's two-line source excerpt.
    messages = [str(w.message).splitlines()[0] for w in caught]
    # On a chaotic record free-run scores mean little: say so (longest record).
    longest = max(X_fit, key=len)
    messages.append(chaos_hint(network, longest))
    for message in dict.fromkeys(m for m in messages if m):
        print(f"{_PROG}: warning: {message}", file=sys.stderr)
    what = model.label
    if ensemble:
        # Members whose runs missed the records far worse are left out.
        used = sum(bool(u) for u in fitted.members_used_)
        of = f"{used} of {len(networks)}" if used < len(networks) else len(networks)
        what = f"median of {of} × {model.label}"
        if args.distil:
            what += ", one network fitted to it"
    info = {
        "inputs": list(inputs),
        "outputs": list(outputs),
        "dt": dt,
        "units": units,
        "files": [str(f) for f in args.files],
        "split_by": args.split_by,
        "label": what,
    }
    _write_atomic(args.save, lambda tmp: _write(tmp, fitted, info))
    if args.quiet:  # warnings only (above), no summary
        return 0
    print(
        f"fitted {what} in {fit_time:.1f} s: trained on "
        f"{len(X_fit)} experiment(s), weights chosen by early stopping "
        f"on {where} (dt = {dt:g} s); saved to {args.save}. "
        + (
            "Scores on the training records, whose held-out shares chose the "
            "members' weights (optimistic; `sysid-nn validate` on unseen "
            "records tells more):"
            if own_shares
            else "Scores on the validation data that chose the weights (optimistic; "
            "`sysid-nn validate` on unseen records tells more):"
            if network.best_validation_score_ is not None
            else "Scores on the training data:"
        )
    )
    print("\n".join(_score_lines(scores, outputs, units)))
    if args.distil:
        errors = fitted.member_record_errors_
        print(
            "The network fitted to the median (network_, which `sysid-nn modal` "
            "reads) misses the fitted records by "
            f"{fitted.network_record_error_:.3g} (the members: "
            f"{errors.min():.3g}-{errors.max():.3g}; root-mean-square error of "
            "the free runs, each output scaled by its spread)."
        )
    return 0


def _check_enough_samples(estimator, X: list, files) -> None:
    """Refuse a fit with no more modelled samples than weights.

    With as many weights as equations a model fits its records exactly,
    whatever they hold, and its training scores mean nothing.
    """
    reach = estimator._history_length()
    n_equations = estimator.n_outputs_ * sum(max(0, len(x) - reach) for x in X)
    n_weights = estimator.coefs_.size
    if n_equations <= n_weights:
        raise _InputError(
            f"the training records ({', '.join(map(str, files))}) are too short "
            f"for the model: {n_equations} modelled output sample(s) after the "
            f"first {reach} (the reach of its lags) for {n_weights} weights, so it "
            "would fit them exactly whatever they hold. Give longer or more "
            "records, or a smaller model (fewer --hidden units, lags or "
            "--n-states); nothing was saved."
        )


def _check_replaces_model(path: Path) -> None:
    """``--overwrite`` replaces a model file only, never data or anything else."""
    from sysid_nn._saved import _is_model_file

    if path.is_file() and not _is_model_file(path):
        raise _OutputError(
            f"{path} exists and is not a model file; --overwrite replaces only "
            "models saved by `sysid-nn fit --save`. Choose another --save."
        )


def _fit(estimator, X, y, X_val, y_val, files, inputs, outputs) -> None:
    """``estimator.fit``; an error about the data names the files and columns."""
    try:
        estimator.fit(X, y, X_val=X_val, y_val=y_val)
    except ValueError as exc:
        # Errors about a parameter start with its name: bad arguments (exit 2).
        first = re.split(r"\W", str(exc), maxsplit=1)[0]
        network = getattr(estimator, "estimator", None) or estimator  # a member
        if isinstance(exc, TypeError) or first in {
            *estimator.get_params(),
            *network.get_params(),
        }:
            raise
        raise _InputError(
            f"cannot fit to {', '.join(map(str, files))}"
            f" (inputs {', '.join(map(repr, inputs))}, outputs "
            f"{', '.join(map(repr, outputs))}): {_one_line(exc)}"
        ) from None
