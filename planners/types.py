"""Every type that crosses the planners' boundary: what they read, what they return, how they fail.

- :class:`HeightMap`: what the planners need from a terrain map (the env's
  ``quad_uneven_env.terrain.HeightField``, the expert's map, satisfies it);
- :class:`ReferenceSample` (and its packed row layout :data:`PACKED_FIELDS`): the planned state of
  the whole robot at one instant in the canonical coordinates (MuJoCo's), from which the controller
  builds beta_ref, its derivatives and the stance set;
- :class:`ReferenceGrid`: a plan's packed rows on its time grid, for the controller's compiled path;
- :class:`PlanningError`: the planners' one error type.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import NamedTuple, Protocol

import numpy as np


class PlanningError(RuntimeError):
    """A planning problem has no acceptable solution.

    The message names where it failed (phase, support polygon edge or leg) and by how much,
    so a caller replanning from measured states can log it and react (stop, shorten the
    stride, pick other footholds). Planners never return a silently bad path.
    """


class FootholdError(PlanningError):
    """No acceptable foothold for a leg; ``failed_test`` is the first acceptance test that no candidate
    passed (one of ``planners.footholds.FOOTHOLD_TESTS``, e.g. ``"slope"``), ``slope_blocked`` the number of
    candidates that pass every test but the slope limit (before the shank-clearance test): > 0 means a
    steeper slope limit could give a foothold."""

    def __init__(self, message: str, failed_test: str, slope_blocked: int = 0) -> None:
        super().__init__(message)
        self.failed_test = failed_test
        self.slope_blocked = slope_blocked


class HeightMap(Protocol):
    """Terrain surface ``z = height(x, y)`` in the world frame (m)."""

    def height(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Surface height (m) at world (x, y) (m), vectorised."""
        ...

    def normal(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Unit upward surface normal (..., 3) at world (x, y) (m)."""
        ...


@dataclasses.dataclass(frozen=True)
class ReferenceSample:
    """Planned whole-robot motion at one time ``t`` (SI units, canonical frames)."""

    t: float
    """time (s) from the start of the plan."""
    p_base_W: np.ndarray
    """(3,) base (trunk frame origin) position in the world frame (m)."""
    quat_WB: np.ndarray
    """(4,) base orientation, unit quaternion (w, x, y, z)."""
    v_base_W: np.ndarray
    """(3,) base linear velocity in the world frame (m/s)."""
    omega_base_B: np.ndarray
    """(3,) base angular velocity in the base frame (rad/s)."""
    a_base_W: np.ndarray
    """(3,) base linear acceleration in the world frame (m/s^2)."""
    domega_base_B: np.ndarray
    """(3,) base angular acceleration in the base frame (rad/s^2)."""
    q_joints: np.ndarray
    """(12,) joint angles (rad), JOINT_NAMES order."""
    qd_joints: np.ndarray
    """(12,) joint velocities (rad/s)."""
    qdd_joints: np.ndarray
    """(12,) joint accelerations (rad/s^2)."""
    stance: tuple[bool, bool, bool, bool]
    """planned stance flags in leg order LF, RF, LH, RH."""

    @property
    def qpos(self) -> np.ndarray:
        """(19,) canonical qpos of the reference."""
        return np.concatenate([self.p_base_W, self.quat_WB, self.q_joints])

    @property
    def qvel(self) -> np.ndarray:
        """(18,) canonical qvel of the reference."""
        return np.concatenate([self.v_base_W, self.omega_base_B, self.qd_joints])

    @property
    def qacc(self) -> np.ndarray:
        """(18,) d/dt of the canonical qvel."""
        return np.concatenate([self.a_base_W, self.domega_base_B, self.qdd_joints])


PACKED_FIELDS: tuple[tuple[str, int], ...] = (
    ("p_base_W", 3), ("quat_WB", 4), ("v_base_W", 3), ("omega_base_B", 3), ("a_base_W", 3),
    ("domega_base_B", 3), ("q_joints", 12), ("qd_joints", 12), ("qdd_joints", 12),
)  # fmt: skip
"""Layout of a packed reference row (55 floats): the :class:`ReferenceSample` arrays in this order."""


class ReferenceGrid(NamedTuple):
    """A plan's reference on its time grid, packed for one compiled lookup per physics step
    (:meth:`planners.reference.Reference.row` in :func:`planners.reference_kernels.grid_index`)."""

    t: np.ndarray
    """(T,) s from the cycle start: the grid times."""
    dt: float
    """s, the grid spacing."""
    t_end: float
    """s, the cycle's duration (times are clipped to [0, t_end])."""
    packed: np.ndarray
    """(T, 55) the packed rows (:data:`PACKED_FIELDS`); not to be written."""
    masks: np.ndarray
    """(T,) int64 planned stance bitmask of each row (bit i: leg i)."""
    rows: Sequence[np.ndarray]
    """the rows of ``packed`` as (55,) views (a sequence indexed like ``packed``)."""
