"""The toolbox on the community's benchmarks, next to the published results.

For every benchmark of :mod:`sysid_nn.datasets` (Silverbox, Wiener-Hammerstein
2009, Cascaded Tanks, EMPS, and the Bouc-Wen benchmark generated from its
specification) and every model configuration below, fits on the official
training data (the estimators hold out the last fifth of it for validation,
their default ``validation_fraction=0.2``), simulates each test record from
rest and reports the RMSE after the benchmark's initialisation window
(``n_skip`` samples), as the community's submissions do, and the fit time.
The Bouc-Wen multisine test is one steady-state period: the model runs from
rest over its input repeated twice and is scored on the second period.

Each (benchmark, model) row is stored in ``results_field.csv`` and the
Markdown table ``results_field.md`` is rebuilt from all stored rows, so one
benchmark or one model can be rerun alone::

    python benchmarks/bench_field.py                       # everything
    python benchmarks/bench_field.py --only silverbox      # one benchmark
    python benchmarks/bench_field.py --only emps --models tdl,linear

The measured benchmarks are read with the ``sysid_nn.datasets`` loaders
(``pip install "sysid_nn[benchmarks]"``) from ``--data-home`` (default: the
loaders' data directory, ``SYSID_NN_DATA`` or ``~/sysid_nn_data``); they are
downloaded there on first use.
"""

from __future__ import annotations

import argparse
import csv
import os
import platform
import time
import warnings
from pathlib import Path

import numpy as np
from sklearn.exceptions import ConvergenceWarning

from sysid_nn import ISSMRegressor, TDLRegressor, datasets

HERE = Path(__file__).resolve().parent
CSV = HERE / "results_field.csv"
MD = HERE / "results_field.md"
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

#: Model name -> (label, factory). The defaults, and the linear model.
MODELS = {
    "tdl": ("TDLRegressor()", lambda: TDLRegressor(random_state=SEED)),
    "issm": ("ISSMRegressor()", lambda: ISSMRegressor(random_state=SEED)),
    "linear": (
        "TDLRegressor(hidden_layer_sizes=())",
        lambda: TDLRegressor(hidden_layer_sizes=(), random_state=SEED),
    ),
}

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
    ("emps", "test"): ("LSTM 0.074, RNN 0.089 (Champneys et al. 2024)", ""),
}

FIELDS = ["benchmark", "model", "label", "test", "unit", "rmse", "fit_s", "warnings"]


def _simulate(model, X, name: str, benchmark: str, n_period: int):
    """Free run from rest; a periodic test is run twice and the last period kept."""
    if benchmark == "boucwen" and name == "multisine":
        return model.simulate(np.tile(X, (2, 1)))[-n_period:]
    return model.simulate(X)


def run_one(benchmark: str, model_name: str, data) -> list[dict]:
    """Fit one model on one benchmark and score it on every test record."""
    _, unit, scale = BENCHMARKS[benchmark]
    label, factory = MODELS[model_name]
    model = factory()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ConvergenceWarning)
        start = time.perf_counter()
        model.fit(data.X_train, data.y_train)
        fit_s = time.perf_counter() - start
    kinds = sorted({w.category.__name__ for w in caught})
    rows = []
    for name, X, y in zip(data.test_names, data.X_test, data.y_test, strict=True):
        y_sim = _simulate(model, X, name, benchmark, len(y))
        err = (y - y_sim)[data.n_skip :]
        rows.append(
            {
                "benchmark": benchmark,
                "model": model_name,
                "label": label,
                "test": name,
                "unit": unit,
                "rmse": float(np.sqrt(np.mean(err**2)) * scale),
                "fit_s": round(fit_s, 1),
                "warnings": " ".join(kinds),
            }
        )
        print(
            f"{benchmark:>20} {label:>38} {name:>24}: "
            f"RMSE {rows[-1]['rmse']:.4g} {unit}, fit {fit_s:.1f} s",
            flush=True,
        )
    return rows


def _load_rows() -> list[dict]:
    if not CSV.is_file():
        return []
    with CSV.open(newline="") as f:
        return list(csv.DictReader(f))


def _store(rows: list[dict]) -> None:
    keep = {(r["benchmark"], r["model"]) for r in rows}
    old = [r for r in _load_rows() if (r["benchmark"], r["model"]) not in keep]
    order = {name: i for i, name in enumerate(BENCHMARKS)}
    merged = sorted(
        [*old, *rows],
        key=lambda r: (order.get(r["benchmark"], 99), r["model"], r["test"]),
    )
    with CSV.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=FIELDS)
        writer.writeheader()
        writer.writerows(merged)
    _write_markdown(merged)


def _fmt(value: str) -> str:
    return f"{float(value):.3g}"


def _write_markdown(rows: list[dict]) -> None:
    lines = [
        "# The toolbox on the community's benchmarks",
        "",
        "Test RMSE of a free-run simulation from rest, skipping the benchmark's "
        "initialisation window, and fit time; one run each, `random_state=0`, "
        "the last fifth of the training data as validation (the estimators' "
        "default). Published results: best black-box simulation RMSE as "
        "collected in the benchmark issue. Written by `benchmarks/bench_field.py` "
        f"on {platform.machine()}, Python {platform.python_version()}, "
        f"{os.cpu_count()} cores shared with other jobs: fit times are noisy.",
        "",
        "| benchmark | test | model | RMSE | fit (s) | best published | others |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        best, others = PUBLISHED.get((r["benchmark"], r["test"]), ("", ""))
        note = f" ({r['warnings']})" if r["warnings"] else ""
        lines.append(
            f"| {r['benchmark']} | {r['test']} | `{r['label']}` | "
            f"{_fmt(r['rmse'])} {r['unit']} | {r['fit_s']}{note} | "
            f"{best} | {others} |"
        )
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
        default=",".join(MODELS),
        help=f"comma-separated models among {', '.join(MODELS)}",
    )
    parser.add_argument("--data-home", default=None, help="data directory")
    args = parser.parse_args(argv)
    benchmarks = [b for b in args.only.split(",") if b]
    models = [m for m in args.models.split(",") if m]
    unknown = set(benchmarks) - set(BENCHMARKS) | set(models) - set(MODELS)
    if unknown:
        parser.error(f"unknown benchmark or model: {', '.join(sorted(unknown))}")
    for benchmark in benchmarks:
        loader = BENCHMARKS[benchmark][0]
        data = loader(data_home=args.data_home)
        for model_name in models:
            _store(run_one(benchmark, model_name, data))
    print(MD.read_text())


if __name__ == "__main__":
    main()
