"""The expert at physics rate: the env's control hook (reset, the call after ``mj_step1``, and its fast lane).

At every physics step :class:`PhysicsHook` reads the measured state (into the expert's own model, unless it shares
the simulator's data), lets the disturbance recovery and the friction adaptation look at it on their check steps,
plans the next cycle when the current one is over, and computes the joint torques: by the controller's compiled
step on the plan's grid (:meth:`ComputedTorqueController.grid_step_into`) where it applies, else by the readable
controller call (:meth:`ComputedTorqueController.__call__`, the reference both are tested equal to), times the
adaptive gains of ``ExpertConfig.adaptation`` (:mod:`agents.control.adaptation`) if any. The env's fast lane
(:meth:`PhysicsHook.torques_into`) takes a plain grid step without the call's Python.

It never raises out of a rollout once reset: a failure of the controller at a physics step (logged with its
reason) keeps the last good torques for that step.
"""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np

from agents.control import inverse_dynamics_kernels as IK
from agents.control.adaptation import AdaptiveGains
from agents.control.controller import ComputedTorqueController
from agents.control.nominal import NominalModel
from agents.expert.config import ExpertConfig
from agents.expert.cycle import CyclePlanner
from agents.expert.friction import SLIP_CHECK_EVERY, FrictionAdaptation
from agents.expert.log import FailureLog
from agents.expert.recovery import DISTURBANCE_CHECK_EVERY, NO_OFF_PLAN_CHECK, DisturbanceRecovery
from planners.types import ReferenceSample
from quad_uneven_env import constants as C
from quad_uneven_env.measurement_kernels import clip_finite_into

NOT_ATTACHED = (
    "the ExpertPolicy acts through the env's physics-rate hook, and this env's hook is not reset by it: build it with "
    "attach_expert(env, config) (or install it, or a controller that holds it as `.expert` and forwards reset to it, "
    "with env.unwrapped.set_controller) before env.reset()"
)
"""The message of the RuntimeError an expert that is not its env's controller raises instead of acting."""


class PhysicsHook:
    """The expert's physics-rate controller (:class:`quad_uneven_env.env.PhysicsController`).

    :param config: the expert's settings.
    :param controller: the computed-torque controller (its reference: ``planner.reference``).
    :param nominal: the expert's own model, or None (``model="oracle"``: the simulator's).
    :param planner: the gait-cycle planner.
    :param recovery: the disturbance check.
    :param friction: the friction assumption and the slip check.
    :param adaptation: the adaptive gains on the torques, or None.
    :param log: where failures go.
    """

    def __init__(
        self,
        config: ExpertConfig,
        controller: ComputedTorqueController,
        nominal: NominalModel | None,
        planner: CyclePlanner,
        recovery: DisturbanceRecovery,
        friction: FrictionAdaptation,
        adaptation: AdaptiveGains | None,
        log: FailureLog,
    ) -> None:
        self.config = config
        self.controller = controller
        self.nominal = nominal
        self.planner = planner
        self.recovery = recovery
        self.friction = friction
        self.adaptation = adaptation
        self.log = log
        self.compiled = True
        """take the controller's compiled step where it applies (False: the readable controller call at every
        physics step, the reference the compiled step is tested equal to; slower)."""
        self.shares_simulator_data = False
        """this episode's dynamics terms are read from the simulator's data ("oracle", or "nominal" in an
        exactly nominal world with ``share_nominal_world``); False: from the nominal model's copy."""
        self.tau_ok = np.zeros(C.N_JOINTS)
        """(12,) N m: the torques of the last successful physics step."""
        self._foot_sensor_adr = planner.foot_sensor_adr
        self._clipped = np.empty(C.N_JOINTS)  # the compiled step's copy clipped to the motor limits (unused)
        self._data: mujoco.MjData | None = None  # the data the expert plans and controls with
        self._model: mujoco.MjModel | None = None
        self._sim: mujoco.MjData | None = None  # the simulator's: measured state and contact flags only
        self._terrain: Any = None
        self._steps = 0
        self._last_controller_error = ""

    def reset_with(self, data: mujoco.MjData) -> bool:
        """Whether the env's last reset reached this hook with the simulator's data ``data``."""
        return self._sim is data

    def reset(self, model: mujoco.MjModel, data: mujoco.MjData, terrain: Any) -> None:
        """Called by the env at every reset: plan the first cycle from the measured stand."""
        self._sim = data
        self._terrain = terrain
        self.log.clear()
        self._last_controller_error = ""
        self.tau_ok[:] = 0.0
        self._steps = 0
        self.recovery.reset()
        nominal = self.nominal
        self.friction.reset(self.controller, model)
        if nominal is None:  # oracle: the simulator's model (and the friction of its foot-terrain contacts)
            self.shares_simulator_data = True
            self._model, self._data = model, data
        else:
            self.shares_simulator_data = self.config.share_nominal_world and nominal.matches(model)
            if self.shares_simulator_data:
                self._model, self._data = model, data
            else:
                self._model, self._data = nominal.model, nominal.measure(data.qpos, data.qvel, data.time)
        self.controller.reset(self._model, self._data, terrain)
        self.friction.start(self._model)
        self.planner.reset(self._data, data, terrain)
        if self.adaptation is not None:
            self.adaptation.reset(float(data.time))

    def planned_now(self, sim_time: float) -> tuple[ReferenceSample, float]:
        """The current plan at simulator time ``sim_time`` (s) (:meth:`CyclePlanner.planned_now`)."""
        return self.planner.planned_now(sim_time - self.controller.t0)

    def __call__(self, model: mujoco.MjModel, data: mujoco.MjData, action: np.ndarray) -> np.ndarray:
        """Joint torques (N m) of the computed-torque controller at the measured state, times the adaptive gains
        (``ExpertConfig.adaptation``).

        Never raises once reset: a failing step (logged in the failure log) returns the last good torques.

        :raises RuntimeError: if the env's reset has not reached this hook (:data:`NOT_ATTACHED`).
        """
        if self._sim is None:
            raise RuntimeError(NOT_ATTACHED)
        tau = self._controller_torques(model, data, action)
        if self.adaptation is None:
            return tau
        return self.adaptation.apply(tau, float(data.time), data.qpos[7:], self.planned_now)

    def _controller_torques(self, model: mujoco.MjModel, data: mujoco.MjData, action: np.ndarray) -> np.ndarray:
        """Joint torques (N m) of the computed-torque controller (the call's, before the adaptive gains)."""
        try:
            own = data if self.shares_simulator_data else self.nominal.measure(data.qpos, data.qvel, data.time)  # type: ignore[union-attr]
            self._steps += 1
            ctrl = self.controller
            if self.recovery.enabled and self._steps % DISTURBANCE_CHECK_EVERY == 0:
                self.recovery.check(own, ctrl.t0)
            if self.friction.adapting and self._steps % SLIP_CHECK_EVERY == 0:
                touch = self._sim.sensordata[self._foot_sensor_adr]
                self.friction.check_slip(self._model, own, self.planner.planned_stance, touch, self._terrain)
            contacts = None if self.shares_simulator_data else ctrl.foot_contact_bits(data)
            if self.compiled and self._compiled_step(model, own, contacts):
                return self.tau_ok.copy()
            tau = ctrl(model, data, action) if contacts is None else ctrl(self._model, own, action, contacts)
            if tau.shape == self.tau_ok.shape and IK.copy_if_finite(tau, self.tau_ok):
                return tau
            err = "non-finite torques"
        except Exception as exc:  # degrade, never crash a rollout
            err = f"{type(exc).__name__}: {exc}"
        if err != self._last_controller_error:  # one entry per run of equal failures
            self.log.add(f"t={float(data.time):.3f} s: controller failed ({err}); keeping the last good torques")
        self._last_controller_error = err
        return self.tau_ok.copy()

    def _compiled_step(self, model: mujoco.MjModel, own: mujoco.MjData, contacts: int | None) -> bool:
        """The controller's call by its compiled step on the plan's grid (the next cycle planned first when this
        one is over, as the call's reference would); False where the readable call must run."""
        ctrl, planner = self.controller, self.planner
        t = float(own.time) - ctrl.t0
        if t >= planner.t_end:
            planner.advance(t)
        grid = planner.grid
        if grid is None:  # a hold
            return False
        m = model if contacts is None else self._model
        done = ctrl.grid_step_into(
            m, own, grid, planner.t_start, planner.t_end, self._sim.sensordata, self._foot_sensor_adr, self.tau_ok,  # type: ignore[union-attr]
            ctrl.torque_limit, self._clipped, NO_OFF_PLAN_CHECK, -1 if contacts is None else contacts,
        )  # fmt: skip
        return done == 1

    def torques_into(
        self, model: mujoco.MjModel, data: mujoco.MjData, action: Any, out: np.ndarray, limit: np.ndarray
    ) -> bool:
        """The hook's fast lane (:class:`~quad_uneven_env.env.PhysicsController`): the torques ``self(model,
        data, action)`` returns, clipped to ``±limit`` (N m), written into ``out`` in one compiled call when the
        step is a plain grid step; False where the full call must run instead (nothing it would not redo the
        same way changed: the own model's copy of the measured state, the inverse-dynamics buffers). The action
        is ignored, as by the call. With an adaptation the lane writes the controller's torques unclipped, and
        the gains and the clip follow here, as in the call.

        Never taken on a slip-check step, and on a disturbance-check step only while the base is on its plan (the
        check is compiled into the call). Outside the nominal world the measured state is first copied into the
        expert's own model, as the call does.
        """
        adaptation = self.adaptation
        if adaptation is not None:
            if not self._lane_torques_into(model, data, adaptation.raw, adaptation.no_limit):
                return False
            tau = adaptation.apply(adaptation.raw, float(data.time), data.qpos[7:], self.planned_now)
            return bool(clip_finite_into(tau, limit, out))
        return self._lane_torques_into(model, data, out, limit)

    def _lane_torques_into(
        self, model: mujoco.MjModel, data: mujoco.MjData, out: np.ndarray, limit: np.ndarray
    ) -> bool:
        """:meth:`torques_into` before the adaptive gains."""
        planner = self.planner
        grid = planner.grid
        if grid is None or data is not self._sim or not self.compiled:
            return False
        steps = self._steps + 1
        if self.friction.adapting and steps % SLIP_CHECK_EVERY == 0:
            return False
        ctrl = self.controller
        if self.shares_simulator_data:
            own, contacts = data, -1
        else:
            own, model = self.nominal.measure(data.qpos, data.qvel, data.time), self._model  # type: ignore[union-attr]
            contacts = ctrl.foot_contact_bits(data)
        off_plan = NO_OFF_PLAN_CHECK
        if steps % DISTURBANCE_CHECK_EVERY == 0:
            off_plan = self.recovery.lane_tolerance(own.time - ctrl.t0)
        done = ctrl.grid_step_into(
            model, own, grid, planner.t_start, planner.t_end, data.sensordata, self._foot_sensor_adr, self.tau_ok,
            limit, out, off_plan, contacts,
        )  # fmt: skip
        if done == 1:
            self._steps = steps
        return done == 1


__all__ = ["NOT_ATTACHED", "PhysicsHook"]
