"""
ISSM network: innovations, hidden state and the Kalman-like gain
================================================================

The second network of the paper is a non-linear innovation state-space
model (eq. 7-8),

.. math::

   \\hat{\\mathbf{x}}(t) = G\\big(\\hat{\\mathbf{x}}(t-1), F(t-1),
   \\mathbf{E}(t-1)\\big), \\qquad
   \\mathbf{y}(t) = \\mathbf{H}\\hat{\\mathbf{x}}(t) + \\mathbf{E}(t),
   \\qquad \\mathbf{H} = [\\mathbf{I}_p \\; \\mathbf{0}] .

The first :math:`p` states are the measured outputs, here displacement and
velocity as in the paper; the remaining state is free, and the network has to
invent it. For the hysteretic oscillator the missing piece of the state is
the hysteretic component :math:`Z(t)` of eq. 14-15, which is never
measured. The innovations :math:`\\mathbf{E}(t)` are the one-step prediction
errors; fed back, they make the network a non-linear Kalman filter whose
transition matrix :math:`\\hat{\\boldsymbol{\\Phi}}(t)` and gain
:math:`\\hat{\\mathbf{K}}(t)` (eq. 12) change along the trajectory.

This example fits :class:`~sysid_nn.ISSMRegressor`, looks at its
innovations, compares its hidden state with the true :math:`Z`, and plots
:math:`\\hat{\\boldsymbol{\\Phi}}(t)` and :math:`\\hat{\\mathbf{K}}(t)` from
:meth:`~sysid_nn.ISSMRegressor.predict_states`. It is trained with one
restart and ``max_iter=60``; the defaults (``n_init=4``, ``max_iter=150``)
are what to use for real work.
"""

# %%
# Data: displacement and velocity measured, Z hidden
# --------------------------------------------------
# ``y`` has two columns, so :math:`p = 2`; with the default
# ``n_states=None`` the model has ``p + 2 = 4`` states: the two measured ones
# and two hidden (the paper used 3; the accuracy benchmark found 4 better).
import warnings

import matplotlib.pyplot as plt
import numpy as np
from sklearn.exceptions import ConvergenceWarning

from sysid_nn import HystereticOscillator, ISSMRegressor
from sysid_nn.metrics import nrmse
from sysid_nn.plotting import plot_hysteresis

warnings.filterwarnings("ignore", category=ConvergenceWarning)  # short budget

rec = HystereticOscillator().generate(n_realizations=5, random_state=6)
X = [f[:, None] for f in rec.excitation]
y = [
    np.column_stack([d, v]) for d, v in zip(rec.displacement, rec.velocity, strict=True)
]
X_train, y_train = X[:2], y[:2]
X_val, y_val = X[2:3], y[2:3]
X_test, y_test = X[3:], y[3:]

# %%
# Fitting the network
# -------------------
# The defaults add a linear state-space part :math:`\mathbf{A}\hat{\mathbf{x}}
# + \mathbf{B}F + \mathbf{K}\mathbf{E}` beside the MLP, started at a linear
# model fitted to the data, and train for the free run
# (``focus="simulation"``). The paper's network is
# ``ISSMRegressor(n_states=3, hidden_layer_sizes=(7,), activation="logistic",
# linear_part=False, focus="prediction")``, trained from random weights.
model = ISSMRegressor(n_init=1, max_iter=60, random_state=0)
model.fit(X_train, y_train, X_val=X_val, y_val=y_val)
print(f"{model.n_states_} states, {model.n_outputs_} measured")
print(f"{model.coefs_.size} weights")
print(f"fitted in {model.fit_time_:.1f} s")

# %%
# Innovations, prediction and simulation
# --------------------------------------
# ``predict(X, y)`` feeds the innovations :math:`\mathbf{E}(t-1) =
# \mathbf{y}(t-1) - \mathbf{H}\hat{\mathbf{x}}(t-1)` back and returns the
# one-step prediction; the innovations are what it leaves. ``simulate(X)``
# keeps :math:`\mathbf{E} = \mathbf{0}`, as in the paper's section 4.4. Both
# return displacement and velocity.
y_pred_test = model.predict(X_test, y_test)
y_sim_test = model.simulate(X_test)
# A model chosen by its free run can have an unstable one-step predictor
# (the pitfalls page): where its filter diverges on a record, the
# predictions are NaN from there on, and the record is left out of the
# one-step scores and of the state analysis below.
filtered = [bool(np.isfinite(v).all()) for v in y_pred_test]
for j in np.flatnonzero(np.logical_not(filtered)):
    print(f"test record {j}: the one-step predictor diverged")
j0 = filtered.index(True)  # the record the figures show
x_j, y_j = X_test[j0], y_test[j0]
y_pred = y_pred_test[j0]
innovations = y_j - y_pred
y_sim = y_sim_test[j0]
for k, name in enumerate(("displacement", "velocity")):
    measured = [v[:, k] for v in y_test]
    one_step = nrmse(
        [m for m, ok in zip(measured, filtered, strict=True) if ok],
        [v[:, k] for v, ok in zip(y_pred_test, filtered, strict=True) if ok],
    )
    free_run = nrmse(measured, [v[:, k] for v in y_sim_test])
    print(f"{name:12s} NRMSE: one-step {one_step:.1e}, free run {free_run:.3f}")

fig, (ax_x, ax_e) = plt.subplots(2, 1, figsize=(7, 5), sharex=True)
ax_x.plot(rec.t, y_j[:, 0], "k-", linewidth=1, label="measured")
ax_x.plot(rec.t, y_sim[:, 0], "--", linewidth=1, label="free run (E = 0)")
ax_x.set_ylabel("displacement [m]")
ax_x.legend()
ax_x.set_title("A test record")
ax_e.plot(rec.t, innovations[:, 0], linewidth=0.6)
ax_e.set_ylabel("innovation E₁(t) [m]")
ax_e.set_xlabel("time t [s]")
fig.tight_layout()

# %%
# The estimated hysteretic state
# ------------------------------
# :meth:`~sysid_nn.ISSMRegressor.predict_states` returns all states along the
# trajectory: the measured ones in the units of ``y``, the unmeasured one in
# the estimator's internal coordinates, because only its dynamics, not its
# scale or sign, can be identified. With measured outputs it runs the
# filter (innovations fed in); without, the free run.
states = model.predict_states(X_test, y_test)
print(
    "states:",
    states[0].states.shape,
    " Phi:",
    states[0].Phi.shape,
    " K:",
    states[0].K.shape,
)


# %%
# To compare the hidden states with the true :math:`Z`, map them to :math:`Z`
# by least squares together with the measured states. How much of :math:`Z`
# the hidden states explain beyond displacement and velocity is the gain in
# :math:`R^2` from adding it:
def r2_of_fit(columns, target):
    design = np.column_stack([*columns, np.ones_like(target)])
    coef, *_ = np.linalg.lstsq(design, target, rcond=None)
    fitted = design @ coef
    return 1 - np.var(target - fitted) / np.var(target), fitted


for j, st in enumerate(states):
    if not filtered[j]:
        continue  # the filter diverged on this record
    z = rec.hysteretic[3 + j]
    measured, hidden = st.states[:, :2], st.states[:, 2:]
    r2_xv, _ = r2_of_fit(measured.T, z)
    r2_all, _ = r2_of_fit(st.states.T, z)
    corr = max(abs(np.corrcoef(h, z)[0, 1]) for h in hidden.T)
    print(
        f"test record {j}: R^2 of Z from (X, V) {r2_xv:.3f}, with the hidden "
        f"states {r2_all:.3f}; largest |correlation| of a hidden state with Z "
        f"{corr:.3f}"
    )

# %%
# Displacement and velocity alone leave part of :math:`Z` unexplained; what
# adding the hidden states gains is what the network has found out about the
# hysteresis without ever seeing :math:`Z`. The figure shows :math:`Z` and
# its reconstruction from all states on the first test record, in
# time and against the displacement (the hysteresis loop).
z = rec.hysteretic[3 + j0]
_, z_hat = r2_of_fit(states[j0].states.T, z)
fig, (ax_t, ax_h) = plt.subplots(1, 2, figsize=(10, 3.8))
ax_t.plot(rec.t, z, "k-", linewidth=1, label="true Z")
ax_t.plot(rec.t, z_hat, "--", linewidth=1, label="from the states")
ax_t.set_xlabel("time t [s]")
ax_t.set_ylabel("hysteretic component Z [m]")
ax_t.legend()
plot_hysteresis(
    y_test[j0][:, 0],
    z,
    label="true Z",
    models={"from the states": z_hat},
    ylabel="Z [m]",
    ax=ax_h,
)
fig.tight_layout()

# %%
# Phi(t) and K(t) along the trajectory
# ------------------------------------
# ``Phi[t]`` is :math:`\partial\hat{\mathbf{x}}(t)/\partial\hat{\mathbf{x}}(t-1)`
# and ``K[t]`` is :math:`\partial\hat{\mathbf{x}}(t)/\partial\mathbf{E}(t-1)`,
# the transition matrix and gain of an extended Kalman filter (eq. 12). For a
# linear model they would be constant; here they change with the state along
# the record. The one-step predictor propagates
# errors through :math:`\hat{\boldsymbol{\Phi}}(t) - \hat{\mathbf{K}}(t)\mathbf{H}`
# (eq. 10), which must be stable; the estimator stores the spectral radius
# of its mean along the training data. The gains are in the units of the
# states per unit of the innovations: the measured states in metres and
# metres per second, the hidden one in internal units, so only the gains
# into the same state compare directly.
st = states[j0]
H = np.eye(model.n_outputs_, model.n_states_)
radius_phi = np.abs(np.linalg.eigvals(st.Phi)).max(axis=1)
radius_pred = np.abs(np.linalg.eigvals(st.Phi - st.K @ H)).max(axis=1)
print(f"predictor_spectral_radius_ = {model.predictor_spectral_radius_:.4f}")
for k in range(model.n_states_):
    for i, name in enumerate(("E₁ (displacement)", "E₂ (velocity)")):
        gain = st.K[:, k, i]
        print(
            f"K[{k}, {i}]: state {k} per unit of {name}: mean {gain.mean():+.4g}, "
            f"std {gain.std():.3g}"
        )
print(
    f"spectral radius of Phi - K H on the test record: "
    f"{radius_pred.min():.4f} to {radius_pred.max():.4f}"
)

fig, axes = plt.subplots(3, 1, figsize=(7, 7.5), sharex=True)
axes[0].plot(rec.t, radius_phi, linewidth=0.8, label="Phi(t)")
axes[0].plot(rec.t, radius_pred, linewidth=0.8, label="Phi(t) - K(t) H")
axes[0].axhline(1.0, color="k", linestyle=":", linewidth=1)
axes[0].set_ylabel("spectral radius")
axes[0].legend()
axes[1].plot(rec.t, st.K[:, 2, 0], linewidth=0.8)
axes[1].set_ylabel("K[2, 0]")
axes[1].set_title("gain from the displacement innovation to the hidden state")
axes[2].plot(rec.t, z / HystereticOscillator().z0, "k-", linewidth=0.8)
axes[2].set_ylabel("true Z / z0")
axes[2].set_xlabel("time t [s]")
fig.tight_layout()
plt.show()

# %%
# The third panel shows the true hysteretic component for reference, to set
# the changes of the linearisation against the excursions of :math:`Z`
# towards the yield level :math:`z_0`, where the restoring force changes its
# stiffness. The gains into the measured states hardly move (see the
# standard deviations printed above); the gains into the hidden state do. A
# spectral radius of :math:`\hat{\boldsymbol{\Phi}} - \hat{\mathbf{K}}\mathbf{H}` that
# stays above one for long stretches would make the one-step predictor drift
# from the measurements; the estimator then warns with
# :class:`~sysid_nn.UnstablePredictorWarning`.

# %%
# Displacement alone: starting from a TDL network
# -----------------------------------------------
# With only the displacement measured (:math:`p = 1`), the network must
# invent every state beyond it. Every TDL network is also an ISSM network:
# its states are the past outputs and excitation samples, the MLP gives the
# newest output and the linear part shifts the others down. ``init="tdl"``
# trains a :class:`~sysid_nn.TDLRegressor` with the ISSM's hidden layers on
# the same records, realises it exactly in state space (5 states here:
# :math:`y(t), y(t-1), y(t-2), F(t-1), F(t-2)`) and then fits only the
# innovation gain. ``hidden_layer_sizes=(9,)`` makes it the default TDL
# network. On clean records of the accuracy benchmark this start matched the
# TDL (median free-run NRMSE 0.035 with one training record), where the
# default start from a linear model reached 0.10; with measurement noise the
# default start is the robust one (user guide, "Pitfalls").
y_x = [v[:, 0] for v in y]
models_x = {
    'init="arx"': ISSMRegressor(n_init=1, max_iter=60, random_state=0),
    'init="tdl"': ISSMRegressor(
        init="tdl", hidden_layer_sizes=(9,), n_init=1, max_iter=60, random_state=0
    ),
}
for name, m in models_x.items():
    m.fit(X_train, y_x[:2], X_val=X_val, y_val=y_x[2:3])
    free = nrmse(y_x[3:], m.simulate(X_test))
    one = nrmse(y_x[3:], m.predict(X_test, y_x[3:]))
    one_text = f"{one:.1e}" if np.isfinite(one) else "diverged on a test record"
    print(
        f"{name}: {m.n_states_} states, free run NRMSE {free:.3f}, "
        f"one-step {one_text}, predictor radius "
        f"{m.predictor_spectral_radius_:.3f}"
    )

# %%
# In this short-budget run of one restart the linear start gives the
# slightly better free run, but a one-step predictor that diverges on a test
# record; over the accuracy benchmark's seeds the TDL start is the better
# one on clean records. The TDL start's innovation gain stays at the TDL's
# own one-step predictor (predictor radius
# 0: the measured output takes the place of every lag): on clean records the
# refit finds nothing better within its margin. The model keeps the network
# it started from in ``tdl_``; its free run is that network's, to rounding:
m = models_x['init="tdl"']
print(f"largest difference: {np.abs(m.simulate(x_j) - m.tdl_.simulate(x_j)).max():.1e}")
