"""
A model outside Python's session: model files, ONNX and state space
===================================================================

An identified model is used elsewhere: validated by a colleague, run by a
monitoring system or a controller that knows nothing of sysid_nn. This
example fits a small network to a simulated non-linear system (a damped
resonance followed by a softening static non-linearity), then

* saves it with :func:`~sysid_nn.save_model` to a file that runs no code
  when loaded, and loads it back;
* exports its free run with :func:`~sysid_nn.export_onnx` and runs the
  ONNX graph with onnxruntime alone, the code a user without sysid_nn
  writes;
* exports the one-step map, for a loop of one's own;
* linearises it at rest with :func:`~sysid_nn.to_dlti`, a
  :class:`scipy.signal.dlti` system.

The network is trained with one restart and ``max_iter=40`` so that the
example runs in seconds. The export needs the ``onnx`` extra
(``pip install 'sysid_nn[onnx]'``); running the graph needs only
onnxruntime and numpy.
"""

# %%
# A small network of a non-linear system
# --------------------------------------
import tempfile
import warnings
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from scipy.signal import dlsim, lfilter
from sklearn.exceptions import ConvergenceWarning

from sysid_nn import (
    TDLRegressor,
    export_onnx,
    load_model,
    save_model,
    to_dlti,
)

warnings.filterwarnings("ignore", category=ConvergenceWarning)  # short budget

rng = np.random.default_rng(0)
dt = 0.01
X = [rng.standard_normal((1000, 1)) for _ in range(3)]
y = [np.tanh(lfilter([0.0, 0.2], [1.0, -1.6, 0.8], u[:, 0])) for u in X]
model = TDLRegressor(n_init=1, max_iter=40, random_state=0)
model.fit(X[:1], y[:1], X_val=X[1:2], y_val=y[1:2])
t = dt * np.arange(1000)
folder = Path(tempfile.mkdtemp(prefix="sysid_nn_export_"))

# %%
# A model file that runs no code
# ------------------------------
# The file holds the weights and fitted attributes as JSON and numpy arrays;
# loading builds the estimator back without unpickling anything, and its
# free run is bit-identical. With column names and the sampling step it
# also goes to ``sysid-nn validate --model``.
save_model(
    model, folder / "model.sysid", inputs=["force"], outputs=["displacement"], dt=dt
)
loaded = load_model(folder / "model.sysid")
print("bit-identical:", np.array_equal(loaded.simulate(X[2]), model.simulate(X[2])))

# %%
# The free run in ONNX, run without sysid_nn
# ------------------------------------------
# The graph has one input ``u`` (samples x inputs, float64) and one output
# ``y`` (samples x outputs): the free run from the model's rest, what
# ``simulate`` returns. The code in the second block needs onnxruntime and
# numpy only.
export_onnx(model, folder / "model.onnx")

import onnxruntime as ort  # the user's side starts here

session = ort.InferenceSession(
    str(folder / "model.onnx"), providers=["CPUExecutionProvider"]
)
(y_onnx,) = session.run(None, {"u": X[2]})

y_sim = model.simulate(X[2])
print(
    "largest difference / output std:",
    f"{np.abs(y_onnx[:, 0] - y_sim).max() / y_sim.std():.1e}",
)
fig, ax = plt.subplots(figsize=(7, 3), layout="constrained")
ax.plot(t, y[2], color="0.6", label="measured")
ax.plot(t, y_onnx[:, 0], label="ONNX free run")
ax.set_xlabel("t [s]")
ax.set_ylabel("displacement")
ax.legend()

# %%
# The one-step map, for a loop of one's own
# -----------------------------------------
# With ``step=True`` the graph maps ``(state, u)`` to ``(next_state, y)``,
# rows of a batch. The state the free run starts from is in the model's
# metadata; feeding each ``next_state`` back reproduces the free run.
import json

export_onnx(model, folder / "step.onnx", step=True)
step = ort.InferenceSession(
    str(folder / "step.onnx"), providers=["CPUExecutionProvider"]
)
meta = step.get_modelmeta().custom_metadata_map
state = np.array([json.loads(meta["rest_state"])])
outputs = []
for u_t in X[2][:200]:
    state, y_t = step.run(None, {"state": state, "u": u_t[None, :]})
    outputs.append(y_t[0, 0])
print("loop equals the free run:", np.allclose(outputs, y_onnx[:200, 0]))

# %%
# Linearised at rest
# ------------------
# :func:`~sysid_nn.to_dlti` returns the state-space system of the network
# linearised at its rest: for small excitations the network moves as this
# linear system does. Its poles show the linear dynamics the network has
# learnt about its rest: a pair near the simulated resonance's, of modulus
# ``sqrt(0.8) = 0.894``, beside the poles of the delay line at zero.
system = to_dlti(model, dt=dt)
poles = np.linalg.eigvals(system.A)
print("largest pole moduli:", np.round(np.sort(np.abs(poles))[-2:], 4))
small = 1e-3 * X[2][:500]
_, linear, _ = dlsim(system, small)
deviation = model.simulate(small) - model.rest_output_
print(
    "small-amplitude response, largest difference / its range:",
    f"{np.abs(linear[:, 0] - deviation).max() / np.ptp(deviation):.1e}",
)
