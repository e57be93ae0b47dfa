"""Terrain-following body pitch: the profile, and a pitched plan's reference (exact, MuJoCo-consistent)."""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np
import pytest

import planners
from planners.pitch import MAX_PITCH, BodyPitch, pitch_of_quaternion, planar_rotation, terrain_pitch
from planners.wholebody import WholeBody
from quad_uneven_env import constants as C
from quad_uneven_env.robot import robot_mjcf

FEET_XY = np.array([[0.25, 0.185], [0.25, -0.185], [-0.25, 0.185], [-0.25, -0.185]])


def test_terrain_pitch_is_the_slope_of_the_footholds():
    def feet(dzdx, dzdy=0.0):
        return np.column_stack([FEET_XY, 0.3 + dzdx * FEET_XY[:, 0] + dzdy * FEET_XY[:, 1]])

    assert terrain_pitch(feet(0.0, 0.1)) == pytest.approx(0.0, abs=1e-12)  # roll only: no pitch
    assert terrain_pitch(feet(-0.16 / 0.5)) == pytest.approx(np.arctan(0.32))  # down the stairs: nose down (> 0)
    assert terrain_pitch(feet(0.2)) == pytest.approx(-np.arctan(0.2))
    assert terrain_pitch(feet(-5.0)) == pytest.approx(MAX_PITCH)
    assert terrain_pitch(np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 1.0], [2.0, 0.0, 2.0]])) == 0.0  # collinear


def test_body_pitch_profile_derivatives_and_rotation():
    bp = BodyPitch(0.05, 0.3, 3.1)
    t = np.linspace(0.1, 3.0, 9)
    h = 1e-6
    np.testing.assert_allclose((bp.angle(t + h) - bp.angle(t - h)) / (2 * h), bp.rate(t), atol=1e-7)
    np.testing.assert_allclose((bp.rate(t + h) - bp.rate(t - h)) / (2 * h), bp.accel(t), atol=1e-6)
    ends = np.array([0.0, 3.1])
    np.testing.assert_allclose(bp.angle(ends), [0.05, 0.3])
    np.testing.assert_allclose(bp.rate(ends), 0.0, atol=1e-15)
    np.testing.assert_allclose(bp.accel(ends), 0.0, atol=1e-15)
    R = np.empty(9)
    for tk in t:
        q = bp.quaternion(tk)
        mujoco.mju_quat2Mat(R, q)
        np.testing.assert_allclose(R.reshape(3, 3), bp.rotation(tk), atol=1e-15)
        assert pitch_of_quaternion(q) == pytest.approx(bp.angle(tk))
    nose = bp.rotation(3.1) @ [1.0, 0.0, 0.0]
    assert nose[2] < 0.0  # positive pitch: nose down
    assert BodyPitch().level and not bp.level


def test_place_base_rotated_with_identity_is_place_base(paper_robot, rng):
    wb = WholeBody(paper_robot)
    c = np.array([0.1, 0.02, 0.35]) + 0.01 * rng.normal(size=(4, 3))
    x = np.column_stack([FEET_XY + 0.1, np.zeros(4)])[None] + 0.01 * rng.normal(size=(4, 4, 3))
    vel = [0.1 * rng.normal(size=a.shape) for a in (c, c, x, x)]
    ref = wb.place_base(c, vel[0], vel[1], x, vel[2], vel[3])
    z3 = np.zeros((4, 3))
    rot = wb.place_base_rotated(c, vel[0], vel[1], x, vel[2], vel[3], np.tile(np.eye(3), (4, 1, 1)), z3, z3)
    for a, b in zip(ref, rot, strict=True):
        np.testing.assert_allclose(a, b, atol=1e-12)


@pytest.fixture(scope="module")
def pitched_ref():
    # The paper's blocks slope the footholds; start pitched so the profile moves over the cycle.
    sc = dataclasses.replace(planners.paper_scenario(), body_pitch="terrain", pitch_start=0.1)
    plan = planners.plan_gait_cycle(sc)
    assert plan.pitch is not None and plan.pitch.start == 0.1 and abs(plan.pitch.end - 0.1) > 0.05
    return plan.reference()


@pytest.fixture(scope="module")
def turning_ref():
    """A cycle on flat ground turning by 0.5 rad from a yaw of 0.4 rad, pitched from 0.05 rad (terrain mode)."""
    feet = np.column_stack([FEET_XY @ planar_rotation(0.4).T, np.zeros(4)])
    zero = (0.0, 0.0, 0.0)
    sc = planners.Scenario(
        terrain="flat", feet_start=feet, cog_start={"pos": (0.0, 0.0, 0.33), "vel": zero, "acc": zero},
        durations=(0.5, 0.5, 0.5, 0.1, 0.5, 0.5, 0.5), epsilon=20.0, cog_height=0.33, stride=(0.05, 0.02),
        body_pitch="terrain", pitch_start=0.05, yaw_start=0.4, turn=0.5,
    )  # fmt: skip
    plan = planners.plan_gait_cycle(sc)
    assert plan.pitch.yawed and plan.pitch.start == 0.05
    return plan.reference()


@pytest.mark.parametrize("name", ["pitched_ref", "turning_ref"])
def test_reference_com_feet_and_orientation_match_mujoco(name, request, paper_robot):
    """Every sample's whole-body COM is the planned COG and its feet are the planned foot sites (MuJoCo's
    kinematics of the sampled pose); its orientation and base-frame rates are the plan's profile."""
    ref = request.getfixturevalue(name)
    m = mujoco.MjModel.from_xml_string(robot_mjcf(paper_robot))
    d = mujoco.MjData(m)
    plan = ref.plan
    t = np.linspace(0.0, plan.duration, 17)
    x, _, _ = ref.feet(t)
    trunk = m.body(C.TRUNK_BODY).id
    sites = [m.site(C.foot_site(leg)).id for leg in C.LEG_NAMES]
    for k, tk in enumerate(t):
        s = ref.sample(tk)
        d.qpos[:] = s.qpos
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        np.testing.assert_allclose(d.subtree_com[trunk], plan.cog.position(t[k : k + 1])[0], atol=1e-9)
        np.testing.assert_allclose(d.site_xpos[sites], x[k], atol=1e-9)
        np.testing.assert_allclose(d.xmat[trunk].reshape(3, 3), plan.pitch.rotation(tk), atol=1e-12)
        w, a = plan.pitch.omega_base(np.array(tk))
        np.testing.assert_allclose(s.omega_base_B, w, atol=1e-12)
        np.testing.assert_allclose(s.domega_base_B, a, atol=1e-12)
        if name == "pitched_ref":
            assert pitch_of_quaternion(s.quat_WB) == pytest.approx(plan.pitch.angle(tk))


@pytest.mark.parametrize("name", ["pitched_ref", "turning_ref"])
def test_reference_derivatives_match_finite_differences(name, request):
    ref = request.getfixturevalue(name)
    t = np.array([0.37, 1.41, 1.77, 2.63, 3.05, 4.52, 5.33, 5.91]) * ref.plan.duration / 6.1
    h = 1e-5
    out, plus, minus = ref.evaluate(t, 8), ref.evaluate(t + h, 8), ref.evaluate(t - h, 8)
    for i in (0, 3):  # base position and joints
        np.testing.assert_allclose((plus[i] - minus[i]) / (2 * h), out[i + 1], atol=1e-6)
        np.testing.assert_allclose((plus[i + 1] - minus[i + 1]) / (2 * h), out[i + 2], atol=1e-4)
    if name == "turning_ref":
        return
    pitch = ref.plan.pitch
    for tk in t:
        s = ref.sample(tk)
        np.testing.assert_allclose(s.omega_base_B, [0.0, pitch.rate(tk), 0.0], atol=1e-15)
        np.testing.assert_allclose(s.domega_base_B, [0.0, pitch.accel(tk), 0.0], atol=1e-15)


def test_scenario_rejects_unknown_pitch_mode():
    with pytest.raises(ValueError, match="body_pitch"):
        dataclasses.replace(planners.paper_scenario(), body_pitch="roll")
    with pytest.raises(ValueError, match="pitch_start"):
        dataclasses.replace(planners.paper_scenario(), pitch_start=float("nan"))
