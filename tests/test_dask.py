"""Restarts and grid searches on the worker processes of a local Dask cluster.

The estimators, their data and the compiled kernels' arguments travel to
separate worker processes (pickled), and each worker limits its own BLAS
threads; the results must equal the serial ones bit for bit.
"""

import warnings

import joblib
import numpy as np
import pytest
from sklearn.exceptions import ConvergenceWarning
from sklearn.model_selection import GridSearchCV, KFold

from sysid_nn import HystereticOscillator, ISSMRegressor, TDLRegressor


@pytest.mark.filterwarnings("ignore:The linear model of:UserWarning")
def test_restarts_and_grid_search_on_worker_processes():
    distributed = pytest.importorskip("dask.distributed")
    rec = HystereticOscillator().generate(4, 400, random_state=3)
    X = [f[:, None] for f in rec.excitation]
    y = list(rec.displacement)
    y2 = [np.column_stack(p) for p in zip(rec.displacement, rec.velocity, strict=True)]
    params = {"n_init": 3, "max_iter": 4, "random_state": 0}
    grid = {"hidden_layer_sizes": [(2,), (4,)]}
    small = TDLRegressor(n_init=1, max_iter=3, random_state=0)

    def fit_all(n_jobs):
        return (
            TDLRegressor(**params, n_jobs=n_jobs).fit(X[:2], y[:2]),
            ISSMRegressor(**params, n_jobs=n_jobs).fit(X[:2], y2[:2]),
            GridSearchCV(small, grid, cv=KFold(2), n_jobs=n_jobs).fit(X, y),
        )

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)  # short budgets
        warnings.filterwarnings(
            "ignore", "A linear one-step model leaves a white misfit", UserWarning
        )
        serial = fit_all(None)
        with (
            distributed.LocalCluster(
                n_workers=2,
                threads_per_worker=1,
                processes=True,
                dashboard_address=None,
            ) as cluster,
            distributed.Client(cluster) as client,
            distributed.get_task_stream(client) as tasks,
            joblib.parallel_config(backend="dask"),
        ):
            on_dask = fit_all(-1)
    # Every restart and every (candidate, fold) fit ran as a task.
    assert len(tasks.data) >= 2 * params["n_init"] + 2 * 2
    for ours, theirs in zip(serial[:2], on_dask[:2], strict=True):
        np.testing.assert_array_equal(ours.coefs_, theirs.coefs_)
        np.testing.assert_array_equal(ours.restart_scores_, theirs.restart_scores_)
    np.testing.assert_array_equal(
        serial[2].cv_results_["mean_test_score"],
        on_dask[2].cv_results_["mean_test_score"],
    )
    assert serial[2].best_params_ == on_dask[2].best_params_
