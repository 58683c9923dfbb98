"""Inverse dynamics: the actions that take the environment from planned state s_t to planned state s_{t+1}."""

from __future__ import annotations

import contextlib
import json
from collections.abc import Callable, Sequence
from typing import Any, Protocol, runtime_checkable

import numpy as np
import torch
from torch import nn

from ebm_agent.moves import MoveStatistics
from ebm_agent.networks import build_mlp, normalise_dims

__all__ = [
    "GroundTruthInverseDynamics",
    "InverseDynamics",
    "MLPInverseDynamics",
    "PlanFollower",
    "RLSInverseDynamics",
    "make_inverse_dynamics",
]

INVERSE_DYNAMICS_KINDS = ("ground_truth", "mlp", "rls", "rls_tracking")
"""The kinds :func:`make_inverse_dynamics` builds: the env's own, a learned MLP, recursive least squares solved for
the next planned state (``"rls"``), or the same fit following the rest of the plan (``"rls_tracking"``)."""


@runtime_checkable
class InverseDynamics(Protocol):
    """What the agent needs from an inverse-dynamics model; batched over B transitions."""

    def __call__(self, states: np.ndarray, next_states: np.ndarray) -> np.ndarray:
        """
        Actions for the transitions.

        :param states: [B, D].
        :param next_states: [B, D].
        :return: [B, A] actions within the action bounds.
        """
        ...

    def update(self, states: np.ndarray, next_states: np.ndarray, actions: np.ndarray) -> dict[str, float]:
        """
        One learning step on real (executed) transitions.

        :param states: [B, D].
        :param next_states: [B, D].
        :param actions: [B, A] executed actions.
        :return: floats to log (empty for models that do not learn).
        """
        ...

    def state_dict(self) -> dict[str, Any]:
        """:return: everything needed to restore the model."""
        ...

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """:param state: a dict from :meth:`state_dict`."""
        ...


@runtime_checkable
class PlanFollower(Protocol):
    """An inverse model that can aim at several planned states ahead, not only the next one."""

    def follow(self, states: np.ndarray, plans_ahead: Sequence[np.ndarray]) -> np.ndarray:
        """
        The first action of each env's action sequence that best follows its planned states.

        :param states: [B, D] the states the actions start from.
        :param plans_ahead: B arrays [k_b, D] (k_b >= 1): the planned states after each one, in order.
        :return: [B, A] actions within the action bounds.
        """
        ...


class GroundTruthInverseDynamics:
    """
    The environment's own inverse dynamics (e.g. ``env.unwrapped.inverse_dynamics``), clipped to the action bounds.

    For the particle and maze this is the original's exact ``clip(20 * (s' - s), -1, 1)``.

    :param fn: batched ``fn(states [B, D], next_states [B, D]) -> actions [B, A]``.
    :param action_low: [A] lower action bounds.
    :param action_high: [A] upper action bounds.
    """

    def __init__(
        self,
        fn: Callable[[np.ndarray, np.ndarray], np.ndarray],
        action_low: np.ndarray,
        action_high: np.ndarray,
    ) -> None:
        if not callable(fn):
            raise TypeError(f"GroundTruthInverseDynamics: fn must be callable, got {type(fn).__name__}.")
        self.fn = fn
        self.action_low, self.action_high = _check_bounds(action_low, action_high, None, "GroundTruthInverseDynamics")
        self.action_dim = int(self.action_low.shape[0])

    def __call__(self, states: np.ndarray, next_states: np.ndarray) -> np.ndarray:
        states, next_states = _check_pairs(states, next_states, None, "GroundTruthInverseDynamics")
        actions = np.asarray(self.fn(states, next_states), dtype=np.float32)
        if actions.shape != (states.shape[0], self.action_dim):
            raise ValueError(
                f"GroundTruthInverseDynamics: fn returned shape {actions.shape}, expected "
                f"({states.shape[0]}, {self.action_dim}); fn must be batched over the first axis."
            )
        return np.clip(actions, self.action_low, self.action_high)

    def update(self, states: np.ndarray, next_states: np.ndarray, actions: np.ndarray) -> dict[str, float]:
        """Nothing to learn. :return: an empty dict."""
        return {}

    def state_dict(self) -> dict[str, Any]:
        """:return: an empty dict (the function is not saved; it comes from the env)."""
        return {}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Nothing to restore. :param state: ignored."""


class MLPInverseDynamics:
    """
    The original's learned inverse dynamics (``traj_model.TrajInverseDynamics``), trained on executed transitions.

    ``concat(s, s') -> Linear 32 - ReLU - Linear 32 - ReLU - Linear 32 - Linear(32 -> A, no bias)``, trained by MSE
    against the executed actions with Adam(lr, betas=(0.9, 0.999)). The original had no output squashing; here
    outputs are clipped to the action bounds at inference so that the actions are always valid.

    :param state_dim: D.
    :param action_dim: A.
    :param action_low: [A] lower action bounds.
    :param action_high: [A] upper action bounds.
    :param hidden_dim: width of the hidden layers (32).
    :param lr: Adam learning rate (1e-3).
    :param device: torch device of the network.
    :param seed: seed of the weight initialisation (the global torch RNG is left untouched).
    :param masked_dims: state dims zeroed in both inputs (e.g. the target dims, as for the energy).
    """

    def __init__(
        self,
        state_dim: int,
        action_dim: int,
        action_low: np.ndarray,
        action_high: np.ndarray,
        hidden_dim: int = 32,
        lr: float = 1e-3,
        device: str | torch.device = "cpu",
        seed: int | None = None,
        masked_dims: Sequence[int] = (),
    ) -> None:
        self.state_dim = _check_dim(state_dim, "state_dim", "MLPInverseDynamics")
        self.action_dim = _check_dim(action_dim, "action_dim", "MLPInverseDynamics")
        self.action_low, self.action_high = _check_bounds(action_low, action_high, self.action_dim, "MLPInverseDynamics")
        self.device = torch.device(device)
        self.masked_dims = normalise_dims(masked_dims, state_dim, "masked_dims")
        seed_context = _seeded_torch(seed) if seed is not None else contextlib.nullcontext()
        with seed_context:
            trunk = build_mlp(2 * state_dim, hidden_dim, hidden_dim=hidden_dim, num_hidden_layers=2, activation="relu")
            head = nn.Linear(hidden_dim, action_dim, bias=False)
            nn.init.xavier_uniform_(head.weight)
        # The original's third 32-unit layer has no activation before the bias-free output layer.
        self.module = nn.Sequential(*trunk, head).to(self.device)
        keep = torch.ones(2 * state_dim, device=self.device)
        for dim in self.masked_dims:
            keep[dim] = keep[state_dim + dim] = 0.0
        self._input_mask = keep  # [2D]
        self.optimizer = torch.optim.Adam(self.module.parameters(), lr=lr, betas=(0.9, 0.999))

    def _inputs(self, states: np.ndarray, next_states: np.ndarray) -> torch.Tensor:
        states, next_states = _check_pairs(states, next_states, self.state_dim, "MLPInverseDynamics")
        pairs = torch.as_tensor(np.concatenate([states, next_states], axis=1), device=self.device)  # [B, 2D]
        return pairs * self._input_mask

    def __call__(self, states: np.ndarray, next_states: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            actions = self.module(self._inputs(states, next_states)).cpu().numpy()  # [B, A]
        return np.clip(actions, self.action_low, self.action_high)

    def update(self, states: np.ndarray, next_states: np.ndarray, actions: np.ndarray) -> dict[str, float]:
        """
        One Adam step on the MSE to the executed actions.

        :return: ``{"id_loss": mse}`` before the step.
        """
        inputs = self._inputs(states, next_states)
        targets = torch.as_tensor(_check_actions(actions, inputs.shape[0], self.action_dim), device=self.device)
        loss = torch.mean((self.module(inputs) - targets) ** 2)
        self.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        self.optimizer.step()
        return {"id_loss": float(loss.detach())}

    def state_dict(self) -> dict[str, Any]:
        """:return: network and optimiser state."""
        return {"module": self.module.state_dict(), "optimizer": self.optimizer.state_dict()}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """:param state: a dict from :meth:`state_dict`."""
        self.module.load_state_dict(state["module"])
        self.optimizer.load_state_dict(state["optimizer"])


class RLSInverseDynamics:
    """
    Inverse dynamics from a linear forward model fitted online by recursive least squares.

    The forward model is ``s'_sub ~ W [s_sub; a; 1]`` over the state dims ``state_dims`` (default all; leave out
    the target dims, which no action moves). It is fitted by exact RLS with forgetting factor ``forgetting``
    (covariance P starts at ``init_cov * I``); each batch is one block update equal to feeding its rows one by one.
    Actions come from the Tikhonov-regularised solve ``min_a |W_a a - (s'_sub - W_s s_sub - b)|^2 +
    ridge |a - a_prior|^2``, clipped to the bounds. This is the original's ``--linear_inverse_dynamics`` ablation
    with its bug fixed: the original's NLMS update regressed onto s instead of s', learning the identity.

    ``ridge`` is absolute (0.3 as the original), so it only acts as a mild prior when W_a is large; for a system
    whose actions move the state little per step (the particle moves 0.05 per unit action) lower it.

    With ``track_steps`` other than 1, :meth:`follow` turns a plan into actions the way a tracking controller does
    (the planned states followed by a PD controller of the third-party reference's Diffuser numbers): through the
    fitted model it solves for the whole action sequence a_0 .. a_{k-1} whose predicted states best match the next
    k planned states, each dim in units of its real moves (the running std of s' - s), and returns a_0. A plan whose
    positions and velocities disagree (a planner that has not learnt that positions move by the velocities) is then
    followed where it goes over k steps, not matched one inconsistent step at a time.

    A fresh fit has W_a = 0, and the solve then returns the prior (zero) action for every transition: an agent
    acting on it would never move, so its data would never identify W_a. Until ``warmup`` transitions have been
    folded in, the model therefore answers with actions drawn uniformly within the bounds (from its own seeded
    generator), which excites every action direction, as an off-policy learner's random warm-up does.

    :param state_dim: D.
    :param action_dim: A.
    :param action_low: [A] lower action bounds.
    :param action_high: [A] upper action bounds.
    :param forgetting: RLS forgetting factor in (0, 1]; 1 weighs all data equally.
    :param ridge: Tikhonov weight pulling the action towards the prior action.
    :param init_cov: initial covariance scale (large: weak prior on W = 0).
    :param state_dims: dims of s and s' the model uses (None: all).
    :param warmup: transitions of uniformly random actions before the fit is used (None: 10 per feature, i.e.
        10 x (len(state_dims) + A + 1)); 0 solves from the first call.
    :param seed: seed of the warm-up actions' generator.
    :param track_steps: planned states :meth:`follow` aims at: 1 (the one-step solve of ``__call__``), k > 1 (up to
        k), or None (every planned state it is given).
    """

    def __init__(
        self,
        state_dim: int,
        action_dim: int,
        action_low: np.ndarray,
        action_high: np.ndarray,
        forgetting: float = 1.0,
        ridge: float = 0.3,
        init_cov: float = 1e3,
        state_dims: Sequence[int] | None = None,
        warmup: int | None = None,
        seed: int | None = None,
        track_steps: int | None = 1,
    ) -> None:
        self.state_dim = _check_dim(state_dim, "state_dim", "RLSInverseDynamics")
        self.action_dim = _check_dim(action_dim, "action_dim", "RLSInverseDynamics")
        self.action_low, self.action_high = _check_bounds(action_low, action_high, self.action_dim, "RLSInverseDynamics")
        if not 0.0 < forgetting <= 1.0:
            raise ValueError(f"RLSInverseDynamics: forgetting must be in (0, 1], got {forgetting}.")
        if ridge < 0:
            raise ValueError(f"RLSInverseDynamics: ridge must be >= 0, got {ridge}.")
        if init_cov <= 0:
            raise ValueError(f"RLSInverseDynamics: init_cov must be > 0, got {init_cov}.")
        self.forgetting = float(forgetting)
        self.ridge = float(ridge)
        self.init_cov = float(init_cov)
        dims = range(state_dim) if state_dims is None else state_dims
        self.state_dims = np.array(normalise_dims(dims, state_dim, "state_dims"), dtype=np.int64)
        if self.state_dims.size == 0:
            raise ValueError("RLSInverseDynamics: state_dims is empty; the model needs at least one state dim.")
        num_sub = self.state_dims.size
        self.num_features = num_sub + self.action_dim + 1  # F = [s_sub; a; 1]
        if warmup is not None and (isinstance(warmup, bool) or not isinstance(warmup, int | np.integer) or warmup < 0):
            raise ValueError(f"RLSInverseDynamics: warmup must be an int >= 0 or None, got {warmup!r}.")
        self.warmup = 10 * self.num_features if warmup is None else int(warmup)
        self._rng = np.random.default_rng(seed)
        self.weights = np.zeros((num_sub, self.num_features))  # [d, F] W = [W_s | W_a | b]
        self.covariance = np.eye(self.num_features) * self.init_cov  # [F, F] P
        self.num_updates = 0
        if track_steps is not None and (
            isinstance(track_steps, bool) or not isinstance(track_steps, int | np.integer) or track_steps < 1
        ):
            raise ValueError(f"RLSInverseDynamics: track_steps must be an int >= 1 or None, got {track_steps!r}.")
        self.track_steps = None if track_steps is None else int(track_steps)
        self.moves = MoveStatistics()  # the real moves s' - s over state_dims, the unit of follow()'s dims

    def __call__(self, states: np.ndarray, next_states: np.ndarray, prior_actions: np.ndarray | None = None) -> np.ndarray:
        """
        Regularised least-squares actions for each transition.

        :param states: [B, D].
        :param next_states: [B, D].
        :param prior_actions: [B, A] actions to regularise towards (e.g. the previous ones); zeros when None.
        :return: [B, A] actions clipped to the bounds (uniformly random ones during the warm-up).
        """
        states, next_states = _check_pairs(states, next_states, self.state_dim, "RLSInverseDynamics")
        batch = states.shape[0]
        if self.num_updates < self.warmup:  # W_a not identified yet: excite it (see the class docstring)
            return self._rng.uniform(self.action_low, self.action_high, size=(batch, self.action_dim)).astype(np.float32)
        num_sub = self.state_dims.size
        w_state = self.weights[:, :num_sub]  # [d, d]
        w_action = self.weights[:, num_sub : num_sub + self.action_dim]  # [d, A]
        bias = self.weights[:, -1]  # [d]
        s_sub = states[:, self.state_dims].astype(np.float64)
        residual = next_states[:, self.state_dims] - s_sub @ w_state.T - bias  # [B, d] what the action must do
        prior = (
            np.zeros((batch, self.action_dim))
            if prior_actions is None
            else _check_actions(prior_actions, batch, self.action_dim)
        )
        normal = w_action.T @ w_action + self.ridge * np.eye(self.action_dim)  # [A, A]
        rhs = residual @ w_action + self.ridge * prior  # [B, A]
        actions = np.linalg.lstsq(normal, rhs.T, rcond=None)[0].T  # lstsq: fine even while W_a is still zero
        return np.clip(actions, self.action_low, self.action_high).astype(np.float32)

    def follow(self, states: np.ndarray, plans_ahead: Sequence[np.ndarray]) -> np.ndarray:
        """
        The first action of each action sequence that best follows the planned states through the fitted model.

        With ``track_steps`` 1 this is ``__call__`` towards the first planned state, draw for draw. Otherwise, for k
        planned states (at most ``track_steps``), the stacked predictions s_j = M s_{j-1} + B a_{j-1} + b are
        linear in a = [a_0 .. a_{k-1}]: the solve minimises sum_j |(s_j - plan_j) / sigma|^2 + ridge |a|^2, with sigma
        [d] the std of the real moves per dim (ones before any), and returns a_0 clipped to the bounds.

        :param states: [B, D].
        :param plans_ahead: B arrays [k_b, D], k_b >= 1: each env's planned states after its state.
        :return: [B, A] actions (uniformly random ones during the warm-up).
        """
        if len(plans_ahead) != len(states):
            raise ValueError(
                f"RLSInverseDynamics.follow: {len(plans_ahead)} plans for {len(states)} states; pass one per state."
            )
        ahead = [np.asarray(plan).reshape(-1, self.state_dim) for plan in plans_ahead]
        if any(plan.shape[0] == 0 for plan in ahead):
            raise ValueError("RLSInverseDynamics.follow: every plan needs at least one planned state.")
        firsts = np.stack([plan[0] for plan in ahead]) if ahead else np.zeros((0, self.state_dim))  # [B, D] as given
        if self.track_steps == 1 or self.num_updates < self.warmup:
            return self(states, firsts)
        states, _ = _check_pairs(states, firsts, self.state_dim, "RLSInverseDynamics")
        limit = self.track_steps or max(plan.shape[0] for plan in ahead)
        lengths = np.array([min(plan.shape[0], limit) for plan in ahead])
        actions = np.zeros((len(states), self.action_dim))
        for k in np.unique(lengths):  # one stacked solve per number of steps ahead
            rows = np.flatnonzero(lengths == k)
            targets = np.stack([ahead[row][:k, self.state_dims] for row in rows]).astype(np.float64)  # [b, k, d]
            actions[rows] = self._sequence_solve(states[rows][:, self.state_dims].astype(np.float64), targets)
        return np.clip(actions, self.action_low, self.action_high).astype(np.float32)

    def _sequence_solve(self, s_sub: np.ndarray, targets: np.ndarray) -> np.ndarray:
        """First actions [b, A] of the weighted least-squares sequences from ``s_sub`` [b, d] to ``targets`` [b, k, d]."""
        num_sub, num_actions = self.state_dims.size, self.action_dim
        steps = targets.shape[1]
        w_state = self.weights[:, :num_sub]  # [d, d] M
        w_action = self.weights[:, num_sub : num_sub + num_actions]  # [d, A] B
        bias = self.weights[:, -1]  # [d] b
        powers = [np.eye(num_sub)]  # M^0 .. M^(k-1)
        for _ in range(steps - 1):
            powers.append(w_state @ powers[-1])
        gains = np.zeros((steps, num_sub, steps, num_actions))  # [k, d, k, A] d s_j / d a_i = M^(j-i) B for i <= j
        for j in range(steps):
            for i in range(j + 1):
                gains[j, :, i] = powers[j - i] @ w_action
        free = np.zeros_like(targets)  # [b, k, d] the predictions with every action zero
        state = s_sub
        for j in range(steps):
            state = state @ w_state.T + bias
            free[:, j] = state
        scale = self.moves.std if self.moves.count > 1 else np.ones(num_sub)  # [d]
        stacked = (gains / scale[None, :, None, None]).reshape(steps * num_sub, steps * num_actions)  # [k d, k A]
        residuals = ((targets - free) / scale).reshape(len(s_sub), steps * num_sub)  # [b, k d]
        normal = stacked.T @ stacked + self.ridge * np.eye(steps * num_actions)  # [k A, k A]
        sequence = np.linalg.lstsq(normal, stacked.T @ residuals.T, rcond=None)[0].T  # [b, k A]
        return sequence[:, :num_actions]

    def update(self, states: np.ndarray, next_states: np.ndarray, actions: np.ndarray) -> dict[str, float]:
        """
        Fold a batch of executed transitions into the least-squares fit.

        :return: ``{"id_loss": mean squared one-step prediction error before the update}``.
        """
        states, next_states = _check_pairs(states, next_states, self.state_dim, "RLSInverseDynamics")
        actions = _check_actions(actions, states.shape[0], self.action_dim)
        features = np.concatenate([states[:, self.state_dims], actions, np.ones((states.shape[0], 1))], axis=1).astype(
            np.float64
        )  # [B, F]
        targets = next_states[:, self.state_dims].astype(np.float64)  # [B, d]
        self.moves.update(features[:, : self.state_dims.size], targets)  # float64 s and s' over state_dims
        error = float(np.mean((targets - features @ self.weights.T) ** 2)) if states.shape[0] else 0.0
        for start in range(0, states.shape[0], 256):  # block size bounds the [b, b] innovation matrix
            self._block_update(features[start : start + 256], targets[start : start + 256])
        self.num_updates += states.shape[0]
        return {"id_loss": error}

    def _block_update(self, features: np.ndarray, targets: np.ndarray) -> None:
        # Exactly equivalent to b sequential RLS steps with forgetting lam: row j of the block ends up weighted
        # lam^(b-1-j) and the old information lam^b. With Lambda' = diag(lam^-(1+j)) (Woodbury, push-through):
        #   S = Lambda'^-1 + X P X^T, K = P X^T S^-1, theta += K (Y - X theta), P = lam^-b (P - K X P).
        count = features.shape[0]
        lam = self.forgetting
        p_xt = self.covariance @ features.T  # [F, b]
        innovation = np.diag(lam ** (1.0 + np.arange(count))) + features @ p_xt  # [b, b]
        gain = np.linalg.solve(innovation, p_xt.T).T  # [F, b], innovation is symmetric
        errors = targets - features @ self.weights.T  # [b, d]
        self.weights += (gain @ errors).T
        covariance = (self.covariance - gain @ p_xt.T) / lam**count
        self.covariance = 0.5 * (covariance + covariance.T)  # keep P symmetric against round-off

    def state_dict(self) -> dict[str, Any]:
        """:return: the fit (W, P), the number of transitions seen and the warm-up generator's state (JSON text)."""
        return {
            "weights": self.weights.copy(),
            "covariance": self.covariance.copy(),
            "num_updates": self.num_updates,
            "state_dims": self.state_dims.copy(),
            "rng_state": json.dumps(self._rng.bit_generator.state),
            # Flat, as a checkpoint stores a numpy model's state: moves_sums, moves_largest.
            **{f"moves_{key}": value for key, value in self.moves.state_dict().items()},
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """:param state: a dict from :meth:`state_dict` of a model with the same dims."""
        if not np.array_equal(np.asarray(state["state_dims"]), self.state_dims):
            raise ValueError(
                f"RLSInverseDynamics.load_state_dict: saved state_dims {state['state_dims']} differ from this model's "
                f"{self.state_dims}."
            )
        weights = np.asarray(state["weights"], dtype=np.float64)
        if weights.shape != self.weights.shape:
            raise ValueError(
                f"RLSInverseDynamics.load_state_dict: weights of shape {weights.shape}, expected {self.weights.shape}."
            )
        self.weights = weights.copy()
        self.covariance = np.asarray(state["covariance"], dtype=np.float64).copy()
        self.num_updates = int(state["num_updates"])
        if state.get("rng_state") is not None:  # absent in states saved before the warm-up existed
            self._rng.bit_generator.state = json.loads(state["rng_state"])
        # Absent in states saved before plan following: no move recorded.
        self.moves.load_state_dict({"sums": state.get("moves_sums"), "largest": state.get("moves_largest")})


def make_inverse_dynamics(
    kind: str,
    action_low: np.ndarray,
    action_high: np.ndarray,
    state_dim: int | None = None,
    action_dim: int | None = None,
    fn: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
    **kwargs: Any,
) -> InverseDynamics:
    """
    Build an inverse-dynamics model by name.

    :param kind: ``"ground_truth"`` (needs ``fn``), ``"mlp"``, ``"rls"`` or ``"rls_tracking"`` (RLS with
        ``track_steps=None``; the learned ones need ``state_dim``).
    :param action_low: [A] lower action bounds.
    :param action_high: [A] upper action bounds.
    :param state_dim: D (learned models).
    :param action_dim: A (defaults to the size of the bounds).
    :param fn: the env's batched inverse dynamics (ground truth).
    :param kwargs: extra constructor options of the chosen class (e.g. ``lr``, ``seed``, ``ridge``).
    :return: the model.
    :raises ValueError: for an unknown kind or a missing argument.
    """
    if kind == "ground_truth":
        if fn is None:
            raise ValueError(
                "make_inverse_dynamics('ground_truth') needs fn, e.g. fn=env.unwrapped.inverse_dynamics; "
                "use kind='rls_tracking', 'rls' or 'mlp' for an env without one."
            )
        if kwargs:
            raise ValueError(f"make_inverse_dynamics('ground_truth') takes no options, got {sorted(kwargs)}.")
        return GroundTruthInverseDynamics(fn, action_low, action_high)
    if kind in ("mlp", "rls", "rls_tracking"):
        if state_dim is None:
            raise ValueError(f"make_inverse_dynamics({kind!r}) needs state_dim.")
        if action_dim is None:
            action_dim = int(np.asarray(action_low).reshape(-1).shape[0])
        if kind == "mlp":
            return MLPInverseDynamics(state_dim, action_dim, action_low, action_high, **kwargs)
        if kind == "rls_tracking":
            kwargs = {"track_steps": None, **kwargs}
        return RLSInverseDynamics(state_dim, action_dim, action_low, action_high, **kwargs)
    raise ValueError(f"Unknown inverse dynamics kind {kind!r}; choose one of {list(INVERSE_DYNAMICS_KINDS)}.")


def _check_dim(value: Any, name: str, owner: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
        raise ValueError(f"{owner}: {name} must be a positive int, got {value!r}.")
    return int(value)


def _check_bounds(low: Any, high: Any, action_dim: int | None, owner: str) -> tuple[np.ndarray, np.ndarray]:
    low = np.asarray(low, dtype=np.float32).reshape(-1)
    high = np.asarray(high, dtype=np.float32).reshape(-1)
    if low.shape != high.shape or (action_dim is not None and low.shape[0] != action_dim):
        raise ValueError(
            f"{owner}: action_low and action_high must both have shape [{action_dim or 'A'}], got {low.shape} and "
            f"{high.shape}."
        )
    if np.any(low > high):
        raise ValueError(f"{owner}: action_low must be <= action_high, got low={low} high={high}.")
    return low, high


def _check_pairs(states: Any, next_states: Any, state_dim: int | None, owner: str) -> tuple[np.ndarray, np.ndarray]:
    states = np.asarray(states, dtype=np.float32)
    next_states = np.asarray(next_states, dtype=np.float32)
    if states.ndim != 2 or states.shape != next_states.shape or (state_dim is not None and states.shape[1] != state_dim):
        raise ValueError(
            f"{owner}: states and next_states must both have shape [B, {state_dim or 'D'}], got {states.shape} and "
            f"{next_states.shape}."
        )
    return states, next_states


def _check_actions(actions: Any, batch: int, action_dim: int) -> np.ndarray:
    actions = np.asarray(actions, dtype=np.float32)
    if actions.shape != (batch, action_dim):
        raise ValueError(f"actions must have shape ({batch}, {action_dim}), got {actions.shape}.")
    return actions


@contextlib.contextmanager
def _seeded_torch(seed: int):  # type: ignore[no-untyped-def]
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        yield
