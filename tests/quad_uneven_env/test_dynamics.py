"""Dynamics backends against MuJoCo's own M and qfrc_bias; foot Jacobians and their derivatives."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from quad_uneven_env import constants as C
from quad_uneven_env.robot.dynamics import BACKENDS, make_dynamics
from quad_uneven_env.robot.model import robot_mjcf

N_STATES = 1000
TOL = 1e-8


@pytest.fixture(scope="module")
def mj_model(paper_robot) -> mujoco.MjModel:
    """The robot alone (no terrain, so no contact): MuJoCo's M and qfrc_bias are the reference."""
    return mujoco.MjModel.from_xml_string(robot_mjcf(paper_robot))


@pytest.fixture(scope="module")
def backends(mj_model) -> dict:
    return {b: make_dynamics(b, mj_model) for b in BACKENDS}


def random_states(model: mujoco.MjModel, rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    """n random states: any base pose and orientation, joints in range, |v| <= 2 m/s, |w|, |qd| <= 5 rad/s."""
    qpos = np.zeros((n, C.NQ))
    qpos[:, :3] = rng.uniform(-2.0, 2.0, (n, 3))
    quat = rng.normal(size=(n, 4))
    qpos[:, 3:7] = quat / np.linalg.norm(quat, axis=1, keepdims=True)
    lo, hi = model.jnt_range[1:, 0], model.jnt_range[1:, 1]
    qpos[:, 7:] = rng.uniform(lo, hi, (n, C.N_JOINTS))
    qvel = np.concatenate([rng.uniform(-2.0, 2.0, (n, 3)), rng.uniform(-5.0, 5.0, (n, 15))], axis=1)
    return qpos, qvel


def mujoco_reference(model, qpos, qvel):
    """MuJoCo's M, qfrc_bias, gravity (bias at zero velocity) and foot-site Jacobians."""
    d = mujoco.MjData(model)
    n = len(qpos)
    M = np.empty((n, C.NV, C.NV))
    h = np.empty((n, C.NV))
    G = np.empty((n, C.NV))
    J = np.empty((n, C.N_LEGS, 3, C.NV))
    for k in range(n):
        d.qpos[:], d.qvel[:] = qpos[k], qvel[k]
        mujoco.mj_forward(model, d)
        mujoco.mj_fullM(model, d, M[k])
        h[k] = d.qfrc_bias
        for i, s in enumerate(C.FOOT_SITES):
            mujoco.mj_jacSite(model, d, J[k, i], None, model.site(s).id)
        d.qvel[:] = 0.0
        mujoco.mj_forward(model, d)
        G[k] = d.qfrc_bias
    return M, h, G, J


@pytest.fixture(scope="module")
def states_and_reference(mj_model):
    rng = np.random.default_rng(2024)
    qpos, qvel = random_states(mj_model, rng, N_STATES)
    return qpos, qvel, mujoco_reference(mj_model, qpos, qvel)


@pytest.mark.parametrize("backend", BACKENDS)
def test_backends_match_mujoco_on_random_states(backend, backends, states_and_reference):
    qpos, qvel, (M_ref, h_ref, G_ref, J_ref) = states_and_reference
    dyn = backends[backend]
    if backend == "explicit":
        t = dyn.terms(qpos, qvel)  # batched
        M, h, G, J = t.M, t.h, t.G, t.J_feet
    else:
        ts = [dyn.terms(qpos[k], qvel[k]) for k in range(N_STATES)]
        M, h, G, J = (np.array([getattr(t, f) for t in ts]) for f in ("M", "h", "G", "J_feet"))
    assert np.abs(M - M_ref).max() < TOL
    assert np.abs(h - h_ref).max() < TOL
    assert np.abs(G - G_ref).max() < TOL
    assert np.abs(J - J_ref).max() < TOL
    # the comparison is not vacuous: the velocity-dependent part is large
    assert np.abs(h_ref - G_ref).max() > 10.0


def test_explicit_batch_equals_single(backends, states_and_reference):
    qpos, qvel, _ = states_and_reference
    dyn = backends["explicit"]
    batch = dyn.terms(qpos[:5], qvel[:5])
    for k in range(5):
        single = dyn.terms(qpos[k], qvel[k])
        assert single.M.shape == (C.NV, C.NV)
        np.testing.assert_allclose(single.M, batch.M[k], atol=1e-12)
        np.testing.assert_allclose(single.h, batch.h[k], atol=1e-12)
        np.testing.assert_allclose(single.Jdot_qdot_feet, batch.Jdot_qdot_feet[k], atol=1e-12)


@pytest.mark.parametrize("backend", BACKENDS)
def test_jdot_qdot_is_the_feet_classical_acceleration(backend, backends, mj_model):
    """d/dt (J(q(t)) qvel) at constant qvel (qacc = 0), central differences along mj_integratePos."""
    rng = np.random.default_rng(7)
    qpos, qvel = random_states(mj_model, rng, 20)
    dyn = backends[backend]
    dt = 1e-6
    worst = 0.0
    for k in range(20):
        plus, minus = qpos[k].copy(), qpos[k].copy()
        mujoco.mj_integratePos(mj_model, plus, qvel[k], dt)
        mujoco.mj_integratePos(mj_model, minus, qvel[k], -dt)
        vp = dyn.terms(plus, qvel[k]).J_feet @ qvel[k]
        vm = dyn.terms(minus, qvel[k]).J_feet @ qvel[k]
        fd = (vp - vm) / (2 * dt)
        worst = max(worst, np.abs(fd - dyn.terms(qpos[k], qvel[k]).Jdot_qdot_feet).max())
        assert np.abs(fd).max() > 1.0  # accelerations of several m/s^2 at these speeds
    assert worst < 1e-5


def test_jdot_qdot_matches_foot_position_second_difference(backends, mj_model):
    """Foot positions along a constant-qvel path: p(t+dt) - 2 p(t) + p(t-dt) = Jdot_qdot dt^2."""
    rng = np.random.default_rng(8)
    qpos, qvel = random_states(mj_model, rng, 5)
    d = mujoco.MjData(mj_model)
    sites = [mj_model.site(s).id for s in C.FOOT_SITES]
    dt = 1e-4

    def feet(qp):
        d.qpos[:] = qp
        mujoco.mj_kinematics(mj_model, d)
        return d.site_xpos[sites].copy()

    for k in range(5):
        plus, minus = qpos[k].copy(), qpos[k].copy()
        mujoco.mj_integratePos(mj_model, plus, qvel[k], dt)
        mujoco.mj_integratePos(mj_model, minus, qvel[k], -dt)
        acc = (feet(plus) - 2 * feet(qpos[k]) + feet(minus)) / dt**2
        for dyn in backends.values():
            np.testing.assert_allclose(
                dyn.terms(qpos[k], qvel[k]).Jdot_qdot_feet, acc, atol=1e-4 * max(1, np.abs(acc).max())
            )


def test_mujoco_fast_path_reuses_step1(backends, mj_model):
    """terms_from_data after mj_step1 equals terms() at the same state."""
    d = mujoco.MjData(mj_model)
    rng = np.random.default_rng(3)
    qpos, qvel = random_states(mj_model, rng, 1)
    d.qpos[:], d.qvel[:] = qpos[0], qvel[0]
    mujoco.mj_step1(mj_model, d)
    dyn = backends["mujoco"]
    fast, slow = dyn.terms_from_data(d), dyn.terms(qpos[0], qvel[0])
    for f in ("M", "h", "G", "J_feet", "Jdot_qdot_feet"):
        np.testing.assert_allclose(getattr(fast, f), getattr(slow, f), atol=1e-12)


def test_unknown_backend_and_wrong_model_are_refused(mj_model):
    with pytest.raises(ValueError, match="backend must be one of"):
        make_dynamics("symbolic", mj_model)
    other = mujoco.MjModel.from_xml_string(robot_mjcf())
    other.jnt_axis[other.joint("LF_HAA").id] = [0.0, 0.0, 1.0]
    with pytest.raises(ValueError, match="LF_HAA"):
        make_dynamics("explicit", other)


def test_mujoco_kernel_equals_mujoco_functions(backends, mj_model):
    """The compiled terms_from_data against mj_fullM, mj_jacSite, mj_jacDot and mj_jacSubtreeCom themselves."""
    rng = np.random.default_rng(11)
    qpos, qvel = random_states(mj_model, rng, 200)
    d = mujoco.MjData(mj_model)
    dyn = backends["mujoco"]
    for k in range(200):
        d.qpos[:], d.qvel[:] = qpos[k], qvel[k]
        mujoco.mj_step1(mj_model, d)
        fast, ref = dyn.terms_from_data(d), dyn.terms_from_data_mjcalls(d)
        np.testing.assert_array_equal(fast.M, ref.M)
        np.testing.assert_array_equal(fast.h, ref.h)
        np.testing.assert_allclose(fast.J_feet, ref.J_feet, rtol=0, atol=1e-14)
        np.testing.assert_allclose(fast.Jdot_qdot_feet, ref.Jdot_qdot_feet, rtol=0, atol=1e-12)
        np.testing.assert_allclose(fast.G, ref.G, rtol=0, atol=1e-11)
        assert np.abs(ref.Jdot_qdot_feet).max() > 1.0  # not a trivial comparison


def test_explicit_kernel_equals_numpy_formulas(backends, states_and_reference):
    qpos, qvel, _ = states_and_reference
    dyn = backends["explicit"]
    fast, ref = dyn.terms(qpos[:200], qvel[:200]), dyn.terms_numpy(qpos[:200], qvel[:200])
    for f in ("M", "h", "G", "J_feet", "Jdot_qdot_feet"):
        np.testing.assert_allclose(getattr(fast, f), getattr(ref, f), rtol=0, atol=1e-10)


def test_mujoco_kernel_refuses_other_structures(paper_robot):
    other = mujoco.MjModel.from_xml_string(robot_mjcf(paper_robot))
    other.jnt_type[other.joint("RH_KFE").id] = mujoco.mjtJoint.mjJNT_SLIDE
    with pytest.raises(ValueError, match="RH_KFE"):
        make_dynamics("mujoco", other)
