"""Models outside the session: model files and ONNX graphs against the estimator.

Cases: the linear model (``TDLRegressor(hidden_layer_sizes=())``), the TDL
and the ISSM with their default structure, fitted (``n_init=1``,
``max_iter=30``, ``random_state=0``) to two records of the hysteretic
oscillator (2000 samples at dt = 0.01 s), with the displacement measured
(one output) or the displacement and velocity (two outputs). On a third,
unseen record:

- the model file: ``save_model`` then ``load_model``; whether ``simulate``
  and ``predict`` (with their bands) are bit-identical, the file's size and
  the load time (a joblib pickle of the same estimator beside it);
- the ONNX free run (``export_onnx``) under onnxruntime: the largest
  difference to ``simulate`` over the output's standard deviation, and the
  time of one run of the record (``simulate`` includes its run-in to rest,
  8192 samples of zero excitation, which the graph starts after);
- the one-step graph (``step=True``) run sample by sample from Python, the
  loop a user of the step map writes.

Times are the best of 5 runs (CPU time of the process). Run:
``python benchmarks/bench_export.py``; writes ``results_export.md`` beside
this file (about a minute on 2 cores).
"""

from __future__ import annotations

import io
import json
import os
import platform
import tempfile
import time
import warnings
from pathlib import Path

import joblib
import numpy as np

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results_export.md"
N_SAMPLES = 2000


def _best(call, repeats: int = 5) -> float:
    """Best CPU time of ``repeats`` calls, seconds."""
    times = []
    for _ in range(repeats):
        start = time.process_time()
        call()
        times.append(time.process_time() - start)
    return min(times)


def _estimator(kind: str):
    from sysid_nn import ISSMRegressor, TDLRegressor

    budget = {"n_init": 1, "max_iter": 30, "random_state": 0}
    if kind == "linear":
        return TDLRegressor(hidden_layer_sizes=(), **budget)
    return (TDLRegressor if kind == "tdl" else ISSMRegressor)(**budget)


def _case(kind: str, outputs: tuple[str, ...], rec, folder: Path) -> dict:
    import onnxruntime as ort

    from sysid_nn import export_onnx, load_model, save_model

    X = [f[:, None] for f in rec.excitation]
    y = [np.column_stack([rec[o][j] for o in outputs]) for j in range(3)]
    y = [v[:, 0] if len(outputs) == 1 else v for v in y]
    est = _estimator(kind)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the short budget does not converge
        est.fit(X[:2], y[:2])
    u, y_test = X[2], y[2]

    path = folder / "model.sysid"
    save_model(est, path)
    loaded = load_model(path)
    same = all(
        np.array_equal(a, b, equal_nan=True)
        for a, b in (
            *zip(
                loaded.simulate(u, return_std=True),
                est.simulate(u, return_std=True),
                strict=True,
            ),
            *zip(
                loaded.predict(u, y_test, return_std=True),
                est.predict(u, y_test, return_std=True),
                strict=True,
            ),
        )
    )
    pickled = folder / "model.joblib"
    joblib.dump(est, pickled)

    onnx_path, step_path = folder / "model.onnx", folder / "step.onnx"
    export_onnx(est, onnx_path)
    export_onnx(est, step_path, step=True)
    options = {"providers": ["CPUExecutionProvider"]}
    session = ort.InferenceSession(str(onnx_path), **options)
    step = ort.InferenceSession(str(step_path), **options)
    (y_onnx,) = session.run(None, {"u": u})
    y_sim = est.simulate(u).reshape(len(u), -1)
    difference = np.max(np.abs(y_onnx - y_sim) / y_sim.std(axis=0))
    rest = json.loads(step.get_modelmeta().custom_metadata_map["rest_state"])

    def step_loop() -> None:
        state = np.array([rest])
        for t in range(len(u)):
            state, _ = step.run(None, {"state": state, "u": u[t : t + 1]})

    return {
        "model": {"linear": "linear", "tdl": "TDL", "issm": "ISSM"}[kind],
        "outputs": len(outputs),
        "weights": est.coefs_.size,
        "selected": est.selected_,
        "rest": est.rest_output_ is not None,
        "bit_identical": same,
        "file_kb": path.stat().st_size / 1024,
        "load_ms": 1e3 * _best(lambda: load_model(path)),
        "joblib_kb": pickled.stat().st_size / 1024,
        "joblib_load_ms": 1e3 * _best(lambda: joblib.load(pickled)),
        "onnx_kb": onnx_path.stat().st_size / 1024,
        "difference": difference,
        "simulate_ms": 1e3 * _best(lambda: est.simulate(u)),
        "onnx_ms": 1e3 * _best(lambda: session.run(None, {"u": u})),
        "step_loop_ms": 1e3 * _best(step_loop, repeats=2),
    }


def _table(rows: list[dict]) -> str:
    header = (
        "| model | outputs | weights | selected | at rest | "
        "round trip bit-identical | "
        "file (kB) | "
        "load (ms) | joblib file (kB) | joblib load (ms) | ONNX (kB) | "
        "ONNX - simulate (/ output std) | simulate (ms) | ONNX free run (ms) | "
        "step graph in a Python loop (ms) |"
    )
    lines = [header, "|" + "---|" * header.count(" | ") + "---|"]
    for r in rows:
        lines.append(
            f"| {r['model']} | {r['outputs']} | {r['weights']} | {r['selected']} | "
            f"{'yes' if r['rest'] else 'no'} | "
            f"{'yes' if r['bit_identical'] else 'NO'} | {r['file_kb']:.0f} | "
            f"{r['load_ms']:.1f} | {r['joblib_kb']:.0f} | {r['joblib_load_ms']:.1f} | "
            f"{r['onnx_kb']:.0f} | {r['difference']:.1e} | {r['simulate_ms']:.2f} | "
            f"{r['onnx_ms']:.2f} | {r['step_loop_ms']:.0f} |"
        )
    return "\n".join(lines)


def main() -> None:
    import numba
    import onnxruntime

    from sysid_nn import HystereticOscillator
    from sysid_nn._compile import prepare_kernels

    prepare_kernels(show=False)
    rec = HystereticOscillator().generate(3, n_samples=N_SAMPLES, random_state=0)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for kind in ("linear", "tdl", "issm"):
            for outputs in (("displacement",), ("displacement", "velocity")):
                row = _case(kind, outputs, rec, Path(tmp))
                rows.append(row)
                print(row, flush=True)
    load = os.getloadavg()[0]
    text = io.StringIO()
    text.write("# Model files and ONNX export\n\n")
    text.write(
        f"Machine: {platform.machine()}, {os.cpu_count()} cores (load {load:.1f} "
        f"at the end of the run), Python {platform.python_version()}, NumPy "
        f"{np.__version__}, numba {numba.__version__}, onnxruntime "
        f"{onnxruntime.__version__}.\n\n"
    )
    text.write(
        f"Hysteretic oscillator, {N_SAMPLES} samples at dt = 0.01 s; fitted with "
        "`n_init=1, max_iter=30, random_state=0` on two records, run on a "
        "third; `selected` is the fit's `selected_` (the linear model wins some "
        "of these short fits, and the network then carries its weights). Times: "
        "best of 5 (the step loop: of 2), CPU time of the process, "
        f"one run of the {N_SAMPLES}-sample record; `simulate` includes its "
        "run-in to rest (8192 samples of zero excitation) for a model `at rest` "
        "(one whose free run settles there), which the ONNX graph starts after. "
        "Command: `python benchmarks/bench_export.py`.\n\n"
    )
    text.write(_table(rows) + "\n")
    RESULTS.write_text(text.getvalue())
    print(text.getvalue())


if __name__ == "__main__":
    main()
