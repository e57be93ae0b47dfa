"""A quadruped as data: trunk, four HAA-HFE-KFE legs, feet, limits and a standing pose.

:class:`RobotDescription` is what every robot-specific module reads: the MJCF generators, the kinematics of
any description (:mod:`quad_uneven_env.robot.leg_chain`) and the env. Two builders fill it:

- :meth:`RobotDescription.from_robot_config`: the paper's Table-1 robot (``configs/robot/paper.yaml``);
- :meth:`RobotDescription.from_yaml` / :func:`load_robot`: a URDF read through Pinocchio plus a small YAML of
  what a URDF does not say (leg joint and foot frame names, foot radius, armature, torque limits where the URDF's
  are unusable). The URDF is named by the YAML, relative to it, or inside a package's data
  (``{package: example-robot-data, path: ...}``).

Frames: the trunk frame is the URDF's root link frame (the paper robot's: trunk centre, x forward, z up).
Each joint sits at ``pos`` in its parent's frame with rotation ``rot`` (parent <- joint) and turns about
``axis`` (unit, in its own frame); its child link's inertia is given in the joint's frame. The foot point is
in the shank (KFE) frame. Units are SI: kg, m, kg m^2, rad, N m.
"""

from __future__ import annotations

import dataclasses
import functools
import importlib.metadata
import os
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from quad_uneven_env import constants as C
from quad_uneven_env.config import (
    CONFIG_DIR,
    RobotConfig,
    load_robot_config,
    read_yaml,
    resolve_config_path,
)
from quad_uneven_env.fields import check_fields, excerpt, from_mapping, param

if TYPE_CHECKING:
    import pinocchio as pin

MIN_INERTIA = 1e-15
"""kg m^2: MuJoCo's smallest accepted principal inertia (``mujoco.mjMINVAL``); replaces Table 1's zeros."""

AXIS_TOLERANCE = 1e-6
"""Largest |sin| of the angle between a joint axis and its nominal direction (HAA: trunk x; HFE, KFE: trunk y)."""

DATA_PACKAGE = "example-robot-data"
"""The distribution whose robot models a YAML can name with ``{package: example-robot-data, path: ...}``."""

_ROBOT_DATA_ROOT = "cmeel.prefix/share/example-robot-data/robots"


PAPER_LEG_LENGTH = 0.42
"""m: the paper robot's stretched leg (thigh 0.2 + shank 0.22), the unit of the scaling rules."""
PAPER_MASS = 50.0
"""kg: the paper robot's mass (Table 1), the unit of the scaling rules."""
PAPER_BASE_HEIGHT_LIMITS = (0.12, 1.0)
"""m: the paper robot's fall rule: a base height below the first or above the second ends an episode (a third of
its 0.36 m stand, and 2.78 times it)."""
PAPER_STANDING_HEIGHT = 0.36
"""m: the paper robot's standing height, the unit of the base-height limits of other robots."""
PAPER_PD_GAINS = (100.0, 3.0)
"""(N m/rad, N m s/rad): the paper robot's ``joint_pd`` servo gains."""


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


@dataclasses.dataclass(frozen=True, eq=False)
class RobotDescription:
    """A 12-joint quadruped (the HAA-HFE-KFE chain on each leg), validated at construction.

    :raises ValueError: naming the field, for zero or negative masses, an inertia that is not positive definite
        or violates the triangle inequality, joint axes other than HAA about trunk x and HFE, KFE about trunk y,
        bad limits, or a standing pose outside the joint ranges.
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
    config: RobotConfig | None = None
    """the Table-1 config this description was built from (None for a URDF robot)."""
    gait: GaitSettings = dataclasses.field(default_factory=GaitSettings)
    """the expert's gait settings given by the robot's YAML (``gait``); unset fields are scaled."""

    def __post_init__(self) -> None:
        where = f"robot {self.name!r}"
        if tuple(leg.name for leg in self.legs) != C.LEG_NAMES:
            raise ValueError(f"{where}: legs must be {list(C.LEG_NAMES)} in order, got {[g.name for g in self.legs]}")
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
        for field, value in (("foot_radius", self.foot_radius), ("link_radius", self.link_radius)):
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{where}.{field} must be a finite number > 0 (m), got {value}")
        if not (np.isfinite(self.friction) and self.friction > 0):
            raise ValueError(f"{where}.friction must be a finite number > 0, got {self.friction}")
        q = np.asarray(self.standing_joints, dtype=float)
        if q.shape != (C.N_JOINTS,) or not np.all(np.isfinite(q)):
            raise ValueError(f"{where}.standing_joints must be {C.N_JOINTS} finite angles (rad), got {excerpt(q)}")
        lo, hi = self.joint_ranges[:, 0], self.joint_ranges[:, 1]
        bad = np.flatnonzero((q < lo - 1e-9) | (q > hi + 1e-9))
        if bad.size:
            j = C.JOINT_NAMES[bad[0]]
            raise ValueError(
                f"{where}.standing_joints.{j} must lie in its range {self.joint_ranges[bad[0]].tolist()}, "
                f"got {q[bad[0]]}"
            )

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
        from quad_uneven_env.robot.leg_chain import knee_signs

        return tuple("forward" if s > 0 else "backward" for s in knee_signs(self))

    @property
    def standing_height(self) -> float:
        """m, trunk origin above flat ground in the standing pose with the lowest foot sphere touching it."""
        from quad_uneven_env.robot.leg_chain import feet_positions_B

        return float(-np.min(feet_positions_B(self, self.standing_joints)[:, 2]) + self.foot_radius)

    @property
    def base_height_limits(self) -> tuple[float, float]:
        """m, the env's default ``termination.min_base_height`` and ``max_base_height``: the paper robot's
        :data:`PAPER_BASE_HEIGHT_LIMITS` in units of its standing height (a third of the standing height, and
        2.78 times it)."""
        if self.config is not None:
            return PAPER_BASE_HEIGHT_LIMITS
        k = self.standing_height / PAPER_STANDING_HEIGHT
        return PAPER_BASE_HEIGHT_LIMITS[0] * k, PAPER_BASE_HEIGHT_LIMITS[1] * k

    @property
    def joint_pd_gains(self) -> tuple[float, float]:
        """(N m/rad, N m s/rad), the env's default ``joint_pd`` gains: the paper robot's
        :data:`PAPER_PD_GAINS` scaled with the robot's weight times leg length (stiffness) and with the same
        damping ratio at a natural frequency ~ 1 / sqrt(leg length) (damping ~ mass x leg length^1.5)."""
        if self.config is not None:
            return PAPER_PD_GAINS
        m, s = self.total_mass / PAPER_MASS, self.leg_length / PAPER_LEG_LENGTH
        return PAPER_PD_GAINS[0] * m * s, PAPER_PD_GAINS[1] * m * s**1.5

    # ------------------------------------------------------------------ builders
    @classmethod
    def from_robot_config(cls, cfg: RobotConfig) -> RobotDescription:
        """The paper's Table-1 robot: HAA and HFE at the hip (the trunk corner), the knee ``l1`` below it, the
        foot ``l2`` below the knee; the links' zero axial inertias become :data:`MIN_INERTIA`."""
        from quad_uneven_env.robot.kinematics import hip_positions_B, standing_joint_angles

        eye = np.eye(3)
        hips = hip_positions_B(cfg)

        def rod(link) -> LinkInertia:
            axial, other1, other2 = (max(v, MIN_INERTIA) for v in link.inertia)
            return LinkInertia(link.mass, np.array([0.0, 0.0, -link.com]), np.diag([other1, other2, axial]))

        def joint(leg: str, kind: str, pos, axis, rng, link) -> JointDescription:
            return JointDescription(
                C.joint_name(leg, kind), np.asarray(pos, dtype=float), eye, np.asarray(axis, dtype=float),
                tuple(float(v) for v in rng), float(cfg.torque_limit[kind]), float(cfg.joint_armature),
                float(cfg.joint_damping), link,
            )  # fmt: skip

        massless = LinkInertia(0.0, np.zeros(3), np.zeros((3, 3)))
        legs = tuple(
            LegDescription(
                leg,
                joint(leg, "HAA", hips[i], (1, 0, 0), cfg.joint_range["HAA"], massless),
                joint(leg, "HFE", (0, 0, 0), (0, 1, 0), cfg.joint_range["HFE"], rod(cfg.thigh)),
                joint(leg, "KFE", (0, 0, -cfg.thigh.length), (0, 1, 0), cfg.knee_range(leg), rod(cfg.shank)),
                np.array([0.0, 0.0, -cfg.shank.length]),
                C.foot_site(leg),
            )
            for i, leg in enumerate(C.LEG_NAMES)
        )
        from quad_uneven_env.robot.model import NOMINAL_HIP_HEIGHT

        half = np.asarray(cfg.body.size) / 2.0
        return cls(
            name=cfg.name,
            source=f"robot config {cfg.name!r}",
            trunk=LinkInertia(cfg.body.mass, np.zeros(3), np.diag(cfg.body.inertia)),
            legs=legs,
            foot_radius=cfg.foot_radius,
            link_radius=cfg.link_radius,
            friction=cfg.friction,
            standing_joints=standing_joint_angles(cfg, NOMINAL_HIP_HEIGHT),
            trunk_box=(np.zeros(3), half),
            config=cfg,
        )

    @classmethod
    def from_yaml(cls, path: str | os.PathLike[str]) -> RobotDescription:
        """A URDF robot from its YAML (see the module docstring and docs/robots.md for the fields)."""
        p = Path(path)
        return cls.from_urdf_spec(read_yaml(p), p.parent, str(p))

    @classmethod
    def from_urdf_spec(cls, raw: Mapping[str, Any], base_dir: Path, where: str = "robot") -> RobotDescription:
        """Build from a YAML mapping naming a URDF (``urdf``), relative paths resolved against ``base_dir``."""
        _require_keys(raw, URDF_REQUIRED, URDF_OPTIONAL, where)
        urdf = _resolve_model_file(raw["urdf"], base_dir, f"{where}: urdf")
        srdf = _resolve_model_file(raw["srdf"], base_dir, f"{where}: srdf") if raw.get("srdf") else None
        return from_urdf(
            urdf,
            name=str(raw["name"]),
            legs=raw["legs"],
            foot_radius=raw["foot_radius"],
            srdf=srdf,
            standing_state=raw.get("standing_state", "standing"),
            standing_joints=raw.get("standing_joints"),
            torque_limit=raw.get("torque_limit"),
            joint_range=raw.get("joint_range"),
            armature=raw.get("armature", 0.0),
            damping=raw.get("damping", 0.0),
            friction=raw.get("friction", 1.0),
            link_radius=raw.get("link_radius"),
            gait=raw.get("gait"),
            where=where,
        )


URDF_REQUIRED = frozenset({"name", "urdf", "legs", "foot_radius"})
"""Fields every URDF robot YAML has."""
URDF_OPTIONAL = frozenset(
    {"srdf", "standing_state", "standing_joints", "torque_limit", "joint_range", "armature", "damping", "friction",
     "link_radius", "description", "gait"}
)  # fmt: skip
"""Fields a URDF robot YAML may have (``description``: free text)."""


def _require_keys(raw: Any, required: frozenset[str], optional: frozenset[str], where: str) -> None:
    if not isinstance(raw, Mapping):
        raise ValueError(f"{where} must be a mapping, got {excerpt(raw)}")
    missing = required - set(raw)
    unknown = set(raw) - required - optional
    if missing:
        raise ValueError(f"{where}: missing field(s) {sorted(missing)}")
    if unknown:
        allowed = sorted(required | optional)
        raise ValueError(f"{where}: unknown field(s) {excerpt(sorted(unknown, key=str))}; allowed: {allowed}")


def _check_inertia(link: LinkInertia, where: str, allow_massless: bool) -> None:
    if not np.isfinite(link.mass) or link.mass < 0 or (link.mass == 0 and not allow_massless):
        need = ">= 0" if allow_massless else "> 0"
        raise ValueError(f"{where}.mass must be a finite number {need} (kg), got {link.mass}")
    I = np.asarray(link.inertia, dtype=float)
    if I.shape != (3, 3) or not np.all(np.isfinite(I)) or not np.allclose(I, I.T, atol=1e-12):
        raise ValueError(f"{where}.inertia must be a finite symmetric 3x3 matrix (kg m^2), got {I.tolist()}")
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


# ---------------------------------------------------------------------- model files
def robot_data_dir() -> Path:
    """The ``robots/`` folder of the installed ``example-robot-data`` distribution (the ``robots`` extra).

    :raises ValueError: if the distribution is not installed.
    """
    try:
        dist = importlib.metadata.distribution(DATA_PACKAGE)
    except importlib.metadata.PackageNotFoundError:
        raise ValueError(f"robot models need the {DATA_PACKAGE!r} package: pip install 'quad-uneven[robots]'") from None
    root = Path(str(dist.locate_file(_ROBOT_DATA_ROOT)))
    if not root.is_dir():
        raise ValueError(f"{DATA_PACKAGE} {dist.version} has no {_ROBOT_DATA_ROOT} folder (need version >= 4.4)")
    return root


def _resolve_model_file(spec: Any, base_dir: Path, where: str) -> Path:
    """A URDF/SRDF path: a string relative to ``base_dir``, or ``{package: example-robot-data, path: ...}``."""
    if isinstance(spec, str | os.PathLike):
        p = Path(spec)
        p = p if p.is_absolute() else base_dir / p
    elif isinstance(spec, Mapping) and set(spec) == {"package", "path"} and spec["package"] == DATA_PACKAGE:
        p = robot_data_dir() / str(spec["path"])
    else:
        raise ValueError(
            f"{where} must be a path (relative to the YAML) or {{package: {DATA_PACKAGE}, path: ...}}, "
            f"got {excerpt(spec)}"
        )
    if not p.is_file():
        raise ValueError(f"{where}: file {str(p)!r} does not exist")
    return p


# ---------------------------------------------------------------------- URDF through Pinocchio
def _revolute_axis(model: pin.Model, jid: int, where: str) -> np.ndarray:
    j = model.joints[jid]
    short = j.shortname()
    canonical = {"JointModelRX": (1.0, 0, 0), "JointModelRY": (0, 1.0, 0), "JointModelRZ": (0, 0, 1.0)}
    if short in canonical:
        return np.array(canonical[short])
    if short == "JointModelRevoluteUnaligned":
        return np.array(j.extract().axis, dtype=float)
    raise ValueError(f"{where} ({model.names[jid]}) must be a revolute joint with limits, got {short}")


def _float(value: Any, where: str, lo: float = 0.0, lo_open: bool = True) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        v = float("nan")
    if not np.isfinite(v) or v < lo or (lo_open and v == lo):
        raise ValueError(f"{where} must be a finite number {'>' if lo_open else '>='} {lo:g}, got {excerpt(value)}")
    return v


def _per_kind(value: Any, where: str, lo_open: bool) -> dict[str, float]:
    """A number for all three joints, or a mapping over HAA, HFE, KFE (each a number)."""
    if isinstance(value, Mapping):
        unknown = set(value) - set(C.JOINT_KINDS)
        if unknown:
            names = excerpt(sorted(unknown, key=str))
            raise ValueError(f"{where}: unknown joint(s) {names}; allowed: {list(C.JOINT_KINDS)}")
        return {k: _float(v, f"{where}.{k}", lo_open=lo_open) for k, v in value.items()}
    v = _float(value, where, lo_open=lo_open)
    return dict.fromkeys(C.JOINT_KINDS, v)


RANGE_KEYS = ("HAA", "HFE", "KFE", "HAA_left", "HAA_right", "HFE_front", "HFE_hind", "KFE_front", "KFE_hind")
"""Keys of a URDF robot's ``joint_range`` override: a joint kind, or a kind for one side or end of the trunk."""


def _range_override(ranges: Any, leg: str, kind: str, where: str) -> tuple[float, float] | None:
    if not ranges:
        return None
    if not isinstance(ranges, Mapping) or set(ranges) - set(RANGE_KEYS):
        raise ValueError(f"{where} must be a mapping with keys among {list(RANGE_KEYS)}, got {excerpt(ranges)}")
    side = "left" if C.LEG_SIGN_Y[leg] > 0 else "right"
    end = "front" if leg[1] == "F" else "hind"
    for key in (f"{kind}_{side}", f"{kind}_{end}", kind):
        if key in ranges:
            try:
                lo, hi = (float(v) for v in ranges[key])
            except (TypeError, ValueError):
                raise ValueError(f"{where}.{key} must be [low, high] (rad), got {excerpt(ranges[key])}") from None
            if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
                raise ValueError(f"{where}.{key} must be [low, high] with low < high (rad), got {[lo, hi]}")
            return lo, hi
    return None


def _trunk_box(urdf: Path, root_link: str) -> tuple[np.ndarray, np.ndarray] | None:
    """The largest collision box of the root link or a link fixed to it (centre, half sizes; trunk frame).

    Only boxes aligned with the trunk frame are taken; None if there is none.
    """
    tree = ET.parse(urdf).getroot()
    fixed_children: dict[str, list[tuple[str, np.ndarray, np.ndarray]]] = {}
    for j in tree.findall("joint"):
        if j.get("type") == "fixed":
            o = j.find("origin")
            xyz = np.array([float(v) for v in (o.get("xyz", "0 0 0") if o is not None else "0 0 0").split()])
            rpy = np.array([float(v) for v in (o.get("rpy", "0 0 0") if o is not None else "0 0 0").split()])
            fixed_children.setdefault(j.find("parent").get("link"), []).append((j.find("child").get("link"), xyz, rpy))
    links = {link.get("name"): link for link in tree.findall("link")}
    best = None
    stack = [(root_link, np.zeros(3), True)]
    while stack:
        name, offset, aligned = stack.pop()
        for col in links[name].findall("collision") if name in links else []:
            box = col.find("geometry/box")
            o = col.find("origin")
            rpy = np.array([float(v) for v in (o.get("rpy", "0 0 0") if o is not None else "0 0 0").split()])
            if box is None or not aligned or np.any(np.abs(rpy) > 1e-9):
                continue
            xyz = np.array([float(v) for v in (o.get("xyz", "0 0 0") if o is not None else "0 0 0").split()])
            size = np.array([float(v) for v in box.get("size").split()])
            if best is None or np.prod(size) > np.prod(best[1]) * 8:
                best = (offset + xyz, size / 2.0)
        for child, xyz, rpy in fixed_children.get(name, []):
            stack.append((child, offset + xyz, aligned and not np.any(np.abs(rpy) > 1e-9)))
    return best


def from_urdf(
    urdf: str | os.PathLike[str],
    *,
    name: str,
    legs: Mapping[str, Any],
    foot_radius: float,
    srdf: str | os.PathLike[str] | None = None,
    standing_state: str = "standing",
    standing_joints: Mapping[str, Any] | None = None,
    torque_limit: Any = None,
    joint_range: Mapping[str, Any] | None = None,
    armature: Any = 0.0,
    damping: Any = 0.0,
    friction: float = 1.0,
    link_radius: float | None = None,
    gait: Mapping[str, Any] | None = None,
    where: str = "robot",
) -> RobotDescription:
    """Read a quadruped's URDF through Pinocchio (``buildModelFromUrdf`` with a free-flyer root).

    :param legs: per leg name of :data:`~quad_uneven_env.constants.LEG_NAMES`, ``{joints: [HAA, HFE, KFE],
        foot: frame}`` with the URDF's joint and foot frame names.
    :param foot_radius: m, radius of the foot spheres.
    :param srdf: SRDF whose group state ``standing_state`` gives the standing pose (or ``standing_joints``:
        per leg three angles, rad).
    :param torque_limit: N m, overrides the URDF's effort limits (a number, or a mapping over HAA, HFE, KFE).
    :param joint_range: rad, overrides of the URDF's limits (keys :data:`RANGE_KEYS`).
    :param armature: kg m^2, reflected rotor inertia (a number or a mapping over joint kinds); URDFs lack it.
    :param damping: N m s/rad, joint damping (a number or a mapping over joint kinds).
    :param gait: the expert's gait settings (fields of :class:`GaitSettings`; None: all scaled).
    :raises ValueError: naming the field, for anything but 12 revolute joints in four HAA-HFE-KFE chains on a
        free-floating trunk, a missing joint or foot frame, and every check of :class:`RobotDescription`.
    """
    import pinocchio as pin

    urdf = Path(urdf)
    try:
        model = pin.buildModelFromUrdf(str(urdf), pin.JointModelFreeFlyer())
    except (RuntimeError, ValueError) as err:
        raise ValueError(f"{where}: urdf {str(urdf)!r} cannot be read by Pinocchio: {err}") from None
    if model.nq != C.NQ or model.nv != C.NV:
        raise ValueError(
            f"{where}: urdf {urdf.name} must have {C.N_JOINTS} actuated joints (nq={C.NQ}, nv={C.NV} with the "
            f"free-flyer root), got nq={model.nq - 7}+7, nv={model.nv - 6}+6"
        )
    if not isinstance(legs, Mapping) or set(legs) != set(C.LEG_NAMES):
        got = sorted(legs) if isinstance(legs, Mapping) else legs
        raise ValueError(f"{where}.legs must map each of {list(C.LEG_NAMES)} to {{joints, foot}}, got {excerpt(got)}")
    tau_over = _per_kind(torque_limit, f"{where}.torque_limit", lo_open=True) if torque_limit is not None else {}
    arm = _per_kind(armature, f"{where}.armature", lo_open=False)
    damp = _per_kind(damping, f"{where}.damping", lo_open=False)
    radius = _float(foot_radius, f"{where}.foot_radius")
    gait_settings = from_mapping(GaitSettings, gait, f"{where}.gait")

    def inertia(jid: int) -> LinkInertia:
        y = model.inertias[jid]
        return LinkInertia(float(y.mass), np.array(y.lever, dtype=float), np.array(y.inertia, dtype=float))

    leg_descs, q_index = [], []
    for leg in C.LEG_NAMES:
        spec, w = legs[leg], f"{where}.legs.{leg}"
        _require_keys(spec, frozenset({"joints", "foot"}), frozenset(), w)
        names = spec["joints"]
        if not isinstance(names, list | tuple) or len(names) != 3:
            raise ValueError(f"{w}.joints must be the URDF names of [HAA, HFE, KFE], got {excerpt(names)}")
        jids = []
        for kind, jn in zip(C.JOINT_KINDS, names, strict=True):
            if not model.existJointName(str(jn)):
                raise ValueError(f"{w}.joints: {kind} joint {excerpt(jn)} is not in {urdf.name}")
            jids.append(model.getJointId(str(jn)))
        parents = [model.parents[j] for j in jids]
        if parents != [1, jids[0], jids[1]]:
            raise ValueError(
                f"{w}.joints must form the chain trunk -> {names[0]} -> {names[1]} -> {names[2]} in {urdf.name}, "
                f"got parents {[model.names[p] for p in parents]}"
            )
        joints = []
        for kind, jid in zip(C.JOINT_KINDS, jids, strict=True):
            axis = _revolute_axis(model, jid, f"{w}.{kind}")
            iq, iv = model.joints[jid].idx_q, model.joints[jid].idx_v
            rng = _range_override(joint_range, leg, kind, f"{where}.joint_range") or (
                float(model.lowerPositionLimit[iq]),
                float(model.upperPositionLimit[iq]),
            )
            tau = tau_over.get(kind, float(model.effortLimit[iv]))
            P = model.jointPlacements[jid]
            joints.append(
                JointDescription(
                    model.names[jid],
                    np.array(P.translation, dtype=float),
                    np.array(P.rotation, dtype=float),
                    axis,
                    rng,
                    tau,
                    arm.get(kind, 0.0),
                    damp.get(kind, 0.0),
                    inertia(jid),
                )
            )
            q_index.append(iq)
        foot = str(spec["foot"])
        if not model.existFrame(foot):
            raise ValueError(f"{w}.foot: frame {excerpt(foot)} is not in {urdf.name}")
        frame = model.frames[model.getFrameId(foot)]
        if frame.parentJoint != jids[2]:
            raise ValueError(
                f"{w}.foot: frame {excerpt(foot)} must be fixed to the shank (moved by {names[2]}), "
                f"got {model.names[frame.parentJoint]}"
            )
        leg_descs.append(LegDescription(leg, *joints, np.array(frame.placement.translation, dtype=float), foot))

    standing = _standing_pose(model, srdf, standing_state, standing_joints, q_index, where)
    root_link = next((f.name for f in model.frames if f.parentJoint == 1 and f.type == pin.FrameType.BODY), "")
    thigh = max(float(np.linalg.norm(g.kfe.pos)) for g in leg_descs)
    return RobotDescription(
        name=name,
        source=str(urdf),
        trunk=inertia(1),
        legs=tuple(leg_descs),
        foot_radius=radius,
        link_radius=_float(link_radius, f"{where}.link_radius") if link_radius is not None else 0.1 * thigh,
        friction=_float(friction, f"{where}.friction"),
        standing_joints=standing,
        trunk_box=_trunk_box(urdf, root_link),
        gait=gait_settings,
    )


def _standing_pose(model, srdf, state: str, joints: Any, q_index: list[int], where: str) -> np.ndarray:
    if joints is not None:
        if not isinstance(joints, Mapping) or set(joints) != set(C.LEG_NAMES):
            raise ValueError(f"{where}.standing_joints must map each of {list(C.LEG_NAMES)} to 3 angles (rad)")
        q = np.array([joints[leg] for leg in C.LEG_NAMES], dtype=float).reshape(-1)
        if q.shape != (C.N_JOINTS,):
            raise ValueError(f"{where}.standing_joints must give 3 angles (rad) per leg, got {excerpt(joints)}")
        return q
    if srdf is None:
        raise ValueError(
            f"{where}: a standing pose is needed: give srdf (with a {excerpt(state)} state) or standing_joints"
        )
    import pinocchio as pin

    pin.loadReferenceConfigurations(model, str(srdf), False)
    if state not in model.referenceConfigurations:
        raise ValueError(
            f"{where}.standing_state {excerpt(state)} is not in {Path(srdf).name}; it has "
            f"{sorted(model.referenceConfigurations.keys())}"
        )
    return np.array(model.referenceConfigurations[state], dtype=float)[q_index]


# ---------------------------------------------------------------------- loading by name
def robot_names() -> list[str]:
    """Names of the shipped robots (``configs/robot/*.yaml``)."""
    return sorted(p.stem for p in (CONFIG_DIR / "robot").glob("*.yaml"))


def load_robot(name_or_path: str | os.PathLike[str] = "paper") -> RobotDescription:
    """A robot by name (``configs/robot/NAME.yaml``) or YAML path: a URDF robot if its YAML names a ``urdf``,
    else a Table-1 config (cached)."""
    return _load_robot(str(name_or_path))


@functools.lru_cache(maxsize=16)
def _load_robot(name_or_path: str) -> RobotDescription:
    path = resolve_config_path(name_or_path, "robot")
    raw = read_yaml(path)
    if "urdf" in raw:
        return RobotDescription.from_urdf_spec(raw, path.parent, f"robot {path.name}")
    return RobotDescription.from_robot_config(load_robot_config(name_or_path))
