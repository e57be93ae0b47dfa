"""Constraint elimination, inverse dynamics (checked with MuJoCo) and the computed-torque controller."""

from __future__ import annotations

import dataclasses
import itertools

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import quad_uneven_env  # noqa: F401  (registers QuadUneven-v0)
from agents.control.controller import (
    ComputedTorqueController,
    Gains,
    InverseDynamics,
    eliminate_constraints,
    foot_lookup,
    friction_pyramid,
    measured_foot_contacts,
    verify_inverse_dynamics,
)
from agents.control.references import BaseWaveReference, track_in_env
from planners.types import ReferenceSample
from quad_uneven_env import constants as C
from quad_uneven_env.robot.dynamics import BACKENDS, make_dynamics
from quad_uneven_env.robot.model import robot_mjcf

ALL_STANCES = list(itertools.product((True, False), repeat=4))


@pytest.fixture(scope="module")
def mj_model(paper_robot) -> mujoco.MjModel:
    return mujoco.MjModel.from_xml_string(robot_mjcf(paper_robot))


@pytest.fixture(scope="module")
def dyn(mj_model):
    return make_dynamics("mujoco", mj_model)


def perturbed_stand(cfg, rng, tilt=0.1):
    """Standing pose with random joint offsets, a tilted base and random velocities."""
    qpos = cfg.home_qpos()
    qpos[7:] += rng.normal(0.0, 0.1, C.N_JOINTS)
    axis = rng.normal(size=3)
    quat = np.empty(4)
    mujoco.mju_axisAngle2Quat(quat, axis / np.linalg.norm(axis), tilt)
    qpos[3:7] = quat
    qvel = rng.normal(0.0, 0.5, C.NV)
    return qpos, qvel


# ----------------------------------------------------------------------------- elimination
def test_elimination_constraint_and_spd(paper_robot, dyn, rng):
    for _ in range(5):
        qpos, qvel = perturbed_stand(paper_robot, rng)
        terms = dyn.terms(qpos, qvel)
        for stance in ALL_STANCES:
            proj = eliminate_constraints(terms, stance)
            p = sum(stance)
            assert proj.S.shape == (C.NV, C.NV - 3 * p)
            legs = [i for i in range(4) if stance[i]]
            if legs:
                J_st = terms.J_feet[legs].reshape(-1, C.NV)
                assert np.abs(J_st @ proj.S).max() < 1e-10  # eq. 14
            np.testing.assert_array_equal(proj.S_ua, np.eye(6, C.NV - 3 * p))
            assert proj.S_a.shape == (C.N_JOINTS, C.NV - 3 * p)
            np.testing.assert_allclose(proj.M_beta, proj.M_beta.T, atol=1e-12)
            assert np.linalg.eigvalsh(proj.M_beta).min() > 1e-6


def test_elimination_without_stance_is_the_full_dynamics(paper_robot, dyn, rng):
    qpos, qvel = perturbed_stand(paper_robot, rng)
    terms = dyn.terms(qpos, qvel)
    proj = eliminate_constraints(terms, (False,) * 4)
    np.testing.assert_array_equal(proj.S, np.eye(C.NV))
    np.testing.assert_array_equal(proj.Sdot_betadot, np.zeros(C.NV))
    np.testing.assert_allclose(proj.M_beta, terms.M, atol=1e-12)
    np.testing.assert_allclose(proj.V_beta + proj.G_beta, terms.h, atol=1e-12)


def test_sdot_betadot_keeps_stance_feet_still(paper_robot, dyn, rng):
    """With qvel = S beta_dot, d/dt (J S beta_dot) = 0 along the motion: J (S bdd + Sdot bd) + Jdot qdot = 0."""
    qpos, qvel = perturbed_stand(paper_robot, rng)
    stance = (True, False, True, True)
    proj0 = eliminate_constraints(dyn.terms(qpos, qvel), stance)
    qvel_c = proj0.S @ qvel[proj0.beta_index]  # a velocity satisfying the constraint
    terms = dyn.terms(qpos, qvel_c)
    proj = eliminate_constraints(terms, stance)
    qacc = proj.S @ rng.normal(size=proj.layout.n_beta) + proj.Sdot_betadot
    for i in (0, 2, 3):
        assert np.abs(terms.J_feet[i] @ qacc + terms.Jdot_qdot_feet[i]).max() < 1e-10


def test_bad_stance_is_refused(dyn, paper_robot):
    ID = InverseDynamics(dyn)
    with pytest.raises(ValueError, match="stance must be 4 booleans"):
        ID.solve(paper_robot.home_qpos(), np.zeros(C.NV), np.zeros(6), (True, True, True))
    with pytest.raises(ValueError, match="beta_ddot must have shape"):
        ID.solve(paper_robot.home_qpos(), np.zeros(C.NV), np.zeros(5), (True,) * 4)
    with pytest.raises(ValueError, match="distribution must be one of"):
        InverseDynamics(dyn, "lp")


# ----------------------------------------------------------------------------- inverse dynamics
@pytest.mark.parametrize("backend", BACKENDS)
def test_pinv_is_the_papers_formula_and_satisfies_mujoco(backend, mj_model, paper_robot, rng):
    ID = InverseDynamics(make_dynamics(backend, mj_model), "pinv")
    for _ in range(3):
        qpos, qvel = perturbed_stand(paper_robot, rng)
        for stance in ALL_STANCES:
            nb = C.NV - 3 * sum(stance)
            bdd = rng.normal(0.0, 2.0, nb)
            res = ID.solve(qpos, qvel, bdd, stance)
            proj = eliminate_constraints(ID.dynamics.terms(qpos, qvel), stance)
            tau_paper = np.linalg.pinv(proj.S_a.T) @ (proj.M_beta @ bdd + proj.V_beta + proj.G_beta)
            np.testing.assert_allclose(res.tau, tau_paper, atol=1e-8)
            assert np.all(res.contact_forces[~np.array(stance)] == 0.0)
            check = verify_inverse_dynamics(mj_model, qpos, qvel, bdd, res)
            assert check.stance_foot_acc < 1e-8 and check.base_acc < 1e-8
            if sum(stance) >= 3:  # exactly solvable: the full 18-row system holds
                assert res.exact
                assert check.ok(1e-8), check
            elif not res.exact:
                assert check.eom > 1e-6  # least squares: reported as inexact, and it is


def _cone_feasible(dyn, qpos, qvel, res, stance, mu, fmin) -> bool:
    """An LP (scipy): is there F with J_b^T F = (M qacc + h)[:6], F_i in the pyramid, F_i,z >= fmin?"""
    from scipy.optimize import linprog

    t = dyn.terms(qpos, qvel)
    r = t.M @ res.qacc + t.h
    legs = np.flatnonzero(stance)
    A_eq = np.hstack([t.J_feet[leg][:, :6].T for leg in legs])
    cone = friction_pyramid(np.array([0.0, 0.0, 1.0]), mu)[:4]
    rows = []
    for k in range(len(legs)):
        block = np.zeros((5, 3 * len(legs)))
        block[:4, 3 * k : 3 * k + 3] = -cone
        block[4, 3 * k + 2] = -1.0
        rows.append(block)
    b_ub = np.tile(np.r_[np.zeros(4), -fmin], len(legs))
    lp = linprog(np.zeros(3 * len(legs)), A_ub=np.vstack(rows), b_ub=b_ub, A_eq=A_eq, b_eq=r[:6], bounds=(None, None))
    return lp.status == 0


@pytest.mark.parametrize("backend", BACKENDS)
def test_qp_keeps_forces_in_cone_and_satisfies_mujoco(backend, mj_model, paper_robot, rng):
    ID = InverseDynamics(make_dynamics(backend, mj_model), "qp", min_normal_force=10.0)
    pinv = InverseDynamics(ID.dynamics, "pinv")
    n_pinv_outside = 0
    for _ in range(4):
        qpos, qvel = perturbed_stand(paper_robot, rng, tilt=0.05)
        qvel *= 0.2
        for stance in [s for s in ALL_STANCES if sum(s) >= 3]:
            bdd = np.zeros(C.NV - 3 * sum(stance))
            bdd[:6] = rng.normal(0.0, 0.5, 6)
            res = ID.solve(qpos, qvel, bdd, stance)
            ref = pinv.solve(qpos, qvel, bdd, stance)
            if res.qp_fallback:
                continue
            assert res.distribution == "qp"
            if res.relaxed:
                # Only when no force distribution exists: checked independently with an LP.
                assert not _cone_feasible(ID.dynamics, qpos, qvel, res, stance, ID.mu, 10.0)
                pyramid = friction_pyramid(np.array([0.0, 0.0, 1.0]), ID.mu)[:4]
                for i in np.flatnonzero(stance):
                    assert np.all(pyramid @ res.contact_forces[i] >= -1e-6)
                continue
            assert verify_inverse_dynamics(mj_model, qpos, qvel, bdd, res).ok(1e-8)
            for i in np.flatnonzero(stance):
                cone = friction_pyramid(np.array([0.0, 0.0, 1.0]), ID.mu)
                assert np.all(cone[:4] @ res.contact_forces[i] >= -1e-6)
                assert res.contact_forces[i, 2] >= 10.0 - 1e-6
                n_pinv_outside += bool(np.any(cone[:4] @ ref.contact_forces[i] < 0) or ref.contact_forces[i, 2] < 10)
            # among all solutions, the QP's torques are never smaller than the minimum-norm ones
            assert np.linalg.norm(res.tau) >= np.linalg.norm(ref.tau) - 1e-9
    assert n_pinv_outside > 0  # the cases include some where the paper's pinv leaves the cone


def test_qp_infeasible_relaxes_to_physical_forces(dyn, paper_robot):
    """Commanding the base down faster than free fall needs pulling feet: the "qp" keeps the forces in
    the cones (the base wrench closest to the command), where "pinv" would pull on the ground."""
    qpos = paper_robot.home_qpos()
    bdd = np.zeros(6)
    bdd[2] = -20.0  # faster than free fall: needs pulling feet
    res = InverseDynamics(dyn, "qp").solve(qpos, np.zeros(C.NV), bdd, (True,) * 4)
    ref = InverseDynamics(dyn, "pinv").solve(qpos, np.zeros(C.NV), bdd, (True,) * 4)
    assert np.all(ref.contact_forces[:, 2] < 0)  # the paper's choice pulls
    assert res.relaxed and not res.qp_fallback and res.distribution == "qp"
    cone = friction_pyramid(np.array([0.0, 0.0, 1.0]), dyn.model.geom_friction[0, 0] if hasattr(dyn, "model") else 1.0)
    for i in range(4):
        assert np.all(cone @ res.contact_forces[i] >= -1e-6)
    # The closest physical wrench to "fall faster than g" is no contact force at all.
    np.testing.assert_allclose(res.contact_forces, 0.0, atol=1e-3)
    # Stance torques are consistent with those forces through the leg rows.
    t = dyn.terms(qpos, np.zeros(C.NV))
    r = t.M @ res.qacc + t.h
    for leg in range(4):
        c = slice(6 + 3 * leg, 9 + 3 * leg)
        np.testing.assert_allclose(
            res.tau[3 * leg : 3 * leg + 3], r[c] - t.J_feet[leg][:, c].T @ res.contact_forces[leg], atol=1e-8
        )


def test_stretched_knee_gives_finite_damped_torques(dyn, paper_robot):
    qpos = paper_robot.home_qpos()
    qpos[7 + 2] = 0.0  # LF knee stretched: its 3x3 leg Jacobian is singular
    qpos[7 + 1] = 0.0
    for dist in ("pinv", "qp"):
        res = InverseDynamics(dyn, dist).solve(qpos, np.zeros(C.NV), np.zeros(6), (True,) * 4)
        assert res.damped
        assert np.all(np.isfinite(res.tau)) and np.all(np.isfinite(res.contact_forces))


# ----------------------------------------------------------------------------- controller units
def test_gains_and_stance_selection():
    with pytest.raises(ValueError, match=r"Gains.kp_pos"):
        Gains(kp_pos=-1.0)
    ctrl = ComputedTorqueController(lambda t: None)
    planned = (True, True, True, False)
    assert ctrl.select_stance(planned, np.array([True, True, True, True])) == (True, True, True, False)
    # a planned foot not yet touching with 4 planned: 3 remain -> trusted
    assert ctrl.select_stance((True,) * 4, np.array([True, False, True, True])) == (True, False, True, True)
    # only 2 of 3 planned feet touch: fall back to the plan
    assert ctrl.select_stance(planned, np.array([True, False, True, False])) == planned
    with pytest.raises(ValueError, match="stance_mode"):
        ComputedTorqueController(lambda t: None, stance_mode="guess")


def test_orientation_error_is_on_so3(paper_robot):
    """A 170 deg yaw reference: the command turns the short way, with the rotation-vector magnitude."""
    ctrl = ComputedTorqueController(lambda t: None, gains=Gains(kd_rot=0.0, kp_rot=1.0))
    qpos = paper_robot.home_qpos()
    quat = np.empty(4)
    mujoco.mju_axisAngle2Quat(quat, np.array([0.0, 0.0, 1.0]), np.deg2rad(-170.0))
    ref = ReferenceSample(0.0, qpos[:3], quat, *(np.zeros(3),) * 4, qpos[7:], np.zeros(12), np.zeros(12), (True,) * 4)
    cmd = ctrl.beta_ddot_command(qpos, np.zeros(C.NV), ref, (True,) * 4)
    np.testing.assert_allclose(cmd[3:6], [0.0, 0.0, np.deg2rad(-170.0)], atol=1e-12)


# ----------------------------------------------------------------------------- acceptance in the env
def test_base_wave_reference_derivatives_are_consistent(paper_robot):
    feet = np.array([[0.25, 0.185, 0.0], [0.25, -0.185, 0.0], [-0.25, 0.185, 0.0], [-0.25, -0.185, 0.0]])
    ref = BaseWaveReference(np.array([0.0, 0.0, 0.36]), feet, paper_robot)
    t, h = 0.7, 1e-5
    a, b, c = ref(t - h), ref(t), ref(t + h)
    omega_fd = np.empty(3)
    mujoco.mju_subQuat(omega_fd, c.quat_WB, a.quat_WB)
    np.testing.assert_allclose(omega_fd / (2 * h), b.omega_base_B, atol=1e-8)
    np.testing.assert_allclose((c.omega_base_B - a.omega_base_B) / (2 * h), b.domega_base_B, atol=1e-6)
    np.testing.assert_allclose((c.p_base_W - a.p_base_W) / (2 * h), b.v_base_W, atol=1e-8)
    np.testing.assert_allclose((c.v_base_W - a.v_base_W) / (2 * h), b.a_base_W, atol=1e-6)
    assert np.abs(b.omega_base_B).max() > 0.02  # not a trivial (static) case


def run_in_env(seconds: float, distribution: str, wave: float, seed: int = 3, backend: str = "mujoco") -> dict:
    out = track_in_env(seconds, distribution, wave, seed, backend)
    assert out["termination_reason"] is None, out["termination_reason"]
    assert out["steps_without_all_contacts"] == 0
    return out


@pytest.mark.parametrize("distribution", ["pinv", pytest.param("qp", marks=pytest.mark.slow)])
def test_stands_10s_on_rough_terrain(distribution):
    """Four feet at different heights (rough, 4 cm): 10 s standing, no foot site drifts 1 cm, F_n > 0."""
    out = run_in_env(10.0, distribution, wave=0.0)
    assert out["ground_ptp"] > 0.005  # the feet really stand at different heights
    assert out["slip"].max() < 0.01
    assert out["min_fn"] > 0.0
    assert out["rms_pos"] < 0.005 and out["rms_rot"] < 0.01
    if distribution == "qp":
        assert out["fallbacks"] == 0 and out["cone_violation"] <= 1e-6


@pytest.mark.parametrize("distribution", ["pinv", "qp"])
def test_tracks_base_wave_on_rough_terrain(distribution):
    """z +/- 3 cm at 0.5 Hz with roll and pitch +/- 5 deg at 0.3 Hz for one 0.3 Hz period."""
    out = run_in_env(10.0 / 3.0, distribution, wave=1.0)
    assert out["rms_pos"] <= 0.005
    assert out["rms_rot"] <= 0.01
    assert out["min_fn"] > 0.0
    if distribution == "qp":
        assert out["fallbacks"] == 0 and out["cone_violation"] <= 1e-6


@pytest.mark.slow
def test_tracks_base_wave_10s():
    out = run_in_env(10.0, "pinv", wave=1.0, seed=11)
    assert out["rms_pos"] <= 0.005 and out["rms_rot"] <= 0.01 and out["min_fn"] > 0.0


@pytest.mark.parametrize("backend", ["explicit", "pinocchio"])
def test_controller_runs_on_every_backend(backend):
    """The same control law with the numpy and Pinocchio dynamics inside the env (1 s of the base wave)."""
    out = run_in_env(1.0, "pinv", wave=1.0, backend=backend)
    assert out["rms_pos"] <= 0.005 and out["rms_rot"] <= 0.01 and out["min_fn"] > 0.0


# ----------------------------------------------------------------------------- compiled hot path vs numpy
def test_compiled_pinv_equals_numpy_path(mj_model, dyn, paper_robot, rng):
    """The kernel (3 or 4 stance feet, or none) gives the numpy elimination's result; 1-2 feet use numpy."""
    ID = InverseDynamics(dyn, "pinv")
    for tilt in (0.1, 0.3):
        qpos, qvel = perturbed_stand(paper_robot, rng, tilt)
        terms = dyn.terms(qpos, qvel)
        for stance in ALL_STANCES:
            bdd = rng.normal(0.0, 2.0, C.NV - 3 * sum(stance))
            fast = ID.solve_terms(terms, bdd, stance)
            ref = ID._solve(eliminate_constraints(terms, stance), bdd, None)
            for f in ("tau", "contact_forces", "qacc"):
                np.testing.assert_allclose(getattr(fast, f), getattr(ref, f), rtol=0, atol=1e-9)
            assert (fast.exact, fast.damped, fast.stance) == (ref.exact, ref.damped, ref.stance)
            lay = eliminate_constraints(terms, stance).layout
            compiled = ID.solve_compiled(terms.M, terms.h, terms.J_feet, terms.Jdot_qdot_feet, lay, bdd)
            assert (compiled is not None) == (sum(stance) in (0, 3, 4))
    qpos = paper_robot.home_qpos()
    qpos[7 + 1] = qpos[7 + 2] = 0.0  # stretched LF knee: damped inverse in both paths
    terms = dyn.terms(qpos, np.zeros(C.NV))
    fast = ID.solve_terms(terms, np.ones(6), (True,) * 4)
    ref = ID._solve(eliminate_constraints(terms, (True,) * 4), np.ones(6), None)
    assert fast.damped and ref.damped
    np.testing.assert_allclose(fast.tau, ref.tau, rtol=1e-9, atol=1e-9)


def _beta_ddot_reference(gains, qpos, qvel, ref, stance):
    """The PD command with MuJoCo's quaternion functions (the numpy implementation it replaced)."""
    e_rot, q_inv, q_rel, R_rel = np.empty(3), np.empty(4), np.empty(4), np.empty(9)
    mujoco.mju_subQuat(e_rot, ref.quat_WB, qpos[3:7])
    mujoco.mju_negQuat(q_inv, qpos[3:7])
    mujoco.mju_mulQuat(q_rel, q_inv, ref.quat_WB)
    mujoco.mju_quat2Mat(R_rel, q_rel)
    g = gains
    out = [ref.a_base_W + g.kd_pos * (ref.v_base_W - qvel[0:3]) + g.kp_pos * (ref.p_base_W - qpos[0:3])]
    out.append(
        R_rel.reshape(3, 3) @ (ref.domega_base_B + g.kd_rot * ref.omega_base_B)
        - g.kd_rot * qvel[3:6]
        + g.kp_rot * e_rot
    )
    j = np.array([3 * i + k for i in range(4) if not stance[i] for k in range(3)], dtype=int)
    out.append(
        ref.qdd_joints[j] + g.kd_joint * (ref.qd_joints[j] - qvel[6 + j]) + g.kp_joint * (ref.q_joints[j] - qpos[7 + j])
    )
    return np.concatenate(out)


def test_compiled_pd_command_equals_mujoco_quaternions(paper_robot, rng):
    gains = Gains(kp_pos=300.0, kd_pos=30.0, kp_rot=200.0, kd_rot=20.0, kp_joint=800.0, kd_joint=50.0)
    ctrl = ComputedTorqueController(lambda t: None, gains=gains)
    for k in range(50):
        qpos, qvel = perturbed_stand(paper_robot, rng, tilt=0.5)
        quat = rng.normal(size=4)
        ref = ReferenceSample(
            0.0, *(rng.normal(size=3),), quat / np.linalg.norm(quat), *(rng.normal(size=(4, 3))),
            *(rng.normal(size=(3, 12))), ALL_STANCES[k % 16],
        )  # fmt: skip
        stance = ALL_STANCES[(3 * k) % 16]
        got = ctrl.beta_ddot_command(qpos, qvel, ref, stance)
        np.testing.assert_allclose(got, _beta_ddot_reference(gains, qpos, qvel, ref, stance), rtol=0, atol=1e-10)
    bad = dataclasses.replace(ref, q_joints=np.zeros(11))
    with pytest.raises(ValueError, match="q_joints must have 12"):
        ctrl.beta_ddot_command(qpos, qvel, bad, stance)
    listed = dataclasses.replace(ref, p_base_W=list(ref.p_base_W))  # non-array fields are converted
    np.testing.assert_allclose(ctrl.beta_ddot_command(qpos, qvel, listed, stance), got, atol=0)


def test_controller_call_equals_public_api_composition():
    """One env step: the fused hook = select_stance + beta_ddot_command + terms_from_data + solve_terms + clip."""
    env = gym.make("QuadUneven-v0", terrain={"kind": "rough", "amplitude": 0.04, "spawn_radius": 0.0})
    env.reset(seed=5)
    u = env.unwrapped
    m, d = u.model, u.data
    for _ in range(50):
        mujoco.mj_step(m, d)
    mujoco.mj_step1(m, d)
    feet = d.site_xpos[[m.site(s).id for s in C.FOOT_SITES]].copy()
    ref = BaseWaveReference(d.qpos[:3] + np.array([0.0, 0.0, 0.01]), feet, u.robot)
    for dist in ("pinv", "qp"):
        for planned in ((True,) * 4, (True, False, True, True), (True, False, False, True)):
            sample = dataclasses.replace(ref(0.3), stance=planned)
            ctrl = ComputedTorqueController(lambda t, s=sample: s, distribution=dist)
            ctrl.reset(m, d, u.terrain)
            tau = ctrl(m, d)
            stance = ctrl.select_stance(planned, measured_foot_contacts(d, foot_lookup(m), m.geom(C.TERRAIN_GEOM).id))
            bdd = ctrl.beta_ddot_command(d.qpos, d.qvel, sample, stance)
            p_feet = d.site_xpos[[m.site(s).id for s in C.FOOT_SITES]]
            normals = u.terrain.heightfield.normal(p_feet[:, 0], p_feet[:, 1]) if dist == "qp" else None
            ref_res = InverseDynamics(ctrl.dynamics, dist).solve_terms(
                ctrl.dynamics.terms_from_data(d), bdd, stance, normals
            )
            assert ctrl.last.stance == stance and ctrl.last.distribution == ref_res.distribution
            np.testing.assert_allclose(ctrl.last.tau, ref_res.tau, rtol=0, atol=1e-6 if dist == "qp" else 1e-12)
            np.testing.assert_allclose(tau, np.clip(ref_res.tau, -ctrl.torque_limit, ctrl.torque_limit), atol=1e-6)
    env.close()


def test_warm_started_qp_equals_one_off_solve(dyn, paper_robot, rng):
    """A sequence of different problems through the warm-started QP gives the cold one-off solutions."""
    warm = InverseDynamics(dyn, "qp", min_normal_force=10.0)
    for _ in range(12):
        qpos, qvel = perturbed_stand(paper_robot, rng, tilt=0.05)
        stance = ALL_STANCES[rng.integers(0, 5)]  # 3 or 4 stance feet
        bdd = np.zeros(C.NV - 3 * sum(stance))
        bdd[:6] = rng.normal(0.0, 0.5, 6)
        got = warm.solve(qpos, 0.2 * qvel, bdd, stance)
        cold = InverseDynamics(dyn, "qp", min_normal_force=10.0).solve(qpos, 0.2 * qvel, bdd, stance)
        assert got.qp_fallback == cold.qp_fallback and got.distribution == cold.distribution
        assert got.relaxed == cold.relaxed
        np.testing.assert_allclose(got.contact_forces, cold.contact_forces, rtol=0, atol=1e-5)
        np.testing.assert_allclose(got.tau, cold.tau, rtol=0, atol=1e-5)


def test_friction_pyramid_matches_numpy_construction(rng):
    normals = rng.normal(size=(60, 3))
    normals[:20, 0] *= 30.0  # normals near x: the other helper axis
    n = normals / np.linalg.norm(normals, axis=-1, keepdims=True)
    helper = np.where((np.abs(n[:, 0]) < 0.9)[:, None], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    t1 = np.cross(n, helper)
    t1 /= np.linalg.norm(t1, axis=-1, keepdims=True)
    t2 = np.cross(n, t1)
    mn = (0.7 / np.sqrt(2.0)) * n
    ref = np.stack([mn - t1, mn + t1, mn - t2, mn + t2, n], axis=-2)
    np.testing.assert_allclose(friction_pyramid(normals, 0.7), ref, rtol=0, atol=1e-14)
    np.testing.assert_allclose(friction_pyramid(normals[3], 0.7), ref[3], rtol=0, atol=1e-14)
