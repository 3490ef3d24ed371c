"""The linear model of the default fits against least-squares ARX.

Generated lightly damped chains (a sum of two or three second-order modes,
1-3 % damping, displacement out), one training record of 1024 or 2000
samples from rest under white excitation, clean and with 1 % output noise
(white, 1 % of the output's standard deviation), three seeds. Every model
is scored by the NRMSE of its free run from rest on a test record of 1000
samples (another excitation, noise-free output):

* ``arx``: least-squares ARX of the TDL's lags (``output_lags_``,
  ``input_lags_``, intercept included) fitted by ``numpy.linalg.lstsq`` on
  the training record and simulated;
* ``lin``: the linear model the default ``TDLRegressor()`` judged its
  networks against (captured from the training driver), simulated;
* ``tdl``, ``issm``: ``TDLRegressor()`` and ``ISSMRegressor()``.

A second section fits the hysteretic oscillator (one and three training
records of 1500 samples, displacement out) and scores the defaults on a
record no fit sees, for the "no worse than before" check.

With ``--in-motion`` the chains' training records are cut 500 samples into
the response, so that they start in motion (as a record cut from a longer
measurement), and the oscillator section is left out.

With ``--record FILE`` a measured record of one input and one output (two
columns of text, as the DaISy collection's; the toolbox does not fetch it)
is fitted instead: the first 768 samples train, and the free run over the
whole record from rest is scored on the rest, next to least-squares ARX of
6 and 10 lags (for example the flexible robot arm's record, DaISy 96-009,
torque in and acceleration out, 1024 samples).

Run: ``python benchmarks/bench_linear.py [out.md] [--in-motion | --record
FILE]`` (3-20 minutes: the ISSM's fits of the three-mode chain take up to
200 CPU seconds each); results in ``results_linear.md``.
"""

from __future__ import annotations

import copy
import sys
import time
import warnings

import _protocol as P
import numpy as np
from scipy.signal import cont2discrete, lfilter

from sysid_nn import HystereticOscillator, ISSMRegressor, TDLRegressor
from sysid_nn._engine import _selection
from sysid_nn.metrics import nrmse

#: (modes' natural frequencies in cycles per sample, damping ratio, training
#: samples)
SYSTEMS = {
    "2 modes, 2 %, 1024": ((0.04, 0.11), 0.02, 1024),
    "3 modes, 1 %, 2000": ((0.03, 0.08, 0.15), 0.01, 2000),
}
NOISE = (0.0, 0.01)
SEEDS = (0, 1, 2)
N_TEST = 1000


def chain(freqs, zeta) -> tuple[np.ndarray, np.ndarray]:
    """Discrete transfer function of a sum of second-order modes (ZOH)."""
    b_all, a_all = np.zeros(1), np.ones(1)
    for j, f in enumerate(freqs):
        w = 2 * np.pi * f
        num = [0.0, 0.0, (-1.0) ** j * w**2 / (j + 1)]
        den = [1.0, 2 * zeta * w, w**2]
        bd, ad, _ = cont2discrete((num, den), 1.0, method="zoh")
        bd = np.ravel(bd)
        # Sum of fractions: b_all / a_all + bd / ad.
        b_all = np.polyadd(np.polymul(b_all, ad), np.polymul(bd, a_all))
        a_all = np.polymul(a_all, ad)
    return b_all, a_all


def _median_range(values) -> str:
    return P.median_range(values, 4)


def arx_free_run(u, y, na, nb, u_test) -> np.ndarray:
    """Least-squares ARX(na, nb) with intercept, input delay 1, simulated."""
    h = max(na, nb)
    rows = np.arange(h, len(y))
    phi = np.column_stack(
        [y[rows - i] for i in range(1, na + 1)]
        + [u[rows - i] for i in range(1, nb + 1)]
        + [np.ones(len(rows))]
    )
    theta = np.linalg.lstsq(phi, y[rows], rcond=None)[0]
    a, b, c = theta[:na], theta[na : na + nb], theta[-1]
    yhat = np.zeros(len(u_test))
    for t in range(len(u_test)):
        past_y = [yhat[t - i] if t - i >= 0 else 0.0 for i in range(1, na + 1)]
        past_u = [u_test[t - i] if t - i >= 0 else 0.0 for i in range(1, nb + 1)]
        yhat[t] = a @ past_y + b @ past_u + c
        if not np.isfinite(yhat[t]) or abs(yhat[t]) > 1e6:
            return np.full(len(u_test), np.nan)
    return yhat


class _Capture:
    """Keeps the linear model the training driver judged the networks against."""

    def __init__(self):
        self.original = _selection.linear_candidate
        self.last = None

    def __enter__(self):
        def wrapped(*args, **kwargs):
            self.last = self.original(*args, **kwargs)
            return self.last

        _selection.linear_candidate = wrapped
        return self

    def __exit__(self, *exc):
        _selection.linear_candidate = self.original


def _score(model, X, y) -> float:
    with np.errstate(all="ignore"):
        value = nrmse(y, model.simulate(X))
    return float(value) if np.isfinite(value) else np.inf


def linear_chain_rows(lead: int = 0) -> list[dict]:
    """The chains' fits; ``lead`` samples of the response are cut off the
    front of the training record, which then starts in motion."""
    rows = []
    for name, (freqs, zeta, n) in SYSTEMS.items():
        b, a = chain(freqs, zeta)
        for noise in NOISE:
            for seed in SEEDS:
                rng = np.random.default_rng(seed)
                u = rng.standard_normal(n + lead)
                y = lfilter(b, a, u)
                y = y + noise * y.std() * rng.standard_normal(n + lead)
                u, y = u[lead:], y[lead:]
                u_test = np.random.default_rng(100 + seed).standard_normal(N_TEST)
                y_test = lfilter(b, a, u_test)
                row = {"system": name, "noise": noise, "seed": seed}
                with warnings.catch_warnings(), _Capture() as cap:
                    warnings.simplefilter("ignore")
                    t0 = time.process_time()
                    tdl = TDLRegressor(random_state=seed).fit(u[:, None], y)
                    row["tdl_cpu"] = time.process_time() - t0
                    lin = cap.last
                    t0 = time.process_time()
                    issm = ISSMRegressor(random_state=seed).fit(u[:, None], y)
                    row["issm_cpu"] = time.process_time() - t0
                X_test = u_test[:, None]
                row["lags"] = (tdl.output_lags_, tdl.input_lags_)
                sim = arx_free_run(u, y, *row["lags"], u_test)
                row["arx"] = (
                    float(nrmse(y_test, sim)) if np.all(np.isfinite(sim)) else np.inf
                )
                linear = copy.deepcopy(tdl)
                linear.coefs_ = lin.w
                row["lin"] = _score(linear, X_test, y_test)
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    alone = TDLRegressor(hidden_layer_sizes=(), random_state=seed)
                    row["linear"] = _score(alone.fit(u[:, None], y), X_test, y_test)
                row["issm_states"] = issm.n_states_
                row["tdl"] = _score(tdl, X_test, y_test)
                row["issm"] = _score(issm, X_test, y_test)
                row["tdl_selected"] = tdl.selected_
                row["issm_selected"] = issm.selected_
                print(row, flush=True)
                rows.append(row)
    return rows


def oscillator_rows() -> list[dict]:
    rec = HystereticOscillator().generate(
        n_realizations=5, n_samples=1500, random_state=11
    )
    X = [f[:, None] for f in rec.excitation]
    y = list(rec.displacement)
    rows = []
    for n_rec in (1, 3):
        for seed in (0, 1):
            row = {"records": n_rec, "seed": seed}
            for label, make in (("tdl", TDLRegressor), ("issm", ISSMRegressor)):
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    model = make(random_state=seed).fit(X[:n_rec], y[:n_rec])
                row[label] = _score(model, X[4], y[4])
            print(row, flush=True)
            rows.append(row)
    return rows


def record_rows(path: str, n_train: int = 768) -> list[str]:
    """A measured record of one input and one output (two columns of text):
    the first ``n_train`` samples train, the free run over the whole record
    from rest is scored on the rest (NRMSE), as least squares is."""
    data = np.loadtxt(path)
    u, y = data[:, 0], data[:, 1]
    X = u[:, None]

    def score(sim):
        sim = np.asarray(sim).ravel()
        if not np.all(np.isfinite(sim)):
            return np.inf
        return float(nrmse(y[n_train:], sim[n_train:]))

    lines = [
        f"Record `{path}`: {len(y)} samples, the first {n_train} train.",
        "",
        "| model | NRMSE, `random_state` 0, 1, 2 | order | CPU-s |",
        "|---|---|---|---|",
    ]
    for lags in (6, 10):
        ls = arx_free_run(u[:n_train], y[:n_train], lags, lags, u)
        lines.append(f"| least-squares ARX({lags}, {lags}) | {score(ls):.3g} | | |")
    models = {
        "TDLRegressor(hidden_layer_sizes=())": dict(hidden_layer_sizes=()),
        "TDLRegressor(hidden_layer_sizes=(), output_lags=10, input_lags=10)": dict(
            hidden_layer_sizes=(), output_lags=10, input_lags=10
        ),
        "TDLRegressor()": {},
        "ISSMRegressor()": None,
    }
    for label, params in models.items():
        scores, orders, cpu = [], [], []
        for seed in SEEDS:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                t0 = time.process_time()
                if params is None:
                    model = ISSMRegressor(random_state=seed)
                else:
                    model = TDLRegressor(random_state=seed, **params)
                model.fit(X[:n_train], y[:n_train])
                cpu.append(time.process_time() - t0)
            scores.append(score(model.simulate(X)))
            orders.append(getattr(model, "n_states_", None) or model.output_lags_)
        lines.append(
            f"| `{label}` | {', '.join(f'{v:.3g}' for v in scores)} | "
            f"{', '.join(map(str, orders))} | {_median_range(cpu)} |"
        )
        print(lines[-1], flush=True)
    return lines


def main(*argv: str) -> int:
    """``[out.md] [--in-motion] [--record FILE]``: with ``--in-motion`` the
    chains' training records start 500 samples into the response, and the
    oscillator is not run; with ``--record`` only that measured record is
    fitted (see :func:`record_rows`)."""
    in_motion = "--in-motion" in argv
    files = [a for a in argv if not a.startswith("--")]
    if "--record" in argv:
        record = argv[argv.index("--record") + 1]
        files.remove(record)
        text = "\n".join(record_rows(record))
        print(text)
        if files:
            with open(files[0], "w") as f:
                f.write(text + "\n")
        return 0
    out = files[0] if files else None
    start = time.time()
    chains = linear_chain_rows(lead=500 if in_motion else 0)
    lines = [
        "| system | noise | ARX | linear model | lin / ARX | "
        "TDL(hidden_layer_sizes=()) | TDL() | ISSM() | ISSM states |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for name in SYSTEMS:
        for noise in NOISE:
            sel = [r for r in chains if r["system"] == name and r["noise"] == noise]
            ratio = [r["lin"] / r["arx"] for r in sel]
            lines.append(
                f"| {name} | {noise:.0%} | {_median_range([r['arx'] for r in sel])} | "
                f"{_median_range([r['lin'] for r in sel])} | {_median_range(ratio)} | "
                f"{_median_range([r['linear'] for r in sel])} | "
                f"{_median_range([r['tdl'] for r in sel])} | "
                f"{_median_range([r['issm'] for r in sel])} | "
                f"{', '.join(str(r['issm_states']) for r in sel)} |"
            )
    if not in_motion:
        osc = oscillator_rows()
        lines += ["", "| oscillator records | TDL() | ISSM() |", "|---|---|---|"]
        for n_rec in (1, 3):
            sel = [r for r in osc if r["records"] == n_rec]
            lines.append(
                f"| {n_rec} | {_median_range([r['tdl'] for r in sel])} | "
                f"{_median_range([r['issm'] for r in sel])} |"
            )
    lines.append(f"\nwall time {time.time() - start:.0f} s")
    text = "\n".join(lines)
    print(text)
    if out:
        with open(out, "w") as f:
            f.write(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:]))
