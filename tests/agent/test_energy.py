"""Energy model and MLP builder: shapes, the original's architecture quirks, masking and spectral norm."""

from __future__ import annotations

import pytest
import torch
from torch import nn

from ebm_agent.energy import EnergyConfig, EnergyModel, PeriodicFeatures
from ebm_agent.networks import build_mlp


def test_build_mlp_layout_and_init() -> None:
    net = build_mlp(4, 1, hidden_dim=128, num_hidden_layers=3)
    linears = [m for m in net if isinstance(m, nn.Linear)]
    assert [(lin.in_features, lin.out_features) for lin in linears] == [(4, 128), (128, 128), (128, 128), (128, 1)]
    activations = [m for m in net if isinstance(m, nn.LeakyReLU)]
    assert len(activations) == 3 and all(act.negative_slope == 0.2 for act in activations)
    assert all(torch.all(lin.bias == 0) for lin in linears)
    # Xavier-uniform bound for the 128 x 128 layer is sqrt(6 / 256) ~ 0.153.
    bound = (6.0 / 256) ** 0.5
    assert linears[1].weight.abs().max() <= bound
    assert linears[1].weight.abs().max() > 0.9 * bound


@pytest.mark.parametrize(("name", "cls"), [("relu", nn.ReLU), ("swish", nn.SiLU), ("silu", nn.SiLU)])
def test_build_mlp_activations(name: str, cls: type[nn.Module]) -> None:
    net = build_mlp(3, 2, hidden_dim=8, num_hidden_layers=2, activation=name, out_bias=False)
    assert sum(isinstance(m, cls) for m in net) == 2
    assert net[-1].bias is None


def test_build_mlp_rejects_unknown_activation() -> None:
    with pytest.raises(ValueError, match="leaky_relu"):
        build_mlp(3, 2, activation="gelu2")


def test_energy_shape_for_leading_dims_in_one_call() -> None:
    torch.manual_seed(0)
    model = EnergyModel(3)
    calls = []
    model.net.register_forward_hook(lambda module, inputs, output: calls.append(inputs[0].shape))
    states = torch.randn(2, 5, 4, 3)  # [N, K, T, D]
    next_states = torch.randn(2, 5, 4, 3)
    energies = model(states, next_states)
    assert energies.shape == (2, 5, 4)
    assert calls == [torch.Size([40, 6])]  # one batched network call
    # Same numbers as evaluating one transition at a time.
    single = model(states[1, 3, 2], next_states[1, 3, 2])
    assert single.shape == ()
    torch.testing.assert_close(energies[1, 3, 2], single)


def test_energy_input_is_concatenation_not_difference() -> None:
    torch.manual_seed(0)
    model = EnergyModel(2)
    states = torch.tensor([[0.1, 0.2]])
    shifted = states + 0.5
    # Same difference s' - s, different absolute states: a difference-based model would give equal energies.
    assert not torch.allclose(model(states, states + 0.05), model(shifted, shifted + 0.05))


def test_positive_output_layer_is_bias_free_with_nonnegative_weights() -> None:
    torch.manual_seed(0)
    model = EnergyModel(2)
    layer = model.output_layer
    assert layer.bias is None
    raw = layer.parametrizations.weight.original
    with torch.no_grad():
        raw.copy_(-torch.rand_like(raw) - 0.1)  # all raw weights negative
    assert torch.all(layer.weight >= 0)
    torch.testing.assert_close(layer.weight, raw.abs())
    # The energy is the last hidden features times |W|.
    states, next_states = torch.randn(7, 2), torch.randn(7, 2)
    features = model.net[:-1](torch.cat([states, next_states], dim=-1))
    torch.testing.assert_close(model(states, next_states), (features @ raw.abs().T).squeeze(-1))


def test_output_layer_without_positive_output_has_bias() -> None:
    model = EnergyModel(2, EnergyConfig(positive_output=False))
    assert model.output_layer.bias is not None
    assert not hasattr(model.output_layer, "parametrizations")


def test_masked_dims_do_not_change_the_energy() -> None:
    torch.manual_seed(0)
    model = EnergyModel(5, masked_dims=(-2, -1))
    assert model.masked_dims == (3, 4)
    states, next_states = torch.randn(6, 5), torch.randn(6, 5)
    base = model(states, next_states)
    other_states, other_next = states.clone(), next_states.clone()
    other_states[:, 3:] = torch.randn(6, 2) * 10
    other_next[:, 3:] = torch.randn(6, 2) * 10
    torch.testing.assert_close(model(other_states, other_next), base)
    other_next[:, 0] += 1.0  # an unmasked dim does change it
    assert not torch.allclose(model(states, other_next), base)


def test_energy_is_differentiable_in_the_states() -> None:
    model = EnergyModel(2)
    states = torch.zeros(4, 2, requires_grad=True)
    next_states = torch.full((4, 2), 0.3, requires_grad=True)
    model(states, next_states).sum().backward()
    assert next_states.grad is not None and torch.all(torch.isfinite(next_states.grad))
    assert next_states.grad.abs().sum() > 0


def test_spectral_norm_option_runs_and_normalises_hidden_layers() -> None:
    torch.manual_seed(0)
    model = EnergyModel(3, EnergyConfig(spectral_norm=True, activation="swish"))
    states, next_states = torch.randn(16, 3), torch.randn(16, 3)
    for _ in range(30):  # one power iteration per training-mode forward pass
        energies = model(states, next_states)
    assert energies.shape == (16,) and torch.all(torch.isfinite(energies))
    hidden = [m for m in model.net[:-1] if isinstance(m, nn.Linear)]
    for layer in hidden:
        assert torch.linalg.matrix_norm(layer.weight.detach(), ord=2) == pytest.approx(1.0, abs=0.05)
    assert torch.all(model.output_layer.weight >= 0)


def test_energy_rejects_bad_inputs() -> None:
    model = EnergyModel(2)
    with pytest.raises(ValueError, match=r"\[\.\.\., 2\]"):
        model(torch.zeros(4, 3), torch.zeros(4, 3))
    with pytest.raises(ValueError, match="same shape"):
        model(torch.zeros(4, 2), torch.zeros(5, 2))
    with pytest.raises(TypeError, match="floating"):
        model(torch.zeros(4, 2, dtype=torch.long), torch.zeros(4, 2, dtype=torch.long))
    with pytest.raises(ValueError, match="out of range"):
        EnergyModel(2, masked_dims=(2,))
    with pytest.raises(ValueError, match="activation"):
        EnergyConfig(activation="nope")


def test_energy_state_dict_round_trip() -> None:
    torch.manual_seed(0)
    model = EnergyModel(4, masked_dims=(3,))
    clone = EnergyModel(4, masked_dims=(3,))
    clone.load_state_dict(model.state_dict())
    states, next_states = torch.randn(5, 4), torch.randn(5, 4)
    torch.testing.assert_close(clone(states, next_states), model(states, next_states))


# ------------------------------------------------------------------------------------------------ periodic inputs
def test_periodic_features_put_the_periodic_dims_on_the_circle() -> None:
    features = PeriodicFeatures(4, (0, 1), period=2.0)
    states = torch.tensor([[0.5, -1.0, 0.3, -0.2]])
    out = features(states)  # [1, 6]
    assert out.shape == (1, 6) and features.feature_dim == 6
    expected = torch.tensor([[1.0, 0.0, 0.3, -0.2, 0.0, -1.0]])  # sin(pi/2), sin(-pi), v1, v2, cos(pi/2), cos(-pi)
    torch.testing.assert_close(out, expected, atol=1e-6, rtol=0)
    # Across the wrap: 0.999 and -0.999 are neighbours, and a whole period changes nothing.
    near = features(torch.tensor([[0.999, 0.0, 0.0, 0.0], [-0.999, 0.0, 0.0, 0.0], [2.999, 0.0, 0.0, 0.0]]))
    assert (near[0] - near[1]).abs().max() < 0.01
    torch.testing.assert_close(near[0], near[2], atol=1e-5, rtol=0)
    with pytest.raises(ValueError, match="period"):
        PeriodicFeatures(4, (0,), period=0.0)


def test_periodic_energy_sees_whole_periods_as_the_same_state() -> None:
    torch.manual_seed(0)
    energy = EnergyModel(4, periodic_dims=[0, 1], period=2.0)
    assert energy.net[0].in_features == 12 and energy.feature_dim == 6
    states, next_states = torch.rand(5, 4) * 2 - 1, torch.rand(5, 4) * 2 - 1
    turned = next_states.clone()
    turned[:, :2] += torch.tensor([2.0, -2.0])
    torch.testing.assert_close(energy(states, next_states), energy(states, turned), atol=1e-5, rtol=1e-5)
    # The velocity dims are not periodic: moving them by 2 changes the energy.
    moved = next_states.clone()
    moved[:, 2] += 2.0
    assert not torch.allclose(energy(states, next_states), energy(states, moved))


def test_periodic_inputs_can_be_turned_off_for_the_original_raw_angles() -> None:
    energy = EnergyModel(4, EnergyConfig(periodic_inputs=False), periodic_dims=[0, 1])
    assert energy.features is None and energy.net[0].in_features == 8


def test_masking_a_periodic_dim_masks_its_sin_and_cos() -> None:
    torch.manual_seed(0)
    energy = EnergyModel(3, masked_dims=[1], periodic_dims=[1])
    states, next_states = torch.rand(6, 3), torch.rand(6, 3)
    other = states.clone()
    other[:, 1] = torch.rand(6)
    torch.testing.assert_close(energy(states, next_states), energy(other, next_states))


@pytest.mark.parametrize("masked", [(), (2,)])
def test_the_inference_evaluator_matches_the_module_with_periodic_inputs(masked: tuple[int, ...]) -> None:
    torch.manual_seed(0)
    energy = EnergyModel(4, masked_dims=masked, periodic_dims=[0, 1]).eval()
    states, next_states = torch.rand(3, 40, 4) * 4 - 2, torch.rand(3, 40, 4) * 4 - 2  # [N, K, D], past the wrap
    with torch.inference_mode():
        expected = energy(states, next_states)
        evaluator = energy.inference_evaluator(fused=False)
        assert evaluator is not None
        torch.testing.assert_close(evaluator(states, next_states), expected, atol=0, rtol=0)
        bound = evaluator.bind(states, next_states)
        torch.testing.assert_close(bound(), expected, atol=0, rtol=0)
        fused = energy.inference_evaluator(fused=True)
        assert fused is not None
        torch.testing.assert_close(fused(states, next_states), expected, atol=1e-5, rtol=1e-5)


def test_configs_pickled_before_periodic_inputs_existed_keep_raw_inputs() -> None:
    import pickle

    state = dict(EnergyConfig().__dict__)
    del state["periodic_inputs"]  # what a file saved by an earlier version holds
    old = EnergyConfig.__new__(EnergyConfig)
    old.__setstate__(state)
    assert old.periodic_inputs is False
    assert pickle.loads(pickle.dumps(EnergyConfig())).periodic_inputs is True
