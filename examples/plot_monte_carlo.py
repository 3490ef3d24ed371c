"""
Monte Carlo comparison of the networks (eq. 19-20, figs 4.5 and 4.7)
====================================================================

The paper compares its two networks on 25 simulated realisations that were
not used in training: for each realisation :math:`j` the error
:math:`\\epsilon_j(t)` of the one-step prediction (section 4.3) or of the
free-run simulation (section 4.4) is averaged over time, and the averaged
mean and standard deviation over the realisations,

.. math::

   \\mu_{N_s} = \\frac{1}{N_s} \\sum_{j=1}^{N_s} \\frac{1}{N\\Delta t}
   \\int_0^{N\\Delta t} \\epsilon_j(t)\\, dt , \\qquad
   \\sigma_{N_s} = \\sqrt{\\frac{1}{N_s} \\sum_{j=1}^{N_s}
   \\frac{1}{N\\Delta t} \\int_0^{N\\Delta t}
   \\big(\\epsilon_j(t) - \\mu_{N_j}\\big)^2 dt} ,

are shown as bars (figs 4.5 and 4.7).

:mod:`sysid_nn.study` runs this protocol in four steps, with five models
side by side: the paper's TDL and ISSM networks, the linear baseline and the
toolbox's default TDL and ISSM. This example runs a reduced study: 8 test
realisations instead of 25, two training records, one restart and
``max_iter=30`` per network. The full study is
``run_study(StudyConfig(seed=0), "sysid_nn_results")``, which also writes
every figure, the tables and a report.
"""

# %%
# Configuration and data
# ----------------------
# :class:`~sysid_nn.study.StudyConfig` holds every setting; all seeds are
# derived from ``seed``. ``quick=True`` uses one restart per network and
# ``estimator_params`` overrides the estimators' parameters, here for all
# models at once.
import matplotlib.pyplot as plt
import numpy as np

from sysid_nn.metrics import error_statistics
from sysid_nn.plotting import plot_error_statistics
from sysid_nn.study import StudyConfig, evaluate, fit_models, generate_data, summarize

config = StudyConfig(
    seed=0,
    n_train=2,
    n_val=1,
    n_test=8,
    quick=True,
    estimator_params={"all": {"max_iter": 30}},
)
data = generate_data(config)
print("training records:", data.train.displacement.shape)
print("test records:    ", data.test.displacement.shape)
peaks = np.abs(data.test.displacement).max(axis=1) / data.oscillator.z0
print("peak displacement / z0 of the test records:", np.round(peaks, 2))

# %%
# The training records are the ones of typical amplitude among
# ``config.candidates`` generated records (a record of small amplitude makes
# every model extrapolate); the test realisations are drawn independently and
# differ widely in amplitude, as printed above.
#
# Fitting the models
# ------------------
# :func:`~sysid_nn.study.fit_models` fits every model on the training
# records with early stopping on the validation record. The paper's TDL sees
# every third sample (``dt = 0.03`` s), as in the paper; the ISSMs are given
# displacement and velocity. Warnings raised while fitting are kept, not
# shown: with the short budget most networks stop at ``max_iter``.
models = fit_models(data, config)
for name, model in models.items():
    est = model.estimator
    kinds = sorted({w.split(":")[0] for w in data.fit_warnings[name]})
    print(
        f"{model.label:15s} {type(est).__name__:13s} {est.coefs_.size:4d} weights, "
        f"{est.fit_time_:5.1f} s, warnings: {', '.join(kinds) or 'none'}"
    )

# %%
# Monte Carlo evaluation
# ----------------------
# :func:`~sysid_nn.study.evaluate` runs every model in both modes on every
# test realisation, tests the residuals (whiteness and cross-correlation
# with the input, figs 4.3-4.4) and computes eq. 19-20 with
# :func:`~sysid_nn.metrics.error_statistics`. The realisations are
# independent, so they run in parallel with ``config.n_jobs`` or on a Dask
# cluster (see :ref:`sphx_glr_auto_examples_plot_dask.py`).
evaluation = evaluate(models, data, config)
summary = summarize(evaluation, models)
columns = ["label", "mode", "nrmse_median", "mu_Ns", "sigma_Ns", "n_divergent"]
print(summary[columns].to_string(index=False, float_format=lambda v: f"{v:.3g}"))

# %%
# Read each network against the linear baseline in the same mode: a network
# that does not beat it in simulation has not learnt the hysteresis, however
# well it predicts one step ahead. With the paper's configuration and this
# short budget, compare especially the paper's networks with the linear
# model; :ref:`pitfalls` explains why their plain delays and random start are
# hard to train at ``dt = 0.01`` s.
#
# ``mu_Ns`` and ``sigma_Ns`` are in metres, like the displacement; the
# median normalised RMS error (``nrmse_median``) is scale-free and less
# dominated by the largest realisations. A realisation whose free run
# diverged counts in ``n_divergent`` and makes ``mu_Ns`` and ``sigma_Ns``
# NaN: a divergence is never averaged away.
#
# Figures 4.5 and 4.7
# -------------------
# :func:`~sysid_nn.plotting.plot_error_statistics` draws the bars of the
# paper from ``{model: ErrorStatistics}``, each labelled with its value; when
# the bars differ by orders of magnitude (one-step errors here), the axis is
# logarithmic in both directions. A model whose statistics are NaN (a
# divergent realisation) has no bar.
fig, (ax_pred, ax_sim) = plt.subplots(1, 2, figsize=(10, 4))
plot_error_statistics(
    evaluation.statistics["prediction"],
    unit="m",
    title="One-step prediction errors (fig. 4.5)",
    ax=ax_pred,
)
plot_error_statistics(
    evaluation.statistics["simulation"],
    unit="m",
    title="Simulation errors (fig. 4.7)",
    ax=ax_sim,
)
for ax in (ax_pred, ax_sim):
    ax.tick_params(axis="x", labelrotation=30)
fig.tight_layout()

# %%
# The statistics hide how much the realisations differ. The free-run NRMSE
# of every realisation, against its peak displacement, shows which records
# each model finds hard:
results = evaluation.results.query("mode == 'simulation'")
fig, ax = plt.subplots(figsize=(7, 4))
for key, model in models.items():
    rows = results[results["model"] == key].sort_values("realization")
    ax.semilogy(peaks[rows["realization"]], rows["nrmse"], "o", label=model.label)
ax.set_xlabel("peak displacement / z0 of the test realisation")
ax.set_ylabel("free-run NRMSE")
ax.set_title("Free-run error per test realisation")
ax.legend(fontsize="small")
fig.tight_layout()
plt.show()

# %%
# Eq. 19-20 directly
# ------------------
# The study is built from the public API only. The same statistics for one
# model, from its free runs on the test records:
tdl = models["tdl"]
X_test, y_test = tdl.arrays(data.test)
errors = [
    y - y_sim for y, y_sim in zip(y_test, tdl.estimator.simulate(X_test), strict=True)
]
stats = error_statistics(errors, dt=data.dt)
print(stats.summary)
print(
    "same as the study:",
    np.allclose(
        [stats.mu, stats.sigma],
        [
            evaluation.statistics["simulation"][tdl.label].mu,
            evaluation.statistics["simulation"][tdl.label].sigma,
        ],
        equal_nan=True,
    ),
)
print(stats.to_frame().head())
