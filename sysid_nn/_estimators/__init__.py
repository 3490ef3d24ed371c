"""The estimators: thin scikit-learn shells over the engine.

``_base`` holds the mechanism both networks share (validation, scaling, the
call into the training driver, predict and simulate); ``_tdl`` and ``_issm``
the two structures' hooks; ``_issm_realisation`` the ISSM started from a
trained TDL network; ``_estimator_docs`` the shared docstring sections.
"""
