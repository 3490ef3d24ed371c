"""
Getting started in five minutes
===============================

This example walks through a complete identification with
:class:`~sysid_nn.TDLRegressor`: generate records of the paper's hysteretic
oscillator, fit a recurrent network on a few of them, use it as a simulator
and as a predictor on records it has not seen, score it against the linear
model and check its residuals.

To keep the documentation build fast, the network is trained with one
restart and a reduced iteration budget (``n_init=1``, ``max_iter=40``). The
defaults, ``n_init=4`` and ``max_iter=150``, take a few times longer and are
what you should use for real work.
"""

# %%
# Records of the hysteretic oscillator
# ------------------------------------
# :class:`~sysid_nn.HystereticOscillator` simulates the Bouc-Wen oscillator of
# the paper (eq. 13-15) under modulated, Kanai-Tajimi filtered white noise
# (eq. 16-18), 2000 samples at ``dt = 0.01`` s per record. One record is one
# experiment: the excitation ``X`` is a 2-D array of shape
# ``(n_samples, 1)`` and the displacement ``y`` a 1-D array. Several
# experiments are passed as lists.
import warnings

import matplotlib.pyplot as plt
import numpy as np
from sklearn.exceptions import ConvergenceWarning

from sysid_nn import HystereticOscillator, TDLRegressor
from sysid_nn.metrics import nrmse
from sysid_nn.plotting import plot_response
from sysid_nn.residuals import analyze_residuals

rec = HystereticOscillator().generate(n_realizations=6, random_state=0)
X = [f[:, None] for f in rec.excitation]  # one (2000, 1) array per experiment
y = list(rec.displacement)  # one (2000,) array per experiment

X_train, y_train = X[:2], y[:2]  # two records to learn from
X_val, y_val = X[2:3], y[2:3]  # one record to select the weights on
X_test, y_test = X[3:], y[3:]  # three records the model never sees
print(f"{len(X_train)} training, {len(X_val)} validation, {len(X_test)} test records")

# %%
# Fit a recurrent network
# -----------------------
# The defaults of :class:`~sysid_nn.TDLRegressor` are the setting that
# identified this oscillator best: three output and three excitation lags,
# nine hidden nodes beside a linear bypass started at the least-squares ARX
# fit, trained for free-run simulation with a Levenberg-Marquardt solver.
# The validation record selects the weights with the best free run.
#
# With the shortened budget the last training stage stops at ``max_iter``
# before reaching ``tol``, which the estimator reports with a
# :class:`~sklearn.exceptions.ConvergenceWarning`; it is silenced here on
# purpose.
warnings.filterwarnings("ignore", category=ConvergenceWarning)

model = TDLRegressor(n_init=1, max_iter=40, random_state=0)
model.fit(X_train, y_train, X_val=X_val, y_val=y_val)
print(f"trained in {model.fit_time_:.1f} s, {model.n_iter_} solver iterations")

# %%
# The linear model is the baseline every non-linear model must beat: the same
# estimator without hidden layers, ``hidden_layer_sizes=()``, is an ARX /
# output-error model trained the same way.
linear = TDLRegressor(hidden_layer_sizes=(), n_init=1, max_iter=40, random_state=0)
linear = linear.fit(X_train, y_train, X_val=X_val, y_val=y_val)

# %%
# Simulate and predict
# --------------------
# ``simulate(X)`` runs the model from the excitation alone, starting from
# rest (paper section 4.4). ``predict(X, y)`` is the one-step-ahead
# prediction, which uses the measured displacements up to the previous
# sample (section 4.3); ``horizon=k`` predicts ``k`` steps ahead. Given a
# list, both return a list.
y_sim = model.simulate(X_test)
y_one = model.predict(X_test, y_test)
y_20 = model.predict(X_test, y_test, horizon=20)

print(
    f"network NRMSE on the test records: free run {nrmse(y_test, y_sim):.3f}, "
    f"20-step {nrmse(y_test, y_20):.4f}, one-step {nrmse(y_test, y_one):.1e}"
)
print(
    "linear  NRMSE on the test records: "
    f"free run {nrmse(y_test, linear.simulate(X_test)):.3f}, "
    f"20-step {nrmse(y_test, linear.predict(X_test, y_test, horizon=20)):.4f}, "
    f"one-step {nrmse(y_test, linear.predict(X_test, y_test)):.1e}"
)

# %%
# The normalised RMS error (:func:`sysid_nn.metrics.nrmse`) is 0 for a
# perfect model and 1 for predicting the mean. The one-step errors are tiny
# for both models: at 100 samples per second one-step prediction is nearly
# trivial and does not tell models apart. The free run and the 20-step
# prediction do. ``score`` is the :math:`R^2` of the free run, which is also
# what scikit-learn's model selection uses.
print(
    f"R^2 of the free run: network {model.score(X_test, y_test):.3f}, "
    f"linear {linear.score(X_test, y_test):.3f}"
)

# %%
# Residual test
# -------------
# An adequate model leaves one-step residuals that are white and
# uncorrelated with the excitation (paper fig. 4.3 and 4.4).
# :func:`~sysid_nn.residuals.analyze_residuals` runs the chi-square tests on
# every record and on all of them pooled; ``summary`` is a table with one
# row per test.
report = analyze_residuals(model, X_test, y_test, mode="prediction", max_lag=25)
pooled = report.summary[report.summary["sequence"] == "pooled"]
print(pooled[["test", "statistic", "dof", "p_value", "passed"]].to_string(index=False))
print("all tests passed:", report.passed)

# %%
# Read the table with the data in mind. These records are noise-free, so the
# one-step residual is not measurement noise but the model's own small
# systematic error, and with thousands of samples the chi-square tests detect
# even an error of the size printed above. The tests become the decisive
# check on measured, noisy data; the :ref:`pitfalls` page discusses the
# point and :ref:`sphx_glr_auto_examples_plot_residual_analysis.py` shows
# the tests at work.

# %%
# One figure
# ----------
# The free run of both models on a test record, against the measured
# displacement. The slow drift after yielding (permanent set) is what the
# linear model cannot follow.
j = int(np.argmax([np.abs(v).max() for v in y_test]))  # the largest record
fig, ax = plt.subplots(figsize=(7, 3.5))
plot_response(
    rec.t,
    y_test[j],
    {"network (free run)": y_sim[j], "linear (free run)": linear.simulate(X_test[j])},
    ylabel="displacement X [m]",
    title=f"Test record {3 + j}: free-run simulation",
    ax=ax,
)
ax.set_ylabel("displacement X(t) [m]")
fig.tight_layout()
plt.show()

# %%
# Next steps
# ----------
# * :ref:`sphx_glr_auto_examples_plot_tdl_prediction_vs_simulation.py`:
#   prediction and simulation, training focus, solvers and the paper's
#   network;
# * :ref:`sphx_glr_auto_examples_plot_issm.py`: the innovation state-space
#   network and its hidden hysteretic state;
# * :ref:`sphx_glr_auto_examples_plot_residual_analysis.py` and
#   :ref:`sphx_glr_auto_examples_plot_grid_search.py`: validating a model and
#   choosing its size;
# * :ref:`sphx_glr_auto_examples_plot_csv_data.py`: your own measured data;
# * the :ref:`user guide <user_guide>` for the equations and the training
#   schedule.
