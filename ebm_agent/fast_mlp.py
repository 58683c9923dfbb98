"""Inference-only evaluation of :func:`ebm_agent.networks.build_mlp` networks with reused activation buffers.

The planner scores tens of thousands of transitions per MPPI iteration, dozens of iterations per plan. Each plain
``nn.Sequential`` call allocates one fresh [M, hidden] tensor per layer and activation. On CPU, buffers of a few MB
come from ``mmap`` and are returned to the system when freed, so every allocation pays page faults for memory it then
overwrites: at M = 4,096 transitions and width 128 this doubled the time of the whole energy call on the benchmark
machine (docs/benchmarks.md). :class:`WorkspaceMLP` writes each layer into a buffer it keeps between calls
(``torch.addmm(..., out=)``) and applies the activation in place; it runs the same kernels on the same numbers as the
module, so the energies are identical. On CPU it uses oneDNN's fused linear + activation instead when torch has it (the
kernel ``torch.compile`` picks for such layers): in float32 it was 2x faster than the BLAS matmul plus a separate
activation for batches of 512 to 16,384 rows on the benchmark machine (the planner scores in chunks of a few
thousand, see ``ebm_agent.mppi.CPU_CHUNK_TRANSITIONS``), and 1.25x faster in bf16. Its float32 energies agree with the module's
to float rounding (a few 1e-7), not bit for bit; bf16 ones with autocast's to bf16 rounding.
"""

from __future__ import annotations

import functools
from collections.abc import Callable

import torch
from torch import Tensor, nn
from torch.nn.utils import parametrize

__all__ = ["FUSED_MIN_FEATURES", "FUSED_MIN_ROWS", "MAX_WORKSPACES", "WorkspaceMLP"]

FUSED_MIN_ROWS = 128
"""Batches smaller than this use the buffers even where oneDNN's fused op exists: at 80 rows (the Action FF planner's
one-step rollouts) its call overhead made it 10% slower, from 160 rows on it was faster (1.2x at 160, 1.9x at 640)."""

FUSED_MIN_FEATURES = 9
"""Layers with fewer inputs than this (the energy's first layer on [s, s'] of a 2-D or 4-D state) use the buffers even on
the fused path: the fused op's fixed cost (~19 us per call at 800 rows, 2 threads) outweighs its gain on such thin
matmuls, where addmm plus the in-place activation took ~14 us on the benchmark machine."""

MAX_WORKSPACES = 4
"""Buffer sets kept per evaluator (one per batch size seen: the chunks of a plan, its last chunk, the final score)."""

_InPlace = Callable[[Tensor], object]
_Step = Callable[[Tensor], Tensor]
_Fused = tuple[str, list[float]]
"""oneDNN's name of an activation and its scalars, e.g. ("leaky_relu", [0.2])."""


def _in_place_activation(module: nn.Module) -> tuple[_InPlace, _Fused] | None:
    """The in-place version of a supported activation module and its oneDNN post-op, or None."""
    if isinstance(module, nn.LeakyReLU):
        slope = module.negative_slope
        return (lambda x: torch.nn.functional.leaky_relu_(x, slope)), ("leaky_relu", [slope])
    if isinstance(module, nn.ReLU):
        return torch.relu_, ("relu", [])
    if isinstance(module, nn.SiLU):
        return (lambda x: torch.nn.functional.silu(x, inplace=True)), ("swish", [])
    if isinstance(module, nn.Tanh):
        return torch.tanh_, ("tanh", [])
    return None


def _fused_linear() -> Callable[..., Tensor] | None:
    """oneDNN's fused ``linear + activation`` op on CPU (used by torch.compile's CPU backend), or None."""
    if not torch.backends.mkldnn.is_available():
        return None
    return getattr(torch.ops.mkldnn, "_linear_pointwise", None)


class WorkspaceMLP:
    """
    A snapshot of an MLP's weights, evaluated without gradients into reused buffers.

    Build it with :meth:`from_sequential` right before a batch of evaluations (e.g. once per plan): it reads the
    weights once (parametrisations such as the energy's ``abs()`` output included) and does not see later updates.

    :param layers: (weight [out, in], bias [out] or None, in-place activation or None) per Linear layer.
    :param post_ops: oneDNN's name and scalars of each layer's activation (("none", []) for none), to evaluate with
        the fused op; None never uses it.
    """

    def __init__(
        self, layers: list[tuple[Tensor, Tensor | None, _InPlace | None]], post_ops: list[_Fused] | None = None
    ) -> None:
        if not layers:
            raise ValueError("WorkspaceMLP needs at least one Linear layer.")
        if post_ops is not None and len(post_ops) != len(layers):
            raise ValueError(f"post_ops needs one entry per layer ({len(layers)}), got {len(post_ops)}.")
        self.layers = layers
        self.post_ops = post_ops
        self.in_features = layers[0][0].shape[1]
        # Per batch size (and dtype, device, inference mode): the layer functions and their output buffers.
        self._workspaces: dict[tuple[int, torch.dtype, torch.device, bool], list[_Step]] = {}

    @classmethod
    def from_sequential(cls, net: nn.Sequential, dtype: torch.dtype | None = None, fused: bool = True) -> WorkspaceMLP | None:
        """
        Snapshot ``Linear - activation - ... - Linear`` networks as built by ``build_mlp``.

        :param net: the network.
        :param dtype: the dtype to compute in (weights cast once, inputs cast on each call), e.g. ``torch.bfloat16``
            for what ``torch.autocast`` would do; None keeps the weights' dtype.
        :param fused: use oneDNN's fused linear + activation on CPU when torch has it; False always uses the buffers
            (bit-for-bit the module's float32 energies).
        :return: the evaluator, or None when the network has another shape, another module type, or a parametrisation
            that changes state when evaluated (spectral norm in training mode runs a power iteration per call).
        """
        modules = list(net)
        layers: list[tuple[Tensor, Tensor | None, _InPlace | None]] = []
        post_ops: list[_Fused] = []
        with torch.no_grad():
            for index, module in enumerate(modules):
                if isinstance(module, nn.Linear):
                    if parametrize.is_parametrized(module) and module.training and _has_stateful_parametrization(module):
                        return None
                    weight = module.weight.detach()
                    bias: Tensor | None = None if module.bias is None else module.bias.detach()
                    if dtype is not None:
                        weight, bias = weight.to(dtype), None if bias is None else bias.to(dtype)
                    layers.append((weight, bias, None))
                    post_ops.append(("none", []))
                    continue
                activation = _in_place_activation(module)
                if activation is None or index == 0 or not isinstance(modules[index - 1], nn.Linear):
                    return None
                weight, bias, _ = layers[-1]
                layers[-1] = (weight, bias, activation[0])
                post_ops[-1] = activation[1]
        if not layers or not isinstance(modules[-1], nn.Linear):
            return None
        fused = fused and layers[0][0].device.type == "cpu" and _fused_linear() is not None
        return cls(layers, post_ops if fused else None)

    def __call__(self, inputs: Tensor) -> Tensor:
        """
        Evaluate the network.

        :param inputs: [M, in] inputs (any memory layout and floating dtype).
        :return: [M, out] outputs in the compute dtype, a fresh tensor (the hidden activations live in the reused buffers).
        :raises RuntimeError: when called with gradients enabled (the buffers cannot be part of a graph).
        """
        x = self._checked_input(inputs)
        return self._run(x, self._steps(x))

    def bind(self, inputs: Tensor) -> Callable[[], Tensor]:
        """
        Evaluation of whatever ``inputs`` holds when called, with the per-call checks and lookups done once here.

        The planner binds the buffer it rewrites every MPPI iteration (see ``TransitionEvaluator.bind``); calling the
        result equals ``self(inputs)`` on the buffer's current contents. Bind under ``torch.inference_mode()`` or
        ``no_grad()``, and call it there.

        :param inputs: [M, in] inputs, kept by reference.
        :return: a function of no arguments returning the outputs [M, out] (a fresh tensor each call).
        """
        x = self._checked_input(inputs)
        if x is not inputs:  # another dtype: the cast has to be redone on each call
            return functools.partial(self, inputs)
        return functools.partial(self._run, x, self._steps(x))

    def _checked_input(self, inputs: Tensor) -> Tensor:
        if torch.is_grad_enabled():
            raise RuntimeError("WorkspaceMLP is for inference only: call it under torch.inference_mode() or no_grad().")
        if inputs.ndim != 2 or inputs.shape[1] != self.in_features:
            raise ValueError(f"WorkspaceMLP expects inputs [M, {self.in_features}], got {tuple(inputs.shape)}.")
        dtype = self.layers[0][0].dtype
        return inputs if inputs.dtype == dtype else inputs.to(dtype)

    def _run(self, inputs: Tensor, steps: list[_Step]) -> Tensor:
        x = inputs
        try:
            for step in steps:
                x = step(x)
        except (RuntimeError, NotImplementedError):  # oneDNN's op is private: another torch version may lack or change it
            if self.post_ops is None:
                raise
            self.post_ops = None
            self._workspaces.clear()
            steps[:] = self._steps(inputs)  # in place, so that a bound evaluation switches as well
            return self._run(inputs, steps)
        return x

    def _steps(self, inputs: Tensor) -> list[_Step]:
        """The layer-by-layer functions x -> x for this batch size, with their output buffers (cached per batch size)."""
        key = (inputs.shape[0], inputs.dtype, inputs.device, torch.is_inference_mode_enabled())
        cached = self._workspaces.get(key)
        if cached is not None:
            return cached
        if len(self._workspaces) >= MAX_WORKSPACES:
            self._workspaces.clear()
        rows = inputs.shape[0]
        fused = self.post_ops is not None and rows >= FUSED_MIN_ROWS
        linear_pointwise = _fused_linear()
        last = len(self.layers) - 1
        steps: list[_Step] = []
        for index, (weight, bias, activation) in enumerate(self.layers):
            weight_t = weight.t()  # [in, out] view
            if fused and self.post_ops is not None and linear_pointwise is not None:
                name, scalars = self.post_ops[index]
                thin = weight.shape[1] < FUSED_MIN_FEATURES and index < last
                # The energy's [128 -> 1] output is 2x faster as a plain mm; thin layers see the note at FUSED_MIN_FEATURES.
                if not thin and not (name == "none" and weight.shape[0] == 1):
                    steps.append(functools.partial(_fused_step, linear_pointwise, weight, bias, name, scalars))
                    continue
            out = None if index == last else torch.empty(rows, weight.shape[0], dtype=inputs.dtype, device=inputs.device)
            steps.append(functools.partial(_buffered_step, weight_t, bias, activation, out))  # out: [M, out_i] or fresh
        self._workspaces[key] = steps
        return steps


def _buffered_step(
    weight_t: Tensor, bias: Tensor | None, activation: _InPlace | None, out: Tensor | None, x: Tensor
) -> Tensor:
    """x @ weight_t + bias into ``out`` (a fresh tensor when None), then the in-place activation."""
    if bias is None:
        x = torch.mm(x, weight_t) if out is None else torch.mm(x, weight_t, out=out)
    else:
        x = torch.addmm(bias, x, weight_t) if out is None else torch.addmm(bias, x, weight_t, out=out)
    if activation is not None:
        activation(x)
    return x


def _fused_step(
    linear_pointwise: Callable[..., Tensor], weight: Tensor, bias: Tensor | None, name: str, scalars: list[float], x: Tensor
) -> Tensor:
    """oneDNN's fused linear + activation: a fresh [M, out] tensor."""
    return linear_pointwise(x, weight, bias, name, scalars, "")


def _has_stateful_parametrization(module: nn.Module) -> bool:
    """True when a parametrisation of ``module`` may update buffers when evaluated (anything but a stateless one)."""
    parametrizations = getattr(module, "parametrizations", {})
    return any(
        any(list(p.buffers()) for p in parametrization)  # e.g. spectral norm's power-iteration vectors u, v
        for parametrization in parametrizations.values()
    )
