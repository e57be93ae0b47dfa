"""The expert's own model: nominal terms whatever the simulator's masses, the oracle option, degradation."""

from __future__ import annotations

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import quad_uneven_env  # noqa: F401
from agents.control.nominal import ROBOT_PARAMETER_FIELDS, NominalModel
from agents.control.verify import verify_inverse_dynamics
from agents.expert import ExpertConfig, attach_expert
from quad_uneven_env import constants as C
from quad_uneven_env import physics

PAYLOAD_KG, PAYLOAD_X = 10.0, 0.05
"""A trunk payload the expert is not told of: 10 kg, 5 cm ahead of the trunk origin."""


def make_env(payload: bool = False, terrain="rough"):
    env = gym.make("QuadUneven-v0", terrain=terrain, max_episode_steps=10**6)
    if payload:
        m = env.unwrapped.model
        trunk = m.body(C.TRUNK_BODY).id
        m0 = m.body_mass[trunk]
        payload_pos = np.array([PAYLOAD_X, 0.0, 0.0])
        m.body_ipos[trunk] = (m0 * m.body_ipos[trunk] + PAYLOAD_KG * payload_pos) / (m0 + PAYLOAD_KG)
        m.body_mass[trunk] = m0 + PAYLOAD_KG
        mujoco.mj_setConst(m, mujoco.MjData(m))
    return env


def first_torques(env, config):
    """The expert's torques at the first physics step after a seeded reset, and the expert."""
    policy = attach_expert(env, config)
    env.reset(seed=3)
    u = env.unwrapped
    mujoco.mj_step1(u.model, u.data)
    return policy(u.model, u.data, np.zeros(C.N_JOINTS)), policy


def test_nominal_model_equals_the_simulator_bit_for_bit_in_a_nominal_world():
    env = make_env()
    u = env.unwrapped
    env.reset(seed=1)
    rng = np.random.default_rng(0)
    for _ in range(20):
        env.step(rng.uniform(-0.3, 0.3, C.N_JOINTS))
    mujoco.mj_step1(u.model, u.data)
    nominal = NominalModel(u.robot, u.terrain, u.physics_dt)
    assert nominal.matches(u.model)
    own = nominal.measure(u.data.qpos, u.data.qvel, u.data.time)
    for name in ("M", "qfrc_bias", "xpos", "xmat", "xanchor", "xaxis", "site_xpos", "subtree_com"):
        assert np.array_equal(getattr(own, name), getattr(u.data, name)), name


def test_nominal_model_sees_a_changed_simulator():
    env = make_env(payload=True)
    u = env.unwrapped
    nominal = NominalModel(u.robot, u.terrain, u.physics_dt)
    assert not nominal.matches(u.model)
    assert nominal.model.body_subtreemass[nominal.model.body(C.TRUNK_BODY).id] == pytest.approx(u.robot.total_mass)
    assert "body_mass" in ROBOT_PARAMETER_FIELDS


def test_the_expert_controls_with_its_nominal_model_when_the_simulated_masses_differ():
    # The same measured state in a world with an unknown 10 kg payload and in the nominal world:
    # the nominal expert plans the same COG path and commands the same torques in both.
    tau_payload, expert = first_torques(make_env(payload=True), ExpertConfig())
    tau_nominal, _ = first_torques(make_env(), ExpertConfig())
    np.testing.assert_array_equal(tau_payload, tau_nominal)
    assert not expert.shares_simulator_data
    sim, own = expert.env, expert.nominal
    assert expert.controller.dynamics.model is own.model  # the controller's M, h, J come from the nominal model
    # The COG it planned from is the nominal model's, ~8 mm behind the simulator's (10 kg at +5 cm on 60 kg).
    cog_planned = expert.plans[0][1].cog.position(np.array([0.0]))[0]
    np.testing.assert_allclose(cog_planned, own.data.subtree_com[sim.idx.trunk_body], atol=1e-9)
    cog_sim = physics.cog(sim.data, sim.idx)
    assert cog_sim[0] - cog_planned[0] == pytest.approx(PAYLOAD_KG * PAYLOAD_X / (50.0 + PAYLOAD_KG), abs=2e-3)
    # Its inverse dynamics solve the nominal model's equations of motion, not the simulator's.
    u = sim
    result = expert.controller.last
    on_nominal = verify_inverse_dynamics(own.model, u.data.qpos, u.data.qvel, result.qacc, result)
    on_sim = verify_inverse_dynamics(u.model, u.data.qpos, u.data.qvel, result.qacc, result)
    assert on_nominal.eom < 1e-6
    assert on_sim.eom > 0.5 * PAYLOAD_KG * 9.81  # the unmodelled payload's weight shows up as a residual


def test_the_oracle_reads_the_simulator():
    tau_oracle, oracle = first_torques(make_env(payload=True), ExpertConfig(model="oracle"))
    tau_nominal, _ = first_torques(make_env(payload=True), ExpertConfig())
    assert oracle.shares_simulator_data and oracle.nominal is None
    u = oracle.env
    assert oracle.controller.dynamics.model is u.model
    result = oracle.controller.last
    assert verify_inverse_dynamics(u.model, u.data.qpos, u.data.qvel, result.qacc, result).eom < 1e-6
    assert np.abs(tau_oracle - tau_nominal).max() > 1.0  # N m: the payload's weight is compensated


def test_nominal_oracle_and_the_copy_give_the_same_torques_in_a_nominal_world():
    """In an exactly nominal world the zero-copy path (and the oracle, with the same cone friction)
    reproduce the nominal model's copy bit for bit, step after step, through replans."""

    def torques(config, steps=120):
        env = make_env()
        policy = attach_expert(env, config)
        obs, _ = env.reset(seed=2)
        out = []
        for _ in range(steps):
            obs, *_ = env.step(policy.predict(obs)[0])
            out.append(env.unwrapped.data.ctrl.copy())
        return np.array(out), policy

    copied, p_copy = torques(ExpertConfig(friction=1.0, share_nominal_world=False))
    shared, p_shared = torques(ExpertConfig(friction=1.0))
    oracle, _ = torques(ExpertConfig(model="oracle"))
    assert not p_copy.shares_simulator_data and p_shared.shares_simulator_data
    assert np.array_equal(copied, shared) and np.array_equal(shared, oracle)


def test_the_nominal_cones_use_the_assumed_friction_not_the_simulators():
    env = make_env()
    m = env.unwrapped.model
    for g in (C.TERRAIN_GEOM, *C.FOOT_GEOMS):
        m.geom_friction[m.geom(g).id, 0] = 0.3
    _, nominal = first_torques(env, ExpertConfig(friction=0.6))
    assert nominal.controller.id.mu == 0.6
    _, oracle = first_torques(env, ExpertConfig(model="oracle"))
    assert oracle.controller.id.mu == pytest.approx(0.3)


def test_a_failing_controller_step_keeps_the_last_torques_and_is_logged():
    env = make_env(terrain="flat")
    policy = attach_expert(env)
    obs, _ = env.reset(seed=0)
    for _ in range(3):
        obs, *_ = env.step(policy.predict(obs)[0])
    last = env.unwrapped.data.ctrl.copy()

    def broken(*args, **kwargs):
        raise ZeroDivisionError("division by zero")

    calls = {"__call__": broken, "grid_step_into": broken}  # the controller's two entries from the expert's hook
    broken_controller = {**calls, "t0": 0.0, "torque_limit": None, "foot_of_geom": None, "terrain_geom": 0}
    policy.hook.controller = type("Broken", (), broken_controller)()
    obs, _, _, _, info = env.step(policy.predict(obs)[0])
    assert not info["diverged"]
    np.testing.assert_array_equal(env.unwrapped.data.ctrl, last)
    assert len(policy.failure_log) == 1 and "ZeroDivisionError" in policy.failure_log[0]


def test_bad_model_choice_is_rejected():
    with pytest.raises(ValueError, match=r"ExpertConfig\.model"):
        ExpertConfig(model="simulator")
    with pytest.raises(ValueError, match=r"ExpertConfig\.friction"):
        ExpertConfig(friction=0.0)
