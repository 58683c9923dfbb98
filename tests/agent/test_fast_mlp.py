"""The planner's buffer-reusing energy evaluation gives the module's energies (exactly in float32, autocast's in bf16),
and ``autocast="auto"`` picks bf16 only where the CPU has native bf16."""

from __future__ import annotations

import pytest
import torch
from torch import nn

from ebm_agent.costs import GaussianGoalEnergy, PlanCost
from ebm_agent.energy import EnergyConfig, EnergyModel
from ebm_agent.fast_mlp import FUSED_MIN_ROWS, MAX_WORKSPACES, WorkspaceMLP
from ebm_agent.mppi import MPPIConfig, MPPIPlanner, native_bf16


@pytest.mark.parametrize("activation", ["leaky_relu", "relu", "swish", "tanh"])
@pytest.mark.parametrize("masked_dims", [(), (2,)])
def test_evaluator_equals_the_module_exactly(activation: str, masked_dims: tuple[int, ...]) -> None:
    torch.manual_seed(0)
    energy = EnergyModel(3, EnergyConfig(activation=activation), masked_dims=masked_dims)
    plans = torch.randn(2, 30, 6, 3)  # [N, K, T+1, D]: 300 transitions, enough for the fused op
    exact, fused = energy.inference_evaluator(fused=False), energy.inference_evaluator()
    assert exact is not None and fused is not None
    with torch.inference_mode():
        expected = energy(plans[..., :-1, :], plans[..., 1:, :])  # [N, K, T]
        for _ in range(2):  # the second call reuses the buffers of the first
            assert torch.equal(exact(plans[..., :-1, :], plans[..., 1:, :]), expected)
            # oneDNN's fused kernels sum in another order: float rounding, not bits.
            torch.testing.assert_close(fused(plans[..., :-1, :], plans[..., 1:, :]), expected, rtol=1e-5, atol=1e-6)


def test_outputs_are_fresh_and_buffers_are_bounded() -> None:
    torch.manual_seed(0)
    net = nn.Sequential(nn.Linear(4, 8), nn.LeakyReLU(0.2), nn.Linear(8, 1))
    mlp = WorkspaceMLP.from_sequential(net, fused=False)
    assert mlp is not None
    first_inputs, second_inputs = torch.randn(5, 4), torch.randn(5, 4)
    with torch.no_grad():
        first = mlp(first_inputs)
        kept = first.clone()
        mlp(second_inputs)  # same size: the same hidden buffers
        assert torch.equal(first, kept), "an output must not alias a buffer that the next call overwrites"
        for size in range(1, 3 * MAX_WORKSPACES):
            assert torch.equal(mlp(torch.ones(size, 4)), net(torch.ones(size, 4)))
    assert len(mlp._workspaces) <= MAX_WORKSPACES


def test_bf16_evaluator_matches_autocast() -> None:
    torch.manual_seed(0)
    energy = EnergyModel(2)
    states, next_states = torch.randn(40, 2), torch.randn(40, 2)
    evaluator = energy.inference_evaluator(torch.bfloat16)
    assert evaluator is not None
    with torch.inference_mode():
        with torch.autocast("cpu", dtype=torch.bfloat16):
            expected = energy(states, next_states)
        result = evaluator(states, next_states)
    assert result.dtype == expected.dtype == torch.bfloat16
    torch.testing.assert_close(result.float(), expected.float(), rtol=1e-2, atol=1e-2)


def test_refuses_gradients_and_unsupported_networks() -> None:
    net = nn.Sequential(nn.Linear(4, 8), nn.ReLU(), nn.Linear(8, 1))
    mlp = WorkspaceMLP.from_sequential(net)
    assert mlp is not None
    with pytest.raises(RuntimeError, match="inference only"):
        mlp(torch.ones(2, 4))
    with torch.no_grad(), pytest.raises(ValueError, match=r"inputs \[M, 4\]"):
        mlp(torch.ones(2, 3))
    assert WorkspaceMLP.from_sequential(nn.Sequential(nn.Linear(4, 8), nn.GELU(), nn.Linear(8, 1))) is None
    assert WorkspaceMLP.from_sequential(nn.Sequential(nn.Linear(4, 8), nn.ReLU())) is None
    # Spectral norm in training mode runs a power iteration per call: the planner keeps the module for it.
    normalised = EnergyModel(2, EnergyConfig(spectral_norm=True))
    assert normalised.inference_evaluator() is None
    normalised.eval()
    assert normalised.inference_evaluator() is not None


def test_planner_uses_the_evaluator_and_gives_the_module_plan() -> None:
    torch.manual_seed(0)
    energy = EnergyModel(2)
    start, goals = torch.zeros(2, 2), torch.full((2, 2), 0.5)
    config = MPPIConfig(horizon=5, num_samples=16, iterations=4, noise_scale=1e-3, autocast=None)
    planner = MPPIPlanner(config, state_dim=2)
    noise = planner.draw_noise(2, 4, torch.Generator().manual_seed(0))
    fast = planner.plan(start, goals, PlanCost(energy, GaussianGoalEnergy((0, 1))), noise=noise)
    # A plain callable is not an EnergyModel, so the planner calls it as it is.
    plain_cost = PlanCost(lambda s, n: energy(s, n), GaussianGoalEnergy((0, 1)))
    plain = planner.plan(start, goals, plain_cost, noise=noise)
    torch.testing.assert_close(fast.plans, plain.plans, rtol=0, atol=1e-6)
    torch.testing.assert_close(fast.costs, plain.costs, rtol=1e-5, atol=1e-6)


def test_float32_by_default_and_bf16_on_request() -> None:
    assert MPPIConfig().autocast is None
    assert MPPIPlanner(MPPIConfig(), state_dim=2).autocast_dtype is None
    assert MPPIPlanner(MPPIConfig(autocast="bf16"), state_dim=2).autocast_dtype == torch.bfloat16
    assert not native_bf16(torch.device("meta"))
    assert MPPIPlanner(MPPIConfig(autocast=None), state_dim=2).autocast_dtype is None
    assert MPPIPlanner(MPPIConfig(autocast="fp16"), state_dim=2).autocast_dtype == torch.float16
    with pytest.raises(ValueError, match="autocast"):
        MPPIConfig(autocast="auto")


def test_bf16_falls_back_to_buffers_when_the_fused_op_is_missing(monkeypatch) -> None:
    from ebm_agent import fast_mlp

    torch.manual_seed(0)
    energy = EnergyModel(2)
    inputs = torch.randn(FUSED_MIN_ROWS + 2, 4)  # large enough for the fused op
    mlp = WorkspaceMLP.from_sequential(energy.net, torch.bfloat16)
    assert mlp is not None
    with torch.inference_mode():
        with torch.autocast("cpu", dtype=torch.bfloat16):
            expected = energy.net(inputs).float()
        if mlp.post_ops is not None:  # this build has oneDNN's fused op: make it fail as a future torch might

            def missing(*args: object) -> None:
                raise RuntimeError("no such op")

            monkeypatch.setattr(fast_mlp, "_fused_linear", lambda: missing)
        result = mlp(inputs)
    assert mlp.post_ops is None, "after a failure the evaluator stays on the buffer path"
    torch.testing.assert_close(result.float(), expected, rtol=1e-2, atol=1e-2)


def test_action_ff_planner_uses_the_same_fast_path() -> None:
    from baselines.action_ff import ForwardDynamicsModel

    torch.manual_seed(0)
    model = ForwardDynamicsModel(3, 2, masked_dims=(2,))
    states, actions = torch.randn(4, 80, 3), torch.randn(4, 80, 2)  # [N, K, D], [N, K, A]
    fast = model.inference_evaluator()
    assert fast is not None
    with torch.no_grad():
        torch.testing.assert_close(fast(states, actions), model(states, actions), rtol=1e-5, atol=1e-6)
        assert torch.equal(fast(states, actions)[..., 2], states[..., 2])  # the target dim is copied, not predicted
