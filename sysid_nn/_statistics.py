"""Statistics that the engine and the analyses share.

:func:`loss_differential_statistic` is the Diebold-Mariano (1995) statistic
of two models' per-sample losses: :func:`sysid_nn.nonlinearity_test` compares
a network with its linear model by it on held-out records, and restart
selection (:mod:`sysid_nn._engine._selection`) the refinement of the linear
model with a restart on the validation records. A foundation module: it
imports nothing of the package.
"""

from __future__ import annotations

import numpy as np
from statsmodels.regression.linear_model import OLS


def loss_differential_statistic(d: np.ndarray, bounds: np.ndarray, lag: int) -> float:
    """The Diebold-Mariano statistic of the loss differential ``d``.

    Its mean over its standard error, from the Newey-West (Bartlett)
    heteroscedasticity and autocorrelation consistent variance of
    statsmodels with truncation lag ``lag``, within each record: ``bounds``
    holds where each record's rows start in ``d``, and its end
    (``cov_type="hac-panel"`` for several). ``inf`` (or NaN) where ``d`` is
    constant.
    """
    n = len(d)
    design = np.ones((n, 1))
    if len(bounds) > 2:
        groups = np.repeat(np.arange(len(bounds) - 1), np.diff(bounds))
        fit = OLS(d, design).fit(
            cov_type="hac-panel", cov_kwds={"groups": groups, "maxlags": lag}
        )
    else:
        fit = OLS(d, design).fit(cov_type="HAC", cov_kwds={"maxlags": lag})
    with np.errstate(divide="ignore", invalid="ignore"):
        return float(fit.params[0] / fit.bse[0])
