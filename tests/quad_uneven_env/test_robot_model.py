"""The robot model: Table 1 in MuJoCo, agreement with Pinocchio, conventions, kinematics."""

from __future__ import annotations

import mujoco
import numpy as np
import pinocchio as pin
import pytest

from quad_uneven_env import constants as C
from quad_uneven_env.config import read_yaml, resolve_config_path
from quad_uneven_env.robot import conventions as conv
from quad_uneven_env.robot.description import MIN_INERTIA, load_robot
from quad_uneven_env.robot.kinematics import leg_fk_hip, leg_ik_hip
from quad_uneven_env.robot.model import robot_mjcf
from quad_uneven_env.robot.table1 import from_table1


@pytest.fixture(scope="module")
def models(paper_robot, tmp_path_factory):
    xml = robot_mjcf(paper_robot)
    path = tmp_path_factory.mktemp("mjcf") / "robot.xml"
    path.write_text(xml)
    mj = mujoco.MjModel.from_xml_string(xml)
    pm = pin.buildModelFromMJCF(str(path))
    return mj, pm


def random_qpos(paper_robot, mj, rng):
    q = np.zeros(C.NQ)
    q[:3] = rng.uniform(-1, 1, 3)
    quat = rng.normal(size=4)
    q[3:7] = quat / np.linalg.norm(quat)
    lo, hi = mj.jnt_range[1:, 0], mj.jnt_range[1:, 1]
    q[7:] = rng.uniform(lo, hi)
    return q


def test_table1_masses_and_inertias(paper_robot, models):
    mj, _ = models
    body = mj.body(C.TRUNK_BODY)
    assert body.mass[0] == pytest.approx(40.0)
    np.testing.assert_allclose(body.inertia, [0.4897, 0.8667, 1.2879])
    thigh = mj.body(C.thigh_body("LF"))
    assert thigh.mass[0] == pytest.approx(2.0)
    np.testing.assert_allclose(thigh.ipos, [0, 0, -0.02])
    # Table 1's zero inertia about the long axis becomes mjMINVAL (the long axis is body z).
    np.testing.assert_allclose(thigh.inertia, [0.0067, 0.0067, MIN_INERTIA])
    shank = mj.body(C.shank_body("RH"))
    assert shank.mass[0] == pytest.approx(0.5)
    np.testing.assert_allclose(shank.ipos, [0, 0, -0.08])
    np.testing.assert_allclose(mj.body(C.shank_body("RH")).pos, [0, 0, -0.2])
    assert mujoco.mj_getTotalmass(mj) == pytest.approx(50.0)
    assert paper_robot.total_mass == pytest.approx(50.0)


def test_names_and_orders(models):
    mj, _ = models
    for leg in C.LEG_NAMES:
        assert mj.site(C.foot_site(leg)).id >= 0
    # Joint order in qpos is the project's JOINT_NAMES order.
    adr = [mj.joint(j).qposadr[0] for j in C.JOINT_NAMES]
    assert adr == list(range(7, 19))
    # Hips at the body corners, leg order LF, RF, LH, RH.
    hips = np.array([mj.body(C.thigh_body(leg)).pos for leg in C.LEG_NAMES])
    np.testing.assert_allclose(hips, [[0.25, 0.185, 0], [0.25, -0.185, 0], [-0.25, 0.185, 0], [-0.25, -0.185, 0]])


def test_knee_range_avoids_stretched_singularity(paper_robot, models):
    mj, _ = models
    for leg in C.LEG_NAMES:
        lo, hi = mj.joint(C.joint_name(leg, "KFE")).range
        assert not lo <= 0.0 <= hi, f"{leg} knee range {lo, hi} contains the stretched knee"


def test_pinocchio_agrees_with_mujoco(paper_robot, models, rng):
    mj, pm = models
    pdata = pin.Data(pm)
    md = mujoco.MjData(mj)
    assert pin.computeTotalMass(pm) == pytest.approx(mujoco.mj_getTotalmass(mj), abs=1e-12)
    for _ in range(20):
        qpos = random_qpos(paper_robot, mj, rng)
        md.qpos[:] = qpos
        mujoco.mj_forward(mj, md)
        q_pin = conv.qpos_mj_to_pin(qpos)
        com_pin = pin.centerOfMass(pm, pdata, q_pin)
        np.testing.assert_allclose(com_pin, md.subtree_com[mj.body(C.TRUNK_BODY).id], atol=1e-12)
        M_mj = np.zeros((mj.nv, mj.nv))
        mujoco.mj_fullM(mj, md, M_mj)
        M_pin = pin.crba(pm, pdata, q_pin)
        M_pin = np.triu(M_pin) + np.triu(M_pin, 1).T
        np.testing.assert_allclose(conv.mass_matrix_pin_to_mj(qpos, M_pin), M_mj, atol=1e-10)


def test_convention_roundtrip(rng):
    qpos = np.zeros(C.NQ)
    quat = rng.normal(size=4)
    qpos[3:7] = quat / np.linalg.norm(quat)
    qpos[7:] = rng.normal(size=12)
    np.testing.assert_array_equal(conv.qpos_pin_to_mj(conv.qpos_mj_to_pin(qpos)), qpos)
    qvel = rng.normal(size=C.NV)
    np.testing.assert_allclose(conv.qvel_pin_to_mj(qpos, conv.qvel_mj_to_pin(qpos, qvel)), qvel, atol=1e-14)
    qacc = rng.normal(size=C.NV)
    v = conv.qvel_mj_to_pin(qpos, qvel)
    a = conv.qacc_mj_to_pin(qpos, qvel, qacc)
    np.testing.assert_allclose(conv.qacc_pin_to_mj(qpos, v, a), qacc, atol=1e-13)
    # Against MuJoCo's own quaternion -> matrix.
    R = np.zeros(9)
    mujoco.mju_quat2Mat(R, qpos[3:7])
    np.testing.assert_allclose(conv.quat_to_matrix(qpos[3:7]), R.reshape(3, 3), atol=1e-14)


def test_qacc_conversion_matches_finite_difference(rng):
    # The base linear acceleration of MuJoCo is d/dt of v_W; Pinocchio's is d/dt of v_B.
    qpos = np.zeros(C.NQ)
    qpos[3:7] = [np.cos(0.3), np.sin(0.3), 0, 0]
    v = rng.normal(size=C.NV)
    a = rng.normal(size=C.NV)
    h = 1e-6
    q_pin = conv.qpos_mj_to_pin(qpos)
    model = pin.Model()
    model.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), "ff")
    q1 = pin.integrate(model, q_pin[:7], v[:6] * h + 0.5 * a[:6] * h * h)
    v1 = v[:6] + a[:6] * h
    vw0 = conv.qvel_pin_to_mj(qpos[:7], v[:6])[:3]
    vw1 = conv.qvel_pin_to_mj(conv.qpos_pin_to_mj(q1), v1)[:3]
    acc_fd = (vw1 - vw0) / h
    np.testing.assert_allclose(conv.qacc_pin_to_mj(qpos[:7], v[:6], a[:6])[:3], acc_fd, atol=1e-4)


def test_leg_fk_matches_mujoco_and_ik_inverts_it(paper_robot, models, rng):
    mj, _ = models
    md = mujoco.MjData(mj)
    qpos = paper_robot.home_qpos()
    qpos[:3] = 0.0
    qpos[7:] += rng.uniform(-0.15, 0.15, 12)
    md.qpos[:] = qpos
    mujoco.mj_forward(mj, md)
    l1, l2 = paper_robot.two_link.thigh, paper_robot.two_link.shank
    for i, leg in enumerate(C.LEG_NAMES):
        q_leg = qpos[7 + 3 * i : 10 + 3 * i]
        hip = mj.body(C.thigh_body(leg)).pos
        np.testing.assert_allclose(
            hip + leg_fk_hip(q_leg, l1, l2), md.site_xpos[mj.site(C.foot_site(leg)).id], atol=1e-12
        )
        q_back = leg_ik_hip(leg_fk_hip(q_leg, l1, l2), l1, l2, C.KNEE_SIGN[leg])
        np.testing.assert_allclose(q_back, q_leg, atol=1e-10)


def test_home_pose_feet_touch_ground(paper_robot, models):
    mj, _ = models
    md = mujoco.MjData(mj)
    md.qpos[:] = paper_robot.home_qpos(ground_height=0.1)
    mujoco.mj_forward(mj, md)
    feet = md.site_xpos[[mj.site(s).id for s in C.FOOT_SITES]]
    np.testing.assert_allclose(feet[:, 2], 0.1 + paper_robot.foot_radius, atol=1e-12)


def test_bad_robot_config_names_field():
    raw = read_yaml(resolve_config_path("paper", "robot"))
    raw["thigh"] = dict(raw["thigh"], mass=-1.0)
    with pytest.raises(ValueError, match=r"robot\.thigh\.mass"):
        from_table1(raw)
    raw = read_yaml(resolve_config_path("paper", "robot"))
    raw["joint_range"] = dict(raw["joint_range"], KFE_front=[-2.0, 0.1])
    with pytest.raises(ValueError, match="KFE_front"):
        from_table1(raw)
    raw = read_yaml(resolve_config_path("paper", "robot"))
    raw["colour"] = "red"
    with pytest.raises(ValueError, match="colour"):
        from_table1(raw)
    with pytest.raises(ValueError, match="unknown robot config"):
        load_robot("nonexistent")


def test_yaw_of_quat_and_wrap_angle_against_scipy(rng):
    """The heading of random orientations is scipy's z-y-x yaw; wrap_angle lands in [-pi, pi) and differs
    from its input by a whole number of turns."""
    from scipy.spatial.transform import Rotation

    from quad_uneven_env.spatial import wrap_angle, yaw_of_quat

    quats = rng.normal(size=(50, 4))
    quats /= np.linalg.norm(quats, axis=1, keepdims=True)
    for q in quats:
        expected = Rotation.from_quat(q, scalar_first=True).as_euler("ZYX")[0]
        assert yaw_of_quat(q) == pytest.approx(expected, abs=1e-12)
    for a in np.concatenate([rng.uniform(-20.0, 20.0, 50), [np.pi, -np.pi, 0.0, 3 * np.pi]]):
        w = wrap_angle(float(a))
        assert -np.pi <= w < np.pi
        turns = (a - w) / (2 * np.pi)
        assert turns == pytest.approx(round(turns), abs=1e-9)
