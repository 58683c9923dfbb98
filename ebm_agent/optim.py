"""Adam with the original code's per-element gradient clipping (``custom_adam.py``), used to train the energy model."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any

import torch

__all__ = ["ClippedAdam"]


class ClippedAdam(torch.optim.Adam):
    """
    Adam whose gradient elements are first clipped to a band of a few standard deviations of their history.

    Before the moment update of step t, each gradient element is clipped to
    ``+-(clip_sigma * sqrt(v_{t-1} / (1 - beta2^t)) + clip_offset)``, with v the second-moment estimate. This is the
    original's ``custom_adam.AdamOptimizer._apply_dense`` (3 sigma + 0.1). Note the bias correction uses
    ``beta2^t`` (TF's ``beta2_power`` during step t), not ``beta2^(t-1)`` which would be 0/0 at t=1: on the first
    step v is zero and the bound is just ``clip_offset``. Since Adam normalises by sqrt(v), the first step's size
    does not change; the clip only stops a single huge gradient spike from inflating v (and taking an lr-sized
    step in a wild direction) later on.

    The defaults are the original's energy-model optimiser: lr 1e-3, betas (0.0, 0.999), eps 1e-8. The clip is
    done in place on ``p.grad`` (like ``torch.nn.utils.clip_grad_norm_``) and the update is ``torch.optim.Adam``'s,
    so ``state_dict()``/``load_state_dict()`` round-trip and ``clip_sigma=None`` is exactly plain Adam.

    :param params: parameters or parameter groups.
    :param lr: learning rate.
    :param betas: (beta1, beta2); the original used beta1 = 0 (no momentum).
    :param eps: term added to the denominator.
    :param weight_decay: L2 penalty (0 in the original).
    :param clip_sigma: width of the clip band in standard deviations; None disables clipping (plain Adam).
    :param clip_offset: constant added to the band so that gradients are never clipped to zero (0.1).
    :param kwargs: passed to ``torch.optim.Adam`` (e.g. ``foreach``, ``maximize``).
    """

    def __init__(
        self,
        params: Iterable[torch.Tensor] | Iterable[dict[str, Any]],
        lr: float = 1e-3,
        betas: tuple[float, float] = (0.0, 0.999),
        eps: float = 1e-8,
        weight_decay: float = 0.0,
        clip_sigma: float | None = 3.0,
        clip_offset: float = 0.1,
        **kwargs: Any,
    ) -> None:
        if clip_sigma is not None and clip_sigma < 0:
            raise ValueError(f"ClippedAdam: clip_sigma must be >= 0 or None, got {clip_sigma}.")
        if clip_offset < 0:
            raise ValueError(f"ClippedAdam: clip_offset must be >= 0, got {clip_offset}.")
        if kwargs.get("amsgrad"):
            raise ValueError("ClippedAdam: amsgrad is not supported; use torch.optim.Adam for AMSGrad.")
        super().__init__(params, lr=lr, betas=betas, eps=eps, weight_decay=weight_decay, **kwargs)
        self.defaults["clip_sigma"] = clip_sigma
        self.defaults["clip_offset"] = clip_offset
        for group in self.param_groups:
            group.setdefault("clip_sigma", clip_sigma)
            group.setdefault("clip_offset", clip_offset)

    @torch.no_grad()
    def step(self, closure: Callable[[], float] | None = None) -> float | None:  # type: ignore[override]
        """
        Clip the gradients against the current second moments, then take a plain Adam step.

        :param closure: re-evaluates the model and returns the loss (optional).
        :return: the closure's loss, or None.
        """
        loss = None
        if closure is not None:
            with torch.enable_grad():
                loss = closure()
        for group in self.param_groups:
            clip_sigma = group.get("clip_sigma", self.defaults.get("clip_sigma"))
            clip_offset = group.get("clip_offset", self.defaults.get("clip_offset", 0.1))
            if clip_sigma is None:
                continue
            beta2 = group["betas"][1]
            for param in group["params"]:
                grad = param.grad
                if grad is None:
                    continue
                if grad.is_sparse:
                    raise RuntimeError("ClippedAdam does not support sparse gradients.")
                state = self.state.get(param)
                if not state:
                    grad.clamp_(-clip_offset, clip_offset)  # v_0 = 0: the band is only the offset
                    continue
                # TF's beta2_power during this step is beta2^t with t = (steps taken so far) + 1.
                bias_correction2 = 1.0 - beta2 ** (state["step"] + 1)
                bound = clip_sigma * (state["exp_avg_sq"] / bias_correction2).sqrt() + clip_offset
                torch.clamp(grad, -bound, bound, out=grad)
        adam_step = torch.optim.Adam.step
        if getattr(adam_step, "hooked", False):
            # torch wraps each optimiser class's step() with the step pre/post hooks; they already ran around this
            # step(), so call Adam's unwrapped update to not fire them twice.
            adam_step = adam_step.__wrapped__  # type: ignore[attr-defined]
        adam_step(self)
        return loss
