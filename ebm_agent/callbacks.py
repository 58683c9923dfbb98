"""SB3 callbacks of the planner agents: resumable checkpoints that a crash mid-``learn`` cannot corrupt."""

from __future__ import annotations

import contextlib
import pathlib

import numpy as np
from stable_baselines3.common.callbacks import CheckpointCallback

from ebm_agent.checkpoint_files import replace_with_link


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


__all__ = ["ResumableCheckpointCallback", "latest_checkpoint"]
