"""Reliability of the planning agents: atomic saves, kill-and-resume, divergence guards, safe loading, reproducibility."""

from __future__ import annotations

import base64
import io
import json
import os
import pathlib
import zipfile

import gymnasium as gym
import numpy as np
import pytest
import torch
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.monitor import Monitor
from tensorboard.backend.event_processing.event_file_loader import EventFileLoader

import envs  # noqa: F401  (registers the ids)
from baselines.action_ff import ActionFFAgent
from baselines.random_agent import RandomAgent
from ebm_agent import EBMPlannerAgent
from ebm_agent.callbacks import ResumableCheckpointCallback, latest_checkpoint
from ebm_agent.checkpoint import CheckpointMixin
from ebm_agent.checkpoint_files import read_training_state

FAST_KWARGS = {
    EBMPlannerAgent: {
        "horizon": 3,
        "planner_config": {"num_samples": 8, "iterations": 2},
        "online": {"pos_buffer_size": 1_000},
        "training": {"neg_buffer_size": 500},
        "image_log_interval": 0,
    },
    ActionFFAgent: {
        "horizon": 3,
        "planner_config": {"num_samples": 8, "iterations": 2},
        "online": {"pos_buffer_size": 1_000},
    },
}
AGENTS = list(FAST_KWARGS)
NETWORK = {EBMPlannerAgent: "energy", ActionFFAgent: "dynamics"}


def resumable(agent_class):
    """The agent class with the checkpoint mixin (itself once the lead has put CheckpointMixin in its bases)."""
    if issubclass(agent_class, CheckpointMixin):
        return agent_class
    return type(agent_class.__name__, (CheckpointMixin, agent_class), {"__module__": __name__})


@pytest.fixture(autouse=True)
def _on_the_cpu(monkeypatch):
    """Every agent of this module, and every load, on the CPU, also on a GPU machine (where ``device="auto"`` would
    pick CUDA): the bit-identical resumes tested here compare CPU generator states and CPU runs. The CUDA resume is
    tested in tests/agent/test_cuda.py."""
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)


def make_agent(agent_class, env=None, seed=0, **kwargs):
    env = gym.make("ebm/Particle-v0") if env is None else env
    return resumable(agent_class)("MultiInputPolicy", env, seed=seed, **{**FAST_KWARGS[agent_class], **kwargs})


def weights(agent):
    return {name: tensor.detach().cpu().clone() for name, tensor in agent.policy.state_dict().items()}


def assert_same_weights(first, second):
    assert first.keys() == second.keys()
    for name in first:
        assert torch.equal(first[name], second[name]), name


def leftovers(folder):
    return [name for name in os.listdir(folder) if name.endswith(".tmp")]


class CrashAt(BaseCallback):
    """Simulates a killed run: raises at call ``crash_at``; snapshots the training state at call ``snapshot_at``."""

    def __init__(self, crash_at: int, snapshot_at: int) -> None:
        super().__init__()
        self.crash_at, self.snapshot_at = crash_at, snapshot_at
        self.snapshot: dict = {}

    def _on_step(self) -> bool:
        if self.n_calls == self.snapshot_at:
            model = self.model
            self.snapshot = {
                "num_timesteps": model.num_timesteps,
                "pos_buffer": model.pos_buffer.state_dict(),
                "neg_buffer": model.neg_buffer.state_dict() if hasattr(model, "neg_buffer") else None,
                "generator": model._generator.get_state().clone(),
                "weights": weights(model),
                "optimizer": {k: {n: t.clone() for n, t in v.items()} for k, v in model.policy.optimizer.state.items()},
            }
        if self.n_calls == self.crash_at:
            raise KeyboardInterrupt("simulated kill")
        return True


def scalar_steps(run_folder):
    """Steps of the scalar events of each events file of a TensorBoard run, oldest file first."""
    files = []
    for path in pathlib.Path(run_folder).glob("events.out.tfevents.*"):
        events = [event for event in EventFileLoader(str(path)).Load() if event.summary.value]
        if events:
            files.append((min(e.wall_time for e in events), sorted({e.step for e in events})))
    return [steps for _, steps in sorted(files)]


# --------------------------------------------------------------------------------------- kill and resume
@pytest.mark.parametrize("agent_class", AGENTS)
def test_killed_run_resumes_from_latest_checkpoint_to_the_same_step_count(agent_class, tmp_path):
    total, tb_name = 200, "resume_run"
    train_env = gym.make("ebm/Particle-v0", max_episode_steps=20)  # short episodes: logs are dumped before the kill
    agent = make_agent(agent_class, train_env, tensorboard_log=str(tmp_path / "tb"))
    checkpoints = ResumableCheckpointCallback(save_freq=50, save_path=tmp_path / "ckpt")
    crash = CrashAt(crash_at=130, snapshot_at=100)
    with pytest.raises(KeyboardInterrupt, match="simulated kill"):
        agent.learn(total, callback=[checkpoints, crash], log_interval=1, tb_log_name=tb_name)
    assert agent.num_timesteps == 130
    assert latest_checkpoint(tmp_path / "ckpt") == checkpoints.latest_path
    assert sorted(os.listdir(tmp_path / "ckpt")) == [
        "checkpoint_100_steps.zip",
        "checkpoint_50_steps.zip",
        "checkpoint_latest.zip",
    ]
    assert leftovers(tmp_path / "ckpt") == []

    resumed = resumable(agent_class).load_checkpoint(
        checkpoints.latest_path, env=gym.make("ebm/Particle-v0", max_episode_steps=20)
    )
    saved = crash.snapshot
    assert resumed.num_timesteps == saved["num_timesteps"] == 100
    for name in ("pos_buffer", "neg_buffer"):
        if saved[name] is None:
            continue
        restored = getattr(resumed, name).state_dict()
        assert restored["size"] == saved[name]["size"] > 0 and restored["position"] == saved[name]["position"]
        np.testing.assert_array_equal(restored["states"], saved[name]["states"])
        np.testing.assert_array_equal(restored["next_states"], saved[name]["next_states"])
        assert restored["rng_state"] == saved[name]["rng_state"]
    assert torch.equal(resumed._generator.get_state(), saved["generator"])
    assert_same_weights(weights(resumed), saved["weights"])
    for group, (saved_state, restored_state) in enumerate(
        zip(saved["optimizer"].values(), resumed.policy.optimizer.state.values(), strict=True)
    ):
        for key in saved_state:
            assert torch.equal(saved_state[key], restored_state[key]), (group, key)

    resumed.learn(total - resumed.num_timesteps, reset_num_timesteps=False, tb_log_name=tb_name, log_interval=1)
    assert resumed.num_timesteps == total
    assert len(resumed.pos_buffer) > saved["pos_buffer"]["size"]  # the buffer continued, it did not restart
    # The resumed run writes into the killed run's TensorBoard folder, and its curve continues past the checkpoint.
    assert sorted(os.listdir(tmp_path / "tb")) == [f"{tb_name}_1"]
    killed_steps, resumed_steps = scalar_steps(tmp_path / "tb" / f"{tb_name}_1")
    assert min(killed_steps) <= 100 and max(killed_steps) <= 130
    assert min(resumed_steps) > 100 and max(resumed_steps) == total


@pytest.mark.parametrize("agent_class", AGENTS)
def test_resuming_mid_plan_on_the_env_as_it_was_gives_the_uninterrupted_run(agent_class, tmp_path):
    # The online loop's plans in flight are part of the checkpoint (OnlineLoopState): resumed on the env as it was
    # (pickled), without a reset, the run is bit-identical to one that never stopped.
    import cloudpickle
    from stable_baselines3.common.env_util import make_vec_env

    def fresh():
        venv = make_vec_env("ebm/Particle-v0", n_envs=1, seed=0)
        return make_agent(agent_class, venv), venv

    whole, _ = fresh()
    whole.learn(240)
    cut, venv = fresh()
    cut.learn(119)  # not a multiple of the 3-step horizon: a plan is half executed
    assert cut._online_loop is not None and (cut._online_loop.steps > 0).any()
    cut.save_checkpoint(tmp_path / "cut")
    env_as_it_was = cloudpickle.loads(cloudpickle.dumps(venv))
    resumed = resumable(agent_class).load_checkpoint(tmp_path / "cut", env=env_as_it_was, force_reset=False)
    resumed.learn(240 - 119, reset_num_timesteps=False)
    assert resumed.num_timesteps == 240 and resumed.num_plans == whole.num_plans
    assert_same_weights(weights(resumed), weights(whole))
    # A learn that resets the env starts with no plan in flight.
    resumed.learn(30)
    assert resumed.num_timesteps == 30


def test_checkpoint_restores_numpy_inverse_dynamics(tmp_path):
    agent = make_agent(EBMPlannerAgent, inverse_dynamics="rls")
    agent.learn(60)
    assert agent.inverse_model.num_updates > 0
    path = agent.save_checkpoint(tmp_path / "rls")
    assert path == tmp_path / "rls.zip"
    loaded = resumable(EBMPlannerAgent).load_checkpoint(tmp_path / "rls", env=gym.make("ebm/Particle-v0"))
    np.testing.assert_array_equal(loaded.inverse_model.weights, agent.inverse_model.weights)
    assert loaded.inverse_model.num_updates == agent.inverse_model.num_updates
    # The real moves that weigh plan following's dims come back too.
    assert loaded.inverse_model.moves.count == agent.inverse_model.moves.count > 0
    np.testing.assert_array_equal(loaded.inverse_model.moves.std, agent.inverse_model.moves.std)


def test_rls_agent_identifies_the_particle_and_plain_save_keeps_the_fit(tmp_path):
    # Regression: the RLS fit started at W_a = 0, answered 0 to every plan, and the agent never moved (-100 on the
    # particle for every seed). The warm-up's random actions identify W_a (the particle moves 0.05 per unit action).
    agent = make_agent(EBMPlannerAgent, inverse_dynamics="rls")
    agent.learn(120)
    inverse = agent.inverse_model
    np.testing.assert_allclose(inverse.weights[:, 2:4], 0.05 * np.eye(2), atol=0.01)
    # A plain save keeps the fit too (SB3 stores only torch modules): a loaded RLS agent must not stand still.
    agent.save(tmp_path / "rls_plain.zip")
    loaded = EBMPlannerAgent.load(tmp_path / "rls_plain.zip", env=gym.make("ebm/Particle-v0"))
    np.testing.assert_array_equal(loaded.inverse_model.weights, inverse.weights)
    assert loaded.inverse_model.num_updates == inverse.num_updates
    stream = io.BytesIO()
    agent.save(stream)
    stream.seek(0)
    from_stream = EBMPlannerAgent.load(stream)
    np.testing.assert_array_equal(from_stream.inverse_model.weights, inverse.weights)
    # The weights-only loader restores the fit too (numpy arrays and JSON, no pickle): otherwise a shared RLS
    # model would answer every plan with its warm-up's random actions.
    safe = EBMPlannerAgent.load_weights_only(
        tmp_path / "rls_plain.zip", gym.make("ebm/Particle-v0"), inverse_dynamics="rls", **FAST_KWARGS[EBMPlannerAgent]
    )
    np.testing.assert_array_equal(safe.inverse_model.weights, inverse.weights)
    assert safe.inverse_model.num_updates == inverse.num_updates


def test_checkpoint_is_a_plain_sb3_zip_and_plain_saves_are_not_resumable(tmp_path):
    agent = make_agent(EBMPlannerAgent)
    agent.learn(30)
    path = agent.save_checkpoint(tmp_path / "ckpt.zip")
    loaded = resumable(EBMPlannerAgent).load(path, env=gym.make("ebm/Particle-v0"))  # SB3 ignores the extra members
    assert_same_weights(weights(loaded), weights(agent))
    arrays, meta = read_training_state(path)
    assert meta["num_timesteps"] == 30 and all(array.dtype != object for array in arrays.values())
    agent.save(tmp_path / "plain.zip")
    with pytest.raises(ValueError, match="written by save\\(\\), not save_checkpoint"):
        resumable(EBMPlannerAgent).load_checkpoint(tmp_path / "plain.zip", env=gym.make("ebm/Particle-v0"))
    with pytest.raises(ValueError, match="checkpoint of EBMPlannerAgent, not ActionFFAgent"):
        resumable(ActionFFAgent).load_checkpoint(path, env=gym.make("ebm/Particle-v0"))


def test_callback_validates_its_arguments_and_its_agent(tmp_path):
    with pytest.raises(ValueError, match="save_freq"):
        ResumableCheckpointCallback(save_freq=0, save_path=tmp_path)
    with pytest.raises(ValueError, match="keep_last"):
        ResumableCheckpointCallback(save_freq=5, save_path=tmp_path, keep_last=0)
    with pytest.raises(TypeError, match="save_checkpoint"):
        RandomAgent("MultiInputPolicy", gym.make("ebm/Particle-v0")).learn(
            10, callback=ResumableCheckpointCallback(5, tmp_path)
        )
    agent = make_agent(ActionFFAgent)
    callback = ResumableCheckpointCallback(save_freq=10, save_path=tmp_path / "kept", keep_last=2)
    agent.learn(50, callback=callback)
    assert sorted(os.listdir(tmp_path / "kept")) == [
        "checkpoint_40_steps.zip",
        "checkpoint_50_steps.zip",
        "checkpoint_latest.zip",
    ]
    assert read_training_state(callback.latest_path)[1]["num_timesteps"] == 50


# ---------------------------------------------------------------------------------------- atomic writes
def test_failed_save_leaves_the_previous_file_intact(tmp_path, monkeypatch):
    import stable_baselines3.common.base_class as base_class

    agent = make_agent(EBMPlannerAgent)
    path = tmp_path / "model.zip"
    agent.save(path)
    before = path.read_bytes()

    def crash_midway(save_path, **kwargs):
        pathlib.Path(save_path).write_bytes(b"PK\x03\x04 half a zip")
        raise OSError("disk full")

    monkeypatch.setattr(base_class, "save_to_zip_file", crash_midway)
    agent.learn(20)
    with pytest.raises(OSError, match="disk full"):
        agent.save(path)
    with pytest.raises(OSError, match="disk full"):
        agent.save_checkpoint(path)
    assert path.read_bytes() == before
    assert leftovers(tmp_path) == []


@pytest.mark.parametrize("agent_class", AGENTS)
def test_diverging_loss_stops_training_and_keeps_finite_weights_and_checkpoint(agent_class, tmp_path):
    agent = make_agent(agent_class)
    network = getattr(agent.policy, NETWORK[agent_class])
    original_forward, calls = network.forward, {"train": 0}

    def diverge_after_some_updates(*args):
        output = original_forward(*args)
        if network.training:  # planning calls the network in eval mode; only the loss goes NaN
            calls["train"] += 1
            if calls["train"] > 10:
                return output * float("nan")
        return output

    network.forward = diverge_after_some_updates
    callback = ResumableCheckpointCallback(save_freq=5, save_path=tmp_path)
    with pytest.raises(FloatingPointError, match=r"diverged .*at update \d+"):
        agent.learn(400, callback=callback)
    assert 0 < agent.num_timesteps < 400
    assert all(torch.isfinite(tensor).all() for tensor in weights(agent).values())
    latest = resumable(agent_class).load_checkpoint(callback.latest_path, env=gym.make("ebm/Particle-v0"))
    assert 0 < latest.num_timesteps <= agent.num_timesteps
    assert all(torch.isfinite(tensor).all() for tensor in weights(latest).values())


def test_save_refuses_nan_weights_and_keeps_the_last_good_file(tmp_path):
    agent = make_agent(EBMPlannerAgent)
    good = agent.save_checkpoint(tmp_path / "good.zip")
    before = good.read_bytes()
    with torch.no_grad():
        next(agent.policy.energy.parameters()).view(-1)[0] = float("nan")
    for save in (agent.save, agent.save_checkpoint):
        with pytest.raises(FloatingPointError, match="NaN or inf"):
            save(good)
    assert good.read_bytes() == before and leftovers(tmp_path) == []


# ---------------------------------------------------------------------------------------------- loading
def corrupt(path: pathlib.Path, kind: str) -> None:
    data = path.read_bytes()
    if kind == "truncated":
        path.write_bytes(data[: len(data) // 2])
    elif kind == "empty":
        path.write_bytes(b"")
    elif kind == "garbage":
        path.write_bytes(os.urandom(2048))
    elif kind == "flipped":  # a byte inside a stored member: the zip opens, the CRC does not match
        with zipfile.ZipFile(path) as archive:
            info = archive.getinfo("policy.pth")
        offset = info.header_offset + 30 + len(info.filename) + len(info.extra) + info.compress_size // 2
        path.write_bytes(data[:offset] + bytes([data[offset] ^ 0xFF]) + data[offset + 1 :])
    elif kind == "no_data":
        with zipfile.ZipFile(path, "w") as archive:
            archive.writestr("policy.pth", b"")


@pytest.mark.parametrize("kind", ["truncated", "empty", "garbage", "flipped", "no_data"])
def test_corrupted_files_give_a_clear_error_from_every_loader(kind, tmp_path):
    agent_class = resumable(EBMPlannerAgent)
    path = make_agent(EBMPlannerAgent).save_checkpoint(tmp_path / "model.zip")
    corrupt(path, kind)
    message = "truncated or corrupted" if kind != "no_data" else "not a saved SB3 model"
    env = gym.make("ebm/Particle-v0")
    with pytest.raises(ValueError, match=message):
        agent_class.load(path, env=env)
    with pytest.raises(ValueError, match=message):
        agent_class.load_checkpoint(path, env=env)
    with pytest.raises(ValueError, match=message):
        agent_class.load_weights_only(path, env, **FAST_KWARGS[EBMPlannerAgent])
    with pytest.raises(FileNotFoundError, match="No saved model"):
        agent_class.load(tmp_path / "missing.zip")


def test_mismatched_env_names_both_spaces_and_the_fix(tmp_path):
    agent_class = resumable(EBMPlannerAgent)
    path = make_agent(EBMPlannerAgent).save_checkpoint(tmp_path / "particle.zip")
    reacher = gym.make("ebm/Reacher-v0")
    for load in (agent_class.load, agent_class.load_checkpoint):
        with pytest.raises(ValueError, match="other spaces") as error:
            load(path, env=reacher)
        assert "(2,)" in str(error.value) and "(4,)" in str(error.value) and "Pass the env" in str(error.value)
    with pytest.raises(ValueError, match="does not fit the networks"):
        agent_class.load_weights_only(path, reacher, **FAST_KWARGS[EBMPlannerAgent])
    with pytest.raises(ValueError, match="hyperparameters build"):
        agent_class.load_weights_only(path, gym.make("ebm/Particle-v0"), inverse_dynamics="mlp")
    with pytest.raises(ValueError, match="does not fit the networks"):
        agent_class.load_weights_only(path, gym.make("ebm/Particle-v0"), energy={"hidden_dim": 32})


class _TouchOnUnpickle:
    """Unpickling this object creates a file: a stand-in for arbitrary code in a shared model."""

    def __init__(self, marker: pathlib.Path) -> None:
        self.marker = marker

    def __reduce__(self):
        return (pathlib.Path.touch, (pathlib.Path(self.marker),))


def rewrite_member(path: pathlib.Path, member: str, content: bytes) -> None:
    with zipfile.ZipFile(path) as archive:
        members = {name: archive.read(name) for name in archive.namelist()}
    members[member] = content
    with zipfile.ZipFile(path, "w") as archive:
        for name, value in members.items():
            archive.writestr(name, value)


def test_weights_only_load_never_runs_code_from_the_file(tmp_path):
    import cloudpickle

    agent_class = resumable(EBMPlannerAgent)
    agent = make_agent(EBMPlannerAgent)
    agent.learn(30)
    path = tmp_path / "shared.zip"
    agent.save(path)
    marker = tmp_path / "code_ran"
    with zipfile.ZipFile(path) as archive:
        data = json.loads(archive.read("data"))
    payload = base64.b64encode(cloudpickle.dumps(_TouchOnUnpickle(marker))).decode()
    data["innocent_looking_attribute"] = {":type:": "<class 'int'>", ":serialized:": payload}
    rewrite_member(path, "data", json.dumps(data).encode())

    env = gym.make("ebm/Particle-v0")
    loaded = agent_class.load_weights_only(path, env, **FAST_KWARGS[EBMPlannerAgent])
    assert not marker.exists()
    assert_same_weights(weights(loaded), weights(agent))
    obs, _ = env.reset(seed=1)
    np.testing.assert_array_equal(loaded.predict(obs, deterministic=True)[0], agent.predict(obs, deterministic=True)[0])
    agent_class.load(path, env=env)  # SB3's load unpickles `data`: this is the risk docs/security.md describes
    assert marker.exists()

    marker.unlink()
    buffer = io.BytesIO()
    torch.save({"weight": _TouchOnUnpickle(marker)}, buffer)
    rewrite_member(path, "policy.pth", buffer.getvalue())
    with pytest.raises(ValueError, match="holds more than tensors"):
        agent_class.load_weights_only(path, env, **FAST_KWARGS[EBMPlannerAgent])
    assert not marker.exists()


@pytest.mark.parametrize("agent_class", AGENTS)
def test_agents_are_checkpointable_without_the_test_shim(agent_class):
    assert issubclass(agent_class, CheckpointMixin)


# -------------------------------------------------------------------------------------- reproducibility
@pytest.mark.parametrize("agent_class", AGENTS)
def test_same_seed_gives_identical_evaluation_scores_and_other_seeds_differ(agent_class):
    def scores(seed):
        agent = make_agent(agent_class, seed=seed)
        agent.learn(60)
        # Random starts drawn from the eval env's seeded generator: the scores depend on seed only through the agent.
        eval_env = Monitor(gym.make("ebm/Particle-v0", max_episode_steps=15))
        eval_env.reset(seed=123)
        rewards, _ = evaluate_policy(agent, eval_env, n_eval_episodes=3, deterministic=True, return_episode_rewards=True)
        return np.asarray(rewards)

    first = scores(7)
    np.testing.assert_array_equal(first, scores(7))
    assert not np.array_equal(first, scores(8))


def test_a_generator_saved_on_another_device_is_not_restored_and_the_load_says_so(tmp_path):
    agent = make_agent(EBMPlannerAgent)
    agent.learn(30)
    path = agent.save_checkpoint(tmp_path / "ckpt.zip")
    arrays, meta = read_training_state(path)
    assert meta["generator_devices"] == {"_generator": "cpu"}
    resumed = resumable(EBMPlannerAgent).load_checkpoint(path, env=gym.make("ebm/Particle-v0"))
    assert torch.equal(resumed._generator.get_state(), agent._generator.get_state())
    fresh = resumed._generator.manual_seed(123).get_state()
    meta["generator_devices"] = {"_generator": "cuda"}  # as a checkpoint written by an agent on a GPU reads
    with pytest.warns(UserWarning, match="saved on cuda and this agent runs on cpu.*device='cuda'"):
        resumed._restore_training_state(arrays, meta, path)
    assert torch.equal(resumed._generator.get_state(), fresh)  # kept its own seeding, no crash on the state's size
    del meta["generator_devices"]  # a checkpoint written before the devices were recorded: CPU, restored as before
    resumed._restore_training_state(arrays, meta, path)
    assert torch.equal(resumed._generator.get_state(), agent._generator.get_state())
