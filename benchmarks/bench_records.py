"""Building-like field records: amplitude spread, zero-padded ends, oversampling.

The records imitate those of an instrumented building under earthquakes:
about eleven training and a few test records of 7200 samples, about 170
samples per fundamental period, peak responses spanning two orders of
magnitude (weak shaking keeps the structure elastic, strong shaking drives
it far into yield) and, on some records, an exactly zero tail in both the
excitation and the response (the recorder's padding to a fixed length).
They come from :class:`~sysid_nn.HystereticOscillator` with its default
parameters (natural period 1 s) and the paper's earthquake-like excitation
stretched to the longer record.

``python benchmarks/bench_records.py robustness`` fits the default networks
to these records, with and without the padding and the amplitude spread,
and scores their free runs and one-step predictors on the unseen test
records. ``python benchmarks/bench_records.py sampling`` fits them to the
same physical records resampled (anti-aliased, excitation and response
alike) to 20-200 samples per period.
"""

from __future__ import annotations

import argparse
import json
import time
import warnings
from dataclasses import dataclass

import numpy as np
from scipy.signal import resample_poly

from sysid_nn import HystereticOscillator, ISSMRegressor, TDLRegressor
from sysid_nn.excitation import paper_excitation
from sysid_nn.metrics import nrmse

#: Natural period of the default oscillator (omega0 = 2 pi), in seconds.
PERIOD = 1.0
#: Time of peak and of half intensity of the excitation envelope, in
#: seconds: the paper's 3 s and 15 s stretched to a 42 s record.
T1, T2 = 6.0, 30.0


@dataclass
class Records:
    """Training and test records, each a list of ``(n, 1)`` / ``(n,)`` arrays."""

    X_train: list
    y_train: list
    X_test: list
    y_test: list
    dt: float
    peaks_train: np.ndarray
    peaks_test: np.ndarray


def make_building_records(
    n_train: int = 11,
    n_test: int = 4,
    n_samples: int = 7200,
    samples_per_period: float = 170.0,
    spread: float = 50.0,
    padded: bool = True,
    outputs: str = "x",
    random_state: int = 0,
) -> Records:
    """Field-like records of the hysteretic oscillator.

    Parameters
    ----------
    n_train, n_test : int
        Number of training and test records.
    n_samples : int
        Samples per record.
    samples_per_period : float
        Samples per natural period (sets ``dt``).
    spread : float
        Ratio between the strongest and the weakest record's excitation
        (1 gives records of equal strength); the default 50 spreads the peak
        responses about a hundredfold (yielding amplifies the strong ones).
        The strengths are spaced evenly on a log scale around the paper's
        calibrated ``r0``; test records lie between training ones. The
        training records are shuffled, so that the held-out validation
        record is not the strongest.
    padded : bool
        Set the last 5-15 % of every other training record (excitation and
        response) exactly to zero. Test records are never padded: models are
        scored against the structure's whole response (:func:`score_records`
        checks the predictors on padded copies separately).
    outputs : {"x", "xv"}
        Displacement only (1-D ``y``), or displacement and velocity.
    random_state : int
        Seed of the excitation, the order and the padding.
    """
    rng = np.random.RandomState(random_state)
    dt = PERIOD / samples_per_period
    osc = HystereticOscillator()
    r0 = osc.calibrate_r0()
    n_all = n_train + n_test
    # Training strengths on an even log grid, test strengths between them.
    grid = np.linspace(-0.5, 0.5, 2 * n_all - 1) * np.log10(spread)
    train_pos = np.round(np.linspace(0, len(grid) - 1, n_train)).astype(int)
    test_pos = np.setdiff1d(np.arange(len(grid)), train_pos)
    test_pos = test_pos[np.round(np.linspace(0, len(test_pos) - 1, n_test)).astype(int)]
    force = paper_excitation(
        n_samples, dt, r0=r0, t1=T1, t2=T2, n_realizations=n_all, random_state=rng
    )
    force *= 10.0 ** grid[np.r_[train_pos, test_pos]][:, None]
    res = osc.simulate(force, dt)
    order = np.r_[rng.permutation(n_train), n_train + np.arange(n_test)]

    def record(i, k):
        X = force[i][:, None].copy()
        y = res.displacement[i].copy()
        if outputs == "xv":
            y = np.column_stack([y, res.velocity[i]])
        if padded and k % 2 == 1 and k < n_train:
            X, y = pad_end(X, y, rng.uniform(0.05, 0.15))
        return X, y

    recs = [record(i, k) for k, i in enumerate(order)]
    peaks = np.abs(res.displacement[order]).max(axis=1)
    return Records(
        X_train=[r[0] for r in recs[:n_train]],
        y_train=[r[1] for r in recs[:n_train]],
        X_test=[r[0] for r in recs[n_train:]],
        y_test=[r[1] for r in recs[n_train:]],
        dt=dt,
        peaks_train=peaks[:n_train],
        peaks_test=peaks[n_train:],
    )


def pad_end(X, y, fraction):
    """Copies of ``X`` and ``y`` with their last ``fraction`` set exactly to zero."""
    X, y = X.copy(), y.copy()
    cut = int(len(X) * (1 - fraction))
    X[cut:] = 0.0
    y[cut:] = 0.0
    return X, y


def resample_records(recs: Records, down: int) -> Records:
    """The records decimated by ``down``: anti-aliased (polyphase FIR), both signals."""

    def dec(a):
        return resample_poly(a, 1, down, axis=0)

    return Records(
        X_train=[dec(x) for x in recs.X_train],
        y_train=[dec(y) for y in recs.y_train],
        X_test=[dec(x) for x in recs.X_test],
        y_test=[dec(y) for y in recs.y_test],
        dt=recs.dt * down,
        peaks_train=recs.peaks_train,
        peaks_test=recs.peaks_test,
    )


# ----------------------------------------------------------------- scoring
def _first(a):
    a = np.asarray(a)
    return a if a.ndim == 1 else a[:, 0]


def score_records(model, recs: Records) -> dict:
    """Free-run and one-step NRMSE (displacement) per test record, with warnings."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sim = model.predict(recs.X_test)
        one = model.predict(recs.X_test, recs.y_test)
        # The one-step predictor across the jump of a zero-padded end.
        padded = [
            pad_end(X, y, 0.1) for X, y in zip(recs.X_test, recs.y_test, strict=True)
        ]
        one_padded = model.predict([p[0] for p in padded], [p[1] for p in padded])
    free, step = [], []
    for y, ys, yo in zip(recs.y_test, sim, one, strict=True):
        free.append(_score(y, ys))
        step.append(_score(y, yo))
    return {
        "free": free,
        "one_step": step,
        "nan_free": int(sum(not np.all(np.isfinite(s)) for s in sim)),
        "nan_one_step": int(sum(not np.all(np.isfinite(s)) for s in one)),
        "nan_one_step_padded": int(sum(not np.all(np.isfinite(s)) for s in one_padded)),
        "predict_warnings": sorted({type(w.message).__name__ for w in caught}),
    }


def _score(y, yhat) -> float:
    y, yhat = _first(y), _first(yhat)
    if not np.all(np.isfinite(yhat)):
        return float("inf")
    return float(nrmse(y, yhat))


def make_model(kind: str, n_init: int, random_state: int, input_delay: int = 1):
    common = dict(
        n_init=n_init, random_state=random_state, n_jobs=1, input_delay=input_delay
    )
    if kind == "tdl":
        return TDLRegressor(**common)
    if kind == "tdl_lin":
        return TDLRegressor(hidden_layer_sizes=(), **common)
    if kind == "issm":
        return ISSMRegressor(**common)
    if kind == "issm_lin":
        return ISSMRegressor(hidden_layer_sizes=(), **common)
    raise ValueError(kind)


def fit_and_score(
    kind: str, recs: Records, n_init: int, random_state: int, input_delay: int = 1
) -> dict:
    model = make_model(kind, n_init, random_state, input_delay)
    start = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        model.fit(recs.X_train, recs.y_train)
    out = {
        "model": kind,
        "fit_s": round(time.perf_counter() - start, 1),
        "fit_warnings": sorted({type(w.message).__name__ for w in caught}),
        "fit_messages": [str(w.message)[:160] for w in caught],
        "restart_scores": np.asarray(model.restart_scores_).tolist(),
        "predictor_radius": getattr(model, "predictor_spectral_radius_", None),
    }
    out.update(score_records(model, recs))
    out["median_free"] = float(np.median(out["free"]))
    out["median_one_step"] = float(np.median(out["one_step"]))
    return out


# --------------------------------------------------------------- commands
def robustness(args) -> None:
    """Default fits on padded / unpadded, spread / equal-strength records."""
    variants = {
        "padded+spread": dict(padded=True, spread=50.0),
        "spread": dict(padded=False, spread=50.0),
        "padded+equal": dict(padded=True, spread=1.0),
        "equal": dict(padded=False, spread=1.0),
    }
    for name in args.variants.split(","):
        recs = make_building_records(
            outputs=args.outputs, random_state=args.seed, **variants[name]
        )
        for kind in args.models.split(","):
            res = fit_and_score(kind, recs, args.n_init, args.seed)
            res.update(variant=name, outputs=args.outputs, seed=args.seed)
            print(json.dumps(res), flush=True)


def sampling(args) -> None:
    """Default fits on the same records resampled to fewer samples per period."""
    base = make_building_records(
        n_train=args.n_train,
        n_samples=args.n_samples,
        samples_per_period=args.base_spp,
        padded=False,
        spread=args.spread,
        outputs=args.outputs,
        random_state=args.seed,
    )
    if args.noise:
        # Measurement noise at the recorder's rate, on the training outputs:
        # the anti-aliasing filter removes its part above the new Nyquist.
        rng = np.random.default_rng(args.seed)
        base.y_train = [
            y + args.noise * y.std(axis=0) * rng.standard_normal(y.shape)
            for y in base.y_train
        ]
    for down in [int(d) for d in args.down.split(",")]:
        recs = base if down == 1 else resample_records(base, down)
        for kind in args.models.split(","):
            res = fit_and_score(kind, recs, args.n_init, args.seed, args.input_delay)
            res.update(
                samples_per_period=args.base_spp / down,
                outputs=args.outputs,
                input_delay=args.input_delay,
                noise=args.noise,
            )
            print(json.dumps(res), flush=True)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    rob = sub.add_parser("robustness")
    rob.add_argument("--variants", default="padded+spread,spread,padded+equal,equal")
    rob.add_argument("--models", default="tdl,issm")
    samp = sub.add_parser("sampling")
    samp.add_argument("--base-spp", type=float, default=200.0)
    samp.add_argument("--n-samples", type=int, default=8000)
    samp.add_argument("--down", default="1,2,4,10")
    samp.add_argument("--spread", type=float, default=1.0)
    samp.add_argument("--n-train", type=int, default=5)
    samp.add_argument("--input-delay", type=int, default=1)
    samp.add_argument("--noise", type=float, default=0.0)
    samp.add_argument("--models", default="tdl,issm")
    for p in (rob, samp):
        p.add_argument("--outputs", default="x", choices=("x", "xv"))
        p.add_argument("--n-init", type=int, default=1)
        p.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    {"robustness": robustness, "sampling": sampling}[args.command](args)


if __name__ == "__main__":
    main()
