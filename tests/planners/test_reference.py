"""Whole-body COM placement and joint references: exact derivatives, MuJoCo agreement, IK."""

from __future__ import annotations

import copy
import dataclasses

import mujoco
import numpy as np
import pytest

import planners
from planners.reference import MAX_JOINT_SPEED
from planners.wholebody import WholeBody, leg_point
from quad_uneven_env import constants as C
from quad_uneven_env.robot import robot_mjcf
from quad_uneven_env.robot.description import load_robot
from quad_uneven_env.robot.kinematics import leg_fk_hip


@pytest.fixture(scope="module")
def ref():
    return planners.plan_gait_cycle(planners.paper_scenario()).reference()


@pytest.fixture(scope="module")
def mj(paper_robot):
    m = mujoco.MjModel.from_xml_string(robot_mjcf(paper_robot))
    return m, mujoco.MjData(m)


def test_leg_point_jacobian_and_velocity_product(rng, paper_robot):
    q = rng.uniform(-1, 1, (5, 3))
    qd = rng.normal(size=(5, 3))
    p, J, jd = leg_point(q, 0.2, 0.22, qd)
    np.testing.assert_allclose(p, leg_fk_hip(q, 0.2, 0.22), atol=1e-15)
    h = 1e-6
    fd = np.stack(
        [(leg_point(q + h * e, 0.2, 0.22)[0] - leg_point(q - h * e, 0.2, 0.22)[0]) / (2 * h) for e in np.eye(3)], -1
    )
    np.testing.assert_allclose(J, fd, atol=1e-8)
    # (dJ/dt) qd along q(t) = q + t qd.
    Jp, Jm = leg_point(q + h * qd, 0.2, 0.22)[1], leg_point(q - h * qd, 0.2, 0.22)[1]
    np.testing.assert_allclose(jd, np.einsum("tij,tj->ti", (Jp - Jm) / (2 * h), qd), atol=1e-7)


def test_reference_com_matches_mujoco_and_feet_on_sites(ref, mj):
    m, d = mj
    plan = ref.plan
    t = np.linspace(0.0, plan.duration, 23)
    p, _, _, q, _, _, _ = ref.evaluate(t)
    x, _, _ = ref.feet(t)
    trunk = m.body(C.TRUNK_BODY).id
    sites = [m.site(C.foot_site(leg)).id for leg in C.LEG_NAMES]
    for k in range(t.size):
        d.qpos[:] = 0.0
        d.qpos[:3], d.qpos[3], d.qpos[7:] = p[k], 1.0, q[k]
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        np.testing.assert_allclose(d.subtree_com[trunk], plan.cog.position(t[k : k + 1])[0], atol=1e-9)
        np.testing.assert_allclose(d.site_xpos[sites], x[k], atol=1e-9)
        lo, hi = m.jnt_range[1:, 0], m.jnt_range[1:, 1]
        assert np.all(q[k] >= lo - 1e-9) and np.all(q[k] <= hi + 1e-9), f"joint range at t={t[k]}"


def test_reference_derivatives_match_finite_differences(ref):
    # Away from the phase switches (where accelerations may jump): times inside phases.
    t = np.array([0.37, 1.41, 1.77, 2.63, 3.05, 4.52, 5.33, 5.91])
    h = 1e-5
    out, plus, minus = ref.evaluate(t, 8), ref.evaluate(t + h, 8), ref.evaluate(t - h, 8)
    for i in (0, 3):  # base position and joints
        np.testing.assert_allclose((plus[i] - minus[i]) / (2 * h), out[i + 1], atol=1e-6)
        np.testing.assert_allclose((plus[i + 1] - minus[i + 1]) / (2 * h), out[i + 2], atol=1e-4)


def test_sample_is_a_reference_sample(ref):
    s = ref.sample(1.5)
    assert isinstance(s, planners.ReferenceSample)
    assert s.stance == (True, True, True, False)
    np.testing.assert_allclose(s.quat_WB, [1, 0, 0, 0])
    assert s.qpos.shape == (19,) and s.qvel.shape == (18,) and s.qacc.shape == (18,)
    off = ref.sample(1.5013)  # off the precomputed grid: computed on the spot
    e = ref.evaluate(np.array([1.5013]), 8)
    np.testing.assert_allclose(off.q_joints, e[3][0], atol=1e-10)
    np.testing.assert_allclose(off.qdd_joints, e[5][0], atol=1e-8)


def test_compiled_grid_lookup_equals_row(ref):
    """``reference_kernels.grid_index`` against :meth:`Reference.row` where they could part: grid times,
    times within and just beyond the 1e-9 s tolerance, half-way between grid points (Python rounds half
    to even), before the start and past the end (clipped), and the grid's last point. Both name the row of
    the packed grid (views of it, made at each lookup)."""
    from planners.reference_kernels import grid_index

    g = ref.grid
    assert g.packed.shape == (len(g.t), 55) and g.masks.dtype == np.int64
    k = np.arange(len(g.t))
    times = np.concatenate([
        g.t, g.t + 5e-10, g.t - 5e-10, g.t + 2e-9, g.t - 2e-9, (k + 0.5) * g.dt, k * g.dt + 0.5 * g.dt,
        [-1.0, -1e-12, 0.0, g.t_end, g.t_end + 1e-3, g.t_end + 10.0, 0.0007, 0.001, 0.003],
    ])  # fmt: skip
    hits = 0
    for t in times.tolist():
        want = ref.row(t)
        got = grid_index(t, g.t, g.dt, g.t_end)
        if want is None:
            assert got == -1, t
            continue
        hits += 1
        assert got >= 0 and int(g.masks[got]) == want[1], t
        assert np.shares_memory(g.rows[got], g.packed[got]) and np.shares_memory(want[0], g.packed[got]), t
        np.testing.assert_array_equal(g.packed[got], want[0])
    assert 3 * len(g.t) <= hits < len(times)


def test_com_offset_matches_mujoco_random_pose(rng, paper_robot, mj):
    m, d = mj
    wb = WholeBody(paper_robot)
    q = rng.uniform(m.jnt_range[1:, 0], m.jnt_range[1:, 1])
    d.qpos[:] = 0.0
    d.qpos[:3], d.qpos[3], d.qpos[7:] = (0.1, -0.2, 0.5), 1.0, q
    mujoco.mj_kinematics(m, d)
    mujoco.mj_comPos(m, d)
    np.testing.assert_allclose(
        wb.com_offset(q.reshape(4, 3)) + np.array([0.1, -0.2, 0.5]), d.subtree_com[m.body("trunk").id], atol=1e-12
    )


def test_aim_feet_below_footholds_places_late_feet_under_the_surface():
    """The late-touchdown targets: foot sites (by the leg FK) `depth` below the foothold sites."""
    from planners import paper_scenario, plan_gait_cycle
    from planners.reference import aim_feet_below_footholds
    from quad_uneven_env.constants import LEG_NAMES
    from quad_uneven_env.robot.kinematics import leg_fk_hip

    plan = plan_gait_cycle(paper_scenario())
    ref = plan.reference()
    cfg = ref.cfg
    t = 2.05  # RH has landed (its swing is 1-2 s), RF is swinging
    sample = ref.sample(t)
    legs = np.array([True, False, True, True])
    depth = 0.015
    out = aim_feet_below_footholds(sample, plan, t, legs, depth, cfg)
    hips = cfg.hip_positions_B
    for i in np.flatnonzero(legs):
        landed = plan.swing[LEG_NAMES[i]].t_end <= t
        foothold = plan.footholds[i] if landed else plan.feet_start[i]
        q_leg = out.q_joints[3 * i : 3 * i + 3]
        site = sample.p_base_W + hips[i] + leg_fk_hip(q_leg, cfg.two_link.thigh, cfg.two_link.shank)
        np.testing.assert_allclose(site, foothold + np.array([0.0, 0.0, cfg.foot_radius - depth]), atol=1e-9)
        assert np.all(out.qd_joints[3 * i : 3 * i + 3] == 0.0)
    np.testing.assert_array_equal(out.q_joints[3:6], sample.q_joints[3:6])  # RF untouched


def test_inv3_matches_lapack_on_batches():
    from planners.wholebody import inv3

    A = np.random.default_rng(1).normal(size=(50, 4, 3, 3)) + 2.0 * np.eye(3)
    np.testing.assert_allclose(inv3(A), np.linalg.inv(A), rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(inv3(A) @ A, np.broadcast_to(np.eye(3), A.shape), atol=1e-12)


def test_compiled_base_placement_equals_numpy():
    """The reference grid's compiled kernel against the vectorised numpy place_base, on a real cycle."""
    cfg = load_robot("paper")
    plan = planners.plan_gait_cycle(planners.paper_scenario())
    ref = plan.reference(cfg)
    t = np.linspace(0.0, plan.duration, 400)
    cog = plan.cog
    c, cd, cdd = cog.position(t), cog.velocity(t), cog.acceleration(t)
    x, xd, xdd = ref.feet(t)
    wb = WholeBody(cfg)
    fast = wb.place_base_compiled(c, cd, cdd, x, xd, xdd, newton_steps=3)
    slow = wb.place_base(c, cd, cdd, x, xd, xdd, newton_steps=3)
    for a, b in zip(fast, slow, strict=True):
        np.testing.assert_allclose(a, b.reshape(a.shape), rtol=0, atol=1e-9)
    assert np.abs(fast[5]).max() > 1.0  # swing legs really accelerate: the comparison is not trivial


@pytest.mark.parametrize("raise_m", [0.0, 0.03, 0.05, 0.08])
def test_defect_names_a_leg_planned_beyond_full_stretch(raise_m):
    """The paper's cycle started ``raise_m`` higher: up to 3 cm the legs still reach (finite joint speeds under
    the nominal ~6 rad/s); from 5 cm a stance leg is held stretched, its Jacobian singular, and the reference's
    joint speeds are not defined: the defect names the leg."""
    sc = planners.paper_scenario()
    start = {"pos": (0.01, 0.0, 0.544 + raise_m), "vel": (0.0, 0.0, 0.0), "acc": (0.0, 0.0, 0.0)}
    ref = planners.plan_gait_cycle(dataclasses.replace(sc, cog_start=start)).reference()
    qd = ref.evaluate(ref._grid_t, newton_steps=3)[4]
    if raise_m <= 0.03:
        assert ref.defect() is None
        assert np.abs(qd).max() < 10.0
    else:
        defect = ref.defect()
        assert defect is not None and defect.startswith("singular leg ")
        assert defect.split()[2].rstrip(":") in C.LEG_NAMES
        assert not (np.abs(qd).max() < MAX_JOINT_SPEED)  # huge or NaN: not a motion


def test_defect_reports_a_non_finite_grid(ref):
    broken = copy.copy(ref)
    grid = [a.copy() for a in ref._grid]
    grid[0][7, 2] = np.nan
    broken._grid = tuple(grid)
    assert broken.defect() == f"non-finite base reference at t={ref._grid_t[7]:.3f} s"
    assert ref.defect() is None


def _flat_first_cycle(name: str):
    """The expert's first gait cycle of robot ``name`` on flat ground, from its standing footholds (its scaled
    settings: ``ExpertConfig.for_robot``)."""
    from agents.expert import ExpertConfig
    from planners.robot_geometry import robot_geometry
    from quad_uneven_env.robot.description import load_robot

    desc = load_robot(name)
    g, cfg = robot_geometry(desc), ExpertConfig.for_robot(desc)
    feet = np.column_stack([g.feet_B[:, :2], np.zeros(4)])
    sc = planners.Scenario(
        terrain="flat", feet_start=feet, cog_start={"pos": (0.0, 0.0, cfg.cog_height)}, durations=cfg.durations,
        epsilon=cfg.epsilon, clearance=cfg.clearance, cog_height=cfg.cog_height, stride=(cfg.stride, 0.0),
        robot=g, body_pitch=cfg.body_pitch,
    )  # fmt: skip
    return planners.plan_gait_cycle(sc).reference()


def test_joint_range_excess_finds_a_reference_beyond_its_range(ref):
    """The paper's cycle stays inside the joint ranges; a knee pushed 0.1 rad past its limit at one grid row is
    found, by joint and time."""
    excess, _, _ = ref.joint_range_excess()
    assert excess < 0.0
    broken = copy.copy(ref)
    grid = [a.copy() for a in ref._grid]
    j = C.JOINT_NAMES.index("LH_KFE")
    grid[3][40, j] = ref.geometry.joint_ranges[j, 1] + 0.1
    broken._grid = tuple(grid)
    excess, joint, t = broken.joint_range_excess()
    assert excess == pytest.approx(0.1) and joint == j and t == pytest.approx(ref._grid_t[40])


@pytest.mark.parametrize("name", ["paper", "anymal_c", "go1", "solo12"])
def test_the_first_flat_cycle_stays_inside_the_joint_ranges(name):
    assert _flat_first_cycle(name).joint_range_excess()[0] < 0.0


def test_hyq_swing_knots_are_kept_near_its_hfe_range(monkeypatch):
    """HyQ's HFE range (-1.22 rad forward for the hind legs) binds on flat ground: without the swing knots'
    joint-range test its hind swing is planned ~0.2 rad past it; with it the descent point is moved toward the
    middle of the step, and what remains (between that point and the touch-down) is less than 0.1 rad."""
    import planners.swing

    excess, joint, _ = _flat_first_cycle("hyq").joint_range_excess()
    assert 0.0 < excess < 0.1
    assert C.JOINT_NAMES[joint] in ("LH_HFE", "RH_HFE")
    monkeypatch.setattr(planners.swing, "_fit_joint_ranges", lambda *args: None)
    untested, joint, _ = _flat_first_cycle("hyq").joint_range_excess()
    assert 0.15 < untested < 0.4
    assert C.JOINT_NAMES[joint] in ("LH_HFE", "RH_HFE")
