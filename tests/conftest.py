"""Small fitted models shared by the tests of saving and export, a lightly
damped chain's transfer function, and a spy on the linear candidates."""

import warnings

import numpy as np
import pytest
from scipy.signal import cont2discrete, lfilter


def _record(n_outputs: int, seed: int = 0):
    """A mildly non-linear record: ``n_outputs`` outputs of two inputs."""
    rng = np.random.default_rng(seed)
    u = rng.standard_normal((300, 2))
    y1 = lfilter([0.0, 0.5], [1.0, -1.5, 0.7], u[:, 0])
    y1 += 0.3 * np.tanh(y1)
    y2 = lfilter([0.0, 0.3], [1.0, -0.5], u[:, 1]) + 0.2 * y1
    y = np.column_stack([y1, y2])[:, :n_outputs]
    return u, y[:, 0] if n_outputs == 1 else y


def _estimator(kind: str):
    from sysid_nn import ISSMRegressor, TDLRegressor

    small = {"n_init": 1, "max_iter": 5, "random_state": 0}
    if kind == "linear":
        return TDLRegressor(hidden_layer_sizes=(), **small)
    if kind == "tdl":
        return TDLRegressor(hidden_layer_sizes=(3,), **small)
    return ISSMRegressor(hidden_layer_sizes=(3,), **small)


@pytest.fixture(scope="session")
def fitted_models():
    """``{(kind, n_outputs): (estimator, X, y)}`` for the linear model, the
    TDL and the ISSM with one and two outputs (fitted once per session)."""
    models = {}
    for kind in ("linear", "tdl", "issm"):
        for n_outputs in (1, 2):
            X, y = _record(n_outputs)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # few iterations: not converged
                est = _estimator(kind).fit(X, y)
            models[kind, n_outputs] = (est, X, y)
    return models


def _modal_chain(freqs, zeta: float):
    """``(b, a)`` of a sum of second-order modes (natural frequencies in
    cycles per sample, damping ratio ``zeta``), sampled with a hold."""
    b, a = np.zeros(1), np.ones(1)
    for j, f in enumerate(freqs):
        w = 2 * np.pi * f
        num, den = [0.0, 0.0, (-1.0) ** j * w**2 / (j + 1)], [1.0, 2 * zeta * w, w**2]
        bd, ad, _ = cont2discrete((num, den), 1.0, method="zoh")
        b = np.polyadd(np.polymul(b, ad), np.polymul(np.ravel(bd), a))
        a = np.polymul(a, ad)
    return b, a


@pytest.fixture(scope="session")
def modal_chain():
    """The function ``(freqs, zeta) -> (b, a)`` of a lightly damped chain's
    transfer function (a sum of second-order modes)."""
    return _modal_chain


@pytest.fixture
def linear_candidates(monkeypatch):
    """The linear models the training driver judges networks against, in
    the order it made them (``linear_candidate`` spied on)."""
    from sysid_nn._engine import _selection

    seen = []
    candidate = _selection.linear_candidate

    def spy(*args, **kwargs):
        seen.append(candidate(*args, **kwargs))
        return seen[-1]

    monkeypatch.setattr(_selection, "linear_candidate", spy)
    return seen
