"""The analyses going out of a fitted model: residual correlation tests
(``_correlation_tests``), the delta-method covariance and its propagation
(``_uncertainty``), and output sensitivities (``_sensitivity``)."""
