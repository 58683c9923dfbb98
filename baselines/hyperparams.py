"""Per-environment PPO hyperparameters, rl-zoo3 style: one readable table keyed by env id, with a ``default`` entry.

Every entry lists only what differs from ``default``; :func:`ppo_hyperparams` merges the two. Values are plain
Python (numbers, strings, dicts) so the harness can print them and store them as JSON/YAML next to its results:

- ``learning_rate`` / ``clip_range`` accept rl-zoo3's ``"lin_<value>"`` strings (linear decay to 0 over training);
- ``policy_kwargs["activation_fn"]`` is a name (``"tanh"``, ``"relu"``, ...), turned into a ``torch.nn`` class by
  :func:`baselines.ppo.make_ppo`.

How the entries were chosen (see docs/baselines.md for the measured scores):

- Rollout sizes: ``n_envs * n_steps`` divides 10,000 (and so 50,000, 100,000, 250,000, 500,000), so PPO's rollout
  boundaries fall exactly on the project's budgets and SB3's ``learn`` stops at the budget with nothing wasted.
- No ``VecNormalize`` anywhere: the harness evaluates every agent on raw observations. Our observations are already
  O(1) (particle/maze in [-1, 1], Reacher angles in [-1, 1) and velocities / 10, Sawyer qvel / 10). The Sawyer's
  reward (-10 x metres per step) gives the largest returns; its entry lowers ``gamma`` (shorter value targets) and
  ``vf_coef`` (the value loss does not dominate the clipped gradient norm).
- Several envs per rollout: DESIGN §5 measured PPO on Reacher-v4 at 50k steps: SB3 defaults with 1 env score
  -35 to -60 (random: -42), 4 envs -12.5 to -15.5. Decorrelated rollouts matter more than anything else here.
- Reacher adapts rl-zoo3's tuned ``Reacher-v2`` entry (``gamma=0.9``, ``n_epochs=5``, ``clip_range=0.3``,
  ``gae_lambda`` close to 1) to 4 envs and a small budget (a larger learning rate, more minibatches).
- 2-D point envs (particle, maze): short horizons to the goal, actions saturate at |a| >= 1 (the env rescales by
  max(|a|_inf, 1)), so a larger learning rate and a moderate ``gamma`` learn the greedy reach quickly.
- Sawyer: 7-D torques; full-range random torques pin the arm at its joint limits (DESIGN §3), so the Gaussian
  policy starts narrow (``log_std_init=-1``) as rl-zoo3 does for its MuJoCo / PyBullet arms (``log_std_init=-2``,
  ``ortho_init=False``, ReLU 256 x 256).
"""

from __future__ import annotations

from typing import Any

PPO_HYPERPARAMS: dict[str, dict[str, Any]] = {
    "default": {
        "n_envs": 4,
        "n_steps": 250,  # 4 x 250 = 1000 transitions per rollout
        "batch_size": 100,
        "n_epochs": 10,
        "gamma": 0.99,
        "gae_lambda": 0.95,
        "learning_rate": 3e-4,
        "ent_coef": 0.0,
        "clip_range": 0.2,
        "max_grad_norm": 0.5,
        "vf_coef": 0.5,
        "policy_kwargs": {
            "net_arch": {"pi": [64, 64], "vf": [64, 64]},
            "activation_fn": "tanh",
            "log_std_init": 0.0,
            "ortho_init": True,
        },
    },
    "ebm/Particle-v0": {
        # 100-step episodes; an optimal reach takes about 10-30 steps.
        "n_envs": 4,
        "n_steps": 250,
        "batch_size": 100,
        "gamma": 0.95,
        "learning_rate": 1e-3,
        "n_epochs": 10,
    },
    "ebm/Maze-v0": {
        # 1000-step episodes and a 52-step optimal path around walls: a longer horizon than the particle.
        "n_envs": 4,
        "n_steps": 500,  # 4 x 500 = 2000 transitions per rollout, 2 episodes
        "batch_size": 200,
        "gamma": 0.98,
        "learning_rate": 1e-3,
        "n_epochs": 10,
    },
    "ebm/Reacher-v0": {
        # rl-zoo3 Reacher-v2: gamma 0.9, n_epochs 5, clip 0.3, gae_lambda 1.0, batch 32 (there with 1 env, 1e6 steps).
        "n_envs": 4,
        "n_steps": 250,  # 5 episodes of 50 steps per env per rollout
        "batch_size": 50,
        "gamma": 0.9,
        "gae_lambda": 0.98,
        "learning_rate": 5e-4,
        "n_epochs": 5,
        "clip_range": 0.3,
        "max_grad_norm": 0.9,
    },
    "ebm/SawyerReach-v0": {
        # 1000-step episodes, 7-D torques in [-1, 1], reward -10 x metres per step.
        "n_envs": 4,
        "n_steps": 500,
        "batch_size": 200,
        "gamma": 0.98,
        "gae_lambda": 0.92,
        "learning_rate": 1e-3,  # 3e-4 measured: -1142 / -4937 (seeds 0, 1); 1e-3: -1046 / -534 / -4658 (seeds 0-2)
        "n_epochs": 10,
        "vf_coef": 0.25,
        "max_grad_norm": 0.8,
        "policy_kwargs": {
            "net_arch": {"pi": [256, 256], "vf": [256, 256]},
            "activation_fn": "relu",
            "log_std_init": -1.0,
            "ortho_init": False,
        },
    },
}
"""PPO hyperparameters per Gymnasium id; ``default`` fills in whatever an entry leaves out."""
