"""Frozen configuration dataclasses and the one place YAML is read.

The shipped configs live in the repository's ``configs/`` folder, which the wheel installs as the package data
``quad_uneven_env.configs`` (:data:`CONFIG_DIR` is whichever of the two this copy of the package has); a config
is named (``"paper"`` -> ``configs/robot/paper.yaml``) or given as a path.
"""

from __future__ import annotations

import dataclasses
import functools
import importlib.resources
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from quad_uneven_env.fields import Param, check_fields, param


def shipped_config_dir() -> Path:
    """The folder of the shipped YAML configs: ``$QUAD_UNEVEN_CONFIGS`` if set; else, in a source checkout, the
    repository's ``configs/`` beside the packages; else the installed package data ``quad_uneven_env.configs``."""
    explicit = os.environ.get("QUAD_UNEVEN_CONFIGS")
    if explicit:
        return Path(explicit)
    checkout = Path(__file__).resolve().parents[1] / "configs"
    if (checkout / "robot" / "paper.yaml").is_file():
        return checkout
    return Path(str(importlib.resources.files("quad_uneven_env.configs")))


CONFIG_DIR = shipped_config_dir()
"""Directory of the shipped YAML configs (:func:`shipped_config_dir`)."""


@dataclasses.dataclass(frozen=True)
class BodyParams:
    """The trunk: a rigid box with its COM at the geometric centre."""

    mass: float
    """kg"""
    size: tuple[float, float, float]
    """length, width, height (m), along body x, y, z."""
    inertia: tuple[float, float, float]
    """principal inertia about the COM (kg m^2) along body x, y, z."""


@dataclasses.dataclass(frozen=True)
class LinkParams:
    """A leg link (thigh or shank), a rod hanging along -z of its joint frame at zero angles."""

    length: float
    """joint-to-joint (or joint-to-foot) length (m)."""
    mass: float
    """kg"""
    com: float
    """distance from the proximal joint to the COM along the link (m)."""
    inertia: tuple[float, float, float]
    """principal inertia about the COM (kg m^2): about the long axis first, then the two others."""


@dataclasses.dataclass(frozen=True)
class RobotConfig:
    """Paper Table 1 plus the simulation details the paper leaves open."""

    name: str
    """config name."""
    body: BodyParams
    """trunk parameters."""
    thigh: LinkParams
    """upper leg (hip to knee)."""
    shank: LinkParams
    """lower leg (knee to foot point)."""
    foot_radius: float
    """collision sphere radius centred on the foot point (m)."""
    link_radius: float
    """collision capsule radius of the leg links (m); massless."""
    joint_range: Mapping[str, tuple[float, float]]
    """joint ranges (rad) keyed HAA, HFE, KFE_front, KFE_hind."""
    torque_limit: Mapping[str, float]
    """symmetric motor torque limits (N m) keyed HAA, HFE, KFE."""
    joint_damping: float
    """viscous joint damping (N m s / rad)."""
    joint_armature: float
    """rotor inertia reflected through the gearbox, added to each joint's diagonal of M (kg m^2)."""
    friction: float
    """Coulomb friction coefficient between feet and terrain."""

    @property
    def total_mass(self) -> float:
        """Whole-robot mass (kg): trunk plus four legs."""
        return self.body.mass + 4.0 * (self.thigh.mass + self.shank.mass)

    @property
    def leg_length(self) -> float:
        """Thigh plus shank length (m): the stretched-leg reach."""
        return self.thigh.length + self.shank.length

    def knee_range(self, leg: str) -> tuple[float, float]:
        """KFE range (rad) of ``leg`` (front and hind knees bend in opposite directions)."""
        return tuple(self.joint_range["KFE_front" if leg[1] == "F" else "KFE_hind"])  # type: ignore[return-value]


def _positive(value: Any, field: str) -> float:
    return Param(field, None, "", "", lo=0.0, lo_open=True).check(value, "")


def _non_negative(value: Any, field: str) -> float:
    return Param(field, None, "", "", lo=0.0).check(value, "")


def _triple(value: Any, field: str, allow_zero: bool = False) -> tuple[float, float, float]:
    arr = np.asarray(value, dtype=float)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)) or np.any(arr < 0) or (not allow_zero and np.any(arr == 0)):
        need = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"{field} must be 3 finite numbers {need}, got {value!r}")
    return tuple(float(x) for x in arr)  # type: ignore[return-value]


JOINT_RANGE_KEYS = ("HAA", "HFE", "KFE_front", "KFE_hind")
"""Joints of ``robot.joint_range`` (the knee's range differs between front and hind legs)."""

TORQUE_LIMIT_KEYS = ("HAA", "HFE", "KFE")
"""Joints of ``robot.torque_limit``."""


def _range_pair(value: Any, field: str) -> tuple[float, float]:
    """``[low, high]`` as two finite floats (the order is checked by the caller)."""
    try:
        lo, hi = (float(x) for x in value)
    except (TypeError, ValueError):
        raise ValueError(f"{field} must be [low, high] (two numbers, rad), got {value!r}") from None
    if not (np.isfinite(lo) and np.isfinite(hi)):
        raise ValueError(f"{field} must be [low, high] (two finite numbers, rad), got {value!r}")
    return lo, hi


def _require(raw: Mapping[str, Any], keys: set[str], where: str) -> None:
    if not isinstance(raw, Mapping):
        raise ValueError(f"{where} must be a mapping with fields {sorted(keys)}, got {raw!r}")
    missing = keys - set(raw)
    unknown = set(raw) - keys
    if missing:
        raise ValueError(f"{where}: missing field(s) {sorted(missing)}")
    if unknown:
        raise ValueError(f"{where}: unknown field(s) {sorted(unknown)}; allowed: {sorted(keys)}")


def _link(raw: Mapping[str, Any], where: str) -> LinkParams:
    _require(raw, {"length", "mass", "com", "inertia"}, where)
    length = _positive(raw["length"], f"{where}.length")
    com = float(raw["com"])
    if not 0.0 <= com <= length:
        raise ValueError(f"{where}.com must lie in [0, {where}.length={length}], got {com}")
    return LinkParams(
        length, _positive(raw["mass"], f"{where}.mass"), com, _triple(raw["inertia"], f"{where}.inertia", True)
    )


def robot_config_from_dict(raw: Mapping[str, Any]) -> RobotConfig:
    """Validate a raw mapping (as read from YAML) into a :class:`RobotConfig`.

    :raises ValueError: naming the offending field and its allowed values.
    """
    keys = {f.name for f in dataclasses.fields(RobotConfig)}
    _require(raw, keys, "robot")
    body = raw["body"]
    _require(body, {"mass", "size", "inertia"}, "robot.body")
    _require(raw["joint_range"], set(JOINT_RANGE_KEYS), "robot.joint_range")
    _require(raw["torque_limit"], set(TORQUE_LIMIT_KEYS), "robot.torque_limit")
    ranges = {}
    for k in JOINT_RANGE_KEYS:
        lo, hi = _range_pair(raw["joint_range"][k], f"robot.joint_range.{k}")
        if not lo < hi:
            raise ValueError(f"robot.joint_range.{k} must be [low, high] with low < high, got {[lo, hi]}")
        ranges[k] = (lo, hi)
    if ranges["KFE_front"][1] >= 0.0 or ranges["KFE_hind"][0] <= 0.0:
        raise ValueError("robot.joint_range: KFE_front must stay < 0 and KFE_hind > 0 (no stretched knee)")
    limits = {k: _positive(raw["torque_limit"][k], f"robot.torque_limit.{k}") for k in TORQUE_LIMIT_KEYS}
    return RobotConfig(
        name=str(raw["name"]),
        body=BodyParams(
            _positive(body["mass"], "robot.body.mass"),
            _triple(body["size"], "robot.body.size"),
            _triple(body["inertia"], "robot.body.inertia"),
        ),
        thigh=_link(raw["thigh"], "robot.thigh"),
        shank=_link(raw["shank"], "robot.shank"),
        foot_radius=_positive(raw["foot_radius"], "robot.foot_radius"),
        link_radius=_positive(raw["link_radius"], "robot.link_radius"),
        joint_range=ranges,
        torque_limit=limits,
        joint_damping=_non_negative(raw["joint_damping"], "robot.joint_damping"),
        joint_armature=_non_negative(raw["joint_armature"], "robot.joint_armature"),
        friction=_positive(raw["friction"], "robot.friction"),
    )


class DuplicateKeyError(yaml.constructor.ConstructorError):
    """A mapping of a YAML file that gives one key twice (YAML says keys are unique; PyYAML keeps the last)."""


class UniqueKeyLoader(yaml.SafeLoader):
    """PyYAML's safe loader that refuses a mapping giving one key twice, naming the key and both lines."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        """The mapping of ``node``; :raises DuplicateKeyError: on a key given twice (at its second line)."""
        if isinstance(node, yaml.MappingNode):
            seen: dict[Any, int] = {}
            for key_node, _ in node.value:
                if key_node.tag == "tag:yaml.org,2002:merge":  # '<<': merged keys may be overridden
                    continue
                key = self.construct_object(key_node, deep=True)
                try:
                    first = seen.get(key)
                except TypeError:  # an unhashable key: PyYAML's own error below names it
                    continue
                if first is not None:
                    raise DuplicateKeyError(
                        "while constructing a mapping",
                        node.start_mark,
                        f"duplicate key {key!r} (first given at line {first + 1})",
                        key_node.start_mark,
                    )
                seen[key] = key_node.start_mark.line
        return super().construct_mapping(node, deep=deep)


def load_yaml_text(text: str) -> Any:
    """Parse YAML ``text`` safely (no Python objects), refusing duplicate keys (:class:`UniqueKeyLoader`).

    :raises yaml.YAMLError: on invalid YAML or a duplicate key (its ``problem_mark`` gives the line).
    """
    return yaml.load(text, Loader=UniqueKeyLoader)  # a SafeLoader subclass: no Python objects


def read_yaml(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Read one YAML file into a dict (the only YAML reader of the project).

    :raises ValueError: naming the file if it is missing, unreadable, not valid YAML, gives a key twice in one
        mapping (the key and its line are named) or does not hold a mapping at the top level.
    """
    p = Path(path)
    if not p.is_file():
        raise ValueError(f"config file {str(p)!r} does not exist")
    try:
        with p.open() as f:
            data = load_yaml_text(f.read())
    except DuplicateKeyError as err:
        line = err.problem_mark.line + 1
        raise ValueError(f"config file {str(p)!r} gives a key twice at line {line}: {err.problem}") from None
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        problem = getattr(err, "problem", None) or type(err).__name__
        raise ValueError(f"config file {str(p)!r} is not valid YAML{where}: {problem}") from None
    except (OSError, UnicodeDecodeError) as err:
        raise ValueError(f"config file {str(p)!r} cannot be read: {err}") from None
    if not isinstance(data, dict):
        raise ValueError(f"config file {str(p)!r} must hold a mapping at the top level")
    return data


def resolve_config_path(name_or_path: str | os.PathLike[str], group: str) -> Path:
    """Path of a named config in ``CONFIG_DIR/group`` or of a given YAML path."""
    p = Path(name_or_path)
    if p.suffix in (".yaml", ".yml"):
        return p
    candidate = CONFIG_DIR / group / f"{name_or_path}.yaml"
    if not candidate.is_file():
        names = sorted(x.stem for x in (CONFIG_DIR / group).glob("*.yaml"))
        raise ValueError(f"unknown {group} config {str(name_or_path)!r}; shipped: {names} (or give a .yaml path)")
    return candidate


def load_robot_config(name_or_path: str | os.PathLike[str] = "paper") -> RobotConfig:
    """Load a robot config by name (``configs/robot/NAME.yaml``) or path (cached: planners ask often)."""
    return _load_robot_config(str(name_or_path))


@functools.lru_cache(maxsize=16)
def _load_robot_config(name_or_path: str) -> RobotConfig:
    return robot_config_from_dict(read_yaml(resolve_config_path(name_or_path, "robot")))


@dataclasses.dataclass(frozen=True)
class RewardWeights:
    """Weights of the named reward terms (see :mod:`quad_uneven_env.rewards`); any finite number unless noted."""

    forward_progress: float = param(1.0, "1/(m/s)")
    """per m/s of whole-robot COG velocity along +x."""
    stability: float = param(0.5)
    """per unit of the normalised stability index / ``stability_scale``, clipped to [-1, 1]."""
    stability_scale: float = param(0.1, "m", lo=0.0, hi=1.0, lo_open=True)
    """m, in (0, 1]: normalised index that earns the full stability term."""
    torque: float = param(0.05)
    """per mean squared torque fraction (tau / limit)^2 over the 12 joints."""
    energy: float = param(0.0)
    """per W of absolute mechanical power sum |tau qd|, divided by m g (dimension m/s)."""
    alive: float = param(0.5)
    """per control step not ended by a fall."""
    fall: float = param(10.0)
    """penalty on the step that ends in a fall or divergence."""
    command_tracking_lin: float = param(0.0)
    """per unit of exp(-|v_xy - v_cmd|^2 / command_sigma_lin^2) (needs a ``command``; 0: no tracking term)."""
    command_tracking_yaw: float = param(0.0)
    """per unit of exp(-(yaw_rate - yaw_rate_cmd)^2 / command_sigma_yaw^2) (needs a ``command``)."""
    command_sigma_lin: float = param(0.1, "m/s", lo=0.0, hi=10.0, lo_open=True)
    """m/s, in (0, 10]: velocity error at which ``command_tracking_lin`` has fallen to 1/e of its weight."""
    command_sigma_yaw: float = param(0.2, "rad/s", lo=0.0, hi=10.0, lo_open=True)
    """rad/s, in (0, 10]: yaw-rate error at which ``command_tracking_yaw`` has fallen to 1/e of its weight."""

    def __post_init__(self) -> None:
        check_fields(self)


@dataclasses.dataclass(frozen=True)
class TerminationLimits:
    """When an episode ends in a fall."""

    min_base_height: float = param(0.12, "m", lo=0.0, hi=2.0)
    """m, in [0, 2]: trunk origin above the terrain under it."""
    max_base_height: float = param(1.0, "m", lo=0.0, hi=10.0, lo_open=True)
    """m, in (0, 10], above ``min_base_height``: trunk origin above the terrain under it (a jump or a launch)."""
    max_tilt_deg: float = param(60.0, "deg", lo=0.0, hi=180.0, lo_open=True)
    """degrees in (0, 180] between the trunk z axis and the world z axis (180: never)."""
    trunk_contact: bool = param(True, kind="bool")
    """the trunk touching the terrain ends the episode."""

    def __post_init__(self) -> None:
        check_fields(self)
        if not self.min_base_height < self.max_base_height:
            raise ValueError(
                f"TerminationLimits.min_base_height must be < max_base_height={self.max_base_height}, "
                f"got {self.min_base_height}"
            )


MAX_SCAN_POINTS = 10_000
"""Upper bound on the height-scan grid size (points): the observation grows with it."""


@dataclasses.dataclass(frozen=True)
class HeightScanConfig:
    """Grid of terrain heights around the base, in the yaw-aligned base frame."""

    size_x: float = param(1.0, "m", lo=0.0, hi=10.0)
    """m, in [0, 10]: extent along the heading (centred on the base)."""
    size_y: float = param(0.6, "m", lo=0.0, hi=10.0)
    """m, in [0, 10]: extent across the heading."""
    resolution: float = param(0.1, "m", lo=0.005, hi=1.0)
    """m, in [0.005, 1]: grid spacing."""

    def __post_init__(self) -> None:
        check_fields(self)
        nx, ny = self.shape
        if nx * ny > MAX_SCAN_POINTS:
            raise ValueError(
                f"HeightScanConfig.resolution must give at most {MAX_SCAN_POINTS} points, got {nx} x {ny} "
                f"for size {self.size_x} x {self.size_y} m at {self.resolution} m"
            )

    @property
    def shape(self) -> tuple[int, int]:
        """(nx, ny) points of the grid."""
        return (round(self.size_x / self.resolution) + 1, round(self.size_y / self.resolution) + 1)
