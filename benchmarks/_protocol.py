"""Data protocol and scores shared by the accuracy benchmarks.

The protocol (paper section 4, with the choices of the design notes):

* a pool of ``N_POOL = 32`` realisations of the hysteretic oscillator, 2000
  samples at dt = 0.01 s, from one fixed seed;
* the realisations are ordered by how close their peak displacement is to the
  median peak of the pool (typical amplitude first);
* protocol P1 trains on the first one, P5 on the first five; the two
  realisations after the training ones validate (early stopping and restart
  selection, passed as ``X_val, y_val``);
* the test set is the same for both protocols: the 25 realisations left after
  the first seven (P5's training and validation records);
* dt = 0.03 s is every third sample of the dt = 0.01 records (``x[::3]``),
  as in the paper.

Scores are computed per test realisation and summarised (mean, median,
worst) over the 25 of them.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from scipy.signal import butter, filtfilt

from sysid_nn import HystereticOscillator
from sysid_nn.metrics import nrmse
from sysid_nn.residuals import cross_correlation_test, whiteness_test

N_POOL = 32
N_SAMPLES = 2000
BASE_DT = 0.01
#: Training records of each protocol.
PROTOCOLS = {"P1": 1, "P5": 5}
N_VAL = 2
N_TEST = 25
#: Records reserved for training and validation in every protocol (P5's).
N_RESERVED = max(PROTOCOLS.values()) + N_VAL
#: Start of the free run from measured outputs, in seconds (sample 200 at dt 0.01).
T0_MEASURED = 2.0
#: Corner of the zero-phase high-pass that isolates the oscillatory part.
HIGHPASS_HZ = 0.3
HORIZONS = (1, 10, 50)
MAX_LAG = 25


@dataclass
class Split:
    """Training, validation and test sequences of one (dt, protocol)."""

    dt: float
    protocol: str
    X_train: list
    y_train: list
    X_val: list
    y_val: list
    X_test: list
    y_test: list
    train_idx: list
    val_idx: list
    test_idx: list


def make_pool(seed: int, n_pool: int = N_POOL):
    """Generate the pool of realisations (dt = 0.01 s) with a fixed seed."""
    return HystereticOscillator().generate(
        n_pool, n_samples=N_SAMPLES, dt=BASE_DT, random_state=seed
    )


def amplitude_order(pool) -> np.ndarray:
    """Record indices ordered by closeness of peak |X| to the pool's median peak."""
    peaks = np.abs(pool.displacement).max(axis=1)
    return np.argsort(np.abs(peaks - np.median(peaks)), kind="stable")


def make_split(
    pool, protocol: str, dt: float, outputs: str = "x", n_test=N_TEST
) -> Split:
    """Sequences of one protocol at one sampling step.

    ``outputs="x"`` gives the displacement (1-D ``y``), ``"xv"`` displacement
    and velocity (``y`` of shape ``(n, 2)``, displacement first).
    """
    step = round(dt / BASE_DT)
    if not np.isclose(step * BASE_DT, dt):
        raise ValueError(f"dt must be a multiple of {BASE_DT}; got {dt}.")
    order = amplitude_order(pool)
    n_train = PROTOCOLS[protocol]
    train = order[:n_train]
    val = order[n_train : n_train + N_VAL]
    test = order[N_RESERVED : N_RESERVED + n_test]

    def X(i):
        return pool.excitation[i, ::step][:, None].copy()

    def y(i):
        if outputs == "x":
            return pool.displacement[i, ::step].copy()
        return np.column_stack([pool.displacement[i, ::step], pool.velocity[i, ::step]])

    return Split(
        dt=dt,
        protocol=protocol,
        X_train=[X(i) for i in train],
        y_train=[y(i) for i in train],
        X_val=[X(i) for i in val],
        y_val=[y(i) for i in val],
        X_test=[X(i) for i in test],
        y_test=[y(i) for i in test],
        train_idx=[int(i) for i in train],
        val_idx=[int(i) for i in val],
        test_idx=[int(i) for i in test],
    )


def with_noise(split: Split, level: float, seed: int) -> Split:
    """The split with white measurement noise on the training and validation outputs.

    Each output column gets Gaussian noise of ``level`` times its own standard
    deviation, drawn from ``seed`` so that every model sees the same noisy
    records. The test records stay noise-free: models are scored against
    the true response.
    """
    rng = np.random.default_rng(seed)

    def noisy(y):
        return y + level * y.std(axis=0) * rng.standard_normal(y.shape)

    return replace(
        split,
        y_train=[noisy(y) for y in split.y_train],
        y_val=[noisy(y) for y in split.y_val],
    )


# --------------------------------------------------------------- scoring
def first_col(a: np.ndarray) -> np.ndarray:
    """The displacement column (a 1-D output is returned as is)."""
    a = np.asarray(a)
    return a if a.ndim == 1 else a[:, 0]


def record_nrmse(y_true, y_pred) -> float:
    """NRMSE of one record; ``inf`` for a diverged (NaN) prediction."""
    y_true, y_pred = first_col(y_true), first_col(y_pred)
    if not np.all(np.isfinite(y_pred)):
        return np.inf
    return float(nrmse(y_true, y_pred))


def highpass(x: np.ndarray, dt: float, corner: float = HIGHPASS_HZ) -> np.ndarray:
    """Zero-phase 4th-order Butterworth high-pass (oscillatory part)."""
    b, a = butter(4, corner, btype="highpass", fs=1.0 / dt)
    return filtfilt(b, a, x)


def record_nrmse_highpass(y_true, y_pred, dt: float) -> float:
    y_true, y_pred = first_col(y_true), first_col(y_pred)
    if not np.all(np.isfinite(y_pred)):
        return np.inf
    return record_nrmse(highpass(y_true, dt), highpass(y_pred, dt))


def summary(values) -> dict:
    """Mean, median and worst of per-record scores (``inf`` = diverged)."""
    v = np.asarray(values, dtype=float)
    return {
        "mean": float(np.mean(v)) if np.all(np.isfinite(v)) else np.inf,
        "median": float(np.median(v)),
        "worst": float(np.max(v)),
    }


def timed_fit(model, X, y, X_val=None, y_val=None):
    """``model`` fitted with its warnings silenced, and the fit's CPU seconds."""
    t0 = time.process_time()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model.fit(X, y, X_val=X_val, y_val=y_val)
    return model, time.process_time() - t0


def load_range(rows) -> str:
    """``"min-max"`` of the 1-minute loads recorded in ``rows`` (``"load"``)."""
    loads = [r["load"] for r in rows]
    return f"{min(loads):.1f}-{max(loads):.1f}"


def write_report(text: str, out: str | None, default: str) -> None:
    """Print a benchmark's report and write it to ``out``, or to the file
    ``default`` beside the benchmarks."""
    print(text)
    Path(out if out else Path(__file__).with_name(default)).write_text(text)


def median_range(values, digits: int = 3) -> str:
    """``"median (min - max)"`` of ``values``, to ``digits`` significant digits."""
    v = np.asarray(values, dtype=float)
    f = f"{{:.{digits}g}}"
    return f"{f.format(np.median(v))} ({f.format(v.min())} - {f.format(v.max())})"


def simulate_from_measured(model, X, y, k0: int, p: int, filtered: bool = False):
    """Free run started at sample ``k0`` from the measured outputs before it.

    TDL: ``initial_outputs`` = the measured outputs ``y[k0 - output_lags_:k0]``;
    ISSM: ``initial_state`` = the measured outputs at ``k0 - 1`` as the first
    ``p`` states, zeros (rest) for the unmeasured ones. Both are given the
    measured excitation before ``k0`` (``initial_inputs``), so that the only
    difference from the measured trajectory is the unmeasured state. Returns
    the simulated outputs for samples ``k0..end``.

    ``filtered=True`` (ISSM only): the unmeasured states start at the one-step
    predictor's (extended Kalman filter's) estimate at ``k0 - 1`` from the
    measurements before ``k0`` (``predict_states(X[:k0], y[:k0])``) instead
    of zero.
    """
    if hasattr(model, "output_lags"):
        kwargs = {"initial_outputs": y[k0 - model.output_lags_ : k0]}
    else:
        y0 = np.atleast_1d(y[k0 - 1])
        rest = np.zeros(model.n_states_ - p)
        if filtered:
            rest = model.predict_states(X[:k0], y[:k0]).states[-1, p:]
        kwargs = {"initial_state": np.r_[y0, rest]}
    return model.simulate(X[k0:], initial_inputs=X[:k0], **kwargs)


def residual_tests(e: np.ndarray, x: np.ndarray) -> tuple[bool, bool]:
    """Whiteness and cross-correlation (both sides) decisions of one record."""
    e = first_col(e)
    if not np.all(np.isfinite(e)) or np.std(e) == 0:
        return False, False
    white = whiteness_test(e, max_lag=MAX_LAG).passed
    cross = cross_correlation_test(e, x, max_lag=MAX_LAG).passed
    return bool(white), bool(cross)


def information_floor(pool, dt: float, n_test=N_TEST) -> dict:
    """Scores of the true oscillator when only every ``dt`` sample is kept.

    At dt = 0.03 s the excitation between kept samples is lost to every model.
    As a reference for what the kept samples allow, the true equations are run
    on the excitation interpolated linearly between the kept samples
    (``np.interp`` on the 0.01 s grid): k-step predictions start from the
    *true* state (displacement, velocity and the hysteretic component, which
    no model sees), the free run from rest. Not a strict bound: a model may
    guess the lost excitation better than linear interpolation. Returns the
    same score keys as the models' rows (free-run summary, k-step medians).
    """
    step = round(dt / BASE_DT)
    order = amplitude_order(pool)
    test = order[N_RESERVED : N_RESERVED + n_test]
    osc = HystereticOscillator()
    fine = np.arange(pool.excitation.shape[1])
    free, kstep = [], {k: [] for k in HORIZONS}
    for i in test:
        y = pool.displacement[i, ::step]
        F = np.interp(fine, fine[::step], pool.excitation[i, ::step])
        free.append(record_nrmse(y, osc.simulate(F, BASE_DT).displacement[::step]))
        true = np.stack(
            [pool.displacement[i], pool.velocity[i], pool.hysteretic[i]], axis=1
        )
        for k in HORIZONS:
            # One row per start sample j: from the true state at j, k kept steps.
            starts = np.arange(len(y) - k)
            rows = np.stack([F[step * j : step * (j + k) + 1] for j in starts])
            run = osc.simulate(rows, BASE_DT, initial_state=true[step * starts])
            pred = y.copy()
            pred[starts + k] = run.displacement[:, step * k]
            kstep[k].append(record_nrmse(y, pred))
    row = {f"free_{s}": v for s, v in summary(free).items()}
    for k, v in kstep.items():
        s = summary(v)
        row[f"k{k}_median"], row[f"k{k}_mean"] = s["median"], s["mean"]
    row["n_test"] = len(test)
    return row
