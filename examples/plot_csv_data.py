"""
Your own measured data from CSV files
=====================================

Measured records usually arrive as files: one file per test, with a time
column and one column per sensor, in the units of the laboratory. This
example writes such files, reads them back with pandas, identifies a model
directly from the DataFrame columns, validates it on files it has not seen,
and then does the same with the ``sysid-nn`` command line, without writing
any Python.

The files are made here from the paper's oscillator so that the example is
self-contained: four tests of 20 s at 100 samples per second, the
displacement in millimetres. For your own data, skip the first step. The
network is trained with one restart and ``max_iter=30`` so that the example
runs in seconds; use the defaults (``n_init=4``, ``max_iter=150``) for real
work.
"""

# %%
# Writing the files
# -----------------
# One CSV file per test, with the columns ``time_s``, ``force`` (the
# excitation) and ``displacement_mm``.
import tempfile
import warnings
from pathlib import Path

import matplotlib.pyplot as plt
import pandas as pd
from sklearn.exceptions import ConvergenceWarning

from sysid_nn import HystereticOscillator, TDLRegressor
from sysid_nn.cli import main as sysid_nn_command
from sysid_nn.metrics import nrmse
from sysid_nn.plotting import plot_response
from sysid_nn.residuals import analyze_residuals

warnings.filterwarnings("ignore", category=ConvergenceWarning)  # short budget

folder = Path(tempfile.mkdtemp(prefix="sysid_nn_csv_"))
rec = HystereticOscillator().generate(n_realizations=4, random_state=5)
for j in range(4):
    pd.DataFrame(
        {
            "time_s": rec.t,
            "force": rec.excitation[j],
            "displacement_mm": 1000.0 * rec.displacement[j],
        }
    ).to_csv(folder / f"test_{j + 1:02d}.csv", index=False)
print(sorted(p.name for p in folder.glob("*.csv")))

# %%
# Reading them back
# -----------------
# Everything from here on is what you would do with your own files. The
# sampling step is checked from the time column: all records given to one
# model must share it, and the estimators count lags in samples.
frames = [pd.read_csv(path) for path in sorted(folder.glob("test_*.csv"))]
print(frames[0].head())
dt = frames[0]["time_s"].diff().median()
print(f"{len(frames)} tests, dt = {dt:.4g} s, {len(frames[0])} samples each")

# %%
# Fitting on DataFrame columns
# ----------------------------
# The estimators accept pandas objects wherever they accept arrays: a
# ``DataFrame`` with the excitation column(s) for ``X`` and a ``Series`` for
# ``y``, one per test, in lists. The column names are remembered in
# ``feature_names_in_``, and the units are the user's: the estimators
# standardise internally and predict in millimetres.
X = [frame[["force"]] for frame in frames]
y = [frame["displacement_mm"] for frame in frames]
X_train, y_train = X[:2], y[:2]  # tests 1 and 2
X_val, y_val = X[2:3], y[2:3]  # test 3 selects the weights
X_new, y_new = X[3], y[3]  # test 4 is kept for validation

model = TDLRegressor(n_init=1, max_iter=30, random_state=0)
model.fit(X_train, y_train, X_val=X_val, y_val=y_val)
print("features:", model.feature_names_in_)

# %%
# Validating on an unseen test
# ----------------------------
# The free run is the demanding check: the model reproduces test 4 from its
# force record alone. The one-step residuals go through the correlation
# tests of the paper (figs 4.3-4.4; see
# :ref:`sphx_glr_auto_examples_plot_residual_analysis.py` for how to read
# them).
y_sim = model.simulate(X_new)
print(f"free-run NRMSE on test 4: {nrmse(y_new, y_sim):.3f}")
print(f"free-run R^2 on test 4:   {model.score(X_new, y_new):.3f}")

report = analyze_residuals(model, X_new, y_new, max_lag=25, skip=10)
print(report.summary[["test", "p_value", "passed"]].to_string(index=False))

fig, ax = plt.subplots(figsize=(7, 3.5))
plot_response(
    frames[3]["time_s"],
    y_new,
    y_sim,
    label="free run",
    ylabel="displacement [mm]",
    title="Test 4",
    ax=ax,
)
fig.tight_layout()
plt.show()

# %%
# The same from the command line
# ------------------------------
# ``sysid-nn fit`` reads named columns of CSV (or parquet) files, one
# experiment per file, fits a TDL or ISSM network and saves it to a model
# file (data only: loading it runs no code);
# ``sysid-nn validate`` runs a saved model on other files and writes the
# residual tests, the error statistics of eq. 19-20, figures and a report:
#
# .. code-block:: bash
#
#    sysid-nn fit test_01.csv test_02.csv test_03.csv \
#        --input force --output displacement_mm --dt 0.01 --save model.sysid
#    sysid-nn validate --model model.sysid test_04.csv --out validation
#
# A single file holding several experiments, such as the tidy table of
# ``sysid-nn generate``, is split into experiments with
# ``--split-by realization``. ``sysid-nn fit --help`` lists the options
# (model, lags, hidden layers, focus, restarts). With three or more files,
# early stopping holds out the last one as the validation record, as
# ``X_val`` did above. Here the commands run from Python through the same
# entry point, with a short budget:
files = [str(folder / f"test_{j:02d}.csv") for j in (1, 2, 3)]
saved = str(folder / "model.sysid")
status = sysid_nn_command(
    [
        "fit",
        *files,
        "--input",
        "force",
        "--output",
        "displacement_mm",
        "--dt",
        "0.01",
        "--n-init",
        "1",
        "--max-iter",
        "30",
        "--save",
        saved,
    ]
)
print("fit exit status:", status)

out = folder / "validation"
status = sysid_nn_command(
    [
        "validate",
        "--model",
        saved,
        str(folder / "test_04.csv"),
        "--out",
        str(out),
        "--quiet",
    ]
)
print("validate exit status:", status)
print(sorted(p.name for p in out.iterdir()))
