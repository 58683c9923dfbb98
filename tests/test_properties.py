"""Property-based tests: random and malformed inputs at every boundary give a correct result or the documented error.

"Documented error" means ValueError/TypeError raised at the boundary (never an IndexError or a crash inside torch or
MuJoCo), and a "correct result" is finite: no NaN action, plan or observation ever comes back. Cases that still
need a change elsewhere are strict xfails that name the change.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import torch
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import envs  # noqa: F401  (registers the ids)
from baselines.action_ff import ActionFFAgent
from ebm_agent import (
    EBMPlannerAgent,
    EnergyConfig,
    EnergyModel,
    GaussianGoalEnergy,
    MPPIConfig,
    MPPIPlanner,
    OnlineConfig,
    TrainingConfig,
)
from ebm_agent.config import MOVED_FIELDS, REMOVED_FIELDS
from ebm_agent.costs import PlanCost

FAST = settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
TINY = {"horizon": 3, "planner_config": {"num_samples": 8, "iterations": 2}}
AGENT_KWARGS = {
    EBMPlannerAgent: {**TINY, "image_log_interval": 0},
    ActionFFAgent: TINY,
}
DOCUMENTED = (ValueError, TypeError)


@pytest.fixture(scope="module", params=list(AGENT_KWARGS), ids=lambda cls: cls.__name__)
def agent(request):
    return request.param("MultiInputPolicy", gym.make("ebm/Particle-v0"), seed=0, **AGENT_KWARGS[request.param])


# ----------------------------------------------------------------------------------------------- predict
any_float = st.floats(allow_nan=True, allow_infinity=True, width=32)
in_box = st.floats(-1.0, 1.0, width=32)
valid_vector = hnp.arrays(np.float32, (2,), elements=in_box)
malformed_value = st.one_of(
    hnp.arrays(np.float32, (2,), elements=any_float),  # NaN / inf / huge
    hnp.arrays(np.float64, hnp.array_shapes(min_dims=1, max_dims=3, min_side=0, max_side=4), elements=in_box),
    hnp.arrays(np.int64, (2,), elements=st.integers(-3, 3)),
    hnp.arrays(np.bool_, (2,)),
    st.lists(in_box, min_size=1, max_size=3),
    st.just(np.array(["a", "b"])),
    st.just(np.array([None, 1.0], dtype=object)),
)


@st.composite
def observations(draw: st.DrawFn) -> Any:
    """A goal-conditioned observation dict, valid or with malformed values, missing or extra keys; or not a dict."""
    if draw(st.integers(0, 9)) == 0:
        return draw(st.one_of(st.none(), valid_vector, st.tuples(st.just({}), st.just({}))))
    obs: dict[str, Any] = {}
    for key in ("observation", "achieved_goal", "desired_goal"):
        choice = draw(st.sampled_from(["valid", "valid", "malformed", "missing"]))
        if choice != "missing":
            obs[key] = draw(valid_vector if choice == "valid" else malformed_value)
    if draw(st.booleans()):
        obs[draw(st.text(min_size=1, max_size=5))] = draw(valid_vector)
    return obs


def is_clean_single(obs: Any) -> bool:
    """A dict whose observation and goal are both finite real [2] vectors inside the state box."""
    if not isinstance(obs, dict) or "observation" not in obs or "desired_goal" not in obs:
        return False
    values = [np.asarray(obs[k]) for k in ("observation", "desired_goal")]
    return all(
        v.shape == (2,) and v.dtype.kind in "fiub" and np.all(np.isfinite(v)) and np.all(np.abs(v) <= 1) for v in values
    )


@FAST
@given(obs=observations(), deterministic=st.booleans())
def test_predict_gives_finite_in_bounds_actions_or_a_documented_error(agent, obs, deterministic):
    try:
        actions, state = agent.predict(obs, deterministic=deterministic)
    except DOCUMENTED:
        assert not is_clean_single(obs), "a valid observation was rejected"
        return
    actions = np.asarray(actions)
    assert actions.shape[-1] == 2 and actions.dtype == np.float32
    assert np.all(np.isfinite(actions)) and np.all(np.abs(actions) <= 1.0)
    if is_clean_single(obs):
        assert actions.shape == (2,)
        _, state = agent.predict(obs, state=state, deterministic=deterministic)  # the carried plan is usable too


@FAST
@given(starts=hnp.arrays(np.float32, (3, 2), elements=in_box), goals=hnp.arrays(np.float32, (3, 2), elements=in_box))
def test_batched_predict_matches_the_batch(agent, starts, goals):
    actions, (plans, _, steps, _) = agent.predict({"observation": starts, "desired_goal": goals}, deterministic=True)
    assert actions.shape == (3, 2) and np.all(np.isfinite(actions)) and np.all(np.abs(actions) <= 1.0)
    assert np.all(np.isfinite(plans)) and np.all(steps == 1)


STRICT_PREDICT_CASES = {
    "scalar observation": ({"observation": np.float32(0.1), "desired_goal": np.float32(0.2)}, ValueError, "shape"),
    "3-d observation": ({"observation": np.zeros((2, 2, 2)), "desired_goal": np.zeros((2, 2, 2))}, ValueError, "shape"),
    "complex dtype": ({"observation": np.array([1 + 1j, 0]), "desired_goal": np.zeros(2)}, TypeError, "dtype"),
    "string dtype": ({"observation": np.array(["a", "b"]), "desired_goal": np.zeros(2)}, TypeError, "dtype"),
    "goal outside the state bounds": (
        {"observation": np.zeros(2, np.float32), "desired_goal": np.array([5.0, 5.0], np.float32)},
        ValueError,
        "bounds",
    ),
}


@pytest.mark.parametrize("case", list(STRICT_PREDICT_CASES))
def test_predict_rejects_malformed_observations_that_it_accepts_today(case):
    agent = EBMPlannerAgent("MultiInputPolicy", gym.make("ebm/Particle-v0"), seed=0, **AGENT_KWARGS[EBMPlannerAgent])
    obs, error, fragment = STRICT_PREDICT_CASES[case]
    with pytest.raises(error, match=fragment):
        agent.predict(obs)


# ----------------------------------------------------------------------------------------------- planner
def make_planner(state_dim: int) -> tuple[MPPIPlanner, PlanCost]:
    torch.manual_seed(0)
    energy = EnergyModel(state_dim, EnergyConfig(hidden_dim=8, num_hidden_layers=1))
    cost = PlanCost(energy, GaussianGoalEnergy(list(range(state_dim))), [])
    config = MPPIConfig(horizon=3, num_samples=8, iterations=2)
    return MPPIPlanner(config, state_dim, -np.ones(state_dim), np.ones(state_dim)), cost


PLANNERS = {dim: make_planner(dim) for dim in (1, 2, 3)}


@FAST
@given(
    state_dim=st.sampled_from([1, 2, 3]),
    start_shape=hnp.array_shapes(min_dims=1, max_dims=3, min_side=0, max_side=4),
    goal_shape=hnp.array_shapes(min_dims=1, max_dims=3, min_side=0, max_side=4),
    dtype=st.sampled_from([torch.float32, torch.float64, torch.int64]),
    values=st.floats(-5, 5),
    warm_start=st.booleans(),
)
# Found by hypothesis on 2026-12-02: no env at all divided by zero when sizing the cost chunks.
@example(state_dim=1, start_shape=(0, 1), goal_shape=(0, 0), dtype=torch.float32, values=0.0, warm_start=False)
def test_planner_gives_finite_plans_from_the_start_or_a_documented_error(
    state_dim, start_shape, goal_shape, dtype, values, warm_start
):
    planner, cost = PLANNERS[state_dim]
    start = torch.full(start_shape, values).to(dtype)
    goals = torch.zeros(goal_shape, dtype=dtype)
    init = torch.zeros(start_shape[0], 4, state_dim, dtype=dtype) if warm_start else None
    generator = torch.Generator().manual_seed(0)
    try:
        result = planner.plan(start, goals, cost, init_plan=init, generator=generator)
    except DOCUMENTED:
        well_formed = dtype.is_floating_point and start.ndim == 2 and start.shape[1] == state_dim
        assert not (well_formed and goals.ndim == 2 and goals.shape == (start.shape[0], state_dim)), "valid input rejected"
        return
    plans = result.plans
    assert plans.shape == (start.shape[0], 4, state_dim)
    assert torch.isfinite(plans).all()
    torch.testing.assert_close(plans[:, 0], start.to(plans.dtype))
    assert (plans[:, 1:].abs() <= 1.0 + 1e-6).all()  # every planned state after the start stays in the bounds


@pytest.mark.parametrize("bad", ["start", "goals"])
def test_planner_rejects_non_finite_inputs(bad):
    planner, cost = PLANNERS[2]
    start, goals = torch.zeros(1, 2), torch.zeros(1, 2)
    {"start": start, "goals": goals}[bad][0, 0] = float("nan")
    with pytest.raises(ValueError, match="NaN"):
        planner.plan(start, goals, cost)


# ----------------------------------------------------------------------------------------------- configs
BAD_VALUES: dict[type, dict[str, st.SearchStrategy]] = {
    OnlineConfig: {
        "deviation_threshold": st.one_of(st.floats(max_value=0.0, exclude_max=True), st.just(float("nan"))),
        "replan_threshold": st.floats(max_value=0.0, exclude_max=True),
        "random_action_prob": st.one_of(
            st.floats(min_value=1.0, exclude_min=True), st.floats(max_value=0.0, exclude_max=True)
        ),
        "pos_buffer_size": st.integers(max_value=0),
    },
    TrainingConfig: {
        "neg_replay_prob": st.one_of(st.floats(min_value=1.0, exclude_min=True), st.floats(max_value=0.0, exclude_max=True)),
        "neg_buffer_size": st.integers(max_value=0),
        "l2_anneal_end": st.floats(min_value=1.0, exclude_min=True, allow_nan=False, allow_infinity=False),
    },
    MPPIConfig: {
        "num_samples": st.one_of(st.integers(max_value=0), st.booleans()),
        "iterations": st.one_of(st.integers(max_value=-1), st.floats(0.5, 10)),
        "temperature": st.one_of(st.floats(max_value=0.0), st.just(float("nan"))),
        "noise_scale": st.floats(max_value=0.0),
    },
    EnergyConfig: {
        "hidden_dim": st.integers(max_value=0),
        "num_hidden_layers": st.integers(max_value=-1),
        "activation": st.text(max_size=8).filter(lambda s: s not in {"leaky_relu", "relu", "swish", "silu", "tanh"}),
    },
}
AGENT_ARGUMENT = {OnlineConfig: "online", TrainingConfig: "training", MPPIConfig: "planner_config", EnergyConfig: "energy"}


@st.composite
def bad_config(draw: st.DrawFn) -> tuple[type, str, Any]:
    config_type = draw(st.sampled_from(list(BAD_VALUES)))
    field = draw(st.sampled_from(sorted(BAD_VALUES[config_type])))
    return config_type, field, draw(BAD_VALUES[config_type][field])


@FAST
@given(case=bad_config())
def test_out_of_range_config_values_are_rejected_at_construction(case):
    config_type, field, value = case
    # A value of the wrong type (1.0 for an int) is a TypeError, an out-of-range one a ValueError: both name the field.
    with pytest.raises((ValueError, TypeError), match=field):
        config_type(**{field: value})
    overrides = {**TINY, AGENT_ARGUMENT[config_type]: {field: value}}
    if config_type is MPPIConfig:
        overrides["planner_config"] = {**TINY["planner_config"], field: value}
    with pytest.raises((ValueError, TypeError), match=field):
        EBMPlannerAgent("MultiInputPolicy", gym.make("ebm/Particle-v0"), **overrides)


@FAST
@given(
    key=st.text(min_size=1, max_size=10),
    argument=st.sampled_from(["online", "training", "planner_config", "energy", "cost"]),
)
def test_unknown_config_keys_are_rejected_with_the_valid_ones(key, argument):
    valid = {"online": OnlineConfig, "training": TrainingConfig, "planner_config": MPPIConfig, "energy": EnergyConfig}
    config = valid.get(argument)
    if config is not None and key in config.__dataclass_fields__:
        return
    if argument == "online" and (key in MOVED_FIELDS["OnlineConfig"] or key in REMOVED_FIELDS["OnlineConfig"]):
        return  # those get an error naming where the setting went
    if argument == "cost" and key in (
        "goal_energy",
        "goal_weight",
        "eval_goal_weight",
        "velocity_weight",
        "acceleration_weight",
        "warmup_plans",
    ):
        return
    with pytest.raises(TypeError, match="valid keys"):
        EBMPlannerAgent("MultiInputPolicy", gym.make("ebm/Particle-v0"), **{argument: {key: 1}})


WRONG_TYPE = st.one_of(st.text(max_size=4), st.none(), st.lists(st.integers(), max_size=2), st.complex_numbers())


@FAST
@example(config_type=OnlineConfig, field="closed_loop", value="yes")
@given(
    config_type=st.sampled_from([OnlineConfig, MPPIConfig, EnergyConfig]),
    field=st.sampled_from(["closed_loop", "reinit_energy", "include_mean", "spectral_norm", "temperature"]),
    value=WRONG_TYPE,
)
def test_wrongly_typed_config_fields_raise_a_type_error_naming_the_field(config_type, field, value):
    if field not in config_type.__dataclass_fields__:
        return
    with pytest.raises(TypeError, match=f"{config_type.__name__}.{field}"):
        config_type(**{field: value})


# ------------------------------------------------------------------------------------------------- envs
ENV_IDS = ["ebm/Particle-v0", "ebm/Maze-v0", "ebm/Reacher-v0", "ebm/SawyerReach-v0"]


@pytest.fixture(scope="module", params=ENV_IDS)
def env(request):
    environment = gym.make(request.param, disable_env_checker=True)
    yield environment
    environment.close()


@st.composite
def actions(draw: st.DrawFn, dim: int) -> Any:
    kind = draw(st.sampled_from(["in_bounds", "in_bounds", "any_float", "huge", "wrong_shape", "wrong_type"]))
    if kind == "in_bounds":
        return draw(hnp.arrays(np.float32, (dim,), elements=in_box))
    if kind == "any_float":
        return draw(hnp.arrays(np.float64, (dim,), elements=st.floats(allow_nan=True, allow_infinity=True)))
    if kind == "huge":
        return draw(hnp.arrays(np.float64, (dim,), elements=st.floats(-1e30, 1e30)))
    if kind == "wrong_shape":
        shape = draw(hnp.array_shapes(min_dims=0, max_dims=2, max_side=9).filter(lambda s: s != (dim,)))
        return draw(hnp.arrays(np.float32, shape, elements=in_box))
    return draw(st.sampled_from([None, "up", [0.1] * (dim + 1), {"a": 1}]))


@FAST
@given(data=st.data(), seed=st.integers(0, 2**16))
def test_env_step_gives_finite_observations_or_a_documented_error(env, data, seed):
    obs, _ = env.reset(seed=seed)
    dim = env.action_space.shape[0]
    for action in data.draw(st.lists(actions(dim), min_size=1, max_size=4)):
        clean = isinstance(action, np.ndarray) and action.shape == (dim,) and bool(np.all(np.isfinite(action)))
        try:
            obs, reward, terminated, truncated, info = env.step(action)
        except DOCUMENTED:
            assert not clean, f"a finite action of the right shape was rejected: {action!r}"
            continue
        assert clean, f"a malformed action was accepted: {action!r}"
        for key, value in obs.items():
            assert np.all(np.isfinite(value)), key
            assert env.observation_space[key].shape == value.shape
        assert np.isfinite(reward) and "is_success" in info
        if terminated or truncated:
            obs, _ = env.reset()


box_value = st.one_of(st.floats(-1.5, 1.5), st.floats(allow_nan=True, allow_infinity=True))


@FAST
@given(
    obstacle=st.one_of(st.lists(box_value, min_size=4, max_size=4), st.lists(box_value, max_size=6)),
    start=st.one_of(st.none(), st.tuples(in_box, in_box)),
)
def test_random_obstacle_boxes_give_a_valid_env_or_a_value_error(obstacle, start):
    try:
        environment = gym.make("ebm/Particle-v0", obstacle=obstacle, start=start)
    except ValueError as error:
        assert "obstacle" in str(error) or "start" in str(error) or "goal" in str(error)
        return
    box = np.asarray(obstacle, dtype=np.float64)
    assert box.shape == (4,) and np.all(np.isfinite(box)) and box[0] < box[2] and box[1] < box[3]
    obs, _ = environment.reset(seed=0)
    inside = (box[0] <= obs["observation"][0] <= box[2]) and (box[1] <= obs["observation"][1] <= box[3])
    assert not inside, "the env started inside its obstacle"
    for _ in range(3):
        obs, reward, *_ = environment.step(environment.action_space.sample())
        assert np.all(np.isfinite(obs["observation"])) and np.isfinite(reward)
