"""Delta-method uncertainty of the recurrent networks' outputs.

At the end of ``fit`` the covariance of the fitted weights is estimated from
the exact recurrent Jacobian of the final training objective (the free run
for the simulation focus, the one-step predictor for the prediction focus):

.. math:: C = c \\, A^{+} S A^{+}, \\qquad A = J^T J + \alpha M,

with ``M`` the mask of penalised weights, ``S`` the long-run covariance of
the gradient terms ``r_t J_t`` (Bartlett kernel, bandwidth from the
residuals' autocorrelation: residuals of a free run are rarely white) and
``c`` a degrees-of-freedom correction. For white residuals of variance
``s^2`` this is the textbook ``s^2 (J^T J)^{-1}``. ``predict`` and
``simulate`` propagate ``C`` to every sample through the forward
sensitivities of the run they make, ``var(yhat(t)) = J(t) C J(t)^T``, and add
the residual variance for a prediction interval. Everything here works in the
estimators' standardised units and converts to the user's units on the way
out.
"""

from __future__ import annotations

import dataclasses
import warnings
from dataclasses import dataclass
from itertools import pairwise

import numpy as np

from sysid_nn._exceptions import user_stacklevel
from sysid_nn._kernels._propagation import row_variances

#: Eigenvalues of the normal matrix (scaled to a unit diagonal) below this
#: share of the largest are treated as zero (pseudo-inverse): directions the
#: training data do not determine get no variance instead of an arbitrary
#: huge one. ``J^T J`` squares the condition number of ``J``, so this drops
#: directions whose singular value is below 1e-5 of the largest.
_RCOND = 1e-10

_INTERVALS = ("prediction", "confidence")
#: A sensitivity ``|d yhat / d w|`` (standardised units) above this along the
#: training records means that a change of a weight by 1e-9 moves the output
#: by its standard deviation: the linearisation behind the bands fails. An
#: ISSM fitted to three oscillator records in the tests reaches 8e6; one at
#: the edge of stability reached 1e13 (and a band of 1e-14).
_SENSITIVITY_LIMIT = 1e9


#: Largest ``n_rows * n_outputs * n_weights`` for which the covariance forms
#: the training run's full Jacobian (8 bytes each, about 3 copies at once):
#: beyond it ``J^T J`` is accumulated, as the solver does, so that a fit's
#: memory stays bounded on records of a million samples.
_FULL_JACOBIAN_LIMIT = 2**24


@dataclass
class _Normal:
    """What the covariance needs from the Jacobian of a training run."""

    #: ``J^T J``.
    JtJ: np.ndarray
    #: Long-run covariance of the gradient terms ``r_t J_t`` (Bartlett).
    meat: np.ndarray
    #: Residual sum of squares per output.
    rss: np.ndarray
    #: Number of modelled rows (time steps).
    n_rows: int
    #: Largest ``|d yhat / d w|``.
    max_sensitivity: float
    #: Bartlett bandwidth used for ``meat``, in samples.
    bandwidth: int


def _normal_matrix(est, w, data, seg) -> _Normal | None:
    """``J^T J`` of a run and the long-run covariance of its gradient terms.

    The one place where the full Jacobian of the training data is formed;
    past :data:`_FULL_JACOBIAN_LIMIT` :func:`_accumulated_normal` serves
    instead. Returns ``None`` if the run diverges.
    """
    rows = data.modelled
    if len(rows) * est.n_outputs_ * len(w) > _FULL_JACOBIAN_LIMIT:
        return _accumulated_normal(est, w, data, seg)
    Yhat, J, diverged, _ = est._run(w, data, seg, True, keep_state=False)
    if (diverged >= 0).any():
        return None
    R = Yhat[rows] - data.Y[rows]
    p, n_w = R.shape[1], J.shape[1]
    # Gradient term of each time step, summed over the outputs.
    G = (R.reshape(-1, 1) * J).reshape(len(rows), p, n_w).sum(axis=1)
    lengths = np.diff(data.starts) - data.h
    bounds = np.concatenate([[0], np.cumsum(lengths)])
    L = _bandwidth(R, bounds)
    meat = np.zeros((n_w, n_w))
    for a, b in pairwise(bounds):
        meat += _bartlett(G[a:b], L)
    return _Normal(
        JtJ=J.T @ J,
        meat=meat,
        rss=(R * R).sum(axis=0),
        n_rows=len(rows),
        max_sensitivity=float(np.abs(J).max(initial=0.0)),
        bandwidth=L,
    )


def _accumulated_normal(est, w, data, seg) -> _Normal | None:
    """:class:`_Normal` of a run too long for its full Jacobian.

    ``J^T J`` is accumulated by the kernels while the recurrence runs, as
    Levenberg-Marquardt does, so memory does not grow with ``N x P``. The
    long-run covariance of the gradient terms needs the Jacobian's rows, so
    it is taken as that of white residuals, ``s^2 J^T J``, and the caller is
    warned that the band then ignores their autocorrelation.
    """
    Yhat, (JtJ, _), diverged, _ = est._run(w, data, seg, "normal", keep_state=False)
    if (diverged >= 0).any():
        return None
    rows = data.modelled
    R = Yhat[rows] - data.Y[rows]
    rss = (R * R).sum(axis=0)
    warnings.warn(
        f"The training records of this {type(est).__name__} hold {len(rows)} "
        f"samples: more than the full Jacobian of the bands' autocorrelation-"
        "robust covariance fits in memory. Its covariance assumes white "
        "residuals, so the bands of return_std=True may be too narrow where the "
        "residuals are autocorrelated (a free run's usually are); check them "
        "with sysid_nn.uncertainty.ensemble_std.",
        UserWarning,
        stacklevel=user_stacklevel(),
    )
    return _Normal(
        JtJ=JtJ,
        meat=float(rss.sum()) / R.size * JtJ,
        rss=rss,
        n_rows=len(rows),
        max_sensitivity=np.nan,
        bandwidth=0,
    )


def _restricted(normal: _Normal, idx) -> _Normal:
    """``normal`` of the weights ``idx`` alone, the others held fixed.

    Every field is a sum of products of Jacobian columns, so the block of the
    full run is exactly what a run restricted to those columns gives.
    """
    block = np.ix_(idx, idx)
    return dataclasses.replace(normal, JtJ=normal.JtJ[block], meat=normal.meat[block])


def _bandwidth(R, bounds) -> int:
    """Bartlett bandwidth from the residuals' lag-one autocorrelation.

    Andrews' (1991) AR(1) plug-in rule, ``1.1447 (a n)^(1/3)`` with ``a =
    4 rho^2 / ((1 - rho)^2 (1 + rho)^2)`` and ``n`` the mean record length,
    capped at half the shortest record: about one sample for white
    residuals, hundreds for the slow drift of a free-run error.
    """
    num = den = 0.0
    for a, b in pairwise(bounds):
        r = R[a:b]
        num += float(np.sum(r[1:] * r[:-1]))
        den += float(np.sum(r * r))
    rho = min(max(num / den, 0.0), 0.999) if den > 0 else 0.0
    n = (bounds[-1] - bounds[0]) / max(len(bounds) - 1, 1)
    alpha = 4 * rho**2 / ((1 - rho) ** 2 * (1 + rho) ** 2)
    shortest = int(np.min(np.diff(bounds)))
    return int(min(1.1447 * (alpha * n) ** (1.0 / 3.0), max(shortest // 2, 0)))


def _bartlett(G, L) -> np.ndarray:
    """Long-run covariance ``sum_l (1 - |l| / (L + 1)) sum_t G_t^T G_{t+l}``.

    As the mean outer product of sums over windows of ``L + 1`` consecutive
    rows (the Bartlett kernel's form), scaled to the record's length.
    """
    n = len(G)
    if n == 0:
        return np.zeros((G.shape[1], G.shape[1]))
    width = min(L + 1, n)
    cs = np.vstack([np.zeros((1, G.shape[1])), np.cumsum(G, axis=0)])
    B = cs[width:] - cs[:-width]
    return (B.T @ B) * (n / (len(B) * width))


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


def _delta_covariance(normal: _Normal, penalty, p: int):
    """``(cov, n_eff)``: sandwich covariance and effective number of weights.

    ``cov = c A^+ S A^+`` with ``A = J^T J + alpha M``, ``S`` the long-run
    covariance of the gradient terms and ``c`` the small-sample correction
    ``N p / (N p - n_eff)``. For white residuals of constant variance
    ``s^2``, ``S = s^2 J^T J`` and ``cov = s^2 A^+`` (for ``alpha = 0``).
    """
    inv = _pseudo_inverse(normal.JtJ + np.diag(penalty))
    n_eff = float(np.sum(inv * normal.JtJ))  # trace(inv @ JtJ), both symmetric
    n_res = normal.n_rows * p
    cov = inv @ normal.meat @ inv * (n_res / max(n_res - n_eff, 1.0))
    return cov, n_eff


def _residual_variance(normal: _Normal, n_eff, p):
    """Residual variance per output, corrected for ``n_eff`` fitted weights."""
    return normal.rss / max(normal.n_rows - n_eff / p, 1.0)


def fit_covariance(est, train) -> None:
    """Store ``coefs_covariance_`` and the noise variances on a fitted ``est``.

    * The covariance is the sandwich of :func:`_delta_covariance` for the
      final training objective, pooled over outputs in standardised units.
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
    est.bands_unavailable_ = None
    mask = est._penalty_mask().astype(np.float64)
    alpha = float(est.alpha_)
    free = _normal_matrix(est, w, train, est._final_segment())
    one = _normal_matrix(est, w, train, 1)
    nan = np.full(p, np.nan)
    if free is None or (getattr(est, "init", None) == "tdl" and one is None):
        which = "free run" if free is None else "one-step prediction"
        est.bands_unavailable_ = (
            f"the final {which} of the fitted model diverged on the training "
            "records, so its Jacobian there is undefined"
        )
        warnings.warn(
            f"No confidence or prediction bands for this {type(est).__name__}: "
            f"{est.bands_unavailable_}; return_std gives NaN. A model whose "
            "free run leaves the training range on its own records is not "
            "trustworthy; see the DivergenceWarning of its simulations.",
            UserWarning,
            stacklevel=user_stacklevel(),
        )
        est.coefs_covariance_ = np.full((n_w, n_w), np.nan)
        est.n_effective_params_ = np.nan
        est.noise_variance_ = nan
        est.one_step_noise_variance_ = nan
        est._noise_units = (nan, nan)
        est._cov_root = np.full((1, n_w), np.nan)
        return
    if getattr(est, "init", None) == "tdl":
        tdl = est.tdl_
        G = est._realisation_map()  # the structure's (affine) map
        # The TDL's covariance already holds its own residual variance.
        cov = G @ tdl.coefs_covariance_ @ G.T
        n_eff = float(tdl.n_effective_params_)
    else:
        cov, n_eff = _delta_covariance(free, alpha * mask, p)
    if free.max_sensitivity > _SENSITIVITY_LIMIT:
        warnings.warn(
            f"The outputs of this {type(est).__name__} are extremely sensitive to "
            f"its weights along the training records (|d yhat / d w| up to "
            f"{free.max_sensitivity:.1e} in standardised units): its recurrence "
            "is at the edge of stability there, and the bands of return_std=True, "
            "which linearise the outputs in the weights, are unreliable. Check "
            "them with sysid_nn.uncertainty.ensemble_std.",
            UserWarning,
            stacklevel=user_stacklevel(),
        )
    innovations = getattr(est, "_innovation_index", None)
    if innovations is not None and est._final_segment() != 1 and one is not None:
        idx = innovations()
        cov_k, n_k = _delta_covariance(_restricted(one, idx), alpha * mask[idx], p)
        cov[idx, :] = 0.0
        cov[:, idx] = 0.0
        cov[np.ix_(idx, idx)] = cov_k
        n_eff += n_k
    cov = 0.5 * (cov + cov.T)
    est.coefs_covariance_ = cov
    est.n_effective_params_ = n_eff
    # Kept in standardised units too: squared user units may overflow.
    est._noise_units = (
        _residual_variance(free, n_eff, p),
        _residual_variance(one, n_eff, p) if one is not None else nan,
    )
    with np.errstate(over="ignore"):
        scale2 = est._y_scale**2
        est.noise_variance_ = est._noise_units[0] * scale2
        est.one_step_noise_variance_ = est._noise_units[1] * scale2
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
    var = var.reshape(len(rows), p)
    if interval == "prediction":
        var = var + est._noise_units[1 if one_step else 0]
    std = np.sqrt(var) * est._y_scale
    std[np.isnan(Yhat[rows]).any(axis=1)] = np.nan
    out, k = [], 0
    for a, b in pairwise(data.starts):
        n = b - a - data.h
        block = std[k : k + n]
        out.append(block[:, 0] if y_1d else block)
        k += n
    return out if as_list else out[0]
