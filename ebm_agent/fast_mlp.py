"""Inference-only evaluation of :func:`ebm_agent.networks.build_mlp` networks with reused activation buffers.

The planner scores tens of thousands of transitions per MPPI iteration, dozens of iterations per plan. Each plain
``nn.Sequential`` call allocates one fresh [M, hidden] tensor per layer and activation. On CPU, buffers of a few MB
come from ``mmap`` and are returned to the system when freed, so every allocation pays page faults for memory it then
overwrites: at M = 4,096 transitions and width 128 this doubled the time of the whole energy call on the benchmark
machine (docs/benchmarks.md). :class:`WorkspaceMLP` writes each layer into a buffer it keeps between calls
(``torch.addmm(..., out=)``) and applies the activation in place; it runs the same kernels on the same numbers as the
module, so the energies are identical. On CPU it uses oneDNN's fused linear + activation instead when torch has it (the
kernel ``torch.compile`` picks for such layers): in float32 it was 2x faster than the BLAS matmul plus a separate
activation for batches of up to ~1,000 rows on the benchmark machine (so the planner scores in chunks of that size,
see ``ebm_agent.mppi.CPU_CHUNK_TRANSITIONS``), and 1.25x faster in bf16. Its float32 energies agree with the module's
to float rounding (a few 1e-7), not bit for bit; bf16 ones with autocast's to bf16 rounding.
"""

from __future__ import annotations

from collections.abc import Callable

import torch
from torch import Tensor, nn
from torch.nn.utils import parametrize

__all__ = ["FUSED_MIN_ROWS", "MAX_WORKSPACES", "WorkspaceMLP"]

FUSED_MIN_ROWS = 128
"""Batches smaller than this use the buffers even where oneDNN's fused op exists: at 80 rows (the Action FF planner's
one-step rollouts) its call overhead made it 10% slower, from 160 rows on it was faster (1.2x at 160, 1.9x at 640)."""

MAX_WORKSPACES = 4
"""Buffer sets kept per evaluator (one per batch size seen: the chunks of a plan, its last chunk, the final score)."""

_InPlace = Callable[[Tensor], object]
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
        self._workspaces: dict[tuple[int, torch.dtype, torch.device, bool], list[Tensor]] = {}

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
        if torch.is_grad_enabled():
            raise RuntimeError("WorkspaceMLP is for inference only: call it under torch.inference_mode() or no_grad().")
        if inputs.ndim != 2 or inputs.shape[1] != self.in_features:
            raise ValueError(f"WorkspaceMLP expects inputs [M, {self.in_features}], got {tuple(inputs.shape)}.")
        dtype = self.layers[0][0].dtype
        x = inputs if inputs.dtype == dtype else inputs.to(dtype)
        if self.post_ops is not None and x.shape[0] >= FUSED_MIN_ROWS:
            fused = self._fused(x)
            if fused is not None:
                return fused
        hidden = self._workspace(x)
        last = len(self.layers) - 1
        for index, (weight, bias, activation) in enumerate(self.layers):
            out = None if index == last else hidden[index]  # [M, out_i]; the output is allocated fresh
            if bias is None:
                x = torch.mm(x, weight.t()) if out is None else torch.mm(x, weight.t(), out=out)
            else:
                x = torch.addmm(bias, x, weight.t()) if out is None else torch.addmm(bias, x, weight.t(), out=out)
            if activation is not None:
                activation(x)
        return x

    def _fused(self, x: Tensor) -> Tensor | None:
        """The output via oneDNN's fused layers, or None (and never again) if this torch build rejects the op."""
        linear_pointwise = _fused_linear()
        assert self.post_ops is not None and linear_pointwise is not None
        try:
            for (weight, bias, _), (name, scalars) in zip(self.layers, self.post_ops, strict=True):
                if name == "none" and weight.shape[0] == 1:  # the energy's [128 -> 1]: a plain mm is 2x faster
                    x = torch.mm(x, weight.t()) if bias is None else torch.addmm(bias, x, weight.t())
                else:
                    x = linear_pointwise(x, weight, bias, name, scalars, "")  # [M, out_i]
        except (RuntimeError, NotImplementedError):  # a private op: another torch version may lack or change it
            self.post_ops = None
            return None
        return x

    def _workspace(self, inputs: Tensor) -> list[Tensor]:
        key = (inputs.shape[0], inputs.dtype, inputs.device, torch.is_inference_mode_enabled())
        buffers = self._workspaces.get(key)
        if buffers is None:
            if len(self._workspaces) >= MAX_WORKSPACES:
                self._workspaces.clear()
            sizes = [weight.shape[0] for weight, _, _ in self.layers[:-1]]
            buffers = [torch.empty(inputs.shape[0], size, dtype=inputs.dtype, device=inputs.device) for size in sizes]
            self._workspaces[key] = buffers
        return buffers


def _has_stateful_parametrization(module: nn.Module) -> bool:
    """True when a parametrisation of ``module`` may update buffers when evaluated (anything but a stateless one)."""
    parametrizations = getattr(module, "parametrizations", {})
    return any(
        any(list(p.buffers()) for p in parametrization)  # e.g. spectral norm's power-iteration vectors u, v
        for parametrization in parametrizations.values()
    )
