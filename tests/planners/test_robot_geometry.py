"""The planners' view of a robot (planners.robot_geometry): the paper's numbers, and the chain model of URDF legs."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from planners.robot_geometry import LegChainModel, robot_geometry
from planners.wholebody import WholeBody, leg_point
from quad_uneven_env.robot.description import load_robot
from quad_uneven_env.robot.leg_chain import leg_fk_B
from quad_uneven_env.robot.model import robot_mjcf

URDF_ROBOTS = ("anymal_c", "go1", "hyq", "solo12")


def test_the_paper_robots_geometry_is_table_1():
    desc = load_robot("paper")
    g = robot_geometry(desc)
    hips = desc.hip_positions_B
    assert g.chain is None and g.scale == 1.0 and g.min_reach == 0.12 and not g.tests_joint_ranges
    for a in (g.hips_B, g.shoulders_B, g.feet_B):
        assert np.array_equal(a, hips)
    assert (g.mass, g.leg_length, g.foot_radius) == (50.0, 0.2 + 0.22, 0.02)


def test_the_chain_model_of_the_paper_legs_is_leg_point():
    """The general leg form with the paper's numbers gives :func:`leg_point`'s foot and mass moment."""
    legs = load_robot("paper").two_link
    chain = LegChainModel.from_description(load_robot("paper"))
    rng = np.random.default_rng(0)
    q, qd = rng.uniform(-1, 1, (5, 4, 3)), rng.uniform(-2, 2, (5, 4, 3))
    moment = (legs.thigh_mass * legs.thigh_com + legs.shank_mass * legs.thigh, legs.shank_mass * legs.shank_com)
    for which, ab in (("foot", (legs.thigh, legs.shank)), ("com", moment)):
        for got, want in zip(chain.point(q, which, qd), leg_point(q, *ab, qd), strict=True):
            assert np.allclose(got, want, atol=1e-12)


@pytest.mark.parametrize("name", URDF_ROBOTS)
def test_chain_model_matches_the_description(name):
    """Foot point = the description's forward kinematics; J and (dJ/dt) qd = finite differences; IK inverts it."""
    desc = load_robot(name)
    g = robot_geometry(desc)
    rng = np.random.default_rng(1)
    q = desc.standing_joints.reshape(4, 3) + rng.uniform(-0.3, 0.3, (6, 4, 3))
    qd = rng.uniform(-2, 2, (6, 4, 3))
    p, J, jd = g.chain.point(q, "foot", qd)
    fk = np.stack([leg_fk_B(desc.legs[i], q[:, i]) for i in range(4)], axis=1) - desc.hip_positions_B
    assert np.allclose(p, fk, atol=1e-10)
    h = 1e-6
    for k in range(3):
        dq = np.zeros(3)
        dq[k] = h
        fd = (g.chain.point(q + dq, "foot")[0] - g.chain.point(q - dq, "foot")[0]) / (2 * h)
        assert np.allclose(J[..., k], fd, atol=1e-8)
    dJ = (g.chain.point(q + h * qd, "foot")[1] - g.chain.point(q - h * qd, "foot")[1]) / (2 * h)
    assert np.allclose(jd, np.einsum("...ij,...j->...i", dJ, qd), atol=1e-7)
    assert np.allclose(g.chain.point(g.ik(p), "foot")[0], p, atol=1e-9)


@pytest.mark.parametrize("name", URDF_ROBOTS)
def test_whole_body_com_matches_the_generated_model(name):
    """WholeBody's COM offset (chain model's mass moments) = MuJoCo's whole-robot COM of the description's MJCF."""
    desc = load_robot(name)
    wb = WholeBody(desc)
    m = mujoco.MjModel.from_xml_string(robot_mjcf(desc))
    d = mujoco.MjData(m)
    rng = np.random.default_rng(2)
    for _ in range(3):
        q = desc.standing_joints + rng.uniform(-0.3, 0.3, 12)
        d.qpos[:] = 0.0
        d.qpos[3] = 1.0
        d.qpos[7:] = q
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        assert wb.mass == pytest.approx(float(m.body_subtreemass[1]), rel=1e-12)
        assert np.allclose(wb.com_offset(q.reshape(4, 3)), d.subtree_com[1], atol=1e-10)


@pytest.mark.parametrize("name", URDF_ROBOTS)
def test_urdf_robot_geometry(name):
    """A foot at planar distance d from the HFE axis lies sqrt(d^2 + lat^2) from the shoulder at any HAA angle
    (exactly without an HFE offset normal to both axes; with HyQ's 8 cm: within 3 cm at HAA angles to 0.6 rad);
    the standing feet stand where the standing pose puts them."""

    from quad_uneven_env.robot.leg_chain import chain_constants

    desc = load_robot(name)
    g = robot_geometry(desc)
    assert g is robot_geometry(desc)  # built once per description
    assert g.scale == pytest.approx(desc.leg_length / 0.42)
    rng = np.random.default_rng(3)
    q = desc.standing_joints.reshape(4, 3) + rng.uniform(-0.4, 0.4, (50, 4, 3))
    feet = g.chain.point(q, "foot")[0] + g.hips_B
    for i, c in enumerate(chain_constants(desc)):
        d = np.abs(c.U1 + c.U2 * np.exp(-1j * c.sigma * q[:, i, 2]))
        want = np.hypot(d, c.lat)
        got = np.linalg.norm(feet[:, i] - g.shoulders_B[i], axis=1)
        assert np.allclose(got, want, atol=1e-9 if abs(c.alpha[2]) < 1e-9 else 0.03)
        assert g.leg_length >= np.hypot(abs(c.U1) + abs(c.U2), c.lat) - 1e-12
    legs = g.standing_legs(0.8 * g.leg_length)
    feet = g.chain.point(legs, "foot")[0] + g.hips_B
    assert np.allclose(feet[:, :2], g.feet_B[:, :2], atol=1e-9)
    assert np.allclose(feet[:, 2], g.shoulders_B[:, 2] - 0.8 * g.leg_length, atol=1e-9)
    assert 0.0 < g.min_reach < 0.5 * g.leg_length
