"""What every dynamics backend reads of a robot: a free trunk and four HAA-HFE-KFE leg chains, as arrays.

:class:`LegChains` is built from either source a backend may be given:

- a :class:`~quad_uneven_env.robot.description.RobotDescription` (the robot's nominal numbers, standard gravity);
- a ``mujoco.MjModel`` of the project's robot structure (the robot-only MJCF or the env's scene): the simulated
  robot's numbers, after any per-episode randomization of its masses, and the model's gravity.

Frames and units are the description's: joint ``k`` of a leg sits at ``joint_pos`` in its parent's frame (the
trunk frame for HAA) with rotation ``joint_rot`` (parent <- joint) and turns about ``joint_axis`` (unit, joint
frame); link ``k``'s mass properties and the foot point are given in the joint's frame. kg, m, kg m^2, m/s^2.
"""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np

from quad_uneven_env import constants as C
from quad_uneven_env.robot.quadruped import AXIS_TOLERANCE, RobotDescription

STANDARD_GRAVITY = (0.0, 0.0, -9.81)
"""m/s^2, world-frame gravity of a description (MuJoCo's default ``opt.gravity``)."""

_NOMINAL_AXES = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 1.0, 0.0]])  # HAA: trunk x; HFE, KFE: trunk y


@dataclasses.dataclass(frozen=True, eq=False)
class LegChains:
    """A free trunk and four three-joint leg chains (leg order LF, RF, LH, RH; joints HAA, HFE, KFE)."""

    name: str
    """the description's robot name, or ``"MjModel"``."""
    gravity_W: np.ndarray
    """(3,) m/s^2, world frame."""
    trunk_mass: float
    """kg"""
    trunk_com: np.ndarray
    """(3,) m, trunk frame."""
    trunk_inertia: np.ndarray
    """(3, 3) kg m^2 about the trunk's COM, trunk frame."""
    joint_pos: np.ndarray
    """(4, 3, 3) m, joint origin in its parent's frame."""
    joint_rot: np.ndarray
    """(4, 3, 3, 3) rotation parent <- joint at zero angle."""
    joint_axis: np.ndarray
    """(4, 3, 3) unit rotation axis, joint frame."""
    link_mass: np.ndarray
    """(4, 3) kg, the link each joint moves (the HAA-HFE hip link may be massless)."""
    link_com: np.ndarray
    """(4, 3, 3) m, link COM in the joint's frame."""
    link_inertia: np.ndarray
    """(4, 3, 3, 3) kg m^2 about the link's COM, joint frame."""
    foot: np.ndarray
    """(4, 3) m, foot point in the KFE frame."""
    armature: np.ndarray
    """(12,) kg m^2, reflected rotor inertia on each joint's diagonal of M."""

    @property
    def total_mass(self) -> float:
        """kg, trunk plus the twelve leg links."""
        return self.trunk_mass + float(self.link_mass.sum())

    @classmethod
    def from_description(
        cls, desc: RobotDescription, gravity_W: tuple[float, float, float] | np.ndarray = STANDARD_GRAVITY
    ) -> LegChains:
        """The description's numbers (its nominal robot) under ``gravity_W`` (m/s^2, default standard gravity)."""
        joints = [leg.joints for leg in desc.legs]

        def arr(get) -> np.ndarray:
            return np.array([[get(j) for j in leg] for leg in joints], dtype=float)

        return cls(
            name=desc.name,
            gravity_W=np.array(gravity_W, dtype=float),
            trunk_mass=float(desc.trunk.mass),
            trunk_com=np.array(desc.trunk.com, dtype=float),
            trunk_inertia=np.array(desc.trunk.inertia, dtype=float),
            joint_pos=arr(lambda j: j.pos),
            joint_rot=arr(lambda j: j.rot),
            joint_axis=arr(lambda j: j.axis),
            link_mass=arr(lambda j: j.link.mass),
            link_com=arr(lambda j: j.link.com),
            link_inertia=arr(lambda j: j.link.inertia),
            foot=np.array([leg.foot for leg in desc.legs], dtype=float),
            armature=arr(lambda j: j.armature).reshape(C.N_JOINTS),
        )

    @classmethod
    def from_mjmodel(cls, model: mujoco.MjModel) -> LegChains:
        """The robot of ``model`` (robot-only or a scene): its body tree, inertias, foot sites and gravity.

        A leg's joints may share a body (the paper robot's HAA and HFE) or each move their own (a URDF robot's
        hip link); a body's mass properties belong to the last joint it carries.

        :raises ValueError: naming the joint, body or site, unless the trunk carries one free joint at its
            origin (dofs 0-5) and each leg is three hinges at their bodies' origins on dofs ``6 + 3 leg + k``,
            chained trunk -> HAA -> HFE -> KFE (HAA about trunk x, HFE and KFE about trunk y at zero angles),
            with its foot site on the KFE body and no other body in the robot.
        """
        if model.nv != C.NV or model.nq != C.NQ:
            raise ValueError(f"model must have nq={C.NQ}, nv={C.NV} (the robot only), got nq={model.nq}, nv={model.nv}")
        try:
            trunk = model.body(C.TRUNK_BODY).id
        except KeyError:
            raise ValueError(f"model must have a body {C.TRUNK_BODY!r}") from None
        free = int(model.body_jntadr[trunk])
        if (
            model.body_jntnum[trunk] != 1
            or model.jnt_type[free] != mujoco.mjtJoint.mjJNT_FREE
            or model.jnt_dofadr[free] != 0
            or np.any(model.jnt_pos[free] != 0.0)
        ):
            raise ValueError(f"body {C.TRUNK_BODY!r} must carry exactly one free joint at its origin on dofs 0-5")
        robot_bodies = {trunk}
        pos, rot, axis = np.zeros((4, 3, 3)), np.zeros((4, 3, 3, 3)), np.zeros((4, 3, 3))
        mass, com, inertia = np.zeros((4, 3)), np.zeros((4, 3, 3)), np.zeros((4, 3, 3, 3))
        foot = np.zeros((4, 3))
        for i, leg in enumerate(C.LEG_NAMES):
            parent_body, prev_joint = trunk, -1
            for k, kind in enumerate(C.JOINT_KINDS):
                name = C.joint_name(leg, kind)
                try:
                    j = model.joint(name).id
                except KeyError:
                    raise ValueError(f"model has no joint {name!r}") from None
                b = int(model.jnt_bodyid[j])
                if model.jnt_type[j] != mujoco.mjtJoint.mjJNT_HINGE or model.jnt_dofadr[j] != 6 + 3 * i + k:
                    raise ValueError(f"joint {name} must be a hinge on dof {6 + 3 * i + k}")
                if np.any(model.jnt_pos[j] != 0.0):
                    raise ValueError(f"joint {name} must sit at its body's origin, got pos {model.jnt_pos[j].tolist()}")
                if b == parent_body and j == prev_joint + 1:  # the next joint of the same body: no offset
                    pos[i, k], rot[i, k] = 0.0, np.eye(3)
                elif model.body_parentid[b] == parent_body and j == model.body_jntadr[b]:
                    pos[i, k], rot[i, k] = model.body_pos[b], _quat_to_mat(model.body_quat[b])
                else:
                    raise ValueError(
                        f"joint {name} must be the next joint of body {model.body(parent_body).name!r} or the first "
                        f"of one of its children (the chain trunk -> HAA -> HFE -> KFE)"
                    )
                axis[i, k] = model.jnt_axis[j]
                last_of_body = j == model.body_jntadr[b] + model.body_jntnum[b] - 1
                if last_of_body:
                    mass[i, k] = model.body_mass[b]
                    com[i, k] = model.body_ipos[b]
                    Ri = _quat_to_mat(model.body_iquat[b])
                    inertia[i, k] = Ri @ np.diag(model.body_inertia[b]) @ Ri.T
                parent_body, prev_joint = b, j
                robot_bodies.add(b)
            _check_axes(rot[i], axis[i], leg)
            try:
                site = model.site(C.foot_site(leg)).id
            except KeyError:
                raise ValueError(f"model has no site {C.foot_site(leg)!r}") from None
            if model.site_bodyid[site] != parent_body:
                raise ValueError(f"site {C.foot_site(leg)} must belong to the body of {C.joint_name(leg, 'KFE')}")
            foot[i] = model.site_pos[site]
        for b in range(model.nbody):
            if b not in robot_bodies and _is_descendant(model, b, trunk):
                raise ValueError(f"body {model.body(b).name!r} carries no leg joint: the robot must be trunk + legs")
        Rt = _quat_to_mat(model.body_iquat[trunk])
        return cls(
            name="MjModel",
            gravity_W=model.opt.gravity.copy(),
            trunk_mass=float(model.body_mass[trunk]),
            trunk_com=model.body_ipos[trunk].copy(),
            trunk_inertia=Rt @ np.diag(model.body_inertia[trunk]) @ Rt.T,
            joint_pos=pos,
            joint_rot=rot,
            joint_axis=axis,
            link_mass=mass,
            link_com=com,
            link_inertia=inertia,
            foot=foot,
            armature=model.dof_armature[6 : C.NV].copy(),
        )


def leg_chains(robot: RobotDescription | mujoco.MjModel | LegChains) -> LegChains:
    """:class:`LegChains` of a description, an MjModel, or the chains themselves.

    :raises ValueError: for any other type, or an MjModel of another structure (see :meth:`LegChains.from_mjmodel`).
    """
    if isinstance(robot, LegChains):
        return robot
    if isinstance(robot, RobotDescription):
        return LegChains.from_description(robot)
    if isinstance(robot, mujoco.MjModel):
        return LegChains.from_mjmodel(robot)
    raise ValueError(f"robot must be a RobotDescription or a mujoco.MjModel, got {type(robot).__name__}")


def _quat_to_mat(quat: np.ndarray) -> np.ndarray:
    R = np.empty(9)
    mujoco.mju_quat2Mat(R, np.asarray(quat, dtype=float))
    return R.reshape(3, 3)


def _is_descendant(model: mujoco.MjModel, body: int, root: int) -> bool:
    while body > 0:
        if body == root:
            return True
        body = int(model.body_parentid[body])
    return False


def _check_axes(rot: np.ndarray, axis: np.ndarray, leg: str) -> None:
    """HAA about trunk x, HFE and KFE about trunk y at zero angles (the rule of :class:`RobotDescription`)."""
    R = np.eye(3)
    for k, kind in enumerate(C.JOINT_KINDS):
        R = R @ rot[k]
        a = R @ axis[k]
        if np.linalg.norm(np.cross(a, _NOMINAL_AXES[k])) > AXIS_TOLERANCE:
            raise ValueError(
                f"joint {C.joint_name(leg, kind)} must turn about trunk {'x' if k == 0 else 'y'} at zero angles "
                f"(the HAA-HFE-KFE chain), got axis {np.round(a, 6).tolist()}"
            )
