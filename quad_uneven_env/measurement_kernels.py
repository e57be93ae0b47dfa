"""Compiled (numba) kernel of the env's per-step measurement and observation (:mod:`quad_uneven_env.measurement`).

Its numpy/MuJoCo twins, which the tests compare it with: ``physics.measure_contacts_reference``,
:func:`quad_uneven_env.stability.stability_index`, ``HeightField.height`` and the observation layout.
"""

from __future__ import annotations

import math

import numpy as np

from quad_uneven_env.jit import njit
from quad_uneven_env.observations import STABILITY_CLIP
from quad_uneven_env.physics import MIN_FOOT_FORCE
from quad_uneven_env.spatial_kernels import quat_to_matrix_into
from quad_uneven_env.stability import NO_SUPPORT
from quad_uneven_env.stability_kernels import edge_moments_into
from quad_uneven_env.terrain.heightfield_kernels import heights_into

_MIN_FOOT_FORCE_SQ = MIN_FOOT_FORCE * MIN_FOOT_FORCE


MEASURED_VIEWS = ("sensordata", "site_xpos", "subtree_com", "subtree_linvel", "qpos", "qvel")
"""The ``MjData`` arrays :func:`measure_observe_into` reads, in the order of its ``sim`` tuple."""
OUTPUTS = (
    "foot_forces", "foot_contact", "foot_points", "total_force", "cog", "cog_vel", "cog_acc", "feet_pos", "moments",
    "R", "base", "heights", "scalars", "obs",
)  # fmt: skip
"""The buffers :func:`measure_observe_into` writes, in the order of its ``out`` tuple."""


@njit(nogil=True)
def measure_observe_into(sim, robot, terrain, layout, prev_action, clock_phase, out):  # pragma: no cover - compiled
    """Measure one state and write the observation.

    :param sim: the ``MjData`` arrays of :data:`MEASURED_VIEWS`.
    :param robot: ``(ints, foot_radius, mass, gravity)``: the trunk body, the robot's and the trunk's contact sensor
        addresses, the four feet's sensor addresses and the four foot sites (int64); m; kg; (3,) m/s^2.
    :param terrain: the height field's kernel arguments (``HeightField.kernel_args``).
    :param layout: ``(scan_B, obs_start, obs_low, obs_high)``: the (k, 2) m scan points in the yaw-aligned base
        frame, the start of each field of ``OBS_ORDER`` in the observation, its bounds.
    :param prev_action: (12,) the previous clipped action.
    :param clock_phase: rad, the gait clock's phase.
    :param out: the buffers of :data:`OUTPUTS` (``scalars``: index, feet in contact, ground height, trunk contact,
        other contact).
    """
    sd, site_xpos, subtree_com, subtree_linvel, qpos, qvel = sim
    ints, foot_radius, mass, gravity = robot
    hf_flat, nrow, ncol, ox, oy, inv_cell = terrain
    scan_B, obs_start, obs_low, obs_high = layout
    (foot_forces, foot_contact, foot_points, total_force, cog, cog_vel, cog_acc, feet_pos, moments, R, base, heights,
     scalars, obs) = out  # fmt: skip
    trunk, robot_adr, trunk_adr = ints[0], ints[1], ints[2]
    # Contacts: sensors report the force the robot exerts on the terrain; the terrain's is its negative.
    # A foot's point is the sensor's force-weighted contact point, or the foot's lowest point when it
    # carries (almost) no force: the rule of physics.ContactMeasurement.foot_points.
    n_feet_found = 0.0
    n_stance = 0
    for leg in range(4):
        a = ints[3 + leg]
        s = ints[7 + leg]
        found = sd[a]
        n_feet_found += found
        foot_contact[leg] = found > 0
        f2 = 0.0
        for k in range(3):
            foot_forces[leg, k] = -sd[a + 1 + k]
            f2 += sd[a + 1 + k] * sd[a + 1 + k]
            feet_pos[leg, k] = site_xpos[s, k]
        if found > 0:
            n_stance += 1
        if found > 0 and f2 >= _MIN_FOOT_FORCE_SQ:
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

    # Stability index of the feet in contact (degenerate polygons: see quad_uneven_env.stability).
    g = -gravity[2]
    scalars[1] = n_stance
    stance = np.empty((n_stance, 3))
    j = 0
    for leg in range(4):
        if foot_contact[leg]:
            for k in range(3):
                stance[j, k] = foot_points[leg, k]
            j += 1
    scalars[0] = edge_moments_into(cog, cog_acc, stance, mass, g, moments[:n_stance])

    # Base pose and the terrain scan in the yaw-aligned base frame.
    quat_to_matrix_into(qpos[3:7], R)
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
    heights_into(hf_flat, nrow, ncol, ox, oy, inv_cell, xs, ys, heights)
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
    # Edge slots: the normalised moments, zero-padded; all at the lower bound when some feet touch
    # but span no polygon.
    no_polygon = n_stance > 0 and scalars[0] == NO_SUPPORT
    for k in range(4):
        if no_polygon:
            obs[o[8] + k] = -STABILITY_CLIP
        elif k < n_stance:
            obs[o[8] + k] = moments[k] / norm
        else:
            obs[o[8] + k] = 0.0
    obs[o[9]] = math.sin(clock_phase)
    obs[o[9] + 1] = math.cos(clock_phase)
    for i in range(1, n_scan):
        obs[o[10] + i - 1] = heights[i] - base[2]
    for i in range(obs.shape[0]):
        obs[i] = min(max(obs[i], obs_low[i]), obs_high[i])


@njit(nogil=True)
def clip_finite_into(x, limit, out):  # pragma: no cover - compiled
    """out = clip(x, -limit, limit) if every x is finite (returns True); else False and out untouched."""
    for i in range(x.shape[0]):
        if not math.isfinite(x[i]):
            return False
    for i in range(x.shape[0]):
        out[i] = min(max(x[i], -limit[i]), limit[i])
    return True
