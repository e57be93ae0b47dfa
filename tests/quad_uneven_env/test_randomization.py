"""Domain randomization and disturbances: validation, determinism, exact restore, each factor's effect."""

from __future__ import annotations

import copy
import warnings

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import quad_uneven_env  # noqa: F401
from quad_uneven_env import constants as C
from quad_uneven_env.randomization import (
    ROBOT_BODIES,
    RandomizationConfig,
    config_table,
    factor_values,
    load_randomization,
    randomization_for_robot,
)
from quad_uneven_env.robot.description import load_robot


def make(**kwargs):
    kwargs.setdefault("terrain", "flat")
    return gym.make("QuadUneven-v0", **kwargs)


def model_arrays(model: mujoco.MjModel) -> dict[str, np.ndarray]:
    """Every numpy array of an MjModel, plus its opt and stat structs' fields, as copies."""
    out = {n: getattr(model, n).copy() for n in dir(model) if isinstance(getattr(model, n, None), np.ndarray)}
    for struct in ("opt", "stat"):
        obj = getattr(model, struct)
        for n in dir(obj):
            v = getattr(obj, n)
            if not n.startswith("_") and isinstance(v, np.ndarray | float | int):
                out[f"{struct}.{n}"] = np.array(v, copy=True)
    return out


def assert_bit_identical(a: dict[str, np.ndarray], b: dict[str, np.ndarray]) -> None:
    assert a.keys() == b.keys()
    differ = [n for n in a if a[n].tobytes() != b[n].tobytes()]
    assert not differ, f"model fields changed: {differ}"


# ------------------------------------------------------------------------------------------ validation
@pytest.mark.parametrize(
    ("spec", "match"),
    [
        ({"frction": [0.5, 1.0]}, r"unknown field\(s\) \['frction'\]"),
        ({"friction": [1.0, 0.5]}, r"randomization\.friction must be .*low <= high"),
        ({"friction": [0.0, 0.5]}, r"randomization\.friction must be .*\(0, 5\]"),
        ({"friction": 0.5}, r"randomization\.friction must be"),
        ({"payload_mass": [-1.0, 2.0]}, r"randomization\.payload_mass must be .*\[0, 1000\].*kg"),
        ({"link_mass_scale": [0.0, 1.0]}, r"randomization\.link_mass_scale must be"),
        ({"motor_strength": [-0.5, 1.0]}, r"randomization\.motor_strength must be"),
        ({"joint_damping": [-0.1, 0.0]}, r"randomization\.joint_damping must be"),
        ({"latency": [0.0, 0.03]}, r"randomization\.latency .*control period 0\.02 s"),
        ({"push_impulse": [0.0, 10.0]}, r"randomization\.push_interval is required"),
        ({"payload_com_y": [0.0, 0.1]}, r"randomization\.payload_com_y needs payload_mass"),
        (
            {"push_impulse": [0.0, 10.0], "push_interval": [0.1, 1.0], "push_duration": [0.1, 0.2]},
            r"randomization\.push_duration .*push_interval low",
        ),
        ({"observation_noise": {"joint_angle": 0.1}}, r"randomization\.observation_noise: unknown field"),
        ({"observation_noise": {"joint_pos": -0.1}}, r"randomization\.observation_noise\.joint_pos must be"),
        ("nonexistent_preset", r"randomization: unknown randomization config 'nonexistent_preset'.*mild"),
        (42, r"randomization must be None, a preset name"),
        ({"scale": "mass"}, r"randomization\.scale must be one of \['none', 'robot'\]"),
    ],
)
def test_bad_config_raises_at_make_naming_the_field(spec, match):
    with pytest.raises(ValueError, match=match):
        make(randomization=spec)


def test_presets_match_the_robust_suites():
    mild, hard = load_randomization("mild"), load_randomization("hard")
    total = 50.0  # kg, the paper robot (Table 1: 40 + 4 x (2 + 0.5))
    assert mild.friction[0] >= 0.5 and hard.friction[0] == pytest.approx(0.3)
    assert mild.payload_mass[1] <= 0.2 * total and hard.payload_mass[1] == pytest.approx(0.35 * total)
    assert max(abs(v) for r in (mild.payload_com_x, mild.payload_com_y, mild.payload_com_z) for v in r) <= 0.05
    assert mild.motor_strength == (0.8, 1.2)
    assert mild.latency[1] <= 0.004 and hard.latency[1] == pytest.approx(0.010)
    assert mild.push_impulse[1] <= 15.0 and mild.push_interval == (4.0, 6.0)
    assert hard.push_impulse[1] == pytest.approx(25.0)
    assert load_randomization(mild) is mild and load_randomization(None) is None
    extreme = load_randomization("extreme")  # hard, with weaker motors and heavier payloads
    assert extreme.motor_strength == (0.5, 1.3) and extreme.payload_mass[1] == pytest.approx(0.5 * total)
    changed = {f for f in hard.__dataclass_fields__ if getattr(hard, f) != getattr(extreme, f)}
    assert changed == {"motor_strength", "payload_mass"}


def test_for_robot_scales_by_dynamic_similarity_hand_computed():
    """m = 0.5, s = 0.25 (time and speed x 0.5): masses x 0.5, lengths x 0.25, impulses x 0.25, torques x 0.125,
    damping x 0.0625, angular speeds x 2; ratios, friction and latency as written."""
    raw = {
        "scale": "robot", "friction": [0.4, 0.9], "payload_mass": [0.0, 10.0], "payload_com_x": [-0.08, 0.08],
        "link_mass_scale": [0.8, 1.2], "motor_strength": [0.7, 1.3], "joint_damping": [0.0, 1.0],
        "joint_frictionloss": [0.0, 2.0], "latency": [0.0, 0.01], "push_impulse": [0.0, 20.0],
        "push_interval": [4.0, 6.0], "push_duration": [0.1, 0.2],
        "observation_noise": {"base_lin_vel": 0.2, "base_ang_vel": 0.4, "joint_pos": 0.02, "height_scan": 0.1},
    }  # fmt: skip
    got = RandomizationConfig(**raw).for_robot(0.5, 0.25)
    assert got.scale == "none"
    assert got.payload_mass == (0.0, 5.0) and got.payload_com_x == (-0.02, 0.02)
    assert got.push_impulse == (0.0, 5.0) and got.push_interval == (2.0, 3.0) and got.push_duration == (0.05, 0.1)
    assert got.joint_frictionloss == (0.0, 0.25) and got.joint_damping == (0.0, 0.0625)
    assert (got.friction, got.link_mass_scale, got.motor_strength, got.latency) == (
        (0.4, 0.9),
        (0.8, 1.2),
        (0.7, 1.3),
        (0.0, 0.01),
    )
    noise = got.observation_noise
    assert (noise.base_lin_vel, noise.base_ang_vel, noise.joint_pos, noise.height_scan) == (0.1, 0.8, 0.02, 0.025)
    plain = RandomizationConfig(**{**raw, "scale": "none"})
    assert plain.for_robot(0.5, 0.25) is plain  # a user's own ranges are taken as written


def test_the_paper_robot_takes_the_presets_as_written_and_a_urdf_robot_scales_them():
    hard = load_randomization("hard")
    assert hard.scale == "robot"
    paper = randomization_for_robot(hard, load_robot("paper"))
    assert paper.scale == "none" and paper == RandomizationConfig(**{**hard.__dict__, "scale": "none"})
    go1 = load_robot("go1")
    m, s = go1.total_mass / 50.0, go1.leg_length / 0.42
    env = make(robot="go1", randomization="hard", action_mode="joint_pd")
    try:
        r = env.unwrapped.randomization
        assert r.payload_mass[1] == pytest.approx(17.5 * m) and r.push_impulse[1] == pytest.approx(25.0 * m * s**0.5)
        _, info = env.reset(seed=3)
        assert 0.0 <= info["randomization"]["payload_mass"] <= 17.5 * m
    finally:
        env.close()


def test_yaml_path_and_dict_give_the_same_config(tmp_path):
    raw = {"friction": [0.4, 0.9], "observation_noise": {"joint_vel": 0.5}}
    path = tmp_path / "r.yaml"
    path.write_text("friction: [0.4, 0.9]\nobservation_noise: {joint_vel: 0.5}\n")
    assert load_randomization(str(path)) == load_randomization(raw) == RandomizationConfig(**raw)


def test_docs_table_is_in_sync():
    from pathlib import Path

    doc = (Path(__file__).resolve().parents[2] / "docs" / "randomization.md").read_text()
    assert config_table().strip() in doc


# ------------------------------------------------------------------------------------------ draws
def test_same_seed_same_draw_different_seed_different_draw():
    env = make(randomization="mild")
    _, a = env.reset(seed=5)
    model_a = model_arrays(env.unwrapped.model)
    _, b = env.reset(seed=6)
    _, c = env.reset(seed=5)
    assert a["randomization"] == c["randomization"]
    assert_bit_identical(model_a, model_arrays(env.unwrapped.model))  # same draw, same model: no drift
    differ = [k for k in a["randomization"] if a["randomization"][k] != b["randomization"][k]]
    assert {"friction", "payload_mass", "motor_strength_LF_HAA", "link_mass_scale_trunk"} <= set(differ)
    other = make(randomization="mild")
    _, d = other.reset(seed=5)
    assert d["randomization"] == a["randomization"]


def test_a_seed_draws_the_same_world_on_every_terrain():
    worlds = []
    for terrain in ("flat", "rough", {"kind": "stairs", "direction": "up"}):
        _, info = make(terrain=terrain, randomization="mild").reset(seed=21)
        worlds.append(info["randomization"])
    assert worlds[0]["friction"] == worlds[1]["friction"] == worlds[2]["friction"]
    assert {k: v for k, v in worlds[0].items() if k != "total_mass"} == {
        k: v for k, v in worlds[1].items() if k != "total_mass"
    }


def test_randomized_env_keeps_the_nominal_terrain_and_start_of_its_seed():
    nominal, randomized = make(terrain="rough"), make(terrain="rough", randomization="hard")
    nominal.reset(seed=3)
    randomized.reset(seed=3)
    n, r = nominal.unwrapped, randomized.unwrapped
    assert np.array_equal(n.terrain.heightfield.heights, r.terrain.heightfield.heights)
    assert np.array_equal(n.data.qpos, r.data.qpos)


def test_info_has_the_same_float_keys_for_every_config_step_and_episode():
    keys = None
    for spec in (None, "mild", "hard", {"friction": [0.5, 0.6]}):
        env = make(randomization=spec)
        for seed in (0, 1):
            _, info = env.reset(seed=seed)
            infos = [info] + [env.step(env.action_space.sample())[4] for _ in range(3)]
            for i in infos:
                assert all(type(v) is float for v in i["randomization"].values())
                assert i["push_force"].shape == (3,) and i["push_force"].dtype == np.float64
                keys = keys or list(i["randomization"])
                assert list(i["randomization"]) == keys
    assert set(factor_values(info["randomization"])) >= {"friction", "payload_mass", "latency"}


class _FixedShapeInfo(gym.Wrapper):
    """Drops ``edge_moments`` (one entry per support polygon edge: its length varies) so the rest can stack."""

    def reset(self, **kwargs):
        obs, info = self.env.reset(**kwargs)
        info.pop("edge_moments")
        return obs, info

    def step(self, action):
        *out, info = self.env.step(action)
        info.pop("edge_moments")
        return (*out, info)


def test_vector_env_stacks_the_randomization_info():
    envs = gym.vector.SyncVectorEnv([lambda: _FixedShapeInfo(make(randomization="mild")) for _ in range(2)])
    _, info = envs.reset(seed=[1, 2])
    assert info["randomization"]["friction"].shape == (2,)
    _, _, _, _, info = envs.step(np.zeros((2, 12), dtype=np.float32))
    assert info["push_force"].shape == (2, 3)
    assert info["randomization"]["friction"][0] != info["randomization"]["friction"][1]


# ------------------------------------------------------------------------------------------ restore
def test_thousand_resets_without_randomization_leave_the_model_bit_identical():
    env = make()
    u = env.unwrapped
    before = model_arrays(u.model)
    for seed in range(1000):
        u.reset(seed=seed)
    assert_bit_identical(before, model_arrays(u.model))


@pytest.mark.parametrize("action_mode", ["torque", "joint_pd"])
def test_randomized_resets_then_restore_give_the_nominal_model_bit_for_bit(action_mode):
    env = make(randomization="hard", action_mode=action_mode)
    u = env.unwrapped
    before = model_arrays(u.model)
    for seed in range(30):
        u.reset(seed=seed)
        for _ in range(2):
            u.step(np.zeros(12, dtype=np.float32))
    assert u.model.body_subtreemass[u.idx.trunk_body] != before["body_subtreemass"][u.idx.trunk_body]
    u.model_randomizer.restore()
    assert_bit_identical(before, model_arrays(u.model))


# ------------------------------------------------------------------------------------------ factors
def one_factor(**spec):
    env = make(randomization=spec)
    _, info = env.reset(seed=11)
    return env.unwrapped, info["randomization"]


def test_friction_sets_the_foot_and_terrain_coefficient():
    u, drawn = one_factor(friction=[0.3, 0.4])
    assert 0.3 <= drawn["friction"] <= 0.4
    assert u.model.geom_friction[u.idx.terrain_geom, 0] == drawn["friction"]
    assert (u.model.geom_friction[u.idx.foot_geoms, 0] == drawn["friction"]).all()
    assert (u.model.geom_friction[:, 1:] == make().unwrapped.model.geom_friction[:, 1:]).all()


def _with_payload_body(xml: str, mass: float, pos: np.ndarray) -> str:
    """The scene with the payload as a massive child body of the trunk (an independent reference model)."""
    marker = f'<freejoint name="{C.ROOT_JOINT}"/>'
    body = (
        f'<body name="payload" pos="{pos[0]:.17g} {pos[1]:.17g} {pos[2]:.17g}">'
        f'<inertial pos="0 0 0" mass="{mass:.17g}" diaginertia="1e-12 1e-12 1e-12"/></body>'
    )
    assert marker in xml
    return xml.replace(marker, marker + body, 1)


def test_payload_matches_a_model_with_the_payload_as_a_welded_body():
    from quad_uneven_env.robot.model import PhysicsOptions, scene_mjcf

    u, drawn = one_factor(payload_mass=[8.0, 12.0], payload_com_x=[0.03, 0.05], payload_com_y=[-0.05, -0.03])
    nominal_mass = make().unwrapped.total_mass
    assert drawn["total_mass"] == pytest.approx(nominal_mass + drawn["payload_mass"], abs=1e-12)
    assert u.total_mass == drawn["total_mass"] == u.model.body_subtreemass[u.idx.trunk_body]
    pos = np.array([drawn["payload_com_x"], drawn["payload_com_y"], drawn["payload_com_z"]])
    xml = scene_mjcf(
        u.robot, u.terrain.hfield_asset_xml(), u.terrain.hfield_geom_xml(u.robot.friction), PhysicsOptions()
    )
    ref = mujoco.MjModel.from_xml_string(_with_payload_body(xml, drawn["payload_mass"], pos))
    ref_data = mujoco.MjData(ref)
    ref_data.qpos[:], ref_data.qvel[:] = u.data.qpos, u.data.qvel
    mujoco.mj_forward(ref, ref_data)
    M, M_ref = np.zeros((C.NV, C.NV)), np.zeros((C.NV, C.NV))
    mujoco.mj_fullM(u.model, u.data, M)
    mujoco.mj_fullM(ref, ref_data, M_ref)
    np.testing.assert_allclose(M, M_ref, rtol=0, atol=1e-9)
    trunk = u.idx.trunk_body
    np.testing.assert_allclose(u.data.subtree_com[trunk], ref_data.subtree_com[trunk], rtol=0, atol=1e-12)
    np.testing.assert_allclose(u.data.qfrc_bias, ref_data.qfrc_bias, rtol=0, atol=1e-9)


def test_link_mass_scale_scales_each_body_and_the_normalised_index_uses_the_new_mass():
    u, drawn = one_factor(link_mass_scale=[0.5, 0.6])
    nominal = make().unwrapped.model
    for name in ROBOT_BODIES:
        b = u.model.body(name).id
        s = drawn[f"link_mass_scale_{name}"]
        assert 0.5 <= s <= 0.6
        assert u.model.body_mass[b] == nominal.body_mass[b] * s
        np.testing.assert_array_equal(u.model.body_inertia[b], nominal.body_inertia[b] * s)
    assert u.total_mass == pytest.approx(sum(u.model.body_mass[1:]), abs=1e-12)
    assert u.total_mass < 0.61 * 50.0
    _, _, _, _, info = u.step(np.zeros(12, dtype=np.float32))
    g = -u.model.opt.gravity[2]
    assert info["stability_index_normalized"] == pytest.approx(info["stability_index"] / (u.total_mass * g))


def test_motor_strength_scales_the_applied_torque_up_to_the_nominal_limit():
    u, drawn = one_factor(motor_strength=[0.7, 1.3])
    s = np.array([drawn[f"motor_strength_{j}"] for j in C.JOINT_NAMES])
    assert (s < 1).any() and (s > 1).any()
    lim = u.idx.torque_limit
    for fraction in (0.5, 1.0):
        u.data.ctrl[:] = fraction * lim
        mujoco.mj_forward(u.model, u.data)
        np.testing.assert_allclose(u.data.actuator_force, np.minimum(s * fraction, 1.0) * lim, rtol=1e-12)


def test_motor_strength_scales_the_servo_torque_in_joint_pd_mode():
    env = make(randomization={"motor_strength": [0.7, 1.3]}, action_mode="joint_pd")
    _, info = env.reset(seed=11)
    u = env.unwrapped
    s = np.array([info["randomization"][f"motor_strength_{j}"] for j in C.JOINT_NAMES])
    nominal = make(action_mode="joint_pd").unwrapped
    nominal.reset(seed=11)
    for d in (u.data, nominal.data):
        d.qpos[:], d.qvel[:] = u.data.qpos, 0.3
        d.ctrl[:] = u.data.qpos[7:] + 0.1
    mujoco.mj_forward(u.model, u.data)
    mujoco.mj_forward(nominal.model, nominal.data)
    lim = u.idx.torque_limit
    expected = np.clip(s * nominal.data.actuator_force, -lim, lim)
    np.testing.assert_allclose(u.data.actuator_force, expected, rtol=1e-12, atol=1e-12)


def test_joint_damping_and_frictionloss_act_on_the_joints():
    u, drawn = one_factor(joint_damping=[1.0, 2.0], joint_frictionloss=[3.0, 4.0])
    damping = np.array([drawn[f"joint_damping_{j}"] for j in C.JOINT_NAMES])
    floss = np.array([drawn[f"joint_frictionloss_{j}"] for j in C.JOINT_NAMES])
    assert ((damping >= 1) & (damping <= 2)).all() and ((floss >= 3) & (floss <= 4)).all()
    np.testing.assert_array_equal(u.model.dof_damping[6:], damping)
    np.testing.assert_array_equal(u.model.dof_frictionloss[6:], floss)
    u.data.qvel[6:] = 0.5
    mujoco.mj_forward(u.model, u.data)
    np.testing.assert_allclose(u.data.qfrc_damper[6:], -damping * 0.5, rtol=1e-12)
    friction_rows = u.data.efc_type[: u.data.nefc] == mujoco.mjtConstraint.mjCNSTR_FRICTION_DOF
    assert friction_rows.sum() == C.N_JOINTS


@pytest.mark.parametrize("action_mode", ["torque", "joint_pd"])
def test_latency_applies_the_command_k_physics_steps_late(action_mode):
    """Reference: the same two control steps by hand, the previous command held for the first k steps."""
    env = make(randomization={"latency": [0.006, 0.006]}, action_mode=action_mode)
    u = env.unwrapped
    u.reset(seed=2)
    assert u.episode_draw.latency_steps == 3
    m, d = u.model, mujoco.MjData(u.model)
    spec = mujoco.mjtState.mjSTATE_INTEGRATION
    state = np.empty(mujoco.mj_stateSize(m, spec))
    mujoco.mj_getState(m, u.data, state, spec)
    mujoco.mj_setState(m, d, state, spec)
    held, home = d.ctrl.copy(), d.qpos[7:].copy()
    rng = np.random.default_rng(0)
    for _ in range(2):
        a = rng.uniform(-0.2, 0.2, 12)
        u.step(a.astype(np.float32))
        a = a.astype(np.float32).astype(np.float64)
        cmd = a * u.idx.torque_limit if action_mode == "torque" else home + u.pd_action_scale * a
        cmd = np.clip(cmd, *(m.actuator_ctrlrange.T))
        for j in range(u.frame_skip):
            d.ctrl[:] = held if j < 3 else cmd
            mujoco.mj_step(m, d)
        held = cmd
        np.testing.assert_array_equal(u.data.qpos, d.qpos)


def test_latency_delays_the_controller_hook_torques():
    calls = []

    def controller(model, data, action):
        calls.append(data.ctrl[0])  # what the last physics step applied
        return np.full(12, float(len(calls)))  # command n = n N m

    env = make(randomization={"latency": [0.004, 0.004]}, controller=controller)
    env.reset(seed=0)
    for _ in range(3):
        env.step(np.zeros(12, dtype=np.float32))
    k = 2
    applied = np.array(calls[1:])  # applied at physics steps 0, 1, ...
    expected = np.array([max(n + 1 - k, 0) for n in range(len(applied))], dtype=float)
    np.testing.assert_array_equal(applied, expected)


def test_push_delivers_its_impulse_and_moves_the_trunk():
    spec = {"push_impulse": [20.0, 20.0], "push_interval": [0.1, 0.1], "push_duration": [0.05, 0.05]}
    pushed, still = make(randomization=spec, action_mode="joint_pd"), make(action_mode="joint_pd")
    pushed.reset(seed=4)
    still.reset(seed=4)
    impulse = np.zeros(3)
    zero = np.zeros(12, dtype=np.float32)
    for _ in range(10):  # 0.2 s: the push runs from 0.1 s to 0.15 s
        _, _, _, _, info = pushed.step(zero)
        _, _, _, _, ref = still.step(zero)
        impulse += info["push_force"] * pushed.unwrapped.dt
    push = pushed.unwrapped.pushes[0]
    assert push.start == pytest.approx(0.1) and push.duration == pytest.approx(0.05)
    direction = np.array([np.cos(np.radians(push.direction_deg)), np.sin(np.radians(push.direction_deg)), 0.0])
    np.testing.assert_allclose(impulse, 20.0 * direction, atol=1e-9)
    moved = (info["cog"] - ref["cog"]) @ direction
    assert moved > 0.005  # m: ~ J / m x 0.05 s at most = 0.02 m (less: the feet resist)
    assert np.linalg.norm(info["push_force"]) == 0.0  # over by 0.2 s


def test_observation_noise_stays_in_bounds_and_within_its_scale():
    noise = {"joint_vel": 0.5, "foot_contact": 0.3, "height_scan": 0.05}
    noisy, clean = make(randomization={"observation_noise": noise}), make()
    o1, _ = noisy.reset(seed=9)
    o2, _ = clean.reset(seed=9)
    space = noisy.observation_space
    st = noisy.unwrapped.observation_structure
    for _ in range(20):
        assert space.contains(o1)
        diff = o1.astype(np.float64) - o2
        for name, sl in st.items():
            scale = noise.get(name, 0.0)
            assert np.all(np.abs(diff[sl]) <= scale + 1e-6), name
            if scale == 0.0:
                assert np.all(diff[sl] == 0.0), name
        assert np.abs(diff[st["joint_vel"]]).max() > 0.05
        a = noisy.action_space.sample()
        o1, _, t1, _, _ = noisy.step(a)
        o2, _, t2, _, _ = clean.step(a)
        assert t1 == t2


# ------------------------------------------------------------------------------------------ checkers
@pytest.mark.parametrize("action_mode", ["torque", "joint_pd"])
def test_env_checkers_pass_with_randomization(action_mode):
    from gymnasium.utils.env_checker import check_env
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = make(terrain="rough", randomization="hard", action_mode=action_mode)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env.unwrapped, skip_render_check=True)
        sb3_check_env(env.unwrapped, warn=True)


def test_model_randomizer_snapshot_covers_what_mj_setconst_recomputes():
    u = make(randomization="hard").unwrapped
    probe = copy.deepcopy(u.model)
    probe.body_mass[1:] *= 2.0
    mujoco.mj_setConst(probe, mujoco.MjData(probe))
    before, after = model_arrays(u.model), model_arrays(probe)
    changed = {n for n in before if before[n].tobytes() != after[n].tobytes()}
    assert changed <= set(u.model_randomizer.restored_fields)
