"""Modal parameters, backbone and non-linearity test against the generators' truth.

Sections:

``buildings``
    ``ShearBuilding`` with 3 and 5 storeys, linear (``alpha=1``) and
    non-linear at small amplitude (``alpha=0.1``, ground motion at 1 % of the
    calibrated strength: peak storey drifts about 2 % of the yield drift;
    at 5 % the Bouc-Wen loops, which dissipate at any amplitude for
    ``n = 1``, added 20-40 % to the damping ratios), all floor
    accelerations measured at dt = 0.02 s, clean and with 2 % white output
    noise (of each output's standard deviation). Each
    repetition draws one fresh 2000-sample record, fits the linear TDL
    (``hidden_layer_sizes=()``) and the linear ISSM with
    ``early_stopping=False`` (the delta method needs the weights at the
    minimum of the training loss; early stopping stops short of it, on 80 %
    of the record), and reads :func:`sysid_nn.modal_parameters`; on the
    noisy linear buildings also the linear TDL with its default early
    stopping. Reported per case: the largest
    relative error of the natural frequencies and of the damping ratios
    over the structural modes against ``modal_properties()`` (median and
    range over the repetitions; every structural mode of the truth matched
    to the identified structural mode nearest in frequency; a missing mode
    counts as a failure), the share of repetitions with every frequency
    within 1 % and every damping ratio within 10 %, and the coverage of the
    95 % intervals (frequency and damping ratio, over modes and
    repetitions).
``networks``
    The same with the default ``ISSMRegressor`` network (hidden layer,
    ``n_init=1``), without and with early stopping, on the noisy linear
    3-storey building: fewer repetitions.
``oscillator``
    ``HystereticOscillator`` (paper's parameters, calibrated strength):
    default TDL and ISSM networks (``n_init=1``) fitted to four 2000-sample
    records at dt = 0.01 s per seed; the small-amplitude frequency of
    :func:`sysid_nn.modal_parameters` against ``omega0 / 2 pi``; the backbone
    at 0.2, 0.4 and 0.6 times the yield displacement against the same
    analysis of the generator's own equations; the non-linearity test on two
    held-out records.
``false_positives``
    The non-linearity test on linear 3-storey buildings (first-storey drift
    from the ground acceleration, 2 % output noise): per repetition a
    default TDL network (``hidden_layer_sizes=(5,)``, ``n_init=1``,
    ``max_iter=50``) fitted to two fresh records, tested on two more. The
    rejection rate at the 5 % level, over all repetitions and over those
    where the fit kept a network (a fit that returns its linear model is
    never significant); and against a linear TDL fitted to the same two
    records with ``early_stopping=False``, passed as ``linear_model``.

Usage::

    python benchmarks/bench_modal.py                 # everything, writes results
    python benchmarks/bench_modal.py --quick         # few repetitions, no file
    python benchmarks/bench_modal.py --section buildings --reps 100
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from sysid_nn import (
    HystereticOscillator,
    ISSMRegressor,
    ShearBuilding,
    TDLRegressor,
    backbone,
    modal_parameters,
    nonlinearity_test,
)

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results_modal.md"
DT_BUILDING = 0.02
DT_OSC = 0.01
NOISE = 0.02
SMALL = 0.01  # share of the calibrated ground-motion strength


def _noisy(y, share, rng):
    return y + share * y.std(axis=0) * rng.standard_normal(y.shape)


def _match(found, truth_f):
    """Index of the identified structural mode nearest each true frequency."""
    if not len(found):
        return None
    idx = [int(np.argmin(np.abs(found.frequency_hz.to_numpy() - f))) for f in truth_f]
    return idx if len(set(idx)) == len(idx) else None


def _score(modes, truth):
    """Largest errors and interval hits of one identification."""
    found = modes[modes.structural].reset_index(drop=True)
    idx = _match(found, truth.frequency)
    if idx is None:
        return None
    row = found.iloc[idx]
    f, z = row.frequency_hz.to_numpy(), row.damping_ratio.to_numpy()
    ef = np.max(np.abs(f / truth.frequency - 1))
    ez = np.max(np.abs(z / truth.damping_ratio - 1))
    hit_f = (row.frequency_hz_low <= truth.frequency) & (
        truth.frequency <= row.frequency_hz_high
    )
    hit_z = (row.damping_ratio_low <= truth.damping_ratio) & (
        truth.damping_ratio <= row.damping_ratio_high
    )
    return ef, ez, hit_f.to_numpy(), hit_z.to_numpy(), len(found) - len(truth.frequency)


def _summary(scores):
    ok = [s for s in scores if s is not None]
    missed = len(scores) - len(ok)
    if not ok:
        return {"missed": missed}
    ef = np.array([s[0] for s in ok])
    ez = np.array([s[1] for s in ok])
    hf = np.concatenate([s[2] for s in ok])
    hz = np.concatenate([s[3] for s in ok])
    extra = np.array([s[4] for s in ok])
    within = np.mean([(s[0] <= 0.01) and (s[1] <= 0.10) for s in ok] + [False] * missed)
    return {
        "missed": missed,
        "ef": ef,
        "ez": ez,
        "within": within,
        "cov_f": hf.mean(),
        "cov_z": hz.mean(),
        "extra": extra,
    }


def _pct(x):
    return f"{100 * np.median(x):.3f} ({100 * np.min(x):.3f}-{100 * np.max(x):.3f})"


def buildings(reps, reps_clean, lines, networks=False):
    cases = []
    for n in (3, 5):
        for linear in (True, False):
            for noise in (0.0, NOISE):
                cases.append((n, linear, noise))
    if networks:
        cases = [(3, True, NOISE)]
        models = {
            "ISSM network, no early stopping": lambda: ISSMRegressor(
                n_init=1, early_stopping=False
            ),
            "ISSM network, early stopping (default)": lambda: ISSMRegressor(n_init=1),
        }
    else:
        models = {
            "linear TDL": lambda: TDLRegressor(
                hidden_layer_sizes=(), n_init=1, early_stopping=False
            ),
            "linear ISSM": lambda: ISSMRegressor(
                hidden_layer_sizes=(), n_init=1, early_stopping=False
            ),
            # Only on the noisy linear buildings: what early stopping does.
            "linear TDL, early stopping (default)": lambda: TDLRegressor(
                hidden_layer_sizes=(), n_init=1
            ),
        }
    lines += [
        "| storeys | building | noise | model | reps "
        "| max freq error % (median, range) "
        "| max damping error % (median, range) | all within 1 % / 10 % "
        "| 95 % coverage freq | 95 % coverage damping "
        "| extra structural modes (median, max) "
        "| missed | readout ms (median) |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for n, linear, noise in cases:
        building = ShearBuilding(n_storeys=n, alpha=1.0 if linear else 0.1)
        r0 = building._resolved_r0() * (1.0 if linear else SMALL)
        building.set_params(r0=r0)
        truth = building.modal_properties()
        count = reps if noise else reps_clean
        for name, make in models.items():
            if "early stopping (default)" in name and not (linear and noise):
                continue
            scores, readout = [], []
            for rep in range(count):
                rng = np.random.default_rng(1000 * n + rep)
                rec = building.generate(
                    1, n_samples=2000, dt=DT_BUILDING, random_state=rep,
                    outputs="acceleration",
                )  # fmt: skip
                X = rec.ground_acceleration[0][:, None]
                y = _noisy(rec.acceleration[0], noise, rng)
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    model = make().set_params(random_state=rep).fit(X, y)
                t = time.process_time()
                modes = modal_parameters(model, DT_BUILDING)
                readout.append(time.process_time() - t)
                scores.append(_score(modes, truth))
            s = _summary(scores)
            label = "linear" if linear else f"alpha=0.1, r0 x {SMALL}"
            if "ef" not in s:
                lines.append(
                    f"| {n} | {label} | {noise:.0%} | {name} | {count} | "
                    f"- | - | 0 | - | - | - | {s['missed']} | - |"
                )
                continue
            lines.append(
                f"| {n} | {label} | {noise:.0%} | {name} | {count} | {_pct(s['ef'])} "
                f"| {_pct(s['ez'])} | {s['within']:.2f} | {s['cov_f']:.3f} | "
                f"{s['cov_z']:.3f} | {np.median(s['extra']):.0f}, {np.max(s['extra'])} "
                f"| {s['missed']} | {1000 * np.median(readout):.1f} |"
            )
            print(lines[-1], flush=True)


def oscillator(seeds, lines):
    osc = HystereticOscillator()
    f0 = osc.omega0 / (2 * np.pi)
    amps = np.array([0.2, 0.4, 0.6]) * osc.z0
    t = time.process_time()
    ref = backbone(osc, DT_OSC, amplitudes=amps)
    ref_time = time.process_time() - t
    lines += [
        f"Generator backbone (same analysis, {ref_time:.2f} CPU s): "
        + ", ".join(
            f"{a * 1000:.0f} mm: {f:.4f} Hz, zeta {z:.4f}"
            for a, f, z in zip(amps, ref.frequency_hz, ref.damping_ratio, strict=True)
        ),
        "",
        "| model | seed | selected | small-amplitude freq / (omega0 / 2 pi) - 1 % "
        "| backbone freq error % at 2, 4, 6 mm | backbone damping error % at 2, 4, "
        "6 mm | falls with amplitude | backbone CPU s | readout CPU ms | DM statistic "
        "| p-value |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, make in (
        ("TDL default", lambda s: TDLRegressor(n_init=1, random_state=s)),
        ("ISSM default", lambda s: ISSMRegressor(n_init=1, random_state=s)),
    ):
        for seed in range(seeds):
            rec = osc.generate(6, random_state=100 + seed)
            X, y = [f[:, None] for f in rec.excitation], list(rec.displacement)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                model = make(seed).fit(X[:4], y[:4])
            t = time.process_time()
            modes = modal_parameters(model, DT_OSC)
            readout = time.process_time() - t
            first = modes[modes.structural].frequency_hz
            small = (first.iloc[0] / f0 - 1) * 100 if len(first) else np.nan
            t = time.process_time()
            try:
                curve = backbone(model, DT_OSC, amplitudes=amps)
                fe = (curve.frequency_hz / ref.frequency_hz - 1) * 100
                ze = (curve.damping_ratio / ref.damping_ratio - 1) * 100
                falls = bool(np.all(np.diff(curve.frequency_hz) < 0))
            except ValueError as exc:
                fe = ze = np.full(3, np.nan)
                falls = f"error: {exc}"
            bb_time = time.process_time() - t
            test = nonlinearity_test(model, X[4:], y[4:])
            lines.append(
                f"| {name} | {seed} | {model.selected_} | {small:+.2f} | "
                + ", ".join(f"{v:+.2f}" for v in fe)
                + " | "
                + ", ".join(f"{v:+.1f}" for v in ze)
                + f" | {falls} | {bb_time:.2f} | {1000 * readout:.0f} | "
                f"{test.statistic:.2f} | {test.pvalue:.2g} |"
            )
            print(lines[-1], flush=True)


def false_positives(reps, lines):
    building = ShearBuilding(n_storeys=3, alpha=1.0)
    building.set_params(r0=building._resolved_r0())
    pvals, p_lin, kept = [], [], []
    for rep in range(reps):
        rng = np.random.default_rng(rep)
        rec = building.generate(4, n_samples=2000, dt=DT_BUILDING,
                                random_state=5000 + rep, outputs="drift")  # fmt: skip
        X = [g[:, None] for g in rec.ground_acceleration]
        y = [_noisy(d[:, 0], NOISE, rng) for d in rec.drift]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            net = TDLRegressor(
                hidden_layer_sizes=(5,), n_init=1, max_iter=50, random_state=rep
            ).fit(X[:2], y[:2])
            lin = TDLRegressor(
                hidden_layer_sizes=(), n_init=1, early_stopping=False, random_state=rep
            ).fit(X[:2], y[:2])
        pvals.append(nonlinearity_test(net, X[2:], y[2:]).pvalue)
        p_lin.append(nonlinearity_test(net, X[2:], y[2:], linear_model=lin).pvalue)
        kept.append(net.selected_ == "restart")
    pvals, p_lin, kept = np.array(pvals), np.array(p_lin), np.array(kept)
    lines += [
        f"{reps} repetitions: the network was kept in {kept.sum()}. Against the "
        f"fit's own linear model, rejections at the 5 % level: "
        f"{np.sum(pvals < 0.05)} of {reps} ({np.mean(pvals < 0.05):.1%}); among "
        f"the kept networks {np.sum(pvals[kept] < 0.05)} of {kept.sum()}; at the "
        f"1 % level {np.sum(pvals < 0.01)}. Against a linear model fitted to the "
        f"same records with early_stopping=False (linear_model=): "
        f"{np.sum(p_lin < 0.05)} of {reps} ({np.mean(p_lin < 0.05):.1%}); among "
        f"the kept networks {np.sum(p_lin[kept] < 0.05)} of {kept.sum()}.",
    ]
    print(lines[-1], flush=True)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument(
        "--section",
        choices=("buildings", "networks", "oscillator", "false_positives"),
        action="append",
    )
    parser.add_argument("--reps", type=int, default=100)
    parser.add_argument("--reps-clean", type=int, default=10)
    parser.add_argument("--reps-networks", type=int, default=10)
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--reps-fp", type=int, default=50)
    args = parser.parse_args(argv)
    if args.quick:
        args.reps, args.reps_clean, args.reps_networks = 5, 2, 2
        args.seeds, args.reps_fp = 1, 4
    sections = args.section or [
        "buildings",
        "networks",
        "oscillator",
        "false_positives",
    ]
    load = subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()
    command = "python benchmarks/bench_modal.py " + " ".join(argv or sys.argv[1:])
    out = [
        "# Modal parameters, backbone and non-linearity test",
        "",
        f"Command: `{command.strip()}`; {os.cpu_count()} cores shared; load at the "
        f"start: `{load}`.",
        "",
    ]
    start = time.process_time()
    for name in sections:
        t = time.process_time()
        out += [f"## {name}", ""]
        if name == "buildings":
            buildings(args.reps, args.reps_clean, out)
        elif name == "networks":
            buildings(args.reps_networks, args.reps_networks, out, networks=True)
        elif name == "oscillator":
            oscillator(args.seeds, out)
        else:
            false_positives(args.reps_fp, out)
        out += ["", f"CPU time of the section: {time.process_time() - t:.0f} s.", ""]
    load = subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()
    out += [f"Total CPU time {time.process_time() - start:.0f} s; load at the end: "
            f"`{load}`.", ""]  # fmt: skip
    text = "\n".join(out)
    print(text)
    if not args.quick:
        path = RESULTS.with_name(
            RESULTS.stem
            + ("" if args.section is None else "_" + "_".join(sections))
            + ".md"
        )
        path.write_text(text)
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
