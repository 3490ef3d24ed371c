"""Coverage and cost of the confidence and prediction bands (``return_std``).

Protocol: the accuracy benchmark's pool of hysteretic-oscillator records (dt =
0.01 s, displacement measured), P1 and P5 training records and two validation
records with white measurement noise of a given share of the displacement's
standard deviation; ten unseen test records with fresh noise of the same level.
For every model (the default TDL and ISSM networks) the benchmark reports

- the coverage of the nominal 95 % prediction band (weights plus noise,
  ``simulate(X, return_std=True)``) of the noisy test measurements, over all
  samples of all test records, and the range over the records;
- the coverage of the 95 % confidence band (weights only,
  ``interval="confidence"``) of the noise-free response;
- the median ratio of the band's half-width to the noise's standard deviation,
  and the median free-run NRMSE against the noise-free response;
- the cost of a band: ``simulate(X, return_std=True)`` over ``simulate(X)`` on
  one 2000-sample record, medians of interleaved repetitions in one run (CPU
  time of the calling thread).

Usage::

    python benchmarks/bench_uncertainty.py            # full run, writes results
    python benchmarks/bench_uncertainty.py --quick    # short fits, no file
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import _protocol as P  # noqa: E402

from sysid_nn import ISSMRegressor, TDLRegressor  # noqa: E402
from sysid_nn.uncertainty import interval_coverage, normal_interval  # noqa: E402

SEED = 2024
N_TEST = 10
LEVEL = 0.95
NOISE_LEVELS = (0.001, 0.01)
MODELS = {
    "TDL default": TDLRegressor,
    "ISSM default (X only, p=1)": ISSMRegressor,
}
N_TIMING = 30


def band_cost(model, X) -> tuple[float, float, float]:
    """Median seconds of ``simulate`` without and with the band, and their ratio.

    CPU time of this thread: on a shared machine wall-clock times of a few
    milliseconds vary tenfold with the load; the kernels run in this thread.
    """
    model.simulate(X, return_std=True)  # compile outside the timing
    plain, band = [], []
    for _ in range(N_TIMING):
        t = time.thread_time()
        model.simulate(X)
        plain.append(time.thread_time() - t)
        t = time.thread_time()
        model.simulate(X, return_std=True)
        band.append(time.thread_time() - t)
    p, b = float(np.median(plain)), float(np.median(band))
    return p, b, b / p


def evaluate(name, split, noise, quick, rng) -> dict:
    params = {"random_state": 0, "n_jobs": 2}
    if quick:
        params.update(max_iter=30, n_init=2)
    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = MODELS[name](**params).fit(
            split.X_train, split.y_train, X_val=split.X_val, y_val=split.y_val
        )
    fit_s = time.perf_counter() - start
    sd = float(np.std(np.concatenate(split.y_train)))
    pred, conf, per_record, width, errors = [], [], [], [], []
    y_noisy_all, lo_all, up_all = [], [], []
    for X, y in zip(split.X_test, split.y_test, strict=True):
        y_noisy = y + noise * np.std(y) * rng.standard_normal(y.shape)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            mean, std = model.simulate(X, return_std=True)
            _, std_c = model.simulate(X, return_std=True, interval="confidence")
        lo, up = normal_interval(mean, std, LEVEL)
        per_record.append(interval_coverage(y_noisy, lo, up))
        y_noisy_all.append(y_noisy)
        lo_all.append(lo)
        up_all.append(up)
        conf.append((y, *normal_interval(mean, std_c, LEVEL)))
        width.append(np.nanmedian(1.96 * std) / (noise * np.std(y)))
        errors.append(P.record_nrmse(y, mean))
    pred = interval_coverage(y_noisy_all, lo_all, up_all)
    conf_cov = interval_coverage(
        [c[0] for c in conf], [c[1] for c in conf], [c[2] for c in conf]
    )
    plain, band, ratio = band_cost(model, split.X_test[0])
    return {
        "model": name,
        "protocol": split.protocol,
        "noise": noise,
        "fit_s": fit_s,
        "pred": pred,
        "pred_min": float(np.min(per_record)),
        "pred_max": float(np.max(per_record)),
        "conf": conf_cov,
        "width": float(np.median(width)),
        "nrmse": float(np.median(errors)),
        "noise_est": float(np.sqrt(model.noise_variance_[0]) / (noise * sd)),
        "plain_ms": 1e3 * plain,
        "band_ms": 1e3 * band,
        "ratio": ratio,
    }


def report(rows, elapsed) -> str:
    lines = [
        "# Confidence and prediction bands",
        "",
        __doc__.split("Usage::")[0].strip(),
        "",
        f"Seed {SEED}, {N_TEST} test records of 2000 samples, level {LEVEL:g}; "
        f"total {elapsed:.0f} s (2 shared cores: times are noisy, ratios are from "
        "one run).",
        "",
        "| model | protocol | noise | prediction band coverage (records) "
        "| confidence band coverage | half-width / noise sd | noise sd estimate "
        "/ true | free-run NRMSE | band cost (plain ms, band ms, ratio) "
        "| fit s |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['model']} | {r['protocol']} | {100 * r['noise']:g} % "
            f"| {r['pred']:.3f} ({r['pred_min']:.2f}-{r['pred_max']:.2f}) "
            f"| {r['conf']:.3f} | {r['width']:.2f} | {r['noise_est']:.2f} "
            f"| {r['nrmse']:.3f} | {r['plain_ms']:.2f}, {r['band_ms']:.2f}, "
            f"{r['ratio']:.1f}x | {r['fit_s']:.0f} |"
        )
    return "\n".join(lines) + "\n"


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="short fits, no file")
    ap.add_argument(
        "--noise-levels",
        default=",".join(str(v) for v in NOISE_LEVELS),
        help="measurement-noise levels as fractions of the displacement's std",
    )
    ap.add_argument("--protocols", default="P1,P5")
    args = ap.parse_args(argv)
    start = time.perf_counter()
    pool = P.make_pool(SEED)
    rows = []
    for level in [float(v) for v in args.noise_levels.split(",")]:
        for protocol in args.protocols.split(","):
            split = P.with_noise(
                P.make_split(pool, protocol, P.BASE_DT, n_test=N_TEST),
                level,
                seed=(SEED, round(level * 1e6)),
            )
            for name in MODELS:
                rng = np.random.default_rng((SEED, round(level * 1e6), 1))
                row = evaluate(name, split, level, args.quick, rng)
                rows.append(row)
                print(
                    f"{name} {protocol} noise {level:g}: prediction coverage "
                    f"{row['pred']:.3f}, confidence {row['conf']:.3f}, "
                    f"NRMSE {row['nrmse']:.3f}, band cost {row['ratio']:.1f}x",
                    flush=True,
                )
    text = report(rows, time.perf_counter() - start)
    print(text)
    if not args.quick:
        (HERE / "results_uncertainty.md").write_text(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
