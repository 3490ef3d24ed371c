"""Models outside sysid_nn: ONNX graphs and linear state-space systems.

Both networks are written here as one state-space step map in standardised
units,

.. math::

    z = M_{zs} s + M_{zu} u, \\quad o = G(z), \\quad
    \\hat y = C_o o, \\quad s^+ = M_{ss} s + M_{su} u + M_{so} o,

with ``G`` the fitted multilayer perceptron (with its bypass) and the
matrices fixed selections: for the TDL the state ``s`` holds the fed-back
outputs (newest first) and the past inputs the delay line still reads, and
``M_{zs}``, ``M_{zu}`` carry the lag transform; for the ISSM ``s`` is the
network's state followed by the inputs the input delay holds back, and the
innovations are zero (the free run). :func:`export_onnx` writes this map as
an ONNX graph, run over time by a ``Scan``; :func:`to_dlti` linearises it.
"""

from __future__ import annotations

import json
import os
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["export_onnx", "to_dlti"]

#: Opset of the exported graphs (onnxruntime 1.14 and later run it).
_OPSET = 17
_IR_VERSION = 8


@dataclass(frozen=True)
class _StepMap:
    """The step map of a fitted estimator (see the module docstring).

    ``layers`` are the perceptron's ``(W, b)``, ``bypass`` its linear bypass
    (or None); ``rest`` the state :meth:`simulate` starts from (standardised),
    ``at_rest`` whether that is the model's rest (else the zero-output start
    of a model without one, or a point of the cycle a self-oscillating model
    settles on).
    """

    Mzs: np.ndarray
    Mzu: np.ndarray
    Mss: np.ndarray
    Msu: np.ndarray
    Mso: np.ndarray
    Co: np.ndarray
    layers: list
    bypass: np.ndarray | None
    activation: str
    x_mean: np.ndarray
    x_scale: np.ndarray
    y_mean: np.ndarray
    y_scale: np.ndarray
    rest: np.ndarray
    at_rest: bool

    def network(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``G(z)`` and its Jacobian ``dG/dz`` (rows of ``z`` are samples)."""
        h, jac = z, np.eye(z.shape[-1])
        for W, b in self.layers[:-1]:
            a = h @ W.T + b
            h = (
                1.0 / (1.0 + np.exp(-a))
                if self.activation == "logistic"
                else np.tanh(a)
            )
            slope = h * (1.0 - h) if self.activation == "logistic" else 1.0 - h * h
            jac = (slope[..., :, None] * W) @ jac
        W, b = self.layers[-1]
        out, jac = h @ W.T + b, W @ jac
        if self.bypass is not None:
            out, jac = out + z @ self.bypass.T, jac + self.bypass
        return out, jac

    def step(self, s: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Next state and output (standardised) from state ``s``, input ``u``."""
        out, _ = self.network(s @ self.Mzs.T + u @ self.Mzu.T)
        return s @ self.Mss.T + u @ self.Msu.T + out @ self.Mso.T, out @ self.Co.T


def _shift(n_blocks: int, width: int) -> np.ndarray:
    """``(n_blocks * width)``-square matrix moving each block one slot back."""
    return np.eye(n_blocks * width, k=-width)


def _tdl_matrices(est, origin) -> tuple:
    """TDL: ``s = [y(t-1) .. y(t-na), u(t-1) .. u(t-L)]``, ``L = nk + nb - 1``."""
    na, nb, nk = est.output_lags_, est.input_lags_, est.input_delay
    p, m = est.n_outputs_, est.n_features_in_
    n_y, L = na * p, nk + nb - 1
    n_s = n_y + L * m
    # phi = [y(t-1) .. y(t-na), u(t-nk) .. u(t-nk-nb+1)] from s and u(t).
    Ps, Pu = np.zeros((n_y + nb * m, n_s)), np.zeros((n_y + nb * m, m))
    Ps[:n_y, :n_y] = np.eye(n_y)
    for i in range(nb):
        lag, rows = nk + i, slice(n_y + i * m, n_y + (i + 1) * m)
        if lag == 0:
            Pu[rows] = np.eye(m)
        else:
            Ps[rows, n_y + (lag - 1) * m : n_y + lag * m] = np.eye(m)
    Mss = np.zeros((n_s, n_s))
    Mss[:n_y, :n_y] = _shift(na, p)
    Mss[n_y:, n_y:] = _shift(L, m)
    Msu, Mso = np.zeros((n_s, m)), np.zeros((n_s, p))
    Msu[n_y : n_y + m] = np.eye(m)[: L * m]
    Mso[:p] = np.eye(p)
    # The history simulate's run-in starts from, newest row first.
    Yh, Uh = _history_rows(est, origin)
    start = np.r_[Yh[::-1][:na].ravel(), Uh[::-1][:L].ravel()]
    return est._S @ Ps, est._S @ Pu, Mss, Msu, Mso, np.eye(p), start


def _history_rows(est, origin) -> tuple[np.ndarray, np.ndarray]:
    """Standardised history rows of a run from ``origin`` (``(initial,
    initial_inputs)``, user units; None: zero)."""
    from sysid_nn._engine._state_estimation import origin_conditions

    initial, past = origin_conditions(origin, 1)
    data = est._stack([np.zeros((0, est.n_features_in_))], None, initial, past)
    return data.Y[: data.h], data.U[: data.h]


def _issm_matrices(est, origin) -> tuple:
    """ISSM: ``s = [x(t-1), u(t-1) .. u(t-nk)]``; ``z = [x, u(t-nk), e = 0]``."""
    n, p, m, nk = est.n_states_, est.n_outputs_, est.n_features_in_, est.input_delay
    n_s, n_z = n + nk * m, n + m + p
    Mzs, Mzu = np.zeros((n_z, n_s)), np.zeros((n_z, m))
    Mzs[:n, :n] = np.eye(n)
    if nk == 0:
        Mzu[n : n + m] = np.eye(m)
    else:
        Mzs[n : n + m, n + (nk - 1) * m : n + nk * m] = np.eye(m)
    Mss = np.zeros((n_s, n_s))
    Mss[n:, n:] = _shift(nk, m)
    Msu, Mso = np.zeros((n_s, m)), np.zeros((n_s, n))
    Msu[n : n + m] = np.eye(m)[: nk * m]
    Mso[:n] = np.eye(n)
    Co = np.eye(p, n)
    Yh, Uh = _history_rows(est, origin)
    unmeasured = np.zeros(n - p) if origin is None else origin[0][p:]
    start = np.r_[Yh[-1], unmeasured, Uh[::-1][:nk].ravel()]
    return Mzs, Mzu, Mss, Msu, Mso, Co, start


def _step_map(est) -> _StepMap:
    """The step map of ``est`` and the state its free run starts from."""
    from sysid_nn._engine._layout import MLPLayout
    from sysid_nn._engine._state_estimation import _RUN_IN
    from sysid_nn._estimators._tdl import TDLRegressor
    from sysid_nn._saved import check_network

    check_network(est)
    build = _tdl_matrices if isinstance(est, TDLRegressor) else _issm_matrices
    kind, origin = est._run_in()
    Mzs, Mzu, Mss, Msu, Mso, Co, start = build(est, origin)
    layout = MLPLayout(est._sizes_, est._bypass())
    layers = [(W.copy(), b.copy()) for W, b in layout.matrices(est.coefs_)]
    bypass = layout.bypass_matrix(est.coefs_)
    step = _StepMap(
        Mzs, Mzu, Mss, Msu, Mso, Co, layers,
        None if bypass is None else bypass.copy(), est.activation,
        est._x_mean, est._x_scale, est._y_mean, est._y_scale, start, False,
    )  # fmt: skip
    # simulate's run-in: zero excitation (in the user's units) brings the
    # model to rest (or onto its cycle) before the first sample; a model
    # without either has none.
    u0 = -est._x_mean / est._x_scale
    s = start
    for _ in range(_RUN_IN if kind != "zero" else 0):
        s, _ = step.step(s, u0)
    return _StepMap(**{**step.__dict__, "rest": s, "at_rest": kind == "rest"})


# -------------------------------------------------------------------- dlti
def to_dlti(estimator: Any, *, dt: float | None = None):
    """The linear model, or a network linearised at rest, as a ``dlti``.

    The state-space system of the estimator's step map (see
    :func:`export_onnx` with ``step=True``) linearised at the rest the free
    run starts from: zero excitation and the state ``simulate`` reaches
    under it. Its input is the excitation in the user's units and its
    output the deviation of the outputs from the rest output
    ``rest_output_``, so that for the linear model
    ``simulate(X) = rest_output_ + dlsim(to_dlti(model), X)``; for a network
    this holds for excitations small enough that the network stays near its
    rest. The state is the model's own (standardised): for the TDL the
    fed-back outputs and the past inputs, for the ISSM its states and the
    inputs the input delay holds back.

    Parameters
    ----------
    estimator : TDLRegressor or ISSMRegressor
        A fitted estimator.
    dt : float, default=None
        Sampling step of the system (s); None leaves it unspecified
        (``dt=True`` in :mod:`scipy.signal`).

    Returns
    -------
    system : scipy.signal.dlti
        State-space system ``(A, B, C, D)`` with ``n_features_in_`` inputs
        and ``n_outputs_`` outputs.

    Warns
    -----
    UserWarning
        The model has no rest (``rest_output_`` is None): it is linearised
        where its free run starts (zero output, or a point of the cycle it
        self-oscillates on), which is not an equilibrium.

    See Also
    --------
    export_onnx : The whole model as an ONNX graph.

    Examples
    --------
    >>> import numpy as np
    >>> from scipy.signal import dlsim, lfilter
    >>> from sysid_nn import TDLRegressor, to_dlti
    >>> rng = np.random.default_rng(0)
    >>> u = rng.standard_normal((300, 1))
    >>> y = lfilter([0.0, 0.5], [1.0, -1.5, 0.7], u[:, 0])
    >>> arx = TDLRegressor(output_lags=2, input_lags=1, hidden_layer_sizes=(),
    ...                    n_init=1, random_state=0).fit(u, y)
    >>> system = to_dlti(arx, dt=0.01)
    >>> _, response, _ = dlsim(system, u)
    >>> bool(np.allclose(arx.rest_output_ + response[:, 0], arx.simulate(u)))
    True
    >>> np.round(np.sort(np.abs(np.linalg.eigvals(system.A)))[-2:], 3)
    array([0.837, 0.837])
    """
    from scipy.signal import dlti

    step = _step_map(estimator)
    if not step.at_rest:
        warnings.warn(
            f"This {type(estimator).__name__} has no rest (rest_output_ is None): "
            "it is linearised where its free run starts (zero output, or a "
            "point of the cycle it self-oscillates on; rest_check_.start), "
            "which is not an equilibrium.",
            UserWarning,
            stacklevel=2,
        )
    u0 = -step.x_mean / step.x_scale
    _, G = step.network(step.rest @ step.Mzs.T + u0 @ step.Mzu.T)
    A = step.Mss + step.Mso @ G @ step.Mzs
    B = (step.Msu + step.Mso @ G @ step.Mzu) / step.x_scale
    C = step.y_scale[:, None] * (step.Co @ G @ step.Mzs)
    D = step.y_scale[:, None] * (step.Co @ G @ step.Mzu) / step.x_scale
    return dlti(A, B, C, D, dt=True if dt is None else dt)


# -------------------------------------------------------------------- ONNX
def _onnx():
    try:
        import onnx
    except ImportError:
        raise ImportError(
            "export_onnx needs the onnx package: pip install 'sysid_nn[onnx]' "
            "(or pip install onnx)."
        ) from None
    return onnx


class _Graph:
    """Nodes and constants of a graph, with unique names."""

    def __init__(self, onnx) -> None:
        self.onnx, self.nodes, self.constants = onnx, [], []

    def constant(self, name: str, value: np.ndarray) -> str:
        value = np.ascontiguousarray(value, dtype=np.float64)
        self.constants.append(self.onnx.numpy_helper.from_array(value, name))
        return name

    def op(self, kind: str, *inputs: str, name: str, **attributes) -> str:
        self.nodes.append(
            self.onnx.helper.make_node(
                kind, list(inputs), [name], name=name, **attributes
            )
        )
        return name


def _step_nodes(graph: _Graph, step: _StepMap, s: str, u: str) -> tuple[str, str]:
    """Nodes of one step from state ``s`` and standardised input ``u`` (1-D
    vectors, or rows of a batch); returns the next state's and the
    standardised output's names. The constants live in ``graph`` (the outer
    graph, which a ``Scan`` body reads)."""
    c = graph.constant

    def affine(pairs, name: str) -> str:
        terms = [
            graph.op("MatMul", v, c(f"{name}_M{k}", M.T), name=f"{name}_{k}")
            for k, (v, M) in enumerate(pairs)
        ]
        total = terms[0]
        for k, term in enumerate(terms[1:]):
            total = graph.op("Add", total, term, name=f"{name}_sum{k}")
        return total

    z = affine([(s, step.Mzs), (u, step.Mzu)], "z")
    h = z
    act = "Sigmoid" if step.activation == "logistic" else "Tanh"
    for k, (W, b) in enumerate(step.layers):
        a = graph.op("MatMul", h, c(f"W{k}", W.T), name=f"layer{k}_matmul")
        a = graph.op("Add", a, c(f"b{k}", b), name=f"layer{k}_add")
        h = a if k == len(step.layers) - 1 else graph.op(act, a, name=f"layer{k}_act")
    out = h
    if step.bypass is not None:
        linear = graph.op("MatMul", z, c("bypass", step.bypass.T), name="bypass_matmul")
        out = graph.op("Add", out, linear, name="network_out")
    y = graph.op("MatMul", out, c("Co", step.Co.T), name="y_std")
    s_next = affine([(s, step.Mss), (u, step.Msu), (out, step.Mso)], "s_next")
    return s_next, y


def _standardise(graph: _Graph, step: _StepMap, u: str) -> str:
    centred = graph.op(
        "Sub", u, graph.constant("x_mean", step.x_mean), name="u_centred"
    )
    return graph.op(
        "Div", centred, graph.constant("x_scale", step.x_scale), name="u_std"
    )


def _to_user_units(graph: _Graph, step: _StepMap, y_std: str, name: str) -> str:
    scaled = graph.op(
        "Mul", y_std, graph.constant("y_scale", step.y_scale), name="y_scaled"
    )
    return graph.op("Add", scaled, graph.constant("y_mean", step.y_mean), name=name)


def export_onnx(estimator: Any, path: str | os.PathLike, *, step: bool = False) -> None:
    """Write a fitted estimator's free run (or its one-step map) as ONNX.

    The graph runs without sysid_nn, in any ONNX runtime (onnxruntime, for
    instance, in Python, C, C++, C#, Java or JavaScript). All arithmetic is
    in float64, the estimator's own precision.

    With ``step=False`` the graph has one input ``u``, of shape
    ``(n_samples, n_features_in_)``, the excitation in the user's units, and
    one output ``y``, of shape ``(n_samples, n_outputs_)``: the free run from
    the model's rest, what ``simulate(u)`` returns (as 2-D), within 1e-6 of
    the output's standard deviation. A ``Scan`` over time carries the state.
    Unlike ``simulate``, a run that diverges is not cut to NaN.

    With ``step=True`` it is the one-step map for users who run their own
    loop: inputs ``state``, of shape ``(n_batch, n_state)``, and ``u``, of
    shape ``(n_batch, n_features_in_)``; outputs ``next_state`` and ``y``, of
    shape ``(n_batch, n_outputs_)``, the output at the sample of ``u``. The
    state is in the model's own standardised coordinates (for the TDL the
    fed-back outputs, newest first, and the past inputs; for the ISSM its
    states and the inputs the input delay holds back); the rest state the
    free run starts from is in the model's metadata, ``rest_state`` (a JSON
    list). Feeding each ``next_state`` back as ``state`` reproduces the free
    run.

    Parameters
    ----------
    estimator : TDLRegressor or ISSMRegressor
        A fitted estimator.
    path : str or path-like
        The ``.onnx`` file to write (replaced if it exists).
    step : bool, default=False
        Write the one-step map instead of the free run.

    Raises
    ------
    ImportError
        The ``onnx`` package is missing (install the ``onnx`` extra:
        ``pip install 'sysid_nn[onnx]'``).

    See Also
    --------
    to_dlti : The linear model, or a network linearised at rest.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> import numpy as np
    >>> import onnxruntime as ort
    >>> from sysid_nn import TDLRegressor, export_onnx
    >>> rng = np.random.default_rng(0)
    >>> u = rng.standard_normal((300, 1))
    >>> y = np.convolve(np.tanh(u[:, 0]), [0.0, 0.5, 0.25])[:300]
    >>> model = TDLRegressor(output_lags=2, input_lags=2, hidden_layer_sizes=(3,),
    ...                      n_init=1, max_iter=20, random_state=0).fit(u, y)
    >>> path = pathlib.Path(tempfile.mkdtemp()) / "model.onnx"
    >>> export_onnx(model, path)
    >>> session = ort.InferenceSession(path, providers=["CPUExecutionProvider"])
    >>> (y_onnx,) = session.run(None, {"u": u})
    >>> y_onnx.shape, bool(np.allclose(y_onnx[:, 0], model.simulate(u)))
    ((300, 1), True)
    """
    onnx = _onnx()
    helper, TensorProto = onnx.helper, onnx.TensorProto
    sm = _step_map(estimator)
    n_s, m, p = sm.Mss.shape[0], sm.Msu.shape[1], sm.Co.shape[0]
    graph = _Graph(onnx)

    def tensor(name: str, *shape) -> Any:
        return helper.make_tensor_value_info(name, TensorProto.DOUBLE, list(shape))

    if step:
        u = _standardise(graph, sm, "u")
        s_next, y_std = _step_nodes(graph, sm, "state", u)
        graph.op("Identity", s_next, name="next_state")
        _to_user_units(graph, sm, y_std, "y")
        inputs = [tensor("state", "n_batch", n_s), tensor("u", "n_batch", m)]
        outputs = [tensor("next_state", "n_batch", n_s), tensor("y", "n_batch", p)]
        nodes, constants = graph.nodes, graph.constants
    else:
        u = _standardise(graph, sm, "u")
        outer_nodes = graph.nodes
        graph.nodes = []
        s_next, y_std = _step_nodes(graph, sm, "s", "u_t")
        body_nodes = [*graph.nodes, helper.make_node("Identity", [s_next], ["s_out"])]
        body_nodes.append(helper.make_node("Identity", [y_std], ["y_t"]))
        body = helper.make_graph(
            body_nodes,
            "step",
            [tensor("s", n_s), tensor("u_t", m)],
            [tensor("s_out", n_s), tensor("y_t", p)],
        )
        graph.nodes = outer_nodes
        graph.constant("rest_state", sm.rest)
        scan = helper.make_node(
            "Scan",
            ["rest_state", u],
            ["final_state", "y_std"],
            name="free_run",
            body=body,
            num_scan_inputs=1,
        )
        graph.nodes.append(scan)
        _to_user_units(graph, sm, "y_std", "y")
        inputs = [tensor("u", "n_samples", m)]
        outputs = [tensor("y", "n_samples", p)]
        nodes, constants = graph.nodes, graph.constants
    name = type(estimator).__name__
    model = helper.make_model(
        helper.make_graph(nodes, name, inputs, outputs, initializer=constants),
        opset_imports=[helper.make_opsetid("", _OPSET)],
        producer_name="sysid_nn",
        ir_version=_IR_VERSION,
    )
    from sysid_nn import __version__

    helper.set_model_props(
        model,
        {
            "estimator": name,
            "sysid_nn_version": __version__,
            "graph": "step" if step else "free_run",
            "rest_state": json.dumps(sm.rest.tolist()),
            "at_rest": json.dumps(sm.at_rest),
        },
    )
    onnx.checker.check_model(model, full_check=True)
    onnx.save_model(model, os.fspath(path))
