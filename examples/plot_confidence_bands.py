"""
Confidence bands: how far to trust a simulation
===============================================

A model identified from a handful of records is used to simulate the next
one. Both estimators return, with ``return_std=True``, the standard deviation
of every simulated or predicted sample (scikit-learn's
``GaussianProcessRegressor`` convention): the uncertainty of the fitted
weights, propagated through the recurrence by the delta method, plus, for a
prediction interval, the noise variance of the training residuals. This
example shows

* a simulation with its 95 % prediction and confidence bands;
* the confidence band narrowing as training records are added (P1 to P5);
* the band widening where a test record leaves the amplitude range of the
  training records;
* an ensemble of bootstrap refits as a check of the delta method, which
  shows how far the delta method falls short on this problem.

The networks are trained with one restart (``n_init=1``) so that the example
runs in seconds; the bands are those of these networks.
"""

# %%
# Data with measurement noise
# ---------------------------
# Records of the hysteretic oscillator, 2000 samples at ``dt = 0.01`` s, with
# white measurement noise of 0.1 % of the displacement's standard deviation
# on the records used for training. The records are ordered by how close
# their peak displacement is to the median peak: the first ones are typical,
# the last ones the largest.
import warnings

import matplotlib.pyplot as plt
import numpy as np
from sklearn.exceptions import ConvergenceWarning

from sysid_nn import HystereticOscillator, ISSMRegressor
from sysid_nn.plotting import plot_band
from sysid_nn.uncertainty import ensemble_std, interval_coverage, normal_interval

warnings.filterwarnings("ignore", category=ConvergenceWarning)

rec = HystereticOscillator().generate(n_realizations=12, random_state=3)
peaks = np.abs(rec.displacement).max(axis=1)
order = np.argsort(np.abs(peaks - np.median(peaks)))
rng = np.random.default_rng(0)
noise = 1e-3 * rec.displacement.std()
X = [rec.excitation[i][:, None] for i in order]
y_true = [rec.displacement[i] for i in order]
y = [yi + noise * rng.standard_normal(yi.shape) for yi in y_true]
t = rec.t
X_val, y_val = X[5:7], y[5:7]
test = 7  # a typical record no model is trained on
largest = int(np.argmax([np.abs(yi).max() for yi in y_true]))


def fit(n_records):
    """The default ISSM with one restart, trained on the first ``n_records``."""
    model = ISSMRegressor(n_init=1, random_state=0)
    return model.fit(X[:n_records], y[:n_records], X_val=X_val, y_val=y_val)


# %%
# A simulation and its bands
# --------------------------
# ``interval="prediction"`` (the default) is the band for a new measurement:
# the weights' uncertainty plus the residual noise. ``interval="confidence"``
# is the band of the model's own output (the weights only). The printed
# share of the measurements inside the prediction band is the first check of
# a band: for this single-record model it is far below 95 %. The residuals on
# the training record are mostly the model's error, not noise, and the model
# errs more on a new record than on its training record, which a band from
# the training records alone cannot foresee (see :ref:`uncertainty`).
models = {1: fit(1)}
mean, std = models[1].simulate(X[test], return_std=True)
_, std_conf = models[1].simulate(X[test], return_std=True, interval="confidence")

fig, ax = plt.subplots(figsize=(7, 3.5))
ax.plot(t, y[test], "k-", linewidth=0.6, label="measured")
plot_band(t, mean, std, label="simulated (P1)", ax=ax)
lower, upper = normal_interval(mean, std_conf)
ax.plot(t, lower, ":", color="C1", linewidth=0.8, label="95 % confidence band")
ax.plot(t, upper, ":", color="C1", linewidth=0.8)
ax.set_xlabel("time t [s]")
ax.set_ylabel("displacement")
ax.legend(loc="lower left", fontsize=8)
fig.tight_layout()
print(
    "share of the test record inside the 95 % prediction band: "
    f"{interval_coverage(y[test], *normal_interval(mean, std)):.2f}"
)

# %%
# More records, narrower band
# ---------------------------
# The weights are better determined by more data: the confidence band of
# the same test simulation narrows from one training record (P1) to three
# and five (P3, P5).
for n in (3, 5):
    models[n] = fit(n)
widths = {}
fig, ax = plt.subplots(figsize=(7, 3.5))
for n, model in models.items():
    _, s = model.simulate(X[test], return_std=True, interval="confidence")
    widths[n] = float(np.median(s))
    ax.semilogy(t, 1.96 * s, linewidth=0.8, label=f"P{n}")
ax.set_xlabel("time t [s]")
ax.set_ylabel("half-width of the 95 % confidence band")
ax.legend()
fig.tight_layout()
for n, w in widths.items():
    print(f"P{n}: median half-width {1.96 * w:.2e}")

# %%
# Beyond the training amplitudes, a wider band
# --------------------------------------------
# The weights are determined only where the training records went. The
# largest record of the pool reaches beyond the training amplitude of the
# P1 model (dashed lines); the band is wider where it does, and the model's
# error grows there too.
model = models[1]
mean, std = model.simulate(X[largest], return_std=True, interval="confidence")
reach = np.abs(y[0]).max()
outside = np.abs(y_true[largest]) > reach
fig, (top, bottom) = plt.subplots(2, 1, sharex=True, figsize=(7, 5))
top.plot(t, y_true[largest], "k-", linewidth=0.6, label="true response")
plot_band(t, mean, std, label="simulated (P1)", ax=top)
top.axhline(reach, color="grey", linestyle="--", linewidth=0.8)
top.axhline(-reach, color="grey", linestyle="--", linewidth=0.8,
            label="training amplitude")  # fmt: skip
top.set_ylabel("displacement")
top.legend(loc="lower left", fontsize=8)
bottom.plot(t, std, linewidth=0.8, label="band standard deviation")
bottom.plot(t, np.abs(y_true[largest] - mean), linewidth=0.5, alpha=0.6,
            label="|error|")  # fmt: skip
bottom.set_xlabel("time t [s]")
bottom.legend(loc="upper left", fontsize=8)
fig.tight_layout()
inside_sd, outside_sd = np.median(std[~outside]), np.median(std[outside])
print(f"median standard deviation inside the training range {inside_sd:.2e}")
print(f"median standard deviation outside it {outside_sd:.2e}")

# %%
# A check of the delta method: bootstrap by experiment
# ----------------------------------------------------
# The delta method linearises the outputs in the weights and takes the
# training residuals for white noise. An ensemble of models refitted to
# records drawn with replacement (a bootstrap by experiment) assumes neither;
# where the two spreads agree, the delta method can be trusted. Here the
# bootstrap spread is about twice as wide: the weights of this network are
# less determined than the curvature of the training loss suggests, and the
# delta-method band is best read as a lower bound. Four members keep this
# example short; use more for a real check.
mean_e, std_e = ensemble_std(
    ISSMRegressor(n_init=1, random_state=0),
    X[:5],
    y[:5],
    X[test],
    n_members=4,
    random_state=0,
)
_, std_delta = models[5].simulate(X[test], return_std=True, interval="confidence")
fig, ax = plt.subplots(figsize=(7, 3))
ax.semilogy(t, std_delta, linewidth=0.8, label="delta method (P5)")
ax.semilogy(t, std_e, linewidth=0.8, label="bootstrap spread (4 members)")
ax.set_xlabel("time t [s]")
ax.set_ylabel("standard deviation")
ax.legend()
fig.tight_layout()
print(f"median ratio bootstrap / delta method: {np.median(std_e / std_delta):.2f}")
