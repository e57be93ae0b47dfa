"""Disturbance recovery: replan within the cycle, from the measured state, when the base is pushed off its plan.

Every :data:`DISTURBANCE_CHECK_EVERY` physics steps (``ExpertConfig.recovery``) the base's horizontal position and
velocity are compared with the plan's; beyond ``ExpertConfig.recovery_position`` or ``recovery_velocity`` the
cycle is planned again from the measured COG and velocity (four-leg support first, so a foot in the air is put
down below where it is), and no new check replans before the new cycle's first phase is over.
"""

from __future__ import annotations

import mujoco
import numpy as np

from agents.expert.config import ExpertConfig
from agents.expert.cycle import CyclePlanner
from agents.expert.log import FailureLog
from quad_uneven_env import physics

DISTURBANCE_CHECK_EVERY = 5
"""physics steps between two checks of the base against its plan (``ExpertConfig.recovery``)."""


class DisturbanceRecovery:
    """When to replan a pushed robot, and the replan.

    :param config: the expert's settings (``recovery``, ``recovery_position``, ``recovery_velocity``).
    :param planner: the cycle planner it replans with.
    :param log: where every replan is written.
    """

    def __init__(self, config: ExpertConfig, planner: CyclePlanner, log: FailureLog) -> None:
        self.config = config
        self.planner = planner
        self.log = log
        self.enabled = config.recovery
        self.calm_after = 0.0
        """s (controller time): no disturbance replan before."""
        self.count = 0
        """replans this episode."""

    def reset(self) -> None:
        """Start an episode."""
        self.calm_after = 0.0
        self.count = 0

    def check(self, d: mujoco.MjData, t0: float) -> None:
        """Replan now from the measured state in ``d`` if the base is off its plan.

        :param t0: s, the controller's time origin (``d.time - t0`` is the plans' time).
        """
        planner = self.planner
        t = float(d.time) - t0
        if t < self.calm_after or planner.row_of is None or t >= planner.t_end:
            return
        packed = planner.row_of(t - planner.t_start)
        if packed is None:
            return
        row, cfgx = packed[0], self.config
        q, v = d.qpos, d.qvel
        dv = (v[0] - row[7]) ** 2 + (v[1] - row[8]) ** 2
        dp = (q[0] - row[0]) ** 2 + (q[1] - row[1]) ** 2
        if dv <= cfgx.recovery_velocity**2 and dp <= cfgx.recovery_position**2:
            return
        self.count += 1
        self.log.add(
            f"t={t:.2f} s: base {np.sqrt(dp):.3f} m and {np.sqrt(dv):.2f} m/s off its plan: replanning from the "
            "measured state"
        )
        cog = physics.cog(d, planner.env.idx).copy()
        vel = np.array([v[0], v[1], 0.0])
        planner.start_cycle(t, cog_start={"pos": cog, "vel": vel, "acc": np.zeros(3)}, measured=True)
        self.calm_after = t + planner.durations[0]


__all__ = ["DISTURBANCE_CHECK_EVERY", "DisturbanceRecovery"]
