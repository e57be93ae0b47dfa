"""The one set of field validators: a declaration per field gives its check, its error message and its docs row.

:class:`Param` declares a field (default, unit, allowed range or choices, meaning); every config of the
project is validated through it, so every bad value raises the same ``ValueError``:
``where.field must be <allowed> (<unit>), got <value>``.

- terrain kinds list their parameters as ``Param`` objects (:mod:`quad_uneven_env.terrain.params`);
- frozen config dataclasses declare fields with :func:`param` and call :func:`check_fields` in
  ``__post_init__``; :func:`from_mapping` builds one from a user's mapping, rejecting unknown keys;
- :func:`excerpt` is how every error message of the project shows a value the user gave: a short, one-line
  excerpt, whatever the value's size.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
import re
import reprlib
from collections.abc import Mapping
from typing import Any, TypeVar

import numpy as np

REQUIRED = object()
"""Sentinel default of a parameter the user must give."""

EXCERPT_CHARS = 120
"""Longest text :func:`excerpt` returns (characters)."""

_EXCERPT = reprlib.Repr()
_EXCERPT.maxlevel = 3
_EXCERPT.maxlist = _EXCERPT.maxtuple = _EXCERPT.maxset = _EXCERPT.maxfrozenset = _EXCERPT.maxdict = 6
_EXCERPT.maxdeque = _EXCERPT.maxarray = 6
_EXCERPT.maxstring = _EXCERPT.maxother = 80
_EXCERPT.maxlong = 40


def excerpt(value: Any, limit: int = EXCERPT_CHARS) -> str:
    """The repr of ``value`` cut to at most ``limit`` characters on one line, for an error message.

    Containers show their first items and nest at most 3 deep (:mod:`reprlib`), so the cost is bounded too:
    a value a user file or argument gives (a list of 10^9 items, a 1 MB string) is never repr'd in full.
    Short values read as ``repr`` gives them (``0.5``, ``'abc'``, ``[1, 2]``).
    """
    if isinstance(value, np.ndarray) and value.size > _EXCERPT.maxlist:  # numpy's summary: first and last items
        with np.printoptions(threshold=_EXCERPT.maxlist, edgeitems=2):
            text = repr(value)
    elif isinstance(value, np.ndarray):
        text = _EXCERPT.repr(value.tolist())
    else:
        text = _EXCERPT.repr(value)
    return clip(text, limit)


def clip(text: str, limit: int = EXCERPT_CHARS) -> str:
    """``text`` on one line (line breaks and the blanks around them become one space), cut to at most ``limit``
    characters (the cut marked by ``...``): a message of a library that may quote the user's input."""
    text = re.sub(r"\s*\n\s*", " ", text[: 4 * limit])
    return text if len(text) <= limit else text[: limit - 3] + "..."


@dataclasses.dataclass(frozen=True)
class Param:
    """One validated field: terrain parameter or config dataclass field.

    ``kind`` is ``"float"``, ``"int"``, ``"bool"``, ``"choice"`` (one of ``choices``), ``"xy"`` (a
    finite (x, y) pair or None), ``"range"`` (a ``[low, high]`` pair with low <= high, both within
    ``lo``/``hi``, or None) or ``"array"`` (validated by its owner).
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
    none_ok: bool = False
    """None is allowed too (meaning "not set"; the owner documents what that means)."""

    def allowed(self) -> str:
        """Human-readable allowed values, e.g. ``"number in (0, 30]"`` or ``"one of ['up', 'down']"``."""
        if self.none_ok:
            return dataclasses.replace(self, none_ok=False).allowed() + " or null"
        if self.kind == "choice":
            return f"one of {list(self.choices)}"
        if self.kind == "xy":
            return "a finite (x, y) pair or null"
        if self.kind == "array":
            return "a 2-D array or the path of a .npy file"
        if self.kind == "bool":
            return "true or false"
        if self.kind == "range":
            return f"null or a [low, high] pair with low <= high, each a number in {self._interval()}"
        return f"{'integer' if self.kind == 'int' else 'number'} in {self._interval()}"

    def _interval(self) -> str:
        """The allowed interval of a number, e.g. ``(0, 30]``."""
        lo = "-inf" if self.lo is None else f"{self.lo:g}"
        hi = "inf" if self.hi is None else f"{self.hi:g}"
        left = "(" if self.lo_open or self.lo is None else "["
        right = ")" if self.hi_open or self.hi is None else "]"
        return f"{left}{lo}, {hi}{right}"

    def check(self, value: Any, where: str) -> Any:
        """Validated, normalised ``value`` (float, int, bool, str or tuple); ValueError naming ``where.name``.

        Booleans are not numbers, and a number must be finite and in range before anything else uses it.
        """
        field = f"{where}.{self.name}" if where else self.name
        if value is None and self.none_ok:
            return None
        if self.kind == "bool":
            if not isinstance(value, bool | np.bool_):
                raise ValueError(
                    f"{field} must be {self.allowed()}, got {excerpt(value)} of type {type(value).__name__}"
                )
            return bool(value)
        if self.kind == "choice":
            if not isinstance(value, str) or value not in self.choices:
                raise ValueError(f"{field} must be {self.allowed()}, got {excerpt(value)}")
            return value
        if self.kind == "xy":
            if value is None:
                return None
            try:
                pair = tuple(float(v) for v in value)
            except (TypeError, ValueError):
                pair = ()
            if len(pair) != 2 or not all(math.isfinite(v) for v in pair):
                raise ValueError(f"{field} must be {self.allowed()} (m), got {excerpt(value)}")
            return pair
        if self.kind == "range":
            return self._check_range(value, field)
        if self.kind == "array":
            return value
        if isinstance(value, bool) or not isinstance(value, numbers.Real):
            raise ValueError(
                f"{field} must be {self._a()}{self._unit()}, got {excerpt(value)} of type {type(value).__name__}"
            )
        v = float(value)
        if self.kind == "int":
            if not math.isfinite(v) or v != int(v):
                raise ValueError(f"{field} must be an {self.allowed()}, got {excerpt(value)}")
            v = int(v)
        if not math.isfinite(v) or not self._in_range(v):
            raise ValueError(f"{field} must be {self._a()}{self._unit()}, got {excerpt(value)}")
        return v

    def _check_range(self, value: Any, field: str) -> tuple[float, float] | None:
        if value is None:
            return None
        bad = ValueError(f"{field} must be {self.allowed()}{self._unit()}, got {excerpt(value)}")
        if isinstance(value, str | bytes | Mapping) or not hasattr(value, "__len__") or len(value) != 2:
            raise bad
        if any(isinstance(v, bool) or not isinstance(v, numbers.Real) for v in value):
            raise bad
        low, high = float(value[0]), float(value[1])
        if not (math.isfinite(low) and math.isfinite(high)) or low > high:
            raise bad
        if not (self._in_range(low) and self._in_range(high)):
            raise bad
        return (low, high)

    def _a(self) -> str:
        text = self.allowed()
        return f"an {text}" if text[0] in "aeiou" else f"a {text}"

    def _unit(self) -> str:
        return "" if self.unit in ("", "-") else f" ({self.unit})"

    def _in_range(self, v: float) -> bool:
        if self.lo is not None and (v < self.lo or (self.lo_open and v == self.lo)):
            return False
        return not (self.hi is not None and (v > self.hi or (self.hi_open and v == self.hi)))


_META = "quad_uneven_param"
T = TypeVar("T")


def param(default: Any, unit: str = "-", doc: str = "", **check: Any) -> Any:
    """A dataclass field with default ``default`` whose value is checked by a :class:`Param`.

    :param check: ``kind``, ``lo``, ``hi``, ``lo_open``, ``hi_open``, ``choices`` of :class:`Param`.
    """
    return dataclasses.field(default=default, metadata={_META: Param("", default, unit, doc, **check)})


def params_of(cls: type) -> tuple[Param, ...]:
    """The :class:`Param` of every field of dataclass ``cls`` declared with :func:`param`, named."""
    return tuple(
        dataclasses.replace(f.metadata[_META], name=f.name) for f in dataclasses.fields(cls) if _META in f.metadata
    )


def check_fields(obj: Any, where: str | None = None) -> None:
    """Check (and normalise in place: ints to floats, numpy bools to bools) every :func:`param` field of ``obj``.

    :param where: prefix of the error messages (default: the class name).
    :raises ValueError: ``where.field must be <allowed>, got <value>``.
    """
    where = type(obj).__name__ if where is None else where
    for p in params_of(type(obj)):
        object.__setattr__(obj, p.name, p.check(getattr(obj, p.name), where))


def from_mapping(cls: type[T], raw: Mapping[str, Any] | T | None, where: str) -> T:
    """An instance of the frozen config dataclass ``cls`` from ``raw`` (None: the defaults; an instance: itself).

    :raises ValueError: on a non-mapping, an unknown key (listing the allowed ones) or a bad value,
        each message starting with ``where``.
    """
    if raw is None:
        return cls()
    if isinstance(raw, cls):
        return raw
    names = [f.name for f in dataclasses.fields(cls)]  # type: ignore[arg-type]
    if not isinstance(raw, Mapping):
        raise ValueError(f"{where} must be a mapping with keys from {sorted(names)}, got {excerpt(raw)}")
    unknown = sorted((k for k in raw if k not in names), key=str)
    if unknown:
        raise ValueError(f"{where}: unknown field(s) {excerpt(unknown)}; allowed: {sorted(names)}")
    checks = {p.name: p for p in params_of(cls)}
    values = {k: checks[k].check(v, where) if k in checks else v for k, v in raw.items()}
    try:
        return cls(**values)
    except ValueError as err:  # cross-field checks of __post_init__ name the class: name ``where`` instead
        raise ValueError(str(err).replace(f"{cls.__name__}.", f"{where}.", 1)) from None


def check_mapping(raw: Any, params: tuple[Param, ...], where: str) -> dict[str, Any]:
    """``raw`` (a user's mapping) checked against ``params``: no unknown key, every ``REQUIRED`` one given, each
    value checked by its :class:`Param`, the defaults of the others filled in.

    :raises ValueError: ``where must be a mapping ...``, ``where: unknown field(s) ...``, ``where.field is
        required (<allowed>)`` or the field's own message.
    """
    allowed = {p.name: p for p in params}
    if not isinstance(raw, Mapping):
        raise ValueError(f"{where} must be a mapping with keys from {sorted(allowed)}, got {excerpt(raw)}")
    unknown = sorted((k for k in raw if k not in allowed), key=str)
    if unknown:
        raise ValueError(f"{where}: unknown field(s) {excerpt(unknown)}; allowed: {sorted(allowed)}")
    out: dict[str, Any] = {}
    for name, p in allowed.items():
        if name in raw:
            out[name] = p.check(raw[name], where)
        elif p.default is REQUIRED:
            raise ValueError(f"{where}.{name} is required ({p.allowed()})")
        else:
            out[name] = p.default
    return out


def check_vector(value: Any, p: Param, where: str, n: int = 3) -> tuple[float, ...]:
    """``n`` numbers, each checked by ``p`` (as ``where.name[i]``).

    :raises ValueError: ``where.name must be n numbers ...`` or the element's own message.
    """
    field = f"{where}.{p.name}" if where else p.name
    if isinstance(value, str | bytes | Mapping) or not hasattr(value, "__len__") or len(value) != n:
        raise ValueError(f"{field} must be {n} numbers, each {p._a()}{p._unit()}, got {excerpt(value)}")
    return tuple(dataclasses.replace(p, name=f"{p.name}[{i}]").check(v, where) for i, v in enumerate(value))
