"""Where an episode ran: the CPU and the versions of the numerical libraries, recorded with every episode.

A legged robot near a fall is chaotic, and floating-point results differ between CPUs (MuJoCo's and BLAS's SIMD
code paths) and library versions: the same episode (terrain, seed, drawn world) can end differently on another
machine. Paired comparisons are exact only between runs made on one machine kind with one set of libraries;
:func:`agents.evaluation.compare.compare_runs` says when two runs were not.
"""

from __future__ import annotations

import functools
import importlib.metadata
import platform
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

__all__ = ["PACKAGES", "SIMD_FLAGS", "distinct_machines", "machine_info", "machines_differ"]

PACKAGES = ("numpy", "scipy", "mujoco", "pin", "numba", "daqp", "gymnasium", "torch", "stable-baselines3")
"""Distributions whose versions are recorded (``"absent"`` if not installed)."""

SIMD_FLAGS = ("avx512f", "avx2", "fma", "avx", "sse4_2", "neon", "asimd")
"""CPU flags recorded (those present): the vector instruction sets numerical libraries dispatch on."""


def _cpu() -> tuple[str, str]:
    """(CPU model name, its :data:`SIMD_FLAGS` present, space-separated) from /proc/cpuinfo where it exists."""
    model, flags = platform.processor() or "unknown", set()
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        text = ""
    for line in text.splitlines():
        key, _, value = line.partition(":")
        key = key.strip()
        if key == "model name" and model in ("unknown", "", platform.machine()):
            model = value.strip()
        elif key in ("flags", "Features") and not flags:
            flags = set(value.split())
    return model, " ".join(f for f in SIMD_FLAGS if f in flags)


def _version(name: str) -> str:
    try:
        return importlib.metadata.version(name)
    except importlib.metadata.PackageNotFoundError:
        return "absent"


def machine_info() -> dict[str, str]:
    """This process's machine: ``python``, ``arch``, ``cpu`` (model name), ``simd`` (flags present) and the version of
    every :data:`PACKAGES` distribution (a new dict each call; computed once per process)."""
    return dict(_machine_info())


@functools.cache
def _machine_info() -> dict[str, str]:
    cpu, simd = _cpu()
    return {
        "python": platform.python_version(),
        "arch": platform.machine(),
        "cpu": cpu,
        "simd": simd,
        **{name: _version(name) for name in PACKAGES},
    }


def distinct_machines(records: Iterable[Mapping[str, Any]]) -> list[dict[str, str]]:
    """The different ``machine`` entries of episode records, in order of first appearance (records without one,
    written before it was recorded, are left out)."""
    seen: list[dict[str, str]] = []
    for r in records:
        m = r.get("machine")
        if m is not None and dict(m) not in seen:
            seen.append(dict(m))
    return seen


def machines_differ(a: Iterable[Mapping[str, Any]], b: Iterable[Mapping[str, Any]]) -> list[str] | None:
    """The fields in which the machines of two sets of episode records differ; ``[]`` if all ran on one machine
    kind; None if either set has no record of its machine."""
    ma, mb = distinct_machines(a), distinct_machines(b)
    if not ma or not mb:
        return None
    every = ma + mb
    keys = sorted({k for m in every for k in m})
    return [k for k in keys if len({m.get(k) for m in every}) > 1]
