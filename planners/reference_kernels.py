"""Compiled twin of :meth:`planners.reference.Reference.row`'s grid lookup (for the controller's one call per
physics step; ``tests/planners/test_reference.py`` checks the two agree, at half-way times and off the grid)."""

from __future__ import annotations

from quad_uneven_env.jit import njit


@njit(nogil=True)
def grid_index(t, grid_t, dt, t_end):  # pragma: no cover - compiled
    """Index of the grid time equal to ``t`` (s from the cycle start, clipped to [0, ``t_end``]) to 1e-9 s, or -1.

    :param grid_t: (T,) grid times (s), spaced ``dt`` from 0.
    """
    tc = min(max(t, 0.0), t_end)
    k = round(tc / dt)  # half to even, as Python's round
    if k < grid_t.shape[0] and abs(grid_t[k] - tc) < 1e-9:
        return k
    return -1
