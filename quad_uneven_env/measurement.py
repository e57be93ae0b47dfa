"""The env's per-step measurement and observation, filled by one compiled kernel.

Every control step the env needs the foot contacts (from MuJoCo's contact sensors), the
whole-robot COG and its acceleration, the stability index of the feet in contact, the terrain
height under the base and around it, and the observation vector built from all of that. In
numpy this is ~70 small array operations (together as costly as a MuJoCo step of this model);
here it is one numba call (:mod:`quad_uneven_env.measurement_kernels`) writing into preallocated
buffers.

The arithmetic is that of :func:`quad_uneven_env.physics.measure_contacts`,
:func:`quad_uneven_env.stability.stability_index`, :meth:`HeightField.height` and the layout of
:mod:`quad_uneven_env.observations`; ``tests/quad_uneven_env/test_measurement.py`` checks each against them.
"""

from __future__ import annotations

import math
from typing import Any

import mujoco
import numpy as np

from quad_uneven_env import constants as C
from quad_uneven_env.compiled_call import argument_type, entry_point
from quad_uneven_env.measurement_kernels import MEASURED_VIEWS, measure_observe_into
from quad_uneven_env.observations import ObsField, observation_structure
from quad_uneven_env.physics import ContactMeasurement, RobotIndex
from quad_uneven_env.terrain.heightfield import HeightField

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

OPTIONAL_TRAILING = (("command",), ("course_heading", "course_lateral"))
"""Field groups a layout may add after :data:`OBS_ORDER` (one of them at most), written by
:meth:`StepMeasurement.update` after the kernel."""

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
    :param fields: the observation layout; its field names must be :data:`OBS_ORDER`, optionally followed by
        one group of :data:`OPTIONAL_TRAILING` (``"command"``, or ``"course_heading", "course_lateral"``).
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
        names = tuple(f.name for f in fields)
        if names not in (OBS_ORDER, *(OBS_ORDER + group for group in OPTIONAL_TRAILING)):
            raise ValueError(f"observation fields must be {OBS_ORDER} (+ one of {OPTIONAL_TRAILING}), got {names}")
        structure = observation_structure(fields)
        self._command = structure.get("command")
        self._heading = structure.get("course_heading")
        self._lateral = structure.get("course_lateral")
        self._obs_start = np.array([structure[name].start for name in OBS_ORDER], dtype=np.int64)
        self._obs_low = np.ascontiguousarray(obs_low, dtype=np.float64)
        self._obs_high = np.ascontiguousarray(obs_high, dtype=np.float64)
        self._data = data
        self._bind(data)
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
        """(4, 3) m, contact point of each foot by the contact rule of :mod:`quad_uneven_env.physics`."""
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
        self._layout = (self._scan_B, self._obs_start, self._obs_low, self._obs_high)
        self._out = (
            self.foot_forces, self.foot_contact, self.foot_points, self.total_force, self.cog, self.cog_vel,
            self.cog_acc, self.feet_pos, self._moments, self.R, self.base, self.heights, self._scalars, self.obs,
        )  # fmt: skip  # in the kernel's order (measurement_kernels.OUTPUTS)
        self._call: tuple | None = None
        # (the kernel's compiled entry point, the height field, action and gravity arrays it was resolved with, the
        # terrain tuple's numba type): every other array argument is a buffer of this object; a new terrain's
        # heights of the same type keep the entry point (see quad_uneven_env.compiled_call)

    def _bind(self, data: mujoco.MjData) -> None:
        """The views of ``data``'s buffers the kernel reads (bound once: MuJoCo never reallocates them)."""
        self._views = tuple(getattr(data, name) for name in MEASURED_VIEWS)

    def __getstate__(self) -> dict[str, Any]:
        """Pickled and copied without its views of ``data`` (a copy gets views of its own copy of ``data``) and
        without the kernel's entry point (bound to this process; resolved again at the first call)."""
        state = {k: v for k, v in self.__dict__.items() if k != "_views"}
        state["_call"] = None
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._bind(self._data)

    # ------------------------------------------------------------------ outputs
    @property
    def index(self) -> float:
        """N m, stability index of the feet in contact (``-inf`` without a support polygon: see ``stability``)."""
        return float(self._scalars[_INDEX])

    @property
    def moments(self) -> np.ndarray:
        """(n,) N m, tumbling moment of each support polygon edge, n = feet in contact (clockwise; a zero-length
        edge reports the index, all are ``-inf`` without a polygon)."""
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
    def update(
        self,
        heightfield: HeightField,
        prev_action: np.ndarray,
        gait_period: float,
        command: np.ndarray | None = None,
        course_y: float = 0.0,
    ) -> None:
        """Measure ``data``'s state and build the observation.

        :param heightfield: the terrain surface MuJoCo collides with.
        :param prev_action: (12,) the previous clipped action (observation field ``prev_action``).
        :param gait_period: s, period of the observation's gait clock.
        :param command: (3,) the commanded vx, vy (m/s), yaw rate (rad/s) (field ``command``, when the layout has it).
        :param course_y: m, world y of the course's centre line (fields ``course_heading`` and ``course_lateral``,
            when the layout has them: the trunk's yaw ``atan2(R[1, 0], R[0, 0])`` from world +x and its origin's
            y minus ``course_y``).
        """
        terrain = heightfield.kernel_args
        flat = terrain[0]
        call = self._call
        kernel = None
        if call is not None and call[2] is prev_action and call[3] is self.gravity:
            if call[1] is flat:
                kernel = call[0]
            elif argument_type(measure_observe_into, terrain) == call[4]:  # a new terrain (every reset), same type
                kernel = call[0]
                self._call = (kernel, flat, prev_action, self.gravity, call[4])
        args = (
            self._views,
            (self._ints, self.foot_radius, self.mass, self.gravity),
            terrain,
            self._layout,
            prev_action,
            2.0 * math.pi * self._data.time / gait_period,
            self._out,
        )
        if kernel is not None:
            kernel(*args)
        else:
            measure_observe_into(*args)
            entry = entry_point(measure_observe_into, args)
            terrain_type = argument_type(measure_observe_into, terrain)
            self._call = None if entry is None else (entry, flat, prev_action, self.gravity, terrain_type)
        sl = self._command
        if sl is not None:
            np.clip(command, self._obs_low[sl], self._obs_high[sl], out=self.obs[sl])
        if self._heading is not None:
            R, obs = self.R, self.obs
            yaw = math.atan2(R[1, 0], R[0, 0])
            obs[self._heading.start] = math.sin(yaw)
            obs[self._heading.start + 1] = math.cos(yaw)
            k = self._lateral.start
            obs[k] = min(max(float(self.base[1]) - course_y, self._obs_low[k]), self._obs_high[k])
