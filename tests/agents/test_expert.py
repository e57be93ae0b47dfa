"""The scripted expert walks: planner + inverse dynamics in the loop."""

from __future__ import annotations

import dataclasses

import gymnasium as gym
import numpy as np
import pytest

import planners
import quad_uneven_env  # noqa: F401
from agents.expert import ExpertConfig, ExpertPolicy, attach_expert
from agents.expert import cycle as expert_cycle
from planners import PlanningError
from quad_uneven_env import constants as C


def walk(terrain, seconds, seed=0, config=None, on_step=None):
    env = gym.make("QuadUneven-v0", terrain=terrain, max_episode_steps=10**6)
    policy = attach_expert(env, config)
    obs, info = env.reset(seed=seed)
    x0 = info["cog"][0]
    indices = []
    for _ in range(int(seconds / env.unwrapped.dt)):
        action, _ = policy.predict(obs)
        obs, _, terminated, _, info = env.step(action)
        indices.append(info["stability_index"])
        assert not terminated, info["termination_reason"]
        if on_step is not None:
            on_step(env.unwrapped)
    return policy, info["cog"][0] - x0, np.array(indices), info


def leg_links_on_terrain(env) -> list[str]:
    """Names of the thigh and shank geoms touching the terrain (feet and trunk excluded)."""
    m, d = env.model, env.data
    terrain = m.geom(C.TERRAIN_GEOM).id
    links = {m.geom(f"{leg}_{part}_geom").id for leg in C.LEG_NAMES for part in ("thigh", "shank")}
    touching = set()
    for g1, g2 in d.contact.geom[: d.ncon]:
        other = g2 if g1 == terrain else g1 if g2 == terrain else None
        if other in links:
            touching.add(m.geom(int(other)).name)
    return sorted(touching)


@pytest.mark.parametrize("terrain", ["flat", {"kind": "rough", "amplitude": 0.04}])
def test_expert_walks_forward_without_falling(terrain):
    policy, distance, index, info = walk(terrain, 9.3)  # three gait cycles
    assert distance > 0.7  # 3 x 0.33 m planned; the last cycle's end is not yet reached
    assert abs(info["cog"][1]) < 0.1  # keeps heading +x
    # The measured stability index stays positive nearly all the time.
    assert np.mean(index > 0) > 0.99
    assert len(policy.planner_times_ms) >= 3 and policy.failure_log == []


def test_predict_follows_sb3_protocol():
    env = gym.make("QuadUneven-v0", terrain="flat")
    policy = attach_expert(env)
    obs, _ = env.reset(seed=0)
    action, state = policy.predict(obs, state="s", episode_start=np.ones(1, bool), deterministic=True)
    assert action.shape == env.action_space.shape and action.dtype == env.action_space.dtype
    assert state == "s" and env.action_space.contains(action)


class _Wrapper:
    """A physics-rate controller around the expert, as the residual agent's: holds it as ``.expert``, forwards
    the reset."""

    def __init__(self, expert):
        self.expert = expert

    def reset(self, model, data, terrain):
        self.expert.reset(model, data, terrain)

    def __call__(self, model, data, action):
        return self.expert(model, data, action)


def test_an_expert_that_is_not_its_envs_controller_refuses_to_act():
    """Built but not installed, installed after the reset, or replaced: ``predict`` raises a RuntimeError naming
    ``attach_expert`` instead of returning zero actions to a robot without torques; the hook called by an env
    whose reset did not reach it ends the episode with that reason. Installed (directly or held by a controller
    that forwards the reset) before the reset, it acts."""
    env = gym.make("QuadUneven-v0", terrain="flat")
    u = env.unwrapped
    expert = ExpertPolicy(env)
    obs, _ = env.reset(seed=0)
    with pytest.raises(RuntimeError, match=r"not its env's physics-rate controller.*attach_expert\(env"):
        expert.predict(obs)
    with pytest.raises(RuntimeError, match="attach_expert"):
        expert.planned_now(0.0)
    u.set_controller(expert)  # after the reset: no plan
    with pytest.raises(RuntimeError, match=r"installed after the env's last reset.*attach_expert"):
        expert.predict(obs)
    _, _, terminated, _, info = env.step(np.zeros(12, dtype=np.float32))
    assert terminated and "RuntimeError" in info["termination_reason"] and "attach_expert" in info["termination_reason"]
    for controller in (expert, _Wrapper(expert)):
        u.set_controller(controller)
        obs, info = env.reset(seed=0)
        x0 = info["cog"][0]
        for _ in range(60):
            obs, _, terminated, _, info = env.step(expert.predict(obs)[0])
            assert not terminated
        assert info["cog"][0] - x0 > 0.05  # it walks
        assert np.abs(expert.last_torques).max() > 1.0
    u.set_controller(None)
    with pytest.raises(RuntimeError, match="not its env's physics-rate controller"):
        expert.predict(obs)


def test_planning_failure_degrades_to_standing(monkeypatch):
    def always_fail(scenario):
        raise PlanningError("forced failure for the test")

    monkeypatch.setattr(expert_cycle, "plan_gait_cycle", always_fail)
    policy = _stands_still_on_flat_ground()
    assert any("forced failure" in line for line in policy.failure_log)


def _stands_still_on_flat_ground(steps: int = 100):
    """The expert on flat ground for ``steps`` control steps: it must not fall, keep finite torques, log a
    stand-still and end where it started (1 cm)."""
    env = gym.make("QuadUneven-v0", terrain="flat")
    policy = attach_expert(env)
    obs, info = env.reset(seed=0)
    x0 = info["cog"].copy()
    for _ in range(steps):
        obs, _, terminated, _, info = env.step(policy.predict(obs)[0])
        assert not terminated
        assert np.isfinite(policy.last_torques).all()
    assert any("standing still" in line for line in policy.failure_log)
    np.testing.assert_allclose(info["cog"][:2], x0[:2], atol=0.01)
    return policy


def test_a_plan_with_a_stretched_stance_leg_is_refused(monkeypatch):
    """A plan whose whole-body reference holds a leg beyond full stretch (singular joint velocities) is refused
    like a failed plan: the expert stands still, its torques stay finite, the refusal names the leg."""
    start = {"pos": (0.01, 0.0, 0.594), "vel": (0.0, 0.0, 0.0), "acc": (0.0, 0.0, 0.0)}  # 5 cm above reach
    stretched = planners.plan_gait_cycle(dataclasses.replace(planners.paper_scenario(), cog_start=start))
    monkeypatch.setattr(expert_cycle, "plan_gait_cycle", lambda scenario: stretched)
    policy = _stands_still_on_flat_ground()
    refused = [line for line in policy.failure_log if "whole-body reference refused (singular leg" in line]
    assert refused, policy.failure_log[:3]
    assert not any("non-finite" in line for line in policy.failure_log)


def test_bad_config_is_rejected():
    env = gym.make("QuadUneven-v0", terrain="flat")
    with pytest.raises(ValueError, match="distribution"):
        attach_expert(env, ExpertConfig(distribution="magic"))
    with pytest.raises(ValueError, match="body_pitch"):
        attach_expert(env, ExpertConfig(body_pitch="magic"))
    with pytest.raises(ValueError, match=r"ExpertConfig.steep_friction must be a number in \[0, 2\]"):
        ExpertConfig(steep_friction=-0.1)


def test_stance_shanks_stay_off_the_stair_nosings():
    """Regression: 8 cm stairs down, seed 3. With a level body the plan lowered the COG for the
    front feet (a step lower) while the left hind foot still stood 2.5 cm behind the top nosing;
    the hind leg folded until its forward knee was below the foot and at t = 10.6 s the shank
    rested on the nosing, lifting the foot (index < 0 for 1.6 % of the episode)."""
    touched = []

    def check(env):
        touched.extend((round(env.data.time, 2), name) for name in leg_links_on_terrain(env))

    terrain = {"kind": "stairs", "direction": "down", "riser": 0.08, "tread": 0.3, "n_steps": 5}
    policy, distance, index, _ = walk(terrain, 12.0, seed=3, on_step=check)
    assert touched == []
    assert np.all(index >= 0.0)
    assert distance > 1.0 and policy.failure_log == []


@pytest.mark.slow
@pytest.mark.parametrize(
    "terrain",
    [
        {"kind": "stairs", "direction": "pyramid", "riser": 0.08},
        "stepping_stones",
        {"kind": "slope", "angle_deg": 10},
        "paper",
    ],
)
def test_expert_crosses_hard_terrain(terrain):
    _, distance, index, _ = walk(terrain, 31.0)
    assert distance > 2.5
    assert np.mean(index > 0) > 0.99


def test_a_foot_in_the_air_at_a_measured_replan_lands_at_the_nearest_terrain_point():
    """On a 20 deg slope, the robot lifted 15 cm (no foot touches; the points below are beyond the legs'
    stance reach): each foot gets the terrain point nearest to its site within 0.1 m, found again here by
    brute force on a 2 mm grid (to the 1 cm grid's resolution), along the ramp's normal, not straight
    below. Lifted 4 cm (within reach) and with the feet down, they keep the point straight below."""
    import mujoco

    from quad_uneven_env import physics

    env = gym.make(
        "QuadUneven-v0",
        terrain={"kind": "slope", "params": {"angle_deg": 20, "ramp_length": 1.5, "plateau_length": 0.3}},
    )
    expert = attach_expert(env)
    env.reset(seed=0)
    u = env.unwrapped
    footholds = expert.planner.measured_footholds
    hf = u.terrain.heightfield
    x0, y0 = u.data.qpos[:2]
    ramp = x0 + np.linspace(0.0, 3.0, 301)
    x1 = ramp[np.argmax(np.gradient(hf.height(ramp, np.full_like(ramp, y0))) > 0) + 80]  # 0.8 m up the ramp
    u.data.qpos[0] = x1
    u.data.qpos[2] += float(hf.height(x1, y0) - hf.height(x0, y0)) + 0.15  # 15 cm higher: beyond reach
    u.data.qpos[3:7] = (np.cos(np.radians(-10.0)), 0.0, np.sin(np.radians(-10.0)), 0.0)  # pitched with the ramp
    mujoco.mj_forward(u.model, u.data)
    touch = u.data.sensordata[expert.planner.foot_sensor_adr]
    assert (touch <= 0).all()
    lifted = footholds(mid_swing=True)
    plain = footholds()
    sites = physics.feet_pos(u.data, u.idx)
    for leg in range(4):
        g = np.arange(-0.1, 0.1001, 0.002)
        gx, gy = np.meshgrid(g, g)
        inside = np.hypot(gx, gy) <= 0.1 + 1e-9
        x, y = sites[leg, 0] + gx[inside], sites[leg, 1] + gy[inside]
        dist = np.sqrt((x - sites[leg, 0]) ** 2 + (y - sites[leg, 1]) ** 2 + (hf.height(x, y) - sites[leg, 2]) ** 2)
        got = np.linalg.norm(lifted[leg] - sites[leg])
        assert lifted[leg, 2] == pytest.approx(float(hf.height(lifted[leg, 0], lifted[leg, 1])), abs=1e-12)
        assert dist.min() - 1e-9 <= got <= dist.min() + 0.01 * np.sin(np.radians(20.0)) + 1e-9
        # on the uniform ramp the nearest point is along its normal: the vertical gap times cos(20 deg)
        assert got == pytest.approx(np.linalg.norm(plain[leg] - sites[leg]) * np.cos(np.radians(20.0)), abs=2e-3)
        assert np.linalg.norm(plain[leg] - sites[leg]) - got > 0.005  # not straight below
    u.data.qpos[2] -= 0.11  # 4 cm above the ramp: within reach
    mujoco.mj_forward(u.model, u.data)
    assert (u.data.sensordata[expert.planner.foot_sensor_adr] <= 0).all()
    np.testing.assert_array_equal(footholds(mid_swing=True), footholds())
    u.data.qpos[2] -= 0.04  # down: the feet in contact keep the point below them
    mujoco.mj_forward(u.model, u.data)
    down = u.data.sensordata[expert.planner.foot_sensor_adr] > 0
    assert down.any()
    np.testing.assert_array_equal(footholds(mid_swing=True)[down], footholds()[down])


@pytest.mark.parametrize("steep_friction", [0.8, 0.0])
def test_a_ramp_too_steep_for_the_assumed_friction_is_walked_with_the_steep_ground_friction(steep_friction):
    """A 25 deg ramp is steeper than the default cones hold (atan(0.25 / sqrt 2) = 10 deg). The default expert
    plans the strides onto it again assuming friction 0.8 (logged), walks those cycles with cones of 0.8
    and the level ones with 0.25, and climbs; with ``steep_friction=0`` it stands before the ramp."""
    env = gym.make(
        "QuadUneven-v0",
        terrain={"kind": "slope", "params": {"angle_deg": 25, "ramp_length": 1.2, "plateau_length": 0.5}},
        max_episode_steps=10**6,
    )
    expert = attach_expert(env, ExpertConfig(steep_friction=steep_friction))
    env.reset(seed=0)
    assumed = {expert.assumed_friction}
    for _ in range(round(16.0 / env.unwrapped.dt)):
        _, _, terminated, _, info = env.step(expert.predict(None)[0])
        assert not terminated, info["termination_reason"]
        assumed.add(expert.assumed_friction)
    steep_tries = [line for line in expert.failure_log if "planned assuming friction 0.80" in line]
    if steep_friction:
        assert assumed == {0.25, 0.8} and steep_tries
        assert info["distance"] > 1.0  # the ramp starts at ~0.3 m
    else:
        assert assumed == {0.25} and not steep_tries
        assert info["distance"] < 0.6 and any("failed test: slope" in line for line in expert.failure_log)
