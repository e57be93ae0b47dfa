"""The env's compiled measurement + observation kernel against independent numpy/MuJoCo references."""

from __future__ import annotations

import math

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import quad_uneven_env  # noqa: F401
from quad_uneven_env.measurement import OBS_ORDER
from quad_uneven_env.observations import STABILITY_CLIP
from quad_uneven_env.physics import measure_contacts_reference
from quad_uneven_env.stability import NO_SUPPORT, stability_index


def reference_observation(u, contacts, index, moments, heights_base, heights_scan) -> np.ndarray:
    """The observation assembled field by field with numpy, from the documented layout."""
    d, st = u.data, u.observation_structure
    R = np.empty(9)
    mujoco.mju_quat2Mat(R, d.qpos[3:7])
    R = R.reshape(3, 3)
    norm = u.idx.total_mass * -u.model.opt.gravity[2]
    obs = np.empty(u.observation_space.shape[0])
    obs[st["base_height"]] = d.qpos[2] - heights_base
    obs[st["projected_gravity"]] = R.T @ np.array([0.0, 0.0, -1.0])
    obs[st["base_lin_vel"]] = R.T @ d.qvel[:3]
    obs[st["base_ang_vel"]] = d.qvel[3:6]
    obs[st["joint_pos"]] = d.qpos[7:]
    obs[st["joint_vel"]] = d.qvel[6:]
    obs[st["foot_contact"]] = contacts.foot_contact
    obs[st["stability_index"]] = index / norm if math.isfinite(index) else -STABILITY_CLIP
    edges = np.zeros(4)
    if moments.size and index == NO_SUPPORT:
        edges[:] = -STABILITY_CLIP
    elif moments.size:
        edges[: moments.size] = moments / norm
    obs[st["edge_moments"]] = edges
    phase = 2 * np.pi * d.time / u.gait_period
    obs[st["gait_clock"]] = (np.sin(phase), np.cos(phase))
    obs[st["height_scan"]] = heights_scan - d.qpos[2]
    obs[st["prev_action"]] = u._prev_action
    return np.clip(obs, u.observation_space.low, u.observation_space.high)


def scan_points_W(u) -> np.ndarray:
    """(k, 2) world xy of the scan points: base + yaw rotation of the base-frame grid."""
    R = np.empty(9)
    mujoco.mju_quat2Mat(R, u.data.qpos[3:7])
    yaw = math.atan2(R[3], R[0])
    rot = np.array([[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]])
    return u.data.qpos[:2] + u._scan_B @ rot.T


def check_against_reference(u) -> None:
    meas = u._measure()
    ref = measure_contacts_reference(u.model, u.data, u.idx, u.robot.foot_radius)
    np.testing.assert_allclose(meas.foot_forces, ref.foot_forces, atol=1e-9)
    np.testing.assert_array_equal(meas.foot_contact, ref.foot_contact)
    np.testing.assert_allclose(meas.foot_points, ref.foot_points, atol=1e-9)
    np.testing.assert_allclose(meas.total_force, ref.total_force, atol=1e-9)
    assert meas.trunk_contact == ref.trunk_contact and meas.other_contact == ref.other_contact
    trunk = u.idx.trunk_body
    np.testing.assert_array_equal(meas.cog, u.data.subtree_com[trunk])
    np.testing.assert_allclose(meas.cog_acc, ref.total_force / u.idx.total_mass + u.model.opt.gravity, atol=1e-12)
    # The numpy (vectorised) path of the index, not the compiled one the single-instant call uses.
    index, moments = stability_index(
        meas.cog[None], meas.cog_acc[None], ref.foot_points[ref.foot_contact], u.idx.total_mass, -u.model.opt.gravity[2]
    )
    index, moments = float(index[0]), moments[0]
    assert meas.index == pytest.approx(index, abs=1e-9) or (meas.index == index == NO_SUPPORT)
    np.testing.assert_allclose(meas.moments, moments, atol=1e-9)
    xy = scan_points_W(u)
    heights = u.terrain.heightfield.height(xy[:, 0], xy[:, 1])
    np.testing.assert_allclose(meas.heights, heights, atol=1e-12)
    R = np.empty(9)
    mujoco.mju_quat2Mat(R, u.data.qpos[3:7])
    np.testing.assert_allclose(meas.R.ravel(), R, atol=1e-15)
    expected = reference_observation(u, ref, float(index), np.asarray(moments), heights[0], heights[1:])
    np.testing.assert_allclose(meas.obs, expected, atol=1e-9)


def test_field_order_matches_the_layout():
    u = gym.make("QuadUneven-v0", terrain="flat").unwrapped
    assert tuple(u.observation_structure) == OBS_ORDER


def test_kernel_matches_references_while_the_robot_moves():
    """Random torques on rough terrain: feet make and break contact, the base tilts and yaws."""
    env = gym.make("QuadUneven-v0", terrain={"kind": "rough", "amplitude": 0.06})
    u = env.unwrapped
    env.reset(seed=3)
    rng = np.random.default_rng(0)
    n_stance_seen = set()
    for _ in range(60):
        *_, terminated, _, _ = env.step(rng.uniform(-0.6, 0.6, 12))
        if terminated:
            break
        check_against_reference(u)
        n_stance_seen.add(int(u._meas.foot_contact.sum()))
    assert len(n_stance_seen) >= 2  # the walk really changed the contact set


@pytest.mark.parametrize("lift", [0.0, 0.5])
def test_kernel_with_a_yawed_base_and_without_support(lift):
    env = gym.make("QuadUneven-v0", terrain="rough")
    u = env.unwrapped
    env.reset(seed=1)
    d = u.data
    yaw = 0.7
    d.qpos[3:7] = (math.cos(yaw / 2), 0.05, -0.03, math.sin(yaw / 2))
    d.qpos[3:7] /= np.linalg.norm(d.qpos[3:7])
    d.qpos[2] += lift  # 0.5 m up: no foot touches, index -inf
    d.qvel[:6] = (0.3, -0.2, 0.1, 0.5, -0.4, 0.2)
    mujoco.mj_forward(u.model, d)
    check_against_reference(u)
    if lift:
        assert u._meas.index == NO_SUPPORT and u._meas.obs[u.observation_structure["stability_index"]] == -0.5


def test_clip_finite_into():
    from quad_uneven_env.measurement_kernels import clip_finite_into

    lim = np.array([1.0, 2.0, 3.0])
    out = np.full(3, 7.0)
    assert clip_finite_into(np.array([5.0, -5.0, 0.5]), lim, out)
    np.testing.assert_array_equal(out, [1.0, -2.0, 0.5])
    out[:] = 7.0
    assert not clip_finite_into(np.array([0.0, np.nan, 0.0]), lim, out)
    np.testing.assert_array_equal(out, 7.0)  # untouched
    assert not clip_finite_into(np.array([np.inf, 0.0, 0.0]), lim, out)


@pytest.mark.parametrize(
    "points, expect",
    [
        # LF and RF reported on the same point, LH and RH elsewhere: a triangle with a zero-length edge.
        ([[0.25, 0.0, 0.0], [0.25, 0.0, 0.0], [-0.25, 0.18, 0.0], [-0.25, -0.18, 0.0]], "finite"),
        # Three feet on one point, the fourth elsewhere: no polygon.
        ([[0.25, 0.0, 0.0], [0.25, 0.0, 0.0], [0.25, 0.0, 0.0], [-0.25, -0.18, 0.0]], "no_support"),
        # All four on the line y = 0: index -|moment about the line|.
        ([[0.25, 0.0, 0.0], [0.1, 0.0, 0.0], [-0.1, 0.0, 0.0], [-0.25, 0.0, 0.0]], "collinear"),
    ],
)
def test_kernel_with_coincident_and_collinear_contact_points(points, expect):
    """Sensor data written by hand: every foot loaded, at degenerate points; kernel = numpy path, no exception."""
    env = gym.make("QuadUneven-v0", terrain="flat")
    u = env.unwrapped
    env.reset(seed=0)
    sd = u.data.sensordata
    for leg, p in enumerate(points):
        a = u.idx.foot_sensor_adr[leg]
        sd[a] = 1.0  # one contact found
        sd[a + 1 : a + 4] = (0.0, 0.0, -100.0)  # the foot pushes the terrain down: 100 N up on the foot
        sd[a + 4 : a + 7] = p
    meas = u._meas
    meas.update(u.terrain.heightfield, u._prev_action, u.gait_period)
    np.testing.assert_array_equal(meas.foot_points, points)
    index, moments = stability_index(
        meas.cog[None], meas.cog_acc[None], np.array(points), u.idx.total_mass, -u.model.opt.gravity[2]
    )
    np.testing.assert_allclose(meas.index, index[0], rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(meas.moments, moments[0], rtol=1e-12, atol=1e-9)
    obs = meas.obs[u.observation_structure["edge_moments"]]
    assert np.isfinite(meas.obs).all()
    if expect == "finite":
        # The zero-length edge reports the index, as does the lowest real edge.
        assert np.isfinite(meas.index) and np.sum(meas.moments == meas.index) >= 2
    elif expect == "no_support":
        assert meas.index == NO_SUPPORT and np.all(obs == -STABILITY_CLIP)
    else:
        # Gravity and inertia load F = -m (a + g z); its moment about the x axis through the feet.
        f = -u.idx.total_mass * (meas.cog_acc - u.model.opt.gravity)
        moment = np.cross(meas.cog - np.array(points[0]), f)[0]
        assert meas.index == pytest.approx(-abs(moment), rel=1e-9)
