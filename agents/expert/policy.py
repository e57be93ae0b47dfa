"""The scripted expert as an SB3-style policy, and the one way to put it in an env: :func:`attach_expert`."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from agents.control.adaptation import make_adaptation
from agents.control.controller import ComputedTorqueController
from agents.control.nominal import NominalModel
from agents.expert.config import ExpertConfig
from agents.expert.cycle import CyclePlanner
from agents.expert.friction import FrictionAdaptation
from agents.expert.hook import NOT_ATTACHED, PhysicsHook
from agents.expert.log import FailureLog
from agents.expert.recovery import DisturbanceRecovery


class ExpertPolicy(PhysicsHook):
    """Planner + inverse-dynamics controller as an SB3-style policy for ``QuadUneven-v0``.

    The expert acts through the env's physics-rate hook, not through its actions: it is the env's physics-rate
    controller itself (its :class:`~agents.expert.hook.PhysicsHook` side: ``reset``, the call and the fast lane
    ``torques_into``), installed by :func:`attach_expert`, or held as ``.expert`` by a controller that wraps it (the
    residual RL agent's) and forwards the env's reset to it, before ``env.reset``. Otherwise :meth:`predict` raises
    a ``RuntimeError`` instead of returning actions that would leave the robot without torques.

    Its parts, one job each: :class:`~agents.expert.cycle.CyclePlanner` (:attr:`planner`: a plan per gait cycle,
    and its fallbacks), :class:`~agents.expert.friction.FrictionAdaptation` (:attr:`friction`: the friction its
    cones and footholds assume), :class:`~agents.expert.recovery.DisturbanceRecovery` (:attr:`recovery`: replans
    when pushed), around one :class:`~agents.control.controller.ComputedTorqueController` (:attr:`controller`), with
    the adaptive gains of ``ExpertConfig.adaptation`` on its torques (:attr:`adaptation`).

    :param env: the environment (wrapped or not), on any robot.
    :param config: gait and control settings (None: :meth:`ExpertConfig.for_robot` of the env's robot, the
        defaults on the paper's robot).
    """

    def __init__(self, env: gym.Env, config: ExpertConfig | None = None) -> None:
        self.env = env.unwrapped
        u, cfgx = self.env, config or ExpertConfig.for_robot(self.env.robot)
        nominal = NominalModel(u.robot, u.terrain, u.physics_dt) if cfgx.model == "nominal" else None
        log = FailureLog()
        friction = FrictionAdaptation(cfgx, nominal is not None, u.robot.foot_radius, u.physics_dt, u.idx, log)
        planner = CyclePlanner(u, cfgx, friction, log)
        controller = ComputedTorqueController(
            reference=planner.reference,
            backend=cfgx.backend,
            distribution=cfgx.distribution,
            gains=cfgx.gains,
            mu=cfgx.friction if nominal is not None else None,
        )
        super().__init__(
            cfgx,
            controller,
            nominal,
            planner,
            DisturbanceRecovery(cfgx, planner, log),
            friction,
            make_adaptation(cfgx.adaptation, u.dt, u.idx.torque_limit),
            log,
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
        if self._sim is not u.data:
            raise RuntimeError(f"ExpertPolicy was installed after the env's last reset: {NOT_ATTACHED}")

    @property
    def hook(self) -> ExpertPolicy:
        """The physics-rate controller: this expert (its :class:`~agents.expert.hook.PhysicsHook` side, e.g.
        ``hook.compiled``)."""
        return self

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
    def assumed_friction(self) -> float:
        """-: the friction coefficient the controller's cones assume now (``ExpertConfig.friction``, lowered
        by slips with ``friction_adapt``, or the steep-ground friction in a cycle that needs it; the
        simulator's with ``model="oracle"``)."""
        return float(self.controller.mu)

    @property
    def last_torques(self) -> np.ndarray:
        """(12,) N m: the controller's torques of the last successful physics step (a read-only view)."""
        view = self.tau_ok.view()
        view.setflags(write=False)
        return view


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
