"""
Noisy measured records that start from an unknown state
========================================================

Measured records differ from simulated ones in two ways that matter here:
the outputs carry measurement noise, and a record rarely starts at rest, so
the state at its first sample is unknown. This tutorial identifies the
hysteretic oscillator from records with 1 % white noise on the measured
outputs and simulates an unseen record that starts in the middle of the
motion, its initial state estimated from a short measured window
(``simulate(X, y_init=...)``), as benchmarks of the field do with their
"state-initialisation window".

It also shows what :meth:`~sysid_nn.ISSMRegressor.fit` reports about the
noise. The networks are trained with one restart and ``max_iter=40`` to
keep the example fast; the defaults are what to use for real work.
"""

# %%
# Records with measurement noise
# ------------------------------
# Displacement and velocity are measured, each with white noise of 1 % of
# its standard deviation. The test record stays noise-free so that the
# scores measure the model, not the noise.
import warnings

import matplotlib.pyplot as plt
import numpy as np
from sklearn.exceptions import ConvergenceWarning

from sysid_nn import HystereticOscillator, ISSMRegressor, TDLRegressor
from sysid_nn.metrics import nrmse

warnings.filterwarnings("ignore", category=ConvergenceWarning)  # short budget

rec = HystereticOscillator().generate(n_realizations=4, random_state=6)
X = [f[:, None] for f in rec.excitation]
y = [
    np.column_stack([d, v]) for d, v in zip(rec.displacement, rec.velocity, strict=True)
]
rng = np.random.default_rng(0)
noisy = [yi + 0.01 * yi.std(axis=0) * rng.standard_normal(yi.shape) for yi in y]
X_train, y_train = X[:2], noisy[:2]
X_val, y_val = X[2:3], noisy[2:3]
X_test, y_test = X[3], y[3]

# %%
# Fitting, and what ``fit`` says about the noise
# ----------------------------------------------
# ``fit`` estimates the white noise on the training outputs from the records
# alone (``output_noise_std_``, from the residuals of a linear one-step
# model), close to the 1 % added here.
issm = ISSMRegressor(n_init=1, max_iter=40, random_state=0)
issm.fit(X_train, y_train, X_val=X_val, y_val=y_val)
spread = np.concatenate(y_train).std(axis=0)
print(
    "estimated noise, % of each output's spread:", 100 * issm.output_noise_std_ / spread
)

# %%
# At 100 samples per period the dynamics show in the second difference of
# the displacement, a few thousandths of it, and 1 % noise swamps that
# difference: a one-step fit, which takes the measured outputs as exact
# regressors, is then biased. The TDL network reads the hysteretic state from
# exactly this difference. Fitted to the displacement alone, it finds the
# noise and trains with free segment states instead (``shooting_ ==
# "free"``): no stage takes a noisy output as an exact value. The one-step
# schedule (``shooting="measured"``, which warns about the noise) is shown
# for comparison, on the noise-free test record (with this short budget of
# one restart and 40 iterations: 0.19 against 0.74).
disp = [yi[:, 0] for yi in y_train]
for shooting in ("auto", "measured"):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # the noise warning
        tdl = TDLRegressor(n_init=1, max_iter=40, random_state=0, shooting=shooting)
        tdl.fit(X_train, disp, X_val=X_val, y_val=[yi[:, 0] for yi in y_val])
    score = nrmse(y_test[:, 0], tdl.simulate(X_test))
    print(
        f"TDL, shooting={shooting!r:11s} ({tdl.shooting_}): free-run NRMSE {score:.3f}"
    )

# %%
# A record that starts in motion
# ------------------------------
# The test record is cut at 5 s: nothing before it is known. Three ways to
# start the free run:
#
# * from rest, as if the record started from zero;
# * from the measured outputs as the measured states (the unmeasured state at
#   rest), which here would also carry the measurement noise;
# * from the state estimated from the first second of measurements
#   (``y_init``): the initial state whose free run fits that window best in
#   the least-squares sense.
#
# All three are scored after the window.
k0, window = 500, 100
X_cut, y_cut = X_test[k0:], y_test[k0:]
y_meas = y_cut + 0.01 * y_cut.std(axis=0) * rng.standard_normal(y_cut.shape)
from_rest = issm.simulate(X_cut)
from_measured = issm.simulate(
    X_cut, initial_state=np.r_[y_meas[0], np.zeros(issm.n_states_ - 2)]
)
estimated = issm.simulate(X_cut, y_init=y_meas[:window])
for name, sim in (
    ("from rest", from_rest),
    ("from measured outputs", from_measured),
    ("estimated start (y_init)", estimated),
):
    score = nrmse(y_cut[window:, 0], sim[window:, 0])
    print(f"{name:26s} displacement NRMSE after the window: {score:.3f}")

# %%
# The estimated start follows the record from the end of the window on; the
# run from rest needs the record's first seconds to forget its wrong start.
t = (np.arange(len(y_cut)) + k0) * 0.01
fig, ax = plt.subplots(figsize=(8, 3.5))
ax.plot(t, y_meas[:, 0], color="0.75", lw=0.8, label="measured (1 % noise)")
ax.plot(t, from_rest[:, 0], lw=1.0, label="free run from rest")
ax.plot(t, estimated[:, 0], lw=1.2, label="free run, estimated start")
ax.axvspan(t[0], t[window], color="C2", alpha=0.1, label="initialisation window")
ax.set_xlim(t[0], t[0] + 8)
ax.set_xlabel("time (s)")
ax.set_ylabel("displacement")
ax.legend(loc="upper right", fontsize=8)
fig.tight_layout()
plt.show()
