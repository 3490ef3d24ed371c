"""One decision constant of the training, set to other values, on several systems.

The constants that decide a fit (the table on the pitfalls page) must earn
their value on more than one system. This benchmark sets one of them, a
module-level name of ``sysid_nn._engine`` (for example
``_training._REFINE_SCALE``), to each value given in turn, refits the
default ``TDLRegressor()`` and ``ISSMRegressor()`` and reports their test
errors side by side. Systems:

* ``cascaded_tanks``, ``emps``: the field benchmarks (fetched as a user
  fetches them, see ``--data-home``), one training record with its last
  fifth held out (``tail``) and the same fifth moved 25 samples later and
  passed as ``X_val`` (``split+25``); test RMSE of the free run from rest
  after the initialisation window;
* ``chains``: the lightly damped two-mode chain of
  :mod:`bench_linear` (2 % damping, 1024 samples of white excitation, one
  realisation: the seeds are the fits'), clean and with 1 % output noise,
  from rest and cut 500 samples into its response; test NRMSE on a record
  of 1000 samples;
* ``oscillator``: the hysteretic oscillator of the accuracy benchmark's
  protocol P1 (one record of 2000 samples, two validation records), clean
  and with 1 % and 3 % output noise (:mod:`bench_oracle`'s records);
  median test NRMSE over its 25 test records;
* ``--record FILE``: a measured record of one input and one output (two
  columns of text), the first 768 samples train, as in :mod:`bench_linear`.

Each cell is the median (range) of the fits over the cases and the seeds;
``R`` counts the fits that returned the refinement of the linear model,
``L`` the linear model. Fits identical to those of the first value are
counted in ``same``.

Run: ``python benchmarks/bench_constants.py`` for every sweep of
:data:`SWEEPS` (about three hours on 2 cores; ``results_constants.md``), or
one constant, ``python benchmarks/bench_constants.py _training._REFINE_SCALE
0.1,0.03,0.3 [--systems chains,oscillator] [--seeds 0,1,2] [--data-home
DIR] [--record FILE] [--out results.md]`` (the first value should be the
constant's own).
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np
from scipy.signal import lfilter

sys.path.insert(0, str(Path(__file__).resolve().parent))

import _protocol as P
import bench_oracle
from bench_field import BENCHMARKS, _fit
from bench_linear import N_TEST, chain

from sysid_nn import ISSMRegressor, TDLRegressor
from sysid_nn.study._report import blas_kernels

MODELS = {"TDLRegressor()": TDLRegressor, "ISSMRegressor()": ISSMRegressor}
SYSTEMS = ("cascaded_tanks", "emps", "chains", "oscillator")
#: The constants swept by default, each with its own value first.
SWEEPS = {
    "_training._REFINE_SCALE": "0.1,0.03,0.3",
    "_training._REFINE_BUDGET": "5,2,10",
    "_training._EXTRA_BATCHES": "1,0",
    "_selection._SETTLED": "0.001,0.01,0.0001",
    "_selection._MAX_BURN_SHARE": "0.5,0.3,0.7",
    "_selection._START_WINDOW": "50,20,100",
    "_selection._FITTED_START_GAIN": "0.5,0.25,0.75",
    "_selection._AMPLITUDE_MARGIN": "2,1.5,3",
}


def _rmse(model, X, y, skip: int = 0) -> float:
    sim = np.ravel(model.simulate(X))
    if not np.all(np.isfinite(sim)):
        return np.inf
    return float(np.sqrt(np.mean((sim[skip:] - np.ravel(y)[skip:]) ** 2)))


def cases(system: str, data_home=None, record=None):
    """``(label, fit, score)`` of each case of ``system``: ``fit(model)``
    fits it, ``score(model)`` is its test error."""
    if system in ("cascaded_tanks", "emps"):
        data = BENCHMARKS[system][0](data_home=data_home)

        def score(m):
            return _rmse(m, data.X_test[0], data.y_test[0], data.n_skip)

        # The field benchmarks' own protocols (see bench_field._fit).
        yield "tail", lambda m: _fit(m, data, "tail"), score
        yield "split+25", lambda m: _fit(m, data, "split", 25), score
    elif system == "chains":
        b, a = chain((0.04, 0.11), 0.02)
        for lead in (0, 500):
            for noise in (0.0, 0.01):
                rng = np.random.default_rng(0)
                u = rng.standard_normal(1024 + lead)
                y = lfilter(b, a, u)
                y = (y + noise * y.std() * rng.standard_normal(len(y)))[lead:]
                u = u[lead:, None]
                u_test = np.random.default_rng(100).standard_normal((N_TEST, 1))
                y_test = lfilter(b, a, u_test[:, 0])
                yield (
                    f"{'in motion' if lead else 'from rest'}, {noise:.0%}",
                    lambda m, u=u, y=y: m.fit(u, y),
                    lambda m, u=u_test, y=y_test: _rmse(m, u, y) / y.std(),
                )
    elif system == "oscillator":
        clean, noisy, test = bench_oracle.oscillator()
        for level in (0.0, 0.01, 0.03):
            records = clean if level == 0 else noisy(level)
            yield (
                f"P1, {level:.0%}",
                lambda m, r=records: m.fit(r[0], r[1], X_val=r[2], y_val=r[3]),
                lambda m: bench_oracle.test_nrmse(m, test),
            )
    elif system == "record":
        data = np.loadtxt(record)
        u, y, n = data[:, :1], data[:, 1], 768

        def score(m):  # the free run over the whole record, on its rest
            return _rmse(m, u, y, n) / y[n:].std()

        yield Path(record).name, lambda m: m.fit(u[:n], y[:n]), score


def fit_scored(fit, score, model) -> tuple:
    """``(fitted model, test error, CPU seconds of the fit)`` of one case's
    ``fit`` and ``score`` (see :func:`cases`), its warnings silenced."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cpu = time.process_time()
        fitted = fit(model)
        cpu = time.process_time() - cpu
        return fitted, score(fitted), cpu


def _set(module, name: str, value: str) -> None:
    old = getattr(module, name)
    setattr(module, name, type(old)(float(value)))


def run(constant: str, values, systems, seeds, data_home=None, record=None):
    """One row per fit: system, case, model, seed, value, test, what was
    returned, CPU seconds and the weights' checksum."""
    module_name, name = constant.rsplit(".", 1)
    module = importlib.import_module(f"sysid_nn._engine.{module_name}")
    own = getattr(module, name)
    rows = []
    try:
        for system in systems:
            for label, fit, score in cases(system, data_home, record):
                for model_name, cls in MODELS.items():
                    for seed in seeds:
                        for value in values:
                            _set(module, name, value)
                            model, test, cpu = fit_scored(
                                fit, score, cls(random_state=seed)
                            )
                            refined = model.best_restart_ is not None and (
                                model.best_restart_ == model.refined_restart_
                            )
                            row = dict(
                                system=system, case=label, model=model_name,
                                seed=seed, value=value, test=float(test), cpu=cpu,
                                returned="R" if refined else (
                                    "L" if model.selected_ == "linear" else "N"
                                ),
                                coefs=float(np.sum(np.abs(model.coefs_))),
                                load=os.getloadavg()[0],
                            )  # fmt: skip
                            print(row, flush=True)
                            rows.append(row)
    finally:
        setattr(module, name, own)
    return rows


def report(constant: str, values, rows, wall: float) -> str:
    """Per system and model: median (range) of the test errors for each value."""
    lines = [
        f"# `{constant}` set to {', '.join(values)}",
        "",
        f"Command: `python benchmarks/bench_constants.py {constant} "
        f"{','.join(values)}` (wall time {wall / 60:.1f} min; 1-minute load "
        f"{P.load_range(rows)} on 2 cores; BLAS {blas_kernels()}). Median "
        "(range) of test errors "
        "over the cases and seeds; `R` / `L`: fits that returned the "
        "refinement / the linear model; `same`: fits identical to the first "
        "value's; CPU-s: median CPU time of a fit on one core.",
        "",
        "| system | model | fits | " + " | ".join(values) + " | CPU-s |",
        "|---|---|---|" + "---|" * len(values) + "---|",
    ]
    groups = {}
    for r in rows:
        groups.setdefault((r["system"], r["model"]), []).append(r)
    for (system, model), group in groups.items():
        first = {(r["case"], r["seed"]): r for r in group if r["value"] == values[0]}
        cells = []
        for value in values:
            mine = [r for r in group if r["value"] == value]
            tests = [r["test"] for r in mine]
            same = sum(
                r["coefs"] == first[(r["case"], r["seed"])]["coefs"] for r in mine
            )
            counts = "".join(
                f" {sum(r['returned'] == k for r in mine)}{k}" for k in "RL"
            )
            cells.append(f"{P.median_range(tests)};{counts}; same {same}")
        cpu = np.median([r["cpu"] for r in group])
        lines.append(
            f"| {system} | {model} | {len(first)} | "
            + " | ".join(cells)
            + f" | {cpu:.1f} |"
        )
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "constant", nargs="?", help="module.NAME in sysid_nn._engine (default: SWEEPS)"
    )
    parser.add_argument(
        "values", nargs="?", help="comma-separated, the constant's own first"
    )
    parser.add_argument("--systems", default=",".join(SYSTEMS))
    parser.add_argument("--seeds", default="0,1,2")
    parser.add_argument("--data-home", default=None, help="data directory")
    parser.add_argument("--record", default=None, help="a measured record")
    parser.add_argument("--out", default=None, help="report file (markdown)")
    args = parser.parse_args(argv)
    systems = [s for s in args.systems.split(",") if s]
    unknown = set(systems) - set(SYSTEMS)
    if unknown:
        parser.error(f"unknown systems: {', '.join(sorted(unknown))}")
    if args.record:
        systems.append("record")
    if args.constant and not args.values:
        parser.error(f"give the values to set {args.constant} to")
    sweeps = {args.constant: args.values} if args.constant else SWEEPS
    seeds = [int(s) for s in args.seeds.split(",")]
    texts = []
    for constant, values in sweeps.items():
        values = values.split(",")
        start = time.perf_counter()
        rows = run(constant, values, systems, seeds, args.data_home, args.record)
        texts.append(report(constant, values, rows, time.perf_counter() - start))
    text = "\n".join(texts)
    if args.constant:
        print(text)
        if args.out:
            Path(args.out).write_text(text)
    else:
        P.write_report(text, args.out, "results_constants.md")
    return 0


if __name__ == "__main__":
    sys.exit(main())
