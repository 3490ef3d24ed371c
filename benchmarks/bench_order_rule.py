"""What ``ISSMRegressor(n_states="auto")`` chooses, against the true order.

The order is chosen before training starts, so each case fits a linear ISSM
for one iteration (``hidden_layer_sizes=(), n_init=1, max_iter=1``) and reads
``order_selection_``: the singular values' largest gap, the validated order,
the linear order and the chosen number of states. Cases:

* :class:`sysid_nn.ShearBuilding`, 3 and 5 storeys, default parameters, 5
  records of 2000 samples at 0.01 s (``random_state`` 0 and 1): the first
  three train, the fourth validates; outputs every floor's absolute
  acceleration or displacement, with and without white measurement noise of
  2 % of each output's standard deviation. True order ``3 n`` (``2 n``
  linear states, one hysteretic state per storey).
* The hysteretic oscillator's records of ``bench_accuracy.py`` (seed 2024,
  dt 0.01, protocols P1 and P5, displacement or displacement and velocity
  measured): the former defaults 3 and 4.
* Wiener-Hammerstein 2009 and, when their files are there, Silverbox, EMPS and
  Cascaded Tanks (``sysid_nn.datasets``, the training record's last fifth as
  validation): 6 states were right on Wiener-Hammerstein.

Writes ``results_order_rule.md`` next to itself.

Usage::

    python benchmarks/bench_order_rule.py [--data-home DIR]
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
import warnings
from pathlib import Path

import numpy as np
from sklearn.exceptions import ConvergenceWarning

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import _protocol as P  # noqa: E402

from sysid_nn import ISSMRegressor, ShearBuilding, datasets  # noqa: E402

MD = HERE / "results_order_rule.md"


def selection(X, y, X_val, y_val):
    """``order_selection_`` of a one-iteration linear fit, and its CPU time."""
    model = ISSMRegressor(hidden_layer_sizes=(), n_init=1, max_iter=1, random_state=0)
    t0 = time.process_time()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        model.fit(X, y, X_val=X_val, y_val=y_val)
    return model.order_selection_, time.process_time() - t0


def building_cases():
    for n in (3, 5):
        for output in ("acceleration", "displacement"):
            for seed in (0, 1):
                rec = ShearBuilding(n_storeys=n).generate(
                    5, random_state=seed, outputs=output
                )
                X = [g[:, None] for g in rec.ground_acceleration]
                clean = list(getattr(rec, output))
                rng = np.random.default_rng(seed + 10)
                for noise in (0.0, 0.02):
                    y = [
                        v + noise * v.std(axis=0) * rng.standard_normal(v.shape)
                        for v in clean
                    ]
                    label = f"{n} storeys, {output}, seed {seed}, noise {noise:.0%}"
                    yield label, (X[:3], y[:3], X[3:4], y[3:4]), f"{3 * n}"


def oscillator_cases():
    pool = P.make_pool(2024)
    for protocol in ("P1", "P5"):
        for outputs, truth in (("x", "3"), ("xv", "4")):
            s = P.make_split(pool, protocol, 0.01, outputs)
            args = (s.X_train, s.y_train, s.X_val, s.y_val)
            yield f"oscillator {protocol}, {outputs}", args, truth


def field_cases(data_home):
    loaders = {
        "Wiener-Hammerstein": (datasets.fetch_wiener_hammerstein, "6"),
        "Silverbox": (datasets.fetch_silverbox, "-"),
        "EMPS": (datasets.fetch_emps, "-"),
        "Cascaded Tanks": (datasets.fetch_cascaded_tanks, "-"),
    }
    for name, (fetch, truth) in loaders.items():
        try:
            data = fetch(data_home=data_home, download_if_missing=False)
        except Exception as exc:  # files not there: skip the benchmark
            print(f"{name}: not run ({type(exc).__name__})")
            continue
        u, y = np.asarray(data.X_train[0]), np.asarray(data.y_train[0])
        k = int(0.8 * len(y))
        yield f"{name}, last fifth validates", (u[:k], y[:k], u[k:], y[k:]), truth


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data-home", default=None)
    args = parser.parse_args()
    rows = [
        "| records | gap after (ratio) | validated order | linear order "
        "| best linear NRMSE | chosen n_states | right | CPU s |",
        "|---|---|---|---|---|---|---|---|",
    ]
    cases = [*building_cases(), *oscillator_cases(), *field_cases(args.data_home)]
    for label, data, truth in cases:
        sel, cpu = selection(*data)
        sv = sel.singular_values
        ratio = sv[sel.gap_order - 1] / sv[sel.gap_order]
        row = (
            f"| {label} | {sel.gap_order} ({ratio:.3g}) | {sel.validated_order} "
            f"| {sel.linear_order} | {np.min(sel.scores):.3f} | {sel.n_states} "
            f"| {truth} | {cpu:.1f} |"
        )
        print(row, flush=True)
        rows.append(row)
    text = (
        '# The order `n_states="auto"` chooses\n\n'
        "`python benchmarks/bench_order_rule.py` (see its docstring for the "
        "records). `right` is the true order (buildings: 3 n), the former "
        f"defaults (oscillator) or the order known to work. Machine: "
        f"{platform.machine()}, Python {platform.python_version()}; CPU time of "
        "the one-iteration linear fit, selection included.\n\n" + "\n".join(rows) + "\n"
    )
    MD.write_text(text)


if __name__ == "__main__":
    main()
