"""The energy model E(s_t, s_{t+1}): low energy for transitions the environment can make, high for the rest."""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from torch import Tensor, nn
from torch.nn.utils import parametrize

from ebm_agent.config import check_field_types
from ebm_agent.fast_mlp import WorkspaceMLP
from ebm_agent.networks import build_mlp, make_activation, normalise_dims

__all__ = [
    "EVAL_CHUNK",
    "EnergyConfig",
    "EnergyModel",
    "FourierFeatures",
    "PeriodicFeatures",
    "TransitionEvaluator",
    "energy_function",
    "transition_energies",
]


@dataclass
class EnergyConfig:
    """
    Architecture of the energy network; the defaults are the original code's (``traj_model.TrajNetLatentFC``).

    :param hidden_dim: width of each hidden layer (128).
    :param num_hidden_layers: number of hidden layers (3).
    :param activation: ``"leaky_relu"`` (slope 0.2), ``"relu"``, ``"swish"``/``"silu"`` or ``"tanh"``.
    :param spectral_norm: spectrally normalise the hidden layers (off at the original's HEAD).
    :param positive_output: make the output layer bias-free with weights passed through ``abs()`` (the original's
        ``get_weight(..., pos=True)``). The energy is then a non-negative combination of the last hidden features.
    :param periodic_inputs: feed periodic state dims (the env's ``goal_period``, e.g. Reacher's normalised joint angles)
        to the network as (sin, cos) of the angle rather than the raw coordinate, so that the two sides of the wrap
        are neighbours (see :class:`PeriodicFeatures`). Not in the original, which fed Reacher's raw normalised
        angles: their wrap sits at the arm's rest pose (docs/agent.md). No effect on envs without periodic dims.
    :param difference_input: feed (phi(s), phi(s') - phi(s)) instead of (phi(s), phi(s')). Off (the original's).
    :param fourier_features: M > 0 appends M random Fourier features (sin and cos of random projections) of the
        network's input (:class:`FourierFeatures`), against the MLP's bias toward smooth functions that blurs walls
        (issue #34). 0 (off, the original's).
    :param fourier_scale: standard deviation of the Fourier frequencies, in cycles per unit of the input (2.0: best of
        1, 2, 4, 8, 16 on the maze probe; 16 collapses the energy to a constant).
    :param move_input: also feed the move s' - s (periodic dims wrapped), standardised per dim by the model's
        ``move_mean`` and ``move_std`` buffers (the agent sets them from the real moves it trains on). A move much
        smaller than the state's range (Reacher's angles change by ~0.01 a step while its velocities change by ~0.2)
        is then an O(1) input, so that relations between the dims of a move (angles that change by their velocities)
        are near-linear in the input. Off (the original's).
    """

    hidden_dim: int = 128
    num_hidden_layers: int = 3
    activation: str = "leaky_relu"
    spectral_norm: bool = False
    positive_output: bool = True
    periodic_inputs: bool = True
    difference_input: bool = False
    fourier_features: int = 0
    fourier_scale: float = 2.0
    move_input: bool = False

    def __post_init__(self) -> None:
        check_field_types(self)
        if not isinstance(self.hidden_dim, int) or self.hidden_dim < 1:
            raise ValueError(f"EnergyConfig.hidden_dim must be a positive int, got {self.hidden_dim!r}.")
        if not isinstance(self.num_hidden_layers, int) or self.num_hidden_layers < 0:
            raise ValueError(f"EnergyConfig.num_hidden_layers must be an int >= 0, got {self.num_hidden_layers!r}.")
        make_activation(self.activation)
        if isinstance(self.fourier_features, bool) or self.fourier_features < 0:
            raise ValueError(f"EnergyConfig.fourier_features must be an int >= 0, got {self.fourier_features!r}.")
        if not self.fourier_scale > 0:
            raise ValueError(f"EnergyConfig.fourier_scale must be > 0, got {self.fourier_scale!r}.")

    def __setstate__(self, state: dict[str, object]) -> None:
        """Unpickle (SB3's ``load``); files saved before ``periodic_inputs`` existed fed raw angles, so they keep that."""
        self.__dict__.update({"periodic_inputs": False, **state})


class _Abs(nn.Module):
    """Parametrization that exposes ``abs(raw_weight)`` as the layer's weight."""

    def forward(self, weight: Tensor) -> Tensor:
        return weight.abs()


class PeriodicFeatures(nn.Module):
    """
    A state's network features with its periodic coordinates on the circle: [..., D] -> [..., D + P].

    Each periodic coordinate x (period p) becomes sin(2 pi x / p) in its own slot, and cos(2 pi x / p) is appended
    after the D slots, in the order of ``dims``; the other coordinates pass unchanged. States one period apart get
    the same features, and the two sides of a wrap (0.99 and -0.99 for angles normalised to [-1, 1)) are neighbours.

    :param state_dim: D.
    :param dims: the P periodic dims (sorted, distinct, non-negative).
    :param period: their period.
    """

    def __init__(self, state_dim: int, dims: Sequence[int], period: float) -> None:
        super().__init__()
        if not dims:
            raise ValueError("PeriodicFeatures needs at least one periodic dim.")
        if not (isinstance(period, (int, float)) and math.isfinite(period) and period > 0):
            raise ValueError(f"PeriodicFeatures: period must be a positive number, got {period!r}.")
        self.state_dim = state_dim
        self.dims = tuple(dims)
        self.period = float(period)
        self.register_buffer("index", torch.tensor(self.dims, dtype=torch.long), persistent=False)  # [P]

    @property
    def feature_dim(self) -> int:
        """D + P."""
        return self.state_dim + len(self.dims)

    def forward(self, states: Tensor) -> Tensor:
        """
        :param states: [..., D] states.
        :return: [..., D + P] features.
        """
        index: Tensor = self.index  # type: ignore[assignment]
        angles = states.index_select(-1, index) * (2.0 * math.pi / self.period)  # [..., P]
        return torch.cat([states.index_copy(-1, index, torch.sin(angles)), torch.cos(angles)], dim=-1)

    def extra_repr(self) -> str:
        return f"dims={self.dims}, period={self.period}"


class FourierFeatures(nn.Module):
    """
    Random Fourier features (Tancik et al. 2020) appended to an input: [..., I] -> [..., I + 2M].

    ``[x, sin(2 pi x B), cos(2 pi x B)]`` with B [I, M] drawn once from N(0, scale^2) (torch's global generator, so the
    agent's seed fixes it) and saved with the weights. The high frequencies let an MLP fit a step (a wall) that raw
    coordinates only approach slowly.

    :param in_dim: I.
    :param num_features: M.
    :param scale: standard deviation of the frequencies (cycles per input unit).
    """

    def __init__(self, in_dim: int, num_features: int, scale: float) -> None:
        super().__init__()
        self.in_dim, self.num_features, self.scale = in_dim, num_features, float(scale)
        self.register_buffer("frequencies", torch.randn(in_dim, num_features) * (2.0 * math.pi * scale))  # [I, M]

    @property
    def out_dim(self) -> int:
        """I + 2M."""
        return self.in_dim + 2 * self.num_features

    def forward(self, inputs: Tensor) -> Tensor:
        """
        :param inputs: [..., I].
        :return: [..., I + 2M].
        """
        frequencies: Tensor = self.frequencies  # type: ignore[assignment]
        phases = inputs @ frequencies.to(inputs.dtype)  # [..., M]
        return torch.cat([inputs, torch.sin(phases), torch.cos(phases)], dim=-1)

    def extra_repr(self) -> str:
        return f"in_dim={self.in_dim}, num_features={self.num_features}, scale={self.scale}"


class EnergyModel(nn.Module):
    """
    MLP energy over a transition: ``E(s, s') = f(concat(phi(s), phi(s')))``, one scalar per transition.

    The input is the concatenation of the two states, not their difference (as the original); ``phi`` is the
    identity unless ``periodic_dims`` are given (and ``config.periodic_inputs``), when it puts those coordinates on
    the circle (:class:`PeriodicFeatures`). Dims listed in ``masked_dims`` are zeroed in both states' features
    before the network; the original did this for the arm's target position "for stability", so the energy models
    dynamics and never sees the goal.

    :param state_dim: D, size of one state.
    :param config: architecture; ``EnergyConfig()`` (the paper's 3 x 128 LeakyReLU network) when None.
    :param masked_dims: state dims to zero before the network (negative indices count from the end).
    :param periodic_dims: state dims that are periodic (angles), or () for none.
    :param period: the period of ``periodic_dims`` (2.0 for angles normalised to [-1, 1)).
    """

    def __init__(
        self,
        state_dim: int,
        config: EnergyConfig | None = None,
        masked_dims: Sequence[int] = (),
        periodic_dims: Sequence[int] = (),
        period: float = 2.0,
    ) -> None:
        super().__init__()
        if not isinstance(state_dim, int) or isinstance(state_dim, bool) or state_dim < 1:
            raise ValueError(f"EnergyModel: state_dim must be a positive int, got {state_dim!r}.")
        self.state_dim = state_dim
        self.config = config if config is not None else EnergyConfig()
        self.masked_dims = normalise_dims(masked_dims, state_dim, "masked_dims")
        periodic = normalise_dims(periodic_dims, state_dim, "periodic_dims") if self.config.periodic_inputs else ()
        self.features = PeriodicFeatures(state_dim, periodic, period) if periodic else None
        feature_dim = state_dim if self.features is None else self.features.feature_dim  # F

        cfg = self.config
        self.periodic_dims = normalise_dims(periodic_dims, state_dim, "periodic_dims")  # wrapped in the move input
        self.period = float(period)
        extra = state_dim if cfg.move_input else 0  # the standardised move, appended after the pair (and its Fourier features)
        if cfg.move_input:
            self.register_buffer("move_mean", torch.zeros(state_dim))  # [D]
            self.register_buffer("move_std", torch.ones(state_dim))  # [D]
        self.fourier = (
            FourierFeatures(2 * feature_dim, cfg.fourier_features, cfg.fourier_scale) if cfg.fourier_features else None
        )
        self.net = build_mlp(
            (2 * feature_dim if self.fourier is None else self.fourier.out_dim) + extra,
            1,
            hidden_dim=cfg.hidden_dim,
            num_hidden_layers=cfg.num_hidden_layers,
            activation=cfg.activation,
            spectral_norm=cfg.spectral_norm,
            out_bias=not cfg.positive_output,
            # The original's final version normalised only the hidden layers once the output became abs().
            spectral_norm_output=not cfg.positive_output,
        )
        if cfg.positive_output:
            parametrize.register_parametrization(self.output_layer, "weight", _Abs())

        keep = torch.ones(2 * feature_dim)
        for dim in self.masked_dims:
            columns = [dim]
            if periodic and dim in periodic:
                columns.append(state_dim + periodic.index(dim))  # its cos feature
            for column in columns:
                keep[column] = 0.0
                keep[feature_dim + column] = 0.0
        # [2F] multiplicative mask over concat(phi(s), phi(s')); not persistent: it follows from the constructor arguments.
        self.register_buffer("input_mask", keep, persistent=False)

    @property
    def feature_dim(self) -> int:
        """F: the network's input size per state (D, plus one per periodic dim)."""
        return self.state_dim if self.features is None else self.features.feature_dim

    @property
    def output_layer(self) -> nn.Linear:
        """The final ``nn.Linear`` (its ``weight`` is already ``abs()``-ed when ``positive_output``)."""
        layer = self.net[-1]
        assert isinstance(layer, nn.Linear)
        return layer

    def forward(self, states: Tensor, next_states: Tensor) -> Tensor:
        """
        Energy of each transition, in one batched call whatever the leading dims.

        :param states: [..., D] states s_t (e.g. [N, K, T, D] envs x candidates x horizon x state).
        :param next_states: [..., D] next states s_{t+1}, same shape.
        :return: [...] energies (float, same leading dims).
        :raises TypeError: for non-tensor or non-floating inputs.
        :raises ValueError: for mismatched shapes or a last dim other than ``state_dim``.
        """
        for name, value in (("states", states), ("next_states", next_states)):
            if not isinstance(value, Tensor):
                raise TypeError(f"EnergyModel: {name} must be a torch.Tensor, got {type(value).__name__}.")
            if not value.is_floating_point():
                raise TypeError(f"EnergyModel: {name} must be a floating tensor, got dtype {value.dtype}.")
        if states.shape != next_states.shape:
            raise ValueError(
                f"EnergyModel: states and next_states must have the same shape, got {tuple(states.shape)} "
                f"and {tuple(next_states.shape)}."
            )
        if states.ndim == 0 or states.shape[-1] != self.state_dim:
            raise ValueError(f"EnergyModel: expected states of shape [..., {self.state_dim}], got {tuple(states.shape)}.")
        leading = states.shape[:-1]
        move = self.standardised_move(states, next_states).reshape(-1, self.state_dim) if self.config.move_input else None
        if self.features is not None:
            states, next_states = self.features(states), self.features(next_states)  # [..., F] each
        pairs = torch.cat([states, next_states], dim=-1).reshape(-1, 2 * self.feature_dim)  # [M, 2F]
        mask: Tensor = self.input_mask  # type: ignore[assignment]
        if pairs.dtype != mask.dtype:
            pairs = pairs.to(mask.dtype)
        if self.masked_dims:
            pairs = pairs * mask
        if self.config.difference_input:
            first, second = pairs[:, : self.feature_dim], pairs[:, self.feature_dim :]  # [M, F] each
            pairs = torch.cat([first, second - first], dim=1)
        if self.fourier is not None:
            pairs = self.fourier(pairs)  # [M, 2F + 2 * fourier_features]
        if move is not None:
            pairs = torch.cat([pairs, move.to(pairs.dtype)], dim=1)  # [M, ... + D]
        return self.net(pairs).reshape(leading)  # [M, 1] -> [...]

    def raw_move(self, states: Tensor, next_states: Tensor) -> Tensor:
        """s' - s with the periodic dims wrapped into [-period/2, period/2); masked dims are zero.

        :param states: [..., D].
        :param next_states: [..., D].
        :return: [..., D].
        """
        move = next_states - states
        if self.periodic_dims:
            index = torch.tensor(self.periodic_dims, device=move.device)
            half = 0.5 * self.period
            move = move.index_copy(-1, index, torch.remainder(move.index_select(-1, index) + half, self.period) - half)
        if self.masked_dims:
            keep = torch.ones(self.state_dim, dtype=move.dtype, device=move.device)
            keep[list(self.masked_dims)] = 0.0
            move = move * keep
        return move

    def standardised_move(self, states: Tensor, next_states: Tensor) -> Tensor:
        """(raw move - move_mean) / move_std, the ``move_input`` features.

        :param states: [..., D].
        :param next_states: [..., D].
        :return: [..., D].
        """
        mean: Tensor = self.move_mean  # type: ignore[assignment]
        std: Tensor = self.move_std  # type: ignore[assignment]
        return (self.raw_move(states, next_states) - mean.to(states.dtype)) / std.to(states.dtype)

    def set_move_statistics(self, mean: Tensor | np.ndarray, std: Tensor | np.ndarray) -> None:
        """Set the standardisation of ``move_input`` (no effect without it).

        :param mean: [D] mean real move.
        :param std: [D] std of the real moves, > 0.
        """
        if not self.config.move_input:
            return
        move_mean: Tensor = self.move_mean  # type: ignore[assignment]
        move_std: Tensor = self.move_std  # type: ignore[assignment]
        move_mean.copy_(torch.as_tensor(mean, dtype=move_mean.dtype))
        move_std.copy_(torch.as_tensor(std, dtype=move_std.dtype).clamp_min(1e-6))

    def inference_evaluator(self, dtype: torch.dtype | None = None, fused: bool = True) -> TransitionEvaluator | None:
        """
        A gradient-free evaluator of this energy that reuses its activation buffers (see :mod:`ebm_agent.fast_mlp`).

        It snapshots the current weights: build it when the weights are final (the planner builds one per plan).

        :param dtype: compute dtype (``torch.bfloat16`` does what ``torch.autocast`` does to this network: matmuls
            and activations in bf16, energies returned in bf16); None computes in the weights' dtype.
        :param fused: use oneDNN's fused layers on CPU when available (faster; float32 energies equal the module's to
            float rounding); False gives the module's float32 energies bit for bit.
        :return: a callable with :meth:`forward`'s signature and results, or None when the network cannot be evaluated
            that way (spectral norm in training mode, ``difference_input`` or Fourier features).
        """
        if self.config.difference_input or self.fourier is not None or self.config.move_input:
            return None
        network = WorkspaceMLP.from_sequential(self.net, dtype, fused)
        if network is None:
            return None
        mask = self.input_mask if self.masked_dims else None
        return TransitionEvaluator(network, self.state_dim, mask, self.features)  # type: ignore[arg-type]

    def extra_repr(self) -> str:
        return f"state_dim={self.state_dim}, masked_dims={self.masked_dims}"


class TransitionEvaluator:
    """
    E(s, s') through a :class:`WorkspaceMLP`: the pairs are written into a reused [M, 2F] buffer.

    :param network: the snapshot of the energy network.
    :param state_dim: D.
    :param input_mask: the [2F] input mask, or None when no dim is masked.
    :param features: the energy's periodic features (F = D + P), or None (F = D).
    """

    def __init__(
        self, network: WorkspaceMLP, state_dim: int, input_mask: Tensor | None, features: PeriodicFeatures | None = None
    ) -> None:
        self.network = network
        self.state_dim = state_dim
        self.input_mask = input_mask
        self.features = features
        self.feature_dim = state_dim if features is None else features.feature_dim
        self._pairs: Tensor | None = None

    def _pair_inputs(self, states: Tensor, next_states: Tensor) -> list[Tensor]:
        """What is concatenated into the pairs buffer: the two states, or their features."""
        if self.features is None:
            return [states, next_states]
        return [self.features(states), self.features(next_states)]

    def __call__(self, states: Tensor, next_states: Tensor) -> Tensor:
        """
        :param states: [..., D] states s_t.
        :param next_states: [..., D] next states, same shape.
        :return: [...] energies.
        """
        states, next_states, pairs = self._checked(states, next_states)
        leading = states.shape[:-1]
        torch.cat(self._pair_inputs(states, next_states), dim=-1, out=pairs.view(*leading, 2 * self.feature_dim))
        if self.input_mask is not None:
            pairs.mul_(self.input_mask)
        return self.network(pairs).reshape(leading)  # [M, 1] -> [...]

    def _checked(self, states: Tensor, next_states: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        """The inputs in the network's dtype and the [M, 2F] pairs buffer sized for them; raises on bad shapes."""
        if states.shape != next_states.shape or states.ndim == 0 or states.shape[-1] != self.state_dim:
            raise ValueError(
                f"expected states and next_states of the same shape [..., {self.state_dim}], got "
                f"{tuple(states.shape)} and {tuple(next_states.shape)}."
            )
        count = math.prod(states.shape[:-1])
        dtype = self.network.layers[0][0].dtype
        if states.dtype != dtype:
            states, next_states = states.to(dtype), next_states.to(dtype)
        pairs = self._pairs
        if pairs is None or pairs.shape[0] != count or pairs.dtype != dtype or pairs.device != states.device:
            pairs = torch.empty(count, 2 * self.feature_dim, dtype=dtype, device=states.device)  # [M, 2F]
            self._pairs = pairs
        return states, next_states, pairs

    def bind(self, states: Tensor, next_states: Tensor) -> Callable[[], Tensor]:
        """
        ``self(states, next_states)`` as a function of no arguments, for views of a buffer that is rewritten between calls.

        The MPPI loop binds the views of its candidate buffer once per plan, so each iteration skips the checks, the
        buffer lookups and the view bookkeeping (a few microseconds each, against ~300 per iteration). Bind and call it
        under ``torch.inference_mode()`` or ``no_grad()``.

        :param states: [..., D] states s_t, kept by reference.
        :param next_states: [..., D] next states, same shape.
        :return: a function returning the energies [...] of the views' current contents.
        """
        if states.dtype != self.network.layers[0][0].dtype:  # every call casts: nothing to save
            return functools.partial(self, states, next_states)
        states, next_states, pairs = self._checked(states, next_states)
        leading = states.shape[:-1]
        pairs_view = pairs.view(*leading, 2 * self.feature_dim)  # [..., 2F] view of the [M, 2F] buffer
        network = self.network.bind(pairs)
        mask = self.input_mask
        if self.features is None:
            inputs = [states, next_states]

            def pair_inputs() -> list[Tensor]:
                return inputs
        else:
            pair_inputs = functools.partial(self._pair_inputs, states, next_states)

        def energies() -> Tensor:
            torch.cat(pair_inputs(), dim=-1, out=pairs_view)
            if mask is not None:
                pairs.mul_(mask)
            return network().view(leading)  # [M, 1] -> [...]

        return energies


EVAL_CHUNK = 65_536
"""Transitions per energy call, to bound the activation memory."""


def energy_function(agent: Any) -> Callable[[Tensor, Tensor], Tensor]:
    """The energy of an agent (its ``energy_model``) or the energy itself."""
    model = getattr(agent, "energy_model", agent)
    if not callable(model):
        raise TypeError(f"expected an agent with an energy_model or an energy callable, got {type(agent).__name__}.")
    return model  # type: ignore[no-any-return]


def transition_energies(agent: Any, states: np.ndarray, next_states: np.ndarray) -> np.ndarray:
    """E(s, s') of [N, D] pairs as float64 [N], without gradients, in chunks and in eval mode (a spectral norm's power
    iteration must not run); the model's mode is restored.

    :param agent: an agent with ``energy_model``, or an energy callable.
    :param states: [N, D].
    :param next_states: [N, D].
    :return: [N] energies.
    """
    model = energy_function(agent)
    was_training = isinstance(model, nn.Module) and model.training
    parameter = next(model.parameters(), None) if isinstance(model, nn.Module) else None
    device = parameter.device if parameter is not None else torch.device("cpu")
    if isinstance(model, nn.Module):
        model.eval()
    try:
        chunks = []
        with torch.no_grad():
            for start in range(0, len(states), EVAL_CHUNK):
                state_chunk = torch.as_tensor(np.ascontiguousarray(states[start : start + EVAL_CHUNK]), device=device)
                next_chunk = torch.as_tensor(np.ascontiguousarray(next_states[start : start + EVAL_CHUNK]), device=device)
                chunks.append(model(state_chunk.float(), next_chunk.float()).double().cpu().numpy())  # [chunk]
    finally:
        if was_training:
            assert isinstance(model, nn.Module)
            model.train()
    return np.concatenate(chunks) if chunks else np.zeros(0)
