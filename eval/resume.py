"""Online runs that resume where they stopped: a checkpoint after each learning-curve evaluation, read back by the
next ``run_job`` of the same job, continuing exactly as an uninterrupted run would.

A planning agent's online run on the Sawyer takes 2-3 hours on one core, about a session; without this, a run cut
short (a session's end, a killed process) started again from zero. After each of ``EvalCallback``'s evaluations
(every ``eval_freq`` transitions) :class:`ResumeCheckpoint` writes, into ``<run>/resume/``:

- ``agent_<t>.zip``: the agent's resumable checkpoint (``save_checkpoint``: weights, optimiser, replay buffers,
  generators, and the online loop's plans in flight, ``ebm_agent.base.OnlineLoopState``);
- ``envs_<t>.pkl``: the training and evaluation VecEnvs as they are (cloudpickle: simulator state, episode step
  counts, random generators), the learning curve so far and the time spent;
- ``state.json``, written last: which two files form the checkpoint, with the job's fingerprint and defaults digest.

Each file is written atomically and ``state.json`` names the pair, so a kill at any moment leaves the previous
checkpoint whole. :func:`read_run_state` accepts a checkpoint only for the same fingerprint and digest; the
resumed run (``EvalCallback`` refilled with the curve so far) then consumes the rest of the budget, and its
``metrics.json`` lists where it resumed (``resumed_at``). SIGTERM or Ctrl-C during ``learn`` writes the same
checkpoint at the next env step and stops the run (``eval.stop``), so a stopped run loses no transitions. Same
seed, same numbers: a resumed run's weights, curve and final scores equal an uninterrupted run's (tested), wherever
it stopped. The folder is removed once the run is finished.

Like ``load``, reading the checkpoint unpickles: it is meant for a run folder this machine wrote.
"""

from __future__ import annotations

import json
import pickle
import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import cloudpickle
import numpy as np
from stable_baselines3.common.callbacks import BaseCallback, EvalCallback

from ebm_agent.checkpoint_files import atomic_path
from eval.jobs import RESUME_FOLDER, STATE_FILE
from eval.provenance import defaults_digest, job_fingerprint, read_json_dict
from eval.stop import StopFlag

if TYPE_CHECKING:
    from stable_baselines3.common.vec_env import VecEnv

    from eval.jobs import Job

__all__ = [
    "RESUME_FOLDER",
    "STATE_FILE",
    "ResumeCheckpoint",
    "RunState",
    "discard_run_state",
    "read_checkpoint_files",
    "read_run_state",
    "resumable",
    "write_checkpoint_files",
    "write_run_state",
]


CURVE_KEYS = ("evaluations_timesteps", "evaluations_results", "evaluations_length", "evaluations_successes")
"""The ``EvalCallback`` lists that hold the learning curve."""


def resumable(model: Any, job: Job) -> bool:
    """Whether a job's run can keep checkpoints: an online run of an agent with ``save_checkpoint``.

    :param model: the agent.
    :param job: the job.
    :return: True for the planning agents' online runs (PPO's runs are minutes long and are not checkpointed).
    """
    return job.mode == "online" and callable(getattr(model, "save_checkpoint", None))


@dataclass
class RunState:
    """A checkpoint read back: the agent's file, the envs, the curve so far and the time already spent.

    :param agent_path: the agent's ``save_checkpoint`` file.
    :param num_timesteps: transitions consumed when it was written.
    :param train_env: the training VecEnv as it was.
    :param eval_env: the evaluation VecEnv as it was.
    :param curve: ``EvalCallback``'s lists (``CURVE_KEYS``) and ``best_mean_reward``/``last_mean_reward``.
    :param learn_time_s: time spent in ``learn`` up to the checkpoint, over all earlier processes.
    :param resumed_at: the transitions at which earlier processes resumed, oldest first.
    """

    agent_path: Path
    num_timesteps: int
    train_env: VecEnv
    eval_env: VecEnv
    curve: dict[str, Any]
    learn_time_s: float
    resumed_at: list[int] = field(default_factory=list)

    def refill(self, callback: EvalCallback) -> None:
        """Give a new ``EvalCallback`` the learning curve so far, so that its ``evaluations.npz`` holds all of it.

        :param callback: the callback of the resumed run.
        """
        for key in CURVE_KEYS:
            setattr(callback, key, list(self.curve.get(key, [])))
        callback.best_mean_reward = float(self.curve.get("best_mean_reward", -float("inf")))
        callback.last_mean_reward = float(self.curve.get("last_mean_reward", -float("inf")))
        if callback.log_path is not None and callback.evaluations_timesteps:
            # The file as EvalCallback writes it, at once: the run may not evaluate again before its final one.
            arrays: dict[str, Any] = {
                "timesteps": callback.evaluations_timesteps,
                "results": callback.evaluations_results,
                "ep_lengths": callback.evaluations_length,
            }
            if callback.evaluations_successes:
                arrays["successes"] = callback.evaluations_successes
            np.savez(callback.log_path, **arrays)


class ResumeCheckpoint(BaseCallback):
    """The harness's one checkpoint callback: it writes the checkpoint that resuming needs at the steps it is due.

    Due: every ``every`` transitions (a directed collection), right after each evaluation of ``after`` (an online
    run: the ``EvalCallback`` placed before it in the callback list), and, once ``flag`` is set (SIGTERM, Ctrl-C:
    :func:`eval.stop.stop_at_next_step`), at the current step, after which ``learn`` stops. Never twice for one step,
    and never at or past ``total`` (the work then ends within seconds). What a checkpoint holds is ``write``'s
    business: :func:`write_run_state` for an online run, :func:`write_checkpoint_files` for a collection.

    :param write: ``write(elapsed_s)`` writes the checkpoint at the model's current step; ``elapsed_s`` is the time
        spent since ``learn`` began in this process.
    :param total: the budget, in transitions.
    :param every: transitions between two checkpoints, or None.
    :param after: an ``EvalCallback`` earlier in the same callback list, or None.
    :param flag: the stop flag, or None.
    """

    def __init__(
        self,
        write: Callable[[float], object],
        total: int,
        every: int | None = None,
        after: EvalCallback | None = None,
        flag: StopFlag | None = None,
    ) -> None:
        super().__init__()
        if every is not None and every < 1:
            raise ValueError(f"every must be a positive number of transitions or None, got {every}")
        self.write, self.total, self.every, self.after, self.flag = write, int(total), every, after, flag
        self.saved_at: int | None = None
        self._start = time.perf_counter()
        self._next: int | None = None
        self._evaluations = 0

    def _init_callback(self) -> None:
        self._start = time.perf_counter()
        # The model's count: the callback's own is 0 until its first step, which for a resumed run would write a
        # needless checkpoint one step after the one it resumed from.
        steps = int(self.model.num_timesteps)
        self._next = None if self.every is None else (steps // self.every + 1) * self.every
        self._evaluations = len(self.after.evaluations_timesteps) if self.after is not None else 0

    def _on_step(self) -> bool:
        steps = int(self.model.num_timesteps)
        due = False
        if self.every is not None and self._next is not None and steps >= self._next:
            due, self._next = True, (steps // self.every + 1) * self.every
        if self.after is not None and len(self.after.evaluations_timesteps) > self._evaluations:
            self._evaluations, due = len(self.after.evaluations_timesteps), True
        stopping = self.flag is not None and self.flag.requested
        if (due or stopping) and self.saved_at != steps:
            self.save()
        return not stopping

    def save(self) -> None:
        """Write the checkpoint at the model's current step (nothing at or past the budget)."""
        steps = int(self.model.num_timesteps)
        if steps < self.total:
            self.write(time.perf_counter() - self._start)
            self.saved_at = steps


def write_run_state(job: Job, model: Any, callback: EvalCallback, learn_time_s: float, resumed_at: list[int]) -> Path:
    """Write a checkpoint of the run into ``<run>/resume/`` and drop the previous one.

    :param job: the run.
    :param model: the agent (with ``save_checkpoint``).
    :param callback: the run's ``EvalCallback`` (its eval env and curve).
    :param learn_time_s: time spent in ``learn`` so far, over all processes of the run.
    :param resumed_at: transitions at which earlier processes resumed.
    :return: the ``state.json`` written.
    """

    curve: dict[str, Any] = {key: list(getattr(callback, key)) for key in CURVE_KEYS}
    curve["best_mean_reward"] = float(callback.best_mean_reward)
    curve["last_mean_reward"] = float(callback.last_mean_reward)
    payload = {"train_env": model.get_env(), "eval_env": callback.eval_env, "curve": curve}
    identity = {"fingerprint": job_fingerprint(job), "defaults_digest": defaults_digest(job)}
    state = {**identity, "learn_time_s": learn_time_s, "resumed_at": resumed_at}
    return write_checkpoint_files(job.run_dir / RESUME_FOLDER, model, payload, state)


def write_checkpoint_files(folder: Path, model: Any, payload: dict[str, Any], state: dict[str, Any]) -> Path:
    """Write one checkpoint into ``folder``: the agent, the pickled ``payload``, then ``state.json``; drop the last.

    Each file is written atomically and ``state.json``, written last, names the pair, so a kill at any moment leaves
    the previous checkpoint whole.

    :param folder: the checkpoint folder (created when missing).
    :param model: the agent (with ``save_checkpoint``); its ``num_timesteps`` names the files.
    :param payload: what else resuming needs (envs, curves, recorders), pickled with cloudpickle; objects shared
        between its entries stay shared when read back.
    :param state: JSON-able facts about the checkpoint (identity, times); the file names and the step are added.
    :return: the ``state.json`` written.
    """

    folder.mkdir(parents=True, exist_ok=True)
    steps = int(model.num_timesteps)
    agent_file, envs_file = f"agent_{steps}.zip", f"envs_{steps}.pkl"
    model.save_checkpoint(folder / agent_file)
    with atomic_path(folder / envs_file) as temporary:
        temporary.write_bytes(cloudpickle.dumps({**payload, "num_timesteps": steps}))
    record = {**state, "num_timesteps": steps, "agent_file": agent_file, "envs_file": envs_file}
    record["written_at"] = time.strftime("%Y-%m-%dT%H:%M:%S%z")
    with atomic_path(folder / STATE_FILE) as temporary:
        temporary.write_text(json.dumps(record, indent=2))
    for old in folder.iterdir():  # the previous checkpoint, now replaced
        if old.name not in (agent_file, envs_file, STATE_FILE):
            old.unlink(missing_ok=True)
    return folder / STATE_FILE


def read_checkpoint_files(folder: Path, identity: dict[str, Any]) -> tuple[dict[str, Any], Path, dict[str, Any]] | None:
    """The checkpoint in ``folder`` if its ``state.json`` carries ``identity`` and its files read back whole.

    A checkpoint of another identity, or one that cannot be read, is removed (the work starts afresh).

    :param folder: the checkpoint folder.
    :param identity: entries that ``state.json`` must hold with these values (fingerprints, sizes).
    :return: ``(state, agent file, payload)``, or None.
    """

    state = read_json_dict(folder / STATE_FILE)
    if state is None:
        return None
    same = all(state.get(key) == value for key, value in identity.items())
    agent_path, envs_path = folder / str(state.get("agent_file")), folder / str(state.get("envs_file"))
    payload: dict[str, Any] | None = None
    if same and agent_path.is_file() and envs_path.is_file():
        try:
            payload = pickle.loads(envs_path.read_bytes())
        except (pickle.UnpicklingError, EOFError, AttributeError, ImportError, ValueError):
            payload = None
    if payload is None or payload.get("num_timesteps") != state.get("num_timesteps"):
        shutil.rmtree(folder, ignore_errors=True)
        return None
    return state, agent_path, payload


def read_run_state(job: Job) -> RunState | None:
    """The run's checkpoint, if there is one for this very job (same fingerprint and library defaults).

    A checkpoint of another configuration, or one that cannot be read, is removed and the run starts afresh.

    :param job: the run.
    :return: the checkpoint, or None.
    """

    identity = {"fingerprint": job_fingerprint(job), "defaults_digest": defaults_digest(job)}
    found = read_checkpoint_files(job.run_dir / RESUME_FOLDER, identity)
    if found is None:
        return None
    state, agent_path, payload = found
    return RunState(
        agent_path=agent_path,
        num_timesteps=int(state["num_timesteps"]),
        train_env=payload["train_env"],
        eval_env=payload["eval_env"],
        curve=dict(payload["curve"]),
        learn_time_s=float(state.get("learn_time_s", 0.0)),
        resumed_at=[int(step) for step in state.get("resumed_at", [])],
    )


def discard_run_state(job: Job) -> None:
    """Remove the run's checkpoint folder (a finished run, or a checkpoint that does not fit the job).

    :param job: the run.
    """
    shutil.rmtree(job.run_dir / RESUME_FOLDER, ignore_errors=True)
