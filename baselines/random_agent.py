"""Random-exploration agent: uniform random actions behind the Stable-Baselines3 algorithm API.

It is the reference of the exploration experiments (paper Sec. 4.4: maze coverage, Sawyer finger voxel occupancy)
and the "random policy" sanity anchor of every table. Like sb3-contrib's ARS it subclasses ``BaseAlgorithm``, so
``evaluate_policy``, ``EvalCallback``, ``CheckpointCallback``, ``save``/``load``, ``set_env`` and TensorBoard run
folders behave as for PPO.
"""

from __future__ import annotations

import hashlib
import sys
import time
from typing import Any, ClassVar, TypeVar

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.type_aliases import GymEnv, MaybeCallback
from stable_baselines3.common.utils import safe_mean
from stable_baselines3.common.vec_env import VecEnv

from ebm_agent.exploration import count_occupied_cells

SelfRandomAgent = TypeVar("SelfRandomAgent", bound="RandomAgent")


class RandomPolicy(BasePolicy):
    """A policy without parameters that samples uniform actions from a seeded torch generator.

    With ``deterministic=True`` the action is a fixed function of (seed, observation): the same observation always
    gets the same uniformly distributed action, so deterministic evaluation is reproducible without being constant.

    :param observation_space: observation space (any; only its batch size is used).
    :param action_space: ``Box`` (uniform on [low, high]) or ``Discrete``.
    :param seed: seed of the generator (``None``: drawn from torch's global generator).
    :param kwargs: passed to ``BasePolicy`` (feature-extractor settings are accepted and unused).
    """

    def __init__(
        self,
        observation_space: spaces.Space,
        action_space: spaces.Space,
        seed: int | None = None,
        **kwargs: Any,
    ) -> None:
        super().__init__(observation_space, action_space, **kwargs)
        if not isinstance(action_space, (spaces.Box, spaces.Discrete)):
            raise TypeError(f"RandomPolicy supports Box and Discrete action spaces, got {action_space}.")
        self.seed = seed
        self.generator = th.Generator()
        self.generator.manual_seed(seed if seed is not None else int(th.randint(0, 2**62, (1,)).item()))

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()
        data["seed"] = self.seed
        return data

    def sample_actions(self, n: int) -> np.ndarray:
        """Draw ``n`` uniform actions from the policy's generator.

        :param n: number of actions.
        :return: actions [n, *action_shape] (int64 [n] for ``Discrete``).
        """
        if isinstance(self.action_space, spaces.Discrete):
            draws = th.randint(0, int(self.action_space.n), (n,), generator=self.generator)
            return (draws + int(self.action_space.start)).numpy()
        assert isinstance(self.action_space, spaces.Box)
        unit = th.rand((n, *self.action_space.shape), generator=self.generator, dtype=th.float64).numpy()
        return self._scale(unit)

    def _predict(self, observation: th.Tensor | dict[str, th.Tensor], deterministic: bool = False) -> th.Tensor:
        rows = _observation_rows(observation)  # [n, obs_bytes] one flat row per observation of the batch
        if not deterministic:
            return th.as_tensor(self.sample_actions(len(rows)))
        actions = [self._action_for(row) for row in rows]
        return th.as_tensor(np.stack(actions))

    def _action_for(self, row: np.ndarray) -> np.ndarray:
        # A hash of (seed, observation bytes) seeds a one-off generator: same observation -> same action.
        digest = hashlib.blake2b(row.tobytes(), digest_size=8, key=str(self.seed).encode()).digest()
        rng = np.random.default_rng(int.from_bytes(digest, "little"))
        if isinstance(self.action_space, spaces.Discrete):
            return np.asarray(rng.integers(0, int(self.action_space.n)) + int(self.action_space.start))
        return self._scale(rng.random(self.action_space.shape))

    def _scale(self, unit: np.ndarray) -> np.ndarray:
        assert isinstance(self.action_space, spaces.Box)
        low, high = self.action_space.low.astype(np.float64), self.action_space.high.astype(np.float64)
        return (low + unit * (high - low)).astype(self.action_space.dtype)


class RandomAgent(BaseAlgorithm):
    """Uniform random exploration with the SB3 algorithm surface, recording the achieved goals it visits.

    ``learn(total_timesteps)`` steps the env exactly ``total_timesteps`` transitions (``n_envs`` per vectorised
    step; a budget that is not a multiple of ``n_envs`` overshoots by fewer than ``n_envs``), calls
    ``callback.on_step()`` once per vectorised step and logs ``rollout/ep_rew_mean``, ``rollout/ep_len_mean``,
    ``rollout/success_rate`` and ``time/fps``. Actions come from the unwrapped env's
    ``sample_exploration_action()`` when it has one (e.g. the Sawyer's small torque noise, since full-range random
    torques pin the arm at its joint limits) and ``use_env_sampler`` is true; otherwise, and always in
    ``predict``, uniformly from the action space.

    Visited states (the ``achieved_goal`` of Dict observations, else the whole observation) of every observation
    the agent sees (first observations after resets and real last observations included) are kept in
    :attr:`visited_states`; :meth:`occupancy` counts the grid cells / voxels they occupy. They are not saved by
    ``save`` (store ``visited_states`` yourself) and are cleared by ``learn(reset_num_timesteps=True)``.

    :param policy: ``"MultiInputPolicy"`` / ``"MlpPolicy"`` (both :class:`RandomPolicy`) or a policy class.
    :param env: the env (Gymnasium env, VecEnv or registered id); ``None`` only for loading.
    :param use_env_sampler: use the env's ``sample_exploration_action()`` during ``learn`` when it exists.
    :param record_visited: keep the visited states (memory: n_transitions x goal dims x 8 bytes).
    :param stats_window_size: episodes averaged in the rollout logs.
    :param tensorboard_log: TensorBoard folder (``None``: none).
    :param policy_kwargs: extra arguments of the policy.
    :param verbose: 0 silent, 1 info, 2 debug.
    :param seed: seed of the action generator, the env and the global RNGs.
    :param device: torch device (the policy holds no parameters; ``"auto"`` is fine).
    :param _init_setup_model: build the policy now (``load`` passes False).
    """

    policy_aliases: ClassVar[dict[str, type[BasePolicy]]] = {  # type: ignore[misc]
        "MlpPolicy": RandomPolicy,
        "MultiInputPolicy": RandomPolicy,
    }
    policy: RandomPolicy

    def __init__(
        self,
        policy: str | type[RandomPolicy],
        env: GymEnv | str | None,
        use_env_sampler: bool = True,
        record_visited: bool = True,
        stats_window_size: int = 100,
        tensorboard_log: str | None = None,
        policy_kwargs: dict[str, Any] | None = None,
        verbose: int = 0,
        seed: int | None = None,
        device: th.device | str = "auto",
        _init_setup_model: bool = True,
    ) -> None:
        super().__init__(
            policy,
            env,
            learning_rate=0.0,
            policy_kwargs=policy_kwargs,
            stats_window_size=stats_window_size,
            tensorboard_log=tensorboard_log,
            verbose=verbose,
            device=device,
            support_multi_env=True,
            seed=seed,
            supported_action_spaces=(spaces.Box, spaces.Discrete),
        )
        self.use_env_sampler = use_env_sampler
        self.record_visited = record_visited
        self._visited_chunks: list[np.ndarray] = []  # each [n, G]
        self._visited_steps: list[np.ndarray] = []  # each [n], num_timesteps when visited
        if _init_setup_model:
            self._setup_model()

    def _setup_model(self) -> None:
        self.set_random_seed(self.seed)
        self.policy = self.policy_class(  # type: ignore[assignment]
            self.observation_space, self.action_space, seed=self.seed, **self.policy_kwargs
        ).to(self.device)
        self._visited_chunks = []
        self._visited_steps = []

    def _excluded_save_params(self) -> list[str]:
        return [*super()._excluded_save_params(), "_visited_chunks", "_visited_steps"]

    def learn(
        self: SelfRandomAgent,
        total_timesteps: int,
        callback: MaybeCallback = None,
        log_interval: int = 10,
        tb_log_name: str = "Random",
        reset_num_timesteps: bool = True,
        progress_bar: bool = False,
    ) -> SelfRandomAgent:
        """Step the env with random actions for exactly ``total_timesteps`` transitions.

        :param total_timesteps: budget in transitions (summed over envs).
        :param callback: callback(s) called once per vectorised step; returning False stops.
        :param log_interval: finished episodes between log dumps (``None``: only at the end).
        :param tb_log_name: TensorBoard run name (folder ``{tb_log_name}_{N}``).
        :param reset_num_timesteps: restart counters, episode statistics and visited states.
        :param progress_bar: show a tqdm/rich progress bar.
        :return: self.
        """
        if reset_num_timesteps:
            self._visited_chunks, self._visited_steps = [], []
        total_timesteps, callback = self._setup_learn(
            total_timesteps, callback, reset_num_timesteps, tb_log_name, progress_bar
        )
        callback.on_training_start(locals(), globals())
        assert self.env is not None and self._last_obs is not None
        env: VecEnv = self.env
        if not self._visited_chunks:
            self._record_visited(self._last_obs)
        env_sampler = self.use_env_sampler and env.has_attr("sample_exploration_action")
        returns = np.zeros(env.num_envs)  # running episode returns, for envs without a Monitor wrapper
        lengths = np.zeros(env.num_envs, dtype=np.int64)
        episodes_at_last_dump = self._episode_num

        while self.num_timesteps < total_timesteps:
            if env_sampler:
                actions = np.stack(env.env_method("sample_exploration_action"))
            else:
                actions = self.policy.sample_actions(env.num_envs)
            new_obs, rewards, dones, infos = env.step(actions)
            self.num_timesteps += env.num_envs
            returns += rewards
            lengths += 1
            for idx in np.flatnonzero(dones):
                # Without Monitor, infos carry no "episode": fill it as Monitor would (ARS's _mimic_monitor_wrapper).
                infos[idx].setdefault("episode", {"r": float(returns[idx]), "l": int(lengths[idx]), "t": self._elapsed()})
                self._record_visited(infos[idx].get("terminal_observation"))
            returns[dones], lengths[dones] = 0.0, 0
            self._episode_num += int(np.sum(dones))
            self._update_info_buffer(infos, dones)
            self._record_visited(new_obs)  # type: ignore[arg-type]
            self._last_obs = new_obs  # type: ignore[assignment]
            self._last_episode_starts = dones
            callback.update_locals(locals())
            if not callback.on_step():
                break
            if log_interval is not None and self._episode_num - episodes_at_last_dump >= log_interval:
                episodes_at_last_dump = self._episode_num
                self.dump_logs()

        self.dump_logs()
        callback.on_training_end()
        return self

    def dump_logs(self) -> None:
        """Write SB3's rollout and time keys to the logger."""
        assert self.ep_info_buffer is not None and self.ep_success_buffer is not None
        elapsed = self._elapsed()
        fps = int((self.num_timesteps - self._num_timesteps_at_start) / elapsed)
        if len(self.ep_info_buffer) > 0:
            self.logger.record("rollout/ep_rew_mean", safe_mean([info["r"] for info in self.ep_info_buffer]))
            self.logger.record("rollout/ep_len_mean", safe_mean([info["l"] for info in self.ep_info_buffer]))
        if len(self.ep_success_buffer) > 0:
            self.logger.record("rollout/success_rate", safe_mean(self.ep_success_buffer))
        self.logger.record("time/episodes", self._episode_num, exclude="tensorboard")
        self.logger.record("time/fps", fps)
        self.logger.record("time/time_elapsed", int(elapsed), exclude="tensorboard")
        self.logger.record("time/total_timesteps", self.num_timesteps, exclude="tensorboard")
        self.logger.dump(step=self.num_timesteps)

    @property
    def visited_states(self) -> np.ndarray:
        """All visited states, in the order seen: [M, G] (``achieved_goal`` dims, or the observation dims)."""
        if not self._visited_chunks:
            return np.zeros((0, 0))
        return np.concatenate(self._visited_chunks)

    @property
    def visited_timesteps(self) -> np.ndarray:
        """``num_timesteps`` at which each row of :attr:`visited_states` was seen: [M] (0 for the first reset)."""
        if not self._visited_steps:
            return np.zeros(0, dtype=np.int64)
        return np.concatenate(self._visited_steps)

    def occupancy(
        self,
        bins: int | tuple[int, ...],
        low: float | np.ndarray,
        high: float | np.ndarray,
        until_timestep: int | None = None,
    ) -> int:
        """Count the cells of a regular grid over [low, high] that hold at least one visited state.

        The grid tiles the box (cell width (high - low) / bins); states outside the box are ignored. (The original
        code's 10 x 10 x 10 finger voxels were 0.2 wide at a 0.222 spacing, so they did not tile: see
        reference/original_code.md §8; here the cells do.)

        :param bins: cells per dimension (one int for all, or one per dimension).
        :param low: lower corner, scalar or [G].
        :param high: upper corner, scalar or [G].
        :param until_timestep: count only states seen at ``num_timesteps <= until_timestep`` (an exploration curve).
        :return: number of occupied cells.
        """
        states = self.visited_states  # [M, G]
        if until_timestep is not None:
            states = states[self.visited_timesteps <= until_timestep]
        return count_occupied_cells(states, bins, low, high)

    def _record_visited(self, obs: np.ndarray | dict[str, np.ndarray] | None) -> None:
        if not self.record_visited or obs is None:
            return
        states = obs["achieved_goal"] if isinstance(obs, dict) and "achieved_goal" in obs else obs
        if isinstance(states, dict):
            raise TypeError("Recording visited states needs an 'achieved_goal' key in Dict observations.")
        states = np.asarray(states, dtype=np.float64)
        states = states.reshape(1, -1) if states.ndim == 1 else states.reshape(states.shape[0], -1)  # [n, G]
        self._visited_chunks.append(states)
        self._visited_steps.append(np.full(len(states), self.num_timesteps, dtype=np.int64))

    def _elapsed(self) -> float:
        return max((time.time_ns() - self.start_time) / 1e9, sys.float_info.epsilon)


def _observation_rows(observation: th.Tensor | dict[str, th.Tensor]) -> list[np.ndarray]:
    # [n, ...] tensors (or a dict of them, keys in sorted order) -> n flat float64 rows
    if isinstance(observation, dict):
        parts = [observation[key] for key in sorted(observation)]
    else:
        parts = [observation]
    flat = [part.detach().cpu().reshape(part.shape[0], -1).to(th.float64).numpy() for part in parts]
    return list(np.concatenate(flat, axis=1))


__all__ = ["RandomAgent", "RandomPolicy", "count_occupied_cells"]
