"""Fingerprints of default fits: a hash of the weights and of a free run.

A change that is meant to move code without changing what it computes (a
module moved, a function renamed, a call built by keyword) must leave every
line of this script's output unchanged: run it before and after and compare.

Cases: the hysteretic oscillator (one 1500-sample record of displacement,
and two records with displacement and velocity), with the default
``TDLRegressor()``, ``ISSMRegressor()`` and the linear model, validated on
the tail of the training records and on a record passed as ``X_val``; and
a Wiener-Hammerstein-type record (a linear filter, a static cubic, another
filter) for the automatic lags and order. Each line ends with the free-run
NRMSE on a record of the same system that no fit sees, so that a change
that moves rounding can be judged by what it does to accuracy. About a
minute on one core.

Run: ``python benchmarks/fingerprint.py > before.txt`` then, after the
change, ``python benchmarks/fingerprint.py | diff before.txt -``.
"""

from __future__ import annotations

import hashlib
import sys
import warnings

import numpy as np
from scipy.signal import lfilter

from sysid_nn import HystereticOscillator, ISSMRegressor, TDLRegressor
from sysid_nn.metrics import nrmse


def _digest(*arrays: np.ndarray) -> str:
    h = hashlib.sha256()
    for a in arrays:
        h.update(np.ascontiguousarray(np.asarray(a, dtype=float)).tobytes())
    return h.hexdigest()[:16]


def _records() -> dict[str, tuple]:
    rec = HystereticOscillator().generate(
        n_realizations=4, n_samples=1500, random_state=3
    )
    X = [f[:, None] for f in rec.excitation]
    y1 = list(rec.displacement)
    y2 = [
        np.column_stack([d, v])
        for d, v in zip(rec.displacement, rec.velocity, strict=True)
    ]
    rng = np.random.default_rng(7)
    u = rng.standard_normal(3000)
    w = lfilter([0.0, 0.4, 0.2], [1.0, -1.2, 0.5], u)
    v = lfilter([0.0, 0.3], [1.0, -0.6], w + 0.3 * w**3)
    return {
        "oscillator, one record, tail": ([X[0]], [y1[0]], None, None),
        "oscillator, one record, X_val": ([X[0]], [y1[0]], [X[1]], [y1[1]]),
        "oscillator, two records x and v, tail": (X[:2], y2[:2], None, None),
        "wiener-hammerstein, tail": (u[:1500, None], v[:1500], None, None),
    }


def _tests() -> dict[str, tuple]:
    """A record of each system that no fit sees."""
    rec = HystereticOscillator().generate(
        n_realizations=5, n_samples=1500, random_state=3
    )
    rng = np.random.default_rng(7)
    u = rng.standard_normal(3000)
    w = lfilter([0.0, 0.4, 0.2], [1.0, -1.2, 0.5], u)
    v = lfilter([0.0, 0.3], [1.0, -0.6], w + 0.3 * w**3)
    d, s = rec.displacement[4], rec.velocity[4]
    return {
        "oscillator": (rec.excitation[4][:, None], d),
        "oscillator x and v": (rec.excitation[4][:, None], np.column_stack([d, s])),
        "wiener-hammerstein": (u[1500:, None], v[1500:]),
    }


def main() -> int:
    models = {
        "tdl": lambda: TDLRegressor(random_state=0),
        "issm": lambda: ISSMRegressor(random_state=0),
        "linear": lambda: TDLRegressor(hidden_layer_sizes=(), random_state=0),
    }
    tests = _tests()
    for name, (X, y, X_val, y_val) in _records().items():
        system = name.split(",")[0] + (" x and v" if "x and v" in name else "")
        X_test, y_test = tests[system]
        for label, make in models.items():
            model = make()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                model.fit(X, y, X_val=X_val, y_val=y_val)
                X0 = X[0] if isinstance(X, list) else X
                sim = model.simulate(X0)
                test = nrmse(y_test, model.simulate(X_test))
            print(
                f"{name} | {label} | weights {_digest(model.coefs_)} | "
                f"free run {_digest(sim)} | selected {model.selected_} | "
                f"test NRMSE {test:.4g}",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
