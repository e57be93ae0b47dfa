"""The scripted expert as an SB3-style policy, and the one way to put it in an env: :func:`attach_expert`."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import mujoco
import numpy as np

from agents.control.adaptation import AdaptiveGains, make_adaptation
from agents.control.controller import ComputedTorqueController
from agents.control.nominal import NominalModel
from agents.expert.config import ExpertConfig
from agents.expert.cycle import CyclePlanner
from agents.expert.friction import FrictionAdaptation
from agents.expert.hook import NOT_ATTACHED, PhysicsHook
from agents.expert.log import FailureLog
from agents.expert.recovery import DisturbanceRecovery
from planners.types import ReferenceSample


class ExpertPolicy:
    """Planner + inverse-dynamics controller as an SB3-style policy for ``QuadUneven-v0``.

    The expert acts through the env's physics-rate hook, not through its actions: it must be the env's controller
    (:func:`attach_expert` builds it and installs it; a controller that wraps it, like the residual RL agent's,
    holds it as ``.expert`` and forwards the env's reset to it), installed before ``env.reset``. Otherwise
    :meth:`predict` raises a ``RuntimeError`` instead of returning actions that would leave the robot without
    torques.

    Its parts, one job each: :class:`~agents.expert.cycle.CyclePlanner` (:attr:`planner`: a plan per gait cycle,
    and its fallbacks), :class:`~agents.expert.friction.FrictionAdaptation` (:attr:`friction`: the friction its
    cones and footholds assume), :class:`~agents.expert.recovery.DisturbanceRecovery` (:attr:`recovery`: replans
    when pushed) and :class:`~agents.expert.hook.PhysicsHook` (:attr:`hook`: the physics-rate control), around
    one :class:`~agents.control.controller.ComputedTorqueController` (:attr:`controller`), with the adaptive gains
    of ``ExpertConfig.adaptation`` on its torques (:attr:`adaptation`).

    :param env: the environment (wrapped or not), on any robot.
    :param config: gait and control settings (None: :meth:`ExpertConfig.for_robot` of the env's robot, the
        defaults on the paper's robot).
    """

    def __init__(self, env: gym.Env, config: ExpertConfig | None = None) -> None:
        self.env = env.unwrapped
        self.config = config or ExpertConfig.for_robot(self.env.robot)
        u, cfgx = self.env, self.config
        self.nominal: NominalModel | None = None
        """the expert's own model (None with ``model="oracle"``)."""
        if cfgx.model == "nominal":
            self.nominal = NominalModel(u.robot, u.terrain, u.physics_dt)
        self.log = FailureLog()
        self.friction = FrictionAdaptation(
            cfgx, self.nominal is not None, u.robot.foot_radius, u.physics_dt, u.idx, self.log
        )
        self.planner = CyclePlanner(u, cfgx, self.friction, self.log)
        self.recovery = DisturbanceRecovery(cfgx, self.planner, self.log)
        self.controller = ComputedTorqueController(
            reference=self.planner.reference,
            backend=cfgx.backend,
            distribution=cfgx.distribution,
            gains=cfgx.gains,
            mu=cfgx.friction if self.nominal is not None else None,
        )
        adaptation = make_adaptation(cfgx.adaptation, u.dt, u.idx.torque_limit)
        self.hook = PhysicsHook(
            cfgx, self.controller, self.nominal, self.planner, self.recovery, self.friction, adaptation, self.log
        )
        self._zero = np.zeros(env.action_space.shape, dtype=env.action_space.dtype)

    # -------------------------------------------------------------- SB3 protocol
    def predict(
        self,
        observation: np.ndarray,
        state: Any = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = True,
    ) -> tuple[np.ndarray, Any]:
        """The zero action: the expert acts through the physics-rate hook (the residual RL agent adds its action
        on top of it).

        :raises RuntimeError: if the expert is not its env's physics-rate controller (directly or held as
            ``.expert`` by it), or the env has not been reset since it was installed (see :func:`attach_expert`).
        """
        self.check_attached()
        return self._zero.copy(), state

    def check_attached(self) -> None:
        """Raise a ``RuntimeError`` naming :func:`attach_expert` unless the env's physics-rate controller is this
        expert (or holds it as ``.expert``) and the env's last reset reached it."""
        u = self.env
        controller = u.controller
        if controller is not self and getattr(controller, "expert", None) is not self:
            raise RuntimeError(f"ExpertPolicy is not its env's physics-rate controller: {NOT_ATTACHED}")
        if not self.hook.reset_with(u.data):
            raise RuntimeError(f"ExpertPolicy was installed after the env's last reset: {NOT_ATTACHED}")

    # -------------------------------------------------------------- env hook
    def reset(self, model: mujoco.MjModel, data: mujoco.MjData, terrain: Any) -> None:
        """Called by the env at every reset: plan the first cycle from the measured stand."""
        self.hook.reset(model, data, terrain)

    def __call__(self, model: mujoco.MjModel, data: mujoco.MjData, action: np.ndarray) -> np.ndarray:
        """Joint torques (N m) at the measured state (:meth:`PhysicsHook.__call__`)."""
        return self.hook(model, data, action)

    def torques_into(
        self, model: mujoco.MjModel, data: mujoco.MjData, action: Any, out: np.ndarray, limit: np.ndarray
    ) -> bool:
        """The hook's fast lane (:meth:`PhysicsHook.torques_into`)."""
        return self.hook.torques_into(model, data, action, out, limit)

    @property
    def adaptation(self) -> AdaptiveGains | None:
        """the adaptive gains on the torques (:class:`agents.control.adaptation.AdaptiveGains`; None: "none");
        another one may be set before the env's reset."""
        return self.hook.adaptation

    @adaptation.setter
    def adaptation(self, adaptation: AdaptiveGains | None) -> None:
        self.hook.adaptation = adaptation

    # -------------------------------------------------------------- diagnostics
    @property
    def failure_log(self) -> list[str]:
        """why plans failed and what the expert did instead (this episode's)."""
        return self.log.entries

    @property
    def planner_times_ms(self) -> list[float]:
        """wall time of every gait-cycle plan of this episode (ms)."""
        return self.planner.planner_times_ms

    @property
    def plans(self) -> list[Any]:
        """(t_start, plan or hold reference) of every cycle of this episode."""
        return self.planner.plans

    @property
    def recoveries(self) -> int:
        """replans from the measured state this episode (the base pushed off its plan)."""
        return self.recovery.count

    @property
    def shares_simulator_data(self) -> bool:
        """this episode's dynamics terms are read from the simulator's data ("oracle", or "nominal" in an exactly
        nominal world with ``share_nominal_world``); False: from the nominal model's copy."""
        return self.hook.shares_simulator_data

    @property
    def assumed_friction(self) -> float:
        """-: the friction coefficient the controller's cones assume now (``ExpertConfig.friction``, lowered
        by slips with ``friction_adapt``, or the steep-ground friction in a cycle that needs it; the
        simulator's with ``model="oracle"``)."""
        return float(self.controller.mu)

    @property
    def last_torques(self) -> np.ndarray:
        """(12,) N m: the torques of the last successful physics step (a read-only view)."""
        view = self.hook.tau_ok.view()
        view.setflags(write=False)
        return view

    def planned_now(self, sim_time: float) -> tuple[ReferenceSample, float]:
        """The current plan at simulator time ``sim_time`` (s), without planning anything new.

        :return: the planned whole-robot motion (held at the plan's end once past it) and the phase of the
            current cycle in [0, 1].
        :raises RuntimeError: before the env's first reset reached the expert (no plan yet).
        """
        if self.planner.current_ref is None:
            raise RuntimeError(f"ExpertPolicy has no plan yet: {NOT_ATTACHED}")
        return self.hook.planned_now(sim_time)


def attach_expert(env: gym.Env, config: ExpertConfig | None = None) -> ExpertPolicy:
    """Build an :class:`ExpertPolicy` for ``env`` and install it as the env's physics-rate controller.

    Call it before ``env.reset`` (the reset plans the first cycle). This is the one way the expert
    drives an env on its own; ``ExpertPolicy(env, config)`` alone builds it without installing it (for a
    controller that wraps it), and it then refuses to act until it is installed.
    """
    expert = ExpertPolicy(env, config)
    expert.env.set_controller(expert)
    return expert


__all__ = ["ExpertPolicy", "attach_expert"]
