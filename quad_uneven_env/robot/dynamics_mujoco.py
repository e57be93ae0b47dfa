"""Dynamics terms read from MuJoCo itself: the fast path inside the simulator.

``terms_from_data(data)`` reuses what the last ``mj_step1``/``mj_forward`` computed in
``data`` (mass matrix, ``qfrc_bias``, ``cvel``): only ``mj_fullM``, the foot Jacobians
(``mj_jacSite``), their time derivatives (``mj_jacDot``) and the subtree-COM Jacobian (for G)
are evaluated. ``terms(qpos, qvel)`` runs the needed pipeline stages on a private MjData
(no collision detection).
"""

from __future__ import annotations

import mujoco
import numpy as np

from quad_uneven_env import constants as C
from quad_uneven_env.robot.dynamics import DynamicsTerms


class MujocoDynamics:
    """MuJoCo's M (mj_fullM), h (qfrc_bias), G (subtree-COM Jacobian) and foot Jacobians."""

    backend = "mujoco"

    def __init__(self, model: mujoco.MjModel) -> None:
        if model.nv != C.NV:
            raise ValueError(f"model must have nv={C.NV}, got {model.nv}")
        self.model = model
        self._data = mujoco.MjData(model)
        self.trunk = model.body(C.TRUNK_BODY).id
        self.total_mass = float(model.body_subtreemass[self.trunk])
        self.foot_sites = np.array([model.site(s).id for s in C.FOOT_SITES])
        self.foot_bodies = model.site_bodyid[self.foot_sites].copy()
        self.gravity_W = model.opt.gravity.copy()
        self._jac = np.zeros((3, C.NV))
        self._jdot = np.zeros((3, C.NV))

    def terms(self, qpos: np.ndarray, qvel: np.ndarray) -> DynamicsTerms:
        """Dynamics terms at ``qpos`` (19,) and ``qvel`` (18,), computed on a private MjData."""
        m, d = self.model, self._data
        d.qpos[:] = qpos
        d.qvel[:] = qvel
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        mujoco.mj_makeM(m, d)
        mujoco.mj_comVel(m, d)
        mujoco.mj_rne(m, d, 0, d.qfrc_bias)
        return self.terms_from_data(d)

    def terms_from_data(self, data: mujoco.MjData) -> DynamicsTerms:
        """Dynamics terms at ``data``'s state, reusing its last mj_step1 / mj_forward results."""
        m = self.model
        M = np.empty((C.NV, C.NV))
        mujoco.mj_fullM(m, data, M)
        J_feet = np.empty((C.N_LEGS, 3, C.NV))
        Jdd = np.empty((C.N_LEGS, 3))
        jac, jdot = self._jac, self._jdot
        for i in range(C.N_LEGS):
            site = self.foot_sites[i]
            mujoco.mj_jacSite(m, data, J_feet[i], None, site)
            mujoco.mj_jacDot(m, data, jdot, None, data.site_xpos[site], self.foot_bodies[i])
            Jdd[i] = jdot @ data.qvel
        mujoco.mj_jacSubtreeCom(m, data, jac, self.trunk)
        G = -self.total_mass * (self.gravity_W @ jac)
        return DynamicsTerms(M, data.qfrc_bias.copy(), G, J_feet, Jdd)
