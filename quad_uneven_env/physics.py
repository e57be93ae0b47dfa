"""Named, vectorised accessors to the robot in a MuJoCo model/data pair.

:class:`RobotIndex` resolves every id once; :func:`measure_contacts` turns MuJoCo's contact
list into per-foot world-frame forces. Nothing here allocates more than a few small arrays:
it runs every control step.
"""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np

from quad_uneven_env import constants as C


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
        )


@dataclasses.dataclass
class ContactMeasurement:
    """Contacts between the robot and the terrain at one instant (world frame, SI)."""

    foot_forces: np.ndarray
    """(4, 3) force the terrain applies on each foot (N), zero when not in contact."""
    foot_contact: np.ndarray
    """(4,) bool, foot touches the terrain."""
    foot_points: np.ndarray
    """(4, 3) force-weighted contact point of each foot (m); the foot site minus its radius if none."""
    total_force: np.ndarray
    """(3,) sum of all terrain forces on the robot, feet and other links (N)."""
    trunk_contact: bool
    """the trunk touches the terrain."""
    other_contact: bool
    """a thigh or shank (not a foot) touches the terrain."""


def measure_contacts(
    model: mujoco.MjModel, data: mujoco.MjData, idx: RobotIndex, foot_radius: float
) -> ContactMeasurement:
    """Per-foot contact forces (N, world frame) from MuJoCo's last constraint solve."""
    foot_forces = np.zeros((C.N_LEGS, 3))
    weighted_pts = np.zeros((C.N_LEGS, 3))
    weight = np.zeros(C.N_LEGS)
    total = np.zeros(3)
    trunk_contact = other_contact = False
    f6 = np.zeros(6)
    ncon = data.ncon
    if ncon:
        geoms = data.contact.geom[:ncon]
        for i in range(ncon):
            g1, g2 = geoms[i]
            if idx.robot_geoms[g1] == idx.robot_geoms[g2]:
                continue
            robot_g = g2 if idx.robot_geoms[g2] else g1
            mujoco.mj_contactForce(model, data, i, f6)
            frame = data.contact.frame[i].reshape(3, 3)
            # f6 is the force geom1 exerts on geom2, in the contact frame (rows of `frame`).
            f_world = frame.T @ f6[:3]
            if robot_g == g1:
                f_world = -f_world
            total += f_world
            leg = idx.foot_of_geom[robot_g]
            if leg >= 0:
                foot_forces[leg] += f_world
                w = max(f6[0], 1e-9)
                weighted_pts[leg] += w * data.contact.pos[i]
                weight[leg] += w
            elif robot_g == idx.trunk_geom:
                trunk_contact = True
            else:
                other_contact = True
    contact = weight > 0
    points = data.site_xpos[idx.foot_sites].copy()
    points[:, 2] -= foot_radius
    points[contact] = weighted_pts[contact] / weight[contact, None]
    return ContactMeasurement(foot_forces, contact, points, total, trunk_contact, other_contact)


def quat_to_rotation(quat_wxyz: np.ndarray) -> np.ndarray:
    """R_WB (3 x 3) of a (w, x, y, z) quaternion, via MuJoCo."""
    R = np.empty(9)
    mujoco.mju_quat2Mat(R, quat_wxyz)
    return R.reshape(3, 3)


def state_is_finite(data: mujoco.MjData) -> bool:
    """qpos, qvel and qacc are all finite."""
    return bool(np.isfinite(data.qpos).all() and np.isfinite(data.qvel).all() and np.isfinite(data.qacc).all())


_BAD_WARNINGS = (
    mujoco.mjtWarning.mjWARN_BADQPOS,
    mujoco.mjtWarning.mjWARN_BADQVEL,
    mujoco.mjtWarning.mjWARN_BADQACC,
)


def instability_warnings(data: mujoco.MjData) -> int:
    """Number of MuJoCo bad-qpos/qvel/qacc warnings raised so far in ``data``."""
    return int(sum(data.warning[w].number for w in _BAD_WARNINGS))
