"""The paper's section-4 study as plain functions (figs 4.1-4.7, eq. 19-20).

Kirkegaard, Nielsen & Hansen (1995) identify a Bouc-Wen hysteretic
oscillator with a tapped-delay-line (TDL) and an innovation state-space
(ISSM) network, then judge them by one-step prediction (4.3) and free-run
simulation (4.4) on realisations not used in training: residual
correlation tests (figs 4.3-4.4) and the averaged error statistics
``mu_Ns``, ``sigma_Ns`` of eq. 19-20 over 25 realisations (figs 4.5, 4.7).

The study here repeats that protocol with five models side by side: the
paper's two networks, the linear baseline and the toolbox's default TDL and
ISSM. It is built from the public API only, in four steps that can be run
and inspected one by one::

    config = StudyConfig(seed=0)
    data = generate_data(config)            # training, validation, test records
    models = fit_models(data, config)       # {name: StudyModel}
    evaluation = evaluate(models, data, config)
    evaluation.results                      # one row per realisation, model, mode

or all at once, writing figures, tables and a report::

    run_study(config, "sysid_nn_results")

Everything random is seeded from ``config.seed``; the tables are identical
whether the evaluation runs serially, on local processes or on a dask
cluster. The report opens with statements derived from the results: whether
the paper's networks simulate unseen realisations (median free-run NRMSE at
most 1) and which models' one-step residuals pass the whiteness test, with
a pointer to the user guide's pitfalls page that explains them. The figures
carry the oscillator's units (displacement in m, the excitation, a force per
unit mass, in m/s², time and lags in s).
"""

from sysid_nn.study._config import (
    MODES,
    PAPER_ISSM,
    PAPER_MODELS,
    PAPER_TDL,
    StudyConfig,
)
from sysid_nn.study._data import generate_data, select_typical
from sysid_nn.study._figures import FIGURES, hysteresis_loops
from sysid_nn.study._models import StudyModel, fit_models, model_specs
from sysid_nn.study._report import write_report
from sysid_nn.study._run import run_study, run_validation
from sysid_nn.study._scoring import evaluate, summarize

# Saved models (``sysid-nn fit --save``) pickle these classes: they are found
# under the public path, whichever private module defines them.
StudyConfig.__module__ = StudyModel.__module__ = __name__

__all__ = [
    "FIGURES",
    "MODES",
    "PAPER_ISSM",
    "PAPER_MODELS",
    "PAPER_TDL",
    "StudyConfig",
    "StudyModel",
    "evaluate",
    "fit_models",
    "generate_data",
    "hysteresis_loops",
    "model_specs",
    "run_study",
    "run_validation",
    "select_typical",
    "summarize",
    "write_report",
]
