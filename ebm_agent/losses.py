"""Training objectives for the energy model: contrastive divergence (the paper's) and InfoNCE (IBC-style options)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import Tensor

__all__ = [
    "BatchInfoNCE",
    "ConditionalInfoNCE",
    "ContrastBatch",
    "ContrastiveDivergence",
    "EnergyLoss",
    "contrastive_divergence_loss",
    "hard_negative_margin_loss",
    "info_nce_loss",
    "make_loss",
    "reach_candidates",
]


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


Energy = Callable[[Tensor, Tensor], Tensor]
"""E(s [..., D], s' [..., D]) -> [...]: the energy model being trained."""


@dataclass
class ContrastBatch:
    """The tensors of one gradient step of the energy.

    :param states: [P, D] real states s.
    :param next_states: [P, D] their real next states s'.
    :param neg_states: [M, D] planned states (the planned negatives; the batch's own for ``infonce``).
    :param neg_next: [M, D] their planned next states.
    :param candidates: [P, K, D] the contrast next states of each real s (the reach box's, or perturbed real s'), or
        None where the loss uses none (:attr:`EnergyLoss.contrast`).
    :param hard: the failed plan steps, (s [H, D], s'_plan [H, D], s'_real [H, D]), or None.
    """

    states: Tensor
    next_states: Tensor
    neg_states: Tensor
    neg_next: Tensor
    candidates: Tensor | None = None
    hard: tuple[Tensor, Tensor, Tensor] | None = None


class EnergyLoss:
    """A training objective of the energy, built once per agent: ``loss(energy, batch, l2_coeff) -> (loss, stats)``.

    ``contrast`` says which contrast set the caller must draw into ``batch.candidates``: ``"reach"`` (uniform in the
    one-step reach box, :func:`reach_candidates`), ``"perturbed"`` (near misses of the real s') or None.
    """

    contrast: str | None = None

    def __call__(self, energy: Energy, batch: ContrastBatch, l2_coeff: float) -> tuple[Tensor, dict[str, float]]:
        """The scalar loss and its statistics (floats, ``energy_pos`` and ``energy_neg`` among them)."""
        raise NotImplementedError


class ContrastiveDivergence(EnergyLoss):
    """The paper's CD loss (:func:`contrastive_divergence_loss`) over the real and the planned transitions.

    :param perturbed: add the perturbed near misses of the real s' as a second CD term on the same positives, so
        that planned and perturbed negatives weigh equally whatever their numbers:
        ``L = E+ - (E-_plan + E-_pert) / 2 + l2 (...)``.
    :param hard_negative_loss: how the failed plan steps enter (when the batch has them): ``"margin"``, a ranking
        term (:func:`hard_negative_margin_loss`) added with ``hard_negative_weight``; ``"negatives"``, among the
        negatives with weight ``hard_negative_weight`` each, in the contrastive and the L2 term.
    :param hard_negative_weight: the weight of the failed steps.
    :param hard_negative_margin: the margin of ``"margin"``.
    """

    def __init__(
        self,
        perturbed: bool = False,
        hard_negative_loss: str = "margin",
        hard_negative_weight: float = 1.0,
        hard_negative_margin: float = 1.0,
    ) -> None:
        self.perturbed = perturbed
        self.contrast = "perturbed" if perturbed else None
        self.hard_negative_loss = hard_negative_loss
        self.hard_negative_weight = float(hard_negative_weight)
        self.hard_negative_margin = float(hard_negative_margin)

    def __call__(self, energy: Energy, batch: ContrastBatch, l2_coeff: float) -> tuple[Tensor, dict[str, float]]:
        """See :class:`EnergyLoss`."""
        energy_pos = energy(batch.states, batch.next_states)  # [P]
        energy_neg = energy(batch.neg_states, batch.neg_next)  # [M]
        if self.perturbed:
            if batch.candidates is None:
                raise ValueError("a perturbed CD loss needs batch.candidates: [P, K, D] perturbed next states")
            energy_perturbed = energy(batch.states[:, None, :].expand_as(batch.candidates), batch.candidates)  # [P, K]
            loss, stats = contrastive_divergence_loss(energy_pos, energy_neg, l2_coeff=l2_coeff)
            mean_perturbed = energy_perturbed.mean()
            loss = 0.5 * loss + 0.5 * (
                energy_pos.mean() - mean_perturbed + l2_coeff * (energy_pos.square().mean() + energy_perturbed.square().mean())
            )
            stats.update(energy_perturbed=float(mean_perturbed.detach()), loss=float(loss.detach()))
            return loss, stats
        hard = batch.hard
        if hard is not None and self.hard_negative_loss == "negatives":
            return self._with_hard_negatives(energy_pos, energy_neg, energy(hard[0], hard[1]), l2_coeff)
        loss, stats = contrastive_divergence_loss(energy_pos, energy_neg, l2_coeff=l2_coeff)
        if hard is not None and self.hard_negative_loss == "margin":
            energy_failed = energy(hard[0], hard[1])  # [H]
            energy_real = energy(hard[0], hard[2])  # [H]
            term, hard_stats = hard_negative_margin_loss(energy_failed, energy_real, self.hard_negative_margin)
            loss = loss + self.hard_negative_weight * term
            stats.update(hard_stats, loss=float(loss.detach()))
        return loss, stats

    def _with_hard_negatives(
        self, energy_pos: Tensor, energy_neg: Tensor, energy_failed: Tensor, l2_coeff: float
    ) -> tuple[Tensor, dict[str, float]]:
        """CD with the failed steps among the negatives: E(x-) the weighted mean over the planned negatives (weight 1
        each) and the failed steps (``hard_negative_weight`` each), in both terms.

        :param energy_pos: [P] energies of the real transitions.
        :param energy_neg: [M] energies of the planned transitions.
        :param energy_failed: [H] energies of the failed steps (s, s'_plan).
        :param l2_coeff: weight of the L2 term.
        :return: the scalar loss and its statistics (``energy_failed`` and ``num_failed`` added).
        """
        weights = torch.cat([torch.ones_like(energy_neg), torch.full_like(energy_failed, self.hard_negative_weight)])
        weights = weights / weights.sum()  # [M + H]
        negatives = torch.cat([energy_neg, energy_failed])  # [M + H]
        mean_pos, mean_neg = energy_pos.mean(), (weights * negatives).sum()
        loss_ml = mean_pos - mean_neg
        loss_l2 = energy_pos.square().mean() + (weights * negatives.square()).sum()
        loss = loss_ml + l2_coeff * loss_l2
        stats = {
            "energy_pos": float(mean_pos.detach()),
            "energy_neg": float(mean_neg.detach()),
            "energy_failed": float(energy_failed.detach().mean()),
            "num_failed": float(len(energy_failed)),
            "loss": float(loss.detach()),
            "loss_ml": float(loss_ml.detach()),
            "loss_l2": float(loss_l2.detach()),
        }
        return loss, stats


class BatchInfoNCE(EnergyLoss):
    """InfoNCE of each real transition against the batch's planned negatives (:func:`info_nce_loss`); no L2 term."""

    def __call__(self, energy: Energy, batch: ContrastBatch, l2_coeff: float) -> tuple[Tensor, dict[str, float]]:
        """See :class:`EnergyLoss` (``l2_coeff`` unused)."""
        energy_pos = energy(batch.states, batch.next_states)  # [P]
        return info_nce_loss(energy_pos, energy(batch.neg_states, batch.neg_next))


class ConditionalInfoNCE(EnergyLoss):
    """InfoNCE of each real (s, s') against K contrast next states of the same s, plus ``l2_coeff`` x mean E(s, s')^2.

    InfoNCE fixes E(s, .) only up to a constant per s; pinning the real transitions' energy to 0 makes energies
    comparable across states (without it the per-state offset swamps the walls: AUROC ~0.53).

    :param contrast: ``"reach"`` (``loss="infonce_reach"``) or ``"perturbed"`` (``loss="infonce_perturb"``).
    """

    def __init__(self, contrast: str) -> None:
        if contrast not in ("reach", "perturbed"):
            raise ValueError(f"contrast must be 'reach' or 'perturbed', got {contrast!r}.")
        self.contrast = contrast

    def __call__(self, energy: Energy, batch: ContrastBatch, l2_coeff: float) -> tuple[Tensor, dict[str, float]]:
        """See :class:`EnergyLoss`."""
        if batch.candidates is None:
            raise ValueError(f"a conditional InfoNCE loss needs batch.candidates: [P, K, D] {self.contrast} next states")
        energy_pos = energy(batch.states, batch.next_states)  # [P]
        energy_neg = energy(batch.states[:, None, :].expand_as(batch.candidates), batch.candidates)  # [P, K]
        loss, stats = info_nce_loss(energy_pos, energy_neg)
        anchor = energy_pos.square().mean()
        loss = loss + l2_coeff * anchor
        stats.update(loss_anchor=float(anchor.detach()), loss=float(loss.detach()))
        return loss, stats


def make_loss(
    name: str,
    perturbed_negatives: int = 0,
    hard_negative_loss: str = "margin",
    hard_negative_weight: float = 1.0,
    hard_negative_margin: float = 1.0,
) -> EnergyLoss:
    """The loss object of an agent's ``loss`` argument.

    :param name: ``"cd"``, ``"infonce"``, ``"infonce_reach"`` or ``"infonce_perturb"``.
    :param perturbed_negatives: > 0: the CD loss adds the perturbed negatives' term.
    :param hard_negative_loss: how CD takes the failed plan steps (``OnlineConfig.hard_negative_loss``).
    :param hard_negative_weight: their weight.
    :param hard_negative_margin: the margin of ``"margin"``.
    :return: the loss.
    :raises ValueError: for an unknown name.
    """
    if name == "cd":
        return ContrastiveDivergence(perturbed_negatives > 0, hard_negative_loss, hard_negative_weight, hard_negative_margin)
    if name == "infonce":
        return BatchInfoNCE()
    if name in ("infonce_reach", "infonce_perturb"):
        return ConditionalInfoNCE("reach" if name == "infonce_reach" else "perturbed")
    raise ValueError(f"loss must be one of ('cd', 'infonce', 'infonce_reach', 'infonce_perturb'), got {name!r}.")
