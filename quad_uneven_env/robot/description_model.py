"""MJCF of any :class:`~quad_uneven_env.robot.description.RobotDescription` (a URDF robot's simulated model).

The body tree is the description's: trunk -> hip link (HAA) -> thigh (HFE) -> shank (KFE), each body at its
joint's placement, each with its link's full inertia tensor, so the model has the URDF's rigid-body dynamics.
The geometry is primitive (URDF meshes are mostly ``.dae``, which MuJoCo cannot read): the trunk box (the URDF's
collision box, else the box spanned by the hips), a capsule from each HFE to its knee and from each knee to its
foot, and a sphere at each foot point. Names, actuators (torque motors at the description's limits) and sensors
are those of :mod:`quad_uneven_env.constants` and :mod:`quad_uneven_env.robot.model`, so the env and its
measurements read every robot alike. The paper's robot keeps its own generator (:mod:`~quad_uneven_env.robot.model`).
"""

from __future__ import annotations

import mujoco
import numpy as np

from quad_uneven_env import constants as C
from quad_uneven_env.robot.description import JointDescription, LinkInertia, RobotDescription
from quad_uneven_env.robot.leg_chain import feet_positions_B
from quad_uneven_env.robot.model import (
    PhysicsOptions,
    limb_attributes,
    scene_document,
    track_camera_xml,
)


def hip_link_body(leg: str) -> str:
    """MJCF body moved by HAA of ``leg`` (the link between HAA and HFE)."""
    return f"{leg}_hip_link"


def _v(values) -> str:
    """Numbers at full precision (round-trip repr), so the model has the description's exact values."""
    return " ".join(repr(float(v)) for v in np.ravel(values))


def _quat(R: np.ndarray) -> str:
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, np.ascontiguousarray(R, dtype=float).ravel())
    return _v(q)


def _inertial(link: LinkInertia) -> str:
    """The ``<inertial>`` element (none for a massless link); a diagonal tensor as ``diaginertia``, which keeps
    MuJoCo's smallest principal inertias exact (its eigen-solver of ``fullinertia`` does not)."""
    if link.mass == 0:
        return ""
    I = link.inertia
    if np.count_nonzero(I - np.diag(np.diag(I))) == 0:
        return f'<inertial pos="{_v(link.com)}" mass="{link.mass!r}" diaginertia="{_v(np.diag(I))}"/>'
    full = (I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2])
    return f'<inertial pos="{_v(link.com)}" mass="{link.mass!r}" fullinertia="{_v(full)}"/>'


def _joint(leg: str, kind: str, j: JointDescription) -> str:
    return (
        f'<joint name="{C.joint_name(leg, kind)}" axis="{_v(j.axis)}" range="{_v(j.range)}" '
        f'damping="{j.damping!r}" armature="{j.armature!r}"/>'
    )


def _capsule(name: str, a: np.ndarray, b: np.ndarray, radius: float, attrs: str, rgba: str) -> str:
    if np.linalg.norm(b - a) < 1e-6:
        return ""
    return (
        f'<geom name="{name}" type="capsule" fromto="{_v(a)} {_v(b)}" size="{radius:.6g}" mass="0" {attrs} '
        f'rgba="{rgba}"/>'
    )


def _leg_xml(desc: RobotDescription, i: int, limb: str) -> str:
    leg = desc.legs[i]
    name = leg.name
    group = f'contype="{C.ROBOT_CONTYPE}" conaffinity="{C.ROBOT_CONAFFINITY}"'
    fr = f'friction="{desc.friction:.6g} 0.005 0.0001"'
    limb_group = f"{group} {limb} {fr}".replace("  ", " ")
    r = desc.link_radius
    foot = leg.foot
    shank_end = foot * (1.0 - min(desc.foot_radius / max(np.linalg.norm(foot), 1e-9), 1.0))
    thigh = _capsule(f"{name}_thigh_geom", np.zeros(3), leg.kfe.pos, r, limb_group, "0.3 0.3 0.35 1")
    shank = _capsule(f"{name}_shank_geom", np.zeros(3), shank_end, 0.7 * r, limb_group, "0.55 0.55 0.6 1")
    inner = f"""
          {_joint(name, "HFE", leg.hfe)}
          {_inertial(leg.hfe.link)}
          <site name="{C.hip_site(name)}" pos="0 0 0" size="0.01"/>
          {thigh}
          <body name="{C.shank_body(name)}" pos="{_v(leg.kfe.pos)}" quat="{_quat(leg.kfe.rot)}">
            {_joint(name, "KFE", leg.kfe)}
            {_inertial(leg.kfe.link)}
            {shank}
            <geom name="{C.foot_geom(name)}" type="sphere" pos="{_v(foot)}" size="{desc.foot_radius:.6g}" mass="0" {group} {fr} rgba="0.1 0.1 0.1 1"/>
            <site name="{C.foot_site(name)}" pos="{_v(foot)}" size="0.012" rgba="1 0.2 0.2 1"/>
          </body>"""
    if leg.haa.link.mass == 0 and not np.any(leg.hfe.pos) and np.array_equal(leg.hfe.rot, np.eye(3)):
        # a massless hip link at the HFE origin (the paper's robot): HAA and HFE move one body, as in MuJoCo
        # a moving body needs mass
        return f"""
      <body name="{C.thigh_body(name)}" pos="{_v(leg.haa.pos)}" quat="{_quat(leg.haa.rot)}">
        {_joint(name, "HAA", leg.haa)}{inner}
      </body>"""
    return f"""
      <body name="{hip_link_body(name)}" pos="{_v(leg.haa.pos)}" quat="{_quat(leg.haa.rot)}">
        {_joint(name, "HAA", leg.haa)}
        {_inertial(leg.haa.link)}
        <body name="{C.thigh_body(name)}" pos="{_v(leg.hfe.pos)}" quat="{_quat(leg.hfe.rot)}">{inner}
        </body>
      </body>"""


def trunk_box(desc: RobotDescription) -> tuple[np.ndarray, np.ndarray]:
    """(centre, half sizes) m of the trunk's collision box, trunk frame: the description's, else the box whose
    corners are the HAA origins with a height of half the hips' spacing across."""
    if desc.trunk_box is not None:
        return desc.trunk_box
    hips = desc.hip_positions_B
    half = np.abs(hips).max(axis=0)
    half[2] = max(half[2], 0.25 * half[1])
    return np.array([0.0, 0.0, hips[:, 2].mean()]), half


def _trunk_xml(desc: RobotDescription, with_camera: bool, limb: str = "") -> str:
    centre, half = trunk_box(desc)
    legs = "".join(_leg_xml(desc, i, limb) for i in range(C.N_LEGS))
    camera = track_camera_xml() if with_camera else ""
    return f"""
    <body name="{C.TRUNK_BODY}" pos="0 0 {desc.standing_height!r}">
      <freejoint name="{C.ROOT_JOINT}"/>
      {_inertial(desc.trunk)}
      <geom name="{C.TRUNK_GEOM}" type="box" pos="{_v(centre)}" size="{_v(half)}" mass="0" contype="{C.ROBOT_CONTYPE}" conaffinity="{C.ROBOT_CONAFFINITY}" {limb} rgba="0.85 0.55 0.15 1"/>
      {camera}{legs}
    </body>"""


def description_actuators_xml(desc: RobotDescription) -> str:
    """Direct-drive torque motors (N m), one per joint, limited to the description's torque limits."""
    limits = desc.torque_limits
    return "\n".join(
        f'    <motor name="{j}_motor" joint="{j}" gear="1" ctrlrange="{-lim:.6g} {lim:.6g}"/>'
        for j, lim in zip(C.JOINT_NAMES, limits, strict=True)
    )


def description_robot_mjcf(desc: RobotDescription) -> str:
    """MJCF of the robot alone (no terrain, no actuators), standing over the origin."""
    return f"""<mujoco model="{desc.name}_robot">
  <compiler angle="radian" autolimits="true"/>
  <worldbody>{_trunk_xml(desc, with_camera=False)}
  </worldbody>
</mujoco>
"""


def description_scene_mjcf(
    desc: RobotDescription, hfield_asset: str, hfield_geom: str, physics: PhysicsOptions | None = None
) -> str:
    """MJCF of the robot on a height-field terrain (as :func:`quad_uneven_env.robot.model.scene_mjcf`)."""
    p = physics or PhysicsOptions()
    trunk = _trunk_xml(desc, with_camera=True, limb=limb_attributes(p))
    return scene_document(desc.name, trunk, description_actuators_xml(desc), hfield_asset, hfield_geom, p)


def description_home_qpos(desc: RobotDescription, ground_height: float = 0.0) -> np.ndarray:
    """(19,) the standing pose over the origin with the lowest foot sphere on flat ground at ``ground_height``."""
    q = np.zeros(C.NQ)
    q[2] = ground_height + desc.standing_height
    q[3] = 1.0
    q[7:] = desc.standing_joints
    return q


def standing_feet_B(desc: RobotDescription) -> np.ndarray:
    """(4, 3) m, the foot points in the trunk frame in the standing pose."""
    return feet_positions_B(desc, desc.standing_joints)
