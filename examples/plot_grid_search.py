"""
Choosing the number of hidden nodes with cross-validation
=========================================================

The paper constructs its networks "by trial and error". With scikit-learn's
:class:`~sklearn.model_selection.GridSearchCV` the trial and error becomes a
cross-validated search. The one rule to respect with dynamic models is that
a sample is a **whole experiment**: the records are passed as lists, so
:class:`~sklearn.model_selection.KFold` holds out whole records and no time
series is ever cut into shuffled rows.

The search is scored on what the model is for: the free-run simulation
(:func:`~sysid_nn.metrics.make_simulation_scorer`) and the 20-step-ahead
prediction (:func:`~sysid_nn.metrics.make_prediction_scorer`). The one-step
prediction would not do: at ``dt = 0.01`` s it is nearly perfect for every
candidate.

To run in seconds the example searches three candidates over six records of
10 s (1000 samples, half the paper's records) in three folds, with one
restart and ``max_iter=30`` per fit. A full-size search would try more
candidates (and lags) on more and longer experiments with the defaults
``n_init=4`` and ``max_iter=150``, and ``n_jobs`` to run the fits in
parallel.
"""

# %%
# Records as lists of experiments
# -------------------------------
import warnings

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from sklearn.exceptions import ConvergenceWarning
from sklearn.model_selection import GridSearchCV, KFold

from sysid_nn import HystereticOscillator, TDLRegressor
from sysid_nn.metrics import make_prediction_scorer, make_simulation_scorer, nrmse

warnings.filterwarnings("ignore", category=ConvergenceWarning)  # short budget

rec = HystereticOscillator().generate(n_realizations=9, n_samples=1000, random_state=3)
X = [f[:, None] for f in rec.excitation]
y = list(rec.displacement)
X_search, y_search = X[:6], y[:6]  # cross-validated search
X_val, y_val = X[6:7], y[6:7]  # early stopping of every fit
X_test, y_test = X[7:], y[7:]  # held out for the final check

# %%
# ``KFold(3)`` on a list of six records gives three folds of two records
# each: every candidate is trained on four records and scored on the other
# two.
for k, (train, test) in enumerate(KFold(3).split(X_search)):
    print(f"fold {k}: train on records {train.tolist()}, score on {test.tolist()}")

# %%
# The search
# ----------
# The candidates are the linear model, ``hidden_layer_sizes=()``, and one
# hidden layer of 3 or 9 nodes. Both scorers are "greater is better": they
# return minus the normalised RMS error (NRMSE). ``refit="simulation"``
# refits the best candidate on all six records.
#
# Every fit selects its weights on the free run of a validation record
# (early stopping). Fit parameters go through ``search.fit`` to every fit;
# here the same validation record serves all folds. scikit-learn splits a
# fit parameter along with ``X`` when it has as many items as ``X``, so keep
# the number of validation records different from the number of search
# records.
scoring = {
    "simulation": make_simulation_scorer(metric="nrmse"),
    "20-step": make_prediction_scorer(horizon=20, metric="nrmse"),
}
search = GridSearchCV(
    TDLRegressor(n_init=1, max_iter=30, random_state=0),
    {"hidden_layer_sizes": [(), (3,), (9,)]},
    cv=KFold(3),
    scoring=scoring,
    refit="simulation",
)
search.fit(X_search, y_search, X_val=X_val, y_val=y_val)

results = pd.DataFrame(search.cv_results_)
table = pd.DataFrame(
    {
        "hidden layers": results["param_hidden_layer_sizes"].astype(str),
        "free-run NRMSE": -results["mean_test_simulation"],
        "20-step NRMSE": -results["mean_test_20-step"],
        "fit time [s]": results["mean_fit_time"],
    }
)
print(table.to_string(index=False, float_format=lambda v: f"{v:.3g}"))
print("best:", search.best_params_)

# %%
# Each row is the mean over the three folds. The linear model is the
# baseline: a hidden layer that does not beat it has not learnt the
# hysteresis. The spread over the folds, shown below, is large because the
# records differ widely in amplitude; compare it with the differences
# between candidates before trusting a ranking.
fig, ax = plt.subplots(figsize=(6.5, 3.8))
x = np.arange(len(results))
for offset, key in ((-0.1, "simulation"), (0.1, "20-step")):
    ax.errorbar(
        x + offset,
        -results[f"mean_test_{key}"],
        yerr=results[f"std_test_{key}"],
        fmt="o",
        capsize=3,
        label=f"{key} NRMSE",
    )
ax.set_xticks(x, table["hidden layers"])
ax.set_yscale("log")
ax.set_xlabel("hidden_layer_sizes")
ax.set_ylabel("NRMSE on held-out records")
ax.set_title("Cross-validation by experiment (mean ± std over folds)")
ax.legend()
fig.tight_layout()
plt.show()

# %%
# The chosen model on unseen records
# ----------------------------------
# ``best_estimator_`` is refitted on all search records. Cross-validation
# scores are slightly optimistic for the chosen candidate, so judge it on
# records that took no part in the search.
best = search.best_estimator_
print(f"free-run NRMSE on the test records: {nrmse(y_test, best.simulate(X_test)):.3f}")
print(f"search.score, the refit scorer: {search.score(X_test, y_test):.3f}")
print(f"best.score, R^2 of the free run: {best.score(X_test, y_test):.3f}")

# %%
# Notes
# -----
# * ``search.score`` uses the refit scorer, here the negative NRMSE of the
#   free run; the estimator's own ``score`` (used when ``scoring`` is not
#   given) is the :math:`R^2` of the free run.
# * A candidate whose free run diverges scores ``-inf`` and is ranked last
#   (scikit-learn then warns about non-finite scores); pass
#   ``divergence_score=-1e6`` to the scorer factories for a finite penalty.
# * :class:`~sklearn.model_selection.GroupKFold` and
#   :func:`~sklearn.model_selection.cross_val_score` split lists of records
#   in the same way.
