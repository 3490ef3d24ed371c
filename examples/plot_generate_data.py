"""
Generating the paper's hysteretic oscillator data
=================================================

The test structure of Kirkegaard, Nielsen & Hansen (1995) is a
single-degree-of-freedom Bouc-Wen oscillator (eq. 13-15) under
amplitude-modulated, Kanai-Tajimi filtered white noise (eq. 16-18).
:class:`~sysid_nn.HystereticOscillator` simulates it and generates records of
2000 samples at ``dt = 0.01`` s, as in the paper.

This example calibrates the strength of the excitation, draws a few records,
reproduces the training data of the paper's fig. 4.1 and shows the hysteresis
loop that a linear model cannot reproduce.
"""

# %%
# The oscillator and the strength of its excitation
# -------------------------------------------------
# The default parameters are the paper's: ``zeta=0.01``, ``omega0=2*pi``,
# ``alpha=0.05``, ``beta=gamma=0.5``, ``n=1``, ``z0=0.01`` m, and for the
# excitation ``zeta_s=0.5``, ``omega_s=30``, ``t1=3``, ``t2=15``. The paper
# chooses the strength ``r0`` so that the mean peak displacement is twice the
# yield displacement, ``E[max|X(t)|] = 2 z0``. With ``r0="calibrate"`` (the
# default) this is done by a reproducible Monte Carlo calibration, which can
# also be called directly.
import matplotlib.pyplot as plt
import numpy as np

from sysid_nn import HystereticOscillator
from sysid_nn.excitation import modulation
from sysid_nn.plotting import plot_hysteresis, plot_records

osc = HystereticOscillator()
r0 = osc.calibrate_r0()
print(f"calibrated r0 = {r0:.4f}")

# %%
# Generating records
# ------------------
# ``generate`` draws independent realisations of the excitation and simulates
# the response from rest. The result is a :class:`~sklearn.utils.Bunch` of
# arrays of shape ``(n_realizations, n_samples)``.
rec = osc.generate(n_realizations=50, random_state=0)
print("excitation:", rec.excitation.shape, " displacement:", rec.displacement.shape)

peaks = np.abs(rec.displacement).max(axis=1)
print(f"mean peak displacement / z0 = {peaks.mean() / osc.z0:.2f} (target 2)")
print(
    f"smallest and largest peak / z0: {peaks.min() / osc.z0:.2f}, "
    f"{peaks.max() / osc.z0:.2f}"
)

# %%
# The calibration holds on average, but single realisations differ widely in
# amplitude: a model trained on one small record has to extrapolate to the
# larger ones (see the user guide's *Known pitfalls*).

# %%
# Modulation of the excitation
# ----------------------------
# The white noise is modulated by ``r(t)`` of eq. 18, which peaks at ``t1``
# and has dropped to half at ``t2``, before it is filtered by the
# Kanai-Tajimi soil filter.
fig, ax = plt.subplots(figsize=(7, 2.5))
ax.plot(rec.t, modulation(rec.t, r0=rec.r0, t1=osc.t1, t2=osc.t2))
ax.axvline(osc.t1, color="0.6", linestyle=":")
ax.axvline(osc.t2, color="0.6", linestyle=":")
ax.set_xlabel("time t [s]")
ax.set_ylabel("r(t)")
ax.set_title("Modulation function (eq. 18)")
fig.tight_layout()

# %%
# Training data (fig. 4.1)
# ------------------------
# The excitation ``F(t)`` and the displacement ``X(t)`` of one realisation,
# the kind of record the paper trains its networks on.
j = 0
fig = plot_records(
    rec.t,
    rec.excitation[j],
    rec.displacement[j],
    excitation_label="excitation F(t) [m/s²]",
    displacement_label="displacement X(t) [m]",
)
ax_x = fig.axes[1]
ax_x.axhline(osc.z0, color="0.6", linestyle=":", label="± z0")
ax_x.axhline(-osc.z0, color="0.6", linestyle=":")
ax_x.legend(loc="upper right")
fig.set_size_inches(7, 5)
fig.tight_layout()

# %%
# After yielding, the oscillator does not return to zero: the displacement
# drifts to a new equilibrium (permanent set), as between about 4 and 9 s
# here. This slow drift carries a large
# part of the displacement variance, and a free-run simulation has to get it
# right.

# %%
# The hysteresis loop
# -------------------
# The restoring term of eq. 14, ``g = alpha X + (1 - alpha) Z``, plotted
# against the displacement, shows the hysteresis loops; the hysteretic
# component ``Z`` stays within ``+- z0`` since ``beta + gamma = 1``. ``Z`` is
# not measured: the networks must reconstruct its effect from the measured
# displacement (and, for the ISSM, velocity).
g = osc.alpha * rec.displacement[j] + (1 - osc.alpha) * rec.hysteretic[j]
ax = plot_hysteresis(
    rec.displacement[j],
    g,
    xlabel="displacement X(t) [m]",
    ylabel="restoring term g(X, Z) [m]",
    title="Hysteresis loop (eq. 14-15)",
)
ax.figure.tight_layout()

plt.show()
