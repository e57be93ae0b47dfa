"""The MuJoCo model of any :class:`~quad_uneven_env.robot.quadruped.RobotDescription`, as generated MJCF.

:func:`robot_mjcf` gives the robot alone (what Pinocchio and the MuJoCo dynamics backend load); :func:`scene_mjcf`
adds the terrain height field, actuators, contact sensors, lights and a tracking camera for the environment.

The body tree is the description's: trunk -> hip link (HAA) -> thigh (HFE) -> shank (KFE), each body at its
joint's placement, each with its link's full inertia tensor, so the model has the description's rigid-body
dynamics (a URDF's, or Table 1's). A massless hip link at the HFE origin (the paper's robot) is no body of its own:
HAA and HFE then move the thigh body, as a moving MuJoCo body needs mass. The geometry is primitive (URDF meshes
are mostly ``.dae``, which MuJoCo cannot read): the trunk box (the description's, else the box spanned by the
hips), a capsule from each HFE to its knee and from each knee to where its foot sphere begins, and a sphere at each
foot point. Names, actuators (torque motors at the description's limits) and sensors are those of
:mod:`quad_uneven_env.constants`, so the env and its measurements read every robot alike. Numbers are written at
full precision (round-trip ``repr``), so the model has the description's exact values.
"""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np

from quad_uneven_env import constants as C
from quad_uneven_env.robot.description import load_robot
from quad_uneven_env.robot.quadruped import JointDescription, LinkInertia, RobotDescription


@dataclasses.dataclass(frozen=True)
class PhysicsOptions:
    """Simulator settings the paper leaves open."""

    timestep: float = 0.002
    """physics step (s); <= 2 ms."""
    integrator: str = "implicitfast"
    """MuJoCo integrator."""
    cone: str = "elliptic"
    """friction cone model; elliptic with a high impratio keeps stance feet from creeping (pyramidal
    cones make the solver ~3 x cheaper per contact but let the expert's stance feet slide out of
    reach: docs/results.md section 7)."""
    jacobian: str = "sparse"
    """constraint Jacobian layout. MuJoCo's "auto" picks dense below 60 dofs, but each contact row of
    this tree touches at most 9 of the 18 dofs: sparse gives the same solution (to rounding, ~1e-14)
    at 25-35 % less time per physics step in contact-rich states (docs/results.md section 7)."""
    native_ccd: bool = False
    """MuJoCo's own convex collider (GJK/EPA, the default since 3.2) instead of libccd's MPR for the
    height-field prisms. Under impacts a native-CCD sphere deeper than about half its radius gets
    contacts from the prisms' interior side walls, whose horizontal normals and vertical friction
    hold it in the ground ("sucked in"): under random torques feet were more than 1 cm deep for two
    thirds of all foot-steps, up to 13 cm, with ~85 contacts a step. libccd's MPR reports the top faces
    and lets them out (docs/results.md section 7)."""
    impratio: float = 10.0
    """ratio of frictional to normal constraint impedance (stiff friction: the paper assumes no slip)."""
    contact_timeconst: float = 0.0075
    """s: time constant of the feet's and the terrain's contacts (MJCF geom ``solref[0]``; MuJoCo's
    default is 0.02; the limbs have their own, ``limb_contact_timeconst``). At 0.02 s an impacting
    foot sinks deeper into the 2 cm height field and a standing foot ~1.1 mm; at 7.5 ms standing
    penetration is ~0.3 mm with 1-2 contacts a foot (docs/results.md section 7)."""
    contact_dampratio: float = 1.0
    """damping ratio of every contact (MJCF geom ``solref[1]``; 1 = critical, MuJoCo's default)."""
    limb_contact_timeconst: float | None = None
    """s: time constant of the contacts of the trunk, thighs and shanks with the terrain (None: 2 x
    ``timestep``, the stiffest value MuJoCo keeps stable). These geoms carry ``priority="1"`` so their
    own ``solref`` (not the mean with the terrain's) sets the contact; their friction equals the
    terrain's (randomization sets both), so only the stiffness differs from the feet. An impacting limb
    is pushed out sooner, before it drags its foot into the prisms' side walls: with libccd, feet more
    than 1 cm deep under random torques fall from 14 % of foot-steps (7.5 ms limbs) to 1.6 %
    (docs/results.md section 7). The feet keep ``contact_timeconst``: the expert touches the ground
    only with its feet, so its walking does not change."""

    def limb_timeconst(self) -> float:
        """s: the limbs' contact time constant (``limb_contact_timeconst`` or 2 x ``timestep``)."""
        if self.limb_contact_timeconst is not None:
            return float(self.limb_contact_timeconst)
        return 2.0 * self.timestep


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


def shank_end(desc: RobotDescription, i: int) -> np.ndarray:
    """(3,) m, shank frame: the end of leg ``i``'s shank capsule, where its foot sphere begins on the knee-foot
    line (two-link legs: ``shank - foot_radius`` straight below the knee)."""
    r = desc.foot_radius
    if desc.two_link is not None:
        return np.array([0.0, 0.0, -(desc.two_link.shank - r)])
    foot = desc.legs[i].foot
    return foot * (1.0 - min(r / max(np.linalg.norm(foot), 1e-9), 1.0))


def _leg_xml(desc: RobotDescription, i: int, limb: str) -> str:
    leg = desc.legs[i]
    name = leg.name
    group = f'contype="{C.ROBOT_CONTYPE}" conaffinity="{C.ROBOT_CONAFFINITY}"'
    fr = f'friction="{desc.friction:.6g} 0.005 0.0001"'
    limb_group = f"{group} {limb} {fr}".replace("  ", " ")
    r = desc.link_radius
    foot = leg.foot
    thigh = _capsule(f"{name}_thigh_geom", np.zeros(3), leg.kfe.pos, r, limb_group, "0.3 0.3 0.35 1")
    shank = _capsule(f"{name}_shank_geom", np.zeros(3), shank_end(desc, i), 0.7 * r, limb_group, "0.55 0.55 0.6 1")
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
    """The trunk body and its legs; ``limb``: extra MJCF attributes of the trunk, thigh and shank geoms."""
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


def robot_mjcf(desc: RobotDescription | None = None) -> str:
    """MJCF of the robot alone (no terrain, no actuators), standing over the origin: loadable by
    ``pin.buildModelFromMJCF``.

    :param desc: the robot; default the paper's (``configs/robot/paper.yaml``, Table 1).
    :return: the MJCF document as a string (write it to a file for Pinocchio).
    """
    desc = load_robot("paper") if desc is None else desc
    return f"""<mujoco model="{desc.name}_robot">
  <compiler angle="radian" autolimits="true"/>
  <worldbody>{_trunk_xml(desc, with_camera=False)}
  </worldbody>
</mujoco>
"""


def actuators_xml(desc: RobotDescription) -> str:
    """Direct-drive torque motors (N m), one per joint, limited to the description's torque limits."""
    return "\n".join(
        f'    <motor name="{j}_motor" joint="{j}" gear="1" ctrlrange="{-lim:.6g} {lim:.6g}"/>'
        for j, lim in zip(C.JOINT_NAMES, desc.torque_limits, strict=True)
    )


def contact_sensors_xml() -> str:
    """Contact sensors against the terrain: per foot (count, net force, force-weighted point),
    the whole robot (count, net force) and the trunk (count). MuJoCo reports the force that
    the robot geoms exert on the terrain, in the world frame."""
    feet = "\n".join(
        f'    <contact name="{C.foot_contact_sensor(leg)}" geom1="{C.foot_geom(leg)}" geom2="{C.TERRAIN_GEOM}" '
        f'num="1" data="found force pos" reduce="netforce"/>'
        for leg in C.LEG_NAMES
    )
    return f"""{feet}
    <contact name="{C.ROBOT_CONTACT_SENSOR}" subtree1="{C.TRUNK_BODY}" geom2="{C.TERRAIN_GEOM}" num="1" data="found force" reduce="netforce"/>
    <contact name="{C.TRUNK_CONTACT_SENSOR}" geom1="{C.TRUNK_GEOM}" geom2="{C.TERRAIN_GEOM}" num="1" data="found" reduce="netforce"/>"""


def scene_mjcf(
    desc: RobotDescription,
    hfield_asset: str,
    hfield_geom: str,
    physics: PhysicsOptions | None = None,
) -> str:
    """MJCF of the robot on a height-field terrain with actuators, contact sensors, lights and a tracking camera.

    :param hfield_asset: the ``<hfield .../>`` asset element of the terrain.
    :param hfield_geom: the ``<geom type="hfield" .../>`` element of the terrain.
    """
    p = physics or PhysicsOptions()
    trunk = _trunk_xml(desc, with_camera=True, limb=limb_attributes(p))
    return scene_document(desc.name, trunk, actuators_xml(desc), hfield_asset, hfield_geom, p)


def limb_attributes(physics: PhysicsOptions) -> str:
    """MJCF attributes of the trunk, thigh and shank geoms: their own contact time constant (priority 1)."""
    return f'priority="1" solref="{physics.limb_timeconst():.6g} {physics.contact_dampratio:.6g}"'


def track_camera_xml() -> str:
    """The camera that follows the robot (a child of the trunk body)."""
    return f'<camera name="{C.TRACK_CAMERA}" mode="trackcom" pos="0.3 -1.7 0.75" xyaxes="1 0 0 0 0.4 1"/>'


def scene_document(
    name: str, trunk: str, actuators: str, hfield_asset: str, hfield_geom: str, p: PhysicsOptions
) -> str:
    """The scene around a robot: options, contact defaults, sky, the terrain, ``trunk`` (the robot's body
    tree), ``actuators`` (``<motor>`` lines) and the contact sensors of :func:`contact_sensors_xml`."""
    return f"""<mujoco model="{name}_on_terrain">
  <compiler angle="radian" autolimits="true"/>
  <option timestep="{p.timestep:.6g}" integrator="{p.integrator}" cone="{p.cone}" jacobian="{p.jacobian}" impratio="{p.impratio:.6g}">
    <flag nativeccd="{"enable" if p.native_ccd else "disable"}"/>
  </option>
  <default>
    <geom solref="{p.contact_timeconst:.6g} {p.contact_dampratio:.6g}"/>
  </default>
  <visual>
    <global offwidth="1280" offheight="720"/>
    <headlight ambient="0.35 0.35 0.35" diffuse="0.6 0.6 0.6"/>
  </visual>
  <asset>
    <texture name="sky" type="skybox" builtin="gradient" rgb1="0.55 0.7 0.9" rgb2="0.1 0.15 0.25" width="256" height="256"/>
    <texture name="grid" type="2d" builtin="checker" rgb1="0.45 0.5 0.45" rgb2="0.35 0.4 0.35" width="256" height="256"/>
    <material name="terrain_mat" texture="grid" texrepeat="20 20" texuniform="false"/>
    {hfield_asset}
  </asset>
  <worldbody>
    <light name="sun" directional="true" pos="0 0 5" dir="-0.3 0.3 -1" castshadow="true"/>
    {hfield_geom}{trunk}
  </worldbody>
  <actuator>
{actuators}
  </actuator>
  <sensor>
{contact_sensors_xml()}
  </sensor>
</mujoco>
"""
