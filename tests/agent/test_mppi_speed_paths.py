"""MPPI speed paths: the reused candidate buffer, block-drawn noise, chunked scoring, autocast, torch.compile and CUDA
give the plans of the plain computation (exactly, or within the stated tolerance); no timing is asserted here."""

from __future__ import annotations

import copy
import pickle

import pytest
import torch
from torch import Tensor, nn
from torch.utils._python_dispatch import TorchDispatchMode

from ebm_agent import mppi
from ebm_agent.config import make_config
from ebm_agent.costs import AccelerationPrior, BoxObstacleEnergy, GaussianGoalEnergy, PlanCost, VelocityPrior
from ebm_agent.energy import EnergyModel
from ebm_agent.mppi import MPPIConfig, MPPIPlanner, softmax_average
from ebm_agent.planner import clip_states, initial_plan

HORIZON = 10


def reference_plan(planner: MPPIPlanner, start: Tensor, goals: Tensor, cost: PlanCost, noise: Tensor) -> Tensor:
    """
    The MPPI loop written plainly: a fresh cat of the pinned start into every candidate, every iteration.

    Its energy runs on the same kernels as the planner's (oneDNN's fused layers where available), so that a
    difference can only come from the loop; tests/agent/test_fast_mlp.py compares those kernels with the module.
    """
    if isinstance(cost.transition_energy, EnergyModel):
        cost = copy.copy(cost)
        cost.transition_energy = cost.transition_energy.inference_evaluator()
    with torch.inference_mode():
        return _reference_loop(planner, start, goals, cost, noise).clone()


def _reference_loop(planner: MPPIPlanner, start: Tensor, goals: Tensor, cost: PlanCost, noise: Tensor) -> Tensor:
    config = planner.config
    mean = initial_plan(start, planner.horizon)
    # The planner clips the initial plan's s_1..s_T to the bounds (the pinned start stays where it is).
    mean = torch.cat([mean[:, :1], clip_states(mean[:, 1:], planner.state_low, planner.state_high)], dim=1)
    for perturbation in noise:  # [N, K, T, D]
        mean_tail = mean[:, 1:]
        tails = clip_states(mean_tail[:, None] + perturbation, planner.state_low, planner.state_high)
        if config.include_mean:
            tails = torch.cat([mean_tail[:, None], tails], dim=1)
        starts = mean[:, None, :1].expand(-1, tails.shape[1], -1, -1)
        costs = cost(torch.cat([starts, tails], dim=2), goals)  # [N, K]
        new_tail = softmax_average(costs, tails, mean_tail, config.temperature, planner.state_low, planner.state_high)
        mean = torch.cat([mean[:, :1], new_tail], dim=1)
    return mean


def energy_problem(state_dim: int = 3, num_envs: int = 3) -> tuple[Tensor, Tensor, PlanCost]:
    torch.manual_seed(0)
    energy = EnergyModel(state_dim)
    start = 0.3 * torch.rand(num_envs, state_dim, generator=torch.Generator().manual_seed(1))
    goals = torch.full((num_envs, 2), 0.4)
    extras = [VelocityPrior(0.1), AccelerationPrior(0.01), BoxObstacleEnergy((0.1, 0.1), (0.2, 0.2))]
    return start, goals, PlanCost(energy, GaussianGoalEnergy((0, 1), weight=10.0), extras)


@pytest.mark.parametrize(
    ("include_mean", "bounds", "num_samples"),
    [(False, "both", 16), (True, "both", 16), (False, "high", 7), (True, None, 13)],
)
def test_plan_equals_the_plain_loop_exactly(include_mean: bool, bounds: str | None, num_samples: int) -> None:
    start, goals, cost = energy_problem()
    limits = {"both": {"state_low": [-0.5] * 3, "state_high": [0.5] * 3}, "high": {"state_high": [0.2] * 3}, None: {}}
    config = MPPIConfig(
        horizon=HORIZON, num_samples=num_samples, iterations=5, noise_scale=1e-3, include_mean=include_mean, autocast=None
    )
    planner = MPPIPlanner(config, state_dim=3, **limits[bounds])
    noise = planner.draw_noise(3, 5, torch.Generator().manual_seed(0))  # [I, N, K, T, D]
    result = planner.plan(start, goals, cost, noise=noise)
    expected = reference_plan(planner, start, goals, cost, noise)
    assert torch.equal(result.plans, expected)
    if bounds == "high":
        assert result.plans[:, 1:].max() <= 0.2  # the pinned start is never clipped


@pytest.mark.parametrize("block_bytes", [mppi.NOISE_BLOCK_BYTES, 3 * 16 * HORIZON * 3 * 4 * 2])
def test_same_seed_same_plan_and_batched_equals_each_env_alone(monkeypatch, block_bytes: int) -> None:
    # The second size draws the noise in blocks of 2 iterations (5 = 2 + 2 + 1) instead of all 5 at once.
    monkeypatch.setattr(mppi, "NOISE_BLOCK_BYTES", block_bytes)
    start, goals, cost = energy_problem()
    planner = MPPIPlanner(
        MPPIConfig(horizon=HORIZON, num_samples=16, iterations=5, noise_scale=1e-3, autocast=None), state_dim=3
    )
    seeded = planner.plan(start, goals, cost, generator=torch.Generator().manual_seed(5))
    noise = planner.draw_noise(3, 5, torch.Generator().manual_seed(5))
    assert noise.shape == (5, 3, 16, HORIZON, 3)
    assert torch.equal(planner.plan(start, goals, cost, noise=noise).plans, seeded.plans)
    assert not torch.equal(planner.draw_noise(3, 5, torch.Generator().manual_seed(6)), noise)
    for env in range(3):
        alone = planner.plan(start[env : env + 1], goals[env : env + 1], cost, noise=noise[:, env : env + 1])
        torch.testing.assert_close(alone.plans[0], seeded.plans[env], rtol=0, atol=1e-6)


def test_chunked_scoring_matches_one_call() -> None:
    start, goals, cost = energy_problem()
    config = dict(horizon=HORIZON, num_samples=50, iterations=4, noise_scale=1e-3, autocast=None)
    calls: list[int] = []

    def counting_cost(plans: Tensor, goals: Tensor | None) -> Tensor:
        calls.append(plans.shape[1])
        return cost(plans, goals)

    whole = MPPIPlanner(MPPIConfig(**config, chunk_transitions=0), state_dim=3)
    chunked = MPPIPlanner(MPPIConfig(**config, chunk_transitions=3 * 8 * HORIZON), state_dim=3)  # 8 candidates a call
    noise = whole.draw_noise(3, 4, torch.Generator().manual_seed(0))
    expected = whole.plan(start, goals, counting_cost, noise=noise)  # type: ignore[arg-type]
    assert calls[:4] == [50] * 4
    calls.clear()
    result = chunked.plan(start, goals, counting_cost, noise=noise)  # type: ignore[arg-type]
    assert calls[:7] == [8, 8, 8, 8, 8, 8, 2]
    torch.testing.assert_close(result.plans, expected.plans, rtol=0, atol=1e-6)


class DtypeSpy(nn.Module):
    """Wraps an energy and records the dtype its first layer computes in."""

    def __init__(self, energy: EnergyModel) -> None:
        super().__init__()
        self.energy = energy
        self.dtypes: list[torch.dtype] = []

    def forward(self, states: Tensor, next_states: Tensor) -> Tensor:
        self.dtypes.append(self.energy.net[0](torch.cat([states, next_states], dim=-1)).dtype)
        return self.energy(states, next_states)


def test_bf16_autocast_is_close_to_float32() -> None:
    start, goals, cost = energy_problem()
    spy = DtypeSpy(cost.transition_energy)  # type: ignore[arg-type]
    cost.transition_energy = spy
    config = dict(horizon=HORIZON, num_samples=64, iterations=40, noise_scale=1e-3)
    generator_seed = 3
    plain = MPPIPlanner(MPPIConfig(**config, autocast=None), state_dim=3).plan(
        start, goals, cost, generator=torch.Generator().manual_seed(generator_seed)
    )
    assert set(spy.dtypes) == {torch.float32}
    spy.dtypes.clear()
    fast = MPPIPlanner(MPPIConfig(**config, autocast="bf16"), state_dim=3).plan(
        start, goals, cost, generator=torch.Generator().manual_seed(generator_seed)
    )
    assert spy.dtypes[:-1] and set(spy.dtypes[:-1]) == {torch.bfloat16}, "the loop's energy should run in bf16"
    assert spy.dtypes[-1] == torch.float32, "the reported cost is computed in float32"
    assert fast.plans.dtype == torch.float32 and fast.costs.dtype == torch.float32
    assert torch.equal(fast.plans[:, 0], start)
    initial = cost(initial_plan(start, HORIZON)[:, None], goals)[:, 0]
    # The random energy has several minima, so bf16 rounding can send an env to another one: compare plan quality
    # (the float32 cost of each plan), not the states. Both improve on doing nothing, bf16 within 25% of float32.
    assert torch.all(plain.costs < 0.7 * initial) and torch.all(fast.costs < 0.7 * initial)
    assert torch.all(fast.costs < 1.25 * plain.costs), (fast.costs, plain.costs)


def test_compile_path_matches_eager_and_is_not_pickled() -> None:
    start, goals, cost = energy_problem(state_dim=2, num_envs=2)
    options = {"backend": "aot_eager"}  # dynamo tracing without code generation: fast, same kernels as eager
    config = dict(horizon=HORIZON, num_samples=16, iterations=3, noise_scale=1e-3)
    eager = MPPIPlanner(MPPIConfig(**config, autocast=None), state_dim=2)
    compiled = MPPIPlanner(MPPIConfig(**config, compile=True, compile_options=options, autocast=None), state_dim=2)
    noise = eager.draw_noise(2, 3, torch.Generator().manual_seed(0))
    expected = eager.plan(start, goals, cost, noise=noise)
    result = compiled.plan(start, goals, cost, noise=noise)
    torch.testing.assert_close(result.plans, expected.plans, rtol=0, atol=1e-6)
    assert compiled._compiled_energy is not None and compiled._compiled_energy[0] is cost.transition_energy
    wrapper = compiled._compiled_energy[1]
    compiled.plan(start, goals, cost, noise=noise)
    assert compiled._compiled_energy[1] is wrapper, "the compiled energy is reused across plans"
    restored = pickle.loads(pickle.dumps(compiled))
    assert restored._compiled_energy is None and restored._compiled_mix is None
    torch.testing.assert_close(restored.plan(start, goals, cost, noise=noise).plans, expected.plans, rtol=0, atol=1e-6)


@pytest.mark.slow
def test_inductor_compile_is_close_to_eager() -> None:
    start, goals, cost = energy_problem(state_dim=2, num_envs=2)
    config = dict(horizon=HORIZON, num_samples=32, iterations=10, noise_scale=1e-3, temperature=1e-2)
    eager = MPPIPlanner(MPPIConfig(**config, autocast=None), state_dim=2)
    compiled = MPPIPlanner(MPPIConfig(**config, compile=True, autocast=None), state_dim=2)
    noise = eager.draw_noise(2, 10, torch.Generator().manual_seed(0))
    torch.testing.assert_close(
        compiled.plan(start, goals, cost, noise=noise).plans,
        eager.plan(start, goals, cost, noise=noise).plans,
        atol=1e-4,
        rtol=0,
    )


class HostSyncRecorder(TorchDispatchMode):
    """Records the ops that read a tensor back to the host (a CUDA stream sync when the tensor is on the GPU)."""

    SYNCING = ("_local_scalar_dense", "item", "is_nonzero", "nonzero", "equal")

    def __init__(self) -> None:
        super().__init__()
        self.syncs: list[str] = []

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):  # type: ignore[no-untyped-def]
        if func.__name__.split(".")[0] in self.SYNCING:
            self.syncs.append(str(func))
        return func(*args, **(kwargs or {}))


DEVICES = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("autocast", [None, "bf16"])
def test_the_planning_loop_never_reads_back_to_the_host(autocast: str | None, device: str) -> None:
    start, goals, cost = energy_problem()
    cost.transition_energy.to(device)  # type: ignore[union-attr]
    start, goals = start.to(device), goals.to(device)
    config = dict(horizon=HORIZON, num_samples=16, include_mean=True, autocast=autocast, chunk_transitions=200)
    syncs = {}
    for iterations in (1, 6):
        planner = MPPIPlanner(MPPIConfig(**config, iterations=iterations), 3, [-1.0] * 3, [1.0] * 3, device=device)
        generator = torch.Generator(device=device).manual_seed(0)
        with HostSyncRecorder() as recorder:
            planner.plan(start, goals, cost, generator=generator)
        syncs[iterations] = recorder.syncs
    # Input validation at the boundary may read back once per plan; the iterations must add nothing.
    assert syncs[6] == syncs[1], syncs
    with HostSyncRecorder() as recorder:  # the recorder does see a host read
        bool((start > 0).any())
    assert recorder.syncs


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
def test_cuda_plan_matches_cpu() -> None:
    start, goals, cost = energy_problem()
    config = MPPIConfig(horizon=HORIZON, num_samples=32, iterations=5, noise_scale=1e-3, autocast=None)
    cpu = MPPIPlanner(config, state_dim=3, state_low=[-1.0] * 3, state_high=[1.0] * 3)
    noise = cpu.draw_noise(3, 5, torch.Generator().manual_seed(0))
    expected = cpu.plan(start, goals, cost, noise=noise)
    gpu = MPPIPlanner(config, state_dim=3, state_low=[-1.0] * 3, state_high=[1.0] * 3, device="cuda")
    cost.transition_energy.to("cuda")  # type: ignore[union-attr]
    result = gpu.plan(start.cuda(), goals.cuda(), cost, noise=noise.cuda())
    torch.testing.assert_close(result.plans.cpu(), expected.plans, rtol=0, atol=1e-4)
    seeded = gpu.plan(start.cuda(), goals.cuda(), cost, generator=torch.Generator(device="cuda").manual_seed(0))
    assert seeded.plans.device.type == "cuda" and torch.equal(seeded.plans[:, 0].cpu(), start)


def test_speed_options_are_validated_and_reach_the_config() -> None:
    config = make_config(MPPIConfig, {"compile": True, "autocast": "bf16", "chunk_transitions": 0}, "planner_config")
    assert config.compile and config.autocast == "bf16" and config.chunk_transitions == 0
    with pytest.raises(ValueError, match="autocast"):
        MPPIConfig(autocast="int8")
    with pytest.raises(TypeError, match="compile"):
        MPPIConfig(compile="yes")  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="compile_options"):
        MPPIConfig(compile_options=["max-autotune"])  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="chunk_transitions"):
        MPPIConfig(chunk_transitions=-1)


def test_the_chunk_benchmark_times_every_chunk_size_it_is_given():
    from benchmarks.planner import bench_chunks

    medians = bench_chunks(2, 8, 5, 1, chunks=(16, 0), repeats=1, compare=False)
    assert set(medians) == {"16", "0"} and all(value > 0 for value in medians.values())
