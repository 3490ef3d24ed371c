"""
Identifying a multi-storey structure
====================================

A building shaken by an earthquake is the structure most users of this
toolbox measure: accelerometers on the floors, the ground acceleration at the
base. :class:`~sysid_nn.ShearBuilding` simulates such a structure, an
``n``-storey shear frame with a Bouc-Wen hysteretic spring in every storey,
under the earthquake-like ground motion of the paper's oscillator. Because
its true order is known (a linear shear building of ``n`` storeys has
``2 n`` states; each yielding storey adds one hysteretic state), it is the
place to see how an identification finds the order of a structure.

This tutorial generates records of a three-storey building, lets an
:class:`~sysid_nn.ISSMRegressor` read its order from the data (and a
five-storey building's), fits that network and a linear model, and compares
their free runs on a record neither has seen. The budgets are short so that
the page builds in well under a minute; see :ref:`models` for the settings
to use for real work.
"""

# %%
# The building and its records
# ----------------------------
# The defaults: three equal floors and storeys, fundamental frequency 1.42 Hz,
# 2 % damping in every mode, a post-yield stiffness of 10 %, and a ground
# motion whose strength is calibrated so that the mean peak storey drift is
# twice the yield drift. The outputs are the absolute floor accelerations,
# what accelerometers measure; the input is the ground acceleration.
import warnings

import matplotlib.pyplot as plt
from sklearn.exceptions import ConvergenceWarning

from sysid_nn import ISSMRegressor, ShearBuilding
from sysid_nn.metrics import nrmse
from sysid_nn.plotting import plot_order_selection

warnings.filterwarnings("ignore", category=ConvergenceWarning)  # short budget

building = ShearBuilding(n_storeys=3)
modes = building.modal_properties()
print("natural frequencies [Hz]:", modes.frequency.round(2))
print("linear order:", modes.linear_order)

rec = building.generate(5, random_state=0, outputs=("acceleration", "drift"))
X = [g[:, None] for g in rec.ground_acceleration]  # one 2-D input per record
y = list(rec.acceleration)  # (n_samples, 3): one column per floor
X_train, y_train = X[:3], y[:3]
X_val, y_val = X[3:4], y[3:4]
X_test, y_test = X[4], y[4]

fig, (ax_a, ax_d) = plt.subplots(2, 1, figsize=(7, 5), sharex=True)
ax_a.plot(rec.t, rec.ground_acceleration[4], "k-", linewidth=0.6, label="ground")
ax_a.plot(rec.t, y_test[:, 2], linewidth=0.6, label="roof (absolute)")
ax_a.set_ylabel("acceleration")
ax_a.legend()
for i in range(3):
    ax_d.plot(rec.t, rec.drift[4, :, i] / building.z0, linewidth=0.6)
ax_d.axhline(1, color="grey", linestyle=":", linewidth=0.8)
ax_d.axhline(-1, color="grey", linestyle=":", linewidth=0.8)
ax_d.set_ylabel("drift / yield drift")
ax_d.set_xlabel("time t [s]")
ax_d.legend([f"storey {i + 1}" for i in range(3)], fontsize="small")
fig.tight_layout()

# %%
# Order selection from the data
# -----------------------------
# ``ISSMRegressor`` chooses its number of states from the data by default
# (``n_states="auto"``), before training starts. The singular values of the
# block-Hankel projection that its subspace step factorises fall off after
# the order of the linear dynamics: the state of a linear system of order
# ``L`` spans ``L`` directions. A linear model of every candidate order is
# scored by its free run on the validation record; the smallest order within
# 5 % of the best, or the order at the largest gap when that is larger and
# as good, is the linear order ``L``. The network then gets
# ``L + max(p, ceil(L / p))`` states for ``p`` outputs: one more state per
# measured floor, the room for each storey's hysteretic state. For this
# building ``L = 6`` and the network gets ``9 = 3 n`` states, its true order.
# The evidence is kept in ``order_selection_`` and drawn by
# :func:`~sysid_nn.plotting.plot_order_selection`.
network = ISSMRegressor(n_init=1, max_iter=40, random_state=0)
network.fit(X_train, y_train, X_val=X_val, y_val=y_val)
sel = network.order_selection_
print(
    f"3 storeys: gap after {sel.gap_order}, linear order {sel.linear_order}, "
    f"n_states {network.n_states_} (true order {3 * 3})"
)
fig = plot_order_selection(network)
fig.suptitle("Three storeys: the order from the data")
fig.tight_layout()

# %%
# The chosen order follows the number of storeys. Five storeys measured on
# every floor: the largest gap comes after 10 singular values, ``2 n``, and
# the network gets 15 states. The order is chosen before the first training
# step, so one iteration of a linear model is enough to read it here.
five = ShearBuilding(n_storeys=5).generate(5, random_state=0, outputs="acceleration")
X5 = [g[:, None] for g in five.ground_acceleration]
y5 = list(five.acceleration)
probe = ISSMRegressor(hidden_layer_sizes=(), n_init=1, max_iter=1, random_state=0)
probe.fit(X5[:3], y5[:3], X_val=X5[3:4], y_val=y5[3:4])
sel5 = probe.order_selection_
print(
    f"5 storeys: gap after {sel5.gap_order}, linear order {sel5.linear_order}, "
    f"n_states {probe.n_states_} (true order {3 * 5})"
)
fig = plot_order_selection(probe)
fig.suptitle("Five storeys")
fig.tight_layout()

# %%
# The identified network, and the linear model
# --------------------------------------------
# The network above has the chosen ``n_states`` states, the first three the
# measured floor accelerations, and one hidden layer (three units per
# unmeasured state, ``hidden_layer_sizes="auto"``) beside its linear part,
# which lets it bend the storey forces as the storeys yield. The linear model
# (``hidden_layer_sizes=()``, with the linear order's six states) is the
# baseline every non-linear model must beat. One restart and a few dozen
# iterations each.
linear = ISSMRegressor(
    n_states=sel.linear_order,
    hidden_layer_sizes=(),
    n_init=1,
    max_iter=40,
    random_state=0,
)
linear.fit(X_train, y_train, X_val=X_val, y_val=y_val)
fits = {"linear": linear, f"ISSM, {network.n_states_} states": network}
for label, model in fits.items():
    print(f"{label}: {model.coefs_.size} weights, fitted in {model.fit_time_:.1f} s")

# %%
# Free runs on an unseen record
# -----------------------------
# The free run (``simulate``) uses the ground acceleration alone, as a model
# that replaces the structure must. Its normalised RMS error per floor
# (1 is the error of predicting zero):
fig, ax = plt.subplots(figsize=(7, 3.5))
ax.plot(rec.t, y_test[:, 2], "k-", linewidth=1, label="measured")
for label, model in fits.items():
    y_sim = model.simulate(X_test)
    errors = [nrmse(y_test[:, i], y_sim[:, i]) for i in range(3)]
    print(f"{label:22s} NRMSE per floor: " + ", ".join(f"{e:.3f}" for e in errors))
    ax.plot(rec.t, y_sim[:, 2], "--", linewidth=0.8, label=label)
ax.set_xlim(2, 12)
ax.set_xlabel("time t [s]")
ax.set_ylabel("roof acceleration")
ax.set_title("Free run on a test record")
ax.legend()
fig.tight_layout()

# %%
# The hysteresis adds three states (one per storey) that the linear model
# cannot have; the network has them, ``9 = 3 n`` states chosen from the data,
# and its hidden layer bends the storey forces: its free-run error on the
# unseen record is a fraction of the linear model's.
#
# What the models say about the structure
# ---------------------------------------
# :func:`~sysid_nn.modal_parameters` reads the natural frequencies and
# damping ratios of a fitted model from its linearisation at rest, with 95 %
# intervals from the weights' covariance, and marks the numerical modes
# (``structural`` False). The building's own modes come from
# :meth:`~sysid_nn.ShearBuilding.modal_properties`. These records yield, so
# the linear model's modes are those of an equivalent, softer and more damped
# structure; the network's at rest are the small-amplitude ones. (For the
# intervals of a linear model, fit it with ``early_stopping=False``: see
# :ref:`structure`.)
from sysid_nn import backbone, modal_parameters
from sysid_nn.plotting import plot_backbone

dt = float(rec.t[1] - rec.t[0])
print("building: ", modes.frequency.round(3), "Hz, damping", modes.damping_ratio)
for label, model in fits.items():
    table = modal_parameters(model, dt)
    table = table[table.structural]
    print(f"{label}:", table.frequency_hz.round(3).to_numpy(), "Hz, damping",
          table.damping_ratio.round(3).to_numpy())  # fmt: skip

# %%
# How the first mode changes with amplitude: :func:`~sysid_nn.backbone`
# excites the model with a one-period sine burst at its first mode and reads
# the equivalent frequency and damping of the free decay that follows by the
# Hilbert transform. The same analysis of the generator's equations is the
# reference; both soften as the storeys yield (when this page was written,
# the network's first mode fell from 1.405 to 1.336 Hz over the amplitudes
# drawn and the generator's from 1.403 to 1.329 Hz, while the equivalent
# damping rose from about 3 % to 7-8 %).
curve = backbone(network, dt, output=2)
reference = backbone(
    building, dt, amplitudes=curve.amplitude, output=2, response="acceleration"
)
fig = plot_backbone(curve, reference, amplitude_label="roof acceleration amplitude")
fig.tight_layout()
plt.show()
