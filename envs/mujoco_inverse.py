"""Batched ground-truth inverse dynamics for MuJoCo systems stepped several times under one constant control.

``mj_inverse`` answers "which generalised force gives this acceleration *now*"; an env step, though, holds one control
for ``frame_skip`` physics steps of an integrator (RK4 for Reacher, semi-implicit Euler with implicit damping for
Sawyer), so the force that moves s to s' over a whole env step is not the force at s (for the Sawyer's heavily damped
wrist the two differ by up to 0.6 of the action range). The solver takes ``mj_inverse``'s answer for the step's mean
acceleration as a first guess and refines it on the simulator itself: damped Gauss-Newton on the mismatch between the
rolled-out end state and s', with a forward-difference Jacobian from batched rollouts (``mujoco.rollout``, in C),
reused across steps, and a line search that never lets the mismatch grow. Joint limits that engage inside a step put
jumps in the control -> state map; samples that stall beside one get a multi-start rescue. For transitions the
simulator produced, the recovered control is exact to ~1e-8 for all but ~0.2 % of them (docs/mujoco_envs.md).
"""

from __future__ import annotations

import copy
from collections.abc import Callable

import mujoco
import numpy as np
from mujoco import rollout

ResidualFn = Callable[..., np.ndarray]
"""``residual(qpos_end [B, M, nq], qvel_end [B, M, nv], targets [B, 1, T]) -> [B, M, R]``: the weighted mismatch of
M rolled-out end states per sample with that sample's wanted next state (``targets`` as given to ``solve``). A solver
built with ``end_sensors=True`` passes the model's sensor readings at the end states as a fourth argument
``sensors_end [B, M, nsensordata]`` (e.g. ``framepos`` sensors of a fingertip)."""

_STEP_SCALES = np.array([0.5, 0.25, 0.1])
"""Fractions of the Gauss-Newton step tried by the line search when the full step does not help."""


class FrameSkipInverseDynamics:
    """Recover the constant control that carries a MuJoCo system from one state to the next over ``frame_skip`` steps.

    :param model: the compiled model the env steps (it is copied: the copy enables discrete-time inverse dynamics
        and disables control clamping so finite differences see the dynamics beyond the control range).
    :param frame_skip: physics steps per env step.
    :param iterations: at most this many Gauss-Newton steps after the ``mj_inverse`` guess (0: the clipped guess).
    :param fd_step: finite-difference step on the control for the Jacobian.
    :param damping: Levenberg-Marquardt damping added to ``J^T J`` (keeps unreachable targets well posed).
    :param tolerance: residual norm (state units) at which a sample counts as solved.
    :param rescue_tolerance: residual norm above which a sample gets the multi-start rescue (``None``: never).
    :param rescue_ceiling: residual norm above which a sample is taken as unreachable and gets no rescue (``None``:
        no ceiling). The rescue gets past a jump of the control -> state map beside a reachable target; for a target
        far out of reach (a planned state no control gives) Gauss-Newton's least-squares answer is kept.
    :param scan_points: values per control dim in the rescue's coordinate scan (0: no scan).
    :param rescue_starts: random candidate controls per stalled sample in the rescue.
    :param rescue_keep: candidates per stalled sample that the rescue refines.
    :param end_sensors: also pass the model's sensor readings at each rolled-out end state to the residual.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        frame_skip: int,
        iterations: int = 6,
        fd_step: float = 1e-4,
        damping: float = 1e-12,
        tolerance: float = 1e-9,
        rescue_tolerance: float | None = 1e-5,
        rescue_ceiling: float | None = None,
        scan_points: int = 41,
        rescue_starts: int = 128,
        rescue_keep: int = 8,
        end_sensors: bool = False,
    ) -> None:
        if frame_skip < 1:
            raise ValueError(f"frame_skip must be >= 1, got {frame_skip}.")
        if end_sensors and model.nsensordata < 1:
            raise ValueError("end_sensors=True needs a model with sensors; this one has none.")
        if model.nu < 1:
            raise ValueError("The model has no actuators; inverse dynamics needs at least one.")
        self.model = copy.copy(model)
        if self.model.opt.integrator != mujoco.mjtIntegrator.mjINT_RK4:
            # Discrete-time inverse dynamics makes mj_inverse exact for one Euler step with implicit damping
            # (MuJoCo supports it for every integrator but RK4).
            self.model.opt.enableflags |= int(mujoco.mjtEnableBit.mjENBL_INVDISCRETE)
        self.model.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CLAMPCTRL)
        self.data = mujoco.MjData(self.model)
        self.frame_skip = int(frame_skip)
        self.iterations = int(iterations)
        self.fd_step = float(fd_step)
        self.damping = float(damping)
        self.tolerance = float(tolerance)
        self.rescue_tolerance = rescue_tolerance
        self.rescue_ceiling = rescue_ceiling
        self.scan_points = int(scan_points)
        self.rescue_starts = int(rescue_starts)
        self.rescue_keep = int(rescue_keep)
        self.end_sensors = bool(end_sensors)
        self.ctrl_low = self.model.actuator_ctrlrange[:, 0].copy()
        self.ctrl_high = self.model.actuator_ctrlrange[:, 1].copy()
        self._state_spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
        self._template_state = np.empty(mujoco.mj_stateSize(self.model, self._state_spec))
        mujoco.mj_getState(self.model, self.data, self._template_state, self._state_spec)
        # Full-physics state layout: [time, qpos, qvel, act, ...].
        self._qpos_slice = slice(1, 1 + self.model.nq)
        self._qvel_slice = slice(1 + self.model.nq, 1 + self.model.nq + self.model.nv)

    def solve(
        self,
        qpos: np.ndarray,
        qvel: np.ndarray,
        next_qvel: np.ndarray,
        targets: np.ndarray,
        residual: ResidualFn,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Controls (within the actuators' ctrlrange) that best reproduce the wanted next states.

        :param qpos: [B, nq] start positions.
        :param qvel: [B, nv] start velocities.
        :param next_qvel: [B, nv] wanted velocities after the env step (seeds the ``mj_inverse`` guess).
        :param targets: [B, T] the wanted next states, passed to ``residual`` as [B, 1, T].
        :param residual: mismatch of rolled-out end states with ``targets``; the solver minimises its squared norm.
        :return: [B, nu] controls and [B] their squared residual norms (0 for an exactly reproduced transition).
        """
        if qpos.shape[0] == 0:
            return np.zeros((0, self.model.nu)), np.zeros(0)
        # Mocap bodies keep the model's positions: here they are markers with no dynamics.
        start = np.tile(self._template_state, (qpos.shape[0], 1))  # [B, nstate]
        start[:, 0] = 0.0
        start[:, self._qpos_slice] = qpos
        start[:, self._qvel_slice] = qvel
        targets = targets[:, None, :]  # [B, 1, T]

        ctrl = np.clip(self._mj_inverse_guess(qpos, qvel, next_qvel), self.ctrl_low, self.ctrl_high)  # [B, nu]
        ctrl, cost = self._refine(start, ctrl, targets, residual)  # [B, nu], [B]
        if self.rescue_tolerance is None or self.iterations == 0:
            return ctrl, cost

        # Joint limits and contacts that engage inside a step put jumps in the control -> state map, and
        # Gauss-Newton can stall beside one; those samples get a multi-start second try.
        stuck = cost > self.rescue_tolerance**2
        if self.rescue_ceiling is not None:
            stuck &= cost <= self.rescue_ceiling**2
        stalled = np.flatnonzero(stuck)
        if stalled.size:
            rescued, rescued_cost = self._rescue(start[stalled], ctrl[stalled], targets[stalled], residual)
            better = rescued_cost < cost[stalled]
            ctrl[stalled[better]] = rescued[better]
            cost[stalled[better]] = rescued_cost[better]
        return ctrl, cost

    # ------------------------------------------------------------------------------------------------- internals
    def _end_states(self, start: np.ndarray, ctrl: np.ndarray) -> tuple[np.ndarray, ...]:
        """Roll out M candidate controls [B, M, nu] from each of B start states.

        :return: end states [B, M, nq], [B, M, nv], and with ``end_sensors`` their sensor readings [B, M, nsensordata].
        """
        batch, candidates, nu = ctrl.shape
        starts = np.repeat(start, candidates, axis=0)  # [B * M, nstate]
        # A [B * M, 1, nu] control is held (tiled) over the frame_skip steps by rollout; it records the sensors of
        # the state after each step.
        states, sensors = rollout.rollout(self.model, self.data, starts, ctrl.reshape(-1, 1, nu), nstep=self.frame_skip)
        final = states[:, -1, :].reshape(batch, candidates, -1)  # [B, M, nstate]
        ends: tuple[np.ndarray, ...] = (final[..., self._qpos_slice], final[..., self._qvel_slice])
        if self.end_sensors:
            ends += (sensors[:, -1, :].reshape(batch, candidates, -1),)  # [B, M, nsensordata]
        return ends

    def _residual_of(self, start: np.ndarray, ctrl: np.ndarray, targets: np.ndarray, residual: ResidualFn) -> np.ndarray:
        """Residual [B, M, R] of M candidate controls [B, M, nu] per sample."""
        qpos, qvel, *sensors = self._end_states(start, ctrl)
        return residual(qpos, qvel, targets, *sensors)

    def _refine(
        self, start: np.ndarray, ctrl: np.ndarray, targets: np.ndarray, residual: ResidualFn
    ) -> tuple[np.ndarray, np.ndarray]:
        """Up to ``iterations`` damped Gauss-Newton steps, each with a line search that never increases the cost.

        The forward-difference Jacobian (nu rollouts per sample) is computed at the first step and reused after it
        (a chord method: the control enters the dynamics almost linearly); a sample whose reused-Jacobian step does
        not help gets a fresh one. Samples drop out once their residual norm is below ``tolerance``, or when a step
        with a fresh Jacobian no longer helps.

        :return: refined controls [B, nu] and their squared residual norms [B].
        """
        batch, nu = ctrl.shape
        ctrl = ctrl.copy()
        current = self._residual(start, ctrl, targets, residual)  # [B, R]
        jacobian = np.zeros((batch, current.shape[1], nu))  # [B, R, nu]
        stale = np.ones(batch, dtype=bool)
        active = np.flatnonzero(np.sum(current**2, axis=-1) > self.tolerance**2)
        for _ in range(self.iterations):
            if active.size == 0:
                break
            refresh = active[stale[active]]
            if refresh.size:
                jacobian[refresh] = self._jacobian(start[refresh], ctrl[refresh], current[refresh], targets[refresh], residual)
            was_fresh = stale[active].copy()
            stale[refresh] = False
            new_ctrl, new_residual, improved = self._step(
                start[active], ctrl[active], current[active], jacobian[active], targets[active], residual
            )
            ctrl[active], current[active] = new_ctrl, new_residual
            unsolved = np.sum(new_residual**2, axis=-1) > self.tolerance**2
            stale[active[~improved]] = True
            # Keep going while improving, or to retry once with a fresh Jacobian.
            active = active[unsolved & (improved | ~was_fresh)]
        return ctrl, np.sum(current**2, axis=-1)

    def _jacobian(
        self, start: np.ndarray, ctrl: np.ndarray, current: np.ndarray, targets: np.ndarray, residual: ResidualFn
    ) -> np.ndarray:
        """Forward-difference Jacobian [B, R, nu] of the residual at ``ctrl`` [B, nu] (current residual [B, R])."""
        nu = ctrl.shape[1]
        probes = ctrl[:, None, :] + self.fd_step * np.eye(nu)  # [B, nu, nu]: one perturbed copy per control dim
        perturbed = self._residual_of(start, probes, targets, residual)  # [B, nu, R]
        return np.swapaxes((perturbed - current[:, None, :]) / self.fd_step, 1, 2)

    def _step(
        self,
        start: np.ndarray,
        ctrl: np.ndarray,
        current: np.ndarray,
        jacobian: np.ndarray,
        targets: np.ndarray,
        residual: ResidualFn,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """One damped Gauss-Newton step; the full step, else the best shorter one, else no move.

        :return: controls [B, nu], residuals [B, R], and whether each sample improved [B].
        """
        nu = ctrl.shape[1]
        cost = np.sum(current**2, axis=-1)  # [B]
        jt = np.swapaxes(jacobian, 1, 2)  # [B, nu, R]
        step = np.linalg.solve(jt @ jacobian + self.damping * np.eye(nu), jt @ current[..., None])[..., 0]  # [B, nu]
        trial = np.clip(ctrl - step, self.ctrl_low, self.ctrl_high)
        trial_residual = self._residual(start, trial, targets, residual)  # [B, R]
        worse = np.flatnonzero(np.sum(trial_residual**2, axis=-1) >= cost)
        if worse.size:
            shorter = ctrl[worse, None, :] - _STEP_SCALES[None, :, None] * step[worse, None, :]  # [W, L, nu]
            shorter = np.clip(shorter, self.ctrl_low, self.ctrl_high)
            shorter_residual = self._residual_of(start[worse], shorter, targets[worse], residual)  # [W, L, R]
            best = np.argmin(np.sum(shorter_residual**2, axis=-1), axis=1)
            trial[worse] = shorter[np.arange(worse.size), best]
            trial_residual[worse] = shorter_residual[np.arange(worse.size), best]
        improved = np.sum(trial_residual**2, axis=-1) < cost
        return (
            np.where(improved[:, None], trial, ctrl),
            np.where(improved[:, None], trial_residual, current),
            improved,
        )

    def _residual(self, start: np.ndarray, ctrl: np.ndarray, targets: np.ndarray, residual: ResidualFn) -> np.ndarray:
        """Residual [B, R] of controls [B, nu]."""
        return self._residual_of(start, ctrl[:, None, :], targets, residual)[:, 0, :]

    def _rescue(
        self, start: np.ndarray, ctrl: np.ndarray, targets: np.ndarray, residual: ResidualFn
    ) -> tuple[np.ndarray, np.ndarray]:
        """Multi-start search for stalled samples: Gauss-Newton from the best few of many candidate controls.

        Candidates: the stalled control, a coordinate-wise grid scan from it, ``rescue_starts`` / 2 Gaussian
        perturbations of it (std 0.3 of the range) and as many uniform draws; the ``rescue_keep`` cheapest are refined.
        The draws use a fixed seed so that inverse dynamics is a deterministic function of its inputs.

        :return: controls [S, nu] and squared residual norms [S].
        """
        batch, nu = ctrl.shape
        rng = np.random.default_rng(0)
        half_range = 0.5 * (self.ctrl_high - self.ctrl_low)
        half = self.rescue_starts // 2
        candidates = np.concatenate(
            [
                ctrl[:, None, :],
                *([self._scan(start, ctrl, targets, residual)[:, None, :]] if self.scan_points > 0 else []),
                ctrl[:, None, :] + 0.3 * half_range * rng.standard_normal((batch, half, nu)),
                rng.uniform(self.ctrl_low, self.ctrl_high, (batch, half, nu)),
            ],
            axis=1,
        )  # [S, C, nu]
        candidates = np.clip(candidates, self.ctrl_low, self.ctrl_high)
        cost = np.sum(self._residual_of(start, candidates, targets, residual) ** 2, axis=-1)  # [S, C]
        keep = min(self.rescue_keep, candidates.shape[1])
        chosen = np.argsort(cost, axis=1)[:, :keep]  # [S, keep]
        starts = candidates[np.arange(batch)[:, None], chosen].reshape(-1, nu)  # [S * keep, nu]
        refined, refined_cost = self._refine(
            np.repeat(start, keep, axis=0), starts, np.repeat(targets, keep, axis=0), residual
        )
        best = np.argmin(refined_cost.reshape(batch, keep), axis=1)
        rows = np.arange(batch)
        return refined.reshape(batch, keep, nu)[rows, best], refined_cost.reshape(batch, keep)[rows, best]

    def _scan(self, start: np.ndarray, ctrl: np.ndarray, targets: np.ndarray, residual: ResidualFn) -> np.ndarray:
        """Coordinate-wise grid search: each control dim in turn over ``scan_points`` values, the others held."""
        batch, nu = ctrl.shape
        grid = np.linspace(self.ctrl_low, self.ctrl_high, self.scan_points)  # [P, nu]
        for dim in range(nu):
            candidates = np.repeat(ctrl[:, None, :], self.scan_points + 1, axis=1)  # [B, P+1, nu]; slot 0 keeps ctrl
            candidates[:, 1:, dim] = grid[:, dim]
            cost = np.sum(self._residual_of(start, candidates, targets, residual) ** 2, axis=-1)  # [B, P+1]
            ctrl = candidates[np.arange(batch), np.argmin(cost, axis=1)]
        return ctrl

    def _mj_inverse_guess(self, qpos: np.ndarray, qvel: np.ndarray, next_qvel: np.ndarray) -> np.ndarray:
        model, data = self.model, self.data
        env_dt = self.frame_skip * model.opt.timestep
        batch = qpos.shape[0]
        forces = np.empty((batch, model.nv))  # [B, nv] generalised forces that give the mean acceleration
        moments = np.zeros((batch, model.nu, model.nv))  # [B, nu, nv] actuator moments (gear on the dof for motors)
        for i in range(batch):
            data.qpos[:] = qpos[i]
            data.qvel[:] = qvel[i]
            # The step's mean acceleration, treated as if it held from the start state.
            data.qacc[:] = (next_qvel[i] - qvel[i]) / env_dt
            mujoco.mj_inverse(model, data)
            forces[i] = data.qfrc_inverse
            mujoco.mju_sparse2dense(
                moments[i], data.actuator_moment, data.moment_rownnz, data.moment_rowadr, data.moment_colind
            )
        # Least-squares controls: qfrc = moment^T ctrl.
        return (np.linalg.pinv(np.swapaxes(moments, 1, 2)) @ forces[..., None])[..., 0]
