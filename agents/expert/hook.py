"""The expert at physics rate: the env's physics-rate controller (reset, the call after ``mj_step1``, its fast lane).

:class:`PhysicsHook` is the physics-rate side of :class:`~agents.expert.policy.ExpertPolicy`. Every physics step
goes through one method, :meth:`PhysicsHook._step_into`, whether the env takes the fast lane
(:meth:`PhysicsHook.torques_into`, which the expert always answers once reset) or the call
(:meth:`PhysicsHook.__call__`). It

1. reads the measured state once (into the expert's own model, unless it shares the simulator's data);
2. lets the disturbance recovery and the friction adaptation look at it on their check steps;
3. plans the next cycle when the current one is over;
4. computes the joint torques by the controller's compiled step on the plan's grid
   (:meth:`ComputedTorqueController.grid_step_into`) where it applies, else, in place, by the readable controller
   call (:meth:`ComputedTorqueController.__call__`, the reference both are tested equal to);
5. multiplies them by the adaptive gains of ``ExpertConfig.adaptation`` (:mod:`agents.control.adaptation`) if any,
   and clips them to the limit it is given.

It never raises out of a rollout once reset: a failure of the controller at a physics step (logged with its
reason) keeps the last good torques for that step.
"""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np

from agents.control.adaptation import AdaptiveGains
from agents.control.controller import ComputedTorqueController
from agents.control.nominal import NominalModel
from agents.expert.config import ExpertConfig
from agents.expert.cycle import CyclePlanner
from agents.expert.friction import SLIP_CHECK_EVERY, FrictionAdaptation
from agents.expert.log import FailureLog
from agents.expert.recovery import DISTURBANCE_CHECK_EVERY, DisturbanceRecovery
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
    """The expert's physics-rate controller (:class:`quad_uneven_env.env.PhysicsController`), around its parts.

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
        """the computed-torque controller (:class:`~agents.control.controller.ComputedTorqueController`)."""
        self.nominal = nominal
        """the expert's own model (None with ``model="oracle"``)."""
        self.planner = planner
        """a plan per gait cycle, and its fallbacks (:class:`~agents.expert.cycle.CyclePlanner`)."""
        self.recovery = recovery
        """replans when pushed (:class:`~agents.expert.recovery.DisturbanceRecovery`)."""
        self.friction = friction
        """the friction its cones and footholds assume (:class:`~agents.expert.friction.FrictionAdaptation`)."""
        self.adaptation = adaptation
        """the adaptive gains on the torques (:class:`agents.control.adaptation.AdaptiveGains`; None: "none");
        another one may be set before the env's reset."""
        self.log = log
        self.compiled = True
        """take the controller's compiled step where it applies (False: the readable controller call at every
        physics step, the reference the compiled step is tested equal to; slower)."""
        self.shares_simulator_data = False
        """this episode's dynamics terms are read from the simulator's data ("oracle", or "nominal" in an exactly
        nominal world with ``share_nominal_world``); False: from the nominal model's copy."""
        self.tau_ok = np.zeros(C.N_JOINTS)
        """(12,) N m: the controller's torques of the last successful physics step (before the adaptive gains)."""
        self._foot_sensor_adr = planner.foot_sensor_adr
        self._raw = np.empty(C.N_JOINTS)  # the controller's torques of this step, before the adaptive gains
        self._call_tau = np.empty(C.N_JOINTS)  # the call's torques
        self._no_limit = np.full(C.N_JOINTS, np.inf)  # N m: the limit where the torques are clipped later
        self._data: mujoco.MjData | None = None  # the data the expert plans and controls with
        self._model: mujoco.MjModel | None = None
        self._sim: mujoco.MjData | None = None  # the simulator's: measured state and contact flags only
        self._terrain: Any = None
        self._steps = 0
        self._last_controller_error = ""

    # -------------------------------------------------------------- the env's physics-rate controller
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

    def __call__(self, model: mujoco.MjModel, data: mujoco.MjData, action: Any) -> np.ndarray:
        """Joint torques (N m) of this physics step (:meth:`_step_into`), not clipped by the env's limit (the
        controller's motor limits hold; the adaptive gains come after them). The action is ignored.

        :raises RuntimeError: if the env's reset has not reached this hook (:data:`NOT_ATTACHED`).
        """
        if self._sim is None:
            raise RuntimeError(NOT_ATTACHED)
        self._step_into(model, data, self._call_tau, self._no_limit)
        return self._call_tau.copy()

    def torques_into(
        self, model: mujoco.MjModel, data: mujoco.MjData, action: Any, out: np.ndarray, limit: np.ndarray
    ) -> bool:
        """The env's fast lane (:class:`~quad_uneven_env.env.PhysicsController`): this physics step's torques
        (:meth:`_step_into`), clipped to ``±limit`` (N m), into ``out``; True once the env's reset reached this hook
        (False before: the call then raises :data:`NOT_ATTACHED`). The action is ignored."""
        if self._sim is None:
            return False
        self._step_into(model, data, out, limit)
        return True

    # -------------------------------------------------------------- one physics step
    def _step_into(self, model: mujoco.MjModel, data: mujoco.MjData, out: np.ndarray, limit: np.ndarray) -> None:
        """One physics step: the controller's torques (:meth:`_control_into`) times the adaptive gains, clipped to
        ``±limit`` (N m), into ``out``. Torques the gains made non-finite are written as they are (the env then
        ends the episode)."""
        adaptation = self.adaptation
        if adaptation is None:
            self._control_into(model, data, out, limit)
            return
        raw = self._raw
        self._control_into(model, data, raw, self._no_limit)
        tau = adaptation.apply(raw, float(data.time), data.qpos[7:], self.planned_now)
        if not clip_finite_into(tau, limit, out):
            out[:] = tau

    def _control_into(self, model: mujoco.MjModel, data: mujoco.MjData, out: np.ndarray, limit: np.ndarray) -> None:
        """The computed-torque controller's torques at the measured state (N m), clipped to ``±limit``, into
        ``out``, and into :attr:`tau_ok` unclipped: the compiled step once, the readable call where it declines, the
        last good torques where both fail (logged)."""
        try:
            ctrl, planner, shared = self.controller, self.planner, self.shares_simulator_data
            own = data if shared else self.nominal.measure(data.qpos, data.qvel, data.time)  # type: ignore[union-attr]
            self._steps += 1
            if self.recovery.enabled and self._steps % DISTURBANCE_CHECK_EVERY == 0:
                self.recovery.check(own, ctrl.t0)
            touch = self._sim.sensordata  # type: ignore[union-attr]
            if self.friction.adapting and self._steps % SLIP_CHECK_EVERY == 0:
                feet = touch[self._foot_sensor_adr]
                self.friction.check_slip(self._model, own, planner.planned_stance, feet, self._terrain)
            m, contacts = (model, None) if shared else (self._model, ctrl.foot_contact_bits(data))
            if self.compiled:
                t = float(own.time) - ctrl.t0
                if t >= planner.t_end:
                    planner.advance(t)
                grid = planner.grid
                if grid is not None and ctrl.grid_step_into(
                    m, own, grid, planner.t_start, planner.t_end, touch, self._foot_sensor_adr, self.tau_ok, limit,
                    out, -1 if contacts is None else contacts,
                ):  # fmt: skip
                    return
            tau = ctrl(m, own, None, contacts)
            if tau.shape == self.tau_ok.shape and clip_finite_into(tau, limit, out):
                self.tau_ok[:] = tau
                return
            err = "non-finite torques"
        except Exception as exc:  # degrade, never crash a rollout
            err = f"{type(exc).__name__}: {exc}"
        if err != self._last_controller_error:  # one entry per run of equal failures
            self.log.add(f"t={float(data.time):.3f} s: controller failed ({err}); keeping the last good torques")
        self._last_controller_error = err
        clip_finite_into(self.tau_ok, limit, out)

    # -------------------------------------------------------------- the plan
    def planned_now(self, sim_time: float) -> tuple[ReferenceSample, float]:
        """The current plan at simulator time ``sim_time`` (s), without planning anything new.

        :return: the planned whole-robot motion (held at the plan's end once past it) and the phase of the
            current cycle in [0, 1].
        :raises RuntimeError: before the env's first reset reached the expert (no plan yet).
        """
        if self.planner.current_ref is None:
            raise RuntimeError(f"ExpertPolicy has no plan yet: {NOT_ATTACHED}")
        return self.planner.planned_now(sim_time - self.controller.t0)


__all__ = ["NOT_ATTACHED", "PhysicsHook"]
