"""Accuracy of the identified models on unseen realisations (paper section 4).

Trains the estimators on realisations of the hysteretic oscillator under the
protocols of ``_protocol.py`` (P1: one training record of typical amplitude,
P5: five; two validation records; the same 25 unseen test records) at
dt = 0.01 s and dt = 0.03 s, and scores on the test records:

* free-run NRMSE from rest (``simulate(X)``, the model at its own rest): mean,
  median, worst; the number of divergent runs (NaN output);
* free-run NRMSE started at t = 2 s (sample 200 at dt = 0.01) from the
  measured outputs (TDL: ``initial_outputs``; ISSM: ``initial_state`` with the
  measured outputs as the first p states, zeros elsewhere), scored from there;
* free-run NRMSE of the oscillatory part: both signals zero-phase high-passed
  above 0.3 Hz (4th-order Butterworth, ``filtfilt``);
* k-step prediction NRMSE, k = 1, 10, 50 (``predict(X, y, horizon=k)``);
* pass rates of the whiteness and cross-correlation tests of the one-step
  residuals (max lag 25, 5 % level);
* fit time.

With measurement noise (P1 and P5, dt = 0.01, two pool seeds; white noise of
0.1 %, 1 % and 3 % of each output's standard deviation on the training and
validation records, the test records noise-free) the free-run scores are
measured again.

NRMSE = RMS error / standard deviation of the measured signal, per record;
for the ISSM with displacement and velocity measured the displacement column
is scored. Writes ``results.md`` and ``results_accuracy.csv`` next to this
file (``--quick`` writes to the temporary directory instead).

Usage::

    python benchmarks/bench_accuracy.py                 # full run
    python benchmarks/bench_accuracy.py --quick         # smoke test, ~1 min
    python benchmarks/bench_accuracy.py --protocols P1 --dt 0.01 --models tdl,linear
    python benchmarks/run.py accuracy
"""

from __future__ import annotations

import argparse
import csv
import datetime
import os
import platform
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import _protocol as P  # noqa: E402

from sysid_nn import ISSMRegressor, TDLRegressor  # noqa: E402
from sysid_nn.study import PAPER_ISSM, PAPER_TDL  # noqa: E402
from sysid_nn.study._report import blas_kernels  # noqa: E402

DEFAULT_SEED = 2024
ROBUSTNESS_SEEDS = (2025, 2026)
ROBUSTNESS_MODELS = ("tdl", "issm_xv", "linear")
#: Measurement-noise levels (fraction of each output's standard deviation) on
#: the training and validation outputs, at dt = 0.01, for both protocols and
#: the main seed plus the first robustness seed. The ISSM's TDL start is left
#: out: under noise it is the TDL network itself.
NOISE_LEVELS = (0.001, 0.01, 0.03)
NOISE_SEEDS = (DEFAULT_SEED, ROBUSTNESS_SEEDS[0])
NOISE_MODELS = ("tdl", "issm_xv", "issm_x", "linear")
#: Length of the measured window the initial state is estimated from
#: (``simulate(X, y_init=y[:k])``), in seconds: the state-initialisation window.
T_INIT_WINDOW = 1.0
N_JOBS = 2
RANDOM_STATE = 0

# name -> (label, estimator family, measured outputs, constructor kwargs)
MODELS = {
    "tdl": ("TDL default", "tdl", "x", {}),
    "tdl_paper": ("TDL paper (6/5 lags, 9 logistic, one-step)", "tdl", "x", PAPER_TDL),
    "issm_xv": ("ISSM default, X+V measured (p=2)", "issm", "xv", {}),
    "issm_x": ("ISSM default, X only (p=1)", "issm", "x", {}),
    "issm_x_tdl": (
        "ISSM TDL start, X only (p=1; init='tdl', 9 tanh)",
        "issm",
        "x",
        {"init": "tdl", "hidden_layer_sizes": (9,)},
    ),
    "issm_paper": (
        "ISSM paper (3 states, 7 logistic, one-step, p=2)",
        "issm",
        "xv",
        PAPER_ISSM,
    ),
    "linear": (
        "Linear (TDL hidden_layer_sizes=())",
        "tdl",
        "x",
        {"hidden_layer_sizes": ()},
    ),
}
QUICK_MODELS = ("tdl", "linear")
#: The default networks (and the ISSM's TDL start) the targets speak of.
NETWORK_MODELS = ("tdl", "issm_xv", "issm_x", "issm_x_tdl")
FLOOR_LABEL = (
    "Reference: true oscillator from the true state, excitation interpolated "
    "linearly between the kept samples"
)

PROTOCOL_TEXT = """\
Pool of {n_pool} realisations of `HystereticOscillator().generate(n, n_samples=2000,
dt=0.01, random_state=seed)` (seed {seed}), ordered by closeness of the peak
displacement to the pool's median peak. P1 trains on the first record, P5 on the
first five; the next {n_val} validate (`X_val, y_val`); the test set is the {n_test}
records after the first {n_reserved} (the same for P1 and P5). dt = 0.03 uses every
third sample (`x[::3]`). Every estimator has `random_state=0, n_jobs=2` and otherwise
the parameters named in the row.

Scores are NRMSE (RMS error / std of the measured signal) per test record,
displacement only:

- free run from rest (`simulate(X)`: the model at its own rest under zero
  excitation; mean, median, worst; `div` = divergent
  runs, scored as infinite); ratio = its median / the linear model's median;
- free run started at t0 = 2 s from measured outputs, scored from t0 (TDL:
  `initial_outputs` = the measured outputs before t0; ISSM: `initial_state` = the
  measured outputs at t0 - dt as the first p states, zeros elsewhere), with the
  measured excitation before t0 (`initial_inputs`); for the ISSM's TDL start,
  whose other states are past outputs and excitation, zeros there are a jump
  from rest to the measured output, and the filtered state below is the way
  to start it;
- ISSM only: the same with the unmeasured states started at the one-step
  predictor's estimate from the measurements before t0
  (`predict_states(X[:k0], y[:k0])`, "filtered state");
- the record cut at t0 (starting in motion, nothing known before it), its
  initial state estimated from the measured outputs over the first
  {t_window:g} s (`simulate(X[k0:], y_init=y[k0:k0 + k])`, the
  state-initialisation window), scored after the window ("estimated start");
- the free run from rest with both signals zero-phase high-passed above 0.3 Hz
  (4th-order Butterworth, `filtfilt`): the oscillatory part without the drift;
- k-step prediction medians (`predict(X, y, horizon=k)`);
- percentage of test records whose one-step residuals pass the whiteness test
  and the cross-correlation test (both lag sides), max lag 25, 5 % level.

At dt = 0.03 the excitation between kept samples is lost to every model. The
reference row runs the true equations on the excitation interpolated linearly
between the kept samples: k-step predictions from the true state
(displacement, velocity and the hysteretic component, which no model sees),
the free run from rest. It shows what the kept samples allow; it is not a
strict bound, since a model may guess the lost excitation better.

`fit s` is wall-clock training time and `load` the 1-minute load average at the
end of the fit (2 cores shared with other work: fit times above a load of 2 are
inflated)."""


def make_estimator(family: str, kwargs: dict, quick: bool):
    params = dict(kwargs, random_state=RANDOM_STATE, n_jobs=N_JOBS)
    if quick:
        params.update(max_iter=30, n_init=2)
    if family == "tdl":
        return TDLRegressor(**params)
    return ISSMRegressor(**params)


def evaluate(name: str, split: P.Split, quick: bool) -> dict:
    """Fit one model on one split and score it on the test records."""
    label, family, outputs, kwargs = MODELS[name]
    p = 2 if outputs == "xv" else 1
    row = {"model": name, "label": label, "dt": split.dt, "protocol": split.protocol}
    est = make_estimator(family, kwargs, quick)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        t0 = time.perf_counter()
        try:
            est.fit(split.X_train, split.y_train, X_val=split.X_val, y_val=split.y_val)
        except Exception as exc:  # report, do not abort the whole benchmark
            row["error"] = f"{type(exc).__name__}: {exc}"[:200]
            return row
        row["fit_s"] = time.perf_counter() - t0
    row["load_avg_1min"] = os.getloadavg()[0]  # machine load at the end of the fit
    row["fit_warnings"] = ";".join(sorted({type(w.message).__name__ for w in caught}))

    X, Y, dt = split.X_test, split.y_test, split.dt
    k0 = round(P.T0_MEASURED / dt)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sim = est.simulate(X)
        sim_k0 = [
            P.simulate_from_measured(est, x, y, k0, p)
            for x, y in zip(X, Y, strict=True)
        ]
        # The record cut at t0: it starts in motion, from an unknown state.
        kw = round(T_INIT_WINDOW / dt)
        sim_est = est.simulate([x[k0:] for x in X], y_init=[y[k0 : k0 + kw] for y in Y])
        if family == "issm":
            sim_kf = [
                P.simulate_from_measured(est, x, y, k0, p, filtered=True)
                for x, y in zip(X, Y, strict=True)
            ]
        preds = {k: est.predict(X, Y, horizon=k) for k in P.HORIZONS}

    free = [P.record_nrmse(y, s) for y, s in zip(Y, sim, strict=True)]
    row["n_divergent"] = int(sum(not np.all(np.isfinite(s)) for s in sim))
    row["n_divergent_k0"] = int(sum(not np.all(np.isfinite(s)) for s in sim_k0))
    for key, vals in (
        ("free", free),
        (
            "free_k0",
            [P.record_nrmse(y[k0:], s) for y, s in zip(Y, sim_k0, strict=True)],
        ),
        *(
            [
                (
                    "free_kf",
                    [P.record_nrmse(y[k0:], s) for y, s in zip(Y, sim_kf, strict=True)],
                )
            ]
            if family == "issm"
            else []
        ),
        (
            "free_est",
            [
                P.record_nrmse(y[k0 + kw :], s[kw:])
                for y, s in zip(Y, sim_est, strict=True)
            ],
        ),
        (
            "free_hp",
            [P.record_nrmse_highpass(y, s, dt) for y, s in zip(Y, sim, strict=True)],
        ),
    ):
        for stat, v in P.summary(vals).items():
            row[f"{key}_{stat}"] = v
    for k, pred in preds.items():
        s = P.summary([P.record_nrmse(y, yp) for y, yp in zip(Y, pred, strict=True)])
        row[f"k{k}_median"], row[f"k{k}_mean"] = s["median"], s["mean"]
    tests = [
        P.residual_tests(P.first_col(y) - P.first_col(yp), x)
        for x, y, yp in zip(X, Y, preds[1], strict=True)
    ]
    row["white_pass"] = float(np.mean([t[0] for t in tests]))
    row["xcorr_pass"] = float(np.mean([t[1] for t in tests]))
    row["n_test"] = len(X)
    return row


# ------------------------------------------------------------- reporting
def fmt(v, digits=3) -> str:
    if v is None or (isinstance(v, float) and np.isnan(v)):
        return "-"
    if isinstance(v, float):
        if np.isinf(v):
            return "div"
        return f"{v:.{digits}g}"
    return str(v)


COLUMNS = [
    ("fit s", lambda r: fmt(r.get("fit_s"), 3)),
    ("load", lambda r: fmt(r.get("load_avg_1min"), 2)),
    ("free mean", lambda r: fmt(r.get("free_mean"))),
    ("free median", lambda r: fmt(r.get("free_median"))),
    ("free worst", lambda r: fmt(r.get("free_worst"))),
    ("ratio to linear", lambda r: fmt(r.get("ratio"), 2)),
    ("div", lambda r: fmt(r.get("n_divergent"))),
    ("from t0 median", lambda r: fmt(r.get("free_k0_median"))),
    ("from t0 worst", lambda r: fmt(r.get("free_k0_worst"))),
    ("from t0, filtered state, median", lambda r: fmt(r.get("free_kf_median"))),
    ("estimated start, median", lambda r: fmt(r.get("free_est_median"))),
    (">0.3 Hz median", lambda r: fmt(r.get("free_hp_median"))),
    (">0.3 Hz worst", lambda r: fmt(r.get("free_hp_worst"))),
    ("k=1", lambda r: fmt(r.get("k1_median"))),
    ("k=10", lambda r: fmt(r.get("k10_median"))),
    ("k=50", lambda r: fmt(r.get("k50_median"))),
    ("white %", lambda r: fmt(100 * r["white_pass"], 3) if "white_pass" in r else "-"),
    ("xcorr %", lambda r: fmt(100 * r["xcorr_pass"], 3) if "xcorr_pass" in r else "-"),
]


def add_ratios(rows: list[dict]) -> None:
    groups: dict = {}
    for r in rows:
        key = (r["seed"], r["dt"], r["protocol"], r.get("noise", 0.0))
        groups.setdefault(key, []).append(r)
    for group in groups.values():
        lin = next(
            (r for r in group if r["model"] == "linear" and "free_median" in r), None
        )
        for r in group:
            if lin is not None and "free_median" in r:
                r["ratio"] = r["free_median"] / lin["free_median"]


def table(rows: list[dict]) -> list[str]:
    head = "| model | " + " | ".join(c for c, _ in COLUMNS) + " |"
    lines = [head, "|" + "---|" * (len(COLUMNS) + 1)]
    for r in rows:
        if "error" in r:
            lines.append(
                f"| {r['label']} | fit failed: {r['error']} |"
                + " |" * (len(COLUMNS) - 1)
            )
            continue
        lines.append(f"| {r['label']} | " + " | ".join(f(r) for _, f in COLUMNS) + " |")
    return lines


def find(rows, seed, dt, protocol, model, noise=0.0):
    for r in rows:
        if (r["seed"], r["dt"], r["protocol"], r["model"], r.get("noise", 0.0)) == (
            seed,
            dt,
            protocol,
            model,
            noise,
        ):
            return r if "free_median" in r else None
    return None


def targets(rows: list[dict], seed: int) -> list[str]:
    out = []

    def verdict(ok):
        return "not measured" if ok is None else ("**met**" if ok else "**not met**")

    def ratio_target(model, protocol, limit, extra_div=False):
        r = find(rows, seed, 0.01, protocol, model)
        if r is None or "ratio" not in r:
            return None, ""
        ok = r["ratio"] <= limit and (not extra_div or r["n_divergent"] == 0)
        txt = f"ratio {r['ratio']:.3f} (median {r['free_median']:.4f})"
        if extra_div:
            txt += f", {r['n_divergent']} divergent"
        return ok, txt

    for model, name, limits, div in (
        ("tdl", "TDL default", {"P1": 0.1, "P5": 0.05}, True),
        ("issm_xv", "ISSM default (p=2)", {"P1": 0.05, "P5": 0.03}, False),
    ):
        for protocol, limit in limits.items():
            ok, txt = ratio_target(model, protocol, limit, div)
            cond = f"ratio <= {limit}" + (", no divergent simulation" if div else "")
            out.append(
                f"- dt = 0.01, {protocol}, {name}: {cond}: {verdict(ok)}"
                + (f" ({txt})" if txt else "")
            )
    for model in ("issm_x", "issm_x_tdl"):
        for protocol in P.PROTOCOLS:
            a = find(rows, seed, 0.01, protocol, model)
            b = find(rows, seed, 0.01, protocol, "tdl")
            what = f"- dt = 0.01, {protocol}, {MODELS[model][0]} at least as good as"
            if a is None or b is None:
                out.append(f"{what} the TDL: not measured")
                continue
            # "At least as good": no worse than the TDL beyond rounding (the
            # TDL start runs the TDL network itself, to about 1e-12).
            ok = a["free_median"] <= b["free_median"] * (1 + 1e-6)
            out.append(
                f"{what} the TDL (median free run): {verdict(ok)} "
                f"({a['free_median']:.4f} vs {b['free_median']:.4f})"
            )
    for model in NETWORK_MODELS:
        r = find(rows, seed, 0.03, "P5", model)
        if r is None or "ratio" not in r:
            out.append(
                f"- dt = 0.03, P5, {MODELS[model][0]} better than linear: not measured"
            )
            continue
        out.append(
            f"- dt = 0.03, P5, {MODELS[model][0]} better than linear: "
            f"{verdict(r['ratio'] < 1)} (ratio {r['ratio']:.3f})"
        )
    for dt in (0.01, 0.03):
        for protocol in P.PROTOCOLS:
            lin = find(rows, seed, dt, protocol, "linear")
            for model in NETWORK_MODELS:
                r = find(rows, seed, dt, protocol, model)
                if r is None or lin is None:
                    continue
                # "clearly better": at most half the linear model's median error
                r10, r50 = (
                    r["k10_median"] / lin["k10_median"],
                    r["k50_median"] / lin["k50_median"],
                )
                ok = r10 <= 0.5 and r50 <= 0.5
                floor = find(rows, seed, dt, protocol, "floor")
                ref = (
                    ""
                    if floor is None
                    else f"; reference {floor['k10_median'] / lin['k10_median']:.3f}"
                    f", {floor['k50_median'] / lin['k50_median']:.3f}"
                )
                out.append(
                    f"- dt = {dt}, {protocol}, {MODELS[model][0]}: k-step (10, 50) "
                    f"clearly better than linear (ratio <= 0.5): {verdict(ok)} "
                    f"(ratios {r10:.3f}, {r50:.3f}{ref})"
                )
    r = find(rows, seed, 0.01, "P5", "tdl")
    ok = None if r is None else r["fit_s"] < 60
    out.append(
        "- TDL default fit time, P5, dt = 0.01, under a minute on 2 cores: "
        + verdict(ok)
        + (
            ""
            if r is None
            else f" ({r['fit_s']:.1f} s, 1-min load average {r['load_avg_1min']:.1f})"
        )
    )
    return out


def source_version() -> str:
    """Commit of the tree the estimators were imported from, and uncommitted changes."""
    import subprocess

    def git(*cmd):
        out = subprocess.run(["git", *cmd], cwd=HERE, capture_output=True, text=True)
        return out.stdout.strip() if out.returncode == 0 else ""

    head = git("rev-parse", "--short", "HEAD") or "unknown"
    dirty = git("status", "--porcelain", "--", ":/sysid_nn").splitlines()
    if not dirty:
        return f"sysid_nn at commit {head}"
    files = ", ".join(line.split(maxsplit=1)[-1] for line in dirty)
    return f"sysid_nn at commit {head} with uncommitted changes in {files}"


def machine_info() -> list[str]:
    import numba
    import scipy
    import sklearn

    import sysid_nn

    return [
        f"- date: {datetime.datetime.now().isoformat(timespec='seconds')}",
        f"- python {platform.python_version()}, numpy {np.__version__}, "
        f"scipy {scipy.__version__}, numba {numba.__version__}, "
        f"scikit-learn {sklearn.__version__}, sysid_nn {sysid_nn.__version__}",
        f"- {source_version()}",
        f"- {platform.platform()}, {platform.processor() or platform.machine()}, "
        f"{os.cpu_count()} CPUs (shared with other work: times are noisy, "
        f"compare ratios within one run), BLAS {blas_kernels()}",
    ]


def noise_section(rows: list[dict]) -> list[str]:
    """Median free-run NRMSE (and ratio to linear) against the noise level."""
    levels = sorted({r.get("noise", 0.0) for r in rows} - {0.0})
    if not levels:
        return []
    columns = [0.0, *levels]
    seeds = sorted({r["seed"] for r in rows if r.get("noise", 0.0)})
    lines = [
        "## Measurement noise (dt = 0.01 s)",
        "",
        "Median free-run NRMSE on the noise-free test records (ratio to the linear "
        "model trained on the same noisy records), then the range of fit times; noise "
        "in % "
        "of each output's standard deviation, on the training and validation "
        "records only. One cell per pool seed: " + ", ".join(map(str, seeds)) + ".",
        "",
    ]
    for protocol in P.PROTOCOLS:
        head = [f"{100 * lv:g} %" for lv in columns]
        block = [
            f"### {protocol}",
            "",
            "| model | " + " | ".join(head) + " | fit s |",
            "|" + "---|" * (len(columns) + 2),
        ]
        for model in NOISE_MODELS:
            cells, times = [], []
            for lv in columns:
                found = [find(rows, s, 0.01, protocol, model, lv) for s in seeds]
                cells.append(
                    " / ".join(
                        "-"
                        if r is None
                        else f"{r['free_median']:.3g}"
                        + (f" ({r['ratio']:.2g})" if "ratio" in r else "")
                        + (f" {r['n_divergent']} div" if r["n_divergent"] else "")
                        for r in found
                    )
                )
                times += [r["fit_s"] for r in found if r is not None]
            if all(c.strip("- /") == "" for c in cells):
                continue
            span = f"{min(times):.0f}-{max(times):.0f}" if times else "-"
            block.append(
                f"| {MODELS[model][0]} | " + " | ".join(cells) + f" | {span} |"
            )
        if len(block) > 4:
            lines += [*block, ""]
    return lines


def write_report(rows, args, elapsed, out_dir: Path, seeds_main) -> None:
    lines = [
        "# Accuracy benchmark",
        "",
        f"Command: `{' '.join(['python benchmarks/bench_accuracy.py', *args.argv])}` "
        f"(run time {elapsed / 60:.1f} min)",
        "",
        *machine_info(),
        "",
        "## Protocol",
        "",
        PROTOCOL_TEXT.format(
            n_pool=P.N_POOL,
            seed=seeds_main,
            n_val=P.N_VAL,
            n_test=P.N_TEST,
            n_reserved=P.N_RESERVED,
            t_window=T_INIT_WINDOW,
        ),
        "",
    ]
    seeds = sorted({r["seed"] for r in rows})
    for seed in seeds:
        for dt in sorted({r["dt"] for r in rows if r["seed"] == seed}):
            for protocol in P.PROTOCOLS:
                sub = [
                    r
                    for r in rows
                    if (r["seed"], r["dt"], r["protocol"], r.get("noise", 0.0))
                    == (seed, dt, protocol, 0.0)
                ]
                if not sub:
                    continue
                tr = sub[0].get("train_idx")
                lines += [f"## dt = {dt} s, {protocol}, seed {seed}", ""]
                lines += [
                    f"Training records {tr}, validation {sub[0].get('val_idx')}.",
                    "",
                ]
                lines += [*table(sub), ""]
    main_seed = seeds_main
    lines += noise_section(rows)
    lines += ["## Targets", "", *targets(rows, main_seed), ""]
    rob = [r for r in rows if r["seed"] != main_seed and "free_median" in r]
    if rob:
        lines += [
            "## Spread over pool seeds (P1, dt = 0.01, median free-run NRMSE / ratio)",
            "",
        ]
        for model in ROBUSTNESS_MODELS:
            vals = [(s, find(rows, s, 0.01, "P1", model)) for s in seeds]
            txt = ", ".join(
                f"seed {s}: {r['free_median']:.4f}"
                + (f" / {r['ratio']:.3f}" if "ratio" in r else "")
                + (f" ({r['n_divergent']} div)" if r["n_divergent"] else "")
                for s, r in vals
                if r is not None
            )
            if txt:
                lines.append(f"- {MODELS[model][0]}: {txt}")
        lines.append("")
    (out_dir / "results.md").write_text("\n".join(lines))
    keys = []
    for r in rows:
        keys += [k for k in r if k not in keys]
    with open(out_dir / "results_accuracy.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=keys)
        w.writeheader()
        for r in rows:
            w.writerow(
                {k: (str(v) if isinstance(v, list) else v) for k, v in r.items()}
            )


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="smoke test (~1 min)")
    ap.add_argument("--protocols", default=None, help="comma list, e.g. P1,P5")
    ap.add_argument("--dt", default=None, help="comma list, e.g. 0.01,0.03")
    ap.add_argument("--models", default=None, help=f"comma list of {', '.join(MODELS)}")
    ap.add_argument("--seed", type=int, default=DEFAULT_SEED, help="pool seed")
    ap.add_argument(
        "--robustness-seeds",
        default=None,
        help="extra pool seeds for P1 at dt = 0.01 (default 2025,2026; 'none' to skip)",
    )
    ap.add_argument(
        "--noise-levels",
        default=None,
        help="measurement-noise levels at dt = 0.01 (both protocols, seeds "
        f"{NOISE_SEEDS}), as fractions of each output's std (default "
        f"{','.join(map(str, NOISE_LEVELS))}; 'none' to skip)",
    )
    ap.add_argument("--out", default=None, help="output directory")
    args = ap.parse_args(argv)
    args.argv = argv
    quick = args.quick
    protocols = (args.protocols or ("P1" if quick else "P1,P5")).split(",")
    dts = [float(d) for d in (args.dt or ("0.01" if quick else "0.01,0.03")).split(",")]
    models = (
        args.models or (",".join(QUICK_MODELS) if quick else ",".join(MODELS))
    ).split(",")
    for m in models:
        if m not in MODELS:
            ap.error(f"unknown model {m!r}; choose from {', '.join(MODELS)}")
    rob_arg = args.robustness_seeds or (
        "none" if quick else ",".join(map(str, ROBUSTNESS_SEEDS))
    )
    rob_seeds = [] if rob_arg == "none" else [int(s) for s in rob_arg.split(",")]
    noise_arg = args.noise_levels or (
        "none" if quick else ",".join(map(str, NOISE_LEVELS))
    )
    noise_levels = (
        [] if noise_arg == "none" else [float(v) for v in noise_arg.split(",")]
    )
    out_dir = (
        Path(args.out)
        if args.out
        else (Path(tempfile.gettempdir()) / "sysid_nn_bench_quick" if quick else HERE)
    )
    out_dir.mkdir(parents=True, exist_ok=True)

    start = time.perf_counter()
    rows: list[dict] = []
    jobs = [
        (args.seed, dt, pr, m, 0.0) for dt in dts for pr in protocols for m in models
    ]
    jobs += [
        (s, 0.01, "P1", m, 0.0)
        for s in rob_seeds
        for m in ROBUSTNESS_MODELS
        if m in models
    ]
    noise_jobs = [
        (s, 0.01, pr, m, lv)
        for pr in protocols
        for s in (NOISE_SEEDS if noise_levels else ())
        for lv in [0.0, *noise_levels]
        for m in NOISE_MODELS
        if m in models
    ]
    jobs += [j for j in noise_jobs if j not in jobs]
    pools: dict = {}
    n_test = 5 if quick else P.N_TEST
    for seed, dt, protocol, model, noise in jobs:
        if seed not in pools:
            pools[seed] = P.make_pool(seed)
        split = P.make_split(pools[seed], protocol, dt, MODELS[model][2], n_test=n_test)
        if noise:
            # The same noise for every model: drawn from the seed and the level.
            split = P.with_noise(split, noise, seed=(seed, round(noise * 1e6)))
        t0 = time.perf_counter()
        row = evaluate(model, split, quick)
        row.update(
            seed=seed, noise=noise, train_idx=split.train_idx, val_idx=split.val_idx
        )
        rows.append(row)
        status = row.get("error") or (
            f"fit {row['fit_s']:.1f} s, free median {row['free_median']:.4f}, "
            f"worst {fmt(row['free_worst'])}, div {row['n_divergent']}, "
            f"k10 {row['k10_median']:.4f}, k50 {row['k50_median']:.4f}"
        )
        print(
            f"[{time.perf_counter() - start:6.0f} s] seed {seed} dt {dt} {protocol} "
            f"{model}{f' noise {noise:g}' if noise else ''}: {status} "
            f"({time.perf_counter() - t0:.0f} s)",
            flush=True,
        )
        add_ratios(rows)
        write_report(rows, args, time.perf_counter() - start, out_dir, args.seed)
    for dt in dts:
        if dt == P.BASE_DT:
            continue
        # Reference for what the kept samples allow (the same test records
        # for both protocols).
        floor = P.information_floor(pools[args.seed], dt, n_test=n_test)
        for protocol in protocols:
            rows.append(
                dict(floor, model="floor", label=FLOOR_LABEL, dt=dt,
                     protocol=protocol, seed=args.seed, noise=0.0)
            )  # fmt: skip
    add_ratios(rows)
    elapsed = time.perf_counter() - start
    write_report(rows, args, elapsed, out_dir, args.seed)
    print((out_dir / "results.md").read_text())
    print(
        f"wrote {out_dir / 'results.md'} and results_accuracy.csv "
        f"in {elapsed / 60:.1f} min"
    )
    return 0


if __name__ == "__main__":
    # Run by ``benchmarks/run.py`` (runpy), sys.argv is the runner's: use defaults.
    direct = Path(sys.argv[0]).name == Path(__file__).name
    status = main(sys.argv[1:] if direct else [])
    if status:
        raise SystemExit(status)
