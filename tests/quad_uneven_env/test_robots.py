"""Robot descriptions: the paper's robot and the URDF robots of example-robot-data, against Pinocchio.

Every URDF robot's description, kinematics and generated MuJoCo model are checked against Pinocchio reading
the same URDF: foot points (forward kinematics), total mass, the joint-space mass matrix and the bias forces.
The URDF robots need the ``robots`` extra (example-robot-data); without it these tests fail, naming it.
"""

from __future__ import annotations

import hashlib
import textwrap
from pathlib import Path

import gymnasium as gym
import mujoco
import numpy as np
import pinocchio as pin
import pytest

import quad_uneven_env
from quad_uneven_env import constants as C
from quad_uneven_env.config import CONFIG_DIR, read_yaml
from quad_uneven_env.env_config import default_pd_gains
from quad_uneven_env.robot import conventions as cv
from quad_uneven_env.robot.description import RobotDescription, load_robot, robot_data_dir
from quad_uneven_env.robot.kinematics import leg_fk_hip
from quad_uneven_env.robot.leg_chain import feet_ik_B, feet_positions_B, leg_fk_B
from quad_uneven_env.robot.model import PhysicsOptions, robot_mjcf, scene_mjcf
from quad_uneven_env.terrain import Terrain, parse_terrain_spec

URDF_ROBOTS = ("anymal_c", "go1", "hyq", "solo12")
# Published masses (kg) of the URDFs, to one decimal: HyQ 86.8, ANYmal C 52.1, Go1 13.1, Solo12 2.5.
MASSES = {"anymal_c": 52.1, "go1": 13.1, "hyq": 86.8, "solo12": 2.5}
KNEES = {
    "anymal_c": ("backward", "backward", "forward", "forward"),  # the X of ANYmal
    "hyq": ("backward", "backward", "forward", "forward"),
    "go1": ("backward",) * 4,  # Unitree: every knee behind its hip-foot line
    "solo12": ("backward", "backward", "forward", "forward"),
    "paper": ("backward", "backward", "forward", "forward"),
}


def _pin_model(desc: RobotDescription) -> tuple[pin.Model, np.ndarray, np.ndarray]:
    """Pinocchio's model of the description's URDF, with its armature, and the indices (q, v) of our joints."""
    model = pin.buildModelFromUrdf(desc.source, pin.JointModelFreeFlyer())
    jids = [model.getJointId(j.name) for leg in desc.legs for j in leg.joints]
    iq = np.array([model.joints[j].idx_q for j in jids])
    iv = np.array([model.joints[j].idx_v for j in jids])
    model.armature[iv] = [j.armature for leg in desc.legs for j in leg.joints]
    return model, iq, iv


def test_robot_data_is_installed():
    """The URDF robots' models come from the ``robots`` extra; without it every URDF test below fails too."""
    assert (robot_data_dir() / "go1_description" / "urdf" / "go1.urdf").is_file()


def test_robots_lists_the_shipped_robots():
    assert quad_uneven_env.robots() == sorted(("paper", *URDF_ROBOTS))


@pytest.mark.parametrize("name", URDF_ROBOTS)
def test_description_reads_the_urdf(name):
    desc = load_robot(name)
    assert desc.two_link is None and desc.name == name
    assert desc.total_mass == pytest.approx(MASSES[name], abs=0.05)
    model, _, _ = _pin_model(desc)
    assert desc.total_mass == pytest.approx(sum(y.mass for y in model.inertias), rel=1e-12)
    assert desc.knee_directions == KNEES[name]
    assert np.all(desc.torque_limits > 0) and np.all(desc.torque_limits < 500)
    # the standing pose touches flat ground with its lowest foot sphere, and every foot is below the trunk
    feet = feet_positions_B(desc, desc.standing_joints)
    assert np.min(feet[:, 2]) == pytest.approx(desc.foot_radius - desc.standing_height)
    assert np.all(feet[:, 2] < -0.5 * desc.standing_height)


def test_solo12_torque_limits_come_from_its_yaml_not_the_urdf():
    """Solo12's URDF declares 1000 N m efforts; configs/robot/solo12.yaml sets the motors' 2.7 N m."""
    desc = load_robot("solo12")
    model, _, iv = _pin_model(desc)
    assert np.all(model.effortLimit[iv] == 1000.0)
    assert np.all(desc.torque_limits == 2.7)


def test_paper_description_matches_table_1():
    """The Table-1 robot's description says what configs/robot/paper.yaml says, and its joint chain moves the feet
    as the closed form of its two-link legs does."""
    raw = read_yaml(CONFIG_DIR / "robot" / "paper.yaml")
    desc = load_robot("paper")
    thigh, shank = raw["thigh"], raw["shank"]
    assert desc.total_mass == raw["body"]["mass"] + 4 * (thigh["mass"] + shank["mass"])
    assert (desc.two_link.thigh, desc.two_link.shank) == (thigh["length"], shank["length"])
    assert desc.two_link.hip_height == raw["standing_hip_height"]
    half = np.array(raw["body"]["size"][:2]) / 2
    np.testing.assert_array_equal(np.abs(desc.hip_positions_B[:, :2]), np.tile(half, (4, 1)))
    assert desc.knee_directions == KNEES["paper"]
    assert desc.standing_height == pytest.approx(raw["standing_hip_height"] + raw["foot_radius"], abs=1e-15)
    rng = np.random.default_rng(3)
    q = rng.uniform(-1.5, 1.5, (50, 3))
    for i, leg in enumerate(desc.legs):
        hip = desc.hip_positions_B[i]
        assert np.allclose(leg_fk_B(leg, q), hip + leg_fk_hip(q, thigh["length"], shank["length"]), atol=1e-12)
    feet = feet_positions_B(desc, desc.standing_joints)
    np.testing.assert_allclose(feet, desc.standing_feet_B, atol=1e-12)
    np.testing.assert_allclose(feet[:, 2], -raw["standing_hip_height"], atol=1e-12)


@pytest.mark.parametrize("name", URDF_ROBOTS)
def test_forward_kinematics_matches_pinocchio(name):
    desc = load_robot(name)
    model, iq, _ = _pin_model(desc)
    data = model.createData()
    frames = [model.getFrameId(leg.foot_frame) for leg in desc.legs]
    rng = np.random.default_rng(0)
    for _ in range(25):
        qj = rng.uniform(-np.pi, np.pi, C.N_JOINTS)
        q = pin.neutral(model)
        q[iq] = qj
        pin.forwardKinematics(model, data, q)
        pin.updateFramePlacements(model, data)
        expected = np.array([data.oMf[f].translation for f in frames])  # root at the origin: trunk frame
        assert np.allclose(feet_positions_B(desc, qj), expected, atol=1e-9, rtol=0)


@pytest.mark.parametrize("name", ("paper", *URDF_ROBOTS))
def test_inverse_kinematics_round_trip(name):
    """Joint angles near the standing pose (the knee on its side) -> feet -> the same angles, to 1e-9."""
    desc = load_robot(name)
    rng = np.random.default_rng(1)
    q = desc.standing_joints + rng.uniform(-0.3, 0.3, (200, C.N_JOINTS))
    feet = feet_positions_B(desc, q)
    q_back = feet_ik_B(desc, feet)
    assert np.allclose(q_back, q, atol=1e-9, rtol=0)
    assert np.allclose(feet_positions_B(desc, q_back), feet, atol=1e-9, rtol=0)


@pytest.mark.parametrize("name", URDF_ROBOTS)
def test_generated_mjcf_has_the_urdf_dynamics(name):
    """Total mass, mj_fullM vs pin.crba and qfrc_bias vs pin.rnea (MuJoCo's coordinates, conventions.py)."""
    desc = load_robot(name)
    mm = mujoco.MjModel.from_xml_string(robot_mjcf(desc))
    md = mujoco.MjData(mm)
    model, iq, iv = _pin_model(desc)
    data = model.createData()
    assert mm.body_subtreemass[mm.body(C.TRUNK_BODY).id] == pytest.approx(desc.total_mass, rel=1e-12)
    perm = np.r_[0:6, iv]  # Pinocchio's velocity index of each of MuJoCo's
    rng = np.random.default_rng(2)
    for _ in range(10):
        quat = rng.normal(size=4)
        qpos = np.r_[rng.normal(size=3), quat / np.linalg.norm(quat), rng.uniform(-2, 2, C.N_JOINTS)]
        qvel = rng.normal(size=C.NV)
        md.qpos[:], md.qvel[:] = qpos, qvel
        mujoco.mj_forward(mm, md)
        M = np.zeros((C.NV, C.NV))
        mujoco.mj_fullM(mm, md, M)
        q = pin.neutral(model)
        q[:7] = cv.qpos_mj_to_pin(qpos)[:7]
        q[iq] = qpos[7:]
        v = np.zeros(C.NV)
        v[perm] = cv.qvel_mj_to_pin(qpos, qvel)
        M_pin = pin.crba(model, data, q)
        M_pin = np.triu(M_pin) + np.triu(M_pin, 1).T
        assert np.allclose(M, cv.mass_matrix_pin_to_mj(qpos, M_pin[np.ix_(perm, perm)]), atol=1e-8, rtol=0)
        # the bias is the generalized force at zero MuJoCo acceleration: Pinocchio's, mapped by T^-T
        a = np.zeros(C.NV)
        a[perm] = cv.qacc_mj_to_pin(qpos, qvel, np.zeros(C.NV))
        tau_pin = pin.rnea(model, data, q, v, a)[perm]
        bias = np.linalg.solve(cv.velocity_map(qpos).T, tau_pin)
        assert np.allclose(md.qfrc_bias, bias, atol=1e-8, rtol=0)


def test_paper_scene_mjcf_is_pinned():
    """The default env's MJCF, byte for byte (SHA-256 of the document the one generator writes for the paper
    robot on the rough terrain, and of the robot alone): a change that moves the paper robot's model shows here."""
    desc = load_robot("paper")
    terrain = Terrain(parse_terrain_spec("rough"))
    xml = scene_mjcf(desc, terrain.hfield_asset_xml(), terrain.hfield_geom_xml(desc.friction), PhysicsOptions())
    assert hashlib.sha256(xml.encode()).hexdigest() == (
        "293ff00bbc2b7fd203731db698e223edc4de12a7c59825b87d52eb7bca9e94a8"
    )
    assert hashlib.sha256(robot_mjcf(desc).encode()).hexdigest() == (
        "9bed51f717f295ac26d63b969c6427b7a05a69b6b3fce4277997e6571a1a9b49"
    )


@pytest.mark.parametrize("name", URDF_ROBOTS)
def test_env_builds_and_steps_on_each_robot(name):
    """Same observation layout as the paper's robot; a PD hold keeps every robot up for 1 s of rough terrain."""
    paper = gym.make("QuadUneven-v0")
    env = gym.make("QuadUneven-v0", robot=name, action_mode="joint_pd", reset_noise_scale=0.0)
    try:
        assert env.observation_space == paper.observation_space
        assert env.unwrapped.observation_structure == paper.unwrapped.observation_structure
        obs, info = env.reset(seed=0)
        assert env.observation_space.contains(obs)
        u = env.unwrapped
        feet = u.data.site_xpos[u.idx.foot_sites]  # spawned with each foot sphere on the terrain under it
        ground = u.terrain.height(feet[:, 0], feet[:, 1])
        assert np.allclose(feet[:, 2] - u.robot.foot_radius, ground, atol=1e-9)
        assert np.allclose(env.unwrapped.idx.torque_limit, load_robot(name).torque_limits)
        for _ in range(50):
            obs, _, terminated, _, info = env.step(np.zeros(C.N_JOINTS))
            assert not terminated, info["termination_reason"]
        assert env.observation_space.contains(obs)
        assert np.sum(info["foot_contact"]) >= 3
    finally:
        env.close()
        paper.close()


@pytest.mark.parametrize("name", ("paper", *URDF_ROBOTS))
def test_env_defaults_follow_the_robot(name):
    """The base-height limits are a third of the standing height and 2.78 times it, the joint_pd gains scale with
    weight x leg length; the paper robot's are exactly 0.12 m, 1 m and (100, 3)."""
    desc = load_robot(name)
    env = gym.make("QuadUneven-v0", robot=name, action_mode="joint_pd")
    u = env.unwrapped
    kp, kd = default_pd_gains(desc)
    if name == "paper":
        assert (u.termination.min_base_height, u.termination.max_base_height) == (0.12, 1.0)
        assert (kp, kd) == (100.0, 3.0)
    else:
        assert u.termination.min_base_height == pytest.approx(desc.standing_height / 3.0)
        assert u.termination.max_base_height == pytest.approx(desc.standing_height / 0.36)
        assert kp == pytest.approx(100.0 * desc.total_mass * desc.leg_length / (50.0 * 0.42))
    assert u.model.actuator_gainprm[0, 0] == pytest.approx(kp)
    assert u.model.actuator_biasprm[0, 2] == pytest.approx(-kd)
    env.close()
    # given values win
    given = {"termination": {"min_base_height": 0.05}, "pd_kp": 7.0}
    env = gym.make("QuadUneven-v0", robot=name, action_mode="joint_pd", **given)
    assert env.unwrapped.termination.min_base_height == 0.05 and env.unwrapped.model.actuator_gainprm[0, 0] == 7.0
    env.close()


# ---------------------------------------------------------------------- a user's own robot, and bad ones
def _user_robot(tmp_path: Path, urdf_text: str | None = None, **yaml_over: str) -> Path:
    """A user's robot: Go1's URDF copied beside a YAML that names it by a relative path."""
    src = (robot_data_dir() / "go1_description" / "urdf" / "go1.urdf").read_text()
    (tmp_path / "models").mkdir(exist_ok=True)
    (tmp_path / "models" / "mine.urdf").write_text(urdf_text(src) if urdf_text else src)
    fields = {
        "name": "mine",
        "urdf": "models/mine.urdf",
        "legs": textwrap.dedent("""
          LF: {joints: [FL_hip_joint, FL_thigh_joint, FL_calf_joint], foot: FL_foot}
          RF: {joints: [FR_hip_joint, FR_thigh_joint, FR_calf_joint], foot: FR_foot}
          LH: {joints: [RL_hip_joint, RL_thigh_joint, RL_calf_joint], foot: RL_foot}
          RH: {joints: [RR_hip_joint, RR_thigh_joint, RR_calf_joint], foot: RR_foot}"""),
        "foot_radius": "0.02",
        "standing_joints": "{LF: [0, 0.8, -1.6], RF: [0, 0.8, -1.6], LH: [0, 0.8, -1.6], RH: [0, 0.8, -1.6]}",
    }
    fields.update(yaml_over)
    text = "".join(f"{k}:{textwrap.indent(v, '  ')}\n" if "\n" in v else f"{k}: {v}\n" for k, v in fields.items() if v)
    path = tmp_path / "mine.yaml"
    path.write_text(text)
    return path


def test_a_robot_yamls_gait_section_is_read(tmp_path):
    assert load_robot("go1").gait.cycle_time is None  # the shipped Go1 scales every gait setting
    desc = load_robot(_user_robot(tmp_path, gait="{cycle_time: 2.0, stride: 0.2}"))
    assert (desc.gait.cycle_time, desc.gait.stride, desc.gait.swing_height) == (2.0, 0.2, None)


def test_a_users_robot_by_yaml_path(tmp_path):
    path = _user_robot(tmp_path)
    desc = load_robot(path)
    assert desc.name == "mine" and desc.total_mass == pytest.approx(load_robot("go1").total_mass)
    env = gym.make("QuadUneven-v0", robot=str(path), action_mode="joint_pd")
    env.reset(seed=1)
    env.step(np.zeros(C.N_JOINTS))
    env.close()


@pytest.mark.parametrize(
    ("edit", "yaml_over", "message"),
    [
        (None, {"foot_radius": "-0.02"}, r"mine\.yaml\.foot_radius must be a number in \(0, inf\) \(m\), got -0\.02"),
        (None, {"legs": "{LF: {joints: [FL_hip_joint, FL_thigh_joint, FL_calf_joint], foot: FL_toe}}"}, r"\.legs"),
        (
            None,
            {
                "legs": textwrap.dedent("""
              LF: {joints: [FL_hip_joint, FL_thigh_joint, FL_calf_joint], foot: FL_toe}
              RF: {joints: [FR_hip_joint, FR_thigh_joint, FR_calf_joint], foot: FR_foot}
              LH: {joints: [RL_hip_joint, RL_thigh_joint, RL_calf_joint], foot: RL_foot}
              RH: {joints: [RR_hip_joint, RR_thigh_joint, RR_calf_joint], foot: RR_foot}""")
            },
            r"legs\.LF\.foot: frame 'FL_toe' is not in",
        ),
        (None, {"torque_limit": "{HAA: 0}"}, r"torque_limit\.HAA must be a number in \(0, inf\) \(N m\), got 0"),
        (None, {"colour": "red"}, r"unknown field\(s\) \['colour'\]"),
        (None, {"gait": "{stride: -0.1}"}, r"gait\.stride must be a number in \(0, 1\] or null \(m\), got -0\.1"),
        (None, {"gait": "{cycle_time: 0.01}"}, r"gait\.cycle_time must be a number in \[0\.2, 20\]"),
        (None, {"gait": "{speed: 1}"}, r"gait.*unknown.*speed"),
        (
            lambda s: s.replace(
                '<joint name="FL_calf_joint" type="revolute">', '<joint name="FL_calf_joint" type="fixed">'
            ),
            {},
            r"12 actuated joints",
        ),
        (
            lambda s: s.replace('<mass value="0.135862"/>', '<mass value="-0.2"/>', 1),  # + the foot's 0.06 kg
            {},
            r"KFE\.link\.mass must be a finite number > 0",
        ),
        (
            lambda s: s.replace('ixx="0.004431760472"', 'ixx="-0.004431760472"', 1),
            {},
            r"inertia must be positive definite",
        ),
        (
            lambda s: s.replace(
                '<joint name="FL_thigh_joint" type="revolute">\n    <origin rpy="0 0 0" xyz="0 0.08 0"/>\n'
                '    <parent link="FL_hip"/>\n    <child link="FL_thigh"/>\n    <axis xyz="0 1 0"/>',
                '<joint name="FL_thigh_joint" type="revolute">\n    <origin rpy="0 0 0" xyz="0 0.08 0"/>\n'
                '    <parent link="FL_hip"/>\n    <child link="FL_thigh"/>\n    <axis xyz="0 0 1"/>',
            ),
            {},
            r"LF\.HFE \(FL_thigh_joint\) must turn about trunk y",
        ),
    ],
    ids=[
        *("radius", "legs", "foot", "torque", "unknown", "gait_stride", "gait_cycle", "gait_unknown"),
        *("joints", "mass", "inertia", "axis"),
    ],
)
def test_bad_descriptions_are_refused_naming_the_field(tmp_path, edit, yaml_over, message):
    path = _user_robot(tmp_path, edit, **yaml_over)
    if edit is not None:  # the edit must have changed the URDF, or the test proves nothing
        assert (tmp_path / "models" / "mine.urdf").read_text() != (
            robot_data_dir() / "go1_description" / "urdf" / "go1.urdf"
        ).read_text()
    with pytest.raises(ValueError, match=message):
        load_robot(path)


@pytest.mark.parametrize("name", ("paper", *URDF_ROBOTS))
def test_every_robot_passes_the_env_checkers(name):
    """Gymnasium's checker (spaces, seeding, the exact determinism of a seeded reset and step) and SB3's, on each
    robot's QuadUneven-v0 in its default action mode."""
    from gymnasium.utils.env_checker import check_env
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = gym.make("QuadUneven-v0", robot=name, terrain="rough")
    assert env.unwrapped.robot.name == name
    check_env(env.unwrapped, skip_render_check=True)
    sb3_check_env(env.unwrapped, warn=True)
