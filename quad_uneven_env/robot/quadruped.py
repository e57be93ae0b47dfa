"""A quadruped as data: trunk, four HAA-HFE-KFE legs, feet, limits and a standing pose, checked at construction.

:class:`RobotDescription` is what every robot-specific module reads (the MJCF builder, the kinematics of any
description in :mod:`quad_uneven_env.robot.leg_chain`, the planners' view of a robot, the env), and its methods
are the robot facts the rest of the project uses: where the feet stand, the pose standing on uneven ground, the
robot's size relative to the paper robot's. No module outside :mod:`quad_uneven_env.robot` asks which kind of
robot it has. Two builders fill it: :mod:`~quad_uneven_env.robot.table1` (the paper's Table-1 robot) and
:mod:`~quad_uneven_env.robot.urdf` (a URDF read through Pinocchio); :func:`quad_uneven_env.robot.description.load_robot`
picks one by the YAML.

Frames: the trunk frame is the URDF's root link frame (the paper robot's: trunk centre, x forward, z up).
Each joint sits at ``pos`` in its parent's frame with rotation ``rot`` (parent <- joint) and turns about
``axis`` (unit, in its own frame); its child link's inertia is given in the joint's frame. The foot point is
in the shank (KFE) frame. Units are SI: kg, m, kg m^2, rad, N m.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np

from quad_uneven_env import constants as C
from quad_uneven_env.fields import check_fields, excerpt, param
from quad_uneven_env.robot.kinematics import leg_ik_hip
from quad_uneven_env.robot.leg_chain import feet_ik_B, feet_positions_B, knee_signs

MIN_INERTIA = 1e-15
"""kg m^2: MuJoCo's smallest accepted principal inertia (``mujoco.mjMINVAL``); replaces Table 1's zeros."""

AXIS_TOLERANCE = 1e-6
"""Largest |sin| of the angle between a joint axis and its nominal direction (HAA: trunk x; HFE, KFE: trunk y)."""

PAPER_LEG_LENGTH = 0.42
"""m: the paper robot's stretched leg (thigh 0.2 + shank 0.22), the unit of the scaling rules."""
PAPER_MASS = 50.0
"""kg: the paper robot's mass (Table 1), the unit of the scaling rules."""
PAPER_STANDING_HEIGHT = 0.36
"""m: the paper robot's standing height (hip height 0.34 + foot radius 0.02), the unit of the height rules."""
RATIO_ROUNDING = 1e-12
"""A ratio to the paper robot's value this close to 1 is 1: the paper robot's own sums (0.2 m + 0.22 m is
0.42000000000000004 m in floating point) give it exactly the paper's settings."""

G = 9.81
"""m/s^2, gravity of the plausibility bounds."""
MAX_TORQUE_PER_WEIGHT_LENGTH = 10.0
"""A joint's torque limit may be at most this many times the robot's weight times its leg length (m g l; the
shipped robots have 0.24 to 0.65)."""
MIN_LINK_FRACTION = 0.25
"""Each leg's thigh (HFE to knee) and shank (knee to foot point) are at least this fraction of the leg length (the
shipped robots: 0.46 to 0.54)."""
MAX_TRUNK_LEG_RATIO = 3.0
"""The trunk's collision box spans at most this many leg lengths along any axis, and the hips lie within half of
that from the trunk origin (the shipped robots: at most 1.2 leg lengths)."""
MAX_FOOT_SHANK_RATIO = 0.5
"""The foot sphere's radius is at most this fraction of the shortest shank (the link capsule's of the thigh)."""
MAX_STANDING_HEIGHT = 3.5
"""m: the tallest standing height (the env's default base-height limits, 2.78 times it, reach 10 m)."""


@dataclasses.dataclass(frozen=True)
class GaitSettings:
    """The expert's gait on one robot, where it is not scaled from the paper robot's (a robot YAML's ``gait``).

    Every field is optional (null: the scaled value, see docs/robots.md#scaling-rules).
    """

    cycle_time: float | None = param(None, "s", lo=0.2, hi=20.0, none_ok=True)
    """s, in [0.2, 20]: the seven phases of a walk cycle together (their proportions stay the paper's)."""
    stride: float | None = param(None, "m", lo=0.0, hi=1.0, lo_open=True, none_ok=True)
    """m, in (0, 1]: body advance per cycle."""
    swing_height: float | None = param(None, "m", lo=0.0, hi=0.3, none_ok=True)
    """m, in [0, 0.3]: swing clearance of the foot sphere above the terrain."""
    body_height: float | None = param(None, "m", lo=0.05, hi=1.0, none_ok=True)
    """m, in [0.05, 1]: COG height above the mean foothold height."""
    gain_scale: float | None = param(None, "-", lo=0.0, hi=10.0, lo_open=True, none_ok=True)
    """-, in (0, 10]: factor on the scaled computed-torque gains."""

    def __post_init__(self) -> None:
        check_fields(self)


@dataclasses.dataclass(frozen=True, eq=False)
class LinkInertia:
    """A rigid link's mass properties, in the frame of the joint that moves it (the trunk: its own frame)."""

    mass: float
    """kg"""
    com: np.ndarray
    """(3,) m, centre of mass."""
    inertia: np.ndarray
    """(3, 3) kg m^2, inertia tensor about the COM."""


@dataclasses.dataclass(frozen=True, eq=False)
class JointDescription:
    """One revolute joint and the link it moves."""

    name: str
    """the joint's name in its source (URDF joint name; the paper robot: the MJCF name)."""
    pos: np.ndarray
    """(3,) m, joint origin in the parent's frame."""
    rot: np.ndarray
    """(3, 3) rotation parent <- joint (columns: the joint frame's axes in the parent frame)."""
    axis: np.ndarray
    """(3,) unit rotation axis in the joint's frame."""
    range: tuple[float, float]
    """rad, position limits."""
    torque_limit: float
    """N m, symmetric motor limit."""
    armature: float
    """kg m^2, reflected rotor inertia added to the joint's diagonal of M."""
    damping: float
    """N m s / rad, viscous damping."""
    link: LinkInertia
    """the child link's mass properties (joint frame)."""


@dataclasses.dataclass(frozen=True, eq=False)
class LegDescription:
    """One leg: HAA (trunk -> hip link), HFE (hip -> thigh), KFE (thigh -> shank), foot point on the shank."""

    name: str
    """leg name of :data:`quad_uneven_env.constants.LEG_NAMES`."""
    haa: JointDescription
    hfe: JointDescription
    kfe: JointDescription
    foot: np.ndarray
    """(3,) m, foot point (centre of the foot sphere) in the shank (KFE) frame."""
    foot_frame: str
    """the foot frame's name in the source."""

    @property
    def joints(self) -> tuple[JointDescription, JointDescription, JointDescription]:
        """(HAA, HFE, KFE)."""
        return (self.haa, self.hfe, self.kfe)


@dataclasses.dataclass(frozen=True)
class TwoLinkLegs:
    """Four alike legs in the closed form of the paper's Table 1: HAA and HFE at the hip (a trunk corner, at the
    trunk origin's height), the knee ``thigh`` straight below it and the foot point ``shank`` below the knee at zero
    angles, knees bent as :data:`~quad_uneven_env.constants.KNEE_SIGN`; standing with every foot point
    ``hip_height`` straight below its hip. The closed-form kinematics (:mod:`quad_uneven_env.robot.kinematics`) and
    the planners' compiled whole-body model of such legs read these numbers; the description's joints say the same
    (checked at its construction)."""

    thigh: float
    """m, HFE to knee."""
    shank: float
    """m, knee to foot point."""
    thigh_mass: float
    """kg"""
    thigh_com: float
    """m, HFE to the thigh's COM along the link."""
    shank_mass: float
    """kg"""
    shank_com: float
    """m, knee to the shank's COM along the link."""
    hip_height: float
    """m, the standing pose's foot points below their hips."""

    @property
    def knee_signs(self) -> np.ndarray:
        """(4,) the KFE sign of each leg's knee branch (leg order)."""
        return np.array([C.KNEE_SIGN[leg] for leg in C.LEG_NAMES])

    def standing_joints(self, hip_height: float) -> np.ndarray:
        """(12,) rad, every foot point ``hip_height`` (m) straight below its hip.

        :raises ValueError: unless 0 < ``hip_height`` < thigh + shank.
        """
        if not 0.0 < hip_height < self.thigh + self.shank:
            raise ValueError(f"hip_height must be in (0, {self.thigh + self.shank}) m, got {hip_height}")
        target = np.array([0.0, 0.0, -hip_height])
        return np.concatenate([leg_ik_hip(target, self.thigh, self.shank, C.KNEE_SIGN[leg]) for leg in C.LEG_NAMES])


@dataclasses.dataclass(frozen=True, eq=False)
class RobotDescription:
    """A 12-joint quadruped (the HAA-HFE-KFE chain on each leg), validated at construction.

    ``where`` (not stored) starts the error messages (default ``robot 'NAME'``; a loader names the YAML file).

    :raises ValueError: naming the field, for zero or negative masses, an inertia that is not positive definite
        or violates the triangle inequality, joint axes other than HAA about trunk x and HFE, KFE about trunk y,
        bad limits, a joint or foot frame given to two legs, a hip on another side or end of the trunk than its
        leg's name says, sizes out of proportion (:data:`MAX_TORQUE_PER_WEIGHT_LENGTH`, :data:`MIN_LINK_FRACTION`,
        :data:`MAX_TRUNK_LEG_RATIO`, :data:`MAX_FOOT_SHANK_RATIO`, :data:`MAX_STANDING_HEIGHT`), a standing pose
        outside the joint ranges, or two-link legs (``two_link``) that disagree with the joints.
    """

    name: str
    """robot name (the YAML's ``name``)."""
    source: str
    """where the numbers come from (a config or URDF path)."""
    trunk: LinkInertia
    """the trunk's mass properties (trunk frame)."""
    legs: tuple[LegDescription, ...]
    """four legs in :data:`~quad_uneven_env.constants.LEG_NAMES` order."""
    foot_radius: float
    """m, radius of the foot spheres."""
    link_radius: float
    """m, radius of the thigh capsules (the shank's: 0.7 x); collision only, massless."""
    friction: float
    """Coulomb coefficient between feet and terrain."""
    standing_joints: np.ndarray
    """(12,) rad, the standing pose (SRDF ``standing`` state, or the YAML's)."""
    trunk_box: tuple[np.ndarray, np.ndarray] | None = None
    """(centre (3,), half sizes (3,)) m of the trunk's collision box in the trunk frame; None: from the hips."""
    two_link: TwoLinkLegs | None = None
    """the legs in the paper's closed form (the Table-1 robot), or None (the legs' chain, :mod:`leg_chain`)."""
    gait: GaitSettings = dataclasses.field(default_factory=GaitSettings)
    """the expert's gait settings given by the robot's YAML (``gait``); unset fields are scaled."""
    where: dataclasses.InitVar[str | None] = None

    def __post_init__(self, where: str | None) -> None:
        where = f"robot {self.name!r}" if where is None else where
        if tuple(leg.name for leg in self.legs) != C.LEG_NAMES:
            raise ValueError(f"{where}: legs must be {list(C.LEG_NAMES)} in order, got {[g.name for g in self.legs]}")
        _check_names_used_once(self, where)
        _check_inertia(self.trunk, f"{where}.trunk", allow_massless=False)
        for leg in self.legs:
            for kind, j in zip(C.JOINT_KINDS, leg.joints, strict=True):
                w = f"{where}.{leg.name}.{kind}"
                _check_inertia(j.link, f"{w}.link", allow_massless=kind == "HAA")
                if not (np.all(np.isfinite(j.pos)) and np.allclose(j.rot @ j.rot.T, np.eye(3), atol=1e-9)):
                    raise ValueError(f"{w}: placement must be a finite position and a rotation matrix")
                if abs(np.linalg.norm(j.axis) - 1.0) > 1e-9:
                    raise ValueError(f"{w}.axis must be a unit vector, got {j.axis.tolist()}")
                lo, hi = j.range
                if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
                    raise ValueError(f"{w}.range must be [low, high] with low < high (rad), got {[lo, hi]}")
                if not (np.isfinite(j.torque_limit) and j.torque_limit > 0):
                    raise ValueError(f"{w}.torque_limit must be a finite number > 0 (N m), got {j.torque_limit}")
                if not (j.armature >= 0 and j.damping >= 0):
                    raise ValueError(f"{w}: armature and damping must be >= 0, got {j.armature}, {j.damping}")
            _check_axes(leg, f"{where}.{leg.name}")
            if not np.all(np.isfinite(leg.foot)):
                raise ValueError(f"{where}.{leg.name}.foot must be a finite point (m), got {leg.foot.tolist()}")
        _check_hip_sides(self, where)
        for field, value in (("foot_radius", self.foot_radius), ("link_radius", self.link_radius)):
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{where}.{field} must be a finite number > 0 (m), got {value}")
        if not (np.isfinite(self.friction) and self.friction > 0):
            raise ValueError(f"{where}.friction must be a finite number > 0, got {self.friction}")
        _check_proportions(self, where)
        q = np.asarray(self.standing_joints, dtype=float)
        if q.shape != (C.N_JOINTS,) or not np.all(np.isfinite(q)):
            raise ValueError(f"{where}.standing_joints must be {C.N_JOINTS} finite angles (rad), got {q.tolist()}")
        lo, hi = self.joint_ranges[:, 0], self.joint_ranges[:, 1]
        bad = np.flatnonzero((q < lo - 1e-9) | (q > hi + 1e-9))
        if bad.size:
            j = C.JOINT_NAMES[bad[0]]
            raise ValueError(
                f"{where}.standing_joints.{j} must lie in its range {self.joint_ranges[bad[0]].tolist()}, "
                f"got {q[bad[0]]}"
            )
        if not 0.0 < self.standing_height <= MAX_STANDING_HEIGHT:
            raise ValueError(
                f"{where}: the standing pose must hold the trunk in (0, {MAX_STANDING_HEIGHT}] m above flat ground "
                f"(its lowest foot sphere on it), got {self.standing_height:.4g} m"
            )
        if self.two_link is not None:
            _check_two_link(self, self.two_link, where)

    # ------------------------------------------------------------------ derived quantities
    @property
    def total_mass(self) -> float:
        """kg, trunk plus the twelve leg links."""
        return self.trunk.mass + sum(j.link.mass for leg in self.legs for j in leg.joints)

    @property
    def joint_ranges(self) -> np.ndarray:
        """(12, 2) rad, joint position limits in joint order."""
        return np.array([j.range for leg in self.legs for j in leg.joints], dtype=float)

    @property
    def torque_limits(self) -> np.ndarray:
        """(12,) N m, symmetric motor limits in joint order."""
        return np.array([j.torque_limit for leg in self.legs for j in leg.joints])

    @property
    def hip_positions_B(self) -> np.ndarray:
        """(4, 3) m, HAA joint origins in the trunk frame (leg order)."""
        return np.array([leg.haa.pos for leg in self.legs])

    @property
    def leg_length(self) -> float:
        """m, the longest leg's HFE-to-knee plus knee-to-foot distance (its stretched reach from the HFE axis)."""
        return max(float(np.linalg.norm(leg.kfe.pos) + np.linalg.norm(leg.foot)) for leg in self.legs)

    @property
    def knee_directions(self) -> tuple[str, ...]:
        """Per leg ``"backward"`` (the knee behind the hip-foot line in the standing pose) or ``"forward"``."""
        return tuple("forward" if s > 0 else "backward" for s in knee_signs(self))

    @functools.cached_property
    def standing_feet_B(self) -> np.ndarray:
        """(4, 3) m, the foot points in the trunk frame in the standing pose (two-link legs: straight below the
        hips)."""
        if self.two_link is not None:
            feet = self.hip_positions_B
            feet[:, 2] -= self.two_link.hip_height
        else:
            feet = feet_positions_B(self, self.standing_joints)
        feet.setflags(write=False)
        return feet

    @functools.cached_property
    def standing_height(self) -> float:
        """m, trunk origin above flat ground in the standing pose with the lowest foot sphere touching it (two-link
        legs: hip height plus foot radius, summed as the decimal numbers they are: 0.34 + 0.02 = 0.36 m, where the
        binary sum is 0.36000000000000004 m)."""
        if self.two_link is not None:
            return round(self.two_link.hip_height + self.foot_radius, 12)
        return float(-np.min(feet_positions_B(self, self.standing_joints)[:, 2]) + self.foot_radius)

    @property
    def mass_ratio(self) -> float:
        """-, the robot's mass over the paper robot's :data:`PAPER_MASS` (exactly 1 within
        :data:`RATIO_ROUNDING`)."""
        return _paper_ratio(self.total_mass, PAPER_MASS)

    @property
    def length_ratio(self) -> float:
        """-, the leg length over the paper robot's :data:`PAPER_LEG_LENGTH` (exactly 1 within
        :data:`RATIO_ROUNDING`)."""
        return _paper_ratio(self.leg_length, PAPER_LEG_LENGTH)

    @property
    def height_ratio(self) -> float:
        """-, the standing height over the paper robot's :data:`PAPER_STANDING_HEIGHT` (exactly 1 within
        :data:`RATIO_ROUNDING`)."""
        return _paper_ratio(self.standing_height, PAPER_STANDING_HEIGHT)

    def stand_on(self, ground: np.ndarray) -> tuple[float, np.ndarray]:
        """The standing pose over uneven ground, trunk level: each foot sphere on the ground below its standing
        foot point (:attr:`standing_feet_B`), the trunk at the mean of the heights that puts them there.

        :param ground: (4,) m, the ground's height (world z) below each standing foot point.
        :return: (trunk origin's height (m, world z), the 12 joint angles (rad), not clipped to their ranges).
        """
        r = self.foot_radius
        if self.two_link is not None:  # each foot straight below its hip: the closed form
            legs = self.two_link
            base_z = float(np.mean(ground)) + legs.hip_height + r
            q = np.empty(C.N_JOINTS)
            for i, leg in enumerate(C.LEG_NAMES):
                target_H = np.array([0.0, 0.0, ground[i] + r - base_z])
                q[3 * i : 3 * i + 3] = leg_ik_hip(target_H, legs.thigh, legs.shank, C.KNEE_SIGN[leg])
            return base_z, q
        feet = self.standing_feet_B
        base_z = float(np.mean(ground - feet[:, 2])) + r
        targets = feet.copy()
        targets[:, 2] = ground + r - base_z
        return base_z, feet_ik_B(self, targets)

    def home_qpos(self, ground_height: float = 0.0) -> np.ndarray:
        """(19,) the standing pose over the origin with the lowest foot sphere on flat ground at ``ground_height``
        (m)."""
        q = np.zeros(C.NQ)
        q[2] = ground_height + self.standing_height
        q[3] = 1.0
        q[7:] = self.standing_joints
        return q


def _paper_ratio(value: float, paper: float) -> float:
    ratio = value / paper
    return 1.0 if abs(ratio - 1.0) <= RATIO_ROUNDING else ratio


# ---------------------------------------------------------------------- checks
def _check_names_used_once(desc: RobotDescription, where: str) -> None:
    """No joint and no foot frame belongs to two legs (or twice to one)."""
    seen: dict[str, str] = {}
    for leg in desc.legs:
        for kind, j in zip(C.JOINT_KINDS, leg.joints, strict=True):
            key = f"joint {j.name!r}"
            if key in seen:
                raise ValueError(f"{where}.legs.{leg.name}: {key} is given twice (also as {seen[key]})")
            seen[key] = f"{leg.name} {kind}"
        key = f"foot frame {leg.foot_frame!r}"
        if key in seen:
            raise ValueError(f"{where}.legs.{leg.name}: {key} is given twice (also to {seen[key]})")
        seen[key] = leg.name


def _check_hip_sides(desc: RobotDescription, where: str) -> None:
    """Each leg's hip (HAA origin) on the side (left: +y) and at the end (front: +x) its name says."""
    for leg, hip in zip(desc.legs, desc.hip_positions_B, strict=True):
        sx, sy = C.LEG_SIGN_X[leg.name], C.LEG_SIGN_Y[leg.name]
        if hip[0] * sx <= 0 or hip[1] * sy <= 0:
            side = "left (y > 0)" if sy > 0 else "right (y < 0)"
            end = "front (x > 0)" if sx > 0 else "hind (x < 0)"
            raise ValueError(
                f"{where}.legs.{leg.name}: its hip ({leg.haa.name}) must lie at the {end} {side} of the trunk, "
                f"got x = {hip[0]:.4g} m, y = {hip[1]:.4g} m (are two legs' joints swapped?)"
            )


def _check_proportions(desc: RobotDescription, where: str) -> None:
    """Sizes in proportion to the robot: links, foot and link radii, trunk, torque limits."""
    length = desc.leg_length
    for leg in desc.legs:
        for part, size in (("thigh", np.linalg.norm(leg.kfe.pos)), ("shank", np.linalg.norm(leg.foot))):
            if not size >= MIN_LINK_FRACTION * length:
                raise ValueError(
                    f"{where}.legs.{leg.name}: its {part} must be at least {MIN_LINK_FRACTION:g} of the leg length "
                    f"({MIN_LINK_FRACTION * length:.4g} m), got {size:.4g} m"
                )
    shank = min(float(np.linalg.norm(leg.foot)) for leg in desc.legs)
    thigh = min(float(np.linalg.norm(leg.kfe.pos)) for leg in desc.legs)
    for field, value, link, name in (("foot_radius", desc.foot_radius, shank, "shank"),
                                     ("link_radius", desc.link_radius, thigh, "thigh")):  # fmt: skip
        if value > MAX_FOOT_SHANK_RATIO * link:
            raise ValueError(
                f"{where}.{field} must be at most {MAX_FOOT_SHANK_RATIO:g} of the shortest {name} "
                f"({MAX_FOOT_SHANK_RATIO * link:.4g} m), got {excerpt(value)}"
            )
    span = MAX_TRUNK_LEG_RATIO * length
    hips = desc.hip_positions_B
    if np.any(np.abs(hips) > 0.5 * span):
        raise ValueError(
            f"{where}: the hips must lie within {0.5 * span:.4g} m ({0.5 * MAX_TRUNK_LEG_RATIO:g} leg lengths) of "
            f"the trunk origin, got {np.round(hips, 4).tolist()}"
        )
    if desc.trunk_box is not None:
        centre, half = (np.asarray(v, dtype=float) for v in desc.trunk_box)
        if not (np.all(np.isfinite(centre)) and np.all(np.isfinite(half)) and np.all(half > 0)):
            raise ValueError(f"{where}.trunk_box must have finite half sizes > 0 (m), got {half.tolist()}")
        if np.any(2.0 * half > span) or np.any(np.abs(centre) > 0.5 * span):
            raise ValueError(
                f"{where}: the trunk's collision box must span at most {span:.4g} m ({MAX_TRUNK_LEG_RATIO:g} leg "
                f"lengths of {length:.4g} m) along each axis, got sizes {np.round(2.0 * half, 4).tolist()} m "
                f"at {np.round(centre, 4).tolist()}"
            )
    bound = MAX_TORQUE_PER_WEIGHT_LENGTH * desc.total_mass * G * length
    for leg in desc.legs:
        for kind, j in zip(C.JOINT_KINDS, leg.joints, strict=True):
            if j.torque_limit > bound:
                raise ValueError(
                    f"{where}.{leg.name}.{kind}.torque_limit ({j.name}) must be at most {bound:.4g} N m "
                    f"({MAX_TORQUE_PER_WEIGHT_LENGTH:g} x the robot's weight {desc.total_mass:.4g} kg x g x its "
                    f"leg length {length:.4g} m), got {j.torque_limit:.6g} (a YAML's torque_limit overrides it)"
                )


def _check_two_link(desc: RobotDescription, legs: TwoLinkLegs, where: str) -> None:
    """The two-link numbers say what the joints say, exactly (they are one robot's two views)."""
    eye, w = np.eye(3), f"{where}.two_link"
    for leg in desc.legs:
        haa, hfe, kfe = leg.joints
        same = (
            haa.pos[2] == 0.0
            and all(np.array_equal(j.rot, eye) for j in leg.joints)
            and np.array_equal(haa.axis, [1.0, 0.0, 0.0])
            and np.array_equal(hfe.axis, [0.0, 1.0, 0.0])
            and np.array_equal(kfe.axis, [0.0, 1.0, 0.0])
            and not np.any(hfe.pos)
            and np.array_equal(kfe.pos, [0.0, 0.0, -legs.thigh])
            and np.array_equal(leg.foot, [0.0, 0.0, -legs.shank])
            and haa.link.mass == 0.0
            and (hfe.link.mass, kfe.link.mass) == (legs.thigh_mass, legs.shank_mass)
            and np.array_equal(hfe.link.com, [0.0, 0.0, -legs.thigh_com])
            and np.array_equal(kfe.link.com, [0.0, 0.0, -legs.shank_com])
        )
        if not same:
            raise ValueError(f"{w}: leg {leg.name}'s joints and links are not the two-link leg {legs}")
    if not np.array_equal(desc.standing_joints, legs.standing_joints(legs.hip_height)):
        raise ValueError(f"{w}: standing_joints must be the two-link legs standing at hip_height {legs.hip_height} m")


def _check_inertia(link: LinkInertia, where: str, allow_massless: bool) -> None:
    if not np.isfinite(link.mass) or link.mass < 0 or (link.mass == 0 and not allow_massless):
        need = ">= 0" if allow_massless else "> 0"
        raise ValueError(f"{where}.mass must be a finite number {need} (kg), got {link.mass}")
    I = np.asarray(link.inertia, dtype=float)
    if I.shape != (3, 3) or not np.all(np.isfinite(I)) or not np.allclose(I, I.T, atol=1e-12):
        raise ValueError(f"{where}.inertia must be a finite symmetric 3x3 matrix (kg m^2), got {I.tolist()}")
    if not np.all(np.isfinite(link.com)):
        raise ValueError(f"{where}.com must be a finite point (m), got {np.asarray(link.com).tolist()}")
    if link.mass == 0:
        if np.any(I != 0):
            raise ValueError(f"{where}.inertia must be zero for a massless link, got {I.tolist()}")
        return
    eig = np.linalg.eigvalsh(I)
    if eig[0] <= 0:
        raise ValueError(f"{where}.inertia must be positive definite (kg m^2), got eigenvalues {eig.tolist()}")
    if eig[0] + eig[1] < eig[2] * (1 - 1e-9):
        raise ValueError(f"{where}.inertia must satisfy the triangle inequality, got eigenvalues {eig.tolist()}")


def _check_axes(leg: LegDescription, where: str) -> None:
    """HAA about trunk +-x, HFE and KFE about trunk +-y, at zero joint angles."""
    R = np.eye(3)
    nominal = {"HAA": np.array([1.0, 0, 0]), "HFE": np.array([0, 1.0, 0]), "KFE": np.array([0, 1.0, 0])}
    for kind, j in zip(C.JOINT_KINDS, leg.joints, strict=True):
        R = R @ j.rot
        a = R @ j.axis
        if np.linalg.norm(np.cross(a, nominal[kind])) > AXIS_TOLERANCE:
            raise ValueError(
                f"{where}.{kind} ({j.name}) must turn about trunk {'x' if kind == 'HAA' else 'y'} at zero angles "
                f"(the HAA-HFE-KFE chain), got axis {np.round(a, 6).tolist()}"
            )
