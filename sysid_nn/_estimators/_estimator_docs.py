"""Docstring sections the recurrent-network estimators share, written once.

:data:`document_estimator` fills them in as ``%(name)s`` (see
:func:`sysid_nn._docstrings.fill_doc`).
"""

from __future__ import annotations

from sysid_nn._docstrings import fill_doc

#: Parameter descriptions shared by the estimators' docstrings.
_TRAINING_PARAMETERS_DOC = """\
solver : {"lm", "lbfgs", "slsqp"}, default="lm"
    ``"lm"``: Levenberg-Marquardt on the exact recurrent Jacobian
    (forward sensitivities), with Marquardt's scale-invariant damping;
    ``"lbfgs"``: L-BFGS-B with the adjoint (backpropagation-through-time)
    gradient; ``"slsqp"``: sequential quadratic programming as in the
    paper, with the adjoint gradient.
max_iter : int, default=150
    Iterations of the last training stage; the one-step and each shooting
    stage get 2/3 and 4/15 of it, the refinement of the linear model
    (``refined_restart_``) five times it.
tol : float, default=1e-8
    Relative tolerance of the solver: a stage ends when the loss changes
    by less than ``tol`` times its value (or the gradient or step become
    that small).
n_init : int, default=4
    Random restarts; the one with the best validation (or training) loss
    is kept. All run the first three stages, the better half the rest
    (successive halving; see the user guide's training page).
early_stopping : bool, default=True
    Keep, over all accepted steps of all stages, the weights with the best
    validation loss (free run for the simulation focus, one step for the
    prediction focus) and stop the last stage after ``n_iter_no_change``
    steps without improvement.
validation_fraction : float, default=0.2
    Share of the sequences held out when ``early_stopping`` is on and no
    ``X_val`` is given; with one or two sequences, the share of the last
    one's tail, held out as a validation record of its own (judged as one
    passed as ``X_val``).
n_iter_no_change : int, default=10
    Patience of early stopping, in accepted steps.
refit : bool, default=False
    After the restarts are chosen, continue the last stage from the chosen
    weights on the training and validation records together, for the
    number of steps an inner validation chose: the same continuation on
    the training records and the first half of every validation record,
    judged on the second halves; kept where its best step beat the chosen
    weights there by more than two standard errors and the continued
    weights fit the training records no worse than twice the chosen ones
    (``refit_steps_``).
random_state : int, RandomState instance or None, default=None
    Seeds the restarts' initial weights.
verbose : bool, default=False
    Print progress per stage, and within a stage that runs long a line at
    most every 30 s with the accepted steps so far.
n_jobs : int, default=None
    Parallel jobs for the restarts (joblib semantics)."""


#: Entries of the prediction methods' docstrings, shared by all of them.
_EXCITATION_DOC = """\
X : array-like of shape (n_samples, n_inputs) or list of such
    Excitation."""
#: The Parameters and Returns of ``score`` (the free run's R^2).
_SCORE_DOC = f"""\
Parameters
----------
{_EXCITATION_DOC}
y : array-like of shape (n_samples,) or (n_samples, n_outputs), or list
    Measured response.
sample_weight : array-like of shape (n_samples,), default=None
    Sample weights (one array only).

Returns
-------
score : float
    R^2 averaged uniformly over outputs; ``-inf`` where the free run is
    not finite."""
_SIMULATION_STD_DOC = """\
return_std : bool, default=False
    Also return the standard deviation of every sample (delta
    method, see :ref:`uncertainty`).
interval : {"prediction", "confidence"}, default="prediction"
    What the standard deviation is of (only used with
    ``return_std``): ``"prediction"``, a new measurement (weight
    uncertainty plus ``noise_variance_``); ``"confidence"``, the
    model output (weight uncertainty only).

Returns
-------
y_sim : ndarray or list of ndarray
    Simulated response; NaN from a sample where the run diverged (a
    :class:`~sysid_nn.DivergenceWarning` says where).
y_std : ndarray or list of ndarray
    Standard deviation of each value of ``y_sim``, same shape; only
    with ``return_std=True``."""

#: Fitted attributes the estimators share: those of the restarts' selection
#: and those of the residual variances.
_SELECTION_ATTRIBUTES_DOC = """\
best_validation_score_ : float or None
    Negative validation mean squared error (standardised) of the chosen
    weights.
restart_scores_ : ndarray
    Negative selection loss of every restart (of a restart dropped by the
    successive halving, at the point it stopped).
restart_losses_ : ndarray
    Each restart's training loss (the final objective, standardised) at the
    weights its score is of: with validation records a restart is a
    candidate only where this is no worse than ``linear_loss_``.
restart_bounded_ : ndarray of bool
    Whether each restart's free run stays bounded when the training
    excitation is scaled to twice its amplitude about its mean (within five
    times the training outputs' largest standardised value), stays within
    twice the larger of that value and the linear model's reach under two
    excitations like the training records' (their Fourier phases drawn
    anew from a fixed seed, spectrum and range kept), and passes the
    constant-input check (``restart_excursions_`` at most 1), with a
    finite validation score; the others are candidates only where none
    passes. Then those that pass every check some finite restart passes
    (a check that all of them fail tells nothing) come first, and, among
    those and the rest, those that do not self-oscillate
    (``restart_self_oscillating_``).
restart_checks_ : ndarray of bool, shape (n_restarts, 3)
    Which bound checks each restart passed (``restart_bounded_`` is all
    three and a finite validation score): the constant-input check, twice
    the training amplitude, the excitations like the training records'.
restart_excursions_ : ndarray
    Each restart's constant-input check: its free runs from rest under
    constant inputs at the minimum, quartiles and maximum of the training
    excitation, against the linear model's. The larger of two ratios: how
    far a run settles on the side opposite to the linear model's response,
    over ten times the training outputs' largest standardised value; and
    the largest second difference over a run's second half, over ten
    times the larger of the training outputs' largest and the linear
    model's. Runs that diverge or have not settled count 0. Above 1 holds
    the restart out (``restart_bounded_``).
restart_self_oscillating_ : ndarray of bool
    Whether each restart's free run from zero under the training
    excitation's median held constant ends, after 8192 samples, on a
    sustained cycle (as ``rest_check_.cycling`` under zero excitation): the
    band its output covers over the last 2048 samples is the band of the
    2048 before, each edge within a tenth of the band's width (a drift moves
    the band, a decay narrows it). Where no restart passes the bound checks
    (``restart_bounded_``), those that do not self-oscillate are chosen
    from first.
n_restarts_ : int
    Restarts run (the length of ``restart_scores_``).
restart_batches_ : int
    Batches of ``n_init`` restarts run: 2 where no run of the first (the
    refinement included) fitted the training records better than the linear
    model, so that a second batch, on new seeds, ran before the linear model
    could be returned (its restarts follow the refinement in
    ``restart_scores_``).
best_restart_ : int or None
    Index of the chosen restart in ``restart_scores_``; None where the
    linear model was returned (``selected_ == "linear"``).
refined_restart_ : int or None
    Index in ``restart_scores_`` of the restart that refines the trained
    linear model (after the first batch's restarts; None where the linear
    model is no candidate):
    it starts at the linear model with small hidden weights and runs the
    final stage of the schedule only, with five times ``max_iter``.
refinement_advantage_ : float or None
    Where the refinement and a restart that validated better were both
    candidates (each beating the linear model and fitting the training
    records no worse than it), how many standard errors of the difference
    the restart's validation error was lower (the Diebold-Mariano
    statistic, its standard error robust to the free runs'
    autocorrelation): the restart is kept only above 2, else the
    refinement. Infinite where a free run diverged; None where no such
    comparison was made.
refit_steps_ : int or None
    Accepted steps the chosen weights were continued on the training and
    validation records together (``refit``): 0 where the inner validation
    chose none, or none beat the chosen weights by more than two standard
    errors, or the continuation fitted the training records more than
    twice worse (``refit_training_ratio_``), or the validation records were
    too short to halve; None without ``refit`` or validation records.
refit_losses_ : ndarray or None
    The inner validation loss of ``refit`` (standardised mean squared
    error on the second halves of the validation records) at the chosen
    weights and after each accepted step of the continuation on the
    training records and the first halves.
refit_advantage_ : float or None
    Standard errors by which the best step of ``refit_losses_`` beat the
    chosen weights (nan where the best was the chosen weights).
refit_training_ratio_ : float or None
    The free-run loss on the training records of the weights continued on
    all the records over the chosen weights': above 2 (or where the
    continued free run diverged) the chosen weights stay and
    ``refit_steps_`` is 0. Nan where no step was taken on all the records.
closed_form_restarts_ : list of int
    Indices in ``restart_scores_`` of the linear model's closed-form fits,
    judged as they are, untrained (a model without hidden layers; empty
    otherwise): the TDL's least-squares ARX fit to the measured records
    where its start is fitted to low-passed ones (``shooting="free"``), the
    ISSM's subspace and ARX starts.
    Their ``training_history_`` is empty.
best_stage_ : int
    Training stage in which the chosen weights were seen (an index into
    ``training_history_[best_restart_]``; 0 for a closed-form fit).
training_history_ : list of list
    For each restart, one record per training stage it ran: ``segment``
    (length in samples; very large for the free run), ``n_iter``,
    ``loss`` (the stage objective before its first step and after each
    accepted one, standardised, penalty included), ``validation`` (the
    validation loss at the same points, empty without validation data)
    and ``skipped`` (the stage did not run: its starting loss was not
    finite).
loss_curve_ : list of float
    The chosen restart's ``loss`` values over all its stages, in order
    (as ``MLPRegressor.loss_curve_``; stage objectives differ from stage to
    stage).
validation_scores_ : list of float or None
    The chosen restart's negative validation losses at the same points;
    ``best_validation_score_`` is their maximum.
skipped_stages_ : list of int
    Stages of the chosen restart skipped because their starting loss was
    not finite (a :class:`~sklearn.exceptions.ConvergenceWarning` says so).
fallback_ : {None, "linear_start", "none"}
    ``"linear_start"`` when every restart's free run diverged on the
    validation (or training) records and the linear starting model was
    returned; ``"none"`` when that diverged too and the chosen restart's
    weights were kept; both warn :class:`~sysid_nn.DivergenceWarning`.
selected_ : {"restart", "linear"}
    What ``fit`` returned: the best restart, or the linear model (the
    network without hidden layers, trained by the same schedule; the
    network computes it with its output layer silent) when no restart
    whose free run stays bounded at twice the training amplitude (and,
    with validation records, fits the training records no worse than the
    linear model) beat it, with a warning. A model without hidden layers
    is its restarts' best.
validation_burn_in_ : int or None
    Leading samples of every validation record (passed as ``X_val`` or
    held out) simulated from rest left out of the validation score (the
    burn-in, or the window below); 0 for records that start at rest; None
    without validation records.
validation_start_window_ : int or None
    Where a validation record's initial state is not forgotten within
    half of it (an integrating plant) and fitting it to the record's first
    samples (as ``y_init`` does) at least halves the linear model's
    validation error, the number of those samples, fitted before each
    validation run; 0 otherwise, None without validation records.
validation_continues_record_ : bool or None
    Whether the held-out tail of a single record was judged as the
    continuation of the free run over the whole record, rather than from
    rest at its own start: done where the linear model's response to a
    wrong start outlasts the tail (more than 30 % of it left over the
    tail's last fifth), as for a lightly damped structure, and the record
    starts at rest (the run from rest) or the model is a TDL network (the
    run from the record's first measured outputs, its whole initial
    state); None without validation records.
rest_output_ : ndarray of shape (n_outputs,) or None
    The output at the model's rest, where its free run settles under zero
    excitation (after 8192 samples of it, from the zero state or, for a
    model with another rest its training record leads to, from there; see
    ``rest_check_``; user units): free runs without initial conditions
    start there. None where the model does not settle
    (an integrating or self-oscillating one) or settles outside the range
    of the training outputs; free runs then start from zero, or, for a
    model on a sustained cycle within that range, after the run-in, on its
    cycle (``rest_check_.start == "cycle"``).
rest_check_ : Bunch
    The evidence behind ``rest_output_`` (user units): ``start`` (``"rest"``,
    ``"cycle"`` or ``"zero"``), ``reason`` (one sentence: settled within or
    outside the training outputs' range, on a sustained cycle within it,
    still moving, or diverged), ``cycling`` (on a sustained cycle, within
    that range or beyond it: the model self-oscillates), ``end`` (the output
    after the run-in), ``change`` (its largest change over the run-in's last
    2048 samples) against ``tolerance``, ``training_range`` (lowest and
    highest training output), ``run_in`` (the run-in's length),
    ``run_in_from`` (``"zero"``: the run-in starts from the zero state;
    ``"training"``: where the free run over the longest training record
    ends, because the run-in from there found another rest than the zero
    state's and the free run over that record fits it better started
    there, or because only it found a rest or a cycle), and the evidence:
    ``training_start`` (what the run-in from the training record's end
    found: ``"rest"``, ``"cycle"``, ``"zero"``, or None where that free run
    diverged), ``training_end_output`` (the output at the end of that
    run-in) and ``record_losses`` (the mean squared standardised misfit of
    the free run over that record from each start, zero state's first,
    where two rests were compared; else None).
linear_score_ : float or None
    Negative selection loss of that linear model; None where it is not a
    candidate (no hidden layer, no linear part, or the ISSM's TDL start).
linear_loss_ : float or None
    That linear model's training loss (as ``restart_losses_``); None where
    it is not a candidate. ``selected_``, ``best_restart_`` follow from
    these attributes and ``restart_scores_`` (the user guide's training
    page, "Selection rule").
fit_time_ : float
    Seconds spent in training.
layer_coefs_ : list of ndarray
    Weight matrix of each layer, shape ``(n_in, n_out)``, read from
    ``coefs_`` (as ``MLPRegressor.coefs_``).
layer_intercepts_ : list of ndarray
    Bias vector of each layer, read from ``coefs_``.
linear_coef_ : ndarray of shape (n_outputs, n_in) or None
    The linear part beside the network, read from ``coefs_``.
output_noise_std_ : ndarray of shape (n_outputs,)
    The misfit of a linear one-step model (three output and input lags)
    on the training records, in the user's units, corrected for the
    model's own filtering of it: an estimate of white output noise, and an
    upper one (what the lags do not explain counts too).
one_step_misfit_share_ : ndarray of shape (n_outputs,)
    That misfit as a share of the spread of the outputs' second
    difference. Above 0.02 it is broadband, and the ``"auto"`` settings
    react to it (see the user guide's training page).
one_step_misfit_correlation_ : ndarray of shape (n_outputs,)
    Lag-1 autocorrelation of the misfit: small or negative for white noise,
    near one for dynamics the lags do not resolve.
one_step_misfit_explained_ : ndarray of shape (n_outputs,)
    Share of the misfit that squares and cubes of the regressors explain:
    large for a non-linearity's misfit, small for noise.
white_misfit_ : bool
    Whether some output's misfit is broadband, white, not explained by the
    regressors and below 10 % of the output's spread: white measurement
    noise, or excitation between the samples the records do not carry
    (decimation without an anti-aliasing filter). Only then does ``fit``
    warn about the misfit.
samples_per_period_ : float
    Samples per dominant period of the training outputs (NaN when it
    cannot be told).
band_edge_ : float
    Highest frequency (cycles per sample) where the outputs clear the
    misfit; 0.5 when the misfit is not broadband.
bands_unavailable_ : str or None
    Why the model has no confidence and prediction bands (its final free
    run diverged on the training records), or None; warned about."""
_VARIANCE_ATTRIBUTES_DOC = """\
n_effective_params_ : float
    Effective number of weights the data determine (the trace of the
    hat matrix), used to correct the residual variances.
noise_variance_ : ndarray of shape (n_outputs,)
    Residual variance of the free run on the training records (user's
    units), corrected for ``n_effective_params_``.
one_step_noise_variance_ : ndarray of shape (n_outputs,)
    The same for the one-step predictor.
feature_names_in_ : ndarray
    Column names of ``X`` when it was a DataFrame."""

#: Fills the estimators' shared docstring sections: ``%(training_parameters)s``,
#: ``%(selection_attributes)s`` and ``%(variance_attributes)s`` in the class
#: docstring, ``%(excitation)s`` and ``%(simulation_std)s`` (the
#: ``return_std``/``interval`` entries and the Returns of ``simulate``) in
#: the methods', ``%(score)s`` in ``score``'s.
document_estimator = fill_doc(
    training_parameters=_TRAINING_PARAMETERS_DOC,
    excitation=_EXCITATION_DOC,
    score=_SCORE_DOC,
    simulation_std=_SIMULATION_STD_DOC,
    selection_attributes=_SELECTION_ATTRIBUTES_DOC,
    variance_attributes=_VARIANCE_ATTRIBUTES_DOC,
)
