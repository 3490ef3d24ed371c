"""Identification of non-linear dynamic structures with recurrent neural networks.

The toolbox implements the tapped-delay-line (TDL) and innovation state-space
(ISSM) recurrent networks of Kirkegaard, Nielsen & Hansen (1995) as
scikit-learn regressors, a Bouc-Wen hysteretic oscillator to generate data,
and the residual tests used to validate the identified models.

Public modules: :mod:`sysid_nn.excitation`, :mod:`sysid_nn.oscillator`,
:mod:`sysid_nn.building` (multi-storey shear buildings),
:mod:`sysid_nn.residuals`, :mod:`sysid_nn.metrics`, :mod:`sysid_nn.plotting`,
:mod:`sysid_nn.study`, :mod:`sysid_nn.datasets` (the field's measured
benchmarks) and :mod:`sysid_nn.uncertainty` (confidence and prediction bands).
"""

from __future__ import annotations

import importlib

from sysid_nn import _moved

__version__ = "0.1.0.dev0"

# Models pickled before the private modules moved into groups still load.
_moved.install()

# Names are resolved on first access so that ``import sysid_nn`` stays light
# (no numba compilation, no matplotlib) until a class is actually used.
_LAZY = {
    "HystereticOscillator": "sysid_nn.oscillator",
    "ShearBuilding": "sysid_nn.building",
    "TDLRegressor": "sysid_nn._estimators._tdl",
    "ISSMRegressor": "sysid_nn._estimators._issm",
    "DivergenceWarning": "sysid_nn._exceptions",
    "EnsembleRegressor": "sysid_nn._estimators._ensemble",
    "InconsistentVersionWarning": "sysid_nn._exceptions",
    "UnstablePredictorWarning": "sysid_nn._estimators._issm",
    "load_model": "sysid_nn._saved",
    "save_model": "sysid_nn._saved",
    "export_onnx": "sysid_nn._export",
    "to_dlti": "sysid_nn._export",
    "backbone": "sysid_nn._analysis._backbone",
    "frequency_response": "sysid_nn._analysis._frf",
    "instantaneous_frequency": "sysid_nn._analysis._modal",
    "modal_parameters": "sysid_nn._analysis._modal",
    "nonlinearity_test": "sysid_nn._analysis._nonlinearity",
}

__all__ = [
    "DivergenceWarning",
    "EnsembleRegressor",
    "HystereticOscillator",
    "ISSMRegressor",
    "InconsistentVersionWarning",
    "ShearBuilding",
    "TDLRegressor",
    "UnstablePredictorWarning",
    "backbone",
    "export_onnx",
    "frequency_response",
    "instantaneous_frequency",
    "load_model",
    "modal_parameters",
    "nonlinearity_test",
    "save_model",
    "to_dlti",
]


def __getattr__(name: str):
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'sysid_nn' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted([*globals(), *__all__])
