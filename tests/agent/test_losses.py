"""Training objectives (contrastive divergence, InfoNCE) and the clipped Adam optimiser."""

from __future__ import annotations

import copy
import math

import pytest
import torch

from ebm_agent.energy import EnergyConfig, EnergyModel
from ebm_agent.losses import contrastive_divergence_loss, info_nce_loss
from ebm_agent.optim import ClippedAdam


def _tiny_model() -> EnergyModel:
    torch.manual_seed(0)
    return EnergyModel(2, EnergyConfig(hidden_dim=16, num_hidden_layers=2))


def test_cd_gradient_step_lowers_positive_and_raises_negative_energy() -> None:
    model = _tiny_model()
    generator = torch.Generator().manual_seed(1)
    pos_s = torch.rand(32, 2, generator=generator) * 2 - 1
    pos_next = pos_s + 0.02  # small real moves
    neg_s = torch.rand(32, 2, generator=generator) * 2 - 1
    neg_next = neg_s + 0.6  # large impossible jumps
    optimizer = torch.optim.SGD(model.parameters(), lr=0.05)
    with torch.no_grad():
        before_pos, before_neg = model(pos_s, pos_next).mean(), model(neg_s, neg_next).mean()
    for _ in range(3):
        loss, _ = contrastive_divergence_loss(model(pos_s, pos_next), model(neg_s.detach(), neg_next.detach()), l2_coeff=0.0)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
    with torch.no_grad():
        after_pos, after_neg = model(pos_s, pos_next).mean(), model(neg_s, neg_next).mean()
    assert after_pos < before_pos
    assert after_neg > before_neg


def test_cd_keeps_the_gradient_of_the_negative_energy() -> None:
    energy_pos = torch.tensor([0.5, 1.0], requires_grad=True)
    energy_neg = torch.tensor([2.0], requires_grad=True)
    loss, _ = contrastive_divergence_loss(energy_pos, energy_neg)
    loss.backward()
    # dL/dE- = -1 + 2 E- (one negative): not detached, or the contrastive term could not raise E-.
    assert energy_neg.grad is not None
    assert energy_neg.grad.item() == pytest.approx(-1.0 + 2 * 2.0)
    torch.testing.assert_close(energy_pos.grad, torch.tensor([0.5 + 0.5, 0.5 + 1.0]))


def test_cd_loss_value_and_l2_term() -> None:
    energy_pos = torch.tensor([1.0, 2.0])
    energy_neg = torch.tensor([3.0])
    loss, stats = contrastive_divergence_loss(energy_pos, energy_neg, l2_coeff=2.0, ml_coeff=0.5)
    # ml = 1.5 - 3 = -1.5; l2 = (1 + 4) / 2 + 9 = 11.5
    assert loss.item() == pytest.approx(0.5 * -1.5 + 2.0 * 11.5)
    assert stats["loss_ml"] == pytest.approx(-1.5)
    assert stats["loss_l2"] == pytest.approx(11.5)
    assert stats["energy_pos"] == pytest.approx(1.5)
    assert stats["energy_neg"] == pytest.approx(3.0)
    assert stats["loss"] == pytest.approx(loss.item())
    assert all(isinstance(value, float) for value in stats.values())


def test_cd_rejects_empty_batches() -> None:
    with pytest.raises(ValueError, match="energy_neg is empty"):
        contrastive_divergence_loss(torch.ones(3), torch.ones(0))


def test_info_nce_with_obvious_data_is_low_and_wrong_data_is_high() -> None:
    energy_pos = torch.zeros(4)
    energy_neg = torch.full((4, 8), 10.0)
    loss, stats = info_nce_loss(energy_pos, energy_neg)
    assert loss.item() == pytest.approx(math.log(1 + 8 * math.exp(-10.0)), rel=1e-3)
    assert loss.item() < 1e-3
    assert stats["accuracy"] == 1.0
    bad_loss, bad_stats = info_nce_loss(torch.full((4,), 10.0), torch.zeros(4, 8))
    assert bad_loss.item() > 9.0
    assert bad_stats["accuracy"] == 0.0


def test_info_nce_shared_negatives_match_per_positive_negatives() -> None:
    generator = torch.Generator().manual_seed(0)
    energy_pos = torch.rand(5, generator=generator)
    shared = torch.rand(7, generator=generator)
    loss_shared, _ = info_nce_loss(energy_pos, shared)
    loss_full, _ = info_nce_loss(energy_pos, shared.expand(5, 7))
    torch.testing.assert_close(loss_shared, loss_full)
    logits = -torch.cat([energy_pos[:, None], shared.expand(5, 7)], dim=1)
    manual = -(logits.log_softmax(dim=1)[:, 0]).mean()
    torch.testing.assert_close(loss_full, manual)


def test_info_nce_rejects_bad_shapes() -> None:
    with pytest.raises(ValueError, match=r"\[B, M\]"):
        info_nce_loss(torch.zeros(4), torch.zeros(3, 8))
    with pytest.raises(ValueError, match=r"\[B\]"):
        info_nce_loss(torch.zeros(4, 1), torch.zeros(4, 8))


def _run(optimizer_cls: type[torch.optim.Optimizer], grads: list[torch.Tensor], **kwargs: object) -> tuple:
    param = torch.nn.Parameter(torch.zeros_like(grads[0]))
    optimizer = optimizer_cls([param], **kwargs)
    positions = []
    for grad in grads:
        param.grad = grad.clone()
        optimizer.step()
        positions.append(param.detach().clone())
    return positions, optimizer, param


def _gradient_stream(steps: int, size: int = 4) -> list[torch.Tensor]:
    generator = torch.Generator().manual_seed(0)
    return [torch.randn(size, generator=generator) for _ in range(steps)]


def test_clipped_adam_without_clip_matches_plain_adam() -> None:
    grads = _gradient_stream(15)
    mine, _, _ = _run(ClippedAdam, grads, clip_sigma=None)
    plain, _, _ = _run(torch.optim.Adam, grads, lr=1e-3, betas=(0.0, 0.999), eps=1e-8)
    for a, b in zip(mine, plain):
        torch.testing.assert_close(a, b, rtol=0, atol=0)


def test_clipped_adam_clips_to_three_sigma_band() -> None:
    grads = _gradient_stream(10)
    _, optimizer, param = _run(ClippedAdam, grads)
    state = optimizer.state[param]
    expected_bound = 3.0 * (state["exp_avg_sq"] / (1 - 0.999**11)).sqrt() + 0.1
    param.grad = torch.full_like(param, 1e6)
    optimizer.step()
    torch.testing.assert_close(param.grad, expected_bound, rtol=1e-4, atol=0)  # clipped in place, before the moment update


def test_clipped_adam_first_step_band_is_the_offset() -> None:
    param = torch.nn.Parameter(torch.zeros(3))
    optimizer = ClippedAdam([param])
    param.grad = torch.tensor([5.0, -5.0, 0.05])
    optimizer.step()
    torch.testing.assert_close(param.grad, torch.tensor([0.1, -0.1, 0.05]))


def test_clipped_adam_survives_a_gradient_spike_that_stalls_plain_adam() -> None:
    grads = _gradient_stream(30)
    spike = torch.full((4,), 1e6)
    after = _gradient_stream(5)
    stream = [*grads, spike, *after]
    clipped, _, _ = _run(ClippedAdam, stream)
    plain, _, _ = _run(torch.optim.Adam, stream, lr=1e-3, betas=(0.0, 0.999))
    spike_index = len(grads)
    # The spike step itself: a clipped gradient can move at most a few lr.
    clipped_spike_step = (clipped[spike_index] - clipped[spike_index - 1]).abs().max()
    assert clipped_spike_step < 5e-3
    # Afterwards plain Adam's second moment is inflated by the spike and it barely moves; the clipped one does not.
    plain_after = (plain[-1] - plain[spike_index]).abs().max()
    clipped_after = (clipped[-1] - clipped[spike_index]).abs().max()
    assert plain_after < 1e-4
    assert clipped_after > 10 * plain_after


def test_clipped_adam_state_dict_round_trip() -> None:
    grads = _gradient_stream(12)
    _, optimizer, param = _run(ClippedAdam, grads[:6], clip_sigma=2.0)
    saved = optimizer.state_dict()
    assert saved["param_groups"][0]["clip_sigma"] == 2.0
    twin_param = torch.nn.Parameter(param.detach().clone())
    twin = ClippedAdam([twin_param])
    twin.load_state_dict(copy.deepcopy(saved))  # as from torch.save/torch.load: no shared state tensors
    assert twin.param_groups[0]["clip_sigma"] == 2.0
    for grad in grads[6:]:
        for opt, p in ((optimizer, param), (twin, twin_param)):
            p.grad = grad.clone() * 50  # large enough that the clip is active
            opt.step()
    torch.testing.assert_close(twin_param, param, rtol=0, atol=0)


def test_clipped_adam_rejects_bad_options() -> None:
    with pytest.raises(ValueError, match="clip_sigma"):
        ClippedAdam([torch.nn.Parameter(torch.zeros(1))], clip_sigma=-1.0)


def test_clipped_adam_fires_step_hooks_once() -> None:
    torch.optim.Adam([torch.nn.Parameter(torch.zeros(1))])  # makes torch hook-wrap Adam.step as well
    param = torch.nn.Parameter(torch.zeros(2))
    optimizer = ClippedAdam([param])
    calls: list[str] = []
    optimizer.register_step_pre_hook(lambda *args: calls.append("pre"))
    optimizer.register_step_post_hook(lambda *args: calls.append("post"))
    param.grad = torch.ones(2)
    optimizer.step()
    assert calls == ["pre", "post"]
    assert torch.all(param < 0)


def test_the_agent_builds_its_loss_once_from_its_settings() -> None:
    import gymnasium as gym

    import envs  # noqa: F401
    from ebm_agent import EBMPlannerAgent
    from ebm_agent.losses import BatchInfoNCE, ConditionalInfoNCE, ContrastiveDivergence, make_loss

    cases = {
        ("cd", 0): (ContrastiveDivergence, None),
        ("cd", 4): (ContrastiveDivergence, "perturbed"),
        ("infonce", 0): (BatchInfoNCE, None),
        ("infonce_reach", 0): (ConditionalInfoNCE, "reach"),
        ("infonce_perturb", 4): (ConditionalInfoNCE, "perturbed"),
    }
    for (name, perturbed), (cls, contrast) in cases.items():
        loss = make_loss(name, perturbed)
        assert isinstance(loss, cls) and loss.contrast == contrast, name
    with pytest.raises(ValueError, match="loss must be one of"):
        make_loss("hinge")
    agent = EBMPlannerAgent("MultiInputPolicy", gym.make("ebm/Particle-v0"), training={"loss": "infonce_reach"}, device="cpu")
    assert isinstance(agent.loss_fn, ConditionalInfoNCE) and agent.loss_fn.contrast == "reach"


def test_the_conditional_infonce_needs_its_contrast_set() -> None:
    from ebm_agent.losses import ConditionalInfoNCE, ContrastBatch

    states = torch.zeros(3, 2)
    batch = ContrastBatch(states, states + 0.1, states, states)
    with pytest.raises(ValueError, match=r"needs batch\.candidates"):
        ConditionalInfoNCE("reach")(lambda s, t: (t - s).abs().sum(-1), batch, 1.0)
    with pytest.raises(ValueError, match="contrast must be"):
        ConditionalInfoNCE("box")
