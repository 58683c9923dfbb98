"""Typed configuration of the online loop (Algorithm 1) shared by the planning agents, and of the EBM's training."""

from __future__ import annotations

import dataclasses
import math
import types
import typing
from dataclasses import dataclass, fields
from typing import Any, TypeVar

T = TypeVar("T")

HARD_NEGATIVE_LOSSES = ("margin", "negatives")
"""Values of ``TrainingConfig.hard_negative_loss``."""

ARRIVAL_AT = ("plan_end", "aim")
"""Values of ``OnlineConfig.arrival_at``."""

LOSSES: tuple[str, ...] = ("cd", "infonce", "infonce_reach", "infonce_perturb")
"""Values of ``TrainingConfig.loss``."""

THRESHOLD_UNITS = ("state", "step")
"""Values of ``OnlineConfig.threshold_units``."""

REMOVED_FIELDS: dict[str, dict[str, str]] = {
    "OnlineConfig": {
        name: (
            "the original's adaptive planning budget (+20 iterations every 10 gradient steps while the energy gap stayed "
            "above 0.15, up to 800) was removed (issue 45): with the L2-regularised loss the gap settles near 1, so the "
            "rule only ever grew the budget (8x slower planning after 2,000 particle steps, no better score) and no "
            "preset or recorded run used it; the planner's iterations are now fixed by planner_config"
        )
        for name in ("adaptive_iterations", "adapt_every", "adapt_gap", "adapt_increment", "max_iterations")
    },
}
"""Config fields removed from the library: config class name -> {field: why}, for the error a stale setting gets."""

TRAINING_FROM_ONLINE: tuple[str, ...] = (
    "neg_buffer_size",
    "neg_replay_prob",
    "hard_negatives",
    "hard_negative_reach",
    "hard_negative_threshold",
    "hard_negative_buffer_size",
    "hard_negative_batch",
    "hard_negative_weight",
    "hard_negative_margin",
    "hard_negative_loss",
    "l2_final",
    "l2_anneal_start",
    "l2_anneal_end",
)
"""The fields ``OnlineConfig`` held for the EBM's training until issue 45 moved them to :class:`TrainingConfig`."""

TRAINING_FROM_ARGUMENTS: tuple[str, ...] = ("loss", "l2_coeff", "reach_candidates", "perturbed_negatives", "perturb_scales")
"""The EBM constructor's arguments that issue 45 moved to :class:`TrainingConfig`."""

MOVED_SETTINGS: dict[str, str] = {
    **{f"training.{name}": name for name in TRAINING_FROM_ARGUMENTS},
    **{f"training.{name}": f"online.{name}" for name in TRAINING_FROM_ONLINE},
    "cost.warmup_plans": "online.prior_warmup_plans",
}
"""The EBM agent's settings that issue 45 moved: ``"argument.field"`` today -> where it was (``"argument"`` or
``"argument.field"``). The harness reads it to keep the digests of runs recorded before the move (eval/digest.py)."""

MOVED_FIELDS: dict[str, dict[str, str]] = {
    "OnlineConfig": {old.split(".")[1]: new for new, old in MOVED_SETTINGS.items() if old.startswith("online.")}
}
"""Config fields moved to another config: config class name -> {field: its new place}, for the error an old setting
gets."""


@dataclass
class OnlineConfig:
    """The online loop shared by the planning agents (Algorithm 1): how the agent acts, when it replans, what it keeps;
    defaults follow the original code (§2, §5, §8). How the EBM's energy learns is :class:`TrainingConfig`.

    :param deviation_threshold: during ``learn``, a plan ends when max |planned - real| over the model dims exceeds
        this (0.7 in the original for 2-D envs and Reacher; set it per env, e.g. lower for the arm); 0: every
        segment is one step, a new plan from the real state at every step.
    :param replan_threshold: during ``predict``, replan when mean |planned - real| exceeds this (0.55 for 2-D and
        Reacher, 0.3 for the arm in the original's evaluation) or the plan runs out; 0: at every step, as a
        receding-horizon MPC (pytorch_mppi, TD-MPC2) replans.
    :param arrival_threshold: during ``predict``, also replan when the real state is within this (max |.| over the
        model dims) of the plan's final state before the plan runs out: the plan has arrived (typically at a subgoal
        of :mod:`ebm_agent.subgoals`, which sits closer than the horizon's reach) and its remaining steps would only
        hover there; a new plan aims at the next subgoal. None (the default): plans run their course.
    :param arrival_at: what the real state must reach for ``arrival_threshold``: ``"plan_end"`` (the default), the
        plan's final state (max over the model dims); ``"aim"``, the goal or subgoal the plan was made for (max over
        the goal dims). A plan that reaches a near subgoal early can wander about it for the rest of its steps and
        end a little away from it, so its end is never reached; its aim is.
    :param closed_loop: compute each action from the *real* current state to the next planned state (True) instead
        of from planned state to planned state (the original's training mode).
    :param pos_buffer_size: capacity of the real-transition replay buffer (1e6).
    :param replay_positives: add as many replayed positives as fresh ones (the original's 50/50 batch).
    :param reinit_energy: re-initialise (instead of warm-start) a plan whose mean transition energy exceeds this.
    :param train_every_plan: take one gradient step per finished plan segment (Algorithm 1). False: none, while the
        replay buffers (and with them a subgoal graph built from them) and a learned inverse dynamics still grow: the
        model stays as initialised, the untrained control of an online configuration (what its planning, exploration
        and graph do with an energy that learned nothing).
    :param random_action_prob: during ``learn``, replace each env step's action by a uniform random one in the
        action bounds with this probability (the plan's segment then ends on its deviation as usual). 0 (off, the
        paper's): an energy learned only from its own plans' transitions never sees the moves its plans avoid (e.g.
        Reacher's full torques), so it keeps calling them unlikely.
    :param threshold_units: the unit of the four thresholds on a gap between a real and a planned (or aimed-at)
        state, ``deviation_threshold``, ``replan_threshold``, ``arrival_threshold`` and ``hard_negative_threshold``:
        ``"state"`` (the default, the original's), the env's own state units; ``"step"``, the env's measured real
        step: each dim's gap is divided by the largest real |s' - s| of that dim the agent has learnt from
        (:attr:`~ebm_agent.base.PlannerAgentBase.real_moves`, periodic dims wrapped) before the gaps are reduced
        over the dims, so that the same thresholds mean the same on an env of any scale (the maze's 0.05 replan
        drift is 1 step, its 0.025 arrival 0.5 and its 0.01 hard-negative miss 0.2). Until a real move has been
        recorded there is no step: the rules that read these thresholds are skipped (a plan runs its course) and
        ``predict`` warns once.
    """

    deviation_threshold: float = 0.7
    replan_threshold: float = 0.55
    arrival_threshold: float | None = None
    arrival_at: str = "plan_end"
    closed_loop: bool = True
    pos_buffer_size: int = 1_000_000
    replay_positives: bool = True
    reinit_energy: float = 1.0
    train_every_plan: bool = True
    random_action_prob: float = 0.0
    threshold_units: str = "state"

    def __post_init__(self) -> None:
        check_field_types(self)
        for name, choices in (("arrival_at", ARRIVAL_AT), ("threshold_units", THRESHOLD_UNITS)):
            if getattr(self, name) not in choices:
                raise ValueError(f"OnlineConfig.{name} must be one of {choices}, got {getattr(self, name)!r}.")
        for name in ("deviation_threshold", "replan_threshold"):
            if not getattr(self, name) >= 0:
                value = getattr(self, name)
                raise ValueError(f"OnlineConfig.{name} must be >= 0 (0: a new plan at every step), got {value!r}.")
        if self.arrival_threshold is not None and not self.arrival_threshold >= 0:
            raise ValueError(f"OnlineConfig.arrival_threshold must be None (off) or >= 0, got {self.arrival_threshold!r}.")
        if not 0.0 <= self.random_action_prob <= 1.0:
            raise ValueError(f"OnlineConfig.random_action_prob must be in [0, 1], got {self.random_action_prob!r}.")
        if int(self.pos_buffer_size) < 1:
            raise ValueError(f"OnlineConfig.pos_buffer_size must be >= 1, got {self.pos_buffer_size!r}.")


@dataclass
class TrainingConfig:
    """How the EBM agent's energy learns: the contrastive loss, its negatives and its L2 term (the EBM's ``training``).

    :param loss: ``"cd"`` (the paper's contrastive loss), ``"infonce"`` (each positive against the batch's sampled
        negatives) or ``"infonce_reach"``: each real (s, s') against ``reach_candidates`` next states drawn uniformly in
        the one-step reach box around s (:func:`~ebm_agent.losses.reach_candidates`), so that E(s, s') learns
        -log p(s' | s) up to a constant and rises where the env refuses a move (issue #34). Its energy scale is in
        nats: a transition E higher than another is e^E times less likely under the data's policy; ``l2_coeff`` then
        weighs a term mean E(s, s')^2 over the real transitions that pins their energy to 0, since InfoNCE alone
        leaves a free offset per state. That loss ignores the planned and sampled negatives. ``"infonce_perturb"``:
        the same objective and anchor with the ``perturbed_negatives`` near misses of each real s' (Gaussian, per-dim
        scale of the real moves) as its contrast set instead of the reach box, so that the energy resolves next
        states finer than the box: conditional on s, it carries no term of the visited states' density, which the
        planned negatives of CD put into it.
    :param l2_coeff: weight of the energy-magnitude regulariser of the CD loss (1.0).
    :param reach_candidates: K, uniform candidates per positive of ``loss="infonce_reach"`` (64); unused otherwise.
    :param perturbed_negatives: M > 0 adds, to the CD loss, M negatives per real transition (s, s'): (s, s' + eps)
        with eps ~ N(0, (c std(s' - s))^2) per state dim, c drawn per negative from ``perturb_scales`` and std the
        running std of the real moves (periodic dims wrapped). Where the env's next states lie on a thin set (fewer
        action than state dims, e.g. Reacher's angles that must move by their velocities), such near misses are
        transitions it cannot make, which the planned negatives alone rarely show the energy. The loss then weighs
        the planned and the perturbed negatives' means equally. 0 (off, the paper's).
    :param perturb_scales: the noise scales c of ``perturbed_negatives``, in units of the real moves' per-dim std.
    :param neg_buffer_size: capacity of the planned-transition replay buffer (1e4).
    :param neg_replay_prob: probability that a fresh negative is swapped for a replayed one (0.5).
    :param hard_negatives: keep the failed plan steps as labelled negatives (issue #34; off by default). A step
        fails when the real next state s'_real misses the planned one s'_plan by more than
        ``hard_negative_threshold`` (max over the model dims): the agent aimed from the real s_t at s'_plan (with
        ``closed_loop``) and the env did not get there, e.g. it kept the agent at a wall. (s_t, s'_plan) is then a
        transition known to be impossible, from what the agent observed only (never the env's map). Such triples
        (s_t, s'_plan, s'_real) go to a buffer of their own, and each gradient step adds
        ``hard_negative_weight`` x a term over the fresh ones plus ``hard_negative_batch`` replayed ones (see
        ``hard_negative_loss``). The label is exact only with exact inverse dynamics in a deterministic env: with a
        learned inverse model or a noisy env a miss may be the model's error or noise, not an impossible move.
    :param hard_negative_reach: clip each failed target into the one-step reach box around s_t before labelling it,
        s'_try = s_t + clip(s'_plan - s_t, -r, r) with r [D] the largest |s' - s| of the real transitions seen so far
        (updated with the segment's own before its steps are labelled), and count a step as failed only when
        s'_real misses s'_try. A plan that jumps further than one step can reach then yields the in-reach move the
        env was asked for and refused (at a wall: a move of one step into it), not the far jump itself, and an
        over-long jump in the open, which the env executes up to its reach, yields none. Exact for envs whose
        moves are a per-dim box (the point envs); off by default.
    :param hard_negative_threshold: per-dim miss |s'_plan - s'_real| above which a step counts as failed, in state
        units (0.01: a fifth of a maze step of 0.05; the point envs' inverse dynamics is exact to 1e-7).
    :param hard_negative_buffer_size: capacity of the failed-step buffer (1e4).
    :param hard_negative_batch: failed steps replayed from that buffer per gradient step (64), beside the fresh ones.
    :param hard_negative_weight: weight of the hard-negative term in the loss (1.0).
    :param hard_negative_margin: margin m of ``hard_negative_loss="margin"`` (1.0).
    :param hard_negative_loss: ``"margin"``: mean softplus(m - (E(s_t, s'_plan) - E(s_t, s'_real))), a ranking term
        that wants each failed step at least m above the real transition from the same state; ``"negatives"``:
        the failed steps join the contrastive loss's negatives (the weight scales their share of its mean E(x-)).
    :param l2_final: anneal the EBM's ``l2_coeff`` (the weight of the L2 term on the energies) linearly to this value
        between the fractions ``l2_anneal_start`` and ``l2_anneal_end`` of the ``learn`` budget (SB3's progress, as
        its learning-rate schedules; a resumed run keeps its place). None (the default): ``l2_coeff`` throughout.
        A weaker L2 term widens the energy gap (each energy settles near +-1/(2 l2)): the sharp energy of issue 34
        (``l2_coeff`` 0.1) tells walls apart but, learned from the start, also rates moves into the unvisited maze
        impossible and stalls exploration; annealed late, the exploration runs on the lenient energy and the
        evaluation plans on the sharp one. Pretraining uses ``l2_coeff``.
    :param l2_anneal_start: fraction of the budget where the anneal begins (0.5).
    :param l2_anneal_end: fraction of the budget where it reaches ``l2_final`` (0.8); equal to the start: a switch.
    """

    loss: str = "cd"
    l2_coeff: float = 1.0
    reach_candidates: int = 64
    perturbed_negatives: int = 0
    perturb_scales: tuple[float, ...] = (0.25, 0.5, 1.0, 2.0)
    neg_buffer_size: int = 10_000
    neg_replay_prob: float = 0.5
    hard_negatives: bool = False
    hard_negative_reach: bool = False
    hard_negative_threshold: float = 0.01
    hard_negative_buffer_size: int = 10_000
    hard_negative_batch: int = 64
    hard_negative_weight: float = 1.0
    hard_negative_margin: float = 1.0
    hard_negative_loss: str = "margin"
    l2_final: float | None = None
    l2_anneal_start: float = 0.5
    l2_anneal_end: float = 0.8

    def __post_init__(self) -> None:
        if isinstance(self.perturb_scales, list):  # YAML and JSON give sequences as lists
            self.perturb_scales = tuple(self.perturb_scales)
        check_field_types(self)
        self._check_loss()
        self._check_hard_negatives()
        if not 0.0 <= self.neg_replay_prob <= 1.0:
            raise ValueError(f"TrainingConfig.neg_replay_prob must be in [0, 1], got {self.neg_replay_prob!r}.")
        if self.l2_final is not None and not self.l2_final >= 0:
            raise ValueError(f"TrainingConfig.l2_final must be None (no anneal) or >= 0, got {self.l2_final!r}.")
        if not 0.0 <= self.l2_anneal_start <= self.l2_anneal_end <= 1.0:
            raise ValueError(
                "TrainingConfig.l2_anneal_start and l2_anneal_end must satisfy 0 <= start <= end <= 1 (fractions of the "
                f"learn budget), got {self.l2_anneal_start!r} and {self.l2_anneal_end!r}."
            )
        for name in ("neg_buffer_size", "hard_negative_buffer_size"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"TrainingConfig.{name} must be >= 1, got {getattr(self, name)!r}.")

    def _check_loss(self) -> None:
        if self.loss not in LOSSES:
            raise ValueError(f"TrainingConfig.loss must be one of {LOSSES} ('cd' is the paper's), got {self.loss!r}.")
        if self.reach_candidates < 1:
            raise ValueError(f"TrainingConfig.reach_candidates must be a positive int, got {self.reach_candidates!r}.")
        if self.perturbed_negatives < 0:
            raise ValueError(f"TrainingConfig.perturbed_negatives must be an int >= 0, got {self.perturbed_negatives!r}.")
        if self.loss == "infonce_perturb" and self.perturbed_negatives < 1:
            raise ValueError("loss='infonce_perturb' needs perturbed_negatives >= 1 (its contrast set per real transition).")
        if not self.perturb_scales or not all(math.isfinite(c) and c > 0 for c in self.perturb_scales):
            raise ValueError(
                "TrainingConfig.perturb_scales must be a non-empty sequence of finite scales > 0, got "
                f"{self.perturb_scales!r}."
            )

    def _check_hard_negatives(self) -> None:
        if not self.hard_negative_threshold > 0:
            raise ValueError(f"TrainingConfig.hard_negative_threshold must be > 0, got {self.hard_negative_threshold!r}.")
        for name in ("hard_negative_weight", "hard_negative_margin", "hard_negative_batch"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"TrainingConfig.{name} must be >= 0, got {getattr(self, name)!r}.")
        if self.hard_negative_loss not in HARD_NEGATIVE_LOSSES:
            raise ValueError(
                f"TrainingConfig.hard_negative_loss must be one of {HARD_NEGATIVE_LOSSES}, got {self.hard_negative_loss!r}."
            )
        if self.hard_negatives and self.loss != "cd":
            raise ValueError(
                f"hard_negatives adds a term to the CD loss; loss={self.loss!r} would ignore the failed steps. "
                "Use loss='cd' with hard_negatives."
            )
        if self.hard_negatives and self.perturbed_negatives > 0:
            raise ValueError(
                "hard_negatives and perturbed_negatives are two different CD losses and cannot be combined; set one of them."
            )


def make_config(cls: type[T], value: T | dict[str, Any] | None, owner: str) -> T:
    """Build a config dataclass from an instance, a dict of its fields, or None (defaults).

    :param cls: the dataclass type.
    :param value: an instance, a dict, or None.
    :param owner: the parameter name, for messages.
    :return: an instance of ``cls``.
    :raises TypeError: for unknown keys (listing the valid ones) or a value of another type.
    """
    if value is None:
        return cls()
    if isinstance(value, cls):
        return value
    if isinstance(value, dict):
        valid = {f.name for f in fields(cls)}  # type: ignore[arg-type]
        removed = REMOVED_FIELDS.get(cls.__name__, {})
        for key in sorted(set(value) & set(removed)):
            raise TypeError(f"{owner}.{key}: {removed[key]}. Remove the key.")
        moved = MOVED_FIELDS.get(cls.__name__, {})
        for key in sorted(set(value) & set(moved)):
            raise TypeError(
                f"{owner}.{key} moved to {moved[key]} (issue 45: each config holds the settings of one owner); pass "
                f"{moved[key].split('.')[0]}={{{moved[key].split('.')[1]!r}: ...}} instead."
            )
        unknown = sorted(set(value) - valid)
        if unknown:
            raise TypeError(f"{owner}: unknown keys {unknown} for {cls.__name__}; valid keys are {sorted(valid)}.")
        return cls(**value)
    raise TypeError(f"{owner} must be a {cls.__name__}, a dict of its fields, or None; got {type(value).__name__}.")


def _matches(value: Any, expected: Any) -> bool:
    """Whether ``value`` fits the annotation ``expected`` (bool, int, float, str, None, unions, tuples, dicts)."""
    origin = typing.get_origin(expected)
    if origin in (typing.Union, types.UnionType):
        return any(_matches(value, option) for option in typing.get_args(expected))
    if expected is type(None):
        return value is None
    if expected is bool:
        return isinstance(value, bool)
    if expected is int:
        return isinstance(value, int) and not isinstance(value, bool)
    if expected is float:  # an int is a fine float, a bool is not
        return isinstance(value, (int, float)) and not isinstance(value, bool)
    if origin is not None:
        return isinstance(value, origin)
    return expected is Any or isinstance(value, expected)


def check_field_types(config: Any) -> None:
    """Check every field of a config dataclass against its annotation, so a wrong type fails at construction.

    :param config: a dataclass instance.
    :raises TypeError: ``"<Config>.<field> must be <type>, got <value>"``.
    """
    hints = typing.get_type_hints(type(config))
    for field in fields(config):
        value, expected = getattr(config, field.name), hints.get(field.name, Any)
        if not _matches(value, expected):
            name = getattr(expected, "__name__", str(expected))
            raise TypeError(f"{type(config).__name__}.{field.name} must be {name}, got {value!r}.")


def learn_budgets(config: Any) -> tuple[int | None, int | None]:
    """Iterations of a fresh and of a warm-started plan made while learning, read from a planner config.

    Works for any config with ``iterations`` and, optionally, ``train_iterations`` and ``warm_iterations``
    (``MPPIConfig``, ``ActionPlannerConfig``); each budget is at most ``iterations``. A config without such fields
    (None, ``LangevinConfig``, a non-MPPI action planner) has no budgets of its own.

    :param config: the planner config, or None.
    :return: (fresh, warm): None where the planner's full ``iterations`` apply.
    """
    if getattr(config, "method", "mppi") != "mppi" or not hasattr(config, "warm_iterations"):
        return None, None
    full = int(config.iterations)
    train, warm = config.train_iterations, config.warm_iterations
    return (None if train is None else min(train, full)), (None if warm is None else min(warm, full))


def planner_horizon(config: T, horizon: int | None, owner: str = "planner_config") -> T:
    """The planner config an agent plans with: a copy of ``config`` (never the caller's object), with ``horizon``.

    The planner owns its horizon: an agent's ``horizon`` argument only sets it, and the agent then reads it back from
    the planner. Given twice with two values (a ``horizon`` argument and a config whose horizon is not the
    default), the agent cannot tell which is meant, so that is an error.

    :param config: the planner config dataclass (a field ``horizon``).
    :param horizon: T, or None to keep the config's.
    :param owner: the config's parameter name, for messages.
    :return: a copy of ``config`` with the horizon set.
    :raises ValueError: a horizon that is not a positive int, or two different horizons.
    """
    if horizon is None:
        return dataclasses.replace(config)  # type: ignore[type-var]
    if isinstance(horizon, bool) or not isinstance(horizon, int) or horizon < 1:
        raise ValueError(f"horizon must be a positive int (number of planned transitions), got {horizon!r}.")
    default = {f.name: f.default for f in fields(config)}.get("horizon")  # type: ignore[arg-type]
    given = config.horizon  # type: ignore[attr-defined]
    if given not in (default, horizon):
        raise ValueError(
            f"horizon={horizon} and {owner}.horizon={given} disagree; give the horizon once (the horizon argument, or "
            f"the planner config's field)."
        )
    return dataclasses.replace(config, horizon=horizon)  # type: ignore[type-var]
