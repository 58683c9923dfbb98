"""Where our numbers differ from the paper's, and why: the "differences" section of ``docs/results.md``.

Which cells differ is computed, never written down: a cell with at least 3 finished seeds differs from the paper
when the paper's number lies outside the 95% stratified-bootstrap interval of our mean (``eval.stats``). Why it
differs is written down: :data:`EXPLANATIONS` holds what we know, per part pattern and agent, in words and without
numbers (the numbers come from the table beside it, so an explanation cannot go stale with a rerun). A differing
cell without an explanation says "not investigated yet".
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from fnmatch import fnmatchcase

import numpy as np

from eval import stats
from eval.paper.claims import EXPLORATION_CLAIM, LEARNING_CONTROL, SCORE_CLAIMS
from eval.paper.parts import Cell

MIN_SEEDS = 3


@dataclass(frozen=True)
class Explanation:
    """Why the cells of matching parts and agents differ from the paper.

    :param part: an ``fnmatch`` pattern of part names (``table1/maze/*``).
    :param agent: an ``fnmatch`` pattern of agent names (``ebm``, ``action-ff``, ``*``).
    :param text: the reason, with its evidence named (a command, a doc), and no measured numbers.
    :param setting: an ``fnmatch`` pattern of the cells' row labels (``RLS``), for parts whose rows differ in more
        than the agent (the inverse-dynamics ablation); ``*`` for every row.
    """

    part: str
    agent: str
    text: str
    setting: str = "*"


EXPLANATIONS: tuple[Explanation, ...] = (
    Explanation(
        "table1/maze/*",
        "*",
        "Our agents reach the first wall and stay there, as PPO does at 5x the budget (docs/baselines.md). A plan of "
        "the default 10 steps of at most 0.05 per axis sees 0.5 ahead; the way round starts up column 0, away from "
        "the goal, so every goal energy rises along it and no plan of that horizon beats waiting at the wall. The "
        "rejected moves at the wall are real 'stay' transitions, which energy training makes cheap. A 30-step horizon "
        "did not help either (pretrained EBM, seed 0, `python scripts/maze_horizon.py 30`: still at the wall): under the L1 "
        "goal a plan must run about 40 steps round the wall before it ends nearer the goal than the wall is. Nor did 40 "
        "steps with the paper's final-state goal (Eq. 6): `python scripts/probe.py table1/maze/pretrained ebm horizon=40 "
        "'cost={goal_energy: gaussian}' --seeds 0` scored -1331.34, stuck against the bottom edge. The pretrained energy "
        "hardly knows the walls: `python scripts/maze_walls.py <model.zip>` gives a move into the first wall 0.21 and a "
        "move out of the box 0.09 against 0.04-0.16 for free moves (a 0.2 jump: 1.97), so plans run through walls, "
        "the env rejects the move and the agent stands still. The paper's "
        "pretrained EBM number is better than the maze's optimum under the strict wall rule (anchors above); the "
        "original's float artefact at y = 0.25 allows it (docs/environments.md). The original's horizon for the maze "
        "is not recorded (reference/original_code.md §9: 5 to 20 steps in its log).",
    ),
    Explanation(
        "table1/particle/*",
        "ebm",
        "On the open particle map our planner needs no learned dynamics: with the reward-form goal energy and the "
        "ground-truth inverse dynamics an untrained agent already reaches the goal near the optimum (docs/agent.md), "
        "so this cell does not test the energy. Why the paper's online number is far worse than its own pretrained "
        "one is not explained by the protocol recorded in reference/original_code.md.",
    ),
    Explanation(
        "table1/reacher/*",
        "ebm",
        "Reacher's normalised angles wrap at the arm's rest pose, where every episode starts. Fed raw, as in the "
        "original, the energy saw every move through the rest pose as a jump across the state space; our energy takes "
        "each angle as (sin, cos) (docs/agent.md, 'Where we differ'), which brought the pretrained EBM nearer the paper"
        " (the raw-input runs are in docs/results.md of commit cdb9407). Online the EBM stays near the random policy's "
        "level (anchors above): plans move the angles faster than the torques allow and a new plan starts about every "
        "1.3 transitions (`plan/num_plans` in the runs' TensorBoard logs), because the reward-form goal term outweighs "
        "the small energy gap the loss keeps between real and planned transitions (docs/agent.md, 'Status'). Such "
        "plans move their angles several times further than their own velocities say, and our ground-truth inverse "
        "dynamics, weighting angles and velocities / 10 equally, fits them on the velocities and asks for little "
        "torque (`python scripts/reacher_plan_gap.py <model.zip>`). Weighting the angles 30 to 1 makes even an "
        "untrained EBM reach the goal (-4.40 over 3 seeds: `python scripts/probe.py table1/reacher/untrained ebm --env "
        "inverse_angle_weight=30 --seeds 0 1 2`), so the default keeps equal weights and these cells keep testing the "
        "energy (docs/mujoco_envs.md, 'The Reacher's angle weight'). A weaker goal (weight 0.3) did not help online.",
    ),
    Explanation(
        "table1/reacher/online",
        "action-ff",
        "Our Action FF predicts the change of state (residual, the default; docs/baselines.md 'Residual by default'), "
        "the model that matched the paper's pretrained Reacher FF; the original's absolute-state FF, whose one-step "
        "errors are a sizeable part of a move, is the weaker baseline the paper's online number reflects. Not probed "
        "online with residual=False yet.",
    ),
    Explanation(
        "table1/*/pretrained",
        "action-ff",
        "Our Action FF predicts the change of state (docs/baselines.md, 'Residual by default'); the original predicted "
        "the absolute next state, whose one-step errors on random data are a sizeable part of a move, and which "
        "scored far below the paper's Action FF in our runs. The residual model matches the paper on Reacher. On the "
        "particle it stays behind because of the paper's final-state cost: with T = 10 moves of at most 0.05 per "
        "axis, many plans end on the goal while their first actions point anywhere, so the agent wanders near the "
        "goal (`python scripts/ff_first_action.py <model.zip>`). With a horizon of 5 the same model matches the "
        "paper (`python scripts/probe.py table1/particle/pretrained action-ff horizon=5 --seeds 0 1 2`, docs/"
        "baselines.md); the row keeps the EBM's horizon of 10 so that both agents plan alike.",
    ),
    Explanation(
        "table1/particle/online",
        "action-ff",
        "The paper's online Action FF scores far below random actions and standing still (anchors above), which no "
        "working planner on the open particle map does. The original's FF online loop indexed past the end of its "
        "plan at the last step and its evaluation compared states off by one (reference/original_code.md §7); our "
        "FF copies neither bug.",
    ),
    Explanation(
        "inverse_dynamics/sawyer",
        "ebm",
        "The learned inverse model fails, not the energy: `python scripts/sawyer_learned_inverse.py <model.zip>` shows "
        "that on real transitions of the arm the learned model's torques are further from the true ones than zero "
        "torque is, and that the same energy and planner, acting through the env's ground-truth inverse dynamics "
        "instead, reach the target within the first steps of the evaluation episode in which the learned model "
        "drives the finger away. On our torque-driven arm a joint's change of velocity depends on the whole pose "
        "(the arm's mass matrix), which one global linear fit (RLS) cannot follow. The MLP can learn the arm from "
        "ordinary transitions but not from the torques at the limits that a planner through a saturating model "
        "collects (`python scripts/sawyer_inverse_offline.py`, docs/agent.md). The plans also put the finger where "
        "their joints do not (the reason of the other Sawyer EBM cells), pairs of states that no real transition "
        "resembles. The original's RLS ran on the authors' arm, whose inverse dynamics we do not have.",
        setting="RLS",
    ),
    Explanation(
        "table2/sawyer/pretrained_*",
        "action-ff",
        "Our Action FF predicts the change of state (docs/baselines.md, 'Residual by default'), each dim standardized "
        "by its running mean and std ('Standardized outputs'); the original predicted the absolute next state by plain "
        "MSE on raw dims. With the absolute model the random-data row scores far lower, nearer the paper's number but "
        "still above it (`python scripts/probe.py table2/sawyer/pretrained_random action-ff residual=false --seeds 0 1 "
        "2`, docs/baselines.md), and with plain MSE every pretrained row does (docs/baselines.md, 'Standardized "
        "outputs'): its loss, dominated by the joint velocities, left the finger's move unlearned. Our Sawyer is also "
        "not the authors' arm but a torque-driven build of Metaworld's Sawyer (docs/mujoco_envs.md), so its scores "
        "compare with the paper's only in scale.",
    ),
    Explanation(
        "*/sawyer*",  # the online fixed- and variable-goal runs, and the fixed-goal model on variable goals
        "action-ff",
        "Our Action FF predicts the change of state, each dim standardized (docs/baselines.md, 'Residual by default' "
        "and 'Standardized outputs'), where the original predicted the absolute next state by plain MSE on raw dims, "
        "and it plans torques through that model, so it needs no inverse dynamics "
        "and learns quickly on this arm (its learning curve is in the run's evaluations.npz). The original's FF online "
        "loop also indexed past the end of its plan at the last step (reference/original_code.md §7). Our Sawyer is "
        "not the authors' arm but a torque-driven build of Metaworld's Sawyer (docs/mujoco_envs.md), so its scores "
        "compare with the paper's only in scale.",
    ),
    Explanation(
        "*/sawyer*",
        "ebm",
        "Our EBM's plans put their finger dims where their joint dims do not put the finger (0.5-0.9 m apart): the "
        "finger xyz are state dims of their own. Our ground-truth inverse dynamics therefore matches the planned "
        "finger as well as the joints, weighted 100 to 1 (SawyerReachEnv.inverse_finger_weight, docs/mujoco_envs.md); "
        "with the joints alone, as before 2026-12-02, the real finger drifted away from the target "
        "(`python scripts/sawyer_plan_gap.py <model.zip> --finger-weight 0`, docs/agent.md 'Status'). The original's "
        "sampling optimiser scored all 20 observation dims with equal weights. With that inverse dynamics an untrained "
        "EBM already reaches the target (the untrained rows of Table 2), so these cells measure the planner and the "
        "inverse dynamics more than the learned energy. Our Sawyer is not the authors' arm but a torque-driven build "
        "of Metaworld's Sawyer (docs/mujoco_envs.md), so its scores compare with the paper's only in scale.",
    ),
    Explanation(
        "sawyer_ppo/*",
        "ppo",
        "The paper's PPO was OpenAI baselines' PPO with no hyperparameters recorded anywhere (reference/original_code.md, "
        "'PPO'). Ours is SB3's PPO with settings tuned for this Sawyer (4 envs, 256-unit policy, learning rate 1e-3 "
        "chosen over 3e-4 on it: baselines/hyperparams.py), as DESIGN.md asks so that PPO is no straw man. Our Sawyer "
        "is also not the authors' arm but a torque-driven build of Metaworld's Sawyer with gravity compensation on "
        "every arm body (docs/mujoco_envs.md), so its scores compare with the paper's only in scale. The seeds spread "
        "widely at this budget: one stays far from the goal while the others end near it (per-seed scores in the "
        "runs' metrics.json).",
    ),
)
"""What we know about each difference; the first matching entry is used."""


@dataclass(frozen=True)
class Difference:
    """One cell whose numbers differ from the paper's.

    :param part: the cell's part.
    :param cell: the cell.
    :param mean: our mean over seeds.
    :param low: the lower end of its 95% interval.
    :param high: the upper end.
    :param seeds: how many seeds.
    :param explanation: why, or "not investigated yet".
    """

    part: str
    cell: Cell
    mean: float
    low: float
    high: float
    seeds: int
    explanation: str

    @property
    def direction(self) -> str:
        """``"better"`` or ``"worse"`` than the paper (scores are sums of rewards: higher is better)."""
        assert self.cell.paper is not None
        return "better" if self.mean > self.cell.paper else "worse"


def explain(part: str, agent: str, setting: str = "") -> str:
    """The explanation of a cell's difference from the paper.

    :param part: the part's name.
    :param agent: the agent.
    :param setting: the cell's row label (``Cell.setting``); entries with a setting pattern match only their rows.
    :return: the first matching explanation's text, or "not investigated yet".
    """
    for entry in EXPLANATIONS:
        if (
            fnmatchcase(part, entry.part)
            and fnmatchcase(agent, entry.agent)
            and (entry.setting == "*" or fnmatchcase(setting, entry.setting))
        ):
            return entry.text
    return "not investigated yet."


@dataclass(frozen=True)
class ClaimReason:
    """What we know of why one comparison of a claim (``eval.paper.claims``) does not hold or is inconclusive.

    :param claim: the claim's text (``eval.paper.claims.SCORE_CLAIMS``, ``EXPLORATION_CLAIM``, ``LEARNING_CONTROL``).
    :param label: the comparison's label (an env).
    :param text: the reason, with its evidence named, and no measured numbers; shown only while the comparison does
        not hold (a verdict is never written down).
    """

    claim: str
    label: str
    text: str


CLAIM_REASONS: tuple[ClaimReason, ...] = (
    ClaimReason(
        SCORE_CLAIMS[0].text,
        "reacher",
        "online, the EBM stays near the random policy's level on Reacher: its plans move the angles faster than the "
        "torques allow, and the ground-truth inverse dynamics turns them into little torque (the reason of "
        "table1/reacher/online, EBM, below). The Action FF plans torques through its own model and needs no inverse "
        "dynamics.",
    ),
    ClaimReason(
        EXPLORATION_CLAIM,
        "maze",
        "not isolated. What the first seed's heatmaps show: the goal-free EBM's visits pile up along the first "
        "wall (x = -0.5) of the left corridor, whereas the random agent's spread up the corridor. The goal-directed "
        "maze cells end at that wall too, with plans that run through walls the energy hardly knows (the reason of "
        "the table1/maze cells, below). Not tried yet: other horizons or noise for the goal-free plans.",
    ),
    ClaimReason(
        EXPLORATION_CLAIM,
        "sawyer",
        "our Sawyer is a torque-driven build of Metaworld's Sawyer (docs/mujoco_envs.md), on which uniform random "
        "torques swing the arm across the workspace: at the EBM's budget they occupy about as many voxels as the "
        "EBM, and about four times as many as random joint targets do (the figure's table below).",
    ),
    ClaimReason(
        LEARNING_CONTROL,
        "particle",
        "the untrained EBM already reaches the goal near the optimum on the open particle map (the anchors of Table "
        "1): its planner and the ground-truth inverse dynamics leave learning nothing to add (docs/agent.md).",
    ),
    ClaimReason(
        LEARNING_CONTROL,
        "sawyer",
        "the finger-weighted ground-truth inverse dynamics reaches the target from plans that point the finger at "
        "it, learned or not (the reason of the Table 2 EBM cells, below).",
    ),
    ClaimReason(
        LEARNING_CONTROL,
        "maze",
        "trained or not, the EBM ends at the maze's first wall (the reason of the table1/maze cells, below).",
    ),
)
"""What we know of the comparisons of claims that do not hold, in words and without numbers."""


def claim_reason(claim: str, label: str) -> str | None:
    """The reason of a claim's comparison that does not hold (``eval.paper.claims.render_claims``).

    :param claim: the claim's text.
    :param label: the comparison's label.
    :return: the reason, or None when none is written down.
    """
    return next((entry.text for entry in CLAIM_REASONS if entry.claim == claim and entry.label == label), None)


def find_differences(cells: Sequence[tuple[str, Cell, np.ndarray]]) -> list[Difference]:
    """The cells whose 95% interval excludes the paper's number.

    :param cells: (part name, cell, per-seed scores [seeds]) of every cell.
    :return: the differing cells, in the order given; cells without a paper number or with fewer than 3 seeds are
        not judged.
    """
    found = []
    for part, cell, scores in cells:
        if cell.paper is None or len(scores) < MIN_SEEDS:
            continue
        low, high = stats.bootstrap_ci(np.asarray(scores, dtype=np.float64), stats.mean)
        if low <= cell.paper <= high:
            continue
        mean = float(stats.mean(np.asarray(scores, dtype=np.float64)))
        reason = explain(part, cell.agent, cell.setting)
        found.append(Difference(part, cell, mean, float(low), float(high), len(scores), reason))
    return found


def render_differences(differences: Sequence[Difference]) -> list[str]:
    """The markdown section: the differing cells grouped by their explanation, each reason written once.

    Cells that share a reason (the maze's four cells, say) are listed together, in the order given, with the reason
    once below them; a cell with a reason of its own is one line.

    :param differences: from :func:`find_differences`.
    :return: markdown lines.
    """
    lines = [
        "## Where we differ from the paper, and why",
        "",
        f"A cell differs when it has at least {MIN_SEEDS} seeds and the paper's number lies outside the 95% interval "
        "of our mean (computed); the reasons are written in `eval/paper/differences.py`.",
        "",
    ]
    if not differences:
        return [*lines, "No finished cell differs from the paper so far.", ""]
    groups: dict[str, list[Difference]] = {}
    for difference in differences:
        groups.setdefault(difference.explanation, []).append(difference)
    for explanation, members in groups.items():
        if len(members) == 1:
            lines.append(f"- {_describe(members[0])}. Why: {explanation}")
            continue
        lines.append(f"- {len(members)} cells with one reason:")
        lines.extend(f"  - {_describe(member)}" for member in members)
        lines.extend(["", f"  Why: {explanation}", ""])
    return [*lines, ""]


def _describe(difference: Difference) -> str:
    """One differing cell: its part, agent and setting, our mean and interval, and the paper's number."""
    cell = difference.cell
    return (
        f"**{difference.part}, {cell.label}** ({cell.setting}): ours {difference.mean:.2f} "
        f"[95% CI {difference.low:.2f}, {difference.high:.2f}] ({difference.seeds} seeds), {difference.direction} "
        f"than the paper's {cell.paper:g}"
    )


__all__ = [
    "CLAIM_REASONS",
    "EXPLANATIONS",
    "ClaimReason",
    "Difference",
    "Explanation",
    "claim_reason",
    "explain",
    "find_differences",
    "render_differences",
]
