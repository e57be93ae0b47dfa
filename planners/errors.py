"""The planners' one error type."""

from __future__ import annotations


class PlanningError(RuntimeError):
    """A planning problem has no acceptable solution.

    The message names where it failed (phase, support polygon edge or leg) and by how much,
    so a caller replanning from measured states can log it and react (stop, shorten the
    stride, pick other footholds). Planners never return a silently bad path.
    """
