"""Check an inverse-dynamics solution against MuJoCo's own M, h and foot Jacobians."""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np

from agents.control.inverse_dynamics import IDResult
from quad_uneven_env import constants as C


@dataclasses.dataclass(frozen=True)
class IDCheck:
    """Residuals of an inverse-dynamics solution (max absolute values, SI)."""

    eom: float
    """max |M qacc + h - B tau - J^T F| over the 18 rows (N, N m)."""
    stance_foot_acc: float
    """max |J qacc + Jdot qdot| over the stance feet (m/s^2)."""
    base_acc: float
    """max |qacc[:6] - beta_ddot[:6]| (m/s^2, rad/s^2)."""

    def ok(self, tol: float = 1e-8) -> bool:
        """All residuals below ``tol``."""
        return max(self.eom, self.stance_foot_acc, self.base_acc) < tol


def verify_inverse_dynamics(
    model: mujoco.MjModel, qpos: np.ndarray, qvel: np.ndarray, beta_ddot: np.ndarray, result: IDResult
) -> IDCheck:
    """Residuals of ``result`` with MuJoCo's mj_fullM, qfrc_bias, mj_jacSite and mj_jacDot at (qpos, qvel).

    Independent of the backend that produced ``result``: a private MjData is used, collisions are
    not computed.
    """
    d = mujoco.MjData(model)
    d.qpos[:], d.qvel[:] = qpos, qvel
    mujoco.mj_kinematics(model, d)
    mujoco.mj_comPos(model, d)
    mujoco.mj_makeM(model, d)
    mujoco.mj_comVel(model, d)
    h = np.empty(C.NV)
    mujoco.mj_rne(model, d, 0, h)
    M = np.empty((C.NV, C.NV))
    mujoco.mj_fullM(model, d, M)
    resid = M @ result.qacc + h
    resid[6:] -= result.tau
    foot_acc = 0.0
    J = np.empty((3, C.NV))
    Jd = np.empty((3, C.NV))
    for i, site_name in enumerate(C.FOOT_SITES):
        site = model.site(site_name).id
        mujoco.mj_jacSite(model, d, J, None, site)
        resid -= J.T @ result.contact_forces[i]
        if result.stance[i]:
            mujoco.mj_jacDot(model, d, Jd, None, d.site_xpos[site], model.site_bodyid[site])
            foot_acc = max(foot_acc, float(np.abs(J @ result.qacc + Jd @ qvel).max()))
    base = float(np.abs(result.qacc[:6] - np.asarray(beta_ddot)[:6]).max())
    return IDCheck(float(np.abs(resid).max()), foot_acc, base)
