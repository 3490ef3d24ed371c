"""The fitting engine, below the estimators and never importing them.

- model structure: ``_layout`` (the MLP's weight vector), ``_issm_start``,
  ``_subspace``, ``_innovation`` (the ISSM's linear starts and predictor
  gain);
- the training schedule and its objectives: ``_schedule``, ``_solvers``,
  ``_shooting``;
- the training driver and its decisions: ``_training``, ``_selection``,
  ``_order`` (lags and order), ``_diagnosis`` (records read before training);
- the state estimators: ``_state_estimation`` (rest, initial states, noise);
- ``_progress``: progress lines.
"""
