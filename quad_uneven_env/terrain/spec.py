"""Terrain specs: a kind name plus validated parameters, parsed from strings, mappings or YAML presets.

Accepted forms (``parse_terrain_spec``):

- ``None`` -> the default kind ``"rough"`` with default parameters;
- a kind name (``"stairs"``), a preset name in ``configs/terrain/`` (``"stairs_up"``) or a YAML path;
- a mapping ``{"kind": "rough", "amplitude": 0.05}`` or the suite-file form
  ``{"kind": "rough", "params": {"amplitude": 0.05}}`` (both may be mixed, a key only once);
- a :class:`TerrainSpec` (returned as is).
"""

from __future__ import annotations

import dataclasses
import os
import types
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from quad_uneven_env.config import CONFIG_DIR, read_yaml
from quad_uneven_env.fields import excerpt
from quad_uneven_env.terrain.kinds import KINDS

TERRAIN_KINDS: tuple[str, ...] = tuple(KINDS)
"""Every terrain kind name: flat, rough, slope, stairs, stepping_stones, paper, heightmap."""

DEFAULT_KIND = "rough"
"""Kind used when no spec is given."""

PRESET_DIR = CONFIG_DIR / "terrain"
"""Directory of the named terrain presets (``configs/terrain/NAME.yaml``)."""


@dataclasses.dataclass(frozen=True, eq=False)
class TerrainSpec:
    """A terrain kind and its parameters, validated with defaults filled (on construction).

    :param kind: one of ``TERRAIN_KINDS``.
    :param params: parameter values by name (see docs/terrain.md); missing ones take their defaults.
    :raises ValueError: naming the offending field and its allowed values.
    """

    kind: str
    """terrain kind, one of TERRAIN_KINDS."""
    params: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    """validated parameters (read-only mapping), every parameter of the kind present."""

    def __post_init__(self) -> None:
        if not isinstance(self.kind, str) or self.kind not in KINDS:
            raise ValueError(f"terrain.kind must be one of {list(TERRAIN_KINDS)}, got {excerpt(self.kind)}")
        if not isinstance(self.params, Mapping):
            raise ValueError(
                f"terrain.params must be a mapping of parameter names to values, got {excerpt(self.params)}"
            )
        checked = KINDS[self.kind].validate(dict(self.params), f"terrain[{self.kind}]")
        object.__setattr__(self, "params", types.MappingProxyType(checked))

    def __reduce__(self) -> tuple[Any, ...]:
        """Pickled and copied as its kind and a plain dict of its parameters (a read-only mapping does not pickle)."""
        return (TerrainSpec, (self.kind, dict(self.params)))

    def to_dict(self) -> dict[str, Any]:
        """``{"kind": ..., "params": {...}}`` (the suite-file form; arrays stay numpy arrays)."""
        return {"kind": self.kind, "params": dict(self.params)}

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, TerrainSpec):
            return NotImplemented
        if self.kind != other.kind or set(self.params) != set(other.params):
            return False
        return all(_same(self.params[k], other.params[k]) for k in self.params)

    __hash__ = None  # type: ignore[assignment]  # params may hold arrays


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return bool(np.array_equal(np.asarray(a), np.asarray(b)))
    return a == b


def preset_names() -> list[str]:
    """Names of the shipped presets in ``configs/terrain/``."""
    return sorted(p.stem for p in PRESET_DIR.glob("*.yaml"))


def _from_mapping(raw: Mapping[str, Any]) -> TerrainSpec:
    raw = dict(raw)
    if "kind" not in raw:
        raise ValueError(f"terrain.kind is required, one of {list(TERRAIN_KINDS)}; got keys {sorted(raw)}")
    kind = raw.pop("kind")
    nested = raw.pop("params", None)
    if nested is None:
        nested = {}
    if not isinstance(nested, Mapping):
        raise ValueError(f"terrain.params must be a mapping of parameter names to values, got {excerpt(nested)}")
    twice = sorted(set(nested) & set(raw))
    if twice:
        raise ValueError(f"terrain: parameter(s) {twice} given both at the top level and under 'params'")
    return TerrainSpec(kind, {**raw, **nested})


def parse_terrain_spec(spec: str | os.PathLike[str] | Mapping[str, Any] | TerrainSpec | None) -> TerrainSpec:
    """Validated :class:`TerrainSpec` from any accepted form (see the module docstring).

    :raises ValueError: on an unknown kind, preset or parameter, or a value out of range (naming the field).
    """
    if spec is None:
        return TerrainSpec(DEFAULT_KIND, {})
    if isinstance(spec, TerrainSpec):
        return spec
    if isinstance(spec, Mapping):
        return _from_mapping(spec)
    if isinstance(spec, (str, os.PathLike)):
        text = os.fspath(spec)
        if text in KINDS:
            return TerrainSpec(text, {})
        path = Path(text)
        if path.suffix not in (".yaml", ".yml"):
            path = PRESET_DIR / f"{text}.yaml"
        if not path.is_file():
            raise ValueError(
                f"terrain spec {excerpt(text)} is neither a kind {list(TERRAIN_KINDS)}, nor a preset {preset_names()} "
                "in configs/terrain/, nor an existing .yaml file"
            )
        return _from_mapping(read_yaml(path))
    raise ValueError(
        f"terrain spec must be None, a kind name, a preset name or path, a mapping or a TerrainSpec; "
        f"got {type(spec).__name__}"
    )
