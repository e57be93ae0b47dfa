"""What a terrain kind provides: its parameters, checks, layout, elevation bounds and generator."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from quad_uneven_env.fields import excerpt
from quad_uneven_env.terrain.grid import Grid, check_grid, check_spawn_inside, shared_grid
from quad_uneven_env.terrain.params import REQUIRED, SHARED_PARAMS, Param

Params = Mapping[str, Any]


def _no_check(p: dict[str, Any], where: str) -> None:
    return None


def _zero_spawn(p: Params) -> float:
    return 0.0


@dataclasses.dataclass(frozen=True)
class TerrainKind:
    """A terrain kind. ``generate(params, grid, rng)`` returns (nrow, ncol) heights (m) within ``z_bounds``."""

    name: str
    """kind name as used in specs."""
    doc: str
    """one-paragraph description (docs/terrain.md)."""
    params: tuple[Param, ...]
    """the kind's own parameters (the shared ones are added unless ``shared`` is False)."""
    generate: Callable[[Params, Grid, np.random.Generator], np.ndarray]
    """heights (m) of every node; deterministic given the rng state."""
    z_bounds: Callable[[Params], tuple[float, float]]
    """(z_min, z_max) (m) every generated surface stays within; from the params alone."""
    check: Callable[[dict[str, Any], str], None] = _no_check
    """cross-parameter checks beyond the per-parameter ranges (ValueError naming the fields); may replace
    values in the dict by normalised ones (e.g. a .npy path by its array)."""
    spawn_height: Callable[[Params], float] = _zero_spawn
    """terrain height (m) of the spawn area."""
    grid: Callable[[Params], Grid] = shared_grid
    """node layout from the params."""
    shared: bool = True
    """True: the kind also takes SHARED_PARAMS."""

    @property
    def all_params(self) -> tuple[Param, ...]:
        """Every parameter the kind accepts, shared ones first."""
        return (SHARED_PARAMS + self.params) if self.shared else self.params

    def validate(self, raw: Params, where: str) -> dict[str, Any]:
        """Checked params with defaults filled; ValueError naming the offending field."""
        allowed = {q.name: q for q in self.all_params}
        unknown = sorted(set(raw) - set(allowed), key=str)
        if unknown:
            raise ValueError(
                f"{where}: unknown parameter(s) {excerpt(unknown)}; allowed for kind {self.name!r}: {list(allowed)}"
            )
        out: dict[str, Any] = {}
        for name, q in allowed.items():
            if name in raw:
                out[name] = q.check(raw[name], where)
            elif q.default is REQUIRED:
                raise ValueError(f"{where}.{name} is required for kind {self.name!r} ({q.allowed()})")
            else:
                out[name] = q.default
        self.check(out, where)
        grid = self.grid(out)
        check_grid(grid, where, "length, width and cell_size" if self.shared else "the heights' shape")
        check_spawn_inside(grid, out, where, "x_start, length, width or spawn_radius" if self.shared else "origin")
        return out
