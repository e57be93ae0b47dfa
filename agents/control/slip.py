"""Slip of the stance feet, read from the measured state with the robot's own kinematics.

A foot slips when the point of its sphere below its centre (the contact point on level ground, without
the rolling of the sphere with its shank: ``v_site + omega x (-r z)``) moves faster than a threshold
horizontally at every check for :data:`SLIP_DURATION` s, while the controller asks it for at least
:data:`SLIP_MIN_LOAD` of normal force: a foot that carries little moves without telling anything about
the floor, and the settling of a touch-down lasts a few milliseconds. A foot that holds moves below
0.025 m/s on rough terrain. Used by the expert's friction adaptation (``ExpertConfig.friction_adapt``).
"""

from __future__ import annotations

from collections.abc import Callable

import mujoco
import numpy as np

from quad_uneven_env import constants as C

SLIP_DURATION = 0.008
"""s: a stance foot slips when it is faster than the threshold for this long (at every check)."""
SLIP_MIN_LOAD = 50.0
"""N: a moving stance foot counts as slipping only if the controller commanded it at least this normal force
(world z; a tenth of the robot's weight)."""


class SlipDetector:
    """Per-foot slip timers, updated at every check.

    :param speed: m/s, > 0: the contact-point speed above which a loaded stance foot is moving.
    :param foot_radius: m, the foot sphere's radius.
    :param check_dt: s between two calls of :meth:`update`.
    """

    def __init__(self, speed: float, foot_radius: float, check_dt: float) -> None:
        self.speed = float(speed)
        self.foot_radius = float(foot_radius)
        self.check_dt = float(check_dt)
        self.slip_time = np.zeros(C.N_LEGS)
        """s: how long each stance foot has been slipping (0: not now)."""
        self.last_speed = np.zeros(C.N_LEGS)
        """m/s: each stance foot's contact-point speed at the last check (0 for the others)."""
        self._site_ids: list[int] = []
        self._v = np.zeros(6)

    def reset(self, model: mujoco.MjModel) -> None:
        """Start an episode on ``model`` (the one whose data :meth:`update` gets): timers to 0."""
        self._site_ids = [int(model.site(s).id) for s in C.FOOT_SITES]
        self.slip_time[:] = 0.0
        self.last_speed[:] = 0.0

    def update(
        self,
        model: mujoco.MjModel,
        data: mujoco.MjData,
        stance: int,
        touch: np.ndarray,
        loads: Callable[[], np.ndarray],
    ) -> int:
        """The leg (0-3) that has slipped for :data:`SLIP_DURATION` s at this check, or -1.

        :param data: the measured state, with velocities (``mj_comVel`` done).
        :param stance: bitmask of the planned stance feet (bit i: leg i); ``touch`` (4,) > 0 in contact.
        :param loads: the commanded normal forces (4,) (N), called only when some foot moves.
        """
        v, r = self._v, self.foot_radius
        slipping, fz = -1, None
        for leg in range(C.N_LEGS):
            if not (stance >> leg & 1 and touch[leg] > 0):
                self.slip_time[leg] = self.last_speed[leg] = 0.0
                continue
            mujoco.mj_objectVelocity(model, data, mujoco.mjtObj.mjOBJ_SITE, self._site_ids[leg], v, 0)
            speed = float(np.hypot(v[3] - r * v[1], v[4] + r * v[0]))  # v_xy + r (-omega_y, omega_x)
            self.last_speed[leg] = speed
            if speed > self.speed and fz is None:
                fz = loads()
            moving = speed > self.speed and fz[leg] >= SLIP_MIN_LOAD  # type: ignore[index]
            self.slip_time[leg] = self.slip_time[leg] + self.check_dt if moving else 0.0
            if self.slip_time[leg] >= SLIP_DURATION - 1e-9:
                slipping = leg
        return slipping


__all__ = ["SLIP_DURATION", "SLIP_MIN_LOAD", "SlipDetector"]
