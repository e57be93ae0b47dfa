"""Body pitch over a gait cycle: level (the paper) or following the slope of the footholds.

The paper keeps the base orientation at identity. On stairs that puts the hips of the legs on
the higher steps too close to their feet: going down 8 cm stairs with a 0.3 m tread the
footholds of one cycle span three steps (0.24 m) while the hips are level, so the COG has to
drop for the lowest front foot to stay in reach and the hind leg on the top step folds until
its knee (which points forward) is below the foot and the shank rests on the stair nosing,
carrying the load the foot should carry. Pitching the body with the terrain keeps every hip at
about the same height above its foot.

:class:`BodyPitch` is the base orientation over a cycle: a pitch ``theta(t)`` about the body's y
axis going from ``start`` to ``end``, and, for a body that turns, a yaw ``psi(t)`` about world z
going from ``yaw_start`` to ``yaw_end`` (``R_WB = Rz(psi) Ry(theta)``, zero roll), both with a quintic
smoothstep (zero rate and acceleration at both ends, so consecutive cycles join with continuous rate
and acceleration). Without yaw (``yaw_start = yaw_end = 0``, the default) it is the rotation about
world y alone, computed without the yaw factor (no product with an identity, so the numbers are those of the
pitch alone). :func:`terrain_pitch` is the pitch of the
least-squares plane through four footholds along a heading.
"""

from __future__ import annotations

import dataclasses

import numpy as np

MAX_PITCH = np.deg2rad(30.0)
"""rad: largest terrain-following pitch (half the env's 60 deg tilt limit)."""


def terrain_pitch(footholds: np.ndarray, max_pitch: float = MAX_PITCH, yaw: float = 0.0) -> float:
    """Pitch (rad, about the body's y axis; positive: nose down) of the plane through ``footholds`` (n >= 3, 3) (m).

    The plane ``z = a + b x + c y`` is fitted by least squares in the frame yawed by ``yaw`` (rad, about
    world z; 0: the world frame); the body x axis (the heading) rotated by the returned angle is parallel
    to the plane's slope along the heading: ``pitch = atan(-b)``, clipped to ``+-max_pitch``. Footholds
    that span no plane (collinear) give 0.
    """
    f = np.asarray(footholds, dtype=float).reshape(-1, 3)
    if yaw != 0.0:
        # rows p @ R(yaw) = R(yaw)^T p: the points in the yawed frame
        f = np.column_stack([f[:, :2] @ planar_rotation(yaw), f[:, 2]])
    A = np.column_stack([np.ones(len(f)), f[:, 0], f[:, 1]])
    coef, _, rank, _ = np.linalg.lstsq(A, f[:, 2], rcond=None)
    if rank < 3:
        return 0.0
    return float(np.clip(np.arctan(-coef[1]), -max_pitch, max_pitch))


def planar_rotation(yaw: float) -> np.ndarray:
    """(2, 2) rotation by ``yaw`` (rad, counter-clockwise) of the horizontal plane: ``[[c, -s], [s, c]]``."""
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s], [s, c]])


def yaw_pitch_of_quaternion(quat_wxyz: np.ndarray) -> tuple[float, float]:
    """Yaw (rad, about world z) and pitch (rad, about the yawed y axis) of a base orientation (w, x, y, z).

    The z-y-x (yaw, pitch, roll) angles of ``R_WB = Rz(yaw) Ry(pitch) Rx(roll)``: ``yaw = atan2(R[1, 0],
    R[0, 0])``, ``pitch = atan2(-R[2, 0], hypot(R[0, 0], R[1, 0]))``; the roll is dropped.
    """
    w, x, y, z = (float(v) for v in quat_wxyz)
    r00 = 1.0 - 2.0 * (y * y + z * z)
    r10 = 2.0 * (x * y + w * z)
    r20 = 2.0 * (x * z - w * y)
    return float(np.arctan2(r10, r00)), float(np.arctan2(-r20, np.hypot(r00, r10)))


def pitch_of_quaternion(quat_wxyz: np.ndarray) -> float:
    """Pitch (rad, about world y) of a base orientation (w, x, y, z): ``atan2(-R[2, 0], R[0, 0])``."""
    w, x, y, z = (float(v) for v in quat_wxyz)
    r00 = 1.0 - 2.0 * (y * y + z * z)
    r20 = 2.0 * (x * z - w * y)
    return float(np.arctan2(-r20, r00))


@dataclasses.dataclass(frozen=True)
class BodyPitch:
    """Base pitch ``theta(t)`` (rad) from ``start`` at t = 0 to ``end`` at t = ``duration`` (s), then held, and
    yaw ``psi(t)`` (rad) from ``yaw_start`` to ``yaw_end`` likewise: ``R_WB = Rz(psi) Ry(theta)``."""

    start: float = 0.0
    """rad, pitch at the cycle start."""
    end: float = 0.0
    """rad, pitch at the cycle end."""
    duration: float = 1.0
    """s, cycle length."""
    yaw_start: float = 0.0
    """rad, yaw (about world z, counter-clockwise from above) at the cycle start."""
    yaw_end: float = 0.0
    """rad, yaw at the cycle end (``yaw_start`` plus the cycle's turn)."""

    @property
    def level(self) -> bool:
        """The body stays level and unturned (identity orientation, the paper)."""
        return self.start == 0.0 and self.end == 0.0 and not self.yawed

    @property
    def yawed(self) -> bool:
        """The orientation has a yaw (nonzero at either end)."""
        return self.yaw_start != 0.0 or self.yaw_end != 0.0

    def yaw(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Yaw (rad), yaw rate (rad/s) and yaw acceleration (rad/s^2) at times ``t`` (s)."""
        s, ds, dds = self._s(t)
        turn = self.yaw_end - self.yaw_start
        return self.yaw_start + turn * s, turn * ds, turn * dds

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
        """R_WB (..., 3, 3) at times ``t`` (...) (s): ``Rz(psi) Ry(theta)`` (without yaw: about world y only)."""
        th = np.asarray(self.angle(t))
        c, s = np.cos(th), np.sin(th)
        R = np.zeros((*th.shape, 3, 3))
        R[..., 2, 0], R[..., 2, 2] = -s, c
        if not self.yawed:
            R[..., 0, 0], R[..., 0, 2], R[..., 1, 1] = c, s, 1.0
            return R
        psi = self.yaw(t)[0]
        cz, sz = np.cos(psi), np.sin(psi)
        # Rz(psi) Ry(theta) written out
        R[..., 0, 0], R[..., 0, 1], R[..., 0, 2] = cz * c, -sz, cz * s
        R[..., 1, 0], R[..., 1, 1], R[..., 1, 2] = sz * c, cz, sz * s
        return R

    def quaternion(self, t: np.ndarray) -> np.ndarray:
        """(..., 4) base orientation (w, x, y, z) at times ``t`` (...) (s): ``q_z(psi) q_y(theta)``."""
        half = 0.5 * self.angle(t)
        z = np.zeros_like(half)
        if not self.yawed:
            return np.stack([np.cos(half), z, np.sin(half), z], axis=-1)
        hz = 0.5 * self.yaw(t)[0]
        cy, sy, cz, sz = np.cos(half), np.sin(half), np.cos(hz), np.sin(hz)
        return np.stack([cz * cy, -sz * sy, cz * sy, sz * cy], axis=-1)

    def omega(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Angular velocity (..., 3) (rad/s) and acceleration (..., 3) (rad/s^2) at times ``t``, world frame.

        ``omega = psi' z + theta' Rz(psi) y``. Without yaw both are along y, the same in the world and the
        base frame (:meth:`omega_base`).
        """
        t = np.asarray(t, dtype=float)
        w, a = np.zeros((*t.shape, 3)), np.zeros((*t.shape, 3))
        if not self.yawed:
            w[..., 1], a[..., 1] = self.rate(t), self.accel(t)
            return w, a
        psi, dpsi, ddpsi = self.yaw(t)
        dth, ddth = self.rate(t), self.accel(t)
        c, s = np.cos(psi), np.sin(psi)
        w[..., 0], w[..., 1], w[..., 2] = -s * dth, c * dth, dpsi
        a[..., 0] = -c * dpsi * dth - s * ddth
        a[..., 1] = -s * dpsi * dth + c * ddth
        a[..., 2] = ddpsi
        return w, a

    def omega_base(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Angular velocity (..., 3) (rad/s) and acceleration (..., 3) (rad/s^2) at times ``t``, base frame.

        ``R^T`` times :meth:`omega` (the base-frame derivative of the base-frame angular velocity is the
        world-frame acceleration seen in the base frame, as omega x omega = 0).
        """
        w, a = self.omega(t)
        if not self.yawed:
            return w, a
        Rt = np.swapaxes(self.rotation(t), -1, -2)
        return np.einsum("...ij,...j->...i", Rt, w), np.einsum("...ij,...j->...i", Rt, a)


LEVEL = BodyPitch()
"""The paper's level body."""
