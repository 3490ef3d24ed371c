"""Delta-method uncertainty of the recurrent networks' outputs.

At the end of ``fit`` the covariance of the fitted weights is estimated from
the exact recurrent Jacobian of the final training objective (the free run
for the simulation focus, the one-step predictor for the prediction focus):

.. math:: C = s^2 \\, (J^T J + \\alpha M)^{+},

with ``s^2`` the residual variance corrected for the effective number of
weights and ``M`` the mask of penalised weights. ``predict`` and ``simulate``
propagate ``C`` to every sample through the forward sensitivities of the run
they make, ``var(yhat(t)) = J(t) C J(t)^T``, and add the residual variance
for a prediction interval. Everything here works in the estimators'
standardised units and converts to the user's units on the way out.
"""

from __future__ import annotations

import copy
import warnings
from itertools import pairwise

import numpy as np

from sysid_nn._kernels._propagation import row_variances

#: Eigenvalues of the normal matrix (scaled to a unit diagonal) below this
#: share of the largest are treated as zero (pseudo-inverse): directions the
#: training data do not determine get no variance instead of an arbitrary
#: huge one. ``J^T J`` squares the condition number of ``J``, so this drops
#: directions whose singular value is below 1e-5 of the largest.
_RCOND = 1e-10

_INTERVALS = ("prediction", "confidence")
#: A sensitivity ``|d yhat / d w|`` (standardised units) above this along the
#: training records means that a change of a weight by 1e-6 moves the output
#: by its standard deviation: the linearisation behind the bands fails.
_SENSITIVITY_LIMIT = 1e6


def _normal_matrix(est, w, data, seg, cols=None):
    """Normal matrix ``J^T J`` of a run and the residual sums of squares.

    The one place where the full Jacobian of the training data is formed;
    a memory-bounded accumulation can replace it. Returns ``(JtJ, rss,
    n_rows, largest |J|)`` with ``rss`` per output, or ``None`` if the run
    diverges.
    """
    Yhat, J, diverged, _ = est._run(w, data, seg, True)
    if (diverged >= 0).any():
        return None
    if cols is not None:
        J = J[:, cols]
    rows = data.modelled
    R = Yhat[rows] - data.Y[rows]
    return J.T @ J, (R * R).sum(axis=0), len(rows), float(np.abs(J).max(initial=0))


def _pseudo_inverse(M):
    """Symmetric pseudo-inverse with the :data:`_RCOND` cutoff.

    The cutoff applies to ``M`` scaled to a unit diagonal (as Marquardt's
    damping does): a weight the outputs are very sensitive to must not push
    the well-determined ones below the cutoff. Weights with a zero column
    get no variance.
    """
    d = np.sqrt(np.diag(M))
    live = d > 0
    D = np.where(live, 1.0 / np.where(live, d, 1.0), 0.0)
    lam, V = np.linalg.eigh(D[:, None] * M * D[None, :])
    top = lam.max(initial=0.0)
    keep = lam > _RCOND * top if top > 0 else np.zeros(len(lam), dtype=bool)
    inv = (V[:, keep] / lam[keep]) @ V[:, keep].T
    return D[:, None] * inv * D[None, :]


def _delta_covariance(normal, penalty):
    """``(M^+, n_eff)``: unscaled covariance and effective number of weights."""
    JtJ = normal[0]
    inv = _pseudo_inverse(JtJ + np.diag(penalty))
    return inv, float(np.sum(inv * JtJ))  # trace(inv @ JtJ), both symmetric


def _residual_variance(normal, n_eff, p):
    """Residual variance per output, corrected for ``n_eff`` fitted weights."""
    _, rss, n_rows, _ = normal
    dof = max(n_rows - n_eff / p, 1.0)
    return rss / dof


def _realisation_map(est) -> np.ndarray:
    """Jacobian of an ``init="tdl"`` ISSM's weights by its TDL's weights.

    The realisation is affine in the TDL's weights, so unit steps give it
    exactly.
    """
    tdl = copy.copy(est.tdl_)
    w0 = tdl.coefs_
    base, _ = est._realise_tdl(tdl)
    G = np.empty((len(base), len(w0)))
    for j in range(len(w0)):
        tdl.coefs_ = w0.copy()
        tdl.coefs_[j] += 1.0
        G[:, j] = est._realise_tdl(tdl)[0] - base
    return G


def fit_covariance(est, train) -> None:
    """Store ``coefs_covariance_`` and the noise variances on a fitted ``est``.

    * The covariance is ``s^2 (J^T J + alpha M)^+`` of the final training
      objective, pooled over outputs in standardised units.
    * An ISSM started from a TDL network (``init="tdl"``) was trained as
      that network: its covariance is the TDL's, mapped through the exact
      (affine) realisation.
    * Weights on the innovations that the final objective does not see
      (simulation focus, TDL start: they were refitted on the one-step loss
      with the others fixed) get the covariance of that refit, from the
      one-step Jacobian, uncorrelated with the others.
    """
    w, p = est.coefs_, est.n_outputs_
    n_w = len(w)
    mask = est._penalty_mask().astype(np.float64)
    alpha = float(est.alpha)
    free = _normal_matrix(est, w, train, est._final_segment())
    one = _normal_matrix(est, w, train, 1)
    nan = np.full(p, np.nan)
    if free is None or (getattr(est, "init", None) == "tdl" and one is None):
        est.coefs_covariance_ = np.full((n_w, n_w), np.nan)
        est.n_effective_params_ = np.nan
        est.noise_variance_ = nan
        est.one_step_noise_variance_ = nan
        est._cov_root = np.full((1, n_w), np.nan)
        return
    if getattr(est, "init", None) == "tdl":
        tdl = est.tdl_
        G = _realisation_map(est)
        # The TDL's covariance already holds its own residual variance.
        cov = G @ tdl.coefs_covariance_ @ G.T
        n_eff = float(tdl.n_effective_params_)
    else:
        inv, n_eff = _delta_covariance(free, alpha * mask)
        s2 = float(free[1].sum()) / max(free[2] * p - n_eff, 1.0)
        cov = s2 * inv
    if free[3] > _SENSITIVITY_LIMIT:
        warnings.warn(
            f"The outputs of this {type(est).__name__} are extremely sensitive to "
            f"its weights along the training records (|d yhat / d w| up to "
            f"{free[3]:.1e} in standardised units): its recurrence is at the edge "
            "of stability there, and the bands of return_std=True, which "
            "linearise the outputs in the weights, are unreliable. Check them "
            "with sysid_nn.uncertainty.ensemble_std.",
            UserWarning,
            stacklevel=4,
        )
    innovations = getattr(est, "_innovation_index", None)
    if innovations is not None and est._final_segment() != 1 and one is not None:
        idx = innovations()
        sub = _normal_matrix(est, w, train, 1, idx)
        inv_k, n_k = _delta_covariance(sub, alpha * mask[idx])
        s2_k = float(sub[1].sum()) / max(sub[2] * p - n_eff - n_k, 1.0)
        cov[idx, :] = 0.0
        cov[:, idx] = 0.0
        cov[np.ix_(idx, idx)] = s2_k * inv_k
        n_eff += n_k
    cov = 0.5 * (cov + cov.T)
    scale2 = est._y_scale**2
    est.coefs_covariance_ = cov
    est.n_effective_params_ = n_eff
    est.noise_variance_ = _residual_variance(free, n_eff, p) * scale2
    est.one_step_noise_variance_ = (
        _residual_variance(one, n_eff, p) * scale2 if one is not None else nan
    )
    est._cov_root = _square_root(cov)


def _square_root(cov):
    """``L^T`` with ``C = L L^T``, so that every band costs one product.

    Computed on ``C`` scaled to a unit diagonal: the variances of the weights
    span many decades, and each direction kept counts on the data it came
    from. Only eigenvalues at rounding level are dropped.
    """
    d = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    live = d > 0
    D = np.where(live, 1.0 / np.where(live, d, 1.0), 0.0)
    lam, V = np.linalg.eigh(D[:, None] * cov * D[None, :])
    keep = lam > len(lam) * np.finfo(float).eps * lam.max(initial=0.0)
    root = d[:, None] * V[:, keep] * np.sqrt(lam[keep])
    return np.ascontiguousarray(root.T)


def check_interval(interval) -> None:
    """Reject an unknown ``interval`` argument with the choices."""
    if interval not in _INTERVALS:
        raise ValueError(
            f"interval must be 'prediction' (a new measurement: weights and "
            f"noise) or 'confidence' (the model output: weights only); got "
            f"{interval!r}."
        )


def output_std(est, Yhat, J, data, as_list, y_1d, interval, one_step=False):
    """Standard deviation of every modelled sample, shaped like the output.

    ``J`` holds ``d yhat / d w`` of the modelled rows (standardised units),
    as returned with ``Yhat`` by ``est._run``. Rows after a divergence are
    NaN. ``one_step`` chooses the one-step residual variance as the noise
    of a prediction interval.
    """
    check_interval(interval)
    p = est.n_outputs_
    rows = data.modelled
    var = np.empty(len(J))
    row_variances(J, est._cov_root, var)
    var = var.reshape(len(rows), p) * est._y_scale**2
    if interval == "prediction":
        noise = est.one_step_noise_variance_ if one_step else est.noise_variance_
        var = var + noise
    std = np.sqrt(var)
    std[np.isnan(Yhat[rows]).any(axis=1)] = np.nan
    out, k = [], 0
    for a, b in pairwise(data.starts):
        n = b - a - data.h
        block = std[k : k + n]
        out.append(block[:, 0] if y_1d else block)
        k += n
    return out if as_list else out[0]
