"""Declarative terrain parameters: name, default, unit, allowed range, meaning, and their checks.

Every terrain kind lists its parameters as :class:`Param` objects; validation, the error
messages and the parameter tables of ``docs/terrain.md`` all come from these declarations.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from typing import Any

REQUIRED = object()
"""Sentinel default of a parameter the user must give."""


@dataclasses.dataclass(frozen=True)
class Param:
    """One terrain parameter.

    ``kind`` is ``"float"``, ``"int"``, ``"choice"`` (one of ``choices``), ``"xy"`` (a finite
    (x, y) pair or None) or ``"array"`` (validated by the terrain kind itself).
    """

    name: str
    """parameter name (key in the spec's params)."""
    default: Any
    """default value, or ``REQUIRED``."""
    unit: str
    """unit as printed in the docs ("m", "deg", "-")."""
    doc: str
    """one-line meaning."""
    kind: str = "float"
    """value type, see the class docstring."""
    lo: float | None = None
    """lower bound (None: unbounded)."""
    hi: float | None = None
    """upper bound (None: unbounded)."""
    lo_open: bool = False
    """True: the lower bound is excluded."""
    hi_open: bool = False
    """True: the upper bound is excluded."""
    choices: tuple[str, ...] = ()
    """allowed values of a ``"choice"`` parameter."""

    def allowed(self) -> str:
        """Human-readable allowed values, e.g. ``"(0, 30]"`` or ``"one of ['up', 'down']"``."""
        if self.kind == "choice":
            return f"one of {list(self.choices)}"
        if self.kind == "xy":
            return "a finite (x, y) pair or null"
        if self.kind == "array":
            return "a 2-D array or the path of a .npy file"
        lo = "-inf" if self.lo is None else f"{self.lo:g}"
        hi = "inf" if self.hi is None else f"{self.hi:g}"
        left = "(" if self.lo_open or self.lo is None else "["
        right = ")" if self.hi_open or self.hi is None else "]"
        kind = "integer" if self.kind == "int" else "number"
        return f"{kind} in {left}{lo}, {hi}{right}"

    def check(self, value: Any, where: str) -> Any:
        """Validated, normalised ``value`` (float, int, str or tuple); ValueError naming ``where.name``."""
        field = f"{where}.{self.name}"
        if self.kind == "choice":
            if not isinstance(value, str) or value not in self.choices:
                raise ValueError(f"{field} must be {self.allowed()}, got {value!r}")
            return value
        if self.kind == "xy":
            if value is None:
                return None
            try:
                pair = tuple(float(v) for v in value)
            except (TypeError, ValueError):
                pair = ()
            if len(pair) != 2 or not all(math.isfinite(v) for v in pair):
                raise ValueError(f"{field} must be {self.allowed()} (m), got {value!r}")
            return pair
        if self.kind == "array":
            return value
        if isinstance(value, bool) or not isinstance(value, numbers.Real):
            raise ValueError(
                f"{field} must be a {self.allowed()} ({self.unit}), got {value!r} of type {type(value).__name__}"
            )
        v = float(value)
        if self.kind == "int":
            if not math.isfinite(v) or v != int(v):
                raise ValueError(f"{field} must be an {self.allowed()}, got {value!r}")
            v = int(v)
        if not math.isfinite(v) or not self._in_range(v):
            raise ValueError(f"{field} must be a {self.allowed()} ({self.unit}), got {value!r}")
        return v

    def _in_range(self, v: float) -> bool:
        if self.lo is not None and (v < self.lo or (self.lo_open and v == self.lo)):
            return False
        return not (self.hi is not None and (v > self.hi or (self.hi_open and v == self.hi)))


SHARED_PARAMS: tuple[Param, ...] = (
    Param("length", 8.0, "m", "x extent of the grid", lo=0.0, hi=500.0, lo_open=True),
    Param("width", 3.0, "m", "y extent of the grid (centred on y = 0)", lo=0.0, hi=500.0, lo_open=True),
    Param("cell_size", 0.02, "m", "node spacing along x and y", lo=0.005, hi=0.5),
    Param("x_start", -1.5, "m", "world x of the grid's -x edge", lo=-500.0, hi=500.0),
    Param("spawn_radius", 0.6, "m", "radius of the flat area around spawn_xy = (0, 0)", lo=0.0, hi=50.0),
)
"""Parameters every kind except ``heightmap`` takes (heightmap takes cell_size, x_start, spawn_radius)."""
