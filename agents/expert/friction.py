"""The friction the expert assumes: its cones, its foothold slope limit, steep ground, and slips.

The controller's "qp" cones assume a friction coefficient (``ExpertConfig.friction``; the simulator's with
``model="oracle"``), and the footholds are refused where it cannot hold a foot
(:func:`foothold_limits_for_friction`). A stride refused only for steep footholds may be planned again with
``ExpertConfig.steep_friction`` for that one cycle. With ``ExpertConfig.friction_adapt`` a slipping stance foot
(:mod:`agents.control.slip`) lowers the assumption for the rest of the episode.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import mujoco
import numpy as np

from agents.control.controller import ComputedTorqueController
from agents.control.slip import SLIP_DURATION, SlipDetector
from agents.expert.config import ExpertConfig
from agents.expert.log import FailureLog
from planners import FootholdLimits
from quad_uneven_env import constants as C
from quad_uneven_env import physics

SLIP_CHECK_EVERY = 2
"""physics steps between two slip checks (``ExpertConfig.friction_adapt``): 4 ms."""
SLIP_MIN_TILT_COS = float(np.cos(np.radians(15.0)))
"""cos of the steepest stance foothold tilt at which a slip still lowers the assumed friction: on steeper
ground a slipping foot is not read as a slippery floor: on steep ramps feet that land or are dragged slide
briefly on any floor (docs/robustness.md#friction-adaptation)."""
SLIP_SPAWN_SETTLE = 0.1
"""s: no slip is read in the first this-long of an episode, while the robot settles on its spawn pose (its
joints carry the reset noise, and their feet slide while they settle, whatever the floor's friction)."""
SLIP_COOLDOWN = 0.1
"""s: at most one decrease of the assumed friction in this time (a slip is seen at several checks)."""


def foothold_limits_for_friction(mu: float, scale: float = 1.0) -> FootholdLimits:
    """Foothold limits whose slope limit keeps a foot inside the friction pyramid the controller assumes.

    The cones are 4-sided pyramids of ``mu / sqrt(2)`` per tangent axis: a foot on a plane steeper than
    ``atan(mu / sqrt(2))`` (19.5 deg for mu = 0.5) cannot hold its share of the weight inside them, and on
    a slope where every foot is that steep the torque QP has no solution (it is relaxed, the feet slip).
    Such a foothold is refused (the failure log says ``failed test: slope``) rather than walked on.

    :param mu: friction coefficient of the controller's cones (-).
    :param scale: the search squares (``window``, ``reach_window``, ``ring``) in units of the defaults
        (``ExpertConfig.foothold_scale``: the robot's leg length in the paper robot's).
    """
    default = FootholdLimits()
    if scale != 1.0:
        default = dataclasses.replace(
            default, window=default.window * scale, reach_window=default.reach_window * scale, ring=default.ring * scale
        )
    return dataclasses.replace(default, max_slope=min(default.max_slope, float(np.arctan(mu / np.sqrt(2.0)))))


def contact_friction(model: mujoco.MjModel) -> float:
    """Sliding friction of a foot-terrain contact in ``model`` (MuJoCo's default mix: the larger of the two geoms')."""
    foot = float(model.geom_friction[model.geom(C.FOOT_GEOMS[0]).id, 0])
    return max(foot, float(model.geom_friction[model.geom(C.TERRAIN_GEOM).id, 0]))


class FrictionAdaptation:
    """The friction coefficient the controller's cones assume, and the foothold limits that go with it.

    :param config: the expert's settings (``friction``, ``steep_friction``, ``friction_adapt`` and the slip ones).
    :param nominal: whether the expert plans with its own nominal model (with ``model="oracle"`` the assumption
        is the simulator's friction: nothing is adapted).
    :param foot_radius: m, the robot's foot sphere.
    :param physics_dt: s, the simulator's time step.
    :param idx: the env's model indices (``env.idx``: the foot sites).
    :param log: where every change is written.
    """

    def __init__(
        self, config: ExpertConfig, nominal: bool, foot_radius: float, physics_dt: float, idx: Any, log: FailureLog
    ) -> None:
        self.config = config
        self.nominal = nominal
        self.idx = idx
        self.log = log
        self.slip = SlipDetector(config.slip_speed, foot_radius, SLIP_CHECK_EVERY * physics_dt)
        self.adapting = False
        """this episode lowers the friction on slips (``friction_adapt`` with the nominal model)."""
        self.base_mu = config.friction
        """-: the assumed friction outside steep cycles (lowered by slips)."""
        self.foothold_limits = FootholdLimits()
        """the foothold limits of :attr:`base_mu` (:func:`foothold_limits_for_friction`)."""
        self.controller: ComputedTorqueController | None = None
        self._cooldown = 0.0  # s: no decrease before

    def reset(self, controller: ComputedTorqueController, model: mujoco.MjModel) -> None:
        """Start an episode: ``controller``'s cones assume ``ExpertConfig.friction``, or with the oracle the friction
        of ``model``'s foot-terrain contacts. Call before the controller's own reset (which builds its cones)."""
        self.controller = controller
        self._cooldown = 0.0
        self.adapting = self.config.friction_adapt and self.nominal
        controller.mu = self.config.friction if self.nominal else contact_friction(model)

    def start(self, model: mujoco.MjModel) -> None:
        """After the controller's reset: the slip timers on ``model`` (the model the expert controls with), and the
        base friction and foothold limits from the controller's cones."""
        self.slip.reset(model)
        self.base_mu = float(self.controller.mu)  # type: ignore[union-attr]
        self.foothold_limits = foothold_limits_for_friction(self.base_mu, self.config.foothold_scale)

    def steep_mu(self) -> float | None:
        """-: the friction a stride refused for steep footholds may be planned again with, or None."""
        cfg = self.config
        if not self.nominal or cfg.steep_friction <= 0.0:
            return None
        mu = cfg.steep_friction * self.base_mu / cfg.friction  # slips scale it down with the base
        return mu if mu > self.base_mu else None

    def use_for_cycle(self, mu: float) -> None:
        """The controller's cones assume ``mu`` (-) for the cycle just planned."""
        controller = self.controller
        if mu != controller.mu:  # type: ignore[union-attr]
            controller.set_friction(mu)  # type: ignore[union-attr]

    def check_slip(
        self,
        model: mujoco.MjModel,
        d: mujoco.MjData,
        planned: Any,
        touch: np.ndarray,
        terrain: Any,
    ) -> None:
        """Lower the assumed friction if a stance foot slips (the reading of a slip: :mod:`agents.control.slip`).

        A slip counts only while every planned stance foot stands on terrain tilted less than 15 deg
        (:data:`SLIP_MIN_TILT_COS`), and not while the robot settles on its spawn pose.

        :param d: the measured state in the expert's own data (of ``model``).
        :param planned: ``planned(t) -> int``: the planned stance bitmask at controller time t (s).
        :param touch: (4,) the feet's contact sensors (> 0: touching).
        :param terrain: the env's terrain (its height field's normals).
        """
        controller = self.controller
        t = float(d.time)
        if t - controller.t0 < SLIP_SPAWN_SETTLE:  # type: ignore[union-attr]
            return
        stance = planned(t - controller.t0)  # type: ignore[union-attr]
        slipping = self.slip.update(model, d, stance, touch, self._commanded_loads)
        if slipping < 0 or t < self._cooldown or self._stance_tilt_cos(stance, d, terrain) < SLIP_MIN_TILT_COS:
            return
        cfg, old = self.config, self.base_mu
        mu = max(cfg.friction_min, old * cfg.friction_decrease)
        if mu >= old:
            return
        self.base_mu = mu
        controller.set_friction(mu)  # type: ignore[union-attr]  # a steep cycle's cones too: the floor is more slippery
        self.foothold_limits = foothold_limits_for_friction(mu, self.config.foothold_scale)
        self._cooldown = t + SLIP_COOLDOWN
        self.slip.slip_time[:] = 0.0
        self.log.add(
            f"t={t - controller.t0:.2f} s: stance foot {C.LEG_NAMES[slipping]} slips "  # type: ignore[union-attr]
            f"({self.slip.last_speed[slipping]:.2f} m/s, > {cfg.slip_speed:g} m/s for {SLIP_DURATION * 1e3:.0f} "
            f"ms): assumed friction {old:.3f} -> {mu:.3f}"
        )

    def _commanded_loads(self) -> np.ndarray:
        """(4,) N: the normal forces (world z) the controller commanded at its last step (0 before any)."""
        last = self.controller.last  # type: ignore[union-attr]
        return np.zeros(C.N_LEGS) if last is None else last.contact_forces[:, 2]

    def _stance_tilt_cos(self, planned: int, d: mujoco.MjData, terrain: Any) -> float:
        """cos of the steepest terrain tilt under the planned stance feet in ``d`` (1: none)."""
        legs = [leg for leg in range(C.N_LEGS) if planned >> leg & 1]
        if not legs:
            return 1.0
        feet = physics.feet_pos(d, self.idx)
        return float(np.min(terrain.heightfield.normal(feet[legs, 0], feet[legs, 1])[:, 2]))


__all__ = [
    "SLIP_CHECK_EVERY",
    "SLIP_COOLDOWN",
    "SLIP_MIN_TILT_COS",
    "SLIP_SPAWN_SETTLE",
    "FrictionAdaptation",
    "contact_friction",
    "foothold_limits_for_friction",
]
