"""The expert's settings: :class:`ExpertConfig` (gait, control, and the nominal assumptions it plans and controls
with)."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from agents.control.adaptation import ADAPTATIONS
from agents.control.controller import Gains
from agents.control.inverse_dynamics import DISTRIBUTIONS
from planners.gait import validate_durations
from planners.scenario import BODY_PITCH_MODES
from quad_uneven_env.fields import check_fields, excerpt, from_mapping, param
from quad_uneven_env.robot.description import RobotDescription
from quad_uneven_env.robot.dynamics import BACKENDS

EXPERT_MODELS: tuple[str, ...] = ("nominal", "oracle")
"""Allowed values of ``ExpertConfig.model``."""


@dataclasses.dataclass(frozen=True)
class ExpertConfig:
    """Gait and control settings of the expert (SI units), and the nominal assumptions it plans and controls with.

    The defaults are the paper robot's; :meth:`for_robot` scales them to another robot (docs/robots.md).

    Nominal assumptions (``model="nominal"``): the robot's masses, inertias and centres of mass are those of
    the robot description the env was built from (``env.unwrapped.robot``; the paper's robot: 50 kg
    in all, link COMs as in Table 1), never the simulator's; a payload, scaled links or a
    shifted COM are disturbances to it. Its friction cones assume ``friction`` (0.25, a quarter of the
    nominal floor's 1.0: the slow crawl needs little tangential force, and its force QP, which otherwise
    spends whatever cone it is given on internal forces, then asks no floor of 0.25 or more for more than it
    holds; docs/robustness.md#friction). Motor strength, joint
    damping and friction, latency and pushes are not modelled: the feedback and the replanning
    (``recovery``) absorb them.
    """

    durations: tuple[float, ...] = (0.5, 0.5, 0.5, 0.1, 0.5, 0.5, 0.5)
    """s: the 7 phases of the walk cycle (paper order; the paper uses 1, 1, 1, 0.1, 1, 1, 1)."""
    stride: float = param(0.33, "m", lo=0.0, hi=1.0, lo_open=True)
    """m, in (0, 1]: body advance per cycle along +x (0.33 m / 3.1 s = 0.106 m/s nominal); unused in an env with a
    ``command``, whose (vx, vy) times the cycle's duration is the advance instead."""
    cog_height: float = param(0.33, "m", lo=0.05, hi=1.0)
    """m, in [0.05, 1]: COG height above the mean foothold height."""
    epsilon: float = param(20.0, "N m", lo=0.0, hi=1000.0)
    """N m, in [0, 1000]: stability margin of the planned COG path (20 N m = 4 cm of static margin for
    50 kg): much more than the paper's 0.1 N m, because the measured index must stay positive under
    tracking errors and the QP needs room to keep every stance force inside its cone."""
    clearance: float = param(0.05, "m", lo=0.0, hi=0.3)
    """m, in [0, 0.3]: swing clearance of the foot sphere above the terrain."""
    touchdown_depth: float = param(0.015, "m", lo=0.0, hi=0.1)
    """m, in [0, 0.1]: how far below its foothold a late foot (planned stance, no contact yet) is aimed."""
    body_pitch: str = param("terrain", kind="choice", choices=BODY_PITCH_MODES)
    """base orientation of the plans: "terrain" (pitch with the slope of the footholds, so the legs on
    the higher steps of a stair are not folded until their shanks rest on the nosing) or "level"
    (identity, the paper); see :mod:`planners.pitch`."""
    distribution: str = param("qp", kind="choice", choices=DISTRIBUTIONS)
    """inverse-dynamics torque distribution: "pinv" (paper) or "qp" (friction cones)."""
    backend: str = param("mujoco", kind="choice", choices=BACKENDS)
    """dynamics backend of the controller."""
    gains: Gains = dataclasses.field(default_factory=Gains)
    """computed-torque gains."""
    model: str = param("nominal", kind="choice", choices=EXPERT_MODELS)
    """what the expert plans and controls with: "nominal" (its own model of the nominal robot: the robot
    configuration's masses, inertias and centres of mass, fed with the measured state only, see the
    module docstring) or "oracle" (the simulator's live model and state, and its friction in the cones)."""
    friction: float = param(0.25, "-", lo=0.0, hi=2.0, lo_open=True)
    """-, in (0, 2]: friction coefficient the nominal model assumes in its "qp" friction cones at the start
    of an episode (the 4-sided pyramid inside the cone, mu / sqrt(2) per axis), and the slope limit of
    its footholds (``foothold_limits_for_friction``: 10 deg at 0.25). The QP keeps the torques closest to the
    pinv ones, whose internal forces lean on the feet: it uses the cone up to its edge (stance forces at
    tangential / normal 0.5 with cones of 0.5 on any floor), so this is the friction the walk demands of the
    floor, not a margin below it. Where no forces inside it give the planned base acceleration (a payload's or a
    push's correction) the QP takes cones of 0.5 instead (:data:`agents.control.qp_kernels.WIDE_MU`). The nominal
    floor's is 1.0; 0.25 walks floors down to 0.2 (flat) and 0.3 (rough 5 cm, 8 cm stairs). With
    ``friction_adapt`` it is lowered when a stance foot slips. Unused by "oracle", which takes the simulator's."""
    steep_friction: float = param(0.8, "-", lo=0.0, hi=2.0)
    """-, in [0, 2]: the friction the nominal model may assume for one gait cycle whose footholds ``friction``
    refuses as too steep (a ramp steeper than atan(friction / sqrt(2)), 10 deg at 0.25): such a stride is
    planned again with the slope limit of this friction, and if that plan is feasible its cycle runs with
    cones of this friction. The nominal floor's is 1.0, so 0.8 spends part of the margin only where the
    ground leaves no choice (ramps to 28.6 deg, the foothold search's cap); 0 never does (the expert then
    stands before such ramps). Scaled down with ``friction`` when slips lower it (``friction_adapt``). Unused
    by "oracle"."""
    friction_adapt: bool = False
    """lower the assumed friction when a stance foot slips: a planned-stance foot in contact whose contact
    point moves faster than ``slip_speed`` horizontally for 8 ms (:mod:`agents.control.slip`: measured
    state, the expert's own kinematics, checked every
    :data:`~agents.expert.friction.SLIP_CHECK_EVERY` physics steps) multiplies it by ``friction_decrease``, at
    most once per :data:`~agents.expert.friction.SLIP_COOLDOWN` s and never below ``friction_min``; the
    cones and the foothold slope limit follow at once, and every change is logged. It is never raised
    again within the episode. Off by default: a foot shoved by a push or moved by a late torque reads as a slip
    too (docs/robustness.md#friction-adaptation has the figures of both)."""
    slip_speed: float = param(0.05, "m/s", lo=0.0, lo_open=True)
    """m/s, > 0: a stance foot's contact point moving faster than this (for ``SLIP_DURATION``) slips (how fast a
    holding foot moves: docs/robustness.md#friction-adaptation)."""
    friction_decrease: float = param(0.8, "-", lo=0.0, hi=1.0, lo_open=True, hi_open=True)
    """-, in (0, 1): the factor of one decrease of the assumed friction."""
    friction_min: float = param(0.25, "-", lo=0.0, hi=2.0, lo_open=True)
    """-, in (0, 2]: the assumed friction is never lowered below this."""
    recovery: bool = True
    """replan within the cycle, from the measured state, when the base is pushed off its plan (see
    ``recovery_velocity``, ``recovery_position``): the new cycle starts with four-leg support, so a foot
    in the air is put down below where it is, and its COG path starts with the measured velocity."""
    recovery_velocity: float = param(0.12, "m/s", lo=0.0, lo_open=True)
    """m/s, > 0: horizontal base velocity error (measured minus planned) that triggers a replan."""
    recovery_position: float = param(0.04, "m", lo=0.0, lo_open=True)
    """m, > 0: horizontal base position error that triggers a replan."""
    share_nominal_world: bool = True
    """with "nominal": when the simulated robot's parameters equal the nominal ones exactly (checked at
    every reset), read the dynamics terms from the simulator's data instead of copying the measured
    state into the nominal model: the same numbers bit for bit (tested), without the copy and its stages."""
    adaptation: str = param("none", kind="choice", choices=ADAPTATIONS)
    """adaptive gains on the controller's joint torques (:mod:`agents.control.adaptation`), updated once per control
    step of the env from the plan's tracking error and the torques: "none", "knee" (the four knees' gains follow
    the correlation of their tracking error with their load) or "learned" (all twelve, driven by the learned
    strength estimator). They undo weak or strong motors and a heavier body than the model's."""

    foothold_scale: float = param(1.0, "-", lo=0.1, hi=5.0)
    """-, in [0.1, 5]: the foothold search's squares (``FootholdLimits.window``, ``reach_window``, ``ring``) in
    units of the paper robot's (1): a longer leg searches a wider workspace."""

    @classmethod
    def for_robot(cls, robot: RobotDescription, overrides: Mapping[str, Any] | None = None) -> ExpertConfig:
        """The expert's settings on ``robot``: the defaults scaled from the paper robot's
        (docs/robots.md#scaling-rules), then the robot YAML's ``gait``, then ``overrides`` (fields of this class;
        a ``gains`` mapping is merged into the scaled gains). The paper's robot (its size ratios 1) gets the
        defaults: ``ExpertConfig(**overrides)``.

        :raises ValueError: naming the field, as :func:`~quad_uneven_env.fields.from_mapping`.
        """
        given = dict(overrides or {})
        scaled = scaled_settings(robot)
        gains = scaled.pop("gains")
        if "gains" in given and isinstance(given["gains"], Mapping):
            gains = from_mapping(Gains, {**dataclasses.asdict(gains), **given.pop("gains")}, "expert_config.gains")
        return from_mapping(cls, {**scaled, "gains": gains, **given}, "expert_config")

    def __post_init__(self) -> None:
        check_fields(self)
        validate_durations(self.durations)
        if not isinstance(self.gains, Gains):
            raise ValueError(f"ExpertConfig.gains must be a Gains, got {excerpt(self.gains)}")
        for name in ("recovery", "friction_adapt"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"ExpertConfig.{name} must be True or False, got {excerpt(getattr(self, name))}")
        if not isinstance(self.share_nominal_world, bool):
            raise ValueError(
                f"ExpertConfig.share_nominal_world must be True or False, got {excerpt(self.share_nominal_world)}"
            )


SCALED_ROBOT_FRICTION = 0.5
"""-: the friction of the force QP's cones on a robot whose motors have little margin over its weight
(:func:`motor_load` at least :data:`NARROW_CONES_MAX_LOAD`; ``ExpertConfig.friction``, the narrow cones, otherwise).
Cones of 0.25 make the QP trade friction for joint torque: on rough ground at their scale the stance peaks rise
from 0.72 to 0.82 of the motor limit (ANYmal C's hip flexion) and 0.75 to 0.77 (HyQ's), whose weakest motors in
the ``hard`` world (0.7 of their torque) have no such margin; those robots keep the wider cones
(docs/robustness.md#every-robot)."""

NARROW_CONES_MAX_LOAD = 3.5
"""-: the largest :func:`motor_load` at which the expert plans with the narrow cones of ``ExpertConfig.friction``
(the paper robot: 1.72, Go1 2.31, Solo12 2.95 plan with them; HyQ 3.95 and ANYmal C 4.17 do not). In the ``hard``
world at their scale Go1 and Solo12 walk its friction-0.37 and 0.40 worlds with them, which they fall in with cones of
0.5 (docs/robustness.md#every-robot)."""


def motor_load(robot: RobotDescription) -> float:
    """-: the robot's weight times its leg length over its weakest hip-flexion or knee motor's torque limit, how hard
    its motors work to hold it up (``m g L / tau_max``)."""
    limits = np.asarray(robot.torque_limits, dtype=float).reshape(4, 3)[:, 1:]
    return float(robot.total_mass * 9.81 * robot.leg_length / limits.min())


def scaled_settings(robot: RobotDescription) -> dict[str, Any]:
    """The fields of :class:`ExpertConfig` that depend on the robot (docs/robots.md#scaling-rules); the paper
    robot's are the defaults.

    With the leg-length ratio ``s = leg_length / 0.42 m`` and the mass ratio ``m = mass / 50 kg`` (the paper
    robot's): lengths (stride, swing clearance, touch-down depth, recovery distance, foothold search) scale
    with ``s``; times (the phases, each rounded to 10 ms) with ``sqrt(s)`` and speeds (recovery, slip) with
    ``sqrt(s)`` (equal Froude number); the stability margin with ``m s`` (the same static margin in leg
    lengths); the computed-torque gains (per unit mass) with ``1 / s`` (stiffness) and ``1 / sqrt(s)``
    (damping), the same damping ratio at a natural frequency scaled like the gait's. The COG height is the
    robot's standing COG height times the paper robot's ratio of its walking to its standing COG height. The
    force QP's cones are the narrow default where :func:`motor_load` is below :data:`NARROW_CONES_MAX_LOAD`, else
    :data:`SCALED_ROBOT_FRICTION`. The robot YAML's ``gait`` overrides them.
    """
    from planners.robot_geometry import robot_geometry
    from planners.wholebody import WholeBody

    base = ExpertConfig()
    s = robot_geometry(robot).scale
    m = robot.mass_ratio
    t = math.sqrt(s)
    g = robot.gait
    ratio = t if g.cycle_time is None else g.cycle_time / sum(base.durations)
    # whole multiples of 10 ms: every cycle then starts on the controller's time grid (2 ms physics steps), where the
    # reference is a lookup of its precomputed rows
    durations = tuple(max(round(d * ratio, 2), 0.01) for d in base.durations)
    k = 1.0 if g.gain_scale is None else g.gain_scale
    gains = Gains(
        kp_pos=base.gains.kp_pos * k / s, kd_pos=base.gains.kd_pos * math.sqrt(k / s),
        kp_rot=base.gains.kp_rot * k / s, kd_rot=base.gains.kd_rot * math.sqrt(k / s),
        kp_joint=base.gains.kp_joint * k / s, kd_joint=base.gains.kd_joint * math.sqrt(k / s),
    )  # fmt: skip
    if g.body_height is not None:
        cog_height = g.body_height
    else:
        paper = robot_geometry(None)
        cog_height = base.cog_height * standing_cog_height(robot) / _standing_cog_height(WholeBody(paper), 0.36)
    return {
        "durations": durations,
        "stride": base.stride * s if g.stride is None else g.stride,
        "cog_height": round(cog_height, 4),
        "epsilon": base.epsilon * m * s,
        "clearance": base.clearance * s if g.swing_height is None else g.swing_height,
        "touchdown_depth": base.touchdown_depth * s,
        "recovery_velocity": base.recovery_velocity * t,
        "recovery_position": base.recovery_position * s,
        "slip_speed": base.slip_speed * t,
        "foothold_scale": s,
        "friction": base.friction if motor_load(robot) < NARROW_CONES_MAX_LOAD else SCALED_ROBOT_FRICTION,
        "gains": gains,
    }


def standing_cog_height(robot: RobotDescription) -> float:
    """m, the whole-robot COG above flat ground in the robot's standing pose."""
    from planners.robot_geometry import robot_geometry
    from planners.wholebody import WholeBody

    wb = WholeBody(robot_geometry(robot))
    return float(robot.standing_height + wb.com_offset(robot.standing_joints.reshape(4, 3))[2])


def _standing_cog_height(wb: Any, standing_height: float) -> float:
    """m, the COG above flat ground of ``wb``'s robot standing at ``standing_height`` (its feet under its
    standing points)."""
    q = wb.geometry.standing_legs(standing_height - wb.geometry.foot_radius)
    return float(standing_height + wb.com_offset(q)[2])
