"""QuadUneven-v0: API conformance, physics sanity, determinism, robustness."""

from __future__ import annotations

import subprocess
import sys
import warnings

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import quad_uneven_env  # noqa: F401
from quad_uneven_env import constants as C
from quad_uneven_env.stability import normalized_stability_index


def make(**kwargs):
    kwargs.setdefault("terrain", "flat")
    return gym.make("QuadUneven-v0", **kwargs)


def test_make_from_bare_interpreter():
    code = (
        "import gymnasium as gym; e = gym.make('quad_uneven_env:QuadUneven-v0'); "
        "o, _ = e.reset(seed=0); print(o.shape[0], e.spec.max_episode_steps)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    n_obs, max_steps = out.stdout.split()
    assert int(n_obs) > 60 and int(max_steps) == 1000


def test_gymnasium_env_checker_without_warnings():
    from gymnasium.utils.env_checker import check_env

    env = make(terrain="rough")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env.unwrapped, skip_render_check=True)


def test_sb3_env_checker():
    from stable_baselines3.common.env_checker import check_env

    env = make(terrain="rough")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env.unwrapped, warn=True)


def test_observation_structure_covers_the_vector():
    env = make()
    u = env.unwrapped
    st = u.observation_structure
    covered = np.zeros(u.observation_space.shape[0], dtype=int)
    for sl in st.values():
        covered[sl] += 1
    assert (covered == 1).all()
    for name in (
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
    ):
        assert name in st
    assert np.isfinite(u.observation_space.low).all() and np.isfinite(u.observation_space.high).all()


def test_standing_pose_is_measured_correctly():
    """joint_pd with zero action holds the stand on flat ground: forces carry the weight, index ~ geometry."""
    env = make(action_mode="joint_pd", reset_noise_scale=0.0)
    obs, info = env.reset(seed=0)
    for _ in range(50):
        obs, _reward, terminated, _truncated, info = env.step(np.zeros(12))
    assert not terminated
    u = env.unwrapped
    m, g = u.idx.total_mass, 9.81
    assert info["foot_contact"].all()
    # Contact forces carry the weight; the COG does not accelerate.
    np.testing.assert_allclose(info["contact_forces"].sum(axis=0), [0, 0, m * g], atol=0.02 * m * g)
    np.testing.assert_allclose(info["cog_acc"], 0.0, atol=0.2)
    # Static index: distance from the COG to the nearest edge of the foot rectangle (hand computed
    # from the measured contact points), times m g.
    feet = info["feet_pos"].copy()
    feet[:, 2] -= u.robot.foot_radius
    expected, _ = normalized_stability_index(info["cog"], np.zeros(3), feet, m, g)
    assert info["stability_index_normalized"] == pytest.approx(float(expected), abs=0.01)
    half_w = 0.185
    assert info["stability_index_normalized"] == pytest.approx(half_w - abs(info["cog"][1]), abs=0.02)
    st = u.observation_structure
    assert obs[st["stability_index"]][0] == pytest.approx(info["stability_index_normalized"], abs=1e-6)
    assert obs[st["base_height"]][0] == pytest.approx(0.36, abs=0.02)
    np.testing.assert_allclose(obs[st["projected_gravity"]], [0, 0, -1], atol=0.02)


def test_reward_is_sum_of_named_terms():
    env = make(terrain="rough", action_mode="joint_pd")
    env.reset(seed=3)
    rng = np.random.default_rng(0)
    for _ in range(20):
        _, reward, terminated, _, info = env.step(rng.uniform(-0.3, 0.3, 12))
        terms = info["reward_terms"]
        assert set(terms) == {"forward_progress", "stability", "torque", "energy", "alive", "fall"}
        assert reward == pytest.approx(sum(terms.values()), abs=1e-12)
        if terminated:
            break


def test_same_seed_same_trajectory_different_seed_different_terrain():
    def rollout(seed):
        env = make(terrain="rough")
        obs0, _ = env.reset(seed=seed)
        rng = np.random.default_rng(7)
        out = [obs0]
        for _ in range(1000):
            obs, _, terminated, truncated, _ = env.step(rng.uniform(-0.2, 0.2, 12))
            out.append(obs)
            if terminated or truncated:
                env.reset()
        return np.array(out), env.unwrapped.terrain.heightfield.heights.copy()

    a, ha = rollout(11)
    b, _hb = rollout(11)
    np.testing.assert_array_equal(a, b)
    _, hc = rollout(12)
    assert not np.array_equal(ha, hc)


def test_observations_do_not_share_memory():
    env = make()
    o1, _ = env.reset(seed=0)
    o2, *_ = env.step(np.zeros(12))
    assert not np.shares_memory(o1, o2)


@pytest.mark.parametrize(
    "bad, match",
    [(np.full(12, np.nan), "finite"), (np.zeros(11), "shape"), (np.r_[np.zeros(11), np.inf], "finite")],
)
def test_bad_action_raises_and_leaves_state_untouched(bad, match):
    env = make()
    env.reset(seed=0)
    d = env.unwrapped.data
    qpos, qvel, t = d.qpos.copy(), d.qvel.copy(), d.time
    with pytest.raises(ValueError, match=match):
        env.step(bad)
    np.testing.assert_array_equal(d.qpos, qpos)
    np.testing.assert_array_equal(d.qvel, qvel)
    assert d.time == t


def test_out_of_range_action_is_clipped():
    results = []
    for scale in (1.0, 7.5):
        env = make()
        env.reset(seed=0)
        action = np.full(12, scale) * np.resize([1.0, -1.0, 1.0], 12)
        obs, *_ = env.step(action)
        results.append(obs)
    np.testing.assert_array_equal(results[0], results[1])


def test_zero_torque_robot_falls_and_terminates():
    env = make(terrain="rough")
    env.reset(seed=0)
    reason = None
    for _ in range(300):
        _, _reward, terminated, _, info = env.step(np.zeros(12))
        if terminated:
            reason = info["termination_reason"]
            assert info["reward_terms"]["fall"] < 0
            break
    assert reason is not None and reason.startswith("fall"), reason
    assert not info["diverged"]


def test_divergence_ends_episode_with_reason():
    env = make()
    env.reset(seed=0)
    env.unwrapped.data.qvel[:] = 1e30  # numerical blow-up
    obs, reward, terminated, _truncated, info = env.step(np.zeros(12))
    assert terminated and info["diverged"]
    assert info["termination_reason"].startswith("diverged")
    assert np.isfinite(obs).all() and np.isfinite(reward)


def test_controller_hook_runs_at_physics_rate_and_is_applied():
    calls = []

    def controller(model, data, action):
        calls.append(data.time)
        # mj_step1 has run: the mass matrix of the current state is available.
        M = np.zeros((model.nv, model.nv))
        mujoco.mj_fullM(model, data, M)
        assert M[0, 0] == pytest.approx(50.0)
        return np.full(12, 500.0)  # beyond the limits: clipped

    env = make(controller=controller)
    env.reset(seed=0)
    env.step(np.zeros(12))
    u = env.unwrapped
    assert len(calls) == u.frame_skip
    np.testing.assert_allclose(np.diff(calls), u.physics_dt)
    np.testing.assert_allclose(u.data.actuator_force, u.idx.torque_limit)


def test_controller_returning_nan_ends_episode():
    env = make(controller=lambda m, d, a: np.full(12, np.nan))
    env.reset(seed=0)
    _, _, terminated, _, info = env.step(np.zeros(12))
    assert terminated and info["diverged"]


def test_bad_constructor_arguments_name_the_field():
    with pytest.raises(ValueError, match="action_mode"):
        make(action_mode="velocity")
    with pytest.raises(ValueError, match="timestep"):
        make(timestep=0.01)
    with pytest.raises(ValueError, match="reward_weights"):
        make(reward_weights={"speed": 1.0})
    with pytest.raises(ValueError, match="kind"):
        make(terrain="lava")


def test_info_contents():
    env = make(terrain="rough")
    _, info = env.reset(seed=1)
    assert info["contact_forces"].shape == (4, 3)
    assert info["feet_pos"].shape == (4, 3)
    for key in ("cog", "cog_vel", "cog_acc"):
        assert info[key].shape == (3,)
    assert info["diverged"] is False
    # Terrain height under the base agrees with a ray cast down in MuJoCo.
    u = env.unwrapped
    x, y = u.data.qpos[:2]
    terrain_geom = u.model.geom(C.TERRAIN_GEOM).id
    dist = mujoco.mj_rayHfield(u.model, u.data, terrain_geom, np.array([x, y, 5.0]), np.array([0, 0, -1.0]))
    assert info["terrain_height_under_base"] == pytest.approx(5.0 - dist, abs=1e-6)


def test_rgb_render_follows_terrain_regeneration():
    env = make(terrain="rough", render_mode="rgb_array", width=96, height=72)
    env.reset(seed=0)
    a = env.render()
    assert a.shape == (72, 96, 3) and a.dtype == np.uint8 and a.std() > 1
    env.reset(seed=1)
    b = env.render()
    assert not np.array_equal(a, b)
    env.close()


def test_joint_order_matches_constants():
    env = make()
    m = env.unwrapped.model
    for i, name in enumerate(C.JOINT_NAMES):
        assert m.joint(name).qposadr[0] == 7 + i
        assert m.actuator(C.ACTUATOR_NAMES[i]).trnid[0] == m.joint(name).id


def test_contact_sensors_match_raw_contact_list():
    """MuJoCo's contact sensors (the fast path) against the raw contact list (mj_contactForce)."""
    from quad_uneven_env.physics import measure_contacts, measure_contacts_reference

    env = make(terrain="rough", action_mode="joint_pd")
    env.reset(seed=5)
    u = env.unwrapped
    rng = np.random.default_rng(1)
    checked = 0
    for _ in range(60):
        _, _, terminated, _, _ = env.step(rng.uniform(-0.5, 0.5, 12))
        if terminated:
            break
        # Re-evaluate forward so contacts and sensors describe the same (current) state.
        mujoco.mj_forward(u.model, u.data)
        fast = measure_contacts(u.model, u.data, u.idx, u.robot.foot_radius)
        ref = measure_contacts_reference(u.model, u.data, u.idx, u.robot.foot_radius)
        np.testing.assert_array_equal(fast.foot_contact, ref.foot_contact)
        np.testing.assert_allclose(fast.foot_forces, ref.foot_forces, atol=1e-9)
        np.testing.assert_allclose(fast.total_force, ref.total_force, atol=1e-9)
        np.testing.assert_allclose(fast.foot_points, ref.foot_points, atol=1e-9)
        checked += int(fast.foot_contact.sum())
    assert checked > 100


def test_controller_numerical_failure_ends_episode_without_raising():
    def singular(model, data, action):
        return np.linalg.solve(np.zeros((3, 3)), np.ones(3))  # LinAlgError, as a degenerate ID would

    env = make(controller=singular)
    env.reset(seed=0)
    obs, reward, terminated, _, info = env.step(np.zeros(12))
    assert terminated and info["diverged"] and "LinAlgError" in info["termination_reason"]
    assert np.isfinite(obs).all() and np.isfinite(reward)


def test_instability_inside_the_control_loop_stops_before_the_controller_sees_it():
    seen_bad_state = []

    def controller(model, data, action):
        seen_bad_state.append(not np.isfinite(data.qvel).all())
        return np.zeros(12)

    env = make(controller=controller)
    env.reset(seed=0)
    env.unwrapped.data.qvel[:] = np.nan
    _, _, terminated, _, info = env.step(np.zeros(12))
    assert terminated and info["diverged"]
    assert not any(seen_bad_state)


def test_full_range_random_torques_do_not_diverge():
    """An RL agent's first actions: uniform random torques over the whole motor range.

    Without the joints' rotor inertia (``joint_armature``) M is ill-conditioned (links have no
    axial inertia) and about a third of these episodes end with MuJoCo diverging.
    """
    env = make(terrain="rough")
    diverged = []
    for seed in range(10):
        env.reset(seed=seed)
        rng = np.random.default_rng(seed)
        for _ in range(300):
            *_, terminated, truncated, info = env.step(rng.uniform(-1.0, 1.0, 12))
            if terminated or truncated:
                break
        diverged.append(info["diverged"])
    assert not any(diverged), diverged
