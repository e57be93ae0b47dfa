"""The paper's walk gait (§4, §6): seven phases per cycle, lifting order RH, RF, LH, LF (or its mirror image).

A cycle is: four-leg support, RH swing, RF swing, short four-leg support, LH swing, LF swing,
four-leg support. Phase durations are configurable (paper: 1, 1, 1, 0.1, 1, 1, 1 s). Cycles
repeat for continuous walking: the final four-leg support of one cycle is the start of the next
(the next cycle's first phase may be given a short duration). The mirrored order LH, LF, RH, RF
(``"left_first"``) is the same gait seen in a mirror: what the paper's order does when the body moves to the
right, the mirrored one does when it moves to the left (side steps to the left need it: with the right legs
moved first towards the body, no stable COG path is left for the left legs' swings).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from quad_uneven_env.constants import LEG_NAMES
from quad_uneven_env.fields import excerpt

SWING_ORDER: tuple[str | None, ...] = (None, "RH", "RF", None, "LH", "LF", None)
"""Swing leg of each of the seven phases (None: four-leg support)."""

MIRRORED_SWING_ORDER: tuple[str | None, ...] = (None, "LH", "LF", None, "RH", "RF", None)
"""The mirror image of :data:`SWING_ORDER`: left legs first."""

SWING_ORDERS: dict[str, tuple[str | None, ...]] = {"right_first": SWING_ORDER, "left_first": MIRRORED_SWING_ORDER}
"""The allowed swing orders by name (``Scenario.swing_order``)."""

N_PHASES = len(SWING_ORDER)

PAPER_DURATIONS: tuple[float, ...] = (1.0, 1.0, 1.0, 0.1, 1.0, 1.0, 1.0)
"""Phase durations of the paper's §6 cycle (s)."""


@dataclasses.dataclass(frozen=True)
class Phase:
    """One phase of the gait cycle (times in s from the start of the cycle)."""

    index: int
    """0..6 within the cycle."""
    t_start: float
    """start time (s)."""
    t_end: float
    """end time (s)."""
    swing_leg: str | None
    """the leg in swing ("LF", "RF", "LH", "RH") or None for four-leg support."""
    stance: tuple[bool, bool, bool, bool]
    """stance flags in leg order LF, RF, LH, RH."""
    moved: tuple[bool, bool, bool, bool]
    """legs that already stand on their target foothold during this phase (leg order)."""

    @property
    def duration(self) -> float:
        """Phase length (s)."""
        return self.t_end - self.t_start

    def name(self) -> str:
        """Human-readable name, e.g. ``"phase 2 (RH swing)"``."""
        what = f"{self.swing_leg} swing" if self.swing_leg else "four-leg support"
        return f"phase {self.index} ({what})"


def validate_durations(durations: Sequence[float]) -> tuple[float, ...]:
    """Check 7 finite positive phase durations (s); raise ``ValueError`` naming the field."""
    d = np.asarray(durations, dtype=float)
    if d.shape != (N_PHASES,) or not np.all(np.isfinite(d)) or np.any(d <= 0.0):
        raise ValueError(f"durations must be {N_PHASES} finite numbers > 0 (s), got {excerpt(durations)}")
    return tuple(float(x) for x in d)


def walk_cycle(
    durations: Sequence[float] = PAPER_DURATIONS, t0: float = 0.0, order: str = "right_first"
) -> tuple[Phase, ...]:
    """The seven phases of one walk cycle starting at ``t0`` (s) with the given durations (s).

    :param order: a key of :data:`SWING_ORDERS` (``"right_first"``: the paper's RH, RF, LH, LF).
    """
    if order not in SWING_ORDERS:
        raise ValueError(f"order must be one of {list(SWING_ORDERS)}, got {excerpt(order)}")
    d = validate_durations(durations)
    ends = t0 + np.cumsum(d)
    starts = np.concatenate([[t0], ends[:-1]])
    phases = []
    moved = [False] * 4
    for k, leg in enumerate(SWING_ORDERS[order]):
        stance = tuple(leg != name for name in LEG_NAMES)
        phases.append(Phase(k, float(starts[k]), float(ends[k]), leg, stance, tuple(moved)))  # type: ignore[arg-type]
        if leg is not None:
            moved[LEG_NAMES.index(leg)] = True
    return tuple(phases)


def phase_index(phases: Sequence[Phase], t: np.ndarray) -> np.ndarray:
    """Index of the phase containing each time ``t`` (s); times are clipped to the cycle.

    A junction time belongs to the later phase, the cycle's end to the last phase.
    """
    ends = np.array([p.t_end for p in phases[:-1]])
    return np.searchsorted(ends, np.asarray(t, dtype=float), side="right")
