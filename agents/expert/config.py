"""The expert's settings: :class:`ExpertConfig` (gait, control, and the nominal assumptions it plans and controls
with)."""

from __future__ import annotations

import dataclasses

from agents.control.adaptation import ADAPTATIONS
from agents.control.controller import Gains
from agents.control.inverse_dynamics import DISTRIBUTIONS
from planners.gait import validate_durations
from planners.scenario import BODY_PITCH_MODES
from quad_uneven_env.fields import check_fields, param
from quad_uneven_env.robot.dynamics import BACKENDS

EXPERT_MODELS: tuple[str, ...] = ("nominal", "oracle")
"""Allowed values of ``ExpertConfig.model``."""


@dataclasses.dataclass(frozen=True)
class ExpertConfig:
    """Gait and control settings of the expert (SI units), and the nominal assumptions it plans and controls with.

    Nominal assumptions (``model="nominal"``): the robot's masses, inertias and centres of mass are those of
    the robot configuration the env was built from (``env.unwrapped.robot_cfg``; the paper's robot: 50 kg
    in all, link COMs as in Table 1), never the simulator's; a payload, scaled links or a
    shifted COM are disturbances to it. Its friction cones assume ``friction`` (0.5, half the nominal
    floor's 1.0; the inscribed pyramid's ``friction / sqrt(2)`` = 0.35 per tangent axis is the margin that
    covers floors down to about 0.35-0.5 depending on the force's direction). Motor strength, joint
    damping and friction, latency and pushes are not modelled: the feedback and the replanning
    (``recovery``) absorb them.
    """

    durations: tuple[float, ...] = (0.5, 0.5, 0.5, 0.1, 0.5, 0.5, 0.5)
    """s: the 7 phases of the walk cycle (paper order; the paper uses 1, 1, 1, 0.1, 1, 1, 1)."""
    stride: float = param(0.33, "m", lo=0.0, hi=1.0, lo_open=True)
    """m, in (0, 1]: body advance per cycle along +x (0.33 m / 3.1 s = 0.106 m/s nominal); unused in an env with a
    ``command``, whose (vx, vy) times the cycle's duration is the advance instead."""
    cog_height: float = param(0.33, "m", lo=0.1, hi=0.5)
    """m, in [0.1, 0.5]: COG height above the mean foothold height."""
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
    friction: float = param(0.5, "-", lo=0.0, hi=2.0, lo_open=True)
    """-, in (0, 2]: friction coefficient the nominal model assumes in its "qp" friction cones at the start
    of an episode (the 4-sided pyramid inside the cone, mu / sqrt(2) per axis), and the slope limit of
    its footholds (``foothold_limits_for_friction``). The nominal floor's is 1.0; 0.5 keeps the planned
    forces inside the cones of floors down to about 0.4. With ``friction_adapt`` it is lowered when a
    stance foot slips. Unused by "oracle", which takes the simulator's."""
    steep_friction: float = param(0.8, "-", lo=0.0, hi=2.0)
    """-, in [0, 2]: the friction the nominal model may assume for one gait cycle whose footholds ``friction``
    refuses as too steep (a ramp steeper than atan(friction / sqrt(2)), 19.5 deg at 0.5): such a stride is
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
    again within the episode. Off by default: it walks floors of 0.3-0.45, but under hard randomization
    pushed feet read as slips and it loses ``robust_hard`` episodes (docs/robustness.md#friction-adaptation)."""
    slip_speed: float = param(0.05, "m/s", lo=0.0, lo_open=True)
    """m/s, > 0: a stance foot's contact point moving faster than this (for ``SLIP_DURATION``) slips; one
    that holds moves < 0.025 m/s on rough terrain."""
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
    state into the nominal model: the same numbers bit for bit (tested), about 10 µs a step cheaper."""
    adaptation: str = param("none", kind="choice", choices=ADAPTATIONS)
    """adaptive gains on the controller's joint torques (:mod:`agents.control.adaptation`), updated once per control
    step of the env from the plan's tracking error and the torques: "none", "knee" (the four knees' gains follow
    the correlation of their tracking error with their load) or "learned" (all twelve, driven by the learned
    strength estimator). They undo weak or strong motors and a heavier body than the model's."""

    def __post_init__(self) -> None:
        check_fields(self)
        validate_durations(self.durations)
        if not isinstance(self.gains, Gains):
            raise ValueError(f"ExpertConfig.gains must be a Gains, got {self.gains!r}")
        for name in ("recovery", "friction_adapt"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"ExpertConfig.{name} must be True or False, got {getattr(self, name)!r}")
        if not isinstance(self.share_nominal_world, bool):
            raise ValueError(
                f"ExpertConfig.share_nominal_world must be True or False, got {self.share_nominal_world!r}"
            )
