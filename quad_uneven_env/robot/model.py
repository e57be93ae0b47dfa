"""Build the MuJoCo model of the paper's robot (Table 1) as generated MJCF.

``robot_mjcf`` gives the robot alone (what Pinocchio loads); ``scene_mjcf`` adds the
terrain height field, actuators, lights and a tracking camera for the environment.
"""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np

from quad_uneven_env import constants as C
from quad_uneven_env.config import LinkParams, RobotConfig, load_robot_config
from quad_uneven_env.robot.kinematics import hip_positions_B, standing_joint_angles

MIN_INERTIA = mujoco.mjMINVAL
"""kg m^2: the smallest principal inertia MuJoCo accepts; replaces Table 1's zeros."""

NOMINAL_HIP_HEIGHT = 0.34
"""m: hip-to-foot-point height of the default standing pose (81 % of the leg length)."""


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


def _fmt(values) -> str:
    return " ".join(f"{float(v):.10g}" for v in np.atleast_1d(values))


def _link_inertia(link: LinkParams) -> np.ndarray:
    """(Ixx, Iyy, Izz) in the link frame whose z axis is the link's long axis."""
    axial, other1, other2 = (max(v, MIN_INERTIA) for v in link.inertia)
    return np.array([other1, other2, axial])


def _leg_xml(cfg: RobotConfig, leg: str, hip_pos: np.ndarray, limb: str) -> str:
    rng = cfg.joint_range
    kfe = cfg.knee_range(leg)
    l1, l2 = cfg.thigh.length, cfg.shank.length
    group = f'contype="{C.ROBOT_CONTYPE}" conaffinity="{C.ROBOT_CONAFFINITY}"'
    limb_group = f"{group} {limb}".rstrip()
    fr = f'friction="{cfg.friction:.6g} 0.005 0.0001"'
    return f"""
      <body name="{C.thigh_body(leg)}" pos="{_fmt(hip_pos)}">
        <joint name="{C.joint_name(leg, "HAA")}" axis="1 0 0" range="{_fmt(rng["HAA"])}" damping="{cfg.joint_damping:.6g}" armature="{cfg.joint_armature:.6g}"/>
        <joint name="{C.joint_name(leg, "HFE")}" axis="0 1 0" range="{_fmt(rng["HFE"])}" damping="{cfg.joint_damping:.6g}" armature="{cfg.joint_armature:.6g}"/>
        <inertial pos="0 0 {-cfg.thigh.com:.10g}" mass="{cfg.thigh.mass:.10g}" diaginertia="{_fmt(_link_inertia(cfg.thigh))}"/>
        <site name="{C.hip_site(leg)}" pos="0 0 0" size="0.01"/>
        <geom name="{leg}_thigh_geom" type="capsule" fromto="0 0 0 0 0 {-l1:.10g}" size="{cfg.link_radius:.6g}" mass="0" {limb_group} {fr} rgba="0.3 0.3 0.35 1"/>
        <body name="{C.shank_body(leg)}" pos="0 0 {-l1:.10g}">
          <joint name="{C.joint_name(leg, "KFE")}" axis="0 1 0" range="{_fmt(kfe)}" damping="{cfg.joint_damping:.6g}" armature="{cfg.joint_armature:.6g}"/>
          <inertial pos="0 0 {-cfg.shank.com:.10g}" mass="{cfg.shank.mass:.10g}" diaginertia="{_fmt(_link_inertia(cfg.shank))}"/>
          <geom name="{leg}_shank_geom" type="capsule" fromto="0 0 0 0 0 {-(l2 - cfg.foot_radius):.10g}" size="{0.7 * cfg.link_radius:.6g}" mass="0" {limb_group} {fr} rgba="0.55 0.55 0.6 1"/>
          <geom name="{C.foot_geom(leg)}" type="sphere" pos="0 0 {-l2:.10g}" size="{cfg.foot_radius:.6g}" mass="0" {group} {fr} rgba="0.1 0.1 0.1 1"/>
          <site name="{C.foot_site(leg)}" pos="0 0 {-l2:.10g}" size="0.012" rgba="1 0.2 0.2 1"/>
        </body>
      </body>"""


def _trunk_xml(cfg: RobotConfig, with_camera: bool, limb: str = "") -> str:
    """The trunk body and its legs; ``limb``: extra MJCF attributes of the trunk, thigh and shank geoms."""
    b = cfg.body
    half = np.asarray(b.size) / 2.0
    hips = hip_positions_B(cfg)
    legs = "".join(_leg_xml(cfg, leg, hips[i], limb) for i, leg in enumerate(C.LEG_NAMES))
    camera = track_camera_xml() if with_camera else ""
    h0 = NOMINAL_HIP_HEIGHT + cfg.foot_radius
    return f"""
    <body name="{C.TRUNK_BODY}" pos="0 0 {h0:.10g}">
      <freejoint name="{C.ROOT_JOINT}"/>
      <inertial pos="0 0 0" mass="{b.mass:.10g}" diaginertia="{_fmt(b.inertia)}"/>
      <geom name="{C.TRUNK_GEOM}" type="box" size="{_fmt(half)}" mass="0" contype="{C.ROBOT_CONTYPE}" conaffinity="{C.ROBOT_CONAFFINITY}" {limb} rgba="0.85 0.55 0.15 1"/>
      {camera}{legs}
    </body>"""


def robot_mjcf(cfg: RobotConfig | None = None) -> str:
    """MJCF of the robot alone (no terrain, no actuators): loadable by ``pin.buildModelFromMJCF``.

    :param cfg: robot parameters; default ``configs/robot/paper.yaml`` (Table 1).
    :return: the MJCF document as a string (write it to a file for Pinocchio).
    """
    cfg = cfg or load_robot_config()
    return f"""<mujoco model="{cfg.name}_robot">
  <compiler angle="radian" autolimits="true"/>
  <worldbody>{_trunk_xml(cfg, with_camera=False)}
  </worldbody>
</mujoco>
"""


def actuators_xml(cfg: RobotConfig) -> str:
    """Direct-drive torque motors (N m), one per joint, limited to the config's torque limits."""
    lines = []
    for leg in C.LEG_NAMES:
        for kind in C.JOINT_KINDS:
            lim = cfg.torque_limit[kind]
            j = C.joint_name(leg, kind)
            lines.append(f'    <motor name="{j}_motor" joint="{j}" gear="1" ctrlrange="{-lim:.6g} {lim:.6g}"/>')
    return "\n".join(lines)


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


def home_qpos(cfg: RobotConfig, ground_height: float = 0.0) -> np.ndarray:
    """Standing configuration (19,) with the feet touching flat ground at ``ground_height`` (m)."""
    q = np.zeros(C.NQ)
    q[2] = ground_height + NOMINAL_HIP_HEIGHT + cfg.foot_radius
    q[3] = 1.0
    q[7:] = standing_joint_angles(cfg, NOMINAL_HIP_HEIGHT)
    return q


def scene_mjcf(
    cfg: RobotConfig,
    hfield_asset: str,
    hfield_geom: str,
    physics: PhysicsOptions | None = None,
) -> str:
    """MJCF of the robot on a height-field terrain with actuators, lights and a tracking camera.

    :param hfield_asset: the ``<hfield .../>`` asset element of the terrain.
    :param hfield_geom: the ``<geom type="hfield" .../>`` element of the terrain.
    """
    p = physics or PhysicsOptions()
    return scene_document(
        cfg.name, _trunk_xml(cfg, with_camera=True, limb=limb_attributes(p)), actuators_xml(cfg), hfield_asset,
        hfield_geom, p,
    )  # fmt: skip


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
