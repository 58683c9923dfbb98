"""MPPI over state trajectories with smooth STOMP perturbations (paper Eq. 1 and Sec. 3.2; original ``mppi_step``).

Each iteration perturbs the current mean plan's states s_1..s_T (the start is pinned) with K smooth noise samples,
scores all N x K candidates with one cost call, and moves the mean to their softmax(-cost / temperature) average.
The whole iteration is batched over envs, candidates and time, and nothing in the loop reads a tensor back to the
host, so on CUDA the iterations queue up without synchronising.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from torch import Tensor

from ebm_agent.bound_cost import bind_cost
from ebm_agent.config import check_field_types
from ebm_agent.costs import PlanCost
from ebm_agent.energy import EnergyModel
from ebm_agent.planner import PlanResult, as_bounds, clip_states, initial_plan, validate_plan_inputs
from ebm_agent.stomp import StompNoise

__all__ = [
    "AUTOCAST_DTYPES",
    "CPU_CHUNK_TRANSITIONS",
    "NOISE_BLOCK_BYTES",
    "NOISE_UNITS",
    "MPPIConfig",
    "MPPIPlanner",
    "native_bf16",
    "softmax_average",
]

AUTOCAST_DTYPES: dict[str, torch.dtype] = {"bf16": torch.bfloat16, "fp16": torch.float16}
"""Names accepted by ``MPPIConfig.autocast`` and the dtype the cost's matmuls then run in."""

NOISE_BLOCK_BYTES = 16 * 2**20
"""The noise of several iterations is drawn in one call when it fits in this many bytes (one randn + one matmul
instead of one per iteration); larger problems draw it iteration by iteration."""

CPU_CHUNK_TRANSITIONS = 4096
"""Default ``MPPIConfig.chunk_transitions`` on CPU: candidates are scored about 4,096 transitions per cost call. Each
chunk costs ~15 small ops besides the energy's matmuls, so small chunks pay that overhead many times, while one call
on everything (81,920 rows) was 2-3x slower per transition (fresh multi-MB buffers page-fault). 4,096 was the fastest
of 1,024 / 2,048 / 4,096 / 8,192 on all 7 large problems timed (D in {2, 20}, K in {256, 1024}, T in {20, 80}, 10
iterations; 10-35% faster than 1,024): ``python -m benchmarks --quick --chunks 1024 2048 4096 8192``, docs/benchmarks.md.
The agent's default plan (K=80, T=10: 800 transitions) is one chunk either way. It was 1,024 before 2026-12-02, when
fused layers measured 2x slower per transition from 2,048 rows on; on 2026-12-02 they were not (the chunk table of
docs/benchmarks.md). Chunking only splits the matmuls by rows: on the benchmark machine the plans of 20 iterations
were bit for bit the same with chunks of 1,024, 4,096 and none (N x K x T of 64 x 80 x 10, 1 x 1024 x 20, 8 x 80 x 40),
so the recorded figures that plan many envs at once are unchanged."""

CostFn = Callable[[Tensor, Tensor | None], Tensor]

NOISE_UNITS = ("state", "step")
"""Values of ``MPPIConfig.noise_units``."""


@dataclass
class MPPIConfig:
    """
    Settings of the MPPI planner; the defaults are the original code's (README command: T=10 flag default, K=80,
    80 iterations for every plan). ``ebm_agent.presets.FAST_EBM`` keeps K, T and the 80 iterations of an evaluation
    plan but spends 20 on a fresh plan while learning and 3 on a warm-started one, never returning a warm-started
    plan worse than its warm start: 5-15x cheaper learning, the same scores on the particle and the maze, lower
    ones on the Sawyer (docs/benchmarks.md, docs/results.md), so it is opt-in.

    :param horizon: T, the number of planned transitions.
    :param num_samples: K, the candidate plans per env and iteration (the original's noise_sim).
    :param iterations: MPPI iterations per plan (the original's num_plan_steps).
    :param temperature: lambda in softmax(-cost / lambda); the original hard-coded cost * 10000, i.e. 1e-4, which is
        close to picking the best candidate.
    :param noise_scale: c in N(0, c (A^T A)^-1), in the unit of ``noise_units``.
    :param noise_units: the unit of the perturbations: ``"state"`` (the default, the original's), the env's own state
        units, the same noise on every dim; ``"step"``, each dim's perturbation multiplied by that dim's measured real
        step (the agent sets :attr:`MPPIPlanner.noise_unit` from the largest real |s' - s| per dim it has learnt
        from, as ``OnlineConfig.threshold_units="step"`` does), so that ``noise_scale`` is in squared steps and a dim
        that barely moves (FetchReach's fingers, 4e-4 a step) is not perturbed as much as one that moves 0.03. Until
        a real move is recorded the noise is in state units.
    :param terminal_first_difference: keep the original's terminal first-difference row in the STOMP matrix.
    :param include_mean: also score the current mean as a candidate (the original did not), so the mean can only
        be replaced by a candidate that is at least as good when the temperature is low.
    :param compile: ``torch.compile`` the transition energy and the softmax-averaging step on first use. The first
        plan then pays the compilation (15-25 s on CPU); later plans reuse it. Off by default: on the benchmark
        machines it gave no consistent gain (docs/benchmarks.md).
    :param compile_options: keyword arguments of ``torch.compile`` (e.g. ``{"mode": "max-autotune"}`` or
        ``{"backend": "aot_eager"}``), or None for its defaults; only used with ``compile=True``.
    :param chunk_transitions: score the candidates in chunks along K of about this many transitions (N x k x T)
        per cost call; None picks ``CPU_CHUNK_TRANSITIONS`` on CPU and no chunking on other devices, 0 disables it.
        Chunking changes nothing but the batch size of the energy's matmuls (results agree to float rounding).
    :param autocast: ``"bf16"`` or ``"fp16"`` to evaluate the cost under ``torch.autocast`` (the energy's matmuls
        in that dtype, the sums over time, the softmax and the plan itself in float32), or None (the default) for
        float32. bf16 keeps about 3 significant digits of each energy, coarse next to the default temperature of
        1e-4: on random problems the plans' float32 costs move less than with another seed (docs/benchmarks.md), but
        a particle agent trained for 2,000 transitions scored -27 in bf16 against -4.6 in float32 (its last
        centimetre to the goal is below bf16's resolution), so it is opt-in. 1.5-3x faster on CPUs with native bf16
        (AVX512-BF16 or AMX, see :func:`native_bf16`). The final cost of a plan is always computed in float32.
    :param warm_iterations: iterations of a plan warm-started from a previous one (``init_plan`` given, e.g. the
        last plan shifted by the steps executed; at most ``iterations``), or None to run ``iterations`` for every
        plan (the original). A warm start is already near a good plan, so a few iterations refine it: pytorch_mppi
        runs one per control step, mbrl-lib's CEM five. An explicit ``iterations`` argument of
        :meth:`MPPIPlanner.plan` overrides both.
    :param train_iterations: iterations of a fresh (not warm-started) plan made while the agent learns (at most
        ``iterations``), or None for ``iterations``. ``iterations`` stays the budget of every plan made by
        ``predict`` (evaluation), so that a cheaper training loop does not change how a trained agent is evaluated.
        The planner reads it only through the agent, which passes it as ``iterations``.
    :param keep_warm_start: for each env whose iterations ended on a costlier plan than its warm start, return the
        warm start itself, so that a warm-started plan is never worse (by the plan cost) than the shifted plan it
        started from. One extra cost evaluation of N plans per warm-started plan. Off in the original.
    :param stop_tolerance: stop iterating once no env's plan cost fell by more than this over the last
        ``stop_check`` iterations (None: run every iteration, as the original). Each check evaluates the cost of
        the N current plans and reads it back to the host.
    :param stop_check: iterations between two early-stop checks.
    """

    horizon: int = 10
    num_samples: int = 80
    iterations: int = 80
    temperature: float = 1e-4
    noise_scale: float = 1e-5
    noise_units: str = "state"
    terminal_first_difference: bool = True
    include_mean: bool = False
    compile: bool = False
    compile_options: dict[str, Any] | None = None
    chunk_transitions: int | None = None
    autocast: str | None = None
    warm_iterations: int | None = None
    train_iterations: int | None = None
    keep_warm_start: bool = False
    stop_tolerance: float | None = None
    stop_check: int = 5

    def __post_init__(self) -> None:
        check_field_types(self)
        for name in ("horizon", "num_samples"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"MPPIConfig.{name} must be an int >= 1, got {value!r}.")
        if isinstance(self.iterations, bool) or not isinstance(self.iterations, int) or self.iterations < 0:
            raise ValueError(f"MPPIConfig.iterations must be an int >= 0, got {self.iterations!r}.")
        if not self.temperature > 0:
            raise ValueError(f"MPPIConfig.temperature must be > 0, got {self.temperature}; the original used 1e-4.")
        if self.noise_units not in NOISE_UNITS:
            raise ValueError(f"MPPIConfig.noise_units must be one of {NOISE_UNITS}, got {self.noise_units!r}.")
        if not self.noise_scale > 0:
            raise ValueError(f"MPPIConfig.noise_scale must be > 0, got {self.noise_scale}; the original used 1e-5.")
        if not isinstance(self.compile, bool):
            raise TypeError(f"MPPIConfig.compile must be True or False, got {self.compile!r}.")
        if self.compile_options is not None and not isinstance(self.compile_options, dict):
            raise TypeError(
                f"MPPIConfig.compile_options must be a dict of torch.compile keyword arguments or None, "
                f"got {type(self.compile_options).__name__}."
            )
        chunk = self.chunk_transitions
        if chunk is not None and (isinstance(chunk, bool) or not isinstance(chunk, int) or chunk < 0):
            raise ValueError(
                f"MPPIConfig.chunk_transitions must be None (automatic), 0 (no chunking) or an int > 0, got {chunk!r}."
            )
        for name in ("warm_iterations", "train_iterations"):
            value = getattr(self, name)
            if value is not None and (isinstance(value, bool) or not isinstance(value, int) or value < 0):
                raise ValueError(f"MPPIConfig.{name} must be None (use iterations) or an int >= 0, got {value!r}.")
        if self.stop_tolerance is not None and not self.stop_tolerance >= 0:
            raise ValueError(f"MPPIConfig.stop_tolerance must be None (no early stop) or >= 0, got {self.stop_tolerance!r}.")
        if isinstance(self.stop_check, bool) or not isinstance(self.stop_check, int) or self.stop_check < 1:
            raise ValueError(f"MPPIConfig.stop_check must be an int >= 1, got {self.stop_check!r}.")
        if self.autocast is not None and self.autocast not in AUTOCAST_DTYPES:
            raise ValueError(
                f"MPPIConfig.autocast must be None (float32) or one of {sorted(AUTOCAST_DTYPES)}, got {self.autocast!r}."
            )


class MPPIPlanner:
    """
    Model Predictive Path Integral planning in state space (implements ``Planner``).

    :param config: the planner settings.
    :param state_dim: D, the number of state dims.
    :param state_low: lower state bounds [D] that candidates and the mean are clipped to (the original clipped to
        [-1, 1] for every env but the arm), or None.
    :param state_high: upper state bounds [D], or None.
    :param device: device to plan on.
    """

    def __init__(
        self,
        config: MPPIConfig,
        state_dim: int,
        state_low: np.ndarray | Tensor | None = None,
        state_high: np.ndarray | Tensor | None = None,
        device: str | torch.device = "cpu",
    ) -> None:
        if not isinstance(config, MPPIConfig):
            raise TypeError(f"config must be an MPPIConfig, got {type(config).__name__}.")
        if isinstance(state_dim, bool) or not isinstance(state_dim, int) or state_dim < 1:
            raise ValueError(f"state_dim must be an int >= 1, got {state_dim!r}.")
        self.config = config
        self.horizon = config.horizon
        self.state_dim = state_dim
        self.device = torch.device(device)
        self.noise = StompNoise(config.horizon, config.noise_scale, config.terminal_first_difference, device=self.device)
        # [D] per-dim multiplier of the perturbations (``noise_units="step"``: the measured real step), or None.
        self.noise_unit: Tensor | None = None
        self.state_low, self.state_high = as_bounds(state_low, state_high, state_dim, self.device)
        # Compiled callables, built on first use; not pickled (the agent saves the planner with the model).
        self._compiled_energy: tuple[object, Callable[..., Tensor]] | None = None
        self._compiled_mix: Callable[..., Tensor] | None = None

    def plan(
        self,
        start: Tensor,
        goals: Tensor | None,
        cost: PlanCost,
        init_plan: Tensor | None = None,
        generator: torch.Generator | None = None,
        iterations: int | None = None,
        noise: Tensor | None = None,
    ) -> PlanResult:
        """
        Plan from each env's start by MPPI.

        :param start: start states [N, D].
        :param goals: goals [N, G], or None when the cost has no goal energy.
        :param cost: the cost of candidate plans; it is evaluated without gradients.
        :param init_plan: warm start [N, T+1, D], or None to start with every state at the start. Its first state is
            replaced by ``start``.
        :param generator: random generator on the planner's device; the same seed gives the same plan.
        :param iterations: override ``config.iterations``.
        :param noise: pre-drawn perturbations [I, N, K, T, D] to use instead of sampling (for tests and
            reproducibility across batch sizes, see :meth:`draw_noise`); I is then the number of iterations.
        :return: the plans [N, T+1, D] with ``plans[:, 0] == start``, their costs [N], and the iterations run.
        """
        validate_plan_inputs(start, goals, init_plan, self.horizon, self.state_dim, iterations)
        config = self.config
        num_envs = start.shape[0]
        warm = init_plan is not None
        if iterations is not None:
            num_iterations = iterations
        elif warm and config.warm_iterations is not None:
            num_iterations = min(config.warm_iterations, config.iterations)
        else:
            num_iterations = config.iterations
        if noise is not None:
            expected = (num_envs, config.num_samples, self.horizon, self.state_dim)
            if noise.ndim != 5 or tuple(noise.shape[1:]) != expected:
                raise ValueError(f"noise must be [I, N, K, T, D] with (N, K, T, D) = {expected}, got {tuple(noise.shape)}.")
            if iterations is not None and iterations != noise.shape[0]:
                raise ValueError(f"iterations={iterations} disagrees with the {noise.shape[0]} noise draws given.")
            num_iterations = noise.shape[0]
        with torch.inference_mode():
            start = start.to(self.device)
            goals = None if goals is None else goals.to(self.device)
            mean = initial_plan(start, self.horizon) if init_plan is None else init_plan.to(self.device, start.dtype).clone()
            mean[:, 0] = start
            mean[:, 1:] = clip_states(mean[:, 1:], self.state_low, self.state_high)
            keep = warm and config.keep_warm_start
            warm_start = mean.clone() if keep else None  # [N, T+1, D]
            warm_costs = cost(mean[:, None], goals)[:, 0] if keep else None  # [N]
            candidates = self._candidate_buffer(start)  # [N, K', T+1, D]
            iterate = self._iteration(mean, candidates, goals, self._fast_cost(cost))
            if config.stop_tolerance is None or noise is not None:
                # One transfer of user noise before the loop rather than one per iteration.
                blocks = (
                    self._noise_blocks(num_envs, num_iterations, generator) if noise is None else iter([noise.to(self.device)])
                )
                for block in blocks:  # [B, N, K, T, D] noise of B iterations
                    for perturbation in block.to(start.dtype):
                        iterate(perturbation)
            else:
                num_iterations = self._iterate_until_stalled(mean, goals, cost, iterate, num_iterations, generator)
            final_costs = cost(mean[:, None], goals)[:, 0]  # [N], at full precision whatever the autocast
            if keep:
                assert warm_start is not None and warm_costs is not None
                worse = final_costs > warm_costs  # [N]
                mean = torch.where(worse[:, None, None], warm_start, mean)
                final_costs = torch.where(worse, warm_costs, final_costs)
        # Cloning outside inference mode gives ordinary tensors that the agent may later feed to a trained energy.
        return PlanResult(plans=mean.clone(), costs=final_costs.clone(), iterations=num_iterations)

    def _iterate_until_stalled(
        self,
        mean: Tensor,
        goals: Tensor | None,
        cost: PlanCost,
        iterate: Callable[[Tensor], None],
        iterations: int,
        generator: torch.Generator | None,
    ) -> int:
        """Run up to ``iterations`` MPPI iterations on ``mean`` [N, T+1, D], stopping early once no plan improves.

        Every ``stop_check`` iterations the plans' costs [N] are evaluated; when none fell by more than
        ``stop_tolerance`` since the last check, the loop ends. The noise is drawn one check's worth at a time.

        :return: the number of iterations run.
        """
        config = self.config
        assert config.stop_tolerance is not None
        previous = cost(mean[:, None], goals)[:, 0]  # [N]
        done = 0
        while done < iterations:
            size = min(config.stop_check, iterations - done)
            for block in self._noise_blocks(mean.shape[0], size, generator):  # [B, N, K, T, D]
                for perturbation in block.to(mean.dtype):
                    iterate(perturbation)
            done += size
            current = cost(mean[:, None], goals)[:, 0]  # [N]
            if not bool(((previous - current) > config.stop_tolerance).any()):
                break
            previous = current
        return done

    def draw_noise(self, num_envs: int, iterations: int, generator: torch.Generator | None = None) -> Tensor:
        """
        The perturbations ``plan`` draws from ``generator`` for ``num_envs`` envs, drawn the same way.

        ``plan(..., noise=draw_noise(N, I, generator_seeded_s))`` equals ``plan(..., generator=generator_seeded_s)``;
        slicing its env axis gives the noise of planning each env alone.

        :param num_envs: N.
        :param iterations: I.
        :param generator: random generator on the planner's device.
        :return: perturbations [I, N, K, T, D].
        """
        empty = torch.empty(0, num_envs, self.config.num_samples, self.horizon, self.state_dim, device=self.device)
        return torch.cat([empty, *self._noise_blocks(num_envs, iterations, generator)])

    def update(self, mean: Tensor, perturbation: Tensor, goals: Tensor | None, cost: PlanCost) -> Tensor:
        """
        One MPPI iteration: perturb, clip, score, and average the candidates by softmax(-cost / temperature).

        :param mean: current plans [N, T+1, D]; ``mean[:, 0]`` is the pinned start.
        :param perturbation: noise on states s_1..s_T [N, K, T, D].
        :param goals: goals [N, G] or None.
        :param cost: the cost of candidate plans.
        :return: the new plans [N, T+1, D], with the same start.
        """
        new_mean = mean.clone()  # [N, T+1, D]
        candidates = self._candidate_buffer(mean[:, 0])
        self._iteration(new_mean, candidates, goals, self._fast_cost(cost))(perturbation.to(mean.dtype))
        return new_mean

    def to(self, device: str | torch.device) -> MPPIPlanner:
        """
        Move the planner's noise factor and bounds to another device (in place).

        :param device: the target device.
        :return: this planner.
        """
        self.device = torch.device(device)
        self.noise.to(self.device)
        self.state_low = None if self.state_low is None else self.state_low.to(self.device)
        self.state_high = None if self.state_high is None else self.state_high.to(self.device)
        return self

    @property
    def autocast_dtype(self) -> torch.dtype | None:
        """The dtype the cost's matmuls run in during the iterations (None: float32)."""
        return None if self.config.autocast is None else AUTOCAST_DTYPES[self.config.autocast]

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_compiled_energy"] = None
        state["_compiled_mix"] = None
        return state

    # ------------------------------------------------------------------ helpers
    def _iteration(self, mean: Tensor, candidates: Tensor, goals: Tensor | None, cost_fn: CostFn) -> Callable[[Tensor], None]:
        """
        One MPPI iteration as a function of the perturbation [N, K, T, D] that updates ``mean`` [N, T+1, D] in place.

        Perturb, clip, score, and average the candidates by softmax(-cost / temperature). The views of ``mean`` and of
        the reused candidate buffer [N, K', T+1, D] and the bound cost (ebm_agent/bound_cost.py) are made once here,
        not in each of the plan's iterations; ``candidates[:, :, 0]`` must hold the start already.
        """
        mean_tail = mean[:, 1:]  # [N, T, D]
        mean_tails = mean_tail[:, None]  # [N, 1, T, D]
        candidate_tails = candidates[:, :, 1:]  # [N, K', T, D] view
        first = 1 if self.config.include_mean else 0
        # Writing into the buffer replaces the per-iteration cat that pinned the start to every candidate.
        sampled = candidate_tails[:, first:]  # [N, K, T, D]
        mean_slot = candidate_tails[:, 0] if first else None  # [N, T, D]
        clip = self.state_low is not None or self.state_high is not None
        low = None if self.state_low is None else self.state_low.to(sampled.dtype)
        high = None if self.state_high is None else self.state_high.to(sampled.dtype)
        score = self._bound_score(cost_fn, candidates, goals)
        mix = self._mix_fn()
        temperature, dtype = self.config.temperature, mean.dtype

        def iterate(perturbation: Tensor) -> None:
            torch.add(mean_tails, perturbation, out=sampled)
            if clip:
                sampled.clamp_(min=low, max=high)
            if mean_slot is not None:
                mean_slot.copy_(mean_tail)
            costs = score().to(dtype)  # [N, K']
            mean_tail.copy_(mix(costs, candidate_tails, mean_tail, temperature, self.state_low, self.state_high))

        return iterate

    def _bound_score(self, cost_fn: CostFn, candidates: Tensor, goals: Tensor | None) -> Callable[[], Tensor]:
        """The costs [N, K'] of the buffer's current candidates, in chunks along K' when the problem is large."""
        limit = self.config.chunk_transitions
        if limit is None:
            limit = CPU_CHUNK_TRANSITIONS if candidates.device.type == "cpu" else 0
        num_envs, num_candidates = candidates.shape[:2]
        per_chunk = max(1, limit // max(num_envs * self.horizon, 1))  # no env at all: one (empty) chunk
        if limit == 0 or per_chunk >= num_candidates:
            return bind_cost(cost_fn, candidates, goals)
        chunks = [
            bind_cost(cost_fn, candidates[:, first : first + per_chunk], goals)
            for first in range(0, num_candidates, per_chunk)
        ]
        return lambda: torch.cat([chunk() for chunk in chunks], dim=1)

    def _candidate_buffer(self, start: Tensor) -> Tensor:
        num_candidates = self.config.num_samples + int(self.config.include_mean)
        shape = (start.shape[0], num_candidates, self.horizon + 1, self.state_dim)
        candidates = torch.empty(shape, device=start.device, dtype=start.dtype)  # [N, K', T+1, D]
        candidates[:, :, 0] = start[:, None]
        return candidates

    def _noise_blocks(self, num_envs: int, iterations: int, generator: torch.Generator | None) -> Iterator[Tensor]:
        """Perturbations [B, N, K, T, D] for B iterations at a time; the blocking depends only on the shapes."""
        per_iteration = num_envs * self.config.num_samples * self.horizon * self.state_dim * self.noise.dtype.itemsize
        block = max(1, min(iterations, NOISE_BLOCK_BYTES // max(per_iteration, 1)))
        for first in range(0, iterations, block):
            size = min(block, iterations - first)
            sample = self.noise.sample((size, num_envs, self.config.num_samples), self.state_dim, generator)
            unit = getattr(self, "noise_unit", None)  # absent in planners pickled before step units existed
            yield sample if unit is None else sample.mul_(unit.to(sample.device, sample.dtype))

    def _fast_cost(self, cost: PlanCost) -> CostFn:
        """The cost as evaluated inside the loop: with the compiled transition energy and under autocast if set."""
        cost_fn: CostFn = cost
        energy = getattr(cost, "transition_energy", None)
        autocast = self.autocast_dtype
        use_buffers = not (self.config.compile or torch.is_grad_enabled())
        evaluator = energy.inference_evaluator(autocast) if use_buffers and isinstance(energy, EnergyModel) else None
        if evaluator is not None and isinstance(cost, PlanCost):
            # The same energies (autocast's, in bf16) without an allocation per layer and chunk (ebm_agent/fast_mlp.py);
            # the goal and prior terms are elementwise, so autocast would not have changed them.
            fast = copy.copy(cost)
            fast.transition_energy = evaluator
            return fast
        if self.config.compile and isinstance(cost, PlanCost) and energy is not None:
            if self._compiled_energy is None or self._compiled_energy[0] is not energy:
                self._compiled_energy = (energy, torch.compile(energy, **(self.config.compile_options or {})))
            # A shallow copy shares the goal energy, priors and prior_scale; only the transition energy is swapped.
            fast = copy.copy(cost)
            fast.transition_energy = self._compiled_energy[1]
            cost_fn = fast
        if autocast is None:
            return cost_fn
        device_type, dtype = self.device.type, autocast
        inner = cost_fn

        def autocast_cost(plans: Tensor, goals: Tensor | None) -> Tensor:
            with torch.autocast(device_type=device_type, dtype=dtype):
                return inner(plans, goals)

        return autocast_cost

    def _mix_fn(self) -> Callable[..., Tensor]:
        if not self.config.compile:
            return softmax_average
        if self._compiled_mix is None:
            self._compiled_mix = torch.compile(softmax_average, **(self.config.compile_options or {}))
        return self._compiled_mix


def native_bf16(device: torch.device) -> bool:
    """
    Whether ``autocast="bf16"`` runs on native bf16 dot products on this device: a CPU with AVX512-BF16 or AMX tiles.

    :param device: the planner's device.
    :return: True on such a CPU; False on others and on every non-CPU device.
    """
    if device.type != "cpu":
        return False
    probes = ("_is_avx512_bf16_supported", "_is_amx_tile_supported")
    try:
        return any(bool(getattr(torch.cpu, name)()) for name in probes if hasattr(torch.cpu, name))
    except RuntimeError:  # a torch build without the CPU feature probes
        return False


def softmax_average(
    costs: Tensor, candidate_tails: Tensor, mean_tail: Tensor, temperature: float, low: Tensor | None, high: Tensor | None
) -> Tensor:
    """
    The MPPI mean update: the candidates averaged with weights softmax(-cost / temperature), clipped to the bounds.

    :param costs: candidate costs [N, K].
    :param candidate_tails: candidate states s_1..s_T [N, K, T, D].
    :param mean_tail: current mean's s_1..s_T [N, T, D], kept by an env whose costs are all non-finite.
    :param temperature: lambda > 0.
    :param low: lower state bounds [D] or None.
    :param high: upper state bounds [D] or None.
    :return: the new mean's s_1..s_T [N, T, D].
    """
    # A NaN or infinite cost (e.g. an energy that blew up) gets zero weight instead of poisoning the average.
    scaled = torch.nan_to_num(costs, nan=math.inf, posinf=math.inf, neginf=math.inf).mul_(-1.0 / temperature)  # [N, K]
    weights = torch.softmax(scaled, dim=1)  # [N, K]; NaN for an env whose costs are all non-finite
    # A broadcast product and a sum over K; a batched matmul would be a few microseconds faster but sums in another
    # order, and the README's 2,000-transition agent scored -26 instead of -4.6 with that rounding (1 thread).
    new_tail = (weights[:, :, None, None] * candidate_tails).sum(dim=1)  # [N, T, D]
    new_tail = clip_states(new_tail, low, high)
    # An env whose candidates all have non-finite costs keeps its mean (a device-side select, no host sync).
    return torch.where(torch.isnan(new_tail), mean_tail, new_tail)
