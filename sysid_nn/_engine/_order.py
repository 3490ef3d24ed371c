"""The order from the data: the ISSM's ``n_states="auto"``, the TDL's lags.

One subspace projection of the training records (:mod:`sysid_nn._engine._subspace`)
gives the singular values, which fall off after the system's order, and a
linear innovation model of every candidate order (p up to :data:`MAX_ORDER`)
at the cost of a few least-squares fits. Each candidate's free run from rest
on the validation records (the training records when there are none) scores
it. The rule, whose inputs are all kept in ``order_selection_``:

* the *validated order* is the smallest candidate whose validation
  free-run error is within :data:`ORDER_TOLERANCE` (plus :data:`ORDER_FLOOR`)
  of the best candidate's; the *linear order* ``L`` is the singular
  values' largest gap (``gap_order``) instead when that is larger and also
  within the tolerance: among nearly equal free runs the validation can
  prefer too few states (a five-storey building's floor accelerations
  validated 8 where the gap shows its 10);
* the network gets ``L + max(p, ceil(L / p))`` states, at least ``p + 2``:
  beyond the linear order, one state per output or, when more, the linear
  order per output (an ARX's lags) once again. A shear building whose
  every floor is measured gets its ``3 n`` (``2 n`` linear, one hysteretic
  state per storey); a single output gets ``2 L``: on a non-linear system the
  linear models' free run is limited by what they miss, which hides the
  slower part of the dynamics (on the Wiener-Hammerstein benchmark, two
  sixth-order blocks, the linear order came out 3; 4 states gave a test
  error of 8.0 mV, 6 states 0.49 mV);
* records too short for the projection get ``p + 2`` states (empty
  evidence);
* on short records every order from the one at which the auto-sized
  network has at most one weight per :data:`SAMPLES_PER_WEIGHT` training
  samples (down to ``p + 2``) up to the evidence's is a candidate: the
  smallest whose linear models validate within
  :data:`SHORT_RECORD_TOLERANCE` of the evidence's is kept, with a warning
  (:func:`short_record_cap`);
* where no linear model explains the records (best NRMSE above
  :data:`RELIABLE_NRMSE`, or none stable: the hysteretic oscillator's drift,
  an integrator), the order is the singular values' largest gap
  (``gap_order``), at least ``p + 2``.

The TDL network's ``"auto"`` lags are the same order spread over the
outputs, ``ceil(n_states / p)`` and at least 3
(:func:`sysid_nn._engine._issm_start.order_lags`, the lags of the ISSM's ARX start:
3 for the paper's oscillator), and the short-records limit counts the TDL's
own weights. Both estimators take the rule through
``_RecurrentRegressorBase._choose_order``.
"""

from __future__ import annotations

import warnings

import numpy as np
from sklearn.utils import Bunch

from sysid_nn._engine._issm_start import (
    lags_per_output,
    subspace_horizon,
    subspace_records,
)
from sysid_nn._engine._selection import _FITTED_START_GAIN, start_window
from sysid_nn._engine._subspace import is_stable, output_error_model, projection
from sysid_nn._exceptions import user_stacklevel
from sysid_nn._kernels._linear import linear_free_run

#: Largest linear order tried.
MAX_ORDER = 10
#: Relative margin on the validation free-run error within which a smaller
#: order is preferred to the best one.
ORDER_TOLERANCE = 0.05
#: NRMSE below which candidates count as equal (noise-free records).
ORDER_FLOOR = 1e-3
#: Training samples (times outputs) per weight of the network below which
#: the order is lowered (down to ``p + 2``),
SAMPLES_PER_WEIGHT = 10
#: where the linear models up to the lowered order validate within this
#: share of those up to the evidence's order. A network's non-linearity
#: makes up for some of what a lower order misses, not for missing modes:
#: on a Wiener-Hammerstein-type record of 1500 samples the lowered order's
#: linear models validated 14 % worse, and its networks tested 2.3 (TDL)
#: and 4 (ISSM) times better than those of the evidence's order; on
#: generated lightly damped chains they validated 71-103 % (two modes,
#: 1024 samples) and 40-139 % (three modes, 2000 samples) worse, and the
#: evidence's order tested 10-20 times better
#: (``benchmarks/bench_linear.py``).
SHORT_RECORD_TOLERANCE = 0.3
#: Smallest hidden width of ``hidden_layer_sizes="auto"``.
AUTO_WIDTH = 7
#: Validation NRMSE of the best linear model above which its order is not
#: read from the linear models' free run (R^2 0.84; the hysteretic
#: oscillator's linear models reach 0.46-0.96, the field's 0.11-0.17).
RELIABLE_NRMSE = 0.4


def select_order(est, train, val, n_weights, between: bool) -> Bunch:
    """Choose the number of states from ``train``, scored on ``val``.

    ``est`` is the estimator being fitted (standardisation and sizes set);
    ``n_weights(n)`` counts the weights of its network with ``n`` states
    (the short-records rule); ``between``: whether the orders between the
    short-records limit and the evidence's are candidates too (see
    :func:`short_record_cap`).
    Returns the Bunch stored as ``order_selection_``: ``orders`` (the
    candidates), ``scores`` (validation free-run NRMSE of their linear
    models, ``inf`` for one that diverged), ``singular_values`` (of the
    subspace projection, leading ones), ``gap_order`` (the order after which
    the ratio of successive singular values is largest), ``validated_order``
    (the gap order when no candidate is stable), ``linear_order`` (the gap
    order instead when larger and within the tolerance), ``n_outputs`` and
    ``n_states`` (the rule above), the rule's constants ``tolerance``,
    ``floor`` and ``reliable``, and the short-record rule's evidence
    (:func:`short_record_cap`): ``evidence_states``,
    ``short_record_states``, ``short_record_limit``, ``short_record_scores``,
    ``short_record_fitted_start`` (whether those scores are of runs from
    fitted states, :func:`_fitted_start_judges`) and ``reason``.
    """
    p = est.n_outputs_
    top = MAX_ORDER
    horizon = subspace_horizon(est, train, top)
    while horizon == 0 and top > p:
        top -= 1
        horizon = subspace_horizon(est, train, top)
    if horizon == 0:
        # Too short for a projection: the former default, and no evidence.
        empty = np.array([], dtype=float)
        return Bunch(
            orders=np.array([], dtype=int), scores=empty, singular_values=empty,
            gap_order=None, validated_order=None, linear_order=None,
            n_outputs=p, n_states=p + 2,
            tolerance=ORDER_TOLERANCE, floor=ORDER_FLOOR, reliable=RELIABLE_NRMSE,
            evidence_states=p + 2, short_record_states=None, short_record_limit=None,
            short_record_scores=empty,
            short_record_fitted_start=False,
            reason="records too short for the subspace projection: p + 2 states",
        )  # fmt: skip
    Y, U = subspace_records(est, train)
    proj = projection(Y, U, horizon, constant=True)
    sv = proj.singular_values
    orders = np.arange(p, min(top, len(sv) - 1) + 1)
    window = start_window(val)
    runs = np.array(
        [_score(est, output_error_model(Y, U, proj, n), val, window) for n in orders]
    )
    scores = runs[:, 0]
    ratios = sv[orders - 1] / np.maximum(sv[orders], np.finfo(float).tiny)
    gap_order = int(orders[np.argmax(ratios)])
    best = np.min(scores)
    limit = (1.0 + ORDER_TOLERANCE) * best + ORDER_FLOOR
    validated = int(orders[scores <= limit][0]) if np.isfinite(best) else gap_order
    # The gap overrides the validation only among equally good candidates.
    gap_fits = scores[orders == gap_order][0] <= limit
    linear_order = max(validated, gap_order) if gap_fits else validated
    if best <= RELIABLE_NRMSE:
        n_states = max(extra_states(linear_order, p) + linear_order, p + 2)
    else:
        n_states = max(gap_order, p + 2)
    # Short records: no more weights than a tenth of the training samples,
    # where the linear model of the lower order validates as well.
    # The short-record rule compares orders as validation will judge their
    # networks: from states fitted to the records' first samples where the
    # runs from rest have not forgotten their start (a lightly damped arm's
    # acceleration: 0.68-0.71 NRMSE from rest for every order from 3 to 10,
    # 0.034-0.65 from fitted states).
    fitted_start = _fitted_start_judges(runs)
    cap = short_record_cap(
        est, orders, runs[:, 2] if fitted_start else scores, n_states, n_weights,
        len(train.modelled) * p, fitted_start, between,
    )  # fmt: skip
    n_states = cap.n_states
    return Bunch(
        orders=orders,
        scores=scores,
        singular_values=sv[: 2 * MAX_ORDER].copy(),
        gap_order=gap_order,
        validated_order=validated,
        linear_order=linear_order,
        n_outputs=p,
        n_states=int(n_states),
        tolerance=ORDER_TOLERANCE,
        floor=ORDER_FLOOR,
        reliable=RELIABLE_NRMSE,
        evidence_states=cap.evidence_states,
        short_record_states=cap.short_record_states,
        short_record_limit=cap.short_record_limit,
        short_record_scores=cap.short_record_scores,
        short_record_fitted_start=fitted_start,
        reason=cap.reason,
    )


def short_record_cap(
    est, orders, scores, n_states, n_weights, n_samples, fitted_start=False,
    between=True,
) -> Bunch:  # fmt: skip
    """The order the evidence found, or a lower one, by validation.

    The rule lowers ``n_states`` until the network has at most one weight
    per :data:`SAMPLES_PER_WEIGHT` training samples (times outputs), down to
    ``p + 2``. Where it lowers it, every order from that limit up to the
    evidence's is a candidate: the smallest whose linear models (the best
    validation free run of those of ``orders`` up to it, ``scores``)
    validate within :data:`SHORT_RECORD_TOLERANCE` (plus
    :data:`ORDER_FLOOR`) of the best up to the evidence's order is kept (a
    network of fewer weights that misses no mode a linear model sees), with
    a :class:`UserWarning`; where none does, the evidence's order stays.
    Returns a Bunch: ``n_states`` (the order kept), ``evidence_states``,
    ``short_record_states`` (the candidate kept, or the limit where none
    was; None where the rule does not lower the order),
    ``short_record_limit`` (the limit; None likewise),
    ``short_record_scores`` (the best validation free-run NRMSE of the
    linear models up to the evidence's order and up to
    ``short_record_states``; empty where the rule does not lower it) and
    ``reason`` (one sentence). ``fitted_start``: the scores are of runs
    from fitted states (see :func:`_fitted_start_judges`), which the reason
    says. With ``between=False`` the limit is the one lower candidate (the
    TDL's lags: on a two-mode chain of 1024 samples cut in motion its 4
    lags between its limit of 3 and the evidence's 5 tested at 0.155 NRMSE
    against 0.048, where the ISSM's 4 states tested as its 5 did).
    """
    p = est.n_outputs_
    limit = n_states
    while limit > p + 2 and n_weights(limit) * SAMPLES_PER_WEIGHT > n_samples:
        limit -= 1
    if limit == n_states:
        return Bunch(
            n_states=n_states, evidence_states=n_states, short_record_states=None,
            short_record_limit=None, short_record_scores=np.array([]),
            reason="the order the evidence found",
        )  # fmt: skip
    # A network of n states holds the linear models of every order up to n:
    # each order is scored by the best of those (the candidates' scores).
    # Orders between the limit and the evidence's can be candidates too: on
    # a lightly damped chain of two modes held out 30 %, the evidence's 8
    # states against a limit of 3, which misses a mode, where 4 hold both.
    best = {
        n: np.min(scores[orders <= n], initial=np.inf)
        for n in range(limit, n_states + 1)
    }
    bound = (1.0 + SHORT_RECORD_TOLERANCE) * best[n_states] + ORDER_FLOOR
    tried = range(limit, n_states) if between else (limit,)
    passing = [n for n in tried if best[n] <= bound]
    kept = bool(passing)
    lowered = passing[0] if kept else limit
    scores = np.array([best[n_states], best[lowered]])
    start = ", from states fitted to the first samples" if fitted_start else ""
    per_weight = (
        f"the training records hold fewer than {SAMPLES_PER_WEIGHT} samples per "
        f"weight of the network of {n_states} states"
    )
    fewest = f" (the fewest from {limit} up)" if between and lowered > limit else ""
    tested = f"{limit} to {n_states - 1}" if between and limit < n_states - 1 else limit
    if kept:
        reason = (
            f"{per_weight}, and the linear models of up to {lowered} states"
            f"{fewest} validate within {100 * SHORT_RECORD_TOLERANCE:g} % of "
            f"those up to {n_states} (free-run NRMSE {scores[1]:.3g} against "
            f"{scores[0]:.3g}{start})"
        )
        warnings.warn(
            f"{type(est).__name__} lowered the order the records show from "
            f"{n_states} to {lowered} states: {reason}; give the order "
            "explicitly to keep it.",
            UserWarning,
            stacklevel=user_stacklevel(),
        )
    else:
        reason = (
            f"{per_weight}, but the linear models of up to {tested} states "
            f"validate worse (free-run NRMSE {scores[1]:.3g} up to {limit} "
            f"against {scores[0]:.3g}{start}): the evidence's order is kept"
        )
    return Bunch(
        n_states=lowered if kept else n_states,
        evidence_states=n_states,
        short_record_states=lowered,
        short_record_limit=limit,
        short_record_scores=scores,
        reason=reason,
    )


def extra_states(linear_order: int, n_outputs: int) -> int:
    """States of the network beyond the linear order: ``max(p, ceil(L / p))``.

    Examples
    --------
    >>> extra_states(6, 3), extra_states(10, 5), extra_states(3, 1)
    (3, 5, 3)
    """
    return max(n_outputs, lags_per_output(linear_order, n_outputs))


def auto_width(n_states: int, n_outputs: int) -> int:
    """Hidden width of ``hidden_layer_sizes="auto"``.

    Three units per unmeasured state, at least 7: 7 for the paper's
    oscillator (two unmeasured states), 15 for 6 states and one output, the
    width of the best published networks of that order.
    """
    return max(AUTO_WIDTH, 3 * (n_states - n_outputs))


def tdl_auto_width(output_lags: int, n_outputs: int) -> int:
    """Hidden width of the TDL's ``hidden_layer_sizes="auto"``.

    Three units per fed-back output value (``output_lags`` of each output),
    at least 7: 9 for three lags of one output, the paper's width.

    Examples
    --------
    >>> tdl_auto_width(3, 1), tdl_auto_width(6, 1), tdl_auto_width(1, 1)
    (9, 18, 7)
    """
    return max(AUTO_WIDTH, 3 * output_lags * n_outputs)


def _n_weights(est, n: int) -> int:
    """Weights of the auto-sized ISSM network with ``n`` states and its linear part."""
    n_z = n + est.n_features_in_ + est.n_outputs_
    width = auto_width(n, est.n_outputs_)
    return n_z * width + width + width * n + n + n * n_z


def _fitted_start_judges(runs: np.ndarray) -> bool:
    """Whether the orders are compared from fitted starts.

    ``runs`` holds :func:`_score`'s three NRMSE per order. Where the best
    linear model's mean squared error after the window falls below
    :data:`~sysid_nn._engine._selection._FITTED_START_GAIN` of the best run
    from rest over the same rows, as the selection's rule for validation
    records.
    """
    rest, fitted = np.min(runs[:, 1]), np.min(runs[:, 2])
    return bool(np.isfinite(fitted) and fitted**2 < _FITTED_START_GAIN * rest**2)


def _score(est, lin: Bunch, data, window: int = 0) -> np.ndarray:
    """Validation free-run NRMSE of a subspace model: three ways.

    From rest over every sample; from rest after the first ``window``
    samples of each record; and after them from the state whose free run
    best fits them (least squares: the model is linear). ``inf`` where the
    model is unstable or a run diverged. ``data`` are standardised stacked
    records.
    """
    n = lin.A.shape[0]
    if not is_stable(lin.A):
        return np.full(3, np.inf)
    Y, U = subspace_records(est, data)
    u_rest = -est._x_mean / est._x_scale
    x_rest = np.linalg.lstsq(np.eye(n) - lin.A, lin.B @ u_rest + lin.c, rcond=None)[0]
    runs = [[], [], []]
    targets = [[], []]
    for y, u in zip(Y, U, strict=True):
        Yhat = np.empty_like(y)
        linear_free_run(lin.A, lin.B, lin.C, lin.c, u, x_rest, Yhat)
        w = min(window, len(y))
        # The response to a change of the initial state: rows C A^k.
        obs = np.empty((w, y.shape[1], n))
        M = lin.C.copy()
        for k in range(w):
            obs[k], M = M, M @ lin.A
        gap = (y[:w] - Yhat[:w]).ravel()
        dx = np.linalg.lstsq(obs.reshape(-1, n), gap, rcond=None)[0]
        Yfit = np.empty_like(y)
        linear_free_run(lin.A, lin.B, lin.C, lin.c, u, x_rest + dx, Yfit)
        runs[0].append(Yhat - y)
        runs[1].append((Yhat - y)[w:])
        runs[2].append((Yfit - y)[w:])
        targets[0].append(y)
        targets[1].append(y[w:])
    out = np.full(3, np.inf)
    judged = [targets[0], targets[1], targets[1]]
    for i, (e, t) in enumerate(zip(runs, judged, strict=True)):
        e, t = np.concatenate(e), np.concatenate(t)
        if len(e) and np.all(np.isfinite(e)):
            rms = np.sqrt(np.mean(e**2, axis=0))
            out[i] = float(np.mean(rms / np.maximum(t.std(axis=0), 1e-300)))
    return out
