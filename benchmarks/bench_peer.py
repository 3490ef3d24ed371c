"""A peer library's GRU recipe beside the toolbox, on one core of this machine.

Trains the GRU recipe of tsfast (a PyTorch system-identification library) on
Silverbox and Wiener-Hammerstein 2009 and logs, after every epoch, the test
RMSE of the free-run simulation against the cumulative CPU time of the
training, then sets the toolbox's own numbers beside it. The recipe: one GRU
layer of 100 units fed the input only (no output fed back), L1 loss, Adam
with learning rate 3e-3, 10 epochs of a flat-then-cosine learning-rate
schedule (tsfast's ``fit_flat_cos``: flat for 75 % of the steps), windows of
200 samples (every window of the training record once per epoch, batches of
64), the first 50 samples of each window left out of the loss; tsfast
standardises the input. Everything runs on ONE core: the peer's process sets
``torch.set_num_threads(1)`` and pins itself with ``os.sched_setaffinity``.

The data are those of ``bench_field.py --validation split``: the official
training record's first four fifths train, its last fifth validates (tsfast
validates on it after every epoch, as part of the recipe), and the official
test records are simulated from rest over their whole length, scored after
the benchmark's ``n_skip`` samples.

tsfast is never a dependency of the toolbox, its tests or CI: it pulls
PyTorch. Install it in a separate environment::

    python -m venv venv-peer
    venv-peer/bin/pip install tsfast==0.5.0    # PyTorch >= 2.1 comes with it

(a CPU-only PyTorch wheel, installed first, avoids the GPU libraries). Then
run this script with the toolbox's environment (it reads the benchmark data
with ``sysid_nn.datasets``, as ``bench_field.py`` does) and name the peer's
interpreter; the script starts it for the training::

    python benchmarks/bench_peer.py --peer-python venv-peer/bin/python
    python benchmarks/bench_peer.py --peer-python venv-peer/bin/python \\
        --only wiener_hammerstein --epochs 1 --max-batches 20     # smoke test

The toolbox's numbers come from ``results_field_split.csv`` (default fits,
same split; wall-clock fit times), or ``results_field.csv`` where that has no
rows for the benchmark (the estimators' own held-out tail), or, with
``--ours run``, from fits run here on one pinned core with their CPU time
(``--models`` chooses which, among those of ``bench_field.py``). Every row is stored in
``results_peer.csv`` and ``results_peer.md`` is rebuilt from all stored rows;
without ``--peer-python`` only the toolbox's rows are refreshed (from the
field results with ``--ours csv``), the peer's stored rows are kept.
The full recipe takes about 16-20 CPU-minutes per benchmark on this kind of
machine. ``benchmarks/run.py`` does not run this script: it needs the peer's
environment.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
from _results import read_rows, store_rows

HERE = Path(__file__).resolve().parent
CSV = HERE / "results_peer.csv"
MD = HERE / "results_peer.md"
FIELD_SPLIT_CSV = HERE / "results_field_split.csv"
FIELD_CSV = HERE / "results_field.csv"
SEED = 0
#: Benchmark name -> (output unit, scale from volts); the loaders are in bench_field.
UNITS = {"silverbox": ("mV", 1e3), "wiener_hammerstein": ("mV", 1e3)}
FIELDS = [
    "benchmark",
    "model",
    "budget",
    "epoch",
    "cpu_s",
    "test",
    "unit",
    "rmse",
    "source",
]
#: The recipe (see the module docstring).
RECIPE = {
    "hidden_size": 100,
    "lr": 3e-3,
    "epochs": 10,
    "win_sz": 200,
    "n_skip": 50,
    "bs": 64,
}
PEER_LABEL = "tsfast GRU-100"


# --------------------------------------------------------------- the toolbox side
def _split(benchmark: str, data_home: str | None):
    """Training, validation and test records of ``bench_field --validation split``."""
    from bench_field import BENCHMARKS

    data = BENCHMARKS[benchmark][0](data_home=data_home)
    X, y = data.X_train[0], data.y_train[0]
    n = round(0.8 * len(y))
    return data, (X[:n], y[:n]), (X[n:], y[n:])


def _export(benchmark: str, data_home: str | None, folder: Path) -> Path:
    """Write one benchmark's split as .npz for the peer's interpreter."""
    data, (u_tr, y_tr), (u_va, y_va) = _split(benchmark, data_home)
    arrays = {
        "u_train": u_tr[:, 0],
        "y_train": y_tr,
        "u_valid": u_va[:, 0],
        "y_valid": y_va,
        "n_skip": np.array(data.n_skip),
        "test_names": np.array(data.test_names),
    }
    for i, (X, y) in enumerate(zip(data.X_test, data.y_test, strict=True)):
        arrays[f"u_test{i}"] = X[:, 0]
        arrays[f"y_test{i}"] = y
    path = folder / f"{benchmark}.npz"
    np.savez(path, **arrays)
    return path


def _pin_one_core() -> int:
    """Pin this process to one core (the last one it may use); return it."""
    core = max(os.sched_getaffinity(0))
    os.sched_setaffinity(0, {core})
    return core


def run_ours(benchmark: str, model_names: list[str], data_home) -> list[dict]:
    """Fit the toolbox's models on one pinned core and score them (CPU time)."""
    from bench_field import MODELS, _fit, _simulate
    from sklearn.exceptions import ConvergenceWarning

    _pin_one_core()
    data = _split(benchmark, data_home)[0]
    unit, scale = UNITS[benchmark]
    rows = []
    for name in model_names:
        label, factory = MODELS[name]
        model = factory()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            start = time.process_time()
            _fit(model, data, "split")
            cpu = time.process_time() - start
        for test, X, y in zip(data.test_names, data.X_test, data.y_test, strict=True):
            err = (y - _simulate(model, X, test, benchmark, len(y)))[data.n_skip :]
            rows.append(
                {
                    "benchmark": benchmark,
                    "model": label,
                    "budget": "defaults",
                    "epoch": "",
                    "cpu_s": round(cpu, 1),
                    "test": test,
                    "unit": unit,
                    "rmse": float(np.sqrt(np.mean(err**2)) * scale),
                    "source": "measured here, CPU time on one core",
                }
            )
            print(
                f"{benchmark:>20} {label:>38} {test:>24}: {rows[-1]['rmse']:.4g} "
                f"{unit}, {cpu:.0f} CPU-s",
                flush=True,
            )
    return rows


def read_ours(benchmark: str, model_names: list[str]) -> list[dict]:
    """The toolbox's stored rows: the split run's if any, else the default run's.

    ``results_field_split.csv`` holds fits with the same split as the peer's;
    ``results_field.csv`` fits on the whole training record with the
    estimators' own held-out tail. Both store wall-clock fit times, and
    CPU times since they were measured with them.
    """
    from bench_field import MODELS

    for path in (FIELD_SPLIT_CSV, FIELD_CSV):
        stored = [
            r
            for r in read_rows(path)
            if r["benchmark"] == benchmark and r["model"] in model_names
        ]
        if stored:
            break
    else:
        return []
    return [
        {
            "benchmark": benchmark,
            "model": MODELS[r["model"]][0],
            "budget": "defaults",
            "epoch": "",
            "cpu_s": r.get("cpu_s") or r["fit_s"],
            "test": r["test"],
            "unit": r["unit"],
            "rmse": float(r["rmse"]),
            "source": f"{path.name}, "
            + ("CPU time of the fit" if r.get("cpu_s") else "wall-clock fit time"),
        }
        for r in stored
    ]


def run_peer(peer_python: str, npz: Path, benchmark: str, args) -> list[dict]:
    """Train the recipe in the peer's interpreter; return its per-epoch rows."""
    out = npz.with_suffix(".json")
    command = [
        peer_python,
        str(Path(__file__).resolve()),
        "--worker",
        str(npz),
        str(out),
        "--epochs",
        str(args.epochs),
    ]
    if args.max_batches:
        command += ["--max-batches", str(args.max_batches)]
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    subprocess.run(command, check=True, env=env)
    result = json.loads(out.read_text())
    unit, scale = UNITS[benchmark]
    budget = f"{args.epochs} epochs" + (
        f" x {args.max_batches} batches (smoke test)" if args.max_batches else ""
    )
    return [
        {
            "benchmark": benchmark,
            "model": PEER_LABEL,
            "budget": budget,
            "epoch": epoch["epoch"],
            "cpu_s": round(epoch["cpu_s"], 1),
            "test": test,
            "unit": unit,
            "rmse": rmse * scale,
            "source": f"measured here, CPU time on one core (torch {result['torch']})",
        }
        for epoch in result["epochs"]
        for test, rmse in epoch["rmse"].items()
    ]


# --------------------------------------------------------------- the peer side
def worker(npz: str, out: str, epochs: int, max_batches: int | None) -> None:
    """Train the recipe with tsfast (runs in the peer's interpreter only)."""
    core = _pin_one_core()
    import h5py
    import torch
    from tsfast.training import RNNLearner
    from tsfast.tsdata import create_dls

    torch.set_num_threads(1)
    torch.set_num_interop_threads(1)
    torch.manual_seed(SEED)
    # Test evaluation is not training: its CPU time is taken off the clock.
    clock = {"start": time.process_time(), "excluded": 0.0}
    data = np.load(npz)
    folder = Path(tempfile.mkdtemp(prefix="peer-"))
    files = {}
    for split in ("train", "valid"):
        files[split] = [str(folder / f"{split}.hdf5")]
        with h5py.File(files[split][0], "w") as f:
            f["u"] = data[f"u_{split}"].astype(np.float32)
            f["y"] = data[f"y_{split}"].astype(np.float32)
    dls = create_dls(
        u=["u"],
        y=["y"],
        dataset=files,
        win_sz=RECIPE["win_sz"],
        stp_sz=1,
        bs=RECIPE["bs"],
        n_batches_train=max_batches,  # None: every window once per epoch
    )
    learner = RNNLearner(
        dls,
        n_skip=RECIPE["n_skip"],
        hidden_size=RECIPE["hidden_size"],
        rnn_type="gru",
        lr=RECIPE["lr"],
        show_bar=False,
    )
    names = [str(n) for n in data["test_names"]]
    tests = [
        (
            name,
            torch.from_numpy(data[f"u_test{i}"].astype(np.float32))[None, :, None],
            data[f"y_test{i}"],
        )
        for i, name in enumerate(names)
    ]
    n_skip = int(data["n_skip"])
    log = []

    def log_epoch(epoch, n_epoch, train_loss, val_loss, metrics, pbar):
        trained = time.process_time() - clock["start"] - clock["excluded"]
        start = time.process_time()
        learner.model.eval()
        rmse = {}
        with torch.no_grad():
            for name, u, y in tests:
                y_sim = learner.model(u)[0, :, 0].double().numpy()
                rmse[name] = float(np.sqrt(np.mean((y - y_sim)[n_skip:] ** 2)))
        clock["excluded"] += time.process_time() - start
        log.append({"epoch": epoch + 1, "cpu_s": trained, "rmse": rmse})
        print(
            f"epoch {epoch + 1}/{n_epoch}: {trained:.0f} CPU-s, train loss "
            f"{train_loss:.4g}, valid loss {val_loss:.4g}, test RMSE "
            + ", ".join(f"{k} {v * 1e3:.3g} mV" for k, v in rmse.items()),
            flush=True,
        )

    learner.log_epoch = log_epoch
    print(
        f"tsfast GRU-{RECIPE['hidden_size']} on core {core}: "
        f"{len(dls.train)} batches of {RECIPE['bs']} windows per epoch",
        flush=True,
    )
    learner.fit_flat_cos(epochs, lr=RECIPE["lr"])
    Path(out).write_text(json.dumps({"torch": torch.__version__, "epochs": log}))


# --------------------------------------------------------------- results
def _store(rows: list[dict]) -> None:
    """Replace the stored rows of the same benchmark and model; rebuild the table."""
    merged = store_rows(
        CSV,
        FIELDS,
        rows,
        lambda r: (
            r["benchmark"],
            r["model"] != PEER_LABEL,
            int(r["epoch"] or 0),
            r["model"],
            r["test"],
        ),
    )
    _write_markdown(merged)


def _write_markdown(rows: list[dict]) -> None:
    lines = [
        "# A peer's GRU recipe beside the toolbox",
        "",
        "Test RMSE of the free-run simulation from rest after the benchmark's "
        "`n_skip` samples, against the time of training: CPU seconds on one "
        "pinned core where measured here, wall-clock seconds of the stored "
        "field runs otherwise (the `source` column says which). Peer: tsfast's "
        "GRU recipe (one GRU layer of 100 units, input only, L1 loss, Adam "
        "3e-3, flat-then-cosine schedule, windows of 200 samples, the first 50 "
        "out of the loss), its test error logged after every epoch, on one "
        "pinned core, trained on the first four fifths of the official "
        "training record and validated on its last fifth (the split of "
        "`bench_field.py --validation split`). Toolbox: the estimators' "
        "defaults (`random_state=0`); rows read from `results_field_split.csv` "
        "used the same split, rows from `results_field.csv` the whole record "
        "with the estimators' own held-out tail. "
        f"Written by `benchmarks/bench_peer.py` ({platform.machine()}, "
        f"Python {platform.python_version()}).",
        "",
    ]
    for benchmark in sorted({r["benchmark"] for r in rows}):
        mine = [r for r in rows if r["benchmark"] == benchmark]
        tests = list(dict.fromkeys(r["test"] for r in mine))
        unit = mine[0]["unit"]
        lines += [
            f"## {benchmark} (RMSE in {unit})",
            "",
            "| model | budget | epoch | time (s) | "
            + " | ".join(tests)
            + " | source |",
            "|---|---|---|---|" + "---|" * len(tests) + "---|",
        ]
        runs: dict[tuple, dict] = {}
        for r in mine:
            key = (r["model"], r["budget"], r["epoch"], r["cpu_s"], r["source"])
            runs.setdefault(key, {})[r["test"]] = f"{float(r['rmse']):.3g}"
        for (model, budget, epoch, cpu, source), by_test in runs.items():
            values = " | ".join(by_test.get(t, "") for t in tests)
            lines.append(
                f"| {model} | {budget} | {epoch} | {cpu} | {values} | {source} |"
            )
        lines.append("")
    MD.write_text("\n".join(lines))


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--worker", nargs=2, metavar=("NPZ", "JSON"), help=argparse.SUPPRESS
    )
    parser.add_argument(
        "--peer-python", help="interpreter of the environment with tsfast"
    )
    parser.add_argument(
        "--only",
        default=",".join(UNITS),
        help=f"comma-separated benchmarks among {', '.join(UNITS)}",
    )
    parser.add_argument("--epochs", type=int, default=RECIPE["epochs"])
    parser.add_argument(
        "--max-batches",
        type=int,
        default=None,
        help="batches per epoch (random windows); default: every window once",
    )
    parser.add_argument(
        "--ours",
        choices=["csv", "run", "none"],
        default="csv",
        help="the toolbox's numbers: from results_field_split.csv, fitted here "
        "on one core, or none",
    )
    parser.add_argument(
        "--models", default="tdl,issm,linear", help="the toolbox's models (bench_field)"
    )
    parser.add_argument("--data-home", default=None, help="benchmark data directory")
    args = parser.parse_args(argv)
    if args.worker:
        worker(*args.worker, args.epochs, args.max_batches)
        return
    benchmarks = [b for b in args.only.split(",") if b]
    unknown = set(benchmarks) - set(UNITS)
    if unknown:
        parser.error(f"unknown benchmark: {', '.join(sorted(unknown))}")
    if not args.peer_python and args.ours == "none":
        parser.error(
            "--peer-python (the interpreter with tsfast) is required with --ours none"
        )
    sys.path.insert(0, str(HERE))  # bench_field's loaders and models
    models = [m for m in args.models.split(",") if m]
    with tempfile.TemporaryDirectory(prefix="bench-peer-") as tmp:
        for benchmark in benchmarks:
            if args.peer_python:
                npz = _export(benchmark, args.data_home, Path(tmp))
                _store(run_peer(args.peer_python, npz, benchmark, args))
            if args.ours == "run":
                _store(run_ours(benchmark, models, args.data_home))
            elif args.ours == "csv":
                _store(read_ours(benchmark, models))
    print(MD.read_text())


if __name__ == "__main__":
    main()
