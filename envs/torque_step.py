"""The physics step shared by the torque-driven MuJoCo envs (Reacher, Sawyer): validate, clip, integrate."""

from __future__ import annotations

import mujoco
import numpy as np


def step_torques(env_name: str, model: mujoco.MjModel, data: mujoco.MjData, action: object, frame_skip: int) -> None:
    """Apply a normalised torque action for ``frame_skip`` physics steps.

    :param env_name: the env's name, for error messages.
    :param model: the MuJoCo model.
    :param data: its data, advanced in place.
    :param action: [nu] torques in [-1, 1] (clipped there).
    :param frame_skip: physics steps per env step.
    :raises ValueError: for a wrong shape or a non-finite action.
    """
    torques = np.asarray(action, dtype=np.float64)
    if torques.shape != (model.nu,):
        raise ValueError(f"{env_name} expects an action of shape ({model.nu},), got {torques.shape}.")
    if not np.all(np.isfinite(torques)):
        # MuJoCo would only warn and silently reset the simulation; a NaN action is a bug in the caller.
        raise ValueError(
            f"{env_name} got a non-finite action {torques.tolist()}; actions must be finite (they are clipped to [-1, 1])."
        )
    data.ctrl[:] = np.clip(torques, -1.0, 1.0)
    mujoco.mj_step(model, data, nstep=frame_skip)
