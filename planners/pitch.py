"""Body pitch over a gait cycle: level (the paper) or following the slope of the footholds.

The paper keeps the base orientation at identity. On stairs that puts the hips of the legs on
the higher steps too close to their feet: going down 8 cm stairs with a 0.3 m tread the
footholds of one cycle span three steps (0.24 m) while the hips are level, so the COG has to
drop for the lowest front foot to stay in reach and the hind leg on the top step folds until
its knee (which points forward) is below the foot and the shank rests on the stair nosing,
carrying the load the foot should carry. Pitching the body with the terrain keeps every hip at
about the same height above its foot.

:class:`BodyPitch` is a rotation about the world y axis (heading +x, zero roll and yaw) going
from ``start`` to ``end`` over the cycle with a quintic smoothstep (zero rate and acceleration
at both ends, so consecutive cycles join with continuous rate and acceleration).
:func:`terrain_pitch` is the pitch of the least-squares plane through four footholds.
"""

from __future__ import annotations

import dataclasses

import numpy as np

MAX_PITCH = np.deg2rad(30.0)
"""rad: largest terrain-following pitch (half the env's 60 deg tilt limit)."""


def terrain_pitch(footholds: np.ndarray, max_pitch: float = MAX_PITCH) -> float:
    """Pitch (rad, about world y; positive: nose down) of the plane through ``footholds`` (n >= 3, 3) (m).

    The plane ``z = a + b x + c y`` is fitted by least squares; the body x axis rotated by the
    returned angle is parallel to the plane's slope along world x: ``pitch = atan(-b)``, clipped
    to ``+-max_pitch``. Footholds that span no plane (collinear) give 0.
    """
    f = np.asarray(footholds, dtype=float).reshape(-1, 3)
    A = np.column_stack([np.ones(len(f)), f[:, 0], f[:, 1]])
    coef, _, rank, _ = np.linalg.lstsq(A, f[:, 2], rcond=None)
    if rank < 3:
        return 0.0
    return float(np.clip(np.arctan(-coef[1]), -max_pitch, max_pitch))


def pitch_of_quaternion(quat_wxyz: np.ndarray) -> float:
    """Pitch (rad, about world y) of a base orientation (w, x, y, z): ``atan2(-R[2, 0], R[0, 0])``."""
    w, x, y, z = (float(v) for v in quat_wxyz)
    r00 = 1.0 - 2.0 * (y * y + z * z)
    r20 = 2.0 * (x * z - w * y)
    return float(np.arctan2(-r20, r00))


@dataclasses.dataclass(frozen=True)
class BodyPitch:
    """Base pitch ``theta(t)`` (rad) from ``start`` at t = 0 to ``end`` at t = ``duration`` (s), then held."""

    start: float = 0.0
    """rad, pitch at the cycle start."""
    end: float = 0.0
    """rad, pitch at the cycle end."""
    duration: float = 1.0
    """s, cycle length."""

    @property
    def level(self) -> bool:
        """The body stays level (identity orientation, the paper)."""
        return self.start == 0.0 and self.end == 0.0

    def _s(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Smoothstep 10u^3 - 15u^4 + 6u^5 of u = t / duration and its first two time derivatives."""
        T = self.duration
        u = np.clip(np.asarray(t, dtype=float) / T, 0.0, 1.0)
        s = u**3 * (10.0 - 15.0 * u + 6.0 * u**2)
        ds = 30.0 * u**2 * (1.0 - u) ** 2 / T
        dds = 60.0 * u * (1.0 - u) * (1.0 - 2.0 * u) / T**2
        return s, ds, dds

    def angle(self, t: np.ndarray) -> np.ndarray:
        """Pitch (rad) at times ``t`` (s)."""
        return self.start + (self.end - self.start) * self._s(t)[0]

    def rate(self, t: np.ndarray) -> np.ndarray:
        """Pitch rate (rad/s) at times ``t`` (s)."""
        return (self.end - self.start) * self._s(t)[1]

    def accel(self, t: np.ndarray) -> np.ndarray:
        """Pitch acceleration (rad/s^2) at times ``t`` (s)."""
        return (self.end - self.start) * self._s(t)[2]

    def rotation(self, t: np.ndarray) -> np.ndarray:
        """R_WB (..., 3, 3) at times ``t`` (...) (s): rotation by the pitch about world y."""
        th = self.angle(t)
        c, s = np.cos(th), np.sin(th)
        z, o = np.zeros_like(th), np.ones_like(th)
        return np.stack([np.stack([c, z, s], -1), np.stack([z, o, z], -1), np.stack([-s, z, c], -1)], -2)

    def quaternion(self, t: np.ndarray) -> np.ndarray:
        """(..., 4) base orientation (w, x, y, z) at times ``t`` (...) (s)."""
        half = 0.5 * self.angle(t)
        z = np.zeros_like(half)
        return np.stack([np.cos(half), z, np.sin(half), z], axis=-1)

    def omega(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Angular velocity (..., 3) (rad/s) and acceleration (..., 3) (rad/s^2) at times ``t``.

        Both are along y, so they are the same in the world and the base frame.
        """
        t = np.asarray(t, dtype=float)
        w, a = np.zeros((*t.shape, 3)), np.zeros((*t.shape, 3))
        w[..., 1], a[..., 1] = self.rate(t), self.accel(t)
        return w, a


LEVEL = BodyPitch()
"""The paper's level body."""
