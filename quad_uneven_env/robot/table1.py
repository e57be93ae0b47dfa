"""The paper's Table-1 robot (``configs/robot/paper.yaml``) as a
:class:`~quad_uneven_env.robot.quadruped.RobotDescription`.

A Table-1 YAML gives the trunk as a box (mass, size, principal inertia; the hips at its corners at mid height), the
thigh and shank as rods (length, mass, COM along the link, principal inertia about the long axis first), the
joint ranges (the knee's for front and hind legs), torque limits, joint damping and armature, the foot and link
radii, the friction coefficient and the standing pose's hip height. Every field is checked as
:mod:`quad_uneven_env.fields` checks every config (:data:`TABLE1_FIELDS`); the description then checks the robot
as a whole. Its legs are :class:`~quad_uneven_env.robot.quadruped.TwoLinkLegs`: the closed form the paper's
planners use.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from quad_uneven_env import constants as C
from quad_uneven_env.fields import REQUIRED, Param, check_mapping, check_vector, excerpt
from quad_uneven_env.robot.quadruped import (
    MIN_INERTIA,
    JointDescription,
    LegDescription,
    LinkInertia,
    RobotDescription,
    TwoLinkLegs,
)

_MAPPING = "array"  # a nested mapping, checked by its own fields below

TABLE1_FIELDS: tuple[Param, ...] = (
    Param("name", REQUIRED, "-", "the robot's name", kind="array"),
    Param("body", REQUIRED, "-", "the trunk: mass, size, inertia", kind=_MAPPING),
    Param("thigh", REQUIRED, "-", "hip to knee: length, mass, com, inertia", kind=_MAPPING),
    Param("shank", REQUIRED, "-", "knee to foot point: length, mass, com, inertia", kind=_MAPPING),
    Param("foot_radius", REQUIRED, "m", "collision sphere centred on the foot point", lo=0.0, lo_open=True),
    Param("link_radius", REQUIRED, "m", "collision capsule radius of the thigh", lo=0.0, lo_open=True),
    Param("joint_range", REQUIRED, "rad", "ranges of HAA, HFE, KFE_front, KFE_hind", kind=_MAPPING),
    Param("torque_limit", REQUIRED, "N m", "symmetric motor limits of HAA, HFE, KFE", kind=_MAPPING),
    Param("joint_damping", REQUIRED, "N m s/rad", "viscous joint damping", lo=0.0),
    Param("joint_armature", REQUIRED, "kg m^2", "reflected rotor inertia on each joint", lo=0.0),
    Param("friction", REQUIRED, "-", "Coulomb coefficient between feet and terrain", lo=0.0, lo_open=True),
    Param(
        "standing_hip_height", REQUIRED, "m", "the standing pose's foot points below their hips", lo=0.0, lo_open=True
    ),
)
"""The fields of a Table-1 robot YAML."""

BODY_FIELDS: tuple[Param, ...] = (
    Param("mass", REQUIRED, "kg", "trunk mass", lo=0.0, lo_open=True),
    Param("size", REQUIRED, "m", "length, width, height along trunk x, y, z", kind=_MAPPING),
    Param("inertia", REQUIRED, "kg m^2", "principal inertia about the COM along trunk x, y, z", kind=_MAPPING),
)
LINK_FIELDS: tuple[Param, ...] = (
    Param("length", REQUIRED, "m", "joint to joint (or to the foot point)", lo=0.0, lo_open=True),
    Param("mass", REQUIRED, "kg", "link mass", lo=0.0, lo_open=True),
    Param("com", REQUIRED, "m", "proximal joint to the COM along the link", lo=0.0),
    Param("inertia", REQUIRED, "kg m^2", "principal inertia about the COM: the long axis first", kind=_MAPPING),
)
RANGE_FIELDS: tuple[Param, ...] = tuple(
    Param(k, REQUIRED, "rad", f"{k} range", kind="range", lo=-10.0, hi=10.0)
    for k in ("HAA", "HFE", "KFE_front", "KFE_hind")
)
TORQUE_FIELDS: tuple[Param, ...] = tuple(
    Param(k, REQUIRED, "N m", f"{k} motor limit", lo=0.0, lo_open=True) for k in C.JOINT_KINDS
)
_POSITIVE = Param("", REQUIRED, "kg m^2", "", lo=0.0, lo_open=True)
_NON_NEGATIVE = Param("", REQUIRED, "kg m^2", "", lo=0.0)


def from_table1(raw: Mapping[str, Any], where: str = "robot", source: str | None = None) -> RobotDescription:
    """The description of a Table-1 robot YAML's mapping ``raw`` (see the module docstring).

    :param where: the start of error messages (a loader names the file).
    :raises ValueError: naming the field, for a missing, unknown or bad field, and every check of
        :class:`~quad_uneven_env.robot.quadruped.RobotDescription`.
    """
    v = check_mapping(raw, TABLE1_FIELDS, where)
    name = v["name"]
    if not isinstance(name, str) or not name:
        raise ValueError(f"{where}.name must be a non-empty string, got {excerpt(name)}")
    body = check_mapping(v["body"], BODY_FIELDS, f"{where}.body")
    size = check_vector(body["size"], Param("size", REQUIRED, "m", "", lo=0.0, lo_open=True), f"{where}.body")
    trunk_inertia = check_vector(body["inertia"], _named(_POSITIVE, "inertia"), f"{where}.body")
    thigh, thigh_inertia = _link(v["thigh"], f"{where}.thigh")
    shank, shank_inertia = _link(v["shank"], f"{where}.shank")
    ranges = check_mapping(v["joint_range"], RANGE_FIELDS, f"{where}.joint_range")
    for key, (lo, hi) in ranges.items():
        if not lo < hi:
            raise ValueError(f"{where}.joint_range.{key} must be [low, high] with low < high (rad), got {[lo, hi]}")
    if ranges["KFE_front"][1] >= 0.0 or ranges["KFE_hind"][0] <= 0.0:
        raise ValueError(f"{where}.joint_range: KFE_front must stay < 0 and KFE_hind > 0 (no stretched knee)")
    torque = check_mapping(v["torque_limit"], TORQUE_FIELDS, f"{where}.torque_limit")

    eye = np.eye(3)
    half_l, half_w = size[0] / 2.0, size[1] / 2.0
    hips = np.array([[C.LEG_SIGN_X[leg] * half_l, C.LEG_SIGN_Y[leg] * half_w, 0.0] for leg in C.LEG_NAMES])

    def rod(link: dict[str, float], inertia: tuple[float, ...]) -> LinkInertia:
        axial, other1, other2 = (max(x, MIN_INERTIA) for x in inertia)
        return LinkInertia(link["mass"], np.array([0.0, 0.0, -link["com"]]), np.diag([other1, other2, axial]))

    def joint(leg: str, kind: str, pos, axis, rng, link: LinkInertia) -> JointDescription:
        return JointDescription(
            C.joint_name(leg, kind), np.asarray(pos, dtype=float), eye, np.asarray(axis, dtype=float),
            tuple(float(x) for x in rng), float(torque[kind]), float(v["joint_armature"]),
            float(v["joint_damping"]), link,
        )  # fmt: skip

    massless = LinkInertia(0.0, np.zeros(3), np.zeros((3, 3)))
    thigh_link, shank_link = rod(thigh, thigh_inertia), rod(shank, shank_inertia)
    legs = tuple(
        LegDescription(
            leg,
            joint(leg, "HAA", hips[i], (1, 0, 0), ranges["HAA"], massless),
            joint(leg, "HFE", (0, 0, 0), (0, 1, 0), ranges["HFE"], thigh_link),
            joint(leg, "KFE", (0, 0, -thigh["length"]), (0, 1, 0), ranges[f"KFE_{_end(leg)}"], shank_link),
            np.array([0.0, 0.0, -shank["length"]]),
            C.foot_site(leg),
        )
        for i, leg in enumerate(C.LEG_NAMES)
    )
    two_link = TwoLinkLegs(
        thigh["length"], shank["length"], thigh["mass"], thigh["com"], shank["mass"], shank["com"],
        v["standing_hip_height"],
    )  # fmt: skip
    try:
        standing = two_link.standing_joints(two_link.hip_height)
    except ValueError:
        raise ValueError(
            f"{where}.standing_hip_height must be below the stretched leg (thigh + shank = "
            f"{thigh['length'] + shank['length']} m), got {two_link.hip_height}"
        ) from None
    return RobotDescription(
        name=name,
        source=source or f"robot config {excerpt(name)}",
        trunk=LinkInertia(body["mass"], np.zeros(3), np.diag(trunk_inertia)),
        legs=legs,
        foot_radius=v["foot_radius"],
        link_radius=v["link_radius"],
        friction=v["friction"],
        standing_joints=standing,
        trunk_box=(np.zeros(3), np.asarray(size) / 2.0),
        two_link=two_link,
        where=where,
    )


def _named(p: Param, name: str) -> Param:
    return Param(name, p.default, p.unit, p.doc, lo=p.lo, lo_open=p.lo_open)


def _end(leg: str) -> str:
    return "front" if leg[1] == "F" else "hind"


def _link(raw: Any, where: str) -> tuple[dict[str, float], tuple[float, ...]]:
    link = check_mapping(raw, LINK_FIELDS, where)
    if not link["com"] <= link["length"]:
        raise ValueError(f"{where}.com must lie in [0, {where}.length={link['length']}] (m), got {link['com']}")
    return link, check_vector(link["inertia"], _named(_NON_NEGATIVE, "inertia"), where)
