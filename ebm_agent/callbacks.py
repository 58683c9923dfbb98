"""SB3 callbacks of the planner agents: resumable checkpoints that a crash mid-``learn`` cannot corrupt, and the
model-quality probe logged during ``learn``."""

from __future__ import annotations

import contextlib
import pathlib

import gymnasium as gym
import numpy as np
from stable_baselines3.common.callbacks import BaseCallback, CheckpointCallback

from ebm_agent.checkpoint_files import replace_with_link
from ebm_agent.datasets import TransitionDataset, collect_random_transitions
from ebm_agent.probe import FeasibilityResult, NextStateRankResult, can_label_feasibility, model_quality


class ResumableCheckpointCallback(CheckpointCallback):
    """Save a resumable checkpoint every ``save_freq`` callback calls and keep ``<prefix>_latest.zip`` pointing at it.

    Each checkpoint is ``<save_path>/<prefix>_<num_timesteps>_steps.zip`` (written atomically by
    :meth:`CheckpointMixin.save_checkpoint`); ``<prefix>_latest.zip`` is then replaced atomically by a hard link
    to it (a copy where links are not supported). A run killed at any moment leaves the latest checkpoint whole.
    Resume with ``Agent.load_checkpoint(callback.latest_path, env)``.

    :param save_freq: callback calls between checkpoints (one call per vectorised env step, i.e. ``n_envs``
        transitions, as SB3's ``CheckpointCallback``).
    :param save_path: folder of the checkpoints (created if needed).
    :param name_prefix: file name prefix.
    :param keep_last: number of numbered checkpoints to keep (older ones are deleted); None keeps all.
    :param verbose: 2 prints each save.
    """

    def __init__(
        self,
        save_freq: int,
        save_path: str | pathlib.Path,
        name_prefix: str = "checkpoint",
        keep_last: int | None = None,
        verbose: int = 0,
    ) -> None:
        if isinstance(save_freq, bool) or not isinstance(save_freq, int | np.integer) or save_freq < 1:
            raise ValueError(f"save_freq must be a positive int (callback calls between checkpoints), got {save_freq!r}.")
        if keep_last is not None and (isinstance(keep_last, bool) or not isinstance(keep_last, int) or keep_last < 1):
            raise ValueError(f"keep_last must be None (keep every checkpoint) or an int >= 1, got {keep_last!r}.")
        super().__init__(int(save_freq), str(save_path), name_prefix=name_prefix, verbose=verbose)
        self.keep_last = keep_last
        self.latest_path = pathlib.Path(save_path) / f"{name_prefix}_latest.zip"
        self.saved_paths: list[pathlib.Path] = []

    def _init_callback(self) -> None:
        super()._init_callback()
        if not callable(getattr(self.model, "save_checkpoint", None)):
            raise TypeError(
                f"ResumableCheckpointCallback needs an agent with save_checkpoint (CheckpointMixin); "
                f"{type(self.model).__name__} has none. Use SB3's CheckpointCallback(save_replay_buffer=True) for it."
            )

    def _on_step(self) -> bool:
        if self.n_calls % self.save_freq == 0:
            path = self.model.save_checkpoint(self._checkpoint_path(extension="zip"))  # type: ignore[attr-defined]
            replace_with_link(path, self.latest_path)
            self.saved_paths.append(path)
            if self.keep_last is not None:
                while len(self.saved_paths) > self.keep_last:
                    with contextlib.suppress(FileNotFoundError):
                        self.saved_paths.pop(0).unlink()
            if self.verbose >= 2:
                print(f"Saving resumable checkpoint to {path}")
        return True


def latest_checkpoint(save_path: str | pathlib.Path, name_prefix: str = "checkpoint") -> pathlib.Path | None:
    """The ``<prefix>_latest.zip`` a :class:`ResumableCheckpointCallback` keeps, if one was written.

    :param save_path: the callback's folder.
    :param name_prefix: the callback's prefix.
    :return: the path, or None when no checkpoint was saved yet.
    """
    path = pathlib.Path(save_path) / f"{name_prefix}_latest.zip"
    return path if path.is_file() else None


class ModelProbeCallback(BaseCallback):
    """Log the model-quality probe of :mod:`ebm_agent.probe` every ``every`` callback calls during ``learn``.

    Keys (SB3 logger, so TensorBoard when the agent has ``tensorboard_log``):

    - ``probe/next_state_rank``: top-1 rate of the real next state among ``n_candidates`` perturbed ones, on
      ``n_transitions`` held-out random transitions of ``eval_env`` collected once at the start;
      ``probe/next_state_mean_rank``: its mean normalised rank (0 perfect, 0.5 chance).
    - where ``eval_env`` can label feasibility (particle with a box, maze): ``probe/feasibility_auroc``, over states
      near the agent's replay buffer (``pos_buffer``) once it holds data, else over uniform valid states, and
      ``probe/feasibility_auroc_uniform`` over uniform valid states.

    The probe leaves the agent's weights, modes, buffers and random streams as they were, so ``learn`` runs the same
    with or without it; each probe uses its own seed (``seed`` + the probe's index).

    :param eval_env: a gymnasium env of the agent's task (not a VecEnv) that only the probe steps.
    :param every: callback calls (vectorised env steps) between probes.
    :param n_moves: (state, move) samples of each feasibility AUROC.
    :param n_transitions: held-out transitions of the next-state rank.
    :param n_candidates: perturbed candidates per transition.
    :param scale: candidate noise, in std(s' - s) (see :func:`~ebm_agent.probe.next_state_rank`).
    :param held_out: held-out transitions to rank instead of random ones collected from ``eval_env``.
    :param seed: seed of the held-out data and of the probes.
    :param verbose: 1 prints each probe.
    """

    def __init__(
        self,
        eval_env: gym.Env,
        every: int = 10_000,
        n_moves: int = 2000,
        n_transitions: int = 1000,
        n_candidates: int = 64,
        scale: float = 1.0,
        held_out: TransitionDataset | None = None,
        seed: int = 0,
        verbose: int = 0,
    ) -> None:
        super().__init__(verbose)
        if isinstance(every, bool) or not isinstance(every, int | np.integer) or every < 1:
            raise ValueError(f"every must be a positive int (callback calls between probes), got {every!r}.")
        if not isinstance(eval_env, gym.Env):
            raise TypeError(f"ModelProbeCallback needs a gymnasium env (not a VecEnv), got {type(eval_env).__name__}.")
        self.eval_env = eval_env
        self.every = int(every)
        self.n_moves = n_moves
        self.n_transitions = n_transitions
        self.n_candidates = n_candidates
        self.scale = scale
        self.held_out = held_out
        self.seed = seed
        self.can_label = False
        self.num_probes = 0
        self.last_feasibility: FeasibilityResult | None = None
        self.last_rank: NextStateRankResult | None = None

    def _init_callback(self) -> None:
        if not callable(getattr(self.model, "energy_model", None)):
            raise TypeError(f"ModelProbeCallback needs an agent with an energy_model; {type(self.model).__name__} has none.")
        if self.held_out is None:
            self.held_out = collect_random_transitions(self.eval_env, self.n_transitions, seed=self.seed)
        self.can_label = can_label_feasibility(self.eval_env)

    def _on_step(self) -> bool:
        if self.n_calls % self.every == 0:
            self.probe()
        return True

    def probe(self) -> dict[str, float]:
        """Run the probe now and record its keys in the agent's logger.

        :return: the recorded values by key.
        """
        assert self.held_out is not None, "the callback is not initialised: pass it to learn()"
        seed = self.seed + self.num_probes
        self.num_probes += 1
        quality, self.last_feasibility, self.last_rank = model_quality(
            self.model, self.eval_env, self.held_out, self.n_moves, self.n_candidates, self.scale, seed=seed
        )
        values = {f"probe/{key}": value for key, value in quality.items()}
        for key, value in values.items():
            self.logger.record(key, value)
        if self.verbose >= 1:
            print(f"probe at {self.num_timesteps} steps: " + ", ".join(f"{k} {v:.4f}" for k, v in values.items()))
        return values


__all__ = ["ModelProbeCallback", "ResumableCheckpointCallback", "latest_checkpoint"]
