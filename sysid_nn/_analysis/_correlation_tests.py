"""The residual correlation tests behind :mod:`sysid_nn.residuals`.

Whiteness, input cross-correlation and the higher-order (non-linear)
correlation tests on residual series, one sequence or a list pooled without
crossing sequence boundaries; the conventions are those stated in
:mod:`sysid_nn.residuals`, which exports every public name defined here.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
import scipy.linalg
from scipy import stats
from statsmodels.tsa.stattools import ccovf

from sysid_nn._docstrings import fill_doc
from sysid_nn._records._sequences import as_sequence_list, check_paired


# ----------------------------------------------------------------------------
# Validation
# ----------------------------------------------------------------------------
def _series_list(data: Any, name: str) -> list[np.ndarray]:
    """One finite series per sequence (1-D, or 2-D with one column)."""
    seqs, _ = as_sequence_list(data, name, allow_nan=False)
    if seqs[0].shape[1] != 1:
        raise ValueError(
            f"{name} must be one series, 1-D or with one column; got "
            f"{seqs[0].shape[1]} columns. Test each column separately, e.g. "
            f"{name}[:, 0], or use analyze_residuals for all outputs."
        )
    return [s[:, 0] for s in seqs]


def _input_list(data: Any, residuals: list[np.ndarray]) -> list[np.ndarray]:
    """Finite 2-D input sequences paired with the residual sequences."""
    seqs, _ = as_sequence_list(data, "inputs", allow_nan=False)
    check_paired([r[:, None] for r in residuals], seqs, "residuals", "inputs")
    return seqs


def max_lag_bound(n_samples: int) -> int:
    """Largest ``max_lag`` the residual tests accept on ``n_samples`` samples.

    The tests need the lags and as many samples again, plus a margin of ten:
    ``n_samples >= 2 * max_lag + 10``.
    """
    return (n_samples - 10) // 2


def check_max_lag(max_lag: Any, n_samples: int, name: str = "max_lag") -> None:
    """Refuse a ``max_lag`` that is not an integer or too large for the records."""
    if isinstance(max_lag, bool) or not isinstance(max_lag, (int, np.integer)):
        raise ValueError(f"{name} must be an integer >= 1; got {max_lag!r}.")
    bound = max_lag_bound(n_samples)
    if bound < 1:
        raise ValueError(
            f"the residual tests need at least 12 samples per sequence, but the "
            f"shortest has {n_samples}; test longer records."
        )
    if not 1 <= max_lag <= bound:
        raise ValueError(
            f"{name} must be between 1 and {bound} for sequences of {n_samples} "
            f"samples (the shortest; the tests need 2 * {name} + 10 samples); got "
            f"{max_lag!r}. Use {name}={bound} or less, or longer records."
        )


def _check_settings(max_lag: Any, alpha: Any, residuals: list[np.ndarray]) -> float:
    """Validate ``max_lag`` and ``alpha``; return the band quantile z."""
    check_max_lag(max_lag, min(r.size for r in residuals))
    if not (isinstance(alpha, (float, int)) and 0 < alpha < 1):
        raise ValueError(f"alpha must be a number in (0, 1), e.g. 0.05; got {alpha!r}.")
    return float(stats.norm.ppf(1 - alpha / 2))


class _WholeFrame(pd.DataFrame):
    """A DataFrame that prints whole, whatever pandas' display options.

    Test summaries are short and every column matters (test, statistic,
    dof, p-value, verdict): ``print(summary)`` must not elide rows or
    columns to fit a terminal. Everything else is pandas' DataFrame;
    ``pd.DataFrame(summary)`` gives a plain one.
    """

    @property
    def _constructor(self):
        return _WholeFrame

    def __repr__(self) -> str:
        return self.to_string()

    def _repr_html_(self) -> str:
        return self.to_html()


# ----------------------------------------------------------------------------
# Pooled correlations and the chi-square statistic
# ----------------------------------------------------------------------------
def _xcorr(
    a: list[np.ndarray], b: list[np.ndarray], lags: np.ndarray, names: tuple[str, str]
) -> np.ndarray:
    """Pooled ``corr(a(t), b(t - lag))`` for every lag (any sign).

    Lagged products are summed inside each sequence (statsmodels ``ccovf``,
    biased, per-sequence mean removed) and then over sequences; lags longer
    than a sequence contribute nothing from it.
    """
    num = np.zeros(lags.size)
    ss_a = ss_b = 0.0
    pos, neg = lags >= 0, lags < 0
    for x, z in zip(a, b, strict=True):
        n = x.size
        ss_a += n * np.var(x)
        ss_b += n * np.var(z)
        # ccovf(x, z)[k] = 1/n sum_t x(t + k) z(t): lag +k; swapped: lag -k.
        if pos.any():
            fwd = n * ccovf(x, z, adjusted=False, demean=True, fft=True)
            ok = pos & (lags < n)
            num[ok] += fwd[lags[ok]]
        if neg.any():
            bwd = n * ccovf(z, x, adjusted=False, demean=True, fft=True)
            ok = neg & (-lags < n)
            num[ok] += bwd[-lags[ok]]
    for ss, name in ((ss_a, names[0]), (ss_b, names[1])):
        if ss <= 0:
            raise ValueError(
                f"{name} is constant, so its correlations are undefined; "
                "pass a varying signal (or drop that column)."
            )
    return num / np.sqrt(ss_a * ss_b)


def _chi2_statistic(
    rho: np.ndarray, lags: np.ndarray, regressor: list[np.ndarray], n: int, name: str
) -> float:
    """``N rho^T R^{-1} rho`` for correlations of a white series with ``regressor``.

    If ``w`` is white and independent of ``v``, ``sqrt(N) rho_wv(tau)`` over
    the lag set is asymptotically normal with covariance ``R[i, j] =
    rho_v(tau_i - tau_j)`` (the Toeplitz matrix of the regressor's
    autocorrelations), so the statistic is chi-square with ``len(lags)`` dof
    (Soderstrom & Stoica, sec. 11.4, with covariances divided by their
    variances).
    """
    span = int(lags.max() - lags.min())
    acf_v = _xcorr(regressor, regressor, np.arange(span + 1), (name, name))
    toeplitz = acf_v[np.abs(lags[:, None] - lags[None, :])]
    try:
        solution = scipy.linalg.solve(toeplitz, rho, assume_a="pos")
    except (np.linalg.LinAlgError, scipy.linalg.LinAlgError):
        # A regressor with a line spectrum (e.g. a pure sine) has a singular
        # Toeplitz matrix; the pseudo-inverse tests the identifiable part.
        solution = np.linalg.pinv(toeplitz) @ rho
    return float(n * rho @ solution)


#: The attributes every test result shares, documented once.
_LEVEL_DOC = """\
alpha : float
    Significance level.
n_samples : int
    Number of samples ``N``, pooled over sequences."""


class _ChiSquareVerdict:
    """The decision of a result with ``p_value`` and ``alpha`` fields."""

    @property
    def passed(self) -> bool:
        """True if the chi-square test does not reject (``p_value >= alpha``)."""
        return bool(self.p_value >= self.alpha)


@fill_doc(level=_LEVEL_DOC)
@dataclass(frozen=True, eq=False)
class CorrelationTest(_ChiSquareVerdict):
    """One correlation function with its confidence band and chi-square test.

    Attributes
    ----------
    name : str
        Test name, e.g. ``"phi_u2e"``.
    input : int or None
        Input column the test involves (None for the residual alone).
    lags : ndarray of int
        Lags at which ``values`` is given; all of them enter the test.
    values : ndarray
        Normalised correlations at ``lags``.
    band : float
        Half-width ``z_{1-alpha/2} / sqrt(N)`` of the confidence band.
    statistic : float
        Chi-square statistic ``N rho^T R^{-1} rho``.
    dof : int
        Degrees of freedom, the number of lags.
    p_value : float
        Upper tail probability of the statistic.
    %(level)s

    Examples
    --------
    >>> import numpy as np
    >>> e, u = np.random.default_rng(0).standard_normal((2, 500))
    >>> test = nonlinear_correlation_tests(e, u, max_lag=5).get("phi_u2e")
    >>> test.dof, test.lags.tolist()
    (11, [-5, -4, -3, -2, -1, 0, 1, 2, 3, 4, 5])
    """

    name: str
    input: int | None
    lags: np.ndarray
    values: np.ndarray
    band: float
    statistic: float
    dof: int
    p_value: float
    alpha: float
    n_samples: int

    @property
    def n_outside(self) -> int:
        """Number of lags whose correlation lies outside the band."""
        return int(np.sum(np.abs(self.values) > self.band))

    def to_frame(self) -> pd.DataFrame:
        """Return the correlation function with its band as a tidy frame.

        Returns
        -------
        pandas.DataFrame
            Columns ``test, input, lag, value, lower, upper, outside``.
        """
        return pd.DataFrame(
            {
                "test": self.name,
                "input": self.input,
                "lag": self.lags,
                "value": self.values,
                "lower": -self.band,
                "upper": self.band,
                "outside": np.abs(self.values) > self.band,
            }
        )


def _band_fields(series: list[np.ndarray], z: float, alpha: float) -> dict[str, Any]:
    """``band``, ``alpha`` and ``n_samples`` of a test on the pooled ``series``."""
    n = sum(x.size for x in series)
    return {"band": z / np.sqrt(n), "alpha": float(alpha), "n_samples": n}


def _correlation_test(
    name: str,
    white: list[np.ndarray],
    regressor: list[np.ndarray],
    lags: np.ndarray,
    *,
    z: float,
    alpha: float,
    input_index: int | None,
    names: tuple[str, str],
) -> CorrelationTest:
    """Correlations of ``white(t)`` with ``regressor(t - lag)`` and their test."""
    shared = _band_fields(white, z, alpha)
    rho = _xcorr(white, regressor, lags, names)
    stat = _chi2_statistic(rho, lags, regressor, shared["n_samples"], names[1])
    return CorrelationTest(
        name=name,
        input=input_index,
        lags=lags,
        values=rho,
        statistic=stat,
        dof=int(lags.size),
        p_value=float(stats.chi2.sf(stat, lags.size)),
        **shared,
    )


# ----------------------------------------------------------------------------
# Whiteness
# ----------------------------------------------------------------------------
@fill_doc(level=_LEVEL_DOC)
@dataclass(frozen=True, eq=False)
class WhitenessResult(_ChiSquareVerdict):
    """Autocorrelation of the residuals and the chi-square whiteness test.

    Attributes
    ----------
    lags : ndarray of int
        ``0..max_lag``.
    acf : ndarray
        Residual autocorrelation ``r(tau) / r(0)`` at ``lags`` (``acf[0] = 1``).
    band : float
        Half-width ``z_{1-alpha/2} / sqrt(N)`` of the confidence band.
    statistic : float
        ``N sum_{tau=1..M} r(tau)^2 / r(0)^2`` (Box-Pierce), chi-square with
        ``M`` dof when the residuals are white.
    dof : int
        ``M = max_lag``.
    p_value : float
        Upper tail probability of ``statistic``.
    ljung_box : float
        Ljung-Box statistic ``N (N + 2) sum_tau r(tau)^2 / (N - tau)``
        (pooled: ``N - tau`` replaced by the number of lagged pairs).
    ljung_box_p_value : float
        Its p-value (chi-square, ``M`` dof).
    %(level)s

    Examples
    --------
    >>> import numpy as np
    >>> res = whiteness_test(np.random.default_rng(0).standard_normal(500), 10)
    >>> res.summary[["dof", "passed"]].tolist()
    [10, True]
    """

    lags: np.ndarray
    acf: np.ndarray
    band: float
    statistic: float
    dof: int
    p_value: float
    ljung_box: float
    ljung_box_p_value: float
    alpha: float
    n_samples: int

    @property
    def summary(self) -> pd.Series:
        """Statistic, dof, p-value, decision and Ljung-Box as a Series."""
        return pd.Series(
            {
                "statistic": self.statistic,
                "dof": self.dof,
                "p_value": self.p_value,
                "passed": self.passed,
                "ljung_box": self.ljung_box,
                "ljung_box_p_value": self.ljung_box_p_value,
                "n_samples": self.n_samples,
                "n_outside": int(np.sum(np.abs(self.acf[1:]) > self.band)),
            }
        )

    def to_frame(self) -> pd.DataFrame:
        """Return the autocorrelation by lag with its band.

        Returns
        -------
        pandas.DataFrame
            Indexed by ``lag``; columns ``acf, lower, upper, outside``
            (``outside`` is False at lag 0, which is not tested).
        """
        outside = np.abs(self.acf) > self.band
        outside[self.lags == 0] = False  # r(0) = 1 by definition, not a test lag
        return pd.DataFrame(
            {
                "acf": self.acf,
                "lower": -self.band,
                "upper": self.band,
                "outside": outside,
            },
            index=pd.Index(self.lags, name="lag"),
        )


def whiteness_test(
    residuals: Any, max_lag: int = 25, alpha: float = 0.05
) -> WhitenessResult:
    """Chi-square test that the residuals are white (fig. 4.3).

    The autocorrelation ``r(tau)/r(0)`` for ``tau = 0..M`` is the biased
    estimator of statsmodels (``acf(..., adjusted=False)``). Under whiteness
    each ``r(tau)/r(0)``, ``tau >= 1``, is about ``N(0, 1/N)``, which gives the
    band ``+-z_{1-alpha/2}/sqrt(N)``, and ``x = N sum_{tau=1..M}
    r(tau)^2/r(0)^2`` is chi-square with ``M`` degrees of freedom
    (Soderstrom & Stoica, sec. 11.4; the Box-Pierce statistic of
    statsmodels ``acorr_ljungbox(boxpierce=True)``).

    Parameters
    ----------
    residuals : array-like of shape (n_samples,) or (n_samples, 1), or list
        One residual series, or a list of series (several experiments) that
        are pooled as described in the module notes. NaN is rejected.
    max_lag : int, default=25
        Largest lag ``M``, ``1 <= M < n_samples``.
    alpha : float, default=0.05
        Significance level of the band and the test.

    Returns
    -------
    WhitenessResult
        ``acf``, ``band``, ``statistic``, ``dof``, ``p_value``, ``passed``,
        Ljung-Box alongside; ``to_frame()`` and ``summary``.

    Raises
    ------
    ValueError
        If ``residuals`` contain NaN or more than one column, or ``max_lag``
        or ``alpha`` are out of range.

    Examples
    --------
    >>> import numpy as np
    >>> e = np.random.default_rng(0).standard_normal(1000)
    >>> res = whiteness_test(e, max_lag=20)
    >>> res.dof, res.passed
    (20, True)
    >>> res.to_frame().columns.tolist()
    ['acf', 'lower', 'upper', 'outside']
    """
    e = _series_list(residuals, "residuals")
    z = _check_settings(max_lag, alpha, e)
    lags = np.arange(max_lag + 1)
    acf = _xcorr(e, e, lags, ("residuals", "residuals"))
    shared = _band_fields(e, z, alpha)
    n = shared["n_samples"]
    r2 = acf[1:] ** 2
    box_pierce = float(n * r2.sum())
    # Pairs at lag tau: N - tau for one sequence, summed over sequences.
    pairs = np.array([sum(max(x.size - k, 0) for x in e) for k in lags[1:]])
    ljung_box = float(n * (n + 2) * np.sum(r2 / pairs))
    return WhitenessResult(
        lags=lags,
        acf=acf,
        statistic=box_pierce,
        dof=int(max_lag),
        p_value=float(stats.chi2.sf(box_pierce, max_lag)),
        ljung_box=ljung_box,
        ljung_box_p_value=float(stats.chi2.sf(ljung_box, max_lag)),
        **shared,
    )


# ----------------------------------------------------------------------------
# Cross-correlation with the input
# ----------------------------------------------------------------------------
@fill_doc(level=_LEVEL_DOC)
@dataclass(frozen=True, eq=False)
class CrossCorrelationResult:
    """Residual/input cross-correlation and the two chi-square tests.

    Attributes
    ----------
    lags : ndarray of int
        ``-max_lag..max_lag``; ``ccf[k, i] = corr(e(t), u_i(t - lags[k]))``.
    ccf : ndarray of shape (2 max_lag + 1, n_inputs)
        Cross-correlation for every input column.
    band : float
        Half-width ``z_{1-alpha/2} / sqrt(N)`` of the confidence band.
    positive : tuple of CorrelationTest
        Test over the positive lags (input leads residual: unmodelled
        dynamics), one per input column.
    negative : tuple of CorrelationTest
        Test over the negative lags ``-M..-1`` (residual leads input:
        feedback), one per input column.
    %(level)s

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> res = cross_correlation_test(rng.standard_normal(500),
    ...                              rng.standard_normal((500, 2)), max_lag=5)
    >>> res.ccf.shape, res.summary.shape
    ((11, 2), (4, 8))
    """

    lags: np.ndarray
    ccf: np.ndarray
    band: float
    positive: tuple[CorrelationTest, ...]
    negative: tuple[CorrelationTest, ...]
    alpha: float
    n_samples: int

    @property
    def n_inputs(self) -> int:
        """Number of input columns."""
        return int(self.ccf.shape[1])

    @property
    def passed(self) -> bool:
        """True if no test (either side, any input) rejects."""
        return all(t.passed for t in (*self.positive, *self.negative))

    @property
    def summary(self) -> pd.DataFrame:
        """One row per input and side: statistic, dof, p_value, passed, lags."""
        rows = [
            {
                "input": t.input,
                "side": side,
                "statistic": t.statistic,
                "dof": t.dof,
                "p_value": t.p_value,
                "passed": t.passed,
                "lags": f"{t.lags.min()}..{t.lags.max()}",
                "n_outside": t.n_outside,
            }
            for side, tests in (
                ("positive", self.positive),
                ("negative", self.negative),
            )
            for t in tests
        ]
        return _WholeFrame(rows).sort_values(["input", "side"], ignore_index=True)

    def to_frame(self) -> pd.DataFrame:
        """Return the cross-correlation of every input with its band.

        Returns
        -------
        pandas.DataFrame
            Tidy, columns ``input, lag, ccf, lower, upper, outside``.
        """
        n_lags, n_inputs = self.ccf.shape
        return pd.DataFrame(
            {
                "input": np.repeat(np.arange(n_inputs), n_lags),
                "lag": np.tile(self.lags, n_inputs),
                "ccf": self.ccf.T.ravel(),
                "lower": -self.band,
                "upper": self.band,
                "outside": np.abs(self.ccf.T.ravel()) > self.band,
            }
        )


def cross_correlation_test(
    residuals: Any,
    inputs: Any,
    max_lag: int = 25,
    alpha: float = 0.05,
    *,
    include_zero_lag: bool = True,
) -> CrossCorrelationResult:
    """Chi-square tests of residual/input cross-correlation (fig. 4.4).

    With ``r_eu(tau) = corr(e(t), u(t - tau))`` (positive ``tau``: the input
    leads the residual) the function returns ``r_eu`` for ``tau = -M..M``
    with the band ``+-z_{1-alpha/2}/sqrt(N)`` and, per input column, two
    tests (Soderstrom & Stoica, sec. 11.4): for a lag set ``T`` the statistic

    ``x = N r^T (lambda R_u)^{-1} r``, ``r = [cov(e(t), u(t - tau))]_{tau in T}``,

    with ``R_u[i, j] = cov(u(t - tau_i), u(t - tau_j))`` the Toeplitz matrix of
    input autocovariances and ``lambda`` the residual variance, is
    asymptotically chi-square with ``len(T)`` degrees of freedom when ``e`` is
    white and independent of ``u``. It is computed in the equivalent
    correlation form ``N rho^T P_u^{-1} rho``.

    * positive lags ``T+ = 0..M`` (``1..M`` with ``include_zero_lag=False``):
      rejection means input dynamics left in the residual (under-modelling);
    * negative lags ``T- = -M..-1``: rejection means the input depends on
      past residuals, i.e. feedback from output to input.

    Parameters
    ----------
    residuals : array-like of shape (n_samples,) or (n_samples, 1), or list
        One residual series or a list of series (pooled).
    inputs : array-like of shape (n_samples,) or (n_samples, n_inputs), or list
        The input (excitation) paired with ``residuals``.
    max_lag : int, default=25
        Largest lag ``M``, ``1 <= M < n_samples``.
    alpha : float, default=0.05
        Significance level.
    include_zero_lag : bool, default=True
        Whether lag 0 belongs to the positive-lag test. Set False for a model
        with direct feed-through (``input_delay=0``), whose fit makes
        ``r_eu(0)`` small by construction on training data.

    Returns
    -------
    CrossCorrelationResult
        ``lags``, ``ccf``, ``band``, ``positive`` and ``negative`` tests per
        input, ``summary`` and ``to_frame()``.

    Raises
    ------
    ValueError
        If the series contain NaN, lengths differ, ``residuals`` has more than
        one column, an input column is constant, or ``max_lag``/``alpha`` are
        out of range.

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(1)
    >>> u = rng.standard_normal((2000, 1))
    >>> e = rng.standard_normal(2000) + 0.5 * np.roll(u[:, 0], 2)  # u leads e
    >>> res = cross_correlation_test(e, u, max_lag=10)
    >>> int(res.lags[np.argmax(res.ccf[:, 0])])
    2
    >>> res.summary[["side", "passed"]].values.tolist()
    [['negative', True], ['positive', False]]
    """
    e = _series_list(residuals, "residuals")
    u = _input_list(inputs, e)
    z = _check_settings(max_lag, alpha, e)
    lags = np.arange(-max_lag, max_lag + 1)
    pos_lags = np.arange(0 if include_zero_lag else 1, max_lag + 1)
    neg_lags = np.arange(-max_lag, 0)
    ccf = np.empty((lags.size, u[0].shape[1]))
    positive, negative = [], []
    for i in range(u[0].shape[1]):
        col = [x[:, i] for x in u]
        names = ("residuals", f"inputs[:, {i}]")
        ccf[:, i] = _xcorr(e, col, lags, names)
        common = {"z": z, "alpha": alpha, "input_index": i, "names": names}
        positive.append(_correlation_test("r_eu+", e, col, pos_lags, **common))
        negative.append(_correlation_test("r_eu-", e, col, neg_lags, **common))
    return CrossCorrelationResult(
        lags=lags,
        ccf=ccf,
        positive=tuple(positive),
        negative=tuple(negative),
        **_band_fields(e, z, alpha),
    )


# ----------------------------------------------------------------------------
# Higher-order correlation tests for non-linear models
# ----------------------------------------------------------------------------
_NONLINEAR_TESTS = ("phi_ee", "phi_ue", "phi_u2e", "phi_u2e2", "phi_eeu")


@fill_doc(level=_LEVEL_DOC)
@dataclass(frozen=True, eq=False)
class NonlinearTestResult:
    """Billings-Voon higher-order correlation tests.

    Attributes
    ----------
    tests : tuple of CorrelationTest
        ``phi_ee`` once, then ``phi_ue``, ``phi_u2e``, ``phi_u2e2``,
        ``phi_eeu`` for every input column.
    %(level)s

    Examples
    --------
    >>> import numpy as np
    >>> e, u = np.random.default_rng(0).standard_normal((2, 500))
    >>> nonlinear_correlation_tests(e, u, max_lag=5).summary["test"].tolist()
    ['phi_ee', 'phi_ue', 'phi_u2e', 'phi_u2e2', 'phi_eeu']
    """

    tests: tuple[CorrelationTest, ...]
    alpha: float
    n_samples: int

    @property
    def passed(self) -> bool:
        """True if no test rejects."""
        return all(t.passed for t in self.tests)

    def get(self, name: str, input: int | None = None) -> CorrelationTest:
        """Look up one test by name and input column.

        Parameters
        ----------
        name : str
            One of ``"phi_ee"``, ``"phi_ue"``, ``"phi_u2e"``, ``"phi_u2e2"``,
            ``"phi_eeu"``.
        input : int, optional
            Input column (default 0); ignored for ``"phi_ee"``.

        Returns
        -------
        CorrelationTest
            The matching test.
        """
        for t in self.tests:
            if t.name == name and (name == "phi_ee" or t.input == (input or 0)):
                return t
        raise KeyError(
            f"no test {name!r} for input {input!r}; names: {_NONLINEAR_TESTS}"
        )

    @property
    def summary(self) -> pd.DataFrame:
        """One row per test and input: chi-square result and band counts."""
        return _WholeFrame(
            [
                {
                    "test": t.name,
                    "input": t.input,
                    "statistic": t.statistic,
                    "dof": t.dof,
                    "p_value": t.p_value,
                    "passed": t.passed,
                    "n_outside": t.n_outside,
                    "expected_outside": t.alpha * t.dof,
                }
                for t in self.tests
            ]
        )

    def to_frame(self) -> pd.DataFrame:
        """Return all correlation functions with their bands.

        Returns
        -------
        pandas.DataFrame
            Tidy, columns ``test, input, lag, value, lower, upper, outside``.
        """
        return pd.concat([t.to_frame() for t in self.tests], ignore_index=True)


def nonlinear_correlation_tests(
    residuals: Any, inputs: Any, max_lag: int = 25, alpha: float = 0.05
) -> NonlinearTestResult:
    """Higher-order correlation tests for non-linear models (Billings & Voon).

    A linear-in-correlation check misses non-linear terms left in the
    residual (e.g. ``u(t-1)^2``, which is uncorrelated with ``u`` for a
    symmetric input). For a valid model (Billings & Voon 1986) the
    normalised correlations below vanish, with ``u2 = u^2 - mean(u^2)`` and
    ``e2 = e^2 - mean(e^2)``:

    ============  ==========================================  ============
    test          correlation                                 lags
    ============  ==========================================  ============
    ``phi_ee``    ``corr(e(t), e(t - tau))``                  ``1..M``
    ``phi_ue``    ``corr(e(t), u(t - tau))``                  ``-M..M``
    ``phi_u2e``   ``corr(e(t), u2(t - tau))``                 ``-M..M``
    ``phi_u2e2``  ``corr(e2(t), u2(t - tau))``                ``-M..M``
    ``phi_eeu``   ``corr(e(t), e(t - tau) u(t - tau))``       ``1..M``
    ============  ==========================================  ============

    (``phi_eeu`` at lag ``k`` is Billings & Voon's ``phi_e(eu)(k - 1)``.)

    **Decision rule.** Each test is the portmanteau chi-square test used for
    the cross-correlation: ``N rho^T R_v^{-1} rho``, with ``R_v`` the Toeplitz
    matrix of autocorrelations of the second factor ``v`` (``u``, ``u2``,
    ``e u``; ``R = I`` for ``phi_ee``), is asymptotically chi-square with as
    many dof as lags when the first factor is white and independent of the
    past of ``v``; the test passes if ``p_value >= alpha``. This accounts
    for correlated lags and is exact in level, unlike counting lags outside
    the ``+-z/sqrt(N)`` band; that count (``n_outside``) is reported beside
    the expected ``alpha * n_lags`` for the classic visual reading.

    Parameters
    ----------
    residuals : array-like of shape (n_samples,) or (n_samples, 1), or list
        One residual series or a list of series (pooled).
    inputs : array-like of shape (n_samples,) or (n_samples, n_inputs), or list
        The input paired with ``residuals``.
    max_lag : int, default=25
        Largest lag ``M``, ``1 <= M < n_samples``.
    alpha : float, default=0.05
        Significance level.

    Returns
    -------
    NonlinearTestResult
        ``tests``, ``passed``, ``summary`` and ``to_frame()``.

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(2)
    >>> u = rng.standard_normal(3000)
    >>> e = 0.1 * rng.standard_normal(3000) + 0.3 * np.roll(u, 1) ** 2
    >>> res = nonlinear_correlation_tests(e, u, max_lag=10)
    >>> res.get("phi_ue").passed, res.get("phi_u2e").passed
    (True, False)
    """
    e = _series_list(residuals, "residuals")
    u = _input_list(inputs, e)
    z = _check_settings(max_lag, alpha, e)
    both = np.arange(-max_lag, max_lag + 1)
    past = np.arange(1, max_lag + 1)
    e2 = [x**2 for x in e]
    common = {"z": z, "alpha": alpha}
    tests = [
        _correlation_test(
            "phi_ee", e, e, past, input_index=None, names=("residuals",) * 2, **common
        )
    ]
    for i in range(u[0].shape[1]):
        col = [x[:, i] for x in u]
        name = f"inputs[:, {i}]"
        sq = [x**2 for x in col]  # centred inside the correlation
        eu = [a * b for a, b in zip(e, col, strict=True)]
        for test, white, reg, lags, names in (
            ("phi_ue", e, col, both, ("residuals", name)),
            ("phi_u2e", e, sq, both, ("residuals", f"{name}**2")),
            ("phi_u2e2", e2, sq, both, ("residuals**2", f"{name}**2")),
            ("phi_eeu", e, eu, past, ("residuals", f"residuals*{name}")),
        ):
            tests.append(
                _correlation_test(
                    test, white, reg, lags, input_index=i, names=names, **common
                )
            )
    return NonlinearTestResult(
        tests=tuple(tests), alpha=float(alpha), n_samples=sum(x.size for x in e)
    )
