"""Simple whole-body references for the controller: feet fixed, base moving (tests, benchmarks, demos).

:func:`track_in_env` runs the controller on one in the QuadUneven-v0 env and measures the tracking.

:class:`BaseWaveReference` returns :class:`planners.types.ReferenceSample` objects with the base
following a sinusoid in z, roll and pitch (exact derivatives) while the four feet stay where
they are; the joint angles come from the closed-form leg IK.
"""

from __future__ import annotations

import gymnasium as gym
import mujoco
import numpy as np

import quad_uneven_env  # noqa: F401  (registers QuadUneven-v0)
from agents.control.controller import ComputedTorqueController
from planners.robot_geometry import robot_geometry
from planners.types import ReferenceSample
from quad_uneven_env import constants as C
from quad_uneven_env.robot.description import RobotDescription


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
        cfg: RobotDescription,
        dz: float = 0.03,
        fz: float = 0.5,
        ang: float = 0.0872664626,
        fa: float = 0.3,
    ) -> None:
        """:param p0: (3,) base position at rest (m, world); :param feet_W: (4, 3) fixed foot sites (m, world);
        :param cfg: the robot's description; :param dz: z amplitude (m) at ``fz`` (Hz);
        :param ang: roll and pitch amplitude (rad) at ``fa`` (Hz). Zero amplitudes give a standing reference."""
        self.p0, self.feet, self.cfg = np.asarray(p0), np.asarray(feet_W), cfg
        self.dz, self.wz, self.ang, self.wa = dz, 2 * np.pi * fz, ang, 2 * np.pi * fa
        self.geometry = robot_geometry(cfg)
        self.hips = self.geometry.hips_B

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
        return np.concatenate([self.geometry.leg_ik(i, p_H[i]) for i in range(C.N_LEGS)])

    def __call__(self, t: float) -> ReferenceSample:
        """The reference at ``t`` (s); four-foot stance."""
        p, R, v, w, a, wd = self._base(t)
        quat = np.empty(4)
        mujoco.mju_mat2Quat(quat, R.reshape(-1))
        h = 1e-4  # joint derivatives (unused by the controller in four-foot stance) by central differences
        q, qp, qm = self.joints(t), self.joints(t + h), self.joints(t - h)
        return ReferenceSample(t, p, quat, v, w, a, wd, q, (qp - qm) / (2 * h), (qp - 2 * q + qm) / h**2, (True,) * 4)


def track_in_env(
    seconds: float, distribution: str = "pinv", wave: float = 1.0, seed: int = 3, backend: str = "mujoco"
) -> dict:
    """Stand (``wave=0``) or track the base wave (``wave=1``: z +/- 3 cm at 0.5 Hz, roll = pitch +/- 5 deg
    at 0.3 Hz) with the feet where they spawned on rough terrain (4 cm, no flat spawn disc).

    Runs ``QuadUneven-v0`` with ``frame_skip=1`` so every physics step is observed, the controller
    being the env's physics-rate hook. Returns RMS base position (m) and orientation (rad) errors,
    per-foot maximum horizontal drift of the foot sites (m), the smallest measured normal force
    over all feet and steps (N, MuJoCo's contact forces along the terrain normal), the largest
    friction-cone excess ``|F_t| - mu F_n`` of the controller's own stance forces (N), the number
    of "qp" fallbacks, of steps with a foot out of contact, and the termination reason (or None).
    """
    env = gym.make(
        "QuadUneven-v0",
        terrain={"kind": "rough", "amplitude": 0.04, "spawn_radius": 0.0},
        frame_skip=1,
        reset_noise_scale=0.0,
        max_episode_steps=None,
    )
    env.reset(seed=seed)
    u = env.unwrapped
    m, d = u.model, u.data
    sites = [m.site(s).id for s in C.FOOT_SITES]
    feet0 = d.site_xpos[sites].copy()
    ground = u.terrain.height(feet0[:, 0], feet0[:, 1])
    ref = BaseWaveReference(d.qpos[:3].copy(), feet0, u.robot, dz=0.03 * wave, ang=np.deg2rad(5.0) * wave)
    ctrl = ComputedTorqueController(ref, backend=backend, distribution=distribution)
    ctrl.reset(m, d, u.terrain)
    u.set_controller(ctrl)
    n = round(seconds / u.dt)
    e_pos, e_rot = [], []
    slip = np.zeros(4)
    min_fn, cone_excess, fallbacks, no_contact, reason = np.inf, -np.inf, 0, 0, None
    e = np.empty(3)
    mu = u.robot.friction
    for _ in range(n):
        _, _, term, _, info = env.step(np.zeros(C.N_JOINTS))
        if term:
            reason = info["termination_reason"]
            break
        r = ref(d.time)
        e_pos.append(np.linalg.norm(d.qpos[:3] - r.p_base_W))
        mujoco.mju_subQuat(e, r.quat_WB, d.qpos[3:7])
        e_rot.append(np.linalg.norm(e))
        slip = np.maximum(slip, np.linalg.norm(d.site_xpos[sites, :2] - feet0[:, :2], axis=1))
        no_contact += not info["foot_contact"].all()
        normals = u.terrain.heightfield.normal(d.site_xpos[sites, 0], d.site_xpos[sites, 1])
        min_fn = min(min_fn, float(np.einsum("ij,ij->i", info["contact_forces"], normals).min()))
        res = ctrl.last
        fallbacks += res.qp_fallback
        fn = np.einsum("ij,ij->i", res.contact_forces, normals)
        ft = np.linalg.norm(res.contact_forces - fn[:, None] * normals, axis=1)
        cone_excess = max(cone_excess, float((ft - mu * fn).max()))
    env.close()
    return {
        "rms_pos": float(np.sqrt(np.mean(np.square(e_pos)))),
        "rms_rot": float(np.sqrt(np.mean(np.square(e_rot)))),
        "slip": slip,
        "min_fn": min_fn,
        "cone_violation": cone_excess,
        "fallbacks": fallbacks,
        "steps_without_all_contacts": no_contact,
        "termination_reason": reason,
        "ground_ptp": float(np.ptp(ground)),
    }
