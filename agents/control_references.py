"""Simple whole-body references for the controller: feet fixed, base moving (tests, benchmarks, demos).

:class:`BaseWaveReference` returns :class:`planners.types.ReferenceSample` objects with the base
following a sinusoid in z, roll and pitch (exact derivatives) while the four feet stay where
they are; the joint angles come from the closed-form leg IK.
"""

from __future__ import annotations

import mujoco
import numpy as np

from planners.types import ReferenceSample
from quad_uneven_env import constants as C
from quad_uneven_env.config import RobotConfig
from quad_uneven_env.robot.kinematics import hip_positions_B, leg_ik_hip


def _rx(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _ry(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


class BaseWaveReference:
    """Feet fixed in the world; base z +/- dz at fz Hz, roll = pitch = ang sin(2 pi fa t); joints by IK.

    Exact base derivatives (R = R_y(pitch) R_x(roll): omega_B = (roll', pitch' cos roll, -pitch' sin roll)).
    """

    def __init__(
        self,
        p0: np.ndarray,
        feet_W: np.ndarray,
        cfg: RobotConfig,
        dz: float = 0.03,
        fz: float = 0.5,
        ang: float = 0.0872664626,
        fa: float = 0.3,
    ) -> None:
        """:param p0: (3,) base position at rest (m, world); :param feet_W: (4, 3) fixed foot sites (m, world);
        :param cfg: RobotConfig; :param dz: z amplitude (m) at ``fz`` (Hz); :param ang: roll and pitch
        amplitude (rad) at ``fa`` (Hz). Zero amplitudes give a standing reference."""
        self.p0, self.feet, self.cfg = np.asarray(p0), np.asarray(feet_W), cfg
        self.dz, self.wz, self.ang, self.wa = dz, 2 * np.pi * fz, ang, 2 * np.pi * fa
        self.hips = hip_positions_B(cfg)

    def _base(self, t):
        s, c = np.sin(self.wz * t), np.cos(self.wz * t)
        p = self.p0 + np.array([0.0, 0.0, self.dz * s])
        v = np.array([0.0, 0.0, self.dz * self.wz * c])
        a = np.array([0.0, 0.0, -self.dz * self.wz**2 * s])
        sa, ca = np.sin(self.wa * t), np.cos(self.wa * t)
        phi, phid, phidd = self.ang * sa, self.ang * self.wa * ca, -self.ang * self.wa**2 * sa
        th, thd, thdd = phi, phid, phidd
        R = _ry(th) @ _rx(phi)
        w = np.array([phid, thd * np.cos(phi), -thd * np.sin(phi)])
        wd = np.array(
            [phidd, thdd * np.cos(phi) - thd * phid * np.sin(phi), -thdd * np.sin(phi) - thd * phid * np.cos(phi)]
        )
        return p, R, v, w, a, wd

    def joints(self, t: float) -> np.ndarray:
        """(12,) joint angles (rad) keeping the feet at ``feet_W`` while the base is at its pose at ``t``."""
        p, R, *_ = self._base(t)
        p_H = (self.feet - p) @ R - self.hips
        return np.concatenate(
            [
                leg_ik_hip(p_H[i], self.cfg.thigh.length, self.cfg.shank.length, C.KNEE_SIGN[leg])
                for i, leg in enumerate(C.LEG_NAMES)
            ]
        )

    def __call__(self, t: float) -> ReferenceSample:
        """The reference at ``t`` (s); four-foot stance."""
        p, R, v, w, a, wd = self._base(t)
        quat = np.empty(4)
        mujoco.mju_mat2Quat(quat, R.reshape(-1))
        h = 1e-4  # joint derivatives (unused by the controller in four-foot stance) by central differences
        q, qp, qm = self.joints(t), self.joints(t + h), self.joints(t - h)
        return ReferenceSample(t, p, quat, v, w, a, wd, q, (qp - qm) / (2 * h), (qp - 2 * q + qm) / h**2, (True,) * 4)
