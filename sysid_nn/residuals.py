"""Correlation tests on the residuals of an identified model (paper 4.3).

An adequate model leaves residuals ``e(t)`` (measured minus model output)
that are white and independent of the input. This module provides

* :func:`whiteness_test`: autocorrelation of ``e`` with its confidence band
  and the chi-square (Box-Pierce) test, Ljung-Box alongside (fig. 4.3);
* :func:`cross_correlation_test`: residual/input cross-correlation for
  lags ``-M..M`` with the chi-square tests of Soderstrom & Stoica for
  positive lags (unmodelled dynamics) and negative lags (feedback) (fig. 4.4);
* :func:`nonlinear_correlation_tests`: the higher-order correlation tests of
  Billings & Voon (1986) that also see unmodelled non-linear terms;
* :func:`analyze_residuals`: all of them for a fitted estimator on data, per
  sequence and pooled, with a summary table and a figure.

Conventions
-----------
All correlations use the biased estimator (sums divided by ``N``, not by
``N - |tau|``), each sequence centred on its own mean, and are normalised to
correlation coefficients. A **list of sequences** is pooled without crossing
sequence boundaries: lagged products ``sum_t a_j(t) b_j(t - tau)`` are summed
inside every sequence ``j`` and then over sequences, and divided by the pooled
sums of squares, so that ``N = sum_j N_j`` counts all samples. One sequence in
a list gives exactly the single-sequence result.

The cross-correlation lag convention is ``r_eu(tau) = corr(e(t), u(t - tau))``:
a positive lag means the input leads the residual.

Residuals containing NaN (a diverged free run) are rejected by the test
functions with a ``ValueError``; :func:`analyze_residuals` reports such a
sequence as ``"divergent"`` in its summary instead.

References
----------
T. Soderstrom and P. Stoica, *System Identification*, Prentice Hall, 1989,
section 11.4.
S. A. Billings and W. S. F. Voon, "Correlation based model validity tests for
non-linear models", *Int. J. Control* 44(1), 1986.
S. A. Billings and Q. M. Zhu, "Nonlinear model validation using correlation
tests", *Int. J. Control* 60(6), 1994.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import pandas as pd

from sysid_nn._analysis._correlation_tests import (
    CorrelationTest,
    CrossCorrelationResult,
    NonlinearTestResult,
    WhitenessResult,
    _WholeFrame,
    check_max_lag,
    cross_correlation_test,
    nonlinear_correlation_tests,
    whiteness_test,
)
from sysid_nn._records._data import is_sequence_list
from sysid_nn._records._sequences import as_sequence_list, check_paired

__all__ = [
    "CorrelationTest",
    "CrossCorrelationResult",
    "NonlinearTestResult",
    "ResidualAnalysis",
    "WhitenessResult",
    "analyze_residuals",
    "cross_correlation_test",
    "nonlinear_correlation_tests",
    "whiteness_test",
]


# ----------------------------------------------------------------------------
# Everything for a fitted estimator
# ----------------------------------------------------------------------------
Key = tuple[int | str, int]  # (sequence index or "pooled", output column)


@dataclass(frozen=True, eq=False)
class ResidualAnalysis:
    """All residual tests of a model on data; see :func:`analyze_residuals`.

    Attributes
    ----------
    residuals : ndarray or list of ndarray
        Measured minus model output, shaped like ``y`` (a list for a list).
    whiteness : dict
        ``{(sequence, output): WhitenessResult}``; ``sequence`` is the index
        in the list (0 for an array) or ``"pooled"``.
    cross_correlation : dict
        ``{(sequence, output): CrossCorrelationResult}``.
    nonlinear : dict
        ``{(sequence, output): NonlinearTestResult}`` (empty if not run).
    summary : pandas.DataFrame
        One row per sequence (then ``"pooled"``) x output x input x test with
        columns ``sequence, output, input, test, statistic, dof, p_value,
        passed, n_samples, status``; ``passed`` is the verdict, ``status`` is
        ``"ok"`` or ``"divergent"`` (NaN statistics, ``passed=False``).
        ``print(summary)`` shows every row and column whatever pandas'
        display options (frames derived from it too);
        ``pd.DataFrame(summary)`` is a plain DataFrame.
    divergent : tuple of int
        Sequences whose residuals contain NaN (excluded from the pooled tests).
    mode : str
        ``"prediction"`` or ``"simulation"``.
    horizon : int
        Prediction horizon (prediction mode).
    input_names : tuple of str or None
        Names of the input columns: a DataFrame's column names, else the
        estimator's ``feature_names_in_``, else None. :meth:`plot` shows
        them in the cross-correlation legend.

    Examples
    --------
    >>> import numpy as np
    >>> class Zero:
    ...     def simulate(self, X):
    ...         return np.zeros(len(X))
    >>> rng = np.random.default_rng(0)
    >>> report = analyze_residuals(Zero(), rng.standard_normal((300, 1)),
    ...                            rng.standard_normal(300), mode="simulation",
    ...                            max_lag=5)
    >>> report.passed, sorted(report.whiteness)
    (True, [(0, 0)])
    """

    residuals: Any
    whiteness: dict[Key, WhitenessResult]
    cross_correlation: dict[Key, CrossCorrelationResult]
    nonlinear: dict[Key, NonlinearTestResult]
    summary: pd.DataFrame
    divergent: tuple[int, ...]
    mode: str
    horizon: int
    input_names: tuple[str, ...] | None = None

    @property
    def passed(self) -> bool:
        """True if every test on every sequence passed (divergence fails)."""
        return bool(self.summary["passed"].all())

    def to_frame(self) -> pd.DataFrame:
        """Return all correlation functions with their bands.

        Returns
        -------
        pandas.DataFrame
            Tidy, columns ``sequence, output, test, input, lag, value, lower,
            upper, outside``; ``test`` is ``"acf"``, ``"r_eu"`` or a
            non-linear test name.
        """
        frames = []
        for (seq, out), w in self.whiteness.items():
            f = w.to_frame().reset_index().rename(columns={"acf": "value"})
            f.insert(0, "test", "acf")
            f.insert(1, "input", None)
            frames.append(f.assign(sequence=seq, output=out))
        for (seq, out), c in self.cross_correlation.items():
            f = c.to_frame().rename(columns={"ccf": "value"})
            f.insert(0, "test", "r_eu")
            frames.append(f.assign(sequence=seq, output=out))
        for (seq, out), nl in self.nonlinear.items():
            frames.append(nl.to_frame().assign(sequence=seq, output=out))
        columns = ["sequence", "output", "test", "input", "lag", "value"]
        columns += ["lower", "upper", "outside"]
        if not frames:
            return pd.DataFrame(columns=columns)
        return pd.concat(frames, ignore_index=True)[columns]

    def plot(
        self,
        sequence: int | str | None = None,
        output: int = 0,
        *,
        input_names: Sequence[str] | None = None,
    ) -> Any:
        """Autocorrelation and cross-correlation panels (figs 4.3-4.4).

        Parameters
        ----------
        sequence : int or "pooled", optional
            Which result to draw; default ``"pooled"`` for a list, else 0.
        output : int, default=0
            Output column.
        input_names : sequence of str, optional
            Legend text of every input column; default :attr:`input_names`
            (the data's column names), else ``input i``.

        Returns
        -------
        matplotlib.figure.Figure
            Two panels: autocorrelation and cross-correlation with bands.
        """
        from sysid_nn.plotting import plot_residual_analysis

        if sequence is None:
            sequence = "pooled" if isinstance(self.residuals, list) else 0
        names = self.input_names if input_names is None else input_names
        return plot_residual_analysis(
            self, sequence=sequence, output=output, input_names=names
        )


_SUMMARY_COLUMNS = [
    "sequence",
    "output",
    "input",
    "test",
    "statistic",
    "dof",
    "p_value",
    "passed",
    "n_samples",
    "status",
]


def _summary_rows(
    seq: int | str,
    out: int,
    results: tuple[Any, Any, Any],
    dofs: dict[str, int],
    n_inputs: int,
    n_samples: int,
) -> list[dict[str, Any]]:
    """Summary rows of one (sequence, output); NaN statistics when divergent.

    ``results`` is ``(whiteness, cross, nonlinear)``, all None for a divergent
    sequence; ``dofs`` maps every test name in the summary to its dof.
    """
    w, c, nl = results
    specs: list[tuple[int | None, str, Any]] = [(None, "whiteness", w)]
    for i in range(n_inputs):
        specs.append((i, "cross_positive", c and c.positive[i]))
        specs.append((i, "cross_negative", c and c.negative[i]))
        higher = [name for name in dofs if name.startswith("phi_")]
        specs.extend((i, name, nl and nl.get(name, i)) for name in higher)
    return [
        {
            "sequence": seq,
            "output": out,
            "input": inp,
            "test": test,
            "statistic": np.nan if res is None else res.statistic,
            "dof": dofs[test],
            "p_value": np.nan if res is None else res.p_value,
            "passed": False if res is None else res.passed,
            "n_samples": n_samples,
            "status": "ok" if w is not None else "divergent",
        }
        for inp, test, res in specs
    ]


def analyze_residuals(
    estimator: Any,
    X: Any,
    y: Any,
    *,
    mode: Literal["prediction", "simulation"] = "prediction",
    horizon: int = 1,
    max_lag: int = 25,
    alpha: float = 0.05,
    skip: int = 0,
    include_zero_lag: bool = True,
    nonlinear: bool = True,
    y_init: int = 0,
) -> ResidualAnalysis:
    """Run a fitted model on data and test its residuals (figs 4.3-4.4).

    The model output is ``estimator.predict(X, y, horizon=horizon)``
    (``mode="prediction"``: the ``horizon``-step-ahead prediction from
    measured outputs, paper 4.3) or ``estimator.simulate(X)``
    (``mode="simulation"``: the free run, paper 4.4); the residuals are
    ``y`` minus that output. For every sequence, output column and input
    column the whiteness, cross-correlation and (optionally) the higher-order
    tests are run; for a list of sequences also on the pooled sequences (see
    the module notes: lagged sums per sequence, never across boundaries).

    Notes: k-step-ahead residuals (``horizon > 1``) are a moving average of
    order ``horizon - 1`` even for a perfect model, so whiteness is expected
    to fail there; free-run residuals are usually coloured too. The
    whiteness/feedback tests are designed for one-step prediction.

    Parameters
    ----------
    estimator : object
        Fitted model with ``predict(X, y=None, *, horizon=1)`` and
        ``simulate(X)``.
    X : array-like of shape (n_samples, n_inputs) or list of such
        Excitation, passed to the estimator unchanged.
    y : array-like of shape (n_samples,) or (n_samples, n_outputs), or list
        Measured outputs.
    mode : {"prediction", "simulation"}, default="prediction"
        Which model output the residuals are taken from.
    horizon : int, default=1
        Prediction horizon (prediction mode only).
    max_lag : int, default=25
        Largest lag ``M`` of all tests.
    alpha : float, default=0.05
        Significance level.
    skip : int, default=0
        Samples dropped from the start of every sequence before testing
        (start-up transient of a record that does not start at rest).
    include_zero_lag : bool, default=True
        Passed to :func:`cross_correlation_test`.
    nonlinear : bool, default=True
        Also run :func:`nonlinear_correlation_tests`. Its ``phi_ee`` and
        ``phi_ue`` duplicate the whiteness and cross-correlation tests, so
        only ``phi_u2e``, ``phi_u2e2`` and ``phi_eeu`` enter the summary.
    y_init : int, default=0
        Simulation mode only: start each sequence's free run from its first
        ``y_init`` measured outputs, ``estimator.simulate(X, y_init=y[:y_init])``
        (the initial conditions fitted to them), instead of the estimator's
        default start; those samples are left out of the tests, as with
        ``skip``.

    Returns
    -------
    ResidualAnalysis
        ``residuals``, ``whiteness``, ``cross_correlation``, ``nonlinear``,
        ``summary``, ``to_frame()`` and ``plot()``. A sequence whose residuals
        contain NaN (a diverged simulation) appears as ``"divergent"`` in the
        summary and is left out of the pooled tests.

    Examples
    --------
    >>> import numpy as np
    >>> class Gain:  # y(t) = 2 u(t - 1), known exactly
    ...     def simulate(self, X):
    ...         return 2.0 * np.concatenate([[0.0], X[:-1, 0]])
    ...     def predict(self, X, y=None, *, horizon=1):
    ...         return self.simulate(X)
    >>> rng = np.random.default_rng(0)
    >>> X = rng.standard_normal((500, 1))
    >>> y = Gain().simulate(X) + 0.1 * rng.standard_normal(500)
    >>> report = analyze_residuals(Gain(), X, y, max_lag=10)
    >>> report.summary["test"].tolist()
    ['whiteness', 'cross_positive', 'cross_negative', 'phi_u2e', 'phi_u2e2', 'phi_eeu']
    """
    if mode not in ("prediction", "simulation"):
        raise ValueError(f"mode must be 'prediction' or 'simulation'; got {mode!r}.")
    for name, value in (("skip", skip), ("y_init", y_init)):
        if (
            isinstance(value, bool)
            or not isinstance(value, (int, np.integer))
            or value < 0
        ):
            raise ValueError(f"{name} must be an integer >= 0; got {value!r}.")
    if y_init and mode != "simulation":
        raise ValueError(
            f"y_init starts a free run; it applies to mode='simulation', not "
            f"{mode!r}. Leave it out (0) for predictions."
        )
    X_seqs, is_list = as_sequence_list(X, "X")
    y_seqs, y_is_list = as_sequence_list(y, "y")
    if is_list != y_is_list:
        raise ValueError(
            "X and y must both be arrays or both be lists of sequences; got "
            f"{type(X).__name__} and {type(y).__name__}."
        )
    check_paired(X_seqs, y_seqs, "X", "y")
    skip = max(skip, y_init)
    shortest = min(v.shape[0] for v in y_seqs)
    if skip >= shortest:
        raise ValueError(
            f"skip={skip} leaves no samples of the shortest sequence ({shortest} "
            "samples); use a skip well below the sequence length."
        )
    # The same rule as the tests themselves, checked before running the model.
    check_max_lag(max_lag, shortest - skip)
    if mode == "prediction":
        model = estimator.predict(X, y, horizon=horizon)
    elif y_init:
        window = [v[:y_init] for v in y] if is_list else y[:y_init]
        model = estimator.simulate(X, y_init=window)
    else:
        model = estimator.simulate(X)
    if is_sequence_list(model) != is_list:
        raise ValueError(
            f"The estimator's {mode} output is not shaped like y (array vs list)."
        )
    m_seqs, _ = as_sequence_list(model, f"{mode} output")
    check_paired(y_seqs, m_seqs, "y", f"{mode} output")
    res_seqs = [a - b for a, b in zip(y_seqs, m_seqs, strict=True)]

    # Mirror y: 1-D in, 1-D out.
    y_items = list(y) if is_list else [y]
    mirrored = [
        r[:, 0] if np.ndim(item) == 1 else r
        for r, item in zip(res_seqs, y_items, strict=True)
    ]
    residuals = mirrored if is_list else mirrored[0]

    n_out, n_in = res_seqs[0].shape[1], X_seqs[0].shape[1]
    tested = [(r[skip:], x[skip:]) for r, x in zip(res_seqs, X_seqs, strict=True)]
    divergent = tuple(j for j, (r, _) in enumerate(tested) if np.isnan(r).any())
    finite = [j for j in range(len(tested)) if j not in divergent]
    groups: list[tuple[int | str, list[int]]] = [(j, [j]) for j in range(len(tested))]
    if is_list:
        groups.append(("pooled", finite))

    m = int(max_lag)
    dofs = {"whiteness": m, "cross_positive": m + int(include_zero_lag)}
    dofs["cross_negative"] = m
    if nonlinear:
        dofs.update(phi_u2e=2 * m + 1, phi_u2e2=2 * m + 1, phi_eeu=m)
    whiteness, cross, nonlin = {}, {}, {}
    rows: list[dict[str, Any]] = []
    for seq, members in groups:
        ok = bool(members) and all(j in finite for j in members)
        n_samples = sum(tested[j][0].shape[0] for j in members)
        for out in range(n_out):
            w = c = nl = None
            if ok:
                e = [tested[j][0][:, out] for j in members]
                u = [tested[j][1] for j in members]
                w = whiteness_test(e, max_lag, alpha)
                c = cross_correlation_test(
                    e, u, max_lag, alpha, include_zero_lag=include_zero_lag
                )
                whiteness[seq, out], cross[seq, out] = w, c
                if nonlinear:
                    nl = nonlinear_correlation_tests(e, u, max_lag, alpha)
                    nonlin[seq, out] = nl
            rows.extend(_summary_rows(seq, out, (w, c, nl), dofs, n_in, n_samples))
    summary = _WholeFrame(rows, columns=_SUMMARY_COLUMNS)
    return ResidualAnalysis(
        residuals=residuals,
        whiteness=whiteness,
        cross_correlation=cross,
        nonlinear=nonlin,
        summary=summary,
        divergent=divergent,
        mode=mode,
        horizon=int(horizon),
        input_names=_input_names(estimator, X),
    )


def _input_names(estimator: Any, X: Any) -> tuple[str, ...] | None:
    """The inputs' column names: of the DataFrame(s) given, else the estimator's."""
    first = X[0] if isinstance(X, (list, tuple)) and len(X) else X
    columns = getattr(first, "columns", None)
    if columns is not None:
        return tuple(map(str, columns))
    names = getattr(estimator, "feature_names_in_", None)
    return None if names is None else tuple(map(str, names))
