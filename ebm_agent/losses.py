"""Training objectives for the energy model: contrastive divergence (the paper's) and InfoNCE (IBC-style options)."""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor

__all__ = ["contrastive_divergence_loss", "hard_negative_margin_loss", "info_nce_loss", "reach_candidates"]


def contrastive_divergence_loss(
    energy_pos: Tensor,
    energy_neg: Tensor,
    l2_coeff: float = 1.0,
    ml_coeff: float = 1.0,
) -> tuple[Tensor, dict[str, float]]:
    """
    The paper's Algorithm-1 objective (``objective='cd'`` in the original, ``train.py:1780-1797``).

    ``L = ml_coeff * (mean E(x+) - mean E(x-)) + l2_coeff * (mean E(x+)^2 + mean E(x-)^2)``

    The first term pushes the energy of real transitions down and that of planned (imagined) ones up; the second
    keeps energies near zero so the first cannot diverge. Positives and negatives may differ in number (means).

    What is stop-gradiented is the negative *samples* x-, not their energy: the caller must compute
    ``energy_neg = model(x_neg.detach(), x_neg_next.detach())`` so that no gradient flows back into the planner,
    while ``energy_neg`` keeps its gradient with respect to the model's parameters (without it the first term
    could not raise E(x-)). This function therefore does not detach anything.

    :param energy_pos: energies of real transitions, any shape (e.g. [P]).
    :param energy_neg: energies of planned transitions, any shape (e.g. [N]).
    :param l2_coeff: weight of the energy-magnitude regulariser (1.0 in the original).
    :param ml_coeff: weight of the contrastive term (1.0 in the original).
    :return: the scalar loss and floats ``{"energy_pos", "energy_neg", "loss", "loss_ml", "loss_l2"}`` for logging.
    :raises ValueError: for an empty batch.
    """
    _check_nonempty(energy_pos, "energy_pos")
    _check_nonempty(energy_neg, "energy_neg")
    mean_pos = energy_pos.mean()
    mean_neg = energy_neg.mean()
    loss_ml = mean_pos - mean_neg
    loss_l2 = energy_pos.square().mean() + energy_neg.square().mean()
    loss = ml_coeff * loss_ml + l2_coeff * loss_l2
    stats = {
        "energy_pos": float(mean_pos.detach()),
        "energy_neg": float(mean_neg.detach()),
        "loss": float(loss.detach()),
        "loss_ml": float(loss_ml.detach()),
        "loss_l2": float(loss_l2.detach()),
    }
    return loss, stats


def hard_negative_margin_loss(
    energy_failed: Tensor, energy_real: Tensor, margin: float = 1.0
) -> tuple[Tensor, dict[str, float]]:
    """
    Ranking term of the failed plan steps (``OnlineConfig.hard_negatives``, issue #34):
    ``mean softplus(margin - (E(s, s'_plan) - E(s, s'_real)))``.

    Each failed step (s, s'_plan), a move the env refused, is paired with the real transition (s, s'_real) from the
    same state; the term wants the failed one at least ``margin`` higher and fades (softly) once it is. Both
    energies keep their gradients: the pair's gap is what is trained, not either energy's level (the contrastive
    loss's L2 term sets the level).

    :param energy_failed: [H] energies of the failed steps E(s, s'_plan).
    :param energy_real: [H] energies of the real transitions from the same states E(s, s'_real).
    :param margin: wanted gap (>= 0).
    :return: the scalar term and floats ``{"energy_failed", "energy_failed_real", "loss_hard", "num_failed"}``.
    :raises ValueError: for an empty batch or mismatched shapes.
    """
    _check_nonempty(energy_failed, "energy_failed")
    if energy_failed.shape != energy_real.shape:
        raise ValueError(
            f"energy_failed and energy_real must pair up (same shape), got {tuple(energy_failed.shape)} and "
            f"{tuple(energy_real.shape)}."
        )
    term = F.softplus(margin - (energy_failed - energy_real)).mean()
    stats = {
        "energy_failed": float(energy_failed.detach().mean()),
        "energy_failed_real": float(energy_real.detach().mean()),
        "loss_hard": float(term.detach()),
        "num_failed": float(energy_failed.numel()),
    }
    return term, stats


def info_nce_loss(energy_pos: Tensor, energy_neg: Tensor, temperature: float = 1.0) -> tuple[Tensor, dict[str, float]]:
    """
    InfoNCE over energies (as in Implicit BC): cross-entropy of ``softmax(-E / temperature)`` picking the positive.

    An improvement over the paper, off by default. Each positive competes with its own M negatives
    (``energy_neg`` of shape [B, M]) or with M negatives shared by the whole batch (shape [M]).

    :param energy_pos: [B] energies of real transitions.
    :param energy_neg: [B, M] per-positive negatives, or [M] shared negatives.
    :param temperature: softmax temperature (> 0).
    :return: the scalar loss and floats ``{"energy_pos", "energy_neg", "loss", "accuracy"}``, where accuracy is the
        fraction of positives whose energy is below all of their negatives'.
    :raises ValueError: for bad shapes, an empty batch or a non-positive temperature.
    """
    _check_nonempty(energy_pos, "energy_pos")
    _check_nonempty(energy_neg, "energy_neg")
    if energy_pos.ndim != 1:
        raise ValueError(f"info_nce_loss: energy_pos must have shape [B], got {tuple(energy_pos.shape)}.")
    if temperature <= 0:
        raise ValueError(f"info_nce_loss: temperature must be > 0, got {temperature}.")
    batch = energy_pos.shape[0]
    if energy_neg.ndim == 1:
        energy_neg = energy_neg.unsqueeze(0).expand(batch, -1)  # [M] -> [B, M] shared negatives
    elif energy_neg.ndim != 2 or energy_neg.shape[0] != batch:
        raise ValueError(
            f"info_nce_loss: energy_neg must have shape [B, M] with B={batch} or [M], got {tuple(energy_neg.shape)}."
        )
    energies = torch.cat([energy_pos.unsqueeze(1), energy_neg], dim=1)  # [B, 1 + M], positive in column 0
    logits = -energies / temperature
    target = torch.zeros(batch, dtype=torch.long, device=logits.device)
    loss = F.cross_entropy(logits, target)
    accuracy = (energy_pos.unsqueeze(1) < energy_neg).all(dim=1).float().mean()
    stats = {
        "energy_pos": float(energy_pos.detach().mean()),
        "energy_neg": float(energy_neg.detach().mean()),
        "loss": float(loss.detach()),
        "accuracy": float(accuracy),
    }
    return loss, stats


def reach_candidates(states: Tensor, radius: Tensor, num_candidates: int, generator: torch.Generator | None = None) -> Tensor:
    """
    Candidate next states drawn uniformly in the one-step reach box around each state: ``s + U(-r, r)^D``.

    The contrast set of the ``loss="infonce_reach"`` objective (Implicit BC's counter-examples, here over next
    states): with the real s' as the positive among them, InfoNCE makes ``E(s, s')`` approximate
    ``-log p(s' | s)`` up to a constant per s. A candidate through a wall has p = 0, so the energy must rise there;
    a feasible candidate is no worse than the real s', so the energy stays flat over what the env can reach. The
    box is not clipped to the state bounds: leaving the box is infeasible too, and the energy should learn it.

    :param states: [B, D] real states s.
    :param radius: [D] half-width r of the box (the largest real |s' - s| per dim).
    :param num_candidates: K candidates per state.
    :param generator: the random stream (on the states' device), or None for torch's global one.
    :return: [B, K, D] candidate next states.
    """
    if num_candidates < 1:
        raise ValueError(f"reach_candidates: num_candidates must be >= 1, got {num_candidates}.")
    shape = (states.shape[0], num_candidates, states.shape[1])
    noise = torch.rand(shape, generator=generator, device=states.device, dtype=states.dtype) * 2 - 1  # [B, K, D]
    return states[:, None, :] + noise * radius.to(states.dtype)


def _check_nonempty(energy: Tensor, name: str) -> None:
    if not isinstance(energy, Tensor):
        raise TypeError(f"{name} must be a torch.Tensor, got {type(energy).__name__}.")
    if energy.numel() == 0:
        raise ValueError(f"{name} is empty; the loss needs at least one transition on each side.")
