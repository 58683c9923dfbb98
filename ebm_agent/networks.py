"""Multi-layer perceptrons shared by the energy model, the learned inverse dynamics and the Action FF baseline."""

from __future__ import annotations

import itertools
import operator
from collections.abc import Sequence

from torch import nn
from torch.nn.utils import parametrizations

__all__ = ["ACTIVATIONS", "build_mlp", "make_activation", "normalise_dims"]

ACTIVATIONS: tuple[str, ...] = ("leaky_relu", "relu", "swish", "silu", "tanh")
"""Activation names accepted by :func:`build_mlp`."""

# The original code used TF's tf.nn.leaky_relu, whose default negative slope is 0.2 (torch's default is 0.01).
LEAKY_RELU_SLOPE = 0.2


def make_activation(name: str) -> nn.Module:
    """
    Create an activation module from its name.

    :param name: one of :data:`ACTIVATIONS` (``"swish"`` and ``"silu"`` are the same function).
    :return: a fresh activation module.
    :raises ValueError: for an unknown name.
    """
    key = name.lower() if isinstance(name, str) else name
    if key == "leaky_relu":
        return nn.LeakyReLU(LEAKY_RELU_SLOPE)
    if key == "relu":
        return nn.ReLU()
    if key in ("swish", "silu"):
        return nn.SiLU()
    if key == "tanh":
        return nn.Tanh()
    raise ValueError(f"Unknown activation {name!r}; choose one of {list(ACTIVATIONS)}.")


def build_mlp(
    in_dim: int,
    out_dim: int,
    hidden_dim: int = 128,
    num_hidden_layers: int = 3,
    activation: str = "leaky_relu",
    spectral_norm: bool = False,
    out_bias: bool = True,
    spectral_norm_output: bool = True,
) -> nn.Sequential:
    """
    Build ``Linear(in, h) - act - [Linear(h, h) - act] x (L-1) - Linear(h, out)``, initialised like the original.

    "3 x 128" means ``num_hidden_layers=3, hidden_dim=128``: three hidden layers of width 128, four Linear layers.
    Weights are Xavier/Glorot-uniform and biases zero, as ``utils.get_weight`` in the original code.

    :param in_dim: input size.
    :param out_dim: output size.
    :param hidden_dim: width of every hidden layer.
    :param num_hidden_layers: number of hidden layers (0 gives a single linear map).
    :param activation: one of :data:`ACTIVATIONS`; ``"leaky_relu"`` uses slope 0.2 (TF's default, the original's).
    :param spectral_norm: rescale each Linear weight to spectral norm 1 with one power iteration per forward pass in
        training mode (the original's ``spec_norm`` option, off by default at its HEAD).
    :param out_bias: give the output layer a bias.
    :param spectral_norm_output: with ``spectral_norm``, also normalise the output layer (the original did until
        2019-07-01; its final version left the output layer alone).
    :return: the network as an ``nn.Sequential`` whose last module is the output ``nn.Linear``.
    :raises ValueError: for non-positive sizes, a negative depth or an unknown activation.
    """
    for name, value in (("in_dim", in_dim), ("out_dim", out_dim), ("hidden_dim", hidden_dim)):
        if not isinstance(value, int) or isinstance(value, bool) or value < 1:
            raise ValueError(f"build_mlp: {name} must be a positive int, got {value!r}.")
    if not isinstance(num_hidden_layers, int) or num_hidden_layers < 0:
        raise ValueError(f"build_mlp: num_hidden_layers must be an int >= 0, got {num_hidden_layers!r}.")
    make_activation(activation)  # fail early on a bad name, before building anything

    widths = [in_dim] + [hidden_dim] * num_hidden_layers
    layers: list[nn.Module] = []
    for fan_in, fan_out in itertools.pairwise(widths):
        layers.append(_linear(fan_in, fan_out, bias=True, spectral_norm=spectral_norm))
        layers.append(make_activation(activation))
    layers.append(_linear(widths[-1], out_dim, bias=out_bias, spectral_norm=spectral_norm and spectral_norm_output))
    return nn.Sequential(*layers)


def _linear(fan_in: int, fan_out: int, bias: bool, spectral_norm: bool) -> nn.Module:
    layer = nn.Linear(fan_in, fan_out, bias=bias)
    nn.init.xavier_uniform_(layer.weight)
    if layer.bias is not None:
        nn.init.zeros_(layer.bias)
    if spectral_norm:
        # One power iteration per training forward pass with a persistent u, rescaled to norm 1 (spec_iter=1,
        # spec_norm_val=1.0 in the original).
        return parametrizations.spectral_norm(layer, n_power_iterations=1)
    return layer


def normalise_dims(dims: Sequence[int], size: int, name: str = "dims") -> tuple[int, ...]:
    """
    Validate input-dim indices (e.g. the target dims masked out of a model's input).

    :param dims: indices into a vector of ``size`` entries; negative ones count from the end.
    :param size: the vector's length.
    :param name: the argument's name, for error messages.
    :return: the distinct non-negative indices, sorted.
    :raises ValueError: for a non-int entry or an index out of range.
    """
    out: set[int] = set()
    for dim in dims:
        try:
            if isinstance(dim, bool):
                raise TypeError
            index = operator.index(dim)
        except TypeError:
            raise ValueError(f"{name} must hold ints, got {dim!r}.") from None
        if not -size <= index < size:
            raise ValueError(f"{name} entry {index} is out of range for a state of {size} dims.")
        out.add(index % size)
    return tuple(sorted(out))
