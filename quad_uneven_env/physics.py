"""Named, vectorised accessors to the robot in a MuJoCo model/data pair.

:class:`RobotIndex` resolves every id once; :func:`measure_contacts` turns MuJoCo's contact
sensors into per-foot world-frame forces and points, :func:`measure_contacts_reference` does
the same from the raw contact list (the test reference). Nothing here allocates more than a few
small arrays: it runs every control step.

**The contact rule** (one rule for the sensors, the raw contact list and the compiled measurement
of :mod:`quad_uneven_env.measurement_kernels`):

* a foot is *in contact* when MuJoCo has at least one active contact (one with constraint rows)
  between its sphere and the terrain, whatever the force;
* its *contact point* is the mean of its contact positions weighted by the norms of their
  contact-frame forces (MuJoCo's ``reduce="netforce"``) when the net terrain force on the foot is
  at least ``MIN_FOOT_FORCE``; otherwise (no contact, or a contact carrying no force, e.g. a sphere
  already separating, for which the sensor reports the point (0, 0, 0)) it is the foot's lowest
  point, the foot site minus the foot radius along world z.
"""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np

from quad_uneven_env import constants as C

MIN_FOOT_FORCE = 1e-9
"""N: below this net terrain force a foot in contact has no force-weighted point (see the contact rule)."""


@dataclasses.dataclass(frozen=True)
class RobotIndex:
    """Ids and addresses of the robot's named elements in one compiled model."""

    trunk_body: int
    trunk_geom: int
    terrain_geom: int
    hfield: int
    foot_sites: np.ndarray  # (4,) site ids, leg order
    foot_geoms: np.ndarray  # (4,) geom ids, leg order
    robot_geoms: np.ndarray  # (ngeom,) bool: geom belongs to the robot
    foot_of_geom: np.ndarray  # (ngeom,) leg index of a foot geom, -1 otherwise
    torque_limit: np.ndarray  # (12,) N m, from the actuators' ctrlrange
    total_mass: float  # kg
    foot_sensor_adr: np.ndarray  # (4,) sensordata address of each foot's contact sensor
    robot_sensor_adr: int  # sensordata address of the whole-robot contact sensor
    trunk_sensor_adr: int  # sensordata address of the trunk contact sensor

    @property
    def foot_sensor_rows(self) -> np.ndarray:
        """(4, 7) sensordata indices of the foot sensors (found, force, point)."""
        return self._foot_sensor_rows

    def __post_init__(self) -> None:
        object.__setattr__(self, "_foot_sensor_rows", self.foot_sensor_adr[:, None] + np.arange(7))

    @classmethod
    def from_model(cls, model: mujoco.MjModel) -> RobotIndex:
        """Resolve all names of :mod:`quad_uneven_env.constants` in ``model``."""
        foot_geoms = np.array([model.geom(g).id for g in C.FOOT_GEOMS])
        trunk = model.body(C.TRUNK_BODY).id
        robot = np.zeros(model.ngeom, dtype=bool)
        for g in range(model.ngeom):
            b = model.geom_bodyid[g]
            while b not in (0, trunk):
                b = model.body_parentid[b]
            robot[g] = b == trunk
        foot_of_geom = np.full(model.ngeom, -1)
        foot_of_geom[foot_geoms] = np.arange(C.N_LEGS)
        act = [model.actuator(a).id for a in C.ACTUATOR_NAMES]
        return cls(
            trunk_body=trunk,
            trunk_geom=model.geom(C.TRUNK_GEOM).id,
            terrain_geom=model.geom(C.TERRAIN_GEOM).id,
            hfield=model.hfield(C.TERRAIN_HFIELD).id,
            foot_sites=np.array([model.site(s).id for s in C.FOOT_SITES]),
            foot_geoms=foot_geoms,
            robot_geoms=robot,
            foot_of_geom=foot_of_geom,
            torque_limit=model.actuator_ctrlrange[act, 1].copy(),
            total_mass=float(model.body_subtreemass[trunk]),
            foot_sensor_adr=np.array([model.sensor(C.foot_contact_sensor(leg)).adr[0] for leg in C.LEG_NAMES]),
            robot_sensor_adr=int(model.sensor(C.ROBOT_CONTACT_SENSOR).adr[0]),
            trunk_sensor_adr=int(model.sensor(C.TRUNK_CONTACT_SENSOR).adr[0]),
        )


@dataclasses.dataclass
class ContactMeasurement:
    """Contacts between the robot and the terrain at one instant (world frame, SI)."""

    foot_forces: np.ndarray
    """(4, 3) force the terrain applies on each foot (N), zero when not in contact."""
    foot_contact: np.ndarray
    """(4,) bool, foot touches the terrain."""
    foot_points: np.ndarray
    """(4, 3) force-weighted contact point of each foot (m); its lowest point (site minus radius) when the foot
    is not in contact or carries less than ``MIN_FOOT_FORCE`` (the module's contact rule)."""
    total_force: np.ndarray
    """(3,) sum of all terrain forces on the robot, feet and other links (N)."""
    trunk_contact: bool
    """the trunk touches the terrain."""
    other_contact: bool
    """a thigh or shank (not a foot) touches the terrain."""


def measure_contacts(
    model: mujoco.MjModel, data: mujoco.MjData, idx: RobotIndex, foot_radius: float
) -> ContactMeasurement:
    """Per-foot contact forces (N, world frame) from MuJoCo's contact sensors.

    The sensors (see :func:`quad_uneven_env.robot.model.contact_sensors_xml`) are evaluated by
    MuJoCo after its constraint solve; they report the force the robot exerts on the terrain,
    so the force on the robot is its negative. :func:`measure_contacts_reference` computes the
    same from the raw contact list (the test reference).
    """
    sd = data.sensordata
    foot = sd[idx.foot_sensor_rows]  # (4, 7): found, force (3), pos (3)
    contact = foot[:, 0] > 0
    foot_forces = -foot[:, 1:4]
    loaded = contact & (np.einsum("ij,ij->i", foot_forces, foot_forces) >= MIN_FOOT_FORCE * MIN_FOOT_FORCE)
    points = data.site_xpos[idx.foot_sites].copy()
    points[:, 2] -= foot_radius
    points[loaded] = foot[loaded, 4:7]
    r = idx.robot_sensor_adr
    n_robot = sd[r]
    n_trunk = sd[idx.trunk_sensor_adr]
    return ContactMeasurement(
        foot_forces=foot_forces,
        foot_contact=contact,
        foot_points=points,
        total_force=-sd[r + 1 : r + 4],
        trunk_contact=bool(n_trunk > 0),
        other_contact=bool(n_robot - foot[:, 0].sum() - n_trunk > 0),
    )


def measure_contacts_reference(
    model: mujoco.MjModel, data: mujoco.MjData, idx: RobotIndex, foot_radius: float
) -> ContactMeasurement:
    """:func:`measure_contacts` from the raw contact list (slower; the independent reference).

    Same contact rule (module docstring), computed from ``data.contact`` and the constraint forces.
    Vectorised over contacts for elliptic cones, where the constraint force rows of a contact
    are its force in the contact frame; other cones go through ``mj_contactForce``.
    """
    foot_forces = np.zeros((C.N_LEGS, 3))
    total = np.zeros(3)
    n_contacts = np.zeros(C.N_LEGS)
    weight = np.zeros(C.N_LEGS)
    weighted_pts = np.zeros((C.N_LEGS, 3))
    trunk_contact = other_contact = False
    ncon = data.ncon
    if ncon:
        con = data.contact
        geom = con.geom[:ncon]
        rg = idx.robot_geoms[geom]
        adr = con.efc_address[:ncon]
        keep = (rg[:, 0] != rg[:, 1]) & (adr >= 0)
        if keep.any():
            geom, rg, adr = geom[keep], rg[keep], adr[keep]
            f_c = _contact_frame_forces(model, data, np.flatnonzero(keep), adr, con.dim[:ncon][keep])
            frame = con.frame[:ncon][keep].reshape(-1, 3, 3)
            # f_c is the force geom1 exerts on geom2 in the contact frame (rows of `frame`).
            f_world = np.einsum("nij,ni->nj", frame, f_c)
            robot_is_g2 = rg[:, 1]
            f_world[~robot_is_g2] *= -1.0
            robot_g = np.where(robot_is_g2, geom[:, 1], geom[:, 0])
            total = f_world.sum(axis=0)
            leg = idx.foot_of_geom[robot_g]
            on_foot = leg >= 0
            if on_foot.any():
                legs = leg[on_foot]
                w = np.linalg.norm(f_c[on_foot], axis=1)
                pos = con.pos[:ncon][keep][on_foot]
                for k in range(3):
                    foot_forces[:, k] = np.bincount(legs, f_world[on_foot, k], C.N_LEGS)
                    weighted_pts[:, k] = np.bincount(legs, w * pos[:, k], C.N_LEGS)
                weight = np.bincount(legs, w, C.N_LEGS)
                n_contacts = np.bincount(legs, minlength=C.N_LEGS).astype(float)
            trunk_contact = bool((robot_g == idx.trunk_geom).any())
            other_contact = bool(((~on_foot) & (robot_g != idx.trunk_geom)).any())
    contact = n_contacts > 0
    loaded = contact & (np.linalg.norm(foot_forces, axis=1) >= MIN_FOOT_FORCE) & (weight > 0)
    points = data.site_xpos[idx.foot_sites].copy()
    points[:, 2] -= foot_radius
    points[loaded] = weighted_pts[loaded] / weight[loaded, None]
    return ContactMeasurement(foot_forces, contact, points, total, trunk_contact, other_contact)


def _contact_frame_forces(
    model: mujoco.MjModel, data: mujoco.MjData, ids: np.ndarray, efc_adr: np.ndarray, dim: np.ndarray
) -> np.ndarray:
    """(n, 3) contact-frame forces (normal, tangent1, tangent2) of the contacts ``ids``."""
    if model.opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC:
        rows = efc_adr[:, None] + np.arange(3)
        f = data.efc_force[np.minimum(rows, data.nefc - 1)]
        f[dim < 3, 1:] = 0.0  # frictionless contacts have only the normal row
        return f
    f6 = np.zeros(6)
    out = np.zeros((len(ids), 3))
    for k, i in enumerate(ids):
        mujoco.mj_contactForce(model, data, int(i), f6)
        out[k] = f6[:3]
    return out


# ---------------------------------------------------------------------------- named state accessors
# Views into MjData (no copies): copy what must outlive the next physics step.


def base_pos_W(data: mujoco.MjData) -> np.ndarray:
    """(3,) trunk origin, world frame (m)."""
    return data.qpos[0:3]


def base_quat(data: mujoco.MjData) -> np.ndarray:
    """(4,) trunk orientation R_WB as a unit quaternion (w, x, y, z)."""
    return data.qpos[3:7]


def base_lin_vel_W(data: mujoco.MjData) -> np.ndarray:
    """(3,) trunk origin velocity, world frame (m/s)."""
    return data.qvel[0:3]


def base_ang_vel_B(data: mujoco.MjData) -> np.ndarray:
    """(3,) trunk angular velocity, base frame (rad/s)."""
    return data.qvel[3:6]


def joint_pos(data: mujoco.MjData) -> np.ndarray:
    """(12,) joint angles (rad), LF RF LH RH x HAA HFE KFE."""
    return data.qpos[7:]


def joint_vel(data: mujoco.MjData) -> np.ndarray:
    """(12,) joint velocities (rad/s), same order."""
    return data.qvel[6:]


def cog(data: mujoco.MjData, idx: RobotIndex) -> np.ndarray:
    """(3,) whole-robot centre of mass, world frame (m), as of the last position stage."""
    return data.subtree_com[idx.trunk_body]


def feet_pos(data: mujoco.MjData, idx: RobotIndex) -> np.ndarray:
    """(4, 3) foot points (sphere centres), world frame (m), leg order; a copy (fancy indexing)."""
    return data.site_xpos[idx.foot_sites]


def quat_to_rotation(quat_wxyz: np.ndarray) -> np.ndarray:
    """R_WB (3 x 3) of a (w, x, y, z) quaternion, via MuJoCo."""
    R = np.empty(9)
    mujoco.mju_quat2Mat(R, quat_wxyz)
    return R.reshape(3, 3)


def state_is_finite(data: mujoco.MjData) -> bool:
    """qpos, qvel and qacc are all finite."""
    return bool(np.isfinite(data.qpos).all() and np.isfinite(data.qvel).all() and np.isfinite(data.qacc).all())


_W = mujoco.mjtWarning
BAD_WARNINGS: tuple[int, int, int] = (int(_W.mjWARN_BADQPOS), int(_W.mjWARN_BADQVEL), int(_W.mjWARN_BADQACC))
"""indices of MuJoCo's bad-qpos, bad-qvel and bad-qacc warnings in ``data.warning``."""
_BAD_WARNINGS = BAD_WARNINGS


def instability_warnings(data: mujoco.MjData | np.ndarray) -> int:
    """Number of MuJoCo bad-qpos/qvel/qacc warnings raised so far in ``data`` (runs every physics step).

    :param data: the MjData, or its ``data.warning.number`` array (a view into the MjData that
        stays valid, cheaper than taking it again every call).
    """
    n = data if isinstance(data, np.ndarray) else data.warning.number
    return int(n[_BAD_WARNINGS[0]]) + int(n[_BAD_WARNINGS[1]]) + int(n[_BAD_WARNINGS[2]])
