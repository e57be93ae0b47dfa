"""The env's per-step measurement and observation, filled by one compiled kernel.

Every control step the env needs the foot contacts (from MuJoCo's contact sensors), the
whole-robot COG and its acceleration, the stability index of the feet in contact, the terrain
height under the base and around it, and the observation vector built from all of that. In
numpy this is ~70 small array operations (~70 us, as much as one MuJoCo step of this model);
here it is one numba call writing into preallocated buffers.

The arithmetic is that of :func:`quad_uneven_env.physics.measure_contacts`,
:func:`quad_uneven_env.stability.stability_index`, :meth:`HeightField.height` and the layout of
:mod:`quad_uneven_env.observations`; ``tests/test_measurement.py`` checks each against them.
"""

from __future__ import annotations

import math

import mujoco
import numba as nb
import numpy as np

from quad_uneven_env import constants as C
from quad_uneven_env.observations import STABILITY_CLIP, ObsField, observation_structure
from quad_uneven_env.physics import ContactMeasurement, RobotIndex
from quad_uneven_env.stability import NO_SUPPORT, _moments_one
from quad_uneven_env.terrain.heightfield import HeightField, _height_kernel

OBS_ORDER = (
    "base_height",
    "projected_gravity",
    "base_lin_vel",
    "base_ang_vel",
    "joint_pos",
    "joint_vel",
    "foot_contact",
    "stability_index",
    "edge_moments",
    "gait_clock",
    "height_scan",
    "prev_action",
)
"""Observation fields in the order the kernel writes them (must match the layout)."""

# Offsets of the scalar outputs in StepMeasurement._scalars.
_INDEX, _N_STANCE, _GROUND, _TRUNK, _OTHER = range(5)


class StepMeasurement:
    """Preallocated measurement of one robot state (world frame, SI units), refreshed by :meth:`update`.

    Contacts, COG and stability are those of MuJoCo's last constraint solve (the start of the
    last physics step, like ``data.sensordata``); base pose, joints and velocities are the
    current ``qpos``/``qvel``. All arrays are views into buffers that the next :meth:`update`
    overwrites: copy what must outlive the step.

    :param model: the compiled scene (robot + terrain).
    :param data: its data; the buffers of ``data`` are bound once (MuJoCo never reallocates them).
    :param idx: resolved robot ids of ``model``.
    :param foot_radius: m, foot sphere radius (a foot without contact is measured at its lowest point).
    :param scan_B: (k, 2) m, terrain query points in the yaw-aligned base frame; row 0 is the point under the base.
    :param fields: the observation layout; its field names must be :data:`OBS_ORDER`.
    :param obs_low: observation lower bounds, same length as the layout.
    :param obs_high: observation upper bounds.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        data: mujoco.MjData,
        idx: RobotIndex,
        foot_radius: float,
        scan_B: np.ndarray,
        fields: tuple[ObsField, ...],
        obs_low: np.ndarray,
        obs_high: np.ndarray,
    ) -> None:
        if tuple(f.name for f in fields) != OBS_ORDER:
            raise ValueError(f"observation fields must be {OBS_ORDER}, got {tuple(f.name for f in fields)}")
        structure = observation_structure(fields)
        self._obs_start = np.array([structure[name].start for name in OBS_ORDER], dtype=np.int64)
        self._obs_low = np.ascontiguousarray(obs_low, dtype=np.float64)
        self._obs_high = np.ascontiguousarray(obs_high, dtype=np.float64)
        self._data = data
        self._sensordata = data.sensordata
        self._site_xpos = data.site_xpos
        self._subtree_com = data.subtree_com
        self._subtree_linvel = data.subtree_linvel
        self._qpos = data.qpos
        self._qvel = data.qvel
        self._ints = np.array(
            [idx.trunk_body, idx.robot_sensor_adr, idx.trunk_sensor_adr, *idx.foot_sensor_adr, *idx.foot_sites],
            dtype=np.int64,
        )
        self.mass = float(idx.total_mass)
        self.gravity = np.array(model.opt.gravity, dtype=np.float64)
        self.foot_radius = float(foot_radius)
        self._scan_B = np.ascontiguousarray(scan_B, dtype=np.float64)

        n_scan = self._scan_B.shape[0]
        self.foot_forces = np.zeros((C.N_LEGS, 3))
        """(4, 3) N, force of the terrain on each foot."""
        self.foot_contact = np.zeros(C.N_LEGS, dtype=np.bool_)
        """(4,) the foot touches the terrain."""
        self.foot_points = np.zeros((C.N_LEGS, 3))
        """(4, 3) m, force-weighted contact point of each foot (foot site minus its radius if none)."""
        self.total_force = np.zeros(3)
        """(3,) N, sum of all terrain forces on the robot."""
        self.cog = np.zeros(3)
        """(3,) m, whole-robot centre of gravity."""
        self.cog_vel = np.zeros(3)
        """(3,) m/s, its velocity."""
        self.cog_acc = np.zeros(3)
        """(3,) m/s^2, its acceleration by Newton's law: total terrain force / m + gravity."""
        self.feet_pos = np.zeros((C.N_LEGS, 3))
        """(4, 3) m, foot sites."""
        self._moments = np.zeros(C.N_LEGS)
        self.R = np.zeros((3, 3))
        """R_WB of the current base quaternion."""
        self.base = np.zeros(3)
        """(3,) m, trunk origin (current qpos)."""
        self.heights = np.zeros(n_scan)
        """(k,) m, terrain heights at the scan points; [0] is under the base."""
        self._scalars = np.zeros(5)
        self.obs = np.zeros(self._obs_low.shape[0])
        """float64 observation, clipped to its bounds."""

    # ------------------------------------------------------------------ outputs
    @property
    def index(self) -> float:
        """N m, stability index of the feet in contact (``-inf`` with fewer than three)."""
        return float(self._scalars[_INDEX])

    @property
    def moments(self) -> np.ndarray:
        """(n,) N m, tumbling moment of each support polygon edge, n = feet in contact (clockwise)."""
        return self._moments[: int(self._scalars[_N_STANCE])]

    @property
    def ground(self) -> float:
        """m, terrain height under the trunk origin."""
        return float(self._scalars[_GROUND])

    @property
    def scan(self) -> np.ndarray:
        """(k - 1,) m, terrain heights of the height scan grid."""
        return self.heights[1:]

    @property
    def trunk_contact(self) -> bool:
        """The trunk touches the terrain."""
        return bool(self._scalars[_TRUNK])

    @property
    def other_contact(self) -> bool:
        """A thigh or shank (not a foot) touches the terrain."""
        return bool(self._scalars[_OTHER])

    def contacts(self) -> ContactMeasurement:
        """The contact part as a :class:`ContactMeasurement` (copies)."""
        return ContactMeasurement(
            foot_forces=self.foot_forces.copy(),
            foot_contact=self.foot_contact.copy(),
            foot_points=self.foot_points.copy(),
            total_force=self.total_force.copy(),
            trunk_contact=self.trunk_contact,
            other_contact=self.other_contact,
        )

    # ------------------------------------------------------------------ update
    def update(self, heightfield: HeightField, prev_action: np.ndarray, gait_period: float) -> None:
        """Measure ``data``'s state and build the observation.

        :param heightfield: the terrain surface MuJoCo collides with.
        :param prev_action: (12,) the previous clipped action (observation field ``prev_action``).
        :param gait_period: s, period of the observation's gait clock.
        """
        flat, nrow, ncol, ox, oy, inv_cell = heightfield.kernel_args
        _measure_observe(
            self._sensordata,
            self._site_xpos,
            self._subtree_com,
            self._subtree_linvel,
            self._qpos,
            self._qvel,
            self._ints,
            self.foot_radius,
            self.mass,
            self.gravity,
            flat,
            nrow,
            ncol,
            ox,
            oy,
            inv_cell,
            self._scan_B,
            prev_action,
            2.0 * math.pi * self._data.time / gait_period,
            self._obs_start,
            self._obs_low,
            self._obs_high,
            self.foot_forces,
            self.foot_contact,
            self.foot_points,
            self.total_force,
            self.cog,
            self.cog_vel,
            self.cog_acc,
            self.feet_pos,
            self._moments,
            self.R,
            self.base,
            self.heights,
            self._scalars,
            self.obs,
        )


@nb.njit(cache=False, nogil=True)
def _quat_to_matrix(q, R):  # pragma: no cover - compiled
    """mju_quat2Mat's arithmetic (unit quaternion w, x, y, z)."""
    if q[0] == 1.0 and q[1] == 0.0 and q[2] == 0.0 and q[3] == 0.0:
        for i in range(3):
            for j in range(3):
                R[i, j] = 1.0 if i == j else 0.0
        return
    q00, q01, q02, q03 = q[0] * q[0], q[0] * q[1], q[0] * q[2], q[0] * q[3]
    q11, q12, q13 = q[1] * q[1], q[1] * q[2], q[1] * q[3]
    q22, q23, q33 = q[2] * q[2], q[2] * q[3], q[3] * q[3]
    R[0, 0] = q00 + q11 - q22 - q33
    R[1, 1] = q00 - q11 + q22 - q33
    R[2, 2] = q00 - q11 - q22 + q33
    R[0, 1] = 2.0 * (q12 - q03)
    R[0, 2] = 2.0 * (q13 + q02)
    R[1, 0] = 2.0 * (q12 + q03)
    R[1, 2] = 2.0 * (q23 - q01)
    R[2, 0] = 2.0 * (q13 - q02)
    R[2, 1] = 2.0 * (q23 + q01)


@nb.njit(cache=False, nogil=True)
def _measure_observe(  # pragma: no cover - compiled
    sd,
    site_xpos,
    subtree_com,
    subtree_linvel,
    qpos,
    qvel,
    ints,
    foot_radius,
    mass,
    gravity,
    hf_flat,
    nrow,
    ncol,
    ox,
    oy,
    inv_cell,
    scan_B,
    prev_action,
    clock_phase,
    obs_start,
    obs_low,
    obs_high,
    foot_forces,
    foot_contact,
    foot_points,
    total_force,
    cog,
    cog_vel,
    cog_acc,
    feet_pos,
    moments,
    R,
    base,
    heights,
    scalars,
    obs,
):
    trunk, robot_adr, trunk_adr = ints[0], ints[1], ints[2]
    # Contacts: sensors report the force the robot exerts on the terrain; the terrain's is its negative.
    n_feet_found = 0.0
    n_stance = 0
    for leg in range(4):
        a = ints[3 + leg]
        s = ints[7 + leg]
        found = sd[a]
        n_feet_found += found
        foot_contact[leg] = found > 0
        for k in range(3):
            foot_forces[leg, k] = -sd[a + 1 + k]
            feet_pos[leg, k] = site_xpos[s, k]
        if found > 0:
            n_stance += 1
            for k in range(3):
                foot_points[leg, k] = sd[a + 4 + k]
        else:
            foot_points[leg, 0] = site_xpos[s, 0]
            foot_points[leg, 1] = site_xpos[s, 1]
            foot_points[leg, 2] = site_xpos[s, 2] - foot_radius
    for k in range(3):
        total_force[k] = -sd[robot_adr + 1 + k]
        cog[k] = subtree_com[trunk, k]
        cog_vel[k] = subtree_linvel[trunk, k]
        cog_acc[k] = total_force[k] / mass + gravity[k]
    n_trunk = sd[trunk_adr]
    scalars[3] = 1.0 if n_trunk > 0 else 0.0
    scalars[4] = 1.0 if sd[robot_adr] - n_feet_found - n_trunk > 0 else 0.0

    # Stability index of the feet in contact.
    g = -gravity[2]
    scalars[1] = n_stance
    if n_stance < 3:
        scalars[0] = NO_SUPPORT
        for k in range(n_stance):
            moments[k] = NO_SUPPORT
    else:
        stance = np.empty((n_stance, 3))
        j = 0
        for leg in range(4):
            if foot_contact[leg]:
                for k in range(3):
                    stance[j, k] = foot_points[leg, k]
                j += 1
        _moments_one(cog, cog_acc, stance, mass, g, moments[:n_stance])
        scalars[0] = moments[:n_stance].min()

    # Base pose and the terrain scan in the yaw-aligned base frame.
    _quat_to_matrix(qpos[3:7], R)
    for k in range(3):
        base[k] = qpos[k]
    yaw = math.atan2(R[1, 0], R[0, 0])
    c, s = math.cos(yaw), math.sin(yaw)
    n_scan = scan_B.shape[0]
    xs = np.empty(n_scan)
    ys = np.empty(n_scan)
    for i in range(n_scan):
        sx, sy = scan_B[i, 0], scan_B[i, 1]
        xs[i] = base[0] + (c * sx - s * sy)
        ys[i] = base[1] + (s * sx + c * sy)
    _height_kernel(hf_flat, nrow, ncol, ox, oy, inv_cell, xs, ys, heights)
    scalars[2] = heights[0]

    # Observation, in OBS_ORDER.
    norm = mass * g
    o = obs_start
    obs[o[0]] = base[2] - heights[0]
    for k in range(3):
        obs[o[1] + k] = -R[2, k]
        obs[o[2] + k] = R[0, k] * qvel[0] + R[1, k] * qvel[1] + R[2, k] * qvel[2]
        obs[o[3] + k] = qvel[3 + k]
    for j in range(12):
        obs[o[4] + j] = qpos[7 + j]
        obs[o[5] + j] = qvel[6 + j]
        obs[o[11] + j] = prev_action[j]
    for leg in range(4):
        obs[o[6] + leg] = 1.0 if foot_contact[leg] else 0.0
    index_norm = scalars[0] / norm
    obs[o[7]] = index_norm if math.isfinite(index_norm) else -STABILITY_CLIP
    all_finite = True
    for k in range(n_stance):
        if not math.isfinite(moments[k]):
            all_finite = False
    for k in range(4):
        if k < n_stance and all_finite:
            obs[o[8] + k] = moments[k] / norm
        elif n_stance > 0 and not all_finite:
            obs[o[8] + k] = -STABILITY_CLIP
        else:
            obs[o[8] + k] = 0.0
    obs[o[9]] = math.sin(clock_phase)
    obs[o[9] + 1] = math.cos(clock_phase)
    for i in range(1, n_scan):
        obs[o[10] + i - 1] = heights[i] - base[2]
    for i in range(obs.shape[0]):
        obs[i] = min(max(obs[i], obs_low[i]), obs_high[i])


@nb.njit(cache=False, nogil=True)
def clip_finite_into(x, limit, out):  # pragma: no cover - compiled
    """out = clip(x, -limit, limit) if every x is finite (returns True); else False and out untouched."""
    for i in range(x.shape[0]):
        if not math.isfinite(x[i]):
            return False
    for i in range(x.shape[0]):
        out[i] = min(max(x[i], -limit[i]), limit[i])
    return True
