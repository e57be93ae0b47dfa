"""Dynamics terms read from MuJoCo itself: the fast path inside the simulator.

``terms_from_data(data)`` reuses what the last ``mj_step1``/``mj_forward`` computed in
``data`` (mass matrix ``data.M``, ``qfrc_bias``, body frames, joint axes and anchors, subtree
centres of mass): M, the foot Jacobians, their time derivatives and G are assembled by one
compiled kernel (:mod:`quad_uneven_env.robot.dynamics.mujoco_kernels`); the views of ``data``'s arrays
are kept between calls. :meth:`MujocoDynamics.terms_from_data_mjcalls` computes the same terms
with MuJoCo's own ``mj_fullM``, ``mj_jacSite``, ``mj_jacDot`` and ``mj_jacSubtreeCom`` (the
reference the kernel is tested against). ``terms(qpos, qvel)`` runs the needed pipeline stages
on a private MjData (no collision detection).
"""

from __future__ import annotations

import mujoco
import numpy as np

from quad_uneven_env import constants as C
from quad_uneven_env.robot.description import RobotDescription
from quad_uneven_env.robot.dynamics import mujoco_kernels as DK
from quad_uneven_env.robot.dynamics.base import DynamicsTerms
from quad_uneven_env.robot.model import robot_mjcf


def _named_id(model: mujoco.MjModel, kind: str, name: str) -> int:
    """The id of the ``kind`` (``"body"``, ``"joint"``, ``"site"``) ``name``; a ValueError naming it if absent."""
    try:
        return int(getattr(model, kind)(name).id)
    except KeyError:
        raise ValueError(f"model has no {kind} {name!r} (the names of quad_uneven_env.constants)") from None


def _kernel_indices(model: mujoco.MjModel) -> tuple[np.ndarray, np.ndarray]:
    """Index (int64) and parameter (float64) tables of :func:`dynamics_kernels.mujoco_terms`.

    :raises ValueError: the model is not a free trunk with four 3-hinge legs ending in the foot sites.
    """
    trunk = _named_id(model, "body", C.TRUNK_BODY)
    free = int(model.body_jntadr[trunk])
    if model.body_jntnum[trunk] != 1 or model.jnt_type[free] != mujoco.mjtJoint.mjJNT_FREE:
        raise ValueError(f"body {C.TRUNK_BODY!r} must have exactly one free joint")
    if model.jnt_dofadr[free] != 0 or np.any(model.jnt_pos[free] != 0.0):
        raise ValueError("the trunk's free joint must use dofs 0-5 and sit at the body origin")
    sites, jnts, dofs, bodies, msub = [], [], [], [], []
    for i, leg in enumerate(C.LEG_NAMES):
        site = _named_id(model, "site", C.foot_site(leg))
        chain = []  # dofs moving the foot body, root first
        dof = int(model.body_dofadr[model.site_bodyid[site]]) + int(model.body_dofnum[model.site_bodyid[site]]) - 1
        while dof >= 0:
            chain.append(dof)
            dof = int(model.dof_parentid[dof])
        chain = chain[::-1]
        want = [*range(6), *range(6 + 3 * i, 9 + 3 * i)]
        if chain != want:
            raise ValueError(f"leg {leg}: the foot site must be moved by dofs {want}, got {chain}")
        for k in range(3):
            j = _named_id(model, "joint", C.joint_name(leg, C.JOINT_KINDS[k]))
            if model.jnt_type[j] != mujoco.mjtJoint.mjJNT_HINGE or model.jnt_dofadr[j] != 6 + 3 * i + k:
                raise ValueError(f"joint {C.joint_name(leg, C.JOINT_KINDS[k])} must be a hinge on dof {6 + 3 * i + k}")
            jnts.append(j)
            dofs.append(6 + 3 * i + k)
            bodies.append(int(model.jnt_bodyid[j]))
            msub.append(float(model.body_subtreemass[model.jnt_bodyid[j]]))
        sites.append(site)
    idx = np.array([trunk, *sites, *jnts, *dofs, *bodies], dtype=np.int64)
    par = np.array([model.body_subtreemass[trunk], *model.opt.gravity, *msub], dtype=float)
    assert len(idx) == DK.IDX_LEN and len(par) == DK.PAR_LEN
    return idx, par


class MujocoDynamics:
    """MuJoCo's M (``data.M``), h (qfrc_bias), G and foot Jacobians, via one compiled kernel.

    :param robot: an MjModel of the project's robot structure (the env's scene: :meth:`terms_from_data` reads
        its MjData), or a :class:`~quad_uneven_env.robot.description.RobotDescription`, whose robot-only MJCF
        (:func:`~quad_uneven_env.robot.model.robot_mjcf`) is compiled here.
    :raises ValueError: for a model of another structure, naming the body, joint or site.
    """

    backend = "mujoco"

    def __init__(self, robot: mujoco.MjModel | RobotDescription) -> None:
        if isinstance(robot, RobotDescription):
            robot = mujoco.MjModel.from_xml_string(robot_mjcf(robot))
        if not isinstance(robot, mujoco.MjModel):
            raise ValueError(f"robot must be a RobotDescription or a mujoco.MjModel, got {type(robot).__name__}")
        model = robot
        if model.nv != C.NV:
            raise ValueError(f"model must have nv={C.NV}, got {model.nv}")
        self._idx, self._par = _kernel_indices(model)
        self.model = model
        self._data = mujoco.MjData(model)
        self.trunk = model.body(C.TRUNK_BODY).id
        self.total_mass = float(model.body_subtreemass[self.trunk])
        self.foot_sites = np.array([model.site(s).id for s in C.FOOT_SITES])
        self.foot_bodies = model.site_bodyid[self.foot_sites].copy()
        self.gravity_W = model.opt.gravity.copy()
        self._jac = np.zeros((3, C.NV))
        self._jdot = np.zeros((3, C.NV))
        csr = (model.M_rowadr, model.M_rownnz, model.M_colind)
        self._csr = tuple(np.ascontiguousarray(a, dtype=np.int64) for a in csr)
        self._bound: mujoco.MjData | None = None
        self._views: tuple = ()

    def __getstate__(self) -> dict:
        """``copy.deepcopy`` and pickle: without the views of the bound data (a copy would hold stale arrays in
        place of views of its own data); they are taken again at the copy's first call."""
        state = dict(self.__dict__)
        state["_bound"], state["_views"] = None, ()
        return state

    def data_views(self, data: mujoco.MjData) -> tuple:
        """The MjData arrays the kernel reads (views kept while ``data`` is the same object)."""
        if data is not self._bound:
            self._views = (data.qvel, data.M, *self._csr, data.xpos, data.xmat, data.xanchor, data.xaxis,
                           data.site_xpos, data.subtree_com, self._idx, self._par)  # fmt: skip
            self._bound = data
        return self._views

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
        M = np.empty((C.NV, C.NV))
        J_feet = np.empty((C.N_LEGS, 3, C.NV))
        Jdd = np.empty((C.N_LEGS, 3))
        G = np.empty(C.NV)
        DK.mujoco_terms(*self.data_views(data), M, J_feet, Jdd, G)
        return DynamicsTerms(M, data.qfrc_bias.copy(), G, J_feet, Jdd)

    def terms_from_data_mjcalls(self, data: mujoco.MjData) -> DynamicsTerms:
        """As :meth:`terms_from_data` with MuJoCo's mj_fullM, mj_jacSite, mj_jacDot, mj_jacSubtreeCom (slower)."""
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
