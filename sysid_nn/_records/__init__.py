"""The records coming in: one rule for arrays and lists of sequences, the
checks of records and arguments, standardisation and stacking (``_data``,
``_record_checks``, ``_validation``). Imports nothing of the engine's."""
