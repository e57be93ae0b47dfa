"""A URDF robot as a :class:`~quad_uneven_env.robot.quadruped.RobotDescription`, read through Pinocchio.

A robot YAML names the URDF (relative to the YAML, or inside a package's data: ``{package: example-robot-data,
path: ...}``) and says what a URDF does not: each leg's joint and foot frame names, the foot radius, the standing
pose (an SRDF group state, or angles), armature, damping, friction, and torque limits or joint ranges where the
URDF's are unusable (:data:`URDF_FIELDS`). Every field is checked as :mod:`quad_uneven_env.fields` checks every
config; the URDF's and SRDF's own errors become one message naming the file and the field; the description then
checks the robot as a whole. The kinematic tree, the inertias, the limits and the trunk's collision box are
Pinocchio's reading of the URDF (``buildModelFromUrdf``, ``buildGeomFromUrdfString``).
"""

from __future__ import annotations

import importlib.metadata
import os
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from quad_uneven_env import constants as C
from quad_uneven_env.fields import REQUIRED, Param, check_mapping, check_vector, excerpt, from_mapping
from quad_uneven_env.robot.quadruped import (
    GaitSettings,
    JointDescription,
    LegDescription,
    LinkInertia,
    RobotDescription,
)

if TYPE_CHECKING:
    import pinocchio as pin

DATA_PACKAGE = "example-robot-data"
"""The distribution whose robot models a YAML can name with ``{package: example-robot-data, path: ...}``."""

_ROBOT_DATA_ROOT = "cmeel.prefix/share/example-robot-data/robots"

_ANY = "array"  # checked by its own rules below

URDF_FIELDS: tuple[Param, ...] = (
    Param("name", REQUIRED, "-", "the robot's name", kind=_ANY),
    Param("description", None, "-", "free text", kind=_ANY),
    Param("urdf", REQUIRED, "-", "the URDF: a path relative to the YAML or {package, path}", kind=_ANY),
    Param("srdf", None, "-", "an SRDF with the standing state: a path or {package, path}", kind=_ANY),
    Param("standing_state", "standing", "-", "the SRDF's group state of the standing pose", kind=_ANY),
    Param("standing_joints", None, "rad", "per leg [HAA, HFE, KFE] of the standing pose", kind=_ANY),
    Param("legs", REQUIRED, "-", "per leg {joints: [HAA, HFE, KFE], foot: frame}", kind=_ANY),
    Param("foot_radius", REQUIRED, "m", "radius of the foot spheres", lo=0.0, lo_open=True),
    Param("torque_limit", None, "N m", "motor limits over the URDF's efforts", kind=_ANY),
    Param("joint_range", None, "rad", "ranges over the URDF's limits", kind=_ANY),
    Param("armature", 0.0, "kg m^2", "reflected rotor inertia", kind=_ANY),
    Param("damping", 0.0, "N m s/rad", "viscous joint damping", kind=_ANY),
    Param("friction", 1.0, "-", "Coulomb coefficient between feet and terrain", lo=0.0, lo_open=True),
    Param("link_radius", None, "m", "thigh capsule radius (null: 0.1 x the thigh)", lo=0.0, lo_open=True, none_ok=True),
    Param("gait", None, "-", "the expert's gait settings (GaitSettings)", kind=_ANY),
)
"""The fields of a URDF robot YAML (docs/robots.md)."""

RANGE_KEYS = ("HAA", "HFE", "KFE", "HAA_left", "HAA_right", "HFE_front", "HFE_hind", "KFE_front", "KFE_hind")
"""Keys of a URDF robot's ``joint_range`` override: a joint kind, or a kind for one side or end of the trunk."""

_PER_KIND = {
    "torque_limit": Param("torque_limit", None, "N m", "", lo=0.0, lo_open=True),
    "armature": Param("armature", 0.0, "kg m^2", "", lo=0.0),
    "damping": Param("damping", 0.0, "N m s/rad", "", lo=0.0),
}
_ANGLE = Param("", REQUIRED, "rad", "", lo=-4.0 * np.pi, hi=4.0 * np.pi)
_RANGE_FIELDS = tuple(
    Param(k, None, "rad", f"{k} range", kind="range", lo=-4.0 * np.pi, hi=4.0 * np.pi) for k in RANGE_KEYS
)


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


def model_files(raw: Mapping[str, Any], base_dir: Path, where: str) -> tuple[Path, Path | None]:
    """The URDF and the SRDF (or None) a URDF robot YAML's mapping names, relative paths against ``base_dir``.

    :raises ValueError: naming ``where.urdf`` or ``where.srdf`` for a bad spec or a missing file.
    """
    urdf = _resolve_model_file(raw.get("urdf"), base_dir, f"{where}.urdf")
    srdf = _resolve_model_file(raw["srdf"], base_dir, f"{where}.srdf") if raw.get("srdf") is not None else None
    return urdf, srdf


def from_urdf_yaml(raw: Mapping[str, Any], base_dir: Path, where: str = "robot") -> RobotDescription:
    """The description of a URDF robot YAML's mapping ``raw`` (:data:`URDF_FIELDS`), relative paths against
    ``base_dir``.

    :raises ValueError: naming the field (and the file, for the URDF's and SRDF's own errors).
    """
    v = check_mapping(raw, URDF_FIELDS, where)
    if v["description"] is not None and not isinstance(v["description"], str):
        raise ValueError(f"{where}.description must be a text, got {excerpt(v['description'])}")
    urdf, srdf = model_files(v, base_dir, where)
    return from_urdf(
        urdf, name=v["name"], legs=v["legs"], foot_radius=v["foot_radius"], srdf=srdf,
        standing_state=v["standing_state"], standing_joints=v["standing_joints"], torque_limit=v["torque_limit"],
        joint_range=v["joint_range"], armature=v["armature"], damping=v["damping"], friction=v["friction"],
        link_radius=v["link_radius"], gait=v["gait"], where=where,
    )  # fmt: skip


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
        free-floating trunk, a missing joint or foot frame, a URDF or SRDF Pinocchio cannot read, and every check
        of :class:`~quad_uneven_env.robot.quadruped.RobotDescription`.
    """
    urdf = Path(urdf)
    if not isinstance(name, str) or not name:
        raise ValueError(f"{where}.name must be a non-empty string, got {excerpt(name)}")
    radius = Param("foot_radius", REQUIRED, "m", "", lo=0.0, lo_open=True).check(foot_radius, where)
    mu = Param("friction", 1.0, "-", "", lo=0.0, lo_open=True).check(friction, where)
    link_r = Param("link_radius", None, "m", "", lo=0.0, lo_open=True, none_ok=True).check(link_radius, where)
    tau_over = _per_kind(torque_limit, "torque_limit", where)
    arm = _per_kind(armature, "armature", where)
    damp = _per_kind(damping, "damping", where)
    ranges = check_mapping({} if joint_range is None else joint_range, _RANGE_FIELDS, f"{where}.joint_range")
    _check_ranges(ranges, where)
    gait_settings = from_mapping(GaitSettings, gait, f"{where}.gait")
    leg_names = _leg_names(legs, where)
    model = _read_urdf(urdf, where)

    def inertia(jid: int) -> LinkInertia:
        y = model.inertias[jid]
        return LinkInertia(float(y.mass), np.array(y.lever, dtype=float), np.array(y.inertia, dtype=float))

    leg_descs, q_index = [], []
    for leg in C.LEG_NAMES:
        names, foot = leg_names[leg]
        w = f"{where}.legs.{leg}"
        jids = []
        for kind, jn in zip(C.JOINT_KINDS, names, strict=True):
            if not model.existJointName(jn):
                raise ValueError(f"{w}.joints: {kind} joint {excerpt(jn)} is not in {urdf.name}")
            jids.append(model.getJointId(jn))
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
            rng = _range_override(ranges, leg, kind) or (
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
    thigh = max(float(np.linalg.norm(g.kfe.pos)) for g in leg_descs)
    return RobotDescription(
        name=name,
        source=str(urdf),
        trunk=inertia(1),
        legs=tuple(leg_descs),
        foot_radius=radius,
        link_radius=link_r if link_r is not None else 0.1 * thigh,
        friction=mu,
        standing_joints=standing,
        trunk_box=_trunk_box(model, urdf, where),
        gait=gait_settings,
        where=where,
    )


# ---------------------------------------------------------------------- the YAML's fields
def _resolve_model_file(spec: Any, base_dir: Path, where: str) -> Path:
    """A URDF/SRDF path: a string relative to ``base_dir``, or ``{package: example-robot-data, path: ...}``."""
    if isinstance(spec, str | os.PathLike) and str(spec):
        p = Path(spec)
        p = p if p.is_absolute() else base_dir / p
    elif (
        isinstance(spec, Mapping)
        and set(spec) == {"package", "path"}
        and spec["package"] == DATA_PACKAGE
        and isinstance(spec["path"], str)
    ):
        p = robot_data_dir() / spec["path"]
    else:
        raise ValueError(
            f"{where} must be a path (relative to the YAML) or {{package: {DATA_PACKAGE}, path: ...}}, "
            f"got {excerpt(spec)}"
        )
    if not p.is_file():
        raise ValueError(f"{where}: file {str(p)!r} does not exist")
    return p


def _per_kind(value: Any, field: str, where: str) -> dict[str, float]:
    """A number for all three joints, or a mapping over HAA, HFE, KFE (each a number); None: nothing."""
    p = _PER_KIND[field]
    if value is None:
        return {}
    if isinstance(value, Mapping):
        kinds = tuple(Param(k, None, p.unit, p.doc, lo=p.lo, lo_open=p.lo_open) for k in C.JOINT_KINDS)
        given = set(value)
        checked = check_mapping(value, kinds, f"{where}.{field}")
        return {k: x for k, x in checked.items() if k in given}
    return dict.fromkeys(C.JOINT_KINDS, p.check(value, where))


def _leg_names(legs: Any, where: str) -> dict[str, tuple[tuple[str, str, str], str]]:
    """Per leg, its three joint names and its foot frame, each used once."""
    if not isinstance(legs, Mapping) or set(legs) != set(C.LEG_NAMES):
        got = sorted(map(str, legs)) if isinstance(legs, Mapping) else legs
        raise ValueError(f"{where}.legs must map each of {list(C.LEG_NAMES)} to {{joints, foot}}, got {excerpt(got)}")
    out: dict[str, tuple[tuple[str, str, str], str]] = {}
    owner: dict[str, str] = {}
    for leg in C.LEG_NAMES:
        spec, w = legs[leg], f"{where}.legs.{leg}"
        if not isinstance(spec, Mapping) or set(spec) != {"joints", "foot"}:
            raise ValueError(f"{w} must be {{joints: [HAA, HFE, KFE], foot: frame}}, got {excerpt(spec)}")
        names, foot = spec["joints"], spec["foot"]
        if not (isinstance(names, list | tuple) and len(names) == 3 and all(isinstance(n, str) for n in names)):
            raise ValueError(f"{w}.joints must be the URDF names of [HAA, HFE, KFE], got {excerpt(names)}")
        if not isinstance(foot, str):
            raise ValueError(f"{w}.foot must be the URDF name of the foot frame, got {excerpt(foot)}")
        for item, what in [*((n, f"{k} joint") for n, k in zip(names, C.JOINT_KINDS, strict=True)), (foot, "foot")]:
            if item in owner:
                raise ValueError(f"{w}: {what} {excerpt(item)} is given twice (also to {owner[item]})")
            owner[item] = f"{leg} ({what})"
        out[leg] = (tuple(names), foot)  # type: ignore[assignment]
    return out


def _range_override(ranges: Mapping[str, Any], leg: str, kind: str) -> tuple[float, float] | None:
    side = "left" if C.LEG_SIGN_Y[leg] > 0 else "right"
    end = "front" if leg[1] == "F" else "hind"
    for key in (f"{kind}_{side}", f"{kind}_{end}", kind):
        if ranges.get(key) is not None:
            return ranges[key]
    return None


def _check_ranges(ranges: Mapping[str, Any], where: str) -> None:
    for key, value in ranges.items():
        if value is not None and not value[0] < value[1]:
            raise ValueError(f"{where}.joint_range.{key} must be [low, high] with low < high (rad), got {value}")


# ---------------------------------------------------------------------- URDF and SRDF through Pinocchio
def _read_urdf(urdf: Path, where: str) -> pin.Model:
    import pinocchio as pin

    try:
        model = pin.buildModelFromUrdf(str(urdf), pin.JointModelFreeFlyer())
    except (RuntimeError, ValueError) as err:
        raise ValueError(f"{where}.urdf: file {str(urdf)!r} cannot be read by Pinocchio: {_first_line(err)}") from None
    if model.nq != C.NQ or model.nv != C.NV:
        raise ValueError(
            f"{where}.urdf: {urdf.name} must have {C.N_JOINTS} actuated joints (nq={C.NQ}, nv={C.NV} with the "
            f"free-flyer root), got nq={model.nq - 7}+7, nv={model.nv - 6}+6"
        )
    return model


def _first_line(err: BaseException) -> str:
    lines = [x.strip() for x in str(err).splitlines() if x.strip()]
    return (lines[0] if lines else type(err).__name__)[:200]


def _revolute_axis(model: pin.Model, jid: int, where: str) -> np.ndarray:
    j = model.joints[jid]
    short = j.shortname()
    canonical = {"JointModelRX": (1.0, 0, 0), "JointModelRY": (0, 1.0, 0), "JointModelRZ": (0, 0, 1.0)}
    if short in canonical:
        return np.array(canonical[short])
    if short == "JointModelRevoluteUnaligned":
        return np.array(j.extract().axis, dtype=float)
    raise ValueError(f"{where} ({model.names[jid]}) must be a revolute joint with limits, got {short}")


def _standing_pose(model, srdf, state: Any, joints: Any, q_index: list[int], where: str) -> np.ndarray:
    if joints is not None:
        if not isinstance(joints, Mapping) or set(joints) != set(C.LEG_NAMES):
            raise ValueError(
                f"{where}.standing_joints must map each of {list(C.LEG_NAMES)} to 3 angles (rad), got {excerpt(joints)}"
            )
        w = f"{where}.standing_joints"
        return np.array([check_vector(joints[leg], _named(_ANGLE, leg), w) for leg in C.LEG_NAMES]).reshape(-1)
    if srdf is None:
        raise ValueError(
            f"{where}: a standing pose is needed: give srdf (with a {excerpt(state)} state) or standing_joints"
        )
    if not isinstance(state, str) or not state:
        raise ValueError(f"{where}.standing_state must be the name of a group state of the SRDF, got {excerpt(state)}")
    import pinocchio as pin

    try:
        pin.loadReferenceConfigurations(model, str(srdf), False)
    except (RuntimeError, ValueError) as err:
        raise ValueError(f"{where}.srdf: file {str(srdf)!r} cannot be read by Pinocchio: {_first_line(err)}") from None
    states = sorted(entry.key() for entry in model.referenceConfigurations)  # a C++ map of named configurations
    if state not in states:
        raise ValueError(
            f"{where}.standing_state {excerpt(state)} is not a group state of {Path(srdf).name}; it has {states}"
        )
    return np.array(model.referenceConfigurations[state], dtype=float)[q_index]


def _named(p: Param, name: str) -> Param:
    return Param(name, p.default, p.unit, p.doc, lo=p.lo, hi=p.hi, lo_open=p.lo_open)


def _trunk_box(model: pin.Model, urdf: Path, where: str) -> tuple[np.ndarray, np.ndarray] | None:
    """The largest collision box moved by the root joint (the root link's, or a link's fixed to it), aligned with
    the trunk frame: (centre, half sizes) m in the trunk frame; None if there is none.

    Pinocchio places the URDF's collision geometry (``buildGeomFromUrdfString``); the other shapes are dropped
    from the text it reads first, so that no mesh file is looked for.
    """
    import pinocchio as pin

    boxes = 0
    try:
        tree = ET.fromstring(urdf.read_text())
        for link in tree.iter("link"):
            for element in [*link.findall("visual"), *link.findall("collision")]:
                if element.tag == "visual" or element.find("geometry/box") is None:
                    link.remove(element)
                else:
                    boxes += 1
        geometry = pin.buildGeomFromUrdfString(model, ET.tostring(tree, encoding="unicode"), pin.GeometryType.COLLISION)
    except (ET.ParseError, RuntimeError, ValueError, OSError, UnicodeDecodeError) as err:
        raise ValueError(
            f"{where}.urdf: the collision boxes of {str(urdf)!r} cannot be read by Pinocchio: {_first_line(err)}"
        ) from None
    if len(geometry.geometryObjects) != boxes:  # urdfdom drops a collision it cannot parse, with a message only
        raise ValueError(
            f"{where}.urdf: {boxes - len(geometry.geometryObjects)} of the {boxes} collision boxes of {str(urdf)!r} "
            'cannot be read by Pinocchio (a box needs size="x y z", m)'
        )
    best = None
    for obj in geometry.geometryObjects:
        placement = obj.placement
        if obj.parentJoint != 1 or np.abs(placement.rotation - np.eye(3)).max() > 1e-9:
            continue
        half = np.array(obj.geometry.halfSide, dtype=float)
        if best is None or np.prod(half) > np.prod(best[1]):
            best = (np.array(placement.translation, dtype=float), half)
    return best
