"""The SB3 policy object of a planning agent: a holder for its learned networks and their optimiser."""

from __future__ import annotations

from typing import Any

import torch
from gymnasium import spaces
from stable_baselines3.common.policies import BasePolicy
from torch import nn

from ebm_agent.optim import ClippedAdam


class PlanningPolicy(BasePolicy):
    """Holds the learned networks of a planning agent so that SB3's ``save``/``load``/``get_parameters`` see them.

    A planner's action depends on more than one observation (the warm-started plan, the inverse dynamics, extra
    energies), so acting lives in the agent's ``predict``; this object only owns parameters. ``networks`` maps a
    name to a module (e.g. ``{"energy": EnergyModel}``); each becomes an attribute, and ``optimizer`` covers the
    parameters of the modules named in ``trained``.

    :param observation_space: the env's observation space.
    :param action_space: the env's action space.
    :param networks: name -> module.
    :param learning_rate: learning rate of the optimiser.
    :param betas: Adam betas; (0.0, 0.999) as the original's EBM optimiser.
    :param clip_sigma: per-element gradient clip in units of the running gradient std (the original's custom Adam);
        None for plain Adam.
    :param trained: names of the networks the optimiser updates (all when None).
    """

    def __init__(
        self,
        observation_space: spaces.Space,
        action_space: spaces.Space,
        networks: dict[str, nn.Module] | None = None,
        learning_rate: float = 1e-3,
        betas: tuple[float, float] = (0.0, 0.999),
        clip_sigma: float | None = 3.0,
        trained: list[str] | None = None,
    ) -> None:
        super().__init__(observation_space, action_space)
        self.network_names = list((networks or {}).keys())
        for name, module in (networks or {}).items():
            self.add_module(name, module)
        names = self.network_names if trained is None else trained
        params = [p for name in names for p in getattr(self, name).parameters()]
        self.optimizer = ClippedAdam(params, lr=learning_rate, betas=betas, clip_sigma=clip_sigma) if params else None  # type: ignore[assignment]

    def network(self, name: str) -> nn.Module:
        """The network registered under ``name``.

        :param name: e.g. ``"energy"`` or ``"dynamics"``.
        :return: the module.
        """
        module = getattr(self, name)
        assert isinstance(module, nn.Module)
        return module

    def _predict(self, observation: Any, deterministic: bool = False) -> torch.Tensor:
        raise NotImplementedError(
            "A planning policy acts through the agent (agent.predict), which keeps the warm-started plan between "
            "calls; call agent.predict(obs, state=state, episode_start=...) instead of agent.policy.predict."
        )

    def forward(self, *args: Any, **kwargs: Any) -> torch.Tensor:
        """Not used: see :meth:`_predict`."""
        return self._predict(None)
