"""Modal parameters of an identified model, from its linearisation at rest.

Both networks are linearised at the fixed point of their free run under zero
excitation (the rest their simulations start from):

* the TDL network ``yhat(t) = G(yhat(t-1), ..., yhat(t-n_a), F(...))`` as the
  block companion matrix of ``d G / d yhat(t-i)``;
* the ISSM ``x(t) = G(x(t-1), F(t-n_k), 0)`` as its state map ``d G / d x``.

A discrete pole ``z`` gives ``s = log(z) / dt``, the natural frequency
``|s| / (2 pi)`` and the damping ratio ``-Re(s) / |s|``. Their 95 % intervals
are propagated from the weights' covariance (``coefs_covariance_``, the one
behind ``return_std``) by the delta method: the derivative of every pole with
respect to every weight is the first-order eigenvalue perturbation
``u^H (dA / dw) v / (u^H v)``, with ``dA / dw`` by central differences of the
linearisation (rest included) in the weights.
"""

from __future__ import annotations

import numbers

import numpy as np
import pandas as pd
from scipy.stats import norm
from sklearn.utils.validation import check_is_fitted

from sysid_nn._docstrings import fill_doc
from sysid_nn._exceptions import not_a_network
from sysid_nn._kernels._mlp import LOGISTIC
from sysid_nn._records._data import _FREE_RUN

__all__ = ["instantaneous_frequency", "modal_parameters"]

#: A pole whose damped frequency is above this share of the Nyquist
#: frequency is marked ``"nyquist"``: the sampling does not resolve it.
_NYQUIST_SHARE = 0.8
#: A mode whose share of the impulse response (see :func:`_mode_weights`)
#: is below this fraction of the largest mode's is marked ``"unobservable"``.
_UNSEEN = 1e-3
#: A pole with an imaginary part below this (relative to its modulus) is real.
_REAL_TOL = 1e-9
#: Relative step of the central differences in the weights.
_STEP = 1e-6

# The parameters every readout of the linearisation at rest takes.
_document_readout = fill_doc(
    estimator_dt="estimator : TDLRegressor or ISSMRegressor\n    A fitted model.\n"
    "dt : float\n    Sampling interval of the training records in seconds; the "
    "fitted\n    model does not know it."
)


def _check_dt(dt) -> float:
    """``dt`` as a positive finite float, or an error naming it."""
    if (
        isinstance(dt, bool)
        or not isinstance(dt, numbers.Real)
        or not np.isfinite(dt)
        or dt <= 0
    ):
        raise ValueError(
            f"dt must be the sampling interval of the training records in "
            f"seconds, a positive finite number (e.g. dt=0.01 for 100 Hz); got "
            f"{dt!r}. The fitted model does not know its sampling interval."
        )
    return float(dt)


def check_fitted_network(estimator) -> None:
    """Raise unless ``estimator`` is a fitted network (a ``TDLRegressor``,
    an ``ISSMRegressor`` or a subclass): what the readouts take. An
    ensemble's error names the network to pass instead."""
    if not hasattr(estimator, "_layout"):
        raise not_a_network(estimator)
    check_is_fitted(estimator, "coefs_")


def _check_arguments(estimator, dt, level) -> float:
    """Check a readout's ``estimator``, ``dt`` and ``level``; return ``dt``."""
    dt = _check_dt(dt)
    if (
        isinstance(level, bool)
        or not isinstance(level, numbers.Real)
        or not 0.0 < level < 1.0
    ):
        raise ValueError(
            f"level must be a probability strictly between 0 and 1 (e.g. 0.95); "
            f"got {level!r}."
        )
    check_fitted_network(estimator)
    return dt


# ------------------------------------------------------------- the network
def _forward(w, layout, act: int, z: np.ndarray):
    """Output and input Jacobian ``d out / d z`` of the network at ``z``."""
    mats = layout.matrices(w)
    a, jac = z, np.eye(len(z))
    for W, b in mats[:-1]:
        a = W @ a + b
        if act == LOGISTIC:
            a = 1.0 / (1.0 + np.exp(-a))
            slope = a * (1.0 - a)
        else:
            a = np.tanh(a)
            slope = 1.0 - a * a
        jac = slope[:, None] * (W @ jac)
    W, b = mats[-1]
    out, jac = W @ a + b, W @ jac
    L = layout.bypass_matrix(w)
    if L is not None:
        out, jac = out + L @ z, jac + L
    return out, jac


class _Linearisation:
    """The state map of a fitted network at rest, for any weights ``w``.

    ``state_matrix(w)`` returns ``(A, rest)``; ``C`` picks the outputs from
    the state; ``input_response(w, lam)`` the input's way into the state
    (see :func:`_mode_weights`). Everything in standardised units.
    """

    def __init__(self, est) -> None:
        self.est = est
        self.layout = est._layout()
        self.act = int(est._act)
        self.p = est.n_outputs_
        self.m = est.n_features_in_
        self.u0 = -est._x_mean / est._x_scale  # zero excitation, standardised
        self.tdl = hasattr(est, "output_lags_")
        if self.tdl:
            self.na, self.nb, self.nk = (
                est.output_lags_,
                est.input_lags_,
                est.input_delay,
            )
            self.S = est._S
            self.n = self.na * self.p
            self.n_rest = self.p
        else:
            self.nk = est.input_delay
            self.n = self.n_rest = est.n_states_
        self.C = np.eye(self.p, self.n)

    def _map(self, w, r):
        """``(G(r) - r, d G / d r, d G / d z)`` at the rest candidate ``r``."""
        if self.tdl:
            phi = np.r_[np.tile(r, self.na), np.tile(self.u0, self.nb)]
            out, jz = _forward(w, self.layout, self.act, self.S @ phi)
            jphi = jz @ self.S
            jr = jphi[:, : self.n].reshape(self.p, self.na, self.p).sum(axis=1)
            return out - r, jr, jphi
        z = np.r_[r, self.u0, np.zeros(self.p)]
        out, jz = _forward(w, self.layout, self.act, z)
        return out - r, jz[:, : self.n], jz

    def rest(self, w, r0) -> np.ndarray:
        """The fixed point of the free run under zero excitation, by Newton."""
        r = np.array(r0, dtype=np.float64)
        for _ in range(100):
            g, jr, _ = self._map(w, r)
            step = np.linalg.lstsq(jr - np.eye(len(r)), -g, rcond=None)[0]
            r = r + step
            if np.max(np.abs(step)) <= 1e-13 * max(1.0, np.max(np.abs(r))):
                break
        return r

    def state_matrix(self, w, r0):
        """``(A, jphi, rest)``: the state map at the rest of ``w``."""
        r = self.rest(w, r0)
        _, _, j = self._map(w, r)
        if self.tdl:
            A = np.eye(self.n, k=-self.p)
            A[: self.p] = j[:, : self.n]
            return A, j, r
        return j[:, : self.n].copy(), j, r

    def residue_factor(self, j, lam) -> np.ndarray:
        """``Q(lam)``: the input's way into the state at pole ``lam``.

        The transfer function is ``sum_i lam_i C v_i u_i^H Q(lam_i) / (z -
        lam_i)`` plus a polynomial: the TDL's excitation lags enter its first
        block as ``sum_j b_j lam^(-n_k - j)``, the ISSM's as ``B lam^-n_k``.
        """
        if self.tdl:
            B = j[:, self.n :].reshape(self.p, self.nb, self.m)
            powers = lam ** -(self.nk + np.arange(self.nb, dtype=np.float64))
            Q = np.zeros((self.n, self.m), dtype=complex)
            Q[: self.p] = np.einsum("pjm,j->pm", B, powers)
            return Q
        return j[:, self.n : self.n + self.m] * lam ** (-float(self.nk))


def _start_guess(est, lin: _Linearisation) -> np.ndarray:
    """Where Newton starts: the rest of the fitted model, or zero output."""
    rest = getattr(est, "rest_output_", None)
    y = (
        np.zeros(lin.p)
        if rest is None
        else (np.asarray(rest) - est._y_mean) / est._y_scale
    )
    return y if lin.tdl else np.r_[y, np.zeros(lin.n - lin.p)]


def _weight_derivatives(lin: _Linearisation, w, cov, rest, value) -> np.ndarray:
    """``d value(A, jphi) / d w`` at rest, by central differences in the weights.

    ``value`` maps the state matrix and the network's Jacobian of the
    linearisation (the rest found again for each perturbed ``w``, Newton
    starting from ``rest``) to an array; the result has one more, last axis,
    one column per weight, zero for weights without variance in ``cov``.
    """
    out = None
    for k in np.flatnonzero(np.diag(cov) > 0):
        h = _STEP * max(1.0, abs(w[k]))
        wp, wm = w.copy(), w.copy()
        wp[k] += h
        wm[k] -= h
        diff = (
            value(*lin.state_matrix(wp, rest)[:2])
            - value(*lin.state_matrix(wm, rest)[:2])
        ) / (2 * h)
        if out is None:
            out = np.zeros((*np.shape(diff), len(w)), dtype=np.result_type(diff))
        out[..., k] = diff
    if out is None:
        base = np.asarray(value(*lin.state_matrix(w, rest)[:2]))
        out = np.zeros((*base.shape, len(w)), dtype=base.dtype)
    return out


# ------------------------------------------------------------------- poles
def _to_continuous(lam, dt):
    """``(frequency_hz, damping_ratio, s)`` of discrete poles ``lam``."""
    s = np.log(lam.astype(complex)) / dt
    mag = np.abs(s)
    with np.errstate(invalid="ignore", divide="ignore"):
        return mag / (2 * np.pi), -s.real / mag, s


def _gradients(dlam, lam, s, dt):
    """Rows of ``d f / d w`` and ``d zeta / d w`` from ``d lam / d w``."""
    ds = dlam / (lam[:, None] * dt)
    mag = np.abs(s)[:, None]
    dmag = (np.conj(s)[:, None] * ds).real / mag
    df = dmag / (2 * np.pi)
    dzeta = -(ds.real * mag - s.real[:, None] * dmag) / mag**2
    return df, dzeta


def _mode_weights(lin, j, lam, V, Winv) -> np.ndarray:
    """Each pole's share of the impulse response from the inputs.

    ``|lam| ||C v|| ||u^H Q(lam)|| / sqrt(1 - |lam|^2)``: the root energy of
    the mode's term in the impulse response (its residue decaying as
    ``lam^t``); infinite for a pole on or outside the unit circle.
    """
    out = np.empty(len(lam))
    for i, li in enumerate(lam):
        seen = np.linalg.norm(lin.C @ V[:, i])
        driven = np.linalg.norm(Winv[i] @ lin.residue_factor(j, li))
        decay = 1.0 - abs(li) ** 2
        out[i] = abs(li) * seen * driven / np.sqrt(decay) if decay > 0 else np.inf
    return out


def _shape(v: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """A mode shape in output units, largest component +1, made real."""
    phi = v * scale
    k = int(np.argmax(np.abs(phi)))
    if abs(phi[k]) == 0:
        return np.zeros(len(phi))
    return (phi / phi[k]).real


@_document_readout
def modal_parameters(estimator, dt, *, level: float = 0.95) -> pd.DataFrame:
    """Natural frequencies, damping ratios and mode shapes of a fitted model.

    The model is linearised at its rest (the fixed point of its free run
    under zero excitation): the TDL network's lag recursion as a block
    companion matrix, the ISSM's state map. Each discrete pole ``z`` of the
    linearisation gives ``s = log(z) / dt``, the natural frequency
    ``|s| / (2 pi)`` in Hz and the damping ratio ``-Re(s) / |s|``; a complex
    pair is one mode. For the linear model (``hidden_layer_sizes=()``) these
    are its exact modes. The intervals propagate the weights' covariance
    ``coefs_covariance_`` (the one behind ``return_std=True``; see
    :ref:`uncertainty`) by the delta method, with the derivatives of the
    poles in the weights from first-order eigenvalue perturbation of the
    state matrix, whose derivatives are central differences in the weights
    (relative step 1e-6, the rest found again for each).

    The intervals assume what ``return_std`` assumes, in particular weights
    at the minimum of the training loss. Early stopping (the default) stops
    short of it: on linear models of a three-storey building (one record,
    2 % output noise) the spread of the frequencies and damping ratios over
    repeated records was 1.5-4 times the one the intervals claim, and
    0.5-1.3 times with ``early_stopping=False``. Fit a linear model you read
    the modes of without early stopping; a network may need its early
    stopping (see the user guide's page on the structure).

    Parameters
    ----------
    %(estimator_dt)s
    level : float, default=0.95
        Probability of the two-sided Gaussian intervals.

    Returns
    -------
    modes : pandas.DataFrame
        One row per mode (a complex pair, or a real pole), sorted by
        frequency, with columns ``frequency_hz``, ``frequency_hz_low``,
        ``frequency_hz_high``, ``damping_ratio``, ``damping_ratio_low``,
        ``damping_ratio_high``; ``kind``: ``"structural"``, or the reason a
        mode is numerical: ``"real"`` (a real pole, no oscillation),
        ``"nyquist"`` (damped frequency above 80 % of the Nyquist frequency)
        or ``"unobservable"`` (its share of the impulse response from the
        inputs to the outputs is below 1e-3 of the largest mode's);
        ``structural`` (bool); ``participation``, that share relative to the
        largest mode; ``pole`` (the discrete pole, upper half plane); with
        several outputs, ``shape_<k>`` for output ``k``: the mode shape at
        the measured outputs in their units, largest component 1 (the real
        part after that normalisation). ``attrs`` holds ``dt`` and
        ``level``.

    See Also
    --------
    sysid_nn.backbone : Frequency and damping against response amplitude.
    instantaneous_frequency : The first mode along a record.
    sysid_nn.ShearBuilding.modal_properties : The generator's true modes.

    Examples
    --------
    A linear ARX model whose poles are known, ``z = 0.9 exp(+-0.3i)``:

    >>> import numpy as np
    >>> from scipy.signal import lfilter
    >>> from sysid_nn import TDLRegressor, modal_parameters
    >>> rng = np.random.default_rng(0)
    >>> u = rng.standard_normal((500, 1))
    >>> a1, a2 = 2 * 0.9 * np.cos(0.3), -0.81
    >>> y = lfilter([0.0, 1.0], [1.0, -a1, -a2], u[:, 0])
    >>> model = TDLRegressor(output_lags=2, input_lags=1, hidden_layer_sizes=(),
    ...                      n_init=1, random_state=0).fit(u, y)
    >>> modes = modal_parameters(model, dt=0.01)
    >>> s = np.log(0.9 * np.exp(0.3j)) / 0.01
    >>> bool(np.isclose(modes.frequency_hz[0], abs(s) / (2 * np.pi)))
    True
    >>> float(modes.damping_ratio[0].round(4)), modes.kind[0]
    (0.3313, 'structural')
    """
    dt = _check_arguments(estimator, dt, level)
    lin = _Linearisation(estimator)
    w = np.asarray(estimator.coefs_, dtype=np.float64)
    A, j, rest = lin.state_matrix(w, _start_guess(estimator, lin))
    lam, V = np.linalg.eig(A)
    Winv = np.linalg.inv(V)
    keep = lam.imag >= -_REAL_TOL * np.maximum(np.abs(lam), 1e-300)
    keep &= np.abs(lam) > 0  # a pole at zero is a pure delay
    lam_k, V_k, W_k = lam[keep], V[:, keep], Winv[keep]
    freq, zeta, s = _to_continuous(lam_k, dt)
    # First-order eigenvalue perturbation, linear in dA: u^H dA v.
    cov = np.asarray(estimator.coefs_covariance_)
    dlam = _weight_derivatives(
        lin, w, cov, rest, lambda A, j: np.einsum("ij,jk,ki->i", W_k, A, V_k)
    )
    df, dzeta = _gradients(dlam, lam_k, s, dt)
    z = norm.ppf(0.5 + 0.5 * level)
    with np.errstate(invalid="ignore"):
        sd_f = np.sqrt(np.einsum("ij,jk,ik->i", df, cov, df))
        sd_z = np.sqrt(np.einsum("ij,jk,ik->i", dzeta, cov, dzeta))
    weights = _mode_weights(lin, j, lam_k, V_k, W_k)
    top = np.max(weights[np.isfinite(weights)], initial=0.0)
    share = weights / top if top > 0 else np.ones(len(weights))
    real = np.abs(lam_k.imag) <= _REAL_TOL * np.abs(lam_k)
    nyquist = np.abs(np.angle(lam_k)) > _NYQUIST_SHARE * np.pi
    kind = np.where(
        real,
        "real",
        np.where(
            nyquist, "nyquist", np.where(share < _UNSEEN, "unobservable", "structural")
        ),
    )
    table = pd.DataFrame(
        {
            "frequency_hz": freq,
            "frequency_hz_low": freq - z * sd_f,
            "frequency_hz_high": freq + z * sd_f,
            "damping_ratio": zeta,
            "damping_ratio_low": zeta - z * sd_z,
            "damping_ratio_high": zeta + z * sd_z,
            "kind": kind,
            "structural": kind == "structural",
            "participation": share,
            "pole": lam_k,
        }
    )
    if lin.p > 1:
        shapes = np.array(
            [_shape(lin.C @ V_k[:, i], estimator._y_scale) for i in range(len(lam_k))]
        )
        for k in range(lin.p):
            table[f"shape_{k}"] = shapes[:, k]
    table = table.sort_values("frequency_hz", kind="stable").reset_index(drop=True)
    table.index.name = "mode"
    table.attrs.update(dt=dt, level=float(level))
    return table


def _local_state_matrices(est, lin: _Linearisation, X: np.ndarray):
    """The state matrix along the free run over ``X`` from rest, per sample.

    The TDL's network inputs of its own run (``Z``) give the companion
    matrix at every sample; the ISSM's kernels return ``d x(t) / d z`` of
    the run (``D``). Rows after a divergence are NaN.
    """
    Xs, leads, initial, past = est._from_rest([X], True)
    data = est._stack(Xs, None, initial, past)
    w = est.coefs_
    rows = data.modelled[int(leads[0]) :]
    out = np.full((len(rows), lin.n, lin.n), np.nan)
    if lin.tdl:
        _, _, diverged, (_, Z, _) = est._run(w, data, _FREE_RUN, False)
        for i, r in enumerate(rows):
            _, jz = _forward(w, lin.layout, lin.act, Z[r])
            A = np.eye(lin.n, k=-lin.p)
            A[: lin.p] = (jz @ lin.S)[:, : lin.n]
            out[i] = A
    else:
        X0 = est._initial_states(data, initial)
        _, _, diverged, (_, _, _, D) = est._run_from(
            w, data, _FREE_RUN, False, X0, want_lin=True, keep_state=True
        )
        out[:] = D[rows][:, :, : lin.n]
    bad = int(diverged[0]) - int(leads[0])
    if diverged[0] >= 0:
        out[max(bad, 0) :] = np.nan
    return out


def instantaneous_frequency(estimator, X, dt) -> pd.DataFrame:
    """The first mode's frequency and damping along a record, by local linearisation.

    The model is simulated over the excitation ``X`` from rest (as
    ``simulate`` does), and at every sample linearised where its run is
    (the TDL network at its current lags, the ISSM at its current state,
    excitation as it is): the mode followed is the first structural mode of
    the linearisation at rest (:func:`modal_parameters`), tracked from
    sample to sample as the complex pole nearest in frequency to the one
    before. A yielding structure's identified model shows its first mode
    softening during the strong shaking and recovering after it.

    Parameters
    ----------
    estimator : TDLRegressor or ISSMRegressor
        A fitted model.
    X : array-like of shape (n_samples, n_inputs)
        Excitation of one record.
    dt : float
        Sampling interval of the training records in seconds.

    Returns
    -------
    track : pandas.DataFrame
        One row per sample: ``t`` (seconds from the record's start),
        ``frequency_hz`` and ``damping_ratio`` of the local linearisation's
        mode (NaN where the run diverged or no complex pole is left).

    See Also
    --------
    modal_parameters : The modes of the linearisation at rest.
    sysid_nn.plotting.plot_instantaneous_frequency : Draws the track.

    Examples
    --------
    A linear model's local linearisation is the same everywhere:

    >>> import numpy as np
    >>> from scipy.signal import lfilter
    >>> from sysid_nn import TDLRegressor, instantaneous_frequency
    >>> rng = np.random.default_rng(0)
    >>> u = rng.standard_normal((500, 1))
    >>> y = lfilter([0.0, 1.0], [1.0, -2 * 0.9 * np.cos(0.3), 0.81], u[:, 0])
    >>> model = TDLRegressor(output_lags=2, input_lags=1, hidden_layer_sizes=(),
    ...                      n_init=1, random_state=0).fit(u, y)
    >>> track = instantaneous_frequency(model, u, dt=0.01)
    >>> bool(np.allclose(track.frequency_hz, modal_parameters(model, 0.01)
    ...                  .frequency_hz[0]))
    True
    """
    dt = _check_dt(dt)
    check_fitted_network(estimator)
    X = np.asarray(X, dtype=np.float64)
    if X.ndim == 1:
        X = X[:, None]
    if X.ndim != 2 or X.shape[1] != estimator.n_features_in_ or not len(X):
        raise ValueError(
            f"X must be one record of shape (n_samples, {estimator.n_features_in_}) "
            f"(the model's inputs); got shape {X.shape}."
        )
    rest = modal_parameters(estimator, dt)
    rest = rest[rest.structural]
    if not len(rest):
        raise ValueError(
            "The model's linearisation at rest has no structural mode to follow "
            "(see sysid_nn.modal_parameters with its numerical modes)."
        )
    lin = _Linearisation(estimator)
    mats = _local_state_matrices(estimator, lin, X)
    freq = np.full(len(mats), np.nan)
    zeta = np.full(len(mats), np.nan)
    last = float(rest.frequency_hz.iloc[0])
    for i, A in enumerate(mats):
        if not np.all(np.isfinite(A)):
            continue
        lam = np.linalg.eigvals(A)
        lam = lam[(lam.imag > _REAL_TOL * np.abs(lam)) & (np.abs(lam) > 0)]
        lam = lam[np.abs(np.angle(lam)) <= _NYQUIST_SHARE * np.pi]
        if not len(lam):
            continue
        f, z, _ = _to_continuous(lam, dt)
        k = int(np.argmin(np.abs(f - last)))
        freq[i], zeta[i], last = f[k], z[k], f[k]
    return pd.DataFrame(
        {"t": dt * np.arange(len(mats)), "frequency_hz": freq, "damping_ratio": zeta}
    )
