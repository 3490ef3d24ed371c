"""One-line breaks of the training policy, and whether the tests catch them.

Each mutation below is a plausible one-line bug in code that decides what a
fit returns. The script copies the checkout to a temporary folder, applies
one mutation at a time, runs the tests aimed at it and reports ``KILLED``
(a test failed) or ``SURVIVED`` (every test passed: the promise is not
guarded). A mutation whose text is no longer in its file is reported
``STALE``: update it with the code it guards.

Run: ``python benchmarks/mutations.py`` (about a minute), or name some:
``python benchmarks/mutations.py burn-in patience``. Exit status 1 if any
mutation survived or went stale. Add a mutation here with each new
decision of the policy, next to the test named for it.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
POLICY = "tests/test_policy.py"


@dataclass(frozen=True)
class Mutation:
    name: str
    path: str
    original: str
    broken: str
    tests: tuple[str, ...]


MUTATIONS = (
    Mutation(
        "burn-in",
        "sysid_nn/_records/_data.py",
        "return self._rows_after(max(self.burn, self.lead))",
        "return self._rows_after(self.lead)",
        (f"{POLICY}::test_validation_score_leaves_out_the_burn_in_rows",),
    ),
    Mutation(
        "best weights",
        "sysid_nn/_engine/_training.py",
        "        w = tracker.best_w\n",
        "        w = w\n",
        (f"{POLICY}::test_coefs_are_the_best_validated_weights_by_a_clear_margin",),
    ),
    Mutation(
        "failed first fit",
        "sysid_nn/_estimators/_base.py",
        "            self.__dict__.clear()\n",
        "",
        (f"{POLICY}::test_a_failed_first_fit_leaves_only_the_constructor_parameters",),
    ),
    Mutation(
        "patience",
        "sysid_nn/_engine/_training.py",
        "        tracker.since_best = 0\n",
        "",
        (f"{POLICY}::test_patience_counts_the_current_stages_own_steps",),
    ),
    Mutation(
        "two records",
        "sysid_nn/_estimators/_base.py",
        "if len(Xs) >= 3:",
        "if len(Xs) >= 2:",
        (f"{POLICY}::test_two_records_hold_out_the_tail_of_the_second",),
    ),
    Mutation(
        "noise degrees of freedom",
        "sysid_nn/_analysis/_uncertainty.py",
        "normal.rss / max(normal.n_rows - n_eff / p, 1.0)",
        "normal.rss / normal.n_rows",
        (f"{POLICY}::test_noise_variance_carries_its_degrees_of_freedom_correction",),
    ),
    Mutation(
        "covariance small-sample factor",
        "sysid_nn/_analysis/_uncertainty.py",
        "cov = inv @ normal.meat @ inv * (n_res / max(n_res - n_eff, 1.0))",
        "cov = inv @ normal.meat @ inv",
        (f"{POLICY}::test_weight_covariance_carries_its_small_sample_factor",),
    ),
    Mutation(
        "worst restart",
        "sysid_nn/_engine/_selection.py",
        "best = min(pool, key=lambda r: r.criterion)\n",
        "best = max(pool, key=lambda r: r.criterion)\n",
        (f"{POLICY}::test_without_a_linear_candidate_the_best_restart_is_kept",),
    ),
    Mutation(
        "unit margin",
        "sysid_nn/_engine/_subspace.py",
        "np.abs(np.linalg.eigvals(A)).max() < 1.0 - UNIT_MARGIN",
        "np.abs(np.linalg.eigvals(A)).max() < 1.0",
        (
            "tests/test_least_squares.py"
            "::test_a_pole_within_the_margin_of_the_unit_circle_is_not_stable",
        ),
    ),
    Mutation(
        "block states",
        "sysid_nn/_engine/_subspace.py",
        "states[k] = out[-1, p:]",
        "pass",
        (
            "tests/test_least_squares.py"
            "::test_output_error_blocks_carry_the_states_across_blocks",
        ),
    ),
    Mutation(
        "block cutoff",
        "sysid_nn/_engine/_least_squares.py",
        "rcond=cutoff(n_rows, k)",
        "rcond=None",
        (
            "tests/test_least_squares.py"
            "::test_rank_deficient_designs_get_the_minimum_norm_solution",
        ),
    ),
    Mutation(
        "run-in without rest",
        "sysid_nn/_estimators/_base.py",
        'lead = _RUN_IN if start != "zero" else 0',
        "lead = _RUN_IN",
        (f"{POLICY}::test_a_model_without_rest_starts_from_zero_without_run_in",),
    ),
    Mutation(
        "run-in from the zero state",
        "sysid_nn/_estimators/_base.py",
        "self._run_in_from, *found = run_in_origin(self, fitted)",
        "_, *found = run_in_origin(self, fitted)\n        self._run_in_from = None",
        (
            f"{POLICY}::test_a_model_with_two_rests_starts_at_the_one_its_training_"
            "record_leads_to",
        ),
    ),
    Mutation(
        "run-in from the first record",
        "sysid_nn/_engine/_state_estimation.py",
        "return int(np.argmax(np.diff(data.starts)))",
        "return 0",
        (
            f"{POLICY}::test_a_model_with_two_rests_starts_at_the_one_its_training_"
            "record_leads_to",
        ),
    ),
    Mutation(
        "run-in: the training end by default",
        "sysid_nn/_engine/_state_estimation.py",
        "    if losses[1] < losses[0]:\n",
        "    if True:\n",
        (
            f"{POLICY}::test_a_model_with_two_rests_starts_at_the_one_its_training_"
            "record_leads_to",
        ),
    ),
    Mutation(
        "run-in: two rests by their record alike",
        "sysid_nn/_engine/_state_estimation.py",
        "    if same:\n",
        "    if False:\n",
        (f"{POLICY}::test_the_run_in_starts_where_the_training_records_free_run_ends",),
    ),
    Mutation(
        "run-in: only a rest of the zero state's",
        "sysid_nn/_engine/_state_estimation.py",
        '    if zero.start == "zero":\n        return origin, led, evidence\n',
        '    if zero.start == "zero":\n        return None, zero, evidence\n',
        (
            f"{POLICY}::test_a_model_with_two_rests_starts_at_the_one_its_training_"
            "record_leads_to",
        ),
    ),
    Mutation(
        "simulate's run-in from the zero state",
        "sysid_nn/_estimators/_base.py",
        "if origin is not None:  # a run-in from the training record's end",
        "if origin is not None and not at_rest:",
        (
            f"{POLICY}::test_a_model_with_two_rests_starts_at_the_one_its_training_"
            "record_leads_to",
        ),
    ),
    Mutation(
        "export: run-in from the zero state",
        "sysid_nn/_export.py",
        "Mzs, Mzu, Mss, Msu, Mso, Co, start = build(est, origin)",
        "Mzs, Mzu, Mss, Msu, Mso, Co, start = build(est, None)",
        (
            f"{POLICY}::test_a_model_with_two_rests_starts_at_the_one_its_training_"
            "record_leads_to",
        ),
    ),
    Mutation(
        "run-in: the unmeasured states from zero",
        "sysid_nn/_estimators/_issm.py",
        "x[self.n_outputs_ :]]",
        "0.0 * x[self.n_outputs_ :]]",
        (f"{POLICY}::test_the_run_in_starts_where_the_training_records_free_run_ends",),
    ),
    Mutation(
        "run-in only at rest",
        "sysid_nn/_estimators/_base.py",
        'lead = _RUN_IN if start != "zero" else 0',
        'lead = _RUN_IN if start == "rest" else 0',
        (f"{POLICY}::test_a_model_without_rest_starts_from_zero_without_run_in",),
    ),
    Mutation(
        "cycle: a decay too",
        "sysid_nn/_engine/_state_estimation.py",
        "np.abs(last.min(axis=0) - lo) <= _CYCLE_TOL * width",
        "last.min(axis=0) >= lo - _CYCLE_TOL * width",
        (
            "tests/test_engine.py::test_a_model_on_a_sustained_cycle_starts_after_the_run_in",
        ),
    ),
    Mutation(
        "cycle: outside the range",
        "sysid_nn/_engine/_state_estimation.py",
        "if cycling and inside:",
        "if cycling:",
        (
            "tests/test_engine.py::test_a_model_on_a_sustained_cycle_starts_after_the_run_in",
        ),
    ),
    Mutation(
        "cycle: one output enough",
        "sysid_nn/_engine/_state_estimation.py",
        "return bool(np.all(same))",
        "return bool(np.any(same))",
        (
            "tests/test_engine.py::test_a_model_on_a_sustained_cycle_starts_after_the_run_in",
        ),
    ),
    Mutation(
        "self-oscillating restarts alike where none is bounded",
        "sysid_nn/_engine/_selection.py",
        "or [r for r, c in zip(runs, cycling, strict=True) if not c]",
        "or []",
        (
            "tests/test_selection.py"
            "::test_restart_that_self_oscillates_comes_after_one_that_settles_where_none_passes",
        ),
    ),
    Mutation(
        "self-oscillating under zero excitation",
        "sysid_nn/_engine/_selection.py",
        "level = median * est._x_scale + est._x_mean",
        "level = 0.0",
        (
            "tests/test_selection.py"
            "::test_the_choice_among_restarts_is_explained_by_fitted_attributes",
        ),
    ),
    Mutation(
        "export: a cycle is a rest",
        "sysid_nn/_export.py",
        '"at_rest": kind == "rest"',
        '"at_rest": kind != "zero"',
        ("tests/test_export.py::test_dlti_warns_without_a_rest",),
    ),
    Mutation(
        "short-record order always",
        "sysid_nn/_engine/_order.py",
        "passing = [n for n in tried if best[n] <= bound]",
        "passing = list(tried)",
        (
            "tests/test_order.py::test_short_record_order_that_misses_the_dynamics_"
            "gives_way_to_one_that_holds_them",
        ),
    ),
    Mutation(
        "short-record candidates the limit alone",
        "sysid_nn/_engine/_order.py",
        "passing = [n for n in tried if best[n] <= bound]",
        "passing = [n for n in tried[:1] if best[n] <= bound]",
        (
            "tests/test_order.py::"
            "test_evidence_order_stays_where_no_lower_order_validates_as_well",
        ),
    ),
    Mutation(
        "short-record orders between the limit and the evidence for the TDL",
        "sysid_nn/_estimators/_base.py",
        "between=self._orders_between,",
        "between=True,",
        (
            "tests/test_order.py::test_tdl_lags_are_the_short_record_limit_or_the_evidence",
        ),
    ),
    Mutation(
        "short-record order never",
        "sysid_nn/_engine/_order.py",
        "passing = [n for n in tried if best[n] <= bound]",
        "passing = []",
        ("tests/test_order.py::test_short_records_lower_the_order",),
    ),
    Mutation(
        "constant-input response of the wrong side allowed",
        "sysid_nn/_engine/_selection.py",
        "wrong = np.sign(end - end[mid]) * lin_side < 0",
        "wrong = np.sign(end - end[mid]) * lin_side > 0",
        (
            "tests/test_selection.py::"
            "test_restart_that_settles_on_the_wrong_side_or_swings_is_not_chosen",
        ),
    ),
    Mutation(
        "constant-input swing not judged",
        "sysid_nn/_engine/_selection.py",
        "ratios.append(float(max(beyond.max(), swung.max())))",
        "ratios.append(float(beyond.max()))",
        (
            "tests/test_selection.py::"
            "test_restart_that_settles_on_the_wrong_side_or_swings_is_not_chosen",
        ),
    ),
    Mutation(
        "constant-input excursion not disqualifying",
        "sysid_nn/_engine/_selection.py",
        "                x <= 1.0,\n",
        "                x <= np.inf,\n",
        (
            "tests/test_selection.py::"
            "test_restart_that_settles_on_the_wrong_side_or_swings_is_not_chosen",
        ),
    ),
    Mutation(
        "short-record tolerance of the linear order rule",
        "sysid_nn/_engine/_order.py",
        "SHORT_RECORD_TOLERANCE = 0.3",
        "SHORT_RECORD_TOLERANCE = ORDER_TOLERANCE",
        (
            "tests/test_order.py::"
            "test_short_record_order_kept_where_the_evidence_gains_little",
        ),
    ),
    Mutation(
        "wild runs beyond the training range kept",
        "sysid_nn/_engine/_selection.py",
        "_AMPLITUDE_PEAK = 5.0",
        "_AMPLITUDE_PEAK = np.inf",
        (
            "tests/test_selection.py::"
            "test_restart_that_diverges_beyond_the_training_range_is_not_chosen",
        ),
    ),
    Mutation(
        "continuation judged over the training part too",
        "sysid_nn/_records/_data.py",
        "return self._rows_after(max(self.burn, self.lead))",
        "return self._rows_after(self.burn)",
        (
            "tests/test_selection.py::"
            "test_short_tail_of_a_record_at_rest_is_judged_as_its_continuation",
        ),
    ),
    Mutation(
        "continuation never",
        "sysid_nn/_engine/_selection.py",
        "and _START_MEMORY < _start_memory(response, val) < 1.0",
        "and _START_MEMORY < _start_memory(response, val) < 0.0",
        (
            "tests/test_selection.py::"
            "test_short_tail_of_a_record_at_rest_is_judged_as_its_continuation",
        ),
    ),
    Mutation(
        "continuation of records that start in motion",
        "sysid_nn/_engine/_selection.py",
        "    return bool(np.all(np.abs(heads - rest) <= _AT_REST))",
        "    return True",
        (
            "tests/test_selection.py::"
            "test_tail_is_judged_as_its_records_continuation_only_where_needed",
        ),
    ),
    Mutation(
        "continuation of tails the start's response leaves",
        "sysid_nn/_engine/_selection.py",
        "and _START_MEMORY < _start_memory(response, val) < 1.0",
        "and 0.0 <= _start_memory(response, val) < 1.0",
        (
            "tests/test_selection.py::"
            "test_tail_is_judged_as_its_records_continuation_only_where_needed",
        ),
    ),
    Mutation(
        "arx rows with rest lags",
        "sysid_nn/_estimators/_tdl.py",
        "        rows = measured.measured_rows(data.h)\n",
        "        rows = measured.modelled\n",
        ("tests/test_tdl.py::test_closed_form_fit_regresses_only_on_measured_lags",),
    ),
    Mutation(
        "linear model judged from rest",
        "sysid_nn/_engine/_training.py",
        "    elif val is not None and not est._hidden_layers():",
        "    elif False:",
        (f"{POLICY}::test_linear_model_is_judged_as_the_networks_are",),
    ),
    Mutation(
        "records-like excitations not judged",
        "sysid_nn/_engine/_selection.py",
        "    like = surrogate_bounds(est, train, linear)",
        "    like = []",
        (
            "tests/test_selection.py::test_network_wi"
            "ld_under_excitations_like_the_records_is_not_chosen",
        ),
    ),
    Mutation(
        "records-like excitations judged at the wild-run peak",
        "sysid_nn/_engine/_selection.py",
        "pairs.append((data, _AMPLITUDE_MARGIN * max(reach, lin_peak)))",
        "pairs.append((data, _AMPLITUDE_PEAK * max(reach, lin_peak)))",
        (
            "tests/test_selection.py::test_network_wi"
            "ld_under_excitations_like_the_records_is_not_chosen",
        ),
    ),
    Mutation(
        "records-like excitations judged without the linear model",
        "sysid_nn/_engine/_selection.py",
        "pairs.append((data, _AMPLITUDE_MARGIN * max(reach, lin_peak)))",
        "pairs.append((data, _AMPLITUDE_MARGIN * reach))",
        (
            "tests/test_selection.py::test_network_wi"
            "ld_under_excitations_like_the_records_is_not_chosen",
        ),
    ),
    Mutation(
        "records-like excitations with their phases kept",
        "sysid_nn/_engine/_selection.py",
        "    turn = np.exp(2j * np.pi * rng.random(len(spectrum)))",
        "    turn = np.exp(0j * rng.random(len(spectrum)))",
        (
            "tests/test_selection.py::"
            "test_surrogate_excitation_keeps_spectrum_range_and_history",
        ),
    ),
    Mutation(
        "run ends worse than its start",
        "sysid_nn/_engine/_training.py",
        "        if start_loss < loss or not np.isfinite(loss):",
        "        if False:",
        (f"{POLICY}::test_run_without_validation_ends_no_worse_than_its_start",),
    ),
    Mutation(
        "order compared from rest",
        "sysid_nn/_engine/_order.py",
        "and fitted**2 < _FITTED_START_GAIN * rest**2)",
        "and False)",
        (
            "tests/test_order.py::"
            "test_short_record_orders_compared_from_fitted_starts_where_needed",
        ),
    ),
    Mutation(
        "order compared from fitted starts",
        "sysid_nn/_engine/_order.py",
        "    return bool(np.isfinite(fitted) and",
        "    return bool(True or",
        (
            "tests/test_order.py::test_short_record_order_kept_where_the_evidence_gains_little",
        ),
    ),
    Mutation(
        "no closed-form candidate",
        "sysid_nn/_engine/_training.py",
        "    if not est._hidden_layers():\n        # A linear model: its closed-form",
        "    if False:\n        # A linear model: its closed-form",
        (
            f"{POLICY}::test_linear_model_fits_its_training_records_no_worse_than_least_squares",
        ),
    ),
    Mutation(
        "closed-form fit to low-passed records",
        "sysid_nn/_estimators/_tdl.py",
        "        arx_phi = self._regressors(measured, rows)\n",
        "        arx_phi, measured = self._regressors(data, rows), data\n",
        (
            f"{POLICY}::test_linear_model_fits_its_training_records_no_worse_than_least_squares",
        ),
    ),
    Mutation(
        "linear model not held to its closed-form fits",
        "sysid_nn/_engine/_selection.py",
        "        if val is not None and closed_form:",
        "        if False:",
        (
            f"{POLICY}::test_linear_model_fits_its_training_records_no_worse_than_least_squares",
        ),
    ),
    Mutation(
        "linear candidate without its closed-form fits",
        "sysid_nn/_engine/_selection.py",
        "    fits += closed\n",
        "",
        (f"{POLICY}::test_networks_linear_model_is_held_to_its_closed_form_fit",),
    ),
    Mutation(
        "linear candidate not held to its closed-form fits",
        "sysid_nn/_engine/_selection.py",
        "    if val is not None and closed:",
        "    if False:",
        (f"{POLICY}::test_networks_linear_model_is_held_to_its_closed_form_fit",),
    ),
    Mutation(
        "no second batch",
        "sysid_nn/_engine/_training.py",
        "_EXTRA_BATCHES = 1\n",
        "_EXTRA_BATCHES = 0\n",
        (
            "tests/test_selection.py::"
            "test_second_batch_of_restarts_where_the_first_lost_to_the_linear_model",
        ),
    ),
    Mutation(
        "second batch after a network fitted better",
        "sysid_nn/_engine/_selection.py",
        "    if retry and not fits_better(runs, bounded, linear):\n",
        "    if retry:\n",
        (
            "tests/test_selection.py::"
            "test_linear_model_is_returned_where_no_restart_beats_it",
        ),
    ),
    Mutation(
        "second batch where a network fitted better",
        "sysid_nn/_engine/_training.py",
        "            or _selection.fits_better(runs, bounded, linear)\n",
        "            or False\n",
        (
            "tests/test_selection.py::"
            "test_linear_model_is_returned_where_no_restart_beats_it",
        ),
    ),
    Mutation(
        "fitted start weighed within the burn-in",
        "sysid_nn/_engine/_selection.py",
        "        late = max(burn, window)\n",
        "        late = window\n",
        (
            "tests/test_selection.py::"
            "test_fitted_validation_start_is_weighed_against_the_burn_in",
        ),
    ),
    Mutation(
        "refinement never preferred",
        "sysid_nn/_engine/_selection.py",
        "                best = ref\n",
        "                pass\n",
        (
            "tests/test_selection.py::"
            "test_refinement_kept_unless_a_restart_validates_clearly_better",
        ),
    ),
    Mutation(
        "refinement always preferred",
        "sysid_nn/_engine/_selection.py",
        "if not advantage > _SIGNIFICANT:",
        "if True:",
        (
            "tests/test_selection.py::"
            "test_refinement_kept_unless_a_restart_validates_clearly_better",
        ),
    ),
    Mutation(
        "refinement comparison not reported",
        "sysid_nn/_engine/_training.py",
        "        refinement_advantage=advantage,\n",
        "",
        (
            "tests/test_selection.py::"
            "test_refinement_comparison_is_a_fitted_attribute_that_decides",
        ),
    ),
    Mutation(
        "validation noise taken as independent",
        "sysid_nn/_engine/_selection.py",
        "lag = int(np.sqrt(len(d) / (len(bounds) - 1)))",
        "lag = 0",
        (
            "tests/test_selection.py::"
            "test_validation_advantage_allows_for_autocorrelated_errors",
        ),
    ),
    Mutation(
        "record in motion judged from rest on its tail",
        "sysid_nn/_engine/_selection.py",
        "        if record_at_rest or not est._estimates_start():\n",
        "        if record_at_rest:\n",
        (
            "tests/test_selection.py::"
            "test_tail_of_a_record_in_motion_is_judged_from_its_measured_start",
        ),
    ),
    Mutation(
        "record in motion continued from rest",
        "sysid_nn/_engine/_selection.py",
        "whole = continuation(train, val, measured_start=True)",
        "whole = continuation(train, val)",
        (
            "tests/test_selection.py::"
            "test_tail_is_judged_as_its_records_continuation_only_where_needed",
        ),
    ),
    Mutation(
        "linear fits clearly worse on training kept",
        "sysid_nn/_engine/_selection.py",
        "_LINEAR_FIT_MARGIN = 2.0\n",
        "_LINEAR_FIT_MARGIN = np.inf\n",
        (
            "tests/test_selection.py::"
            "test_linear_fit_far_worse_on_training_loses_on_a_record_in_motion",
            "tests/test_selection.py::"
            "test_linear_fit_clearly_worse_on_training_is_no_candidate",
        ),
    ),
    Mutation(
        "linear fits chosen by training loss",
        "sysid_nn/_engine/_selection.py",
        "_LINEAR_FIT_MARGIN = 2.0\n",
        "_LINEAR_FIT_MARGIN = 1.0\n",
        (
            "tests/test_selection.py::"
            "test_linear_fit_clearly_worse_on_training_is_no_candidate",
        ),
    ),
    Mutation(
        "ISSM linear model without its starts",
        "sysid_nn/_estimators/_issm.py",
        '        if for_network or self._hidden_layers() or self.init == "tdl":\n',
        "        if True:\n",
        (
            "tests/test_selection.py::"
            "test_issm_linear_model_keeps_its_start_where_training_fits_worse",
        ),
    ),
    Mutation(
        "ISSM starts as a network's linear candidates",
        "sysid_nn/_estimators/_issm.py",
        '        if for_network or self._hidden_layers() or self.init == "tdl":\n',
        '        if self._hidden_layers() or self.init == "tdl":\n',
        (
            "tests/test_selection.py::"
            "test_issm_linear_candidate_comes_from_its_better_linear_start",
        ),
    ),
    Mutation(
        "ISSM start of a closed-form fit",
        "sysid_nn/_estimators/_issm.py",
        "        elif restart in self.closed_form_restarts_:",
        "        elif False:",
        (
            "tests/test_selection.py::"
            "test_issm_linear_model_keeps_its_start_where_training_fits_worse",
        ),
    ),
    Mutation(
        "ensemble of means",
        "sysid_nn/_estimators/_ensemble.py",
        "return np.nanmedian(stacked, axis=0)",
        "return np.nanmean(stacked, axis=0)",
        (
            "tests/test_ensemble.py::"
            "test_runs_are_the_pointwise_median_of_the_finite_members",
        ),
    ),
    Mutation(
        "ensemble members with diverged runs counted",
        "sysid_nn/_estimators/_ensemble.py",
        "    stacked[~np.isfinite(stacked)] = np.nan\n",
        "",
        (
            "tests/test_ensemble.py::"
            "test_runs_are_the_pointwise_median_of_the_finite_members",
        ),
    ),
    Mutation(
        "ensemble members on one held-out share",
        "sysid_nn/_estimators/_ensemble.py",
        '                params["validation_fraction"] = share\n',
        "                pass\n",
        (
            "tests/test_ensemble.py::"
            "test_members_are_the_fits_of_their_seeds_and_held_out_shares",
        ),
    ),
    Mutation(
        "distil: the network not trained on the records themselves",
        "sysid_nn/_estimators/_ensemble.py",
        "given + train, given_y + train_y, X_val=val",
        "train, train_y, X_val=val",
        (
            "tests/test_ensemble.py::"
            "test_the_distilled_network_is_fitted_to_the_median_on_records_like_its_records",
        ),
    ),
    Mutation(
        "distil: no draws like the records",
        "sysid_nn/_estimators/_ensemble.py",
        "[x for d in draws[:_DISTIL_TRAINING_DRAWS] for x in d]",
        "[x for d in draws[:0] for x in d]",
        (
            "tests/test_ensemble.py::"
            "test_the_distilled_network_is_fitted_to_the_median_on_records_like_its_records",
        ),
    ),
    Mutation(
        "distil: validated on the draws it was trained on",
        "sysid_nn/_estimators/_ensemble.py",
        "[x for d in draws[_DISTIL_TRAINING_DRAWS:] for x in d]",
        "[x for d in draws[:_DISTIL_VALIDATION_DRAWS] for x in d]",
        (
            "tests/test_ensemble.py::"
            "test_the_distilled_network_is_fitted_to_the_median_on_records_like_its_records",
        ),
    ),
    Mutation(
        "distil: the network's seed a member's",
        "sysid_nn/_estimators/_ensemble.py",
        "attempts = rng.randint(np.iinfo(np.int32).max, size=_NETWORK_ATTEMPTS)",
        "attempts = seeds[:_NETWORK_ATTEMPTS]",
        (
            "tests/test_ensemble.py::"
            "test_the_distilled_network_is_fitted_to_the_median_on_records_like_its_records",
        ),
    ),
    Mutation(
        "distil: the draws of the validation records too",
        "sysid_nn/_estimators/_ensemble.py",
        "[like_record(x, rng) for x in records]",
        "[like_record(x, rng) for x in records + _as_records(X_val)]",
        (
            "tests/test_ensemble.py::"
            "test_the_distilled_network_learns_the_validation_records_too",
        ),
    ),
    Mutation(
        "distil: members parting off the records not warned of",
        "sysid_nn/_estimators/_ensemble.py",
        "if self.draw_disagreement_ > _DISAGREEMENT_WARNING:",
        "if self.draw_disagreement_ > 10 * _DISAGREEMENT_WARNING:",
        (
            "tests/test_ensemble.py::"
            "test_members_that_part_off_the_records_are_warned_of",
        ),
    ),
    Mutation(
        "distil: disagreement on the draws alone",
        "sysid_nn/_estimators/_ensemble.py",
        "_distance(given_runs, given_y), _ROUNDING_ERROR",
        "0.1, _ROUNDING_ERROR",
        (
            "tests/test_ensemble.py::"
            "test_the_distilled_network_is_fitted_to_the_median_on_records_like_its_records",
        ),
    ),
    Mutation(
        "distil: one attempt whatever the network fits",
        "sysid_nn/_estimators/_ensemble.py",
        "            if _within(errors[-1], level, self.max_error_ratio):\n",
        "            if True:\n",
        (
            "tests/test_ensemble.py::"
            "test_a_network_that_misses_the_records_is_fitted_again_on_another_seed",
        ),
    ),
    Mutation(
        "distil: the last attempt kept",
        "sysid_nn/_estimators/_ensemble.py",
        "best = int(np.argmin(self.network_record_errors_))",
        "best = len(errors) - 1",
        (
            "tests/test_ensemble.py::"
            "test_a_network_that_misses_the_records_is_fitted_again_on_another_seed",
        ),
    ),
    Mutation(
        "distil: an earlier fit's network kept",
        "sysid_nn/_estimators/_ensemble.py",
        "            self.__dict__.pop(name, None)\n",
        "            pass\n",
        (
            "tests/test_ensemble.py::"
            "test_a_fit_without_distil_keeps_no_network_of_an_earlier_fit",
        ),
    ),
    Mutation(
        "distil: the median read as one network",
        "sysid_nn/_estimators/_ensemble.py",
        '    network = getattr(model, "network_", None)\n',
        '    network = getattr(model, "network_", model)\n',
        (
            "tests/test_ensemble.py::"
            "test_a_fit_without_distil_keeps_no_network_of_an_earlier_fit",
        ),
    ),
    Mutation(
        "distil: the report's structure of the median",
        "sysid_nn/study/_structure.py",
        "    if network is not estimator:\n",
        "    if False:\n",
        (
            "tests/test_ensemble.py::"
            "test_the_report_reads_the_structure_of_the_network_fitted_to_the_median",
        ),
    ),
    Mutation(
        "distil: the modes of the median",
        "sysid_nn/cli/_modal.py",
        "    modes = modal_parameters(network, dt, level=args.level)\n",
        "    modes = modal_parameters(model.estimator, dt, level=args.level)\n",
        (
            "tests/test_cli_modal.py::"
            "test_modal_of_a_distilled_ensemble_reads_its_network",
        ),
    ),
    Mutation(
        "distil: validate silent on the network",
        "sysid_nn/cli/_validate.py",
        "        if network is not None:  # saved by `fit --members N --distil`\n",
        "        if False:\n",
        (
            "tests/test_cli_modal.py::"
            "test_modal_of_a_distilled_ensemble_reads_its_network",
        ),
    ),
    Mutation(
        "distil: the command's --distil without members",
        "sysid_nn/cli/_fit.py",
        "        if distil:\n",
        "        if False:\n",
        ("tests/test_cli.py::test_fit_distil_needs_members",),
    ),
    Mutation(
        "readouts: an ensemble taken for a network",
        "sysid_nn/_analysis/_modal.py",
        "        raise not_a_network(estimator)\n",
        "        pass\n",
        (
            "tests/test_ensemble.py::"
            "test_readouts_of_an_ensemble_name_the_network_to_pass",
        ),
    ),
    Mutation(
        "ensemble median over every member",
        "sysid_nn/_estimators/_ensemble.py",
        "zip(self.estimators_, used, strict=True) if u]",
        "zip(self.estimators_, used, strict=True)]",
        (
            "tests/test_ensemble.py::"
            "test_members_that_miss_the_fitted_records_are_left_out_of_the_median",
        ),
    ),
    Mutation(
        "ensemble members judged on the training records alone",
        "sysid_nn/_estimators/_ensemble.py",
        "        records = [(X, y)] if X_val is None else [(X, y), (X_val, y_val)]\n",
        "        records = [(X, y)]\n",
        (
            "tests/test_ensemble.py::"
            "test_member_record_errors_are_free_runs_over_every_fitted_record",
        ),
    ),
    Mutation(
        "ensemble members kept by the worst error",
        "sysid_nn/_estimators/_ensemble.py",
        '    level = np.quantile(errors, 0.25, method="lower")\n',
        "    level = errors.max()\n",
        (
            "tests/test_ensemble.py::"
            "test_members_that_miss_the_fitted_records_are_left_out_of_the_median",
        ),
    ),
    Mutation(
        "ensemble members judged against the best one",
        "sysid_nn/_estimators/_ensemble.py",
        '    level = np.quantile(errors, 0.25, method="lower")\n',
        "    level = errors.min()\n",
        ("sysid_nn/_estimators/_ensemble.py::sysid_nn._estimators._ensemble._used",),
    ),
    Mutation(
        "ensemble members parted by rounding",
        "sysid_nn/_estimators/_ensemble.py",
        "    return bool(error <= ratio * max(level, _ROUNDING_ERROR))\n",
        "    return bool(error <= ratio * level)\n",
        ("sysid_nn/_estimators/_ensemble.py::sysid_nn._estimators._ensemble._used",),
    ),
    Mutation(
        "linear model trained on validation judged from rest",
        "sysid_nn/_engine/_selection.py",
        "        (lin._fit_one(train, judged, new_restart(k), n_stages)[1], k)",
        "        (lin._fit_one(train, val, new_restart(k), n_stages)[1], k)",
        (
            "tests/test_policy.py::"
            "test_linear_candidate_trains_validated_as_the_networks_will_be",
        ),
    ),
    Mutation(
        "fit --members ignores --seed",
        "sysid_nn/cli/_fit.py",
        "        estimator, n_members=members, distil=distil, random_state=seed\n",
        "        estimator, n_members=members, distil=distil\n",
        ("tests/test_cli.py::test_fit_members_saves_the_median_of_their_fits",),
    ),
    Mutation(
        "halving keeps the worse half",
        "sysid_nn/_engine/_schedule.py",
        "    return sorted(int(k) for k in ranked[: -(-len(ranked) // 2)])",
        "    return sorted(int(k) for k in ranked[len(ranked) // 2 :])",
        (
            "tests/test_schedule.py::test_halving_keeps_the_restart_selected_by_validation",
        ),
    ),
    Mutation(
        "old files without a new parameter",
        "sysid_nn/_saved.py",
        "                    setattr(estimator, name, parameter.default)\n",
        "                    pass\n",
        (
            "tests/test_saved.py::"
            "test_a_file_written_before_a_parameter_existed_loads_with_its_default",
        ),
    ),
    Mutation(
        "refit without the margin",
        "sysid_nn/_engine/_refit.py",
        "        if advantage > _SIGNIFICANT:\n",
        "        if advantage > -np.inf:\n",
        (
            "tests/test_refit.py::"
            "test_refit_keeps_the_chosen_weights_unless_a_step_is_clearly_ahead",
        ),
    ),
    Mutation(
        "refit steps one too many",
        "sysid_nn/_engine/_refit.py",
        "            steps = best\n",
        "            steps = best + 1\n",
        (
            "tests/test_refit.py::"
            "test_refit_continues_on_every_record_for_the_steps_the_inner_"
            "validation_chose",
        ),
    ),
    Mutation(
        "refit reports the steps it asked for",
        "sysid_nn/_engine/_refit.py",
        "        steps = taken[0]  # fewer where the stage converged before them\n",
        "",
        (
            "tests/test_refit.py::"
            "test_refit_reports_the_steps_taken_where_the_stage_ends_before_them",
        ),
    ),
    Mutation(
        "refit continued on the inner records",
        "sysid_nn/_engine/_refit.py",
        "        out = _continue(est, whole, w, count)\n",
        "        out = _continue(est, inner, w, count)\n",
        (
            "tests/test_refit.py::"
            "test_refit_continues_on_every_record_for_the_steps_the_inner_"
            "validation_chose",
        ),
    ),
    Mutation(
        "refit keeps a diverged continuation",
        "sysid_nn/_engine/_refit.py",
        "        if not (np.isfinite(loss) and ratio <= _LINEAR_FIT_MARGIN):\n",
        "        if ratio > _LINEAR_FIT_MARGIN:\n",
        (
            "tests/test_refit.py::"
            "test_a_continuation_that_diverges_on_the_validation_records_is_not_kept",
        ),
    ),
    Mutation(
        "refit ignores the training records",
        "sysid_nn/_engine/_refit.py",
        "        if not (np.isfinite(loss) and ratio <= _LINEAR_FIT_MARGIN):\n",
        "        if not np.isfinite(loss):\n",
        (
            "tests/test_refit.py::"
            "test_refit_keeps_the_chosen_weights_where_the_training_records_fit_worse",
        ),
    ),
    Mutation(
        "refit judges the whole tail",
        "sysid_nn/_estimators/_base.py",
        "            lead = len(Xs[-1]) + half\n",
        "            lead = len(Xs[-1])\n",
        (
            "tests/test_refit.py::"
            "test_refit_judges_the_second_half_of_the_held_out_tail",
        ),
    ),
    Mutation(
        "refit judges validation records from their start",
        "sysid_nn/_estimators/_base.py",
        "                lead=half,\n",
        "                lead=0,\n",
        (
            "tests/test_refit.py::"
            "test_refit_judges_validation_records_after_half_the_shortest",
        ),
    ),
    Mutation(
        "refit halves too short",
        "sysid_nn/_estimators/_base.py",
        "        if half < self._min_samples():\n",
        "        if half < 1:\n",
        (
            "tests/test_refit.py::"
            "test_refit_needs_validation_records_long_enough_to_halve",
        ),
    ),
)


def _copy_checkout(dest: Path) -> None:
    files = subprocess.run(
        ["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"],
        cwd=ROOT,
        capture_output=True,
        check=True,
    ).stdout.split(b"\0")
    for name in filter(None, files):
        src = ROOT / os.fsdecode(name)
        if src.is_file():
            target = dest / os.fsdecode(name)
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, target)


def _run_tests(tree: Path, tests: tuple[str, ...]) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(tree)}
    return subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-x", "-p", "no:cacheprovider", *tests],
        cwd=tree,
        env=env,
        capture_output=True,
        text=True,
    )


def main(argv: list[str]) -> int:
    wanted = [m for m in MUTATIONS if not argv or m.name.split()[0] in argv]
    if not wanted:
        names = ", ".join(m.name for m in MUTATIONS)
        print(f"no mutation named {argv}; the mutations are: {names}")
        return 2
    failed = 0
    with tempfile.TemporaryDirectory() as tmp:
        tree = Path(tmp)
        _copy_checkout(tree)
        # The tests pass on the unmutated code, or the results mean nothing.
        baseline = _run_tests(tree, tuple({t for m in wanted for t in m.tests}))
        if baseline.returncode != 0:
            print("the tests fail on the unmutated code:\n" + baseline.stdout)
            return 1
        for m in wanted:
            path = tree / m.path
            text = path.read_text()
            if text.count(m.original) != 1:
                print(f"STALE     {m.name}: {m.original!r} not once in {m.path}")
                failed += 1
                continue
            path.write_text(text.replace(m.original, m.broken))
            start = time.perf_counter()
            try:
                result = _run_tests(tree, m.tests)
            finally:
                path.write_text(text)
            verdict = "KILLED" if result.returncode != 0 else "SURVIVED"
            failed += verdict == "SURVIVED"
            elapsed = time.perf_counter() - start
            print(f"{verdict:9} {m.name} ({m.path}, {elapsed:.0f} s)", flush=True)
            # What caught it: an assertion, not an import error.
            errors = [ln for ln in result.stdout.splitlines() if ln.startswith("E ")]
            if errors:
                print(f"          {errors[0][:100]}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
