"""Fit time and peak memory against the record length, and where the time goes.

Cases, each fitted in a fresh subprocess (so that peak memory is its own):

- one hysteretic-oscillator record of N = 10^3, 10^4, 10^5 (and, with
  ``--large``, 10^6) samples at dt = 0.01 s (100 samples per fundamental
  period of the linear oscillator), the excitation's modulation stretched so
  that its intensity is nearly constant over the record; displacement
  measured; ``TDLRegressor()`` and ``ISSMRegressor()`` with their defaults
  (``random_state=0``);
- the two-output field shape: 11 records x 7200 samples, displacement and
  velocity measured, dt = 1/170 s (about 170 samples per fundamental
  period), for both networks.

For each fit: wall time, peak resident memory above the level before the fit
(``ru_maxrss``; it includes the numba kernels' own allocations, which
``tracemalloc`` does not see), and per stage of every restart the iterations,
the time, and how it splits between the solver's evaluations (plain runs for
the cost, runs accumulating the normal equations) and the validation runs of
early stopping. The table gives the slope of log time and log memory against
log N over the one-record cases.

Run: ``python benchmarks/bench_scale.py`` (about half an hour on 2 cores);
``--large`` adds N = 10^6 (long); ``--cases tdl:100000 issm:field`` runs
only those; results are appended to ``results_scale.jsonl`` and the table in
``results_scale.md`` is rebuilt from all results there (the latest of each
case).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results_scale.jsonl"
SIZES = (1_000, 10_000, 100_000)
LARGE = 1_000_000
FIELD = (11, 7200, 1.0 / 170.0)


def _records(case: str):
    """Inputs and outputs of a case: ``"<n>"`` (one record) or ``"field"``."""
    from sysid_nn import HystereticOscillator

    if case == "field":
        n_rec, n, dt = FIELD
        duration = n * dt
        osc = HystereticOscillator(t1=0.1 * duration, t2=0.8 * duration)
        rec = osc.generate(n_rec, n, dt=dt, random_state=0)
        X = [f[:, None] for f in rec.excitation]
        y = [
            np.column_stack([d, v])
            for d, v in zip(rec.displacement, rec.velocity, strict=True)
        ]
        return X, y
    n, dt = int(case), 0.01
    duration = n * dt
    # Intensity rises over the first 5 % and is still at 3/4 of its peak at
    # the end: a long, nearly stationary record.
    osc = HystereticOscillator(t1=0.05 * duration, t2=2.0 * duration)
    rec = osc.generate(1, n, dt=dt, random_state=0)
    return rec.excitation[0][:, None], rec.displacement[0]


def _rss() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def _reset_peak() -> bool:
    """Reset the peak resident set (Linux >= 4.0); False where not allowed."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
    except OSError:
        return False
    return True


def _peak() -> int:
    """Peak resident set since the last reset (or since the start)."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) * 1024
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def _timed(fn, clock: dict, key: str):
    """``fn`` adding its wall time to ``clock[key]`` (and counting its calls
    in ``clock["n_" + key]`` where there is one)."""

    def wrapper(*args, **kwargs):
        start = time.perf_counter()
        try:
            return fn(*args, **kwargs)
        finally:
            clock[key] += time.perf_counter() - start
            if "n_" + key in clock:
                clock["n_" + key] += 1

    return wrapper


def _instrument(est, log: list):
    """Record per stage: iterations, time, and its split into evaluations."""
    from sysid_nn._engine import _solvers, _training

    clock = {"resid": 0.0, "n_resid": 0, "normal": 0.0, "n_normal": 0}
    clock.update(track=0.0, n_track=0)

    def timed(name, fn):
        return _timed(fn, clock, name)

    _solvers._Objective.residuals = timed("resid", _solvers._Objective.residuals)
    _solvers._Objective.normal_equations = timed(
        "normal", _solvers._Objective.normal_equations
    )
    _training._Tracker.__call__ = timed("track", _training._Tracker.__call__)
    restart = {"k": -1}
    fit_stages = est._fit_stages

    def fit_stages_logged(train, val, run, stop):
        restart["k"] = run.k
        return fit_stages(train, val, run, stop)

    est._fit_stages = fit_stages_logged
    for name, solve in list(_training._SOLVERS.items()):

        def logged(objective, w, iters, tol, tracker, stall=None, solve=solve):
            before = dict(clock)
            start = time.perf_counter()
            out = solve(objective, w, iters, tol, tracker, stall)
            entry = {k: clock[k] - before[k] for k in clock}
            entry.update(
                restart=restart["k"],
                seg=int(min(objective.seg, 10**9)),
                rows=len(objective.rows),
                budget=int(iters),
                iters=int(out[1]),
                seconds=time.perf_counter() - start,
                early_stop=bool(tracker.stopped),
            )
            log.append(entry)
            print(json.dumps({"stage": entry}), flush=True)
            return out

        _training._SOLVERS[name] = logged


def _worker(kind: str, case: str, params: dict) -> dict:
    from sysid_nn import ISSMRegressor, TDLRegressor

    cls = {"tdl": TDLRegressor, "issm": ISSMRegressor}[kind]
    X, y = _records(case)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        # Compile (or load) the kernels outside the measurement.
        Xw = [x[:300] for x in X] if isinstance(X, list) else X[:300]
        yw = [v[:300] for v in y] if isinstance(y, list) else y[:300]
        cls(n_init=1, max_iter=2, random_state=0).fit(Xw, yw)
        log: list = []
        est = cls(random_state=0, **params)
        _instrument(est, log)
        after_fit = est._after_fit
        phases = {}

        def after_fit_timed(train, val):
            start = time.perf_counter()
            after_fit(train, val)
            phases["after_fit"] = time.perf_counter() - start

        est._after_fit = after_fit_timed
        reset = _reset_peak()
        rss_before = _rss()
        start, cpu = time.perf_counter(), time.process_time()
        est.fit(X, y)
        seconds = time.perf_counter() - start
        cpu = time.process_time() - cpu
    peak = _peak()
    n = sum(len(x) for x in X) if isinstance(X, list) else len(X)
    return {
        "kind": kind,
        "case": case,
        "params": params,
        "peak_since_fit_start": reset,
        "n_samples": n,
        "n_weights": len(est.coefs_),
        "seconds": seconds,
        "cpu_seconds": cpu,
        "restart_seconds": est.fit_time_,
        "after_fit_seconds": phases.get("after_fit", 0.0),
        "peak_rss_above_start": max(0, peak - rss_before),
        "rss_before": rss_before,
        "n_iter": int(est.n_iter_),
        "restart_scores": [float(v) for v in est.restart_scores_],
        "best_validation_score": est.best_validation_score_,
        "stages": log,
        "when": time.strftime("%Y-%m-%d %H:%M:%S"),
        "load_average": os.getloadavg()[0],
    }


def _costs(sizes) -> dict:
    """Thread CPU time of one solver evaluation against N, in this process.

    Best of three of a normal-equations run and of a plain run (one-step and
    100-sample shooting objectives: a free run of briefly trained weights may
    stop early at a divergence) with the default networks fitted briefly to
    the record's start: the per-iteration cost, free of the machine's load.
    """
    from sysid_nn import ISSMRegressor, TDLRegressor
    from sysid_nn._engine._solvers import _Objective

    out = {"kind": "costs", "case": "costs", "rows": []}
    X, y = _records(str(max(sizes)))
    for name, cls in (("tdl", TDLRegressor), ("issm", ISSMRegressor)):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            est = cls(n_init=1, max_iter=1, random_state=0).fit(X[:2000], y[:2000])
        for n in sizes:
            data = est._stack([X[:n]], [y[:n, None]])
            n_res = len(data.modelled) * est.n_outputs_
            for seg in (1, 100):
                obj = _Objective(est, data, seg, est._penalty_mask(), n_res)
                best = {"normal": np.inf, "plain": np.inf}
                for _ in range(3):
                    for what, fn in (
                        ("normal", obj.normal_equations),
                        ("plain", obj.residuals),
                    ):
                        obj._cache_w = None
                        start = time.thread_time()
                        fn(est.coefs_)
                        best[what] = min(best[what], time.thread_time() - start)
                assert np.all(np.isfinite(obj.residuals(est.coefs_)))
                out["rows"].append({"kind": name, "n": n, "seg": seg, **best})
                print(json.dumps(out["rows"][-1]), flush=True)
    return out


#: Options of the capped ``sysid-nn fit`` run of ``--csv``: one restart and a
#: few iterations per stage, so that the run takes minutes, not hours.
CSV_OPTIONS = "--n-init 1 --max-iter 10"


def _write_csv(n: int, path: Path) -> None:
    """The one-record case of ``n`` samples as a CSV file, as users keep it."""
    import pandas as pd

    X, y = _records(str(n))
    frame = {"t": np.arange(n) * 0.01, "excitation": X[:, 0], "displacement": y}
    pd.DataFrame(frame).to_csv(path, index=False)


def _csv_worker(n: str, path: str, options: str) -> dict:
    """``sysid-nn fit`` on ``path`` in this process: time per stage, peak memory."""
    from sysid_nn._analysis import _uncertainty, cli

    labels = ("read CSV", "fit (restarts, selection, covariance)",
              "of which: covariance of the bands", "score held-out part",
              "save model")  # fmt: skip
    stages = dict.fromkeys(labels, 0.0)

    def timed(module, name, label):
        setattr(module, name, _timed(getattr(module, name), stages, label))

    timed(cli, "_read_records", "read CSV")
    timed(cli, "_fit", "fit (restarts, selection, covariance)")
    timed(_uncertainty, "fit_covariance", "of which: covariance of the bands")
    timed(cli, "_scores", "score held-out part")
    timed(cli, "_write_atomic", "save model")
    save = str(Path(path).with_suffix(".joblib"))
    argv = ["fit", path, "--input", "excitation", "--output", "displacement"]
    argv += [*options.split(), "--save", save, "--overwrite", "--verbose"]
    reset = _reset_peak()
    rss_before = _rss()
    start, cpu = time.perf_counter(), time.process_time()
    code = cli.main(argv)
    seconds, cpu = time.perf_counter() - start, time.process_time() - cpu
    # Imports done on the way (pandas, scikit-learn, the compiled kernels).
    stages["the rest (imports, checks)"] = seconds - sum(
        v for k, v in stages.items() if not k.startswith("of which")
    )
    return {
        "kind": "csv",
        "case": n,
        "params": {"options": options},
        "exit_code": code,
        "seconds": seconds,
        "cpu_seconds": cpu,
        "stages": stages,
        "peak_since_fit_start": reset,
        "peak_rss": _peak(),
        "peak_rss_above_start": max(0, _peak() - rss_before),
        "rss_before": rss_before,
        "when": time.strftime("%Y-%m-%d %H:%M:%S"),
        "load_average": os.getloadavg()[0],
    }


def _run_csv(n: int, options: str) -> dict:
    """Write an ``n``-sample CSV, fit it by the command line in a subprocess.

    The subprocess's progress lines (stderr) are kept with the time they
    appeared, to show that a long fit reports as it goes.
    """
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"record_{n}.csv"
        _write_csv(n, path)
        size = path.stat().st_size
        cmd = [sys.executable, __file__, "--csv-worker", str(n), str(path), options]
        env = dict(os.environ, PYTHONPATH=str(HERE.parent))
        start = time.perf_counter()
        proc = subprocess.Popen(
            cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env
        )
        progress = []
        for line in proc.stderr:
            progress.append([round(time.perf_counter() - start, 1), line.rstrip()])
        out = proc.stdout.read()
        if proc.wait() != 0:
            raise RuntimeError("\n".join(p[1] for p in progress))
    result = json.loads(out.strip().splitlines()[-1])["result"]
    result.update(csv_bytes=size, progress=progress, summary=out.splitlines()[:-1])
    return result


def _run_case(kind: str, case: str) -> dict:
    out = subprocess.run(
        [sys.executable, __file__, "--worker", kind, case, "{}"],
        capture_output=True,
        text=True,
        env=dict(os.environ, PYTHONPATH=str(HERE.parent)),
    )
    if out.returncode != 0:
        raise RuntimeError(out.stderr)
    return json.loads(out.stdout.strip().splitlines()[-1])["result"]


def _latest() -> dict:
    latest = {}
    if RESULTS.exists():
        for line in RESULTS.read_text().splitlines():
            r = json.loads(line)
            latest[(r["kind"], r["case"], json.dumps(r.get("params", {})))] = r
    return latest


def _cpu_times(rows) -> tuple[list, list]:
    """N and CPU time of the fits that recorded it."""
    timed = [r for r in rows if "cpu_seconds" in r]
    return [r["n_samples"] for r in timed], [r["cpu_seconds"] for r in timed]


def _cpu(r: dict) -> str:
    return f"{r['cpu_seconds']:.1f}" if "cpu_seconds" in r else "-"


def _mb(nbytes: int) -> str:
    return f"{nbytes / 2**20:.0f}" if nbytes >= 2**20 else "< 1"


def _slope(xs, ys) -> str:
    if len(xs) < 2:
        return "-"
    return f"{np.polyfit(np.log(xs), np.log(ys), 1)[0]:.2f}"


def _above_mb(rows) -> tuple[list, list]:
    """N and peak memory of the fits whose peak is at least 1 MB."""
    big = [r for r in rows if r["peak_rss_above_start"] >= 2**20]
    return [r["n_samples"] for r in big], [r["peak_rss_above_start"] for r in big]


def _stage_summary(r: dict) -> list[str]:
    """Per-stage totals over the restarts of one fit."""
    by_seg: dict = {}
    for st in r["stages"]:
        e = by_seg.setdefault(st["seg"], dict(iters=0, seconds=0.0, n=0, budget=0))
        for k in ("iters", "seconds", "resid", "n_resid", "normal", "n_normal"):
            e[k] = e.get(k, 0) + st[k]
        e["track"] = e.get("track", 0.0) + st["track"]
        e["n"] += 1
        e["budget"] = st["budget"]
        e["stopped"] = e.get("stopped", 0) + int(st["early_stop"])
    rows = []
    for seg, e in sorted(by_seg.items()):
        label = "free run" if seg >= 10**9 else ("one step" if seg == 1 else seg)
        per_normal = e["normal"] / max(1, e["n_normal"])
        per_resid = e["resid"] / max(1, e["n_resid"])
        case = r["case"] + (f" `{json.dumps(r['params'])}`" if r["params"] else "")
        rows.append(
            f"| {r['kind'].upper()} | {case} | {label} | {e['budget']} | "
            f"{e['iters']} / {e['n']} | {e['seconds']:.1f} | "
            f"{e['seconds'] / max(1, e['iters']):.3f} | {per_normal * 1e3:.1f} | "
            f"{per_resid * 1e3:.1f} | {e['track']:.1f} | {e['stopped']} |"
        )
    return rows


def _run_costs(r: dict) -> tuple[float, float]:
    """Mean seconds of one normal-equations run and of one plain run."""
    st = r["stages"]
    normal = sum(x["normal"] for x in st) / max(1, sum(x["n_normal"] for x in st))
    plain = sum(x["resid"] for x in st) / max(1, sum(x["n_resid"] for x in st))
    return normal, plain


def _cost_lines(r: dict) -> list[str]:
    lines = [
        "",
        "## CPU time of one solver evaluation against N",
        "",
        "Thread CPU time (best of three, free of the machine's load) of one "
        "normal-equations run (forward, sensitivities, `J'J` and `J'r`: once "
        "per accepted Levenberg-Marquardt step) and of one plain run (the cost "
        "of a trial step), default networks, one record; `python "
        "benchmarks/bench_scale.py --costs`.",
        "",
        "| network | stage | N | normal equations (s) | (us / sample) | plain "
        "run (s) | (us / sample) |",
        "|---|---|---|---|---|---|---|",
    ]
    groups: dict = {}
    for row in r["rows"]:
        groups.setdefault((row["kind"], row["seg"]), []).append(row)
    for (kind, seg), rows in groups.items():
        stage = "one step" if seg == 1 else f"shooting, {seg} samples"
        for row in rows:
            lines.append(
                f"| {kind.upper()} | {stage} | {row['n']:,} | {row['normal']:.4f} | "
                f"{row['normal'] / row['n'] * 1e6:.2f} | {row['plain']:.4f} | "
                f"{row['plain'] / row['n'] * 1e6:.2f} |"
            )
        ns = [row["n"] for row in rows]
        lines.append(
            f"| {kind.upper()} | {stage} | slope (log-log) | "
            f"{_slope(ns, [row['normal'] for row in rows])} | | "
            f"{_slope(ns, [row['plain'] for row in rows])} | |"
        )
    return lines


#: How the current rows compare with the schedule before segment subsets and
#: successive halving of the restarts (written by hand from the runs named).
SCHEDULE_NOTE = """
## Segment subsets and successive halving of the restarts

Measured on 2 shared cores at load 11-19 (other work running), so CPU times,
and ratios only between runs made at the same time. `before (eb0797c)` rows
ran the previous schedule's code next to the current code:

| case | CPU before (s) | CPU now (s) | ratio | iterations, all restarts, \
before / now | validation loss of the chosen restart, before / now |
|---|---|---|---|---|---|
| TDL, 10^5 samples | 141.1 | 56.9 | 0.40 | 885 / 682 | not recorded |
| TDL, field shape (11 x 7200 x 2) | 103.8 | 36.9 | 0.36 | 486 / 352 | \
6.98e-5 / 7.87e-5 (restart 2 both) |
| ISSM, field shape, halving only | 124.8 | 107.6 | 0.86 (not the same run) | \
733 / 642 | - / 2.38e-5 |

- On 2 cores at load 1-2 with `n_jobs=2` (wall time, runs one after the
  other): TDL 10^5 samples 30.3 s against 76.5 s before (0.40); TDL field
  shape 22.2 s against 53.7 s (0.41).
- The TDL's stages before the free run see 30 000 samples of the 90 000
  (10^5) and 64 800 (field) training samples; validation runs see all. At
  10^5 the validation free runs over the whole record are now 42 % of the
  fit (203 of 486 s wall), the next cost to cut.
- The ISSM sees whole records (its unmeasured states carry over between
  segments); only the halving saves time, and its one-step stage, 100
  iterations in every restart, is 60 % of its fit.
- ISSM, N = 10^5 (halving only): 68.9 s CPU; 120.1 s in an earlier session
  with the previous schedule, at another load (not a ratio).
- N = 10^6, default TDL (at load 1-4): 463 s wall, 452 s CPU, peak memory
  191 MB above the start. Validation free runs over the whole record took
  57 % of the stage time (262 of 456 s); the chosen restart's free run used
  its whole budget of 150 iterations (207 s).
"""


def _write_table() -> str:
    every = _latest()
    costs = every.pop(("costs", "costs", "{}"), None)
    csv_runs = [every.pop(k) for k in sorted(every) if k[0] == "csv"]
    latest = {(k, c): r for (k, c, p), r in every.items() if p == "{}"}
    capped = [r for (k, c, p), r in sorted(every.items()) if p != "{}"]
    lines = [
        "# Scale: fit time and memory against the record length",
        "",
        f"Machine: {platform.machine()}, {os.cpu_count()} cores shared with other "
        f"work (load average at each fit in the last column), Python "
        f"{platform.python_version()}. Defaults of each network, "
        "`random_state=0`, one process per fit; restarts run one after another "
        "(`n_jobs=None`). Peak memory: peak resident set above the level before "
        "the fit (data and compiled kernels already loaded). Command: "
        "`python benchmarks/bench_scale.py [--large]`.",
        "",
        "## One record",
        "",
        "Fit (s) is wall time; CPU (s) the process's CPU time, what the fit "
        "would take on an idle core (where recorded).",
        "",
        "| network | N | weights | fit (s) | CPU (s) | peak memory above start "
        "(MB) | iterations (chosen restart) | load |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for kind in ("tdl", "issm"):
        rows = sorted(
            (r for (k, c), r in latest.items() if k == kind and c != "field"),
            key=lambda r: r["n_samples"],
        )
        for r in rows:
            lines.append(
                f"| {kind.upper()} | {r['n_samples']:,} | {r['n_weights']} | "
                f"{r['seconds']:.1f} | {_cpu(r)} | "
                f"{_mb(r['peak_rss_above_start'])} | "
                f"{r['n_iter']} | {r['load_average']:.1f} |"
            )
        ns = [r["n_samples"] for r in rows]
        lines.append(
            f"| {kind.upper()} slope (log-log) | | | "
            f"{_slope(ns, [r['seconds'] for r in rows])} | "
            f"{_slope(*_cpu_times(rows))} | {_slope(*_above_mb(rows))} | | |"
        )
    if costs:
        lines += _cost_lines(costs)
    lines += [
        "",
        "## Cost of one solver evaluation against N, within the fits",
        "",
        "Wall time, so under the machine's load. "
        "Mean over the whole fit of one normal-equations run (forward, "
        "sensitivities and `J'J`, `J'r`) and of one plain run (a trial step's "
        "cost), in microseconds per sample, and the slope of log time against "
        "log N; rows with a capped budget (N = 10^6) are included.",
        "",
        "| network | N | budget | normal eq. run (us / sample) | plain run "
        "(us / sample) |",
        "|---|---|---|---|---|",
    ]
    for kind in ("tdl", "issm"):
        rows = [r for (k, c), r in latest.items() if k == kind and c != "field"]
        rows += [
            r
            for r in capped
            if r["kind"] == kind and r["case"] != "field" and r["stages"]
        ]
        rows.sort(key=lambda r: r["n_samples"])
        costs = [_run_costs(r) for r in rows]
        for r, (normal, plain) in zip(rows, costs, strict=True):
            budget = json.dumps(r.get("params")) if r.get("params") else "default"
            lines.append(
                f"| {kind.upper()} | {r['n_samples']:,} | {budget} | "
                f"{normal / r['n_samples'] * 1e6:.2f} | "
                f"{plain / r['n_samples'] * 1e6:.2f} |"
            )
        ns = [r["n_samples"] for r in rows]
        lines.append(
            f"| {kind.upper()} slope (log-log) | | | "
            f"{_slope(ns, [c[0] for c in costs])} | "
            f"{_slope(ns, [c[1] for c in costs])} |"
        )
    if capped:
        lines += [
            "",
            "## Capped budgets, and other schedules",
            "",
            "Rows whose parameters name a `schedule` were measured with an "
            "earlier training schedule (the code of that commit), in the same "
            "run as the default row of their case: compare their CPU times.",
            "",
            "| network | N | parameters | fit (s) | CPU (s) | peak memory above "
            "start (MB) | iterations | load |",
            "|---|---|---|---|---|---|---|---|",
        ]
        for r in capped:
            lines.append(
                f"| {r['kind'].upper()} | {r['n_samples']:,} | "
                f"`{json.dumps(r['params'])}` | {r['seconds']:.1f} | {_cpu(r)} | "
                f"{_mb(r['peak_rss_above_start'])} | {r['n_iter']} | "
                f"{r['load_average']:.1f} |"
            )
        for kind in ("tdl", "issm"):
            rows = [
                r
                for r in capped
                if r["kind"] == kind
                and r["case"] != "field"
                and "schedule" not in r["params"]
            ]
            lines.append(
                f"| {kind.upper()} memory slope (log-log) | | | | | "
                f"{_slope(*_above_mb(rows))} | | |"
            )
    lines += [
        "",
        "## Field shape: 11 records x 7200 samples, two outputs",
        "",
        "| network | fit (s) | CPU (s) | restarts (s) | after the restarts (s) | "
        "peak memory above start (MB) | load |",
        "|---|---|---|---|---|---|---|",
    ]
    for kind in ("tdl", "issm"):
        r = latest.get((kind, "field"))
        if r:
            lines.append(
                f"| {kind.upper()} | {r['seconds']:.1f} | {_cpu(r)} | "
                f"{r['restart_seconds']:.1f} | {r['after_fit_seconds']:.1f} | "
                f"{_mb(r['peak_rss_above_start'])} | {r['load_average']:.1f} |"
            )
    lines += [
        "",
        "## Where the time goes",
        "",
        "Per stage, summed over the restarts: the stage's iteration budget, the "
        "iterations used / restarts, its time, the time per iteration, the mean "
        "time of one normal-equations run (forward + sensitivities + `J'J`) and "
        "of one plain run (the cost of a trial step), the time spent in the "
        "validation runs of early stopping, and how many restarts early stopping "
        "ended in that stage.",
        "",
        "| network | case | stage | budget | iterations / restarts | time (s) | "
        "s / iteration | normal eq. run (ms) | plain run (ms) | validation (s) | "
        "early stops |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for key in sorted(
        latest,
        key=lambda k: (k[0], k[1] == "field", int(k[1]) if k[1].isdigit() else 0),
    ):
        lines += _stage_summary(latest[key])
    for r in capped:
        lines += _stage_summary(r)
    lines += _csv_lines(csv_runs)
    text = "\n".join(lines) + "\n" + SCHEDULE_NOTE
    (HERE / "results_scale.md").write_text(text)
    return text


def _csv_lines(runs: list) -> list[str]:
    """The section on ``sysid-nn fit`` of a long CSV file (``--csv``)."""
    if not runs:
        return []
    lines = [
        "",
        "## `sysid-nn fit` on a long CSV file",
        "",
        "One record of N samples (the one-record case above) written as a CSV "
        "file with columns t, excitation, displacement, fitted by the command "
        "line in a fresh process with a capped budget: `python "
        "benchmarks/bench_scale.py --csv N [--csv-options ...]`. Wall time "
        "per stage of the command; peak memory is the whole process's peak "
        "resident set (imports, compiled kernels, data and fit) and its rise "
        "during the command.",
        "",
        "| N | CSV (MB) | options | stage | time (s) |",
        "|---|---|---|---|---|",
    ]
    for r in runs:
        head = f"| {int(r['case']):,} | {r['csv_bytes'] / 2**20:.0f} | "
        head += f"`{r['params']['options']}` | "
        for stage, seconds in r["stages"].items():
            lines.append(f"{head}{stage} | {seconds:.1f} |")
        lines.append(f"{head}whole command (CPU {r['cpu_seconds']:.1f} s) | "
                     f"{r['seconds']:.1f} |")  # fmt: skip
    lines += [
        "",
        "| N | peak resident set (MB) | rise during the command (MB) | "
        "progress lines | load |",
        "|---|---|---|---|---|",
    ]
    for r in runs:
        lines.append(
            f"| {int(r['case']):,} | {_mb(r['peak_rss'])} | "
            f"{_mb(r['peak_rss_above_start'])} | {len(r['progress'])} | "
            f"{r['load_average']:.1f} |"
        )
    last = runs[-1]
    lines += ["", f"Progress of the last run (N = {int(last['case']):,}), "
              "seconds since the start of the process:", "", "```"]  # fmt: skip
    lines += [f"{t:7.1f}  {text[:150]}" for t, text in last["progress"]]
    lines += ["```"]
    return lines


def main(argv: list[str] | None = None) -> str:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--large", action="store_true", help="add N = 10^6")
    parser.add_argument("--cases", nargs="*", help="e.g. tdl:100000 issm:field")
    parser.add_argument("--table", action="store_true", help="only rebuild table")
    parser.add_argument(
        "--costs", action="store_true", help="CPU time of one evaluation against N"
    )
    parser.add_argument(
        "--csv",
        type=int,
        metavar="N",
        help="`sysid-nn fit` on an N-sample CSV file (capped: --csv-options)",
    )
    parser.add_argument("--csv-options", default=CSV_OPTIONS, metavar="OPTIONS")
    parser.add_argument("--worker", nargs=3, help=argparse.SUPPRESS)
    parser.add_argument("--csv-worker", nargs=3, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.csv_worker:
        result = _csv_worker(*args.csv_worker)
        print(json.dumps({"result": result}))
        return ""
    if args.worker:
        kind, case, params = args.worker
        result = _worker(kind, case, json.loads(params))
        with RESULTS.open("a") as f:
            f.write(json.dumps(result) + "\n")
        print(json.dumps({"result": result}))
        return ""
    if args.csv:
        result = _run_csv(args.csv, args.csv_options)
        with RESULTS.open("a") as f:
            f.write(json.dumps(result) + "\n")
    elif args.costs:
        result = _costs([*SIZES, LARGE])
        with RESULTS.open("a") as f:
            f.write(json.dumps(result) + "\n")
    elif not args.table:
        if args.cases:
            cases = [tuple(c.split(":")) for c in args.cases]
        else:
            sizes = [*SIZES, LARGE] if args.large else list(SIZES)
            cases = [(k, str(n)) for n in sizes for k in ("tdl", "issm")]
            cases += [("tdl", "field"), ("issm", "field")]
        for kind, case in cases:
            r = _run_case(kind, case)
            print(
                f"{kind} {case}: {r['seconds']:.1f} s, "
                f"{r['peak_rss_above_start'] / 2**20:.0f} MB",
                flush=True,
            )
    text = _write_table()
    print(text)
    return text


if __name__ == "__main__":
    main()
