"""The toolbox on the community's benchmarks, next to the published results.

For every benchmark of :mod:`sysid_nn.datasets` (Silverbox, Wiener-Hammerstein
2009, Cascaded Tanks, EMPS, and the Bouc-Wen benchmark generated from its
specification) and every model configuration below, fits on the official
training data (the estimators hold out the last fifth of it for validation,
their default ``validation_fraction=0.2``), simulates each test record and
reports the RMSE after the benchmark's initialisation window (``n_skip``
samples), and the fit time. Each test is simulated twice: from rest (the
estimators' default), and from the initial state fitted to the measured
outputs of the initialisation window (``simulate(X, y_init=y[:n_skip])``),
the community's protocol: its submission template applies the model "using
only u and y[:n]".
The Bouc-Wen multisine test is one steady-state period: the model runs from
rest over its input repeated twice and is scored on the second period.

Each (benchmark, model) row is stored in ``results_field.csv`` and the
Markdown table ``results_field.md`` is rebuilt from all stored rows, so one
benchmark or one model can be rerun alone::

    python benchmarks/bench_field.py                       # everything
    python benchmarks/bench_field.py --only silverbox      # one benchmark
    python benchmarks/bench_field.py --only emps --models tdl,linear
    python benchmarks/bench_field.py --select-order --only wiener_hammerstein
    python benchmarks/bench_field.py --validation split --only emps

``--select-order`` measures which lags each benchmark needs instead: the
training record is cut into four consecutive experiments and
``GridSearchCV`` (4-fold, by experiment, scored on the NRMSE of the free run)
chooses the lags of the linear model; the chosen model is then refitted on
the whole record and scored on the test records like the others. Results go
to ``results_field_order.md``.

The measured benchmarks are read with the ``sysid_nn.datasets`` loaders
(``pip install ".[benchmarks]"``) from ``--data-home`` (default: the
loaders' data directory, ``SYSID_NN_DATA`` or ``~/sysid_nn_data``); they are
downloaded there on first use.
"""

from __future__ import annotations

import argparse
import os
import platform
import time
import warnings
from pathlib import Path

import numpy as np
from _results import store_rows
from sklearn.exceptions import ConvergenceWarning
from sklearn.model_selection import GridSearchCV, KFold

from sysid_nn import ISSMRegressor, TDLRegressor, datasets
from sysid_nn.metrics import make_simulation_scorer
from sysid_nn.study._report import blas_kernels

HERE = Path(__file__).resolve().parent
CSV = HERE / "results_field.csv"
MD = HERE / "results_field.md"
#: With ``--validation split``: the last fifth passed as ``X_val``, apart.
SPLIT_CSV = HERE / "results_field_split.csv"
SPLIT_MD = HERE / "results_field_split.md"
ORDER_MD = HERE / "results_field_order.md"
#: Lags tried by --select-order (output and input lags equal).
LAGS = (1, 2, 3, 4, 6, 8, 10)
SEED = 0

#: Benchmark name -> (loader, output unit, scale from SI to that unit).
BENCHMARKS = {
    "cascaded_tanks": (datasets.fetch_cascaded_tanks, "V", 1.0),
    "emps": (datasets.fetch_emps, "m", 1.0),
    "silverbox": (datasets.fetch_silverbox, "mV", 1e3),
    "boucwen": (
        lambda data_home: datasets.make_boucwen_benchmark(random_state=SEED),
        "m",
        1.0,
    ),
    "wiener_hammerstein": (datasets.fetch_wiener_hammerstein, "mV", 1e3),
}

#: Model name -> (label, factory). The defaults, and the linear models.
MODELS = {
    "tdl": ("TDLRegressor()", lambda seed=SEED: TDLRegressor(random_state=seed)),
    "issm": ("ISSMRegressor()", lambda seed=SEED: ISSMRegressor(random_state=seed)),
    "linear": (
        "TDLRegressor(hidden_layer_sizes=())",
        lambda seed=SEED: TDLRegressor(hidden_layer_sizes=(), random_state=seed),
    ),
    "issm_linear": (
        "ISSMRegressor(hidden_layer_sizes=())",
        lambda seed=SEED: ISSMRegressor(hidden_layer_sizes=(), random_state=seed),
    ),
}
#: The models a run fits unless told (the published tables' columns).
DEFAULT_MODELS = ("tdl", "issm", "linear")


def model_variant(name: str) -> bool:
    """Register ``name`` of the form ``model[param=value]`` (a number or a
    flag: ``issm[n_init=8]``, ``issm[alpha=0.001]``, ``issm[refit=True]``)
    in :data:`MODELS` as that model with the parameter set; whether
    ``name`` is (now) known."""
    if name in MODELS:
        return True
    base, _, rest = name.partition("[")
    param, _, text = rest.rstrip("]").partition("=")
    if base not in MODELS or not rest.endswith("]"):
        return False
    if text in ("True", "False"):
        value = text == "True"
    else:
        try:
            value = int(text) if text.isdigit() else float(text)
        except ValueError:
            return False
    label, factory = MODELS[base]
    MODELS[name] = (
        f"{label[:-1]}{', ' if label[-2] != '(' else ''}{param}={text})",
        lambda seed=SEED: factory(seed).set_params(**{param: value}),
    )
    return True


#: Best published black-box simulation RMSE and other references, per test.
PUBLISHED = {
    ("boucwen", "multisine"): (
        "7.53e-6 (gr-SS-NN, tabulated by Iacob et al. 2025)",
        "PNLSS 1.2-1.9e-5; dynoNet 4.52e-5; linear ARX about 1.6e-4",
    ),
    ("silverbox", "multisine"): ("", "LSTM 1.50 (Champneys et al. 2024)"),
    ("silverbox", "arrow_no_extrapolation"): (
        "0.31 (SUBNET, Beintema et al. 2021)",
        "",
    ),
    ("silverbox", "arrow_full"): ("", "LSTM 2.68 (Champneys et al. 2024)"),
    ("wiener_hammerstein", "test"): (
        "0.24 (SUBNET)",
        "NL-LFR 0.29; dynoNet 1.2; GRU 3.97",
    ),
    ("cascaded_tanks", "test"): (
        "0.22 (continuous-time SUBNET, best of 17; median about 0.30)",
        "grey box 0.18; GRU 0.40; linear about 0.75",
    ),
    ("emps", "test"): (
        "0.00461 (continuous-time SUBNET, 2 states)",
        "LSTM 0.074, RNN 0.089 (Champneys et al. 2024)",
    ),
}

FIELDS = [
    "benchmark", "model", "label", "test", "unit", "rmse", "rmse_window", "fit_s",
    "cpu_s", "load", "warnings",
]  # fmt: skip


def _simulate(model, X, name: str, benchmark: str, n_period: int, y_init=None):
    """Free run from rest; a periodic test is run twice and the last period kept.

    With ``y_init`` (the initialisation window's outputs) the run starts from
    the initial state fitted to them instead.
    """
    if benchmark == "boucwen" and name == "multisine":
        return model.simulate(np.tile(X, (2, 1)))[-n_period:]
    if y_init is not None:
        return model.simulate(X, y_init=y_init)
    return model.simulate(X)


def _fit(model, data, validation: str, shift: int = 0):
    """Fit on the training record; ``"split"`` validates on its last fifth alone.

    ``"tail"`` is the estimators' default for one record: the last fifth is
    held out as a validation record of its own (judged as one passed as
    ``X_val``, so both give the same fit). ``"split"`` passes it as ``X_val``,
    its start moved by ``shift`` samples.
    """
    if validation == "tail":
        return model.fit(data.X_train, data.y_train)
    X, y = data.X_train[0], data.y_train[0]
    n = round(0.8 * len(y)) + shift
    return model.fit(X[:n], y[:n], X_val=X[n:], y_val=y[n:])


def run_one(
    benchmark: str,
    model_name: str,
    data,
    validation="tail",
    *,
    random_state: int = SEED,
    shift: int = 0,
) -> list[dict]:
    """Fit one model on one benchmark and score it on every test record."""
    _, unit, scale = BENCHMARKS[benchmark]
    label, factory = MODELS[model_name]
    model = factory(random_state)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ConvergenceWarning)
        start, cpu = time.perf_counter(), time.process_time()
        _fit(model, data, validation, shift)
        fit_s = time.perf_counter() - start
        cpu_s = time.process_time() - cpu
    load = os.getloadavg()[0]
    kinds = sorted({w.category.__name__ for w in caught})
    rows = []
    for name, X, y in zip(data.test_names, data.X_test, data.y_test, strict=True):
        err = (y - _simulate(model, X, name, benchmark, len(y)))[data.n_skip :]
        # Without an initialisation window (Bouc-Wen) both runs are from rest.
        err_w = err
        if data.n_skip:
            window = y[: data.n_skip]
            y_window = _simulate(model, X, name, benchmark, len(y), window)
            err_w = (y - y_window)[data.n_skip :]
        rows.append(
            {
                "benchmark": benchmark,
                "model": model_name,
                "label": label,
                "test": name,
                "unit": unit,
                "rmse": float(np.sqrt(np.mean(err**2)) * scale),
                "rmse_window": float(np.sqrt(np.mean(err_w**2)) * scale),
                "fit_s": round(fit_s, 1),
                "cpu_s": round(cpu_s, 1),
                "load": round(load, 1),
                "warnings": " ".join(kinds),
            }
        )
        print(
            f"{benchmark:>20} {label:>38} {name:>24}: "
            f"RMSE {rows[-1]['rmse']:.4g} {unit} (window: "
            f"{rows[-1]['rmse_window']:.4g}), fit {fit_s:.1f} s "
            f"({cpu_s:.1f} CPU-s, load {load:.1f})",
            flush=True,
        )
    return rows


def select_order(benchmark: str, data) -> list[str]:
    """Cross-validate the lags of the linear model; score the chosen one."""
    _, unit, scale = BENCHMARKS[benchmark]
    X, y = data.X_train[0], data.y_train[0]
    chunks = np.array_split(np.arange(len(y)), 4)
    Xs, ys = [X[c] for c in chunks], [y[c] for c in chunks]
    search = GridSearchCV(
        TDLRegressor(hidden_layer_sizes=(), random_state=SEED),
        # Equal output and input lags: one grid point per value.
        [{"output_lags": [k], "input_lags": [k]} for k in LAGS],
        cv=KFold(4),
        scoring=make_simulation_scorer("nrmse", divergence_score=-1e6),
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        start = time.perf_counter()
        search.fit(Xs, ys)
        model = search.best_estimator_.fit(data.X_train, data.y_train)
        elapsed = time.perf_counter() - start
    cv = " / ".join(
        f"{k}: {-score:.3f}"
        for k, score in zip(LAGS, search.cv_results_["mean_test_score"], strict=True)
    )
    rmses = []
    for name, Xt, yt in zip(data.test_names, data.X_test, data.y_test, strict=True):
        err = (yt - _simulate(model, Xt, name, benchmark, len(yt)))[data.n_skip :]
        rmses.append(f"{name} {np.sqrt(np.mean(err**2)) * scale:.3g} {unit}")
    line = (
        f"| {benchmark} | {search.best_params_['output_lags']} | {cv} | "
        f"{'; '.join(rmses)} | {elapsed:.0f} |"
    )
    print(line, flush=True)
    return [line]


def _store(rows: list[dict]) -> None:
    order = {name: i for i, name in enumerate(BENCHMARKS)}
    tests = {t: i for i, t in enumerate(t for _, t in PUBLISHED)}
    merged = store_rows(
        CSV,
        FIELDS,
        rows,
        lambda r: (
            order.get(r["benchmark"], 99),
            tests.get(r["test"], 99),
            list(MODELS).index(r["model"]) if r["model"] in MODELS else 99,
        ),
    )
    _write_markdown(merged)


def _write_markdown(rows: list[dict]) -> None:
    """One line per test record, the models side by side; fit times below."""
    labels = {name: label for name, (label, _) in MODELS.items()}
    cells, fits, units = {}, {}, {}
    for r in rows:
        key = (r["benchmark"], r["test"])
        note = "*" if r["warnings"] else ""
        window = f" ({float(r['rmse_window']):.3g})" if r.get("rmse_window") else ""
        cells.setdefault(key, {})[r["model"]] = f"{float(r['rmse']):.3g}{window}{note}"
        cpu = r.get("cpu_s") or "?"
        fits.setdefault(r["benchmark"], {})[r["model"]] = (
            f"{r['fit_s']} ({cpu} CPU, load {r.get('load') or '?'})"
        )
        units[key] = r["unit"]
    # Columns for the models that were run (not every model of MODELS).
    shown = [m for m in MODELS if any(m in c for c in cells.values())]
    held_out = (
        "passed as a separate validation record (`X_val`, simulated from rest)"
        if MD == SPLIT_MD
        else "held out by the estimators as a validation record of its own"
    )
    lines = [
        "# The toolbox on the community's benchmarks",
        "",
        "Test RMSE of a free-run simulation from rest, skipping the benchmark's "
        "initialisation window (`n_skip` samples); in brackets, of the run "
        "from the initial state fitted to the window's measured outputs "
        "(`simulate(X, y_init=y[:n_skip])`), the community's protocol. One "
        "run each, `random_state=0`, trained on the "
        f"official training record with its last fifth {held_out}. "
        "The Bouc-Wen data are generated by "
        "`make_boucwen_benchmark(random_state=0)`; its multisine test period is "
        "simulated twice from rest and the second period scored. Published "
        "results: best black-box simulation RMSE in the literature. `*`: the fit "
        "raised warnings, named per row in the `warnings` column of "
        "`results_field.csv` (e.g. `ConvergenceWarning`: a budget ended before "
        "the tolerance; `UserWarning`: the output noise `fit` estimated). "
        "Written by `benchmarks/bench_field.py`.",
        "",
        "| benchmark | test | unit | "
        + " | ".join(labels[m] for m in shown)
        + " | best published | others |",
        "|---|---|---|" + "---|" * len(shown) + "---|---|",
    ]
    for (benchmark, test), by_model in cells.items():
        best, others = PUBLISHED.get((benchmark, test), ("", ""))
        values = " | ".join(by_model.get(m, "") for m in shown)
        lines.append(
            f"| {benchmark} | {test} | {units[(benchmark, test)]} | {values} | "
            f"{best} | {others} |"
        )
    lines += [
        "",
        f"Fit times in seconds of wall time (of CPU time, and the 1-minute load "
        f"average at the end of the fit; {platform.machine()}, Python "
        f"{platform.python_version()}, {os.cpu_count()} cores shared with other "
        f"jobs, BLAS {blas_kernels()}; fits run with the estimators' default single "
        "job). The times grow "
        "with the machine's load: on a loaded machine they can be several "
        "times the idle ones, so compare times only within one run.",
        "",
        "| benchmark | " + " | ".join(labels[m] for m in shown) + " |",
        "|---|" + "---|" * len(shown),
    ]
    for benchmark, by_model in fits.items():
        values = " | ".join(str(by_model.get(m, "")) for m in shown)
        lines.append(f"| {benchmark} | {values} |")
    MD.write_text("\n".join(lines) + "\n")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--only",
        default=",".join(BENCHMARKS),
        help=f"comma-separated benchmarks among {', '.join(BENCHMARKS)}",
    )
    parser.add_argument(
        "--models",
        default=",".join(DEFAULT_MODELS),
        help=f"comma-separated models among {', '.join(MODELS)}",
    )
    parser.add_argument("--data-home", default=None, help="data directory")
    parser.add_argument(
        "--validation",
        choices=["tail", "split"],
        default="tail",
        help="tail: the estimators' default validation on one record; split: "
        "the last fifth as a separate X_val (results_field_split.*)",
    )
    parser.add_argument(
        "--report",
        action="store_true",
        help="only rebuild results_field.md from results_field.csv",
    )
    parser.add_argument(
        "--select-order",
        action="store_true",
        help="cross-validate the linear model's lags instead",
    )
    args = parser.parse_args(argv)
    benchmarks = [b for b in args.only.split(",") if b]
    models = [m for m in args.models.split(",") if m]
    unknown = set(benchmarks) - set(BENCHMARKS) | set(models) - set(MODELS)
    if unknown:
        parser.error(f"unknown benchmark or model: {', '.join(sorted(unknown))}")
    if args.validation == "split":
        global CSV, MD
        CSV, MD = SPLIT_CSV, SPLIT_MD
    if args.report:
        _store([])
        print(MD.read_text())
        return
    lines = []
    for benchmark in benchmarks:
        loader = BENCHMARKS[benchmark][0]
        data = loader(data_home=args.data_home)
        if args.select_order:
            lines += select_order(benchmark, data)
            continue
        for model_name in models:
            _store(run_one(benchmark, model_name, data, args.validation))
    if args.select_order:
        header = [
            "# Model order of the linear model, chosen by cross-validation",
            "",
            "Training record cut into 4 consecutive experiments, 4-fold "
            "`GridSearchCV` of `TDLRegressor(hidden_layer_sizes=())` over equal "
            "output and input lags, scored by the NRMSE of the free run; the "
            "chosen model refitted on the whole record and scored on the test "
            "records (RMSE after the initialisation window).",
            "",
            "| benchmark | chosen lags | CV NRMSE per lags | test RMSE | time (s) |",
            "|---|---|---|---|---|",
        ]
        # Keep the rows of the benchmarks not rerun this time.
        done = {line.split("|")[1].strip() for line in lines}
        kept = [
            line
            for line in (
                ORDER_MD.read_text().splitlines() if ORDER_MD.is_file() else []
            )
            if line.startswith("| ")
            and line.split("|")[1].strip() in BENCHMARKS
            and line.split("|")[1].strip() not in done
        ]
        order = list(BENCHMARKS)
        rows = sorted(
            [*kept, *lines], key=lambda r: order.index(r.split("|")[1].strip())
        )
        ORDER_MD.write_text("\n".join([*header, *rows]) + "\n")
        print(ORDER_MD.read_text())
        return
    print(MD.read_text())


if __name__ == "__main__":
    main()
