"""Frozen configuration dataclasses and the one place YAML is read.

The shipped configs live in the repository's ``configs/`` folder, which the wheel installs as the package data
``quad_uneven_env.configs`` (:data:`CONFIG_DIR` is whichever of the two this copy of the package has); a config
is named (``"paper"`` -> ``configs/robot/paper.yaml``) or given as a path.
"""

from __future__ import annotations

import dataclasses
import importlib.resources
import os
from pathlib import Path
from typing import Any

import yaml

from quad_uneven_env.fields import check_fields, clip, excerpt, param


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


MAX_YAML_BYTES = 16 * 2**20
"""Largest YAML file :func:`read_yaml` reads (bytes): a config is a few kB; large arrays go in .npy files."""

MAX_YAML_DEPTH = 64
"""Deepest nesting of sequences and mappings a YAML document may have (levels)."""

MAX_ALIAS_VALUES = 10_000
"""Most values the aliases (``*name``, ``<<: *name``) of one YAML document may repeat in all: each alias counts
the values of its anchor, aliases inside it included, so a few hundred bytes of nested aliases cannot stand for
billions of values."""


class DuplicateKeyError(yaml.constructor.ConstructorError):
    """A mapping of a YAML file that gives one key twice (YAML says keys are unique; PyYAML keeps the last)."""


class YamlLimitError(yaml.composer.ComposerError):
    """A YAML document beyond this reader's bounds: nested too deep, an alias inside its own anchor, or aliases
    repeating more than :data:`MAX_ALIAS_VALUES` values."""


def _node_count(node: yaml.Node, counts: dict[int, int]) -> int:
    """Values of the complete ``node`` with its aliases expanded (``counts`` memoises them by node id)."""
    key = id(node)
    if key not in counts:
        if isinstance(node, yaml.SequenceNode):
            counts[key] = 1 + sum(_node_count(child, counts) for child in node.value)
        elif isinstance(node, yaml.MappingNode):
            counts[key] = 1 + sum(_node_count(k, counts) + _node_count(v, counts) for k, v in node.value)
        else:
            counts[key] = 1
    return counts[key]


class UniqueKeyLoader(yaml.SafeLoader):
    """PyYAML's safe loader that refuses a mapping giving one key twice, naming the key and both lines, and a
    document nested deeper than :data:`MAX_YAML_DEPTH`, whose aliases repeat more than :data:`MAX_ALIAS_VALUES`
    values, or with an alias inside its own anchor (a value containing itself)."""

    def __init__(self, stream: Any) -> None:
        super().__init__(stream)
        self._depth = 0
        self._open_anchors: set[str] = set()
        self._counts: dict[int, int] = {}
        self._repeated = 0

    def compose_node(self, parent: yaml.Node | None, index: Any) -> yaml.Node:
        """The node at the parser's position, within the bounds above; :raises YamlLimitError: beyond them."""
        event = self.peek_event()
        if isinstance(event, yaml.AliasEvent):
            if event.anchor in self._open_anchors:
                problem = f"the alias *{clip(event.anchor, 40)} lies inside its own anchor (a value containing itself)"
                raise YamlLimitError(None, None, problem, event.start_mark)
            target = self.anchors.get(event.anchor)
            if target is not None:  # else PyYAML's own error names the undefined alias
                self._repeated += _node_count(target, self._counts)
                if self._repeated > MAX_ALIAS_VALUES:
                    problem = (
                        f"its aliases repeat more than {MAX_ALIAS_VALUES} values (here *{clip(event.anchor, 40)}); "
                        "write the values out"
                    )
                    raise YamlLimitError(None, None, problem, event.start_mark)
            return super().compose_node(parent, index)
        if self._depth >= MAX_YAML_DEPTH:
            raise YamlLimitError(None, None, f"values nest deeper than {MAX_YAML_DEPTH} levels", event.start_mark)
        anchor = getattr(event, "anchor", None)
        if anchor is not None:
            self._open_anchors.add(anchor)
        self._depth += 1
        try:
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1
            self._open_anchors.discard(anchor)

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
                        f"duplicate key {excerpt(key)} (first given at line {first + 1})",
                        key_node.start_mark,
                    )
                seen[key] = key_node.start_mark.line
        return super().construct_mapping(node, deep=deep)


def load_yaml_text(text: str) -> Any:
    """Parse YAML ``text`` safely (no Python objects), refusing duplicate keys and unbounded documents
    (:class:`UniqueKeyLoader`).

    :raises yaml.YAMLError: on invalid YAML, a duplicate key or a document beyond the reader's bounds
        (:class:`YamlLimitError`); its ``problem_mark`` gives the line.
    """
    return yaml.load(text, Loader=UniqueKeyLoader)  # a SafeLoader subclass: no Python objects


def read_yaml(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Read one YAML file into a dict (the only YAML reader of the project).

    :raises ValueError: naming the file if it is missing, unreadable, larger than :data:`MAX_YAML_BYTES`, not
        valid YAML, gives a key twice in one mapping (the key and its line are named), nests deeper than
        :data:`MAX_YAML_DEPTH`, has aliases that repeat more than :data:`MAX_ALIAS_VALUES` values or refer to
        a value containing them, or does not hold a mapping at the top level.
    """
    p = Path(path)
    if not p.is_file():
        raise ValueError(f"config file {str(p)!r} does not exist")
    try:
        with p.open("rb") as f:
            raw = f.read(MAX_YAML_BYTES + 1)
        if len(raw) > MAX_YAML_BYTES:
            raise ValueError(
                f"config file {str(p)!r} is larger than {MAX_YAML_BYTES // 2**20} MB (give large arrays as .npy files)"
            )
        data = load_yaml_text(raw.decode("utf-8"))
    except DuplicateKeyError as err:
        line = err.problem_mark.line + 1
        raise ValueError(f"config file {str(p)!r} gives a key twice at line {line}: {err.problem}") from None
    except YamlLimitError as err:
        line = err.problem_mark.line + 1
        raise ValueError(f"config file {str(p)!r} is refused at line {line}: {err.problem}") from None
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        problem = clip(getattr(err, "problem", None) or type(err).__name__)
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
