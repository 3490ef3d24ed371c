"""Where each weight of a network sits in its flat parameter vector.

One layout for both networks (the kernels' in :mod:`sysid_nn._kernels._mlp`):
for each layer its weight matrix, row-major ``(n_out, n_in)``, then its
biases; after the last layer the linear bypass ``(sizes[-1], sizes[0])``
(the TDL's bypass, the ISSM's linear part ``[A B K]``) when there is one.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import pairwise

import numpy as np


@dataclass(frozen=True)
class Layer:
    """Slices of one layer's weights and biases in the flat vector."""

    weights: slice
    biases: slice
    n_out: int
    n_in: int


class MLPLayout:
    """The flat-vector layout of a network with layer ``sizes``.

    Examples
    --------
    >>> import numpy as np
    >>> from sysid_nn._engine._layout import MLPLayout
    >>> layout = MLPLayout([3, 4, 2], bypass=True)
    >>> layout.n_params, [layer.weights for layer in layout.layers]
    (32, [slice(0, 12, None), slice(16, 24, None)])
    >>> W, b = layout.matrices(np.arange(32.0))[1]
    >>> W.shape, layout.bypass_matrix(np.arange(32.0)).shape
    ((2, 4), (2, 3))
    """

    def __init__(self, sizes, bypass: bool) -> None:
        self.sizes = tuple(int(s) for s in sizes)
        layers, pos = [], 0
        for n_in, n_out in pairwise(self.sizes):
            end = pos + n_in * n_out
            layers.append(Layer(slice(pos, end), slice(end, end + n_out), n_out, n_in))
            pos = end + n_out
        self.layers = layers
        #: Start of the bypass: the end of the network's own parameters.
        self.network_end = pos
        n_bypass = self.sizes[0] * self.sizes[-1] if bypass else 0
        self.bypass = slice(pos, pos + n_bypass) if bypass else None
        self.n_params = pos + n_bypass

    def draw_weights(self, w: np.ndarray, rng, activation: str) -> None:
        """Glorot-uniform weights of every layer into ``w`` (biases untouched).

        The bound ``sqrt(6 / (fan_in + fan_out))``, doubled for the logistic
        sigmoid, whose slope at zero is a quarter of tanh's.
        """
        gain = 2.0 if activation == "logistic" else 1.0
        for layer in self.layers:
            bound = gain * np.sqrt(6.0 / (layer.n_in + layer.n_out))
            w[layer.weights] = rng.uniform(-bound, bound, layer.n_in * layer.n_out)

    def penalty_mask(self) -> np.ndarray:
        """The weights an L2 penalty acts on: those of a multilayer network.

        Not the biases, not the bypass, and none for a single (linear) layer.
        """
        mask = np.zeros(self.n_params, dtype=bool)
        if len(self.layers) > 1:
            for layer in self.layers:
                mask[layer.weights] = True
        return mask

    def input_columns(self, cols) -> np.ndarray:
        """Indices of the weights acting on network inputs ``cols``.

        Those of the first layer and of the bypass, row by row.
        """
        cols = np.asarray(cols)
        first = self.layers[0]
        start = first.weights.start
        idx = [start + j * first.n_in + cols for j in range(first.n_out)]
        if self.bypass is not None:
            idx += [
                self.bypass.start + j * self.sizes[0] + cols
                for j in range(self.sizes[-1])
            ]
        return np.concatenate(idx)

    def matrices(self, w: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
        """``(W, b)`` of every layer: ``W`` of shape ``(n_out, n_in)`` (views)."""
        return [
            (w[layer.weights].reshape(layer.n_out, layer.n_in), w[layer.biases])
            for layer in self.layers
        ]

    def bypass_matrix(self, w: np.ndarray) -> np.ndarray | None:
        """The bypass ``(sizes[-1], sizes[0])`` (a view), or None without one."""
        if self.bypass is None:
            return None
        return w[self.bypass].reshape(self.sizes[-1], self.sizes[0])
