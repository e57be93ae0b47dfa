"""A yawing body frame: the orientation profile, the turned nominal footholds, and a plan that is the unturned
plan rotated (flat ground)."""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np
import pytest

from planners import Scenario, plan_gait_cycle
from planners.footholds import choose_footholds
from planners.pitch import BodyPitch, planar_rotation, terrain_pitch, yaw_pitch_of_quaternion
from quad_uneven_env.terrain import Terrain, parse_terrain_spec

FEET_XY = np.array([[0.25, 0.185], [0.25, -0.185], [-0.25, 0.185], [-0.25, -0.185]])


def rz(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def ry(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def skew_inv(S: np.ndarray) -> np.ndarray:
    return np.array([S[2, 1], S[0, 2], S[1, 0]])


def test_yawed_orientation_is_rz_ry_with_consistent_quaternion_and_rates():
    bo = BodyPitch(0.05, 0.2, 3.1, yaw_start=0.4, yaw_end=-0.5)
    assert bo.yawed and not bo.level and BodyPitch(yaw_end=0.1).yawed and not BodyPitch(0.1, 0.2).yawed
    t = np.linspace(0.2, 2.9, 7)
    h = 1e-6
    R = np.empty(9)
    for tk in t:
        th, psi = float(bo.angle(tk)), float(bo.yaw(tk)[0])
        np.testing.assert_allclose(bo.rotation(tk), rz(psi) @ ry(th), atol=1e-15)
        mujoco.mju_quat2Mat(R, bo.quaternion(tk))
        np.testing.assert_allclose(R.reshape(3, 3), rz(psi) @ ry(th), atol=1e-15)
        assert yaw_pitch_of_quaternion(bo.quaternion(tk)) == pytest.approx((psi, th), abs=1e-12)
        # omega_W = skew^-1(dR/dt R^T), omega_B = skew^-1(R^T dR/dt), by central differences
        dR = (bo.rotation(tk + h) - bo.rotation(tk - h)) / (2 * h)
        w, a = bo.omega(np.array(tk))
        wb, ab = bo.omega_base(np.array(tk))
        np.testing.assert_allclose(w, skew_inv(dR @ bo.rotation(tk).T), atol=1e-7)
        np.testing.assert_allclose(wb, skew_inv(bo.rotation(tk).T @ dR), atol=1e-7)
        np.testing.assert_allclose(
            a, (bo.omega(np.array(tk + h))[0] - bo.omega(np.array(tk - h))[0]) / (2 * h), atol=1e-6
        )
        np.testing.assert_allclose(
            ab, (bo.omega_base(np.array(tk + h))[0] - bo.omega_base(np.array(tk - h))[0]) / (2 * h), atol=1e-6
        )
    assert bo.yaw(np.array([0.0, 3.1]))[0] == pytest.approx([0.4, -0.5])
    assert bo.yaw(np.array([0.0, 3.1]))[1] == pytest.approx([0.0, 0.0], abs=1e-15)


def test_terrain_pitch_is_taken_along_the_heading():
    feet = np.column_stack([FEET_XY, 0.3 + 0.2 * FEET_XY[:, 1]])  # rises to the left (world +y)
    assert terrain_pitch(feet) == pytest.approx(0.0, abs=1e-12)
    assert terrain_pitch(feet, yaw=0.5 * np.pi) == pytest.approx(-np.arctan(0.2))  # heading +y: uphill, nose up
    assert terrain_pitch(feet, yaw=-0.5 * np.pi) == pytest.approx(np.arctan(0.2))


def test_nominal_footholds_are_the_hips_turned_about_the_goal(paper_robot):
    """On flat ground every foothold is its nominal point: the hip (base frame) turned by the end yaw, plus the goal."""
    terrain = Terrain(parse_terrain_spec("flat")).generate(np.random.default_rng(0))
    hips = paper_robot.hip_positions_B
    goal = np.array([0.1, -0.05])
    yaw = 0.4
    out = choose_footholds(terrain, paper_robot, np.column_stack([FEET_XY, np.zeros(4)]), np.array([0.0, 0.0, 0.33]),
                           goal, 0.33, yaw_start=0.0, yaw_end=yaw)  # fmt: skip
    c, s = np.cos(yaw), np.sin(yaw)
    for i in range(4):
        a, b = hips[i, 0], hips[i, 1]
        np.testing.assert_allclose(out[i], [goal[0] + c * a - s * b, goal[1] + s * a + c * b, 0.0], atol=1e-12)
    assert planar_rotation(yaw) == pytest.approx(np.array([[c, -s], [s, c]]))


def _flat_scenario(yaw: float, turn: float, stride: tuple[float, float]) -> Scenario:
    """A cycle from the nominal stance turned by ``yaw`` about the origin, on flat ground."""
    feet = np.column_stack([np.array([[0.3, 0.2], [0.3, -0.2], [-0.3, 0.2], [-0.3, -0.2]]) @ planar_rotation(yaw).T,
                            np.zeros(4)])  # fmt: skip
    zero = (0.0, 0.0, 0.0)
    return Scenario(
        terrain="flat", feet_start=feet, cog_start={"pos": (0.0, 0.0, 0.33), "vel": zero, "acc": zero},
        durations=(0.5, 0.5, 0.5, 0.1, 0.5, 0.5, 0.5), epsilon=20.0, cog_height=0.33, stride=stride,
        yaw_start=yaw, turn=turn,
    )  # fmt: skip


@pytest.mark.parametrize("turn", [0.0, 0.3])
def test_a_turned_plan_is_the_unturned_plan_rotated(turn):
    """Flat ground is invariant under a rotation about z: starting turned by psi (stance, COG, stride and yaw all
    rotated) gives the unturned plan rotated by psi: footholds, junction COG points, COG path and base pose.

    With a turn the desired COG points at the two junctions around the four-leg support are the vertex mean of
    the degenerate overlap of two triangles (they share a diagonal), which rounding changes: the COG path is
    then compared at the cycle's ends only."""
    psi, stride = 0.9, np.array([0.1, 0.05])
    base = plan_gait_cycle(_flat_scenario(0.0, turn, tuple(stride)))
    rot = plan_gait_cycle(_flat_scenario(psi, turn, tuple(planar_rotation(psi) @ stride)))
    Rz = rz(psi)
    np.testing.assert_allclose(rot.footholds, base.footholds @ Rz.T, atol=1e-9)
    t = np.linspace(0.0, base.duration, 23) if turn == 0.0 else np.array([0.0, base.duration])
    np.testing.assert_allclose(rot.cog.position(t), base.cog.position(t) @ Rz.T, atol=1e-9)
    assert rot.pitch.yaw(t)[0] == pytest.approx(np.full(len(t), psi) if turn == 0.0 else [psi, psi + turn])
    if turn != 0.0:
        return
    assert base.pitch is None  # unturned: the identity orientation
    rb, rr = base.reference(), rot.reference()
    for tk in t[::4]:
        a, b = rb.sample(tk), rr.sample(tk)
        np.testing.assert_allclose(b.p_base_W, Rz @ a.p_base_W, atol=1e-9)
        np.testing.assert_allclose(b.q_joints, a.q_joints, atol=1e-9)
        np.testing.assert_allclose(b.omega_base_B, 0.0, atol=1e-15)


def test_no_turn_plans_as_without_yaw():
    """yaw_start = turn = 0 is the unturned path exactly: a level plan has no orientation at all (identity)."""
    sc = _flat_scenario(0.0, 0.0, (0.2, 0.0))
    plan = plan_gait_cycle(sc)
    assert plan.pitch is None
    pitched = plan_gait_cycle(dataclasses.replace(sc, body_pitch="terrain"))
    assert not pitched.pitch.yawed
    turned = plan_gait_cycle(dataclasses.replace(sc, turn=0.3))
    assert turned.pitch.yawed and turned.pitch.yaw_end == pytest.approx(0.3)
    np.testing.assert_allclose(turned.footholds[:, :2].mean(0), plan.footholds[:, :2].mean(0), atol=1e-9)


@pytest.mark.parametrize("field", ["turn", "yaw_start"])
def test_scenario_rejects_a_bad_yaw(field):
    with pytest.raises(ValueError, match=field):
        dataclasses.replace(_flat_scenario(0.0, 0.0, (0.2, 0.0)), **{field: float("nan")})
    if field == "turn":
        with pytest.raises(ValueError, match="turn"):
            _flat_scenario(0.0, 2.0, (0.2, 0.0))
