"""The controller's one-call compiled path (agents.control.controller_kernels) against its general path."""

from __future__ import annotations

import itertools

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import quad_uneven_env  # noqa: F401  (registers QuadUneven-v0)
from agents.control import controller_kernels as FK
from agents.control import inverse_dynamics as ID
from agents.control.controller import STANCE_MODES, ComputedTorqueController
from agents.control.controller_kernels import select_stance_mask
from agents.control.fast_path import PackedReference
from agents.control.inverse_dynamics import WorkspaceResult
from agents.expert import ExpertConfig, attach_expert
from planners.types import PACKED_FIELDS


def test_stance_mask_selection_matches_select_stance():
    ctrl = ComputedTorqueController(reference=lambda t: None)
    for mode, planned, measured in itertools.product(STANCE_MODES, range(16), range(16)):
        ctrl.stance_mode = mode
        bits = lambda m: tuple(bool(m >> i & 1) for i in range(4))  # noqa: E731
        want = ctrl.select_stance(bits(planned), np.array(bits(measured)))
        assert bits(select_stance_mask(planned, measured, STANCE_MODES.index(mode))) == want, (mode, planned, measured)


def _expert_states(terrain, config: ExpertConfig, steps: int, every: int):
    """The expert walking ``steps`` env steps from seed 0 on ``terrain``, or until the episode ends (the "pinv"
    expert falls on rough ground); at every ``every``-th step (the first included) ``(policy, model, data)``
    with the derived quantities the hook sees after ``mj_step1``."""
    env = gym.make("QuadUneven-v0", terrain=terrain)
    policy = attach_expert(env, config)
    u = env.unwrapped
    obs, _ = env.reset(seed=0)
    for step in range(steps):
        obs, _, terminated, truncated, _ = env.step(policy.predict(obs)[0])
        if terminated or truncated:  # a fallen robot's replan is no state to compare controllers on
            return
        if step % every == 0:
            mujoco.mj_forward(u.model, u.data)
            yield policy, u.model, u.data


STAIRS = {"kind": "stairs", "riser": 0.08, "direction": "down"}


@pytest.mark.parametrize(
    "distribution, terrain, atol", [("pinv", "rough", 1e-12), ("qp", "rough", 1e-9), ("qp", STAIRS, 1e-9)]
)
def test_fast_path_gives_the_general_paths_torques(distribution, terrain, atol, monkeypatch):
    """The one-call path against the readable one, and for "qp" against the readable one with DAQP too
    (the compiled QP inside the kernel against the reference solver)."""
    daqp_solves = []
    solve = ID._StanceQP.solve
    monkeypatch.setattr(ID._StanceQP, "solve", lambda self: daqp_solves.append(1) or solve(self))
    compared = 0
    for policy, m, d in _expert_states(terrain, ExpertConfig(distribution=distribution), steps=300, every=5):
        ctrl = policy.controller
        t = float(d.time) - ctrl.t0
        if policy._reference_row(t) is None:
            continue
        tau_fast = ctrl(m, d)
        assert isinstance(ctrl._last_reference, PackedReference), "the fast path was not taken"
        fast, ref_fast = ctrl.last, ctrl.last_reference
        row_fn, ctrl.reference_row = ctrl.reference_row, None
        try:
            tau_general = ctrl(m, d)
            general, ref_general = ctrl.last, ctrl.last_reference
            ctrl.id.qp_solver = "daqp"
            tau_daqp = ctrl(m, d)
            with_daqp = ctrl.last
        finally:
            ctrl.reference_row, ctrl.id.qp_solver = row_fn, "compiled"
        np.testing.assert_allclose(tau_fast, tau_general, rtol=0, atol=atol)
        np.testing.assert_allclose(fast.contact_forces, general.contact_forces, rtol=0, atol=1e3 * atol)
        np.testing.assert_allclose(tau_fast, tau_daqp, rtol=0, atol=1e-7)
        np.testing.assert_allclose(fast.contact_forces, with_daqp.contact_forces, rtol=0, atol=1e-5)
        for other in (general, with_daqp):
            assert (fast.stance, fast.distribution, fast.relaxed) == (other.stance, other.distribution, other.relaxed)
        for name, _ in PACKED_FIELDS:
            np.testing.assert_array_equal(getattr(ref_fast, name), getattr(ref_general, name), err_msg=name)
        assert ref_fast.stance == ref_general.stance
        compared += 1
    assert compared >= 10
    assert distribution == "pinv" or len(daqp_solves) >= 3, "no compared step needed the QP"


def test_lazy_last_result_refuses_overwritten_buffers():
    env = gym.make("QuadUneven-v0", terrain="flat")
    policy = attach_expert(env, ExpertConfig(distribution="pinv"))
    ctrl, u = policy.controller, env.unwrapped
    obs, _ = env.reset(seed=0)
    m, d = u.model, u.data
    for _ in range(50):  # until a step takes the fast path (not at a late touch-down)
        obs, *_ = env.step(policy.predict(obs)[0])
        mujoco.mj_forward(m, d)
        ctrl(m, d)
        if isinstance(ctrl._last, WorkspaceResult):
            break
    assert isinstance(ctrl._last, WorkspaceResult), "the fast path did not leave a lazy result"
    stance = (True, True, True, True)
    ctrl.id.solve(d.qpos, d.qvel, np.zeros(6), stance)  # reuses the work buffers
    with pytest.raises(RuntimeError, match="reused"):
        _ = ctrl.last
    ctrl(m, d)
    tau = ctrl.last.tau  # read right after the call: fine
    assert tau.shape == (12,) and np.isfinite(tau).all()


def test_a_failing_compiled_step_takes_the_readable_path(monkeypatch):
    """The kernel refusing its inputs (numba dispatch) gives the readable path's torques, and is not retried."""
    env = gym.make("QuadUneven-v0", terrain="rough")
    policy = attach_expert(env, ExpertConfig())
    ctrl, u = policy.controller, env.unwrapped
    obs, _ = env.reset(seed=0)
    for _ in range(20):
        obs, *_ = env.step(policy.predict(obs)[0])
    m, d = u.model, u.data
    mujoco.mj_forward(m, d)
    calls = []

    def refuse(*args):
        calls.append(1)
        raise TypeError("No matching definition for argument type(s)")

    monkeypatch.setattr(FK, "packed_control_step", refuse)
    tau = ctrl(m, d)
    assert not isinstance(ctrl._last_reference, PackedReference), "the fast path was taken"
    row_fn, ctrl.reference_row = ctrl.reference_row, None
    try:
        np.testing.assert_array_equal(tau, ctrl(m, d))
    finally:
        ctrl.reference_row = row_fn
    ctrl(m, d)
    assert len(calls) == 1
    ctrl._fast.forget_arguments()  # e.g. after set_friction: tried again
    ctrl(m, d)
    assert len(calls) == 2


@pytest.mark.parametrize(
    "distribution, terrain, share",
    [("qp", "rough", True), ("qp", STAIRS, False), ("pinv", "flat", True)],
)
def test_the_grid_step_walks_exactly_as_the_controller_call_it_replaces(distribution, terrain, share, monkeypatch):
    """The expert's hook with ``step_on_grid`` (row lookup, touch-down check and step in one compiled call)
    against the same hook with it refused (``controller(...)`` every step): the same trajectory bit for bit,
    in the simulator's data and in the nominal model's copy (measured contacts handed in), with both branches
    taken: the grid step, and the general path at late touch-downs (a planned foot not touching), plan ends
    and QPs."""
    runs = []
    for grid_step in (True, False):
        env = gym.make("QuadUneven-v0", terrain=terrain)
        policy = attach_expert(env, ExpertConfig(distribution=distribution, share_nominal_world=share))
        ctrl = policy.controller
        taken = []
        real = type(ctrl).step_on_grid

        def counted(self, *args, _real=real, _taken=taken, _on=grid_step):
            tau = _real(self, *args) if _on else None
            _taken.append(tau is not None)
            return tau

        monkeypatch.setattr(type(ctrl), "step_on_grid", counted)
        monkeypatch.setattr(type(policy), "torques_into", None)  # the hook's fast lane: tested below
        obs, _ = env.reset(seed=0)
        assert policy.shares_simulator_data is share
        qpos, torques = [], []
        for _ in range(250):
            obs, _, fell, *_ = env.step(policy.predict(obs)[0])
            qpos.append(env.unwrapped.data.qpos.copy())
            torques.append(policy.last_torques.copy())
            if fell:  # the "pinv" expert tips over after ~2.2 s, on either path
                break
        runs.append((np.array(qpos), np.array(torques), taken, list(policy.failure_log)))
        monkeypatch.undo()
    (q_grid, tau_grid, taken, log_grid), (q_call, tau_call, _, log_call) = runs
    np.testing.assert_array_equal(tau_grid, tau_call)
    np.testing.assert_array_equal(q_grid, q_call)
    assert log_grid == log_call
    assert 0.8 * len(taken) < sum(taken) < len(taken), "both branches must be taken"


@pytest.mark.parametrize("terrain, share", [("rough", True), (STAIRS, True), ("rough", False)])
def test_the_hooks_fast_lane_walks_exactly_as_the_call_it_replaces(terrain, share, monkeypatch):
    """The env with the expert's fast lane (``ExpertPolicy.torques_into``: one compiled call per physics step,
    the disturbance check inside it) against the same env with the lane removed (the hook's full call every
    step): the same torques, trajectory, log and recoveries, bit for bit (the lane calling its kernel's compiled
    entry point from its second step on, :mod:`quad_uneven_env.compiled_call`). The base is knocked off its plan
    (0.3 m/s sideways) so that a check inside the lane finds it off and the full call replans. With
    ``share=False`` both copy the measured state into the nominal model's own data and hand in the contacts."""
    runs = []
    for lane in (True, False):
        env = gym.make("QuadUneven-v0", terrain=terrain)
        policy = attach_expert(env, ExpertConfig(share_nominal_world=share))
        answers = []
        real = type(policy).torques_into

        def counted(self, *args, _real=real, _answers=answers, _on=lane):
            done = _real(self, *args) if _on else False
            _answers.append(done)
            return done

        monkeypatch.setattr(type(policy), "torques_into", counted)
        obs, _ = env.reset(seed=0)
        d = env.unwrapped.data
        qpos, ctrl = [], []
        for step in range(260):
            if step == 150:
                d.qvel[1] += 0.3
            obs, _, fell, *_ = env.step(policy.predict(obs)[0])
            qpos.append(d.qpos.copy())
            ctrl.append(d.ctrl.copy())
            assert not fell
        if lane:  # the lane's later calls went to the kernel's compiled entry point, past numba's dispatcher
            assert policy.controller._lane_call is not None
        runs.append((np.array(qpos), np.array(ctrl), answers, list(policy.failure_log), policy.recoveries))
        monkeypatch.undo()
    (q_lane, u_lane, answers, log_lane, rec_lane), (q_call, u_call, _, log_call, rec_call) = runs
    np.testing.assert_array_equal(u_lane, u_call)
    np.testing.assert_array_equal(q_lane, q_call)
    assert log_lane == log_call and rec_lane == rec_call >= 1
    assert 0.8 * len(answers) < sum(answers) < len(answers), "the lane and the full call must both run"


def test_the_lane_declines_off_the_plan_and_leaves_the_controllers_diagnostics():
    """``grid_step_into`` writes what ``step_on_grid`` returns (clipped to the limit it is given) and leaves
    the same ``last``/``last_reference``; with the off-plan check it returns ``OFF_PLAN`` and writes nothing
    when the base is farther than the tolerance from the row, as ``ExpertPolicy._check_disturbance`` decides."""
    compared = off = 0
    for policy, m, d in _expert_states("rough", ExpertConfig(), steps=200, every=5):
        ctrl = policy.controller
        grid_args = (policy._grid, policy._t_start, policy._t_end, d.sensordata, policy._foot_sensor_adr)
        limit = np.full(12, 20.0)
        tau_ok, out = np.zeros(12), np.full(12, np.nan)
        done = ctrl.grid_step_into(m, d, *grid_args, tau_ok, limit, out)
        if not done:
            assert np.isnan(out).all()
            continue
        last, ref = ctrl.last, ctrl.last_reference
        tau = ctrl.step_on_grid(m, d, *grid_args, np.zeros(12))
        np.testing.assert_array_equal(out, np.clip(tau, -limit, limit))
        np.testing.assert_array_equal(tau_ok, tau)
        np.testing.assert_array_equal(last.tau, ctrl.last.tau)
        np.testing.assert_array_equal(last.contact_forces, ctrl.last.contact_forces)
        assert ref.t == ctrl.last_reference.t and ref.stance == ctrl.last_reference.stance
        np.testing.assert_array_equal(ref.q_joints, ctrl.last_reference.q_joints)
        compared += 1
        row = policy._row_of(float(d.time) - ctrl.t0 - policy._t_start)[0]
        dp2 = (d.qpos[0] - row[0]) ** 2 + (d.qpos[1] - row[1]) ** 2
        for tol2, expected in ((dp2 * 1.01, 1), (dp2 * 0.99, FK.OFF_PLAN)):
            out[:] = np.nan
            got = ctrl.grid_step_into(m, d, *grid_args, np.zeros(12), limit, out, (tol2, 1e6))
            assert got == expected
            assert np.isnan(out).all() == (expected == FK.OFF_PLAN)
            off += expected == FK.OFF_PLAN
    assert compared >= 20 and off == compared


def test_the_grid_step_leaves_the_controllers_diagnostics():
    """After ``step_on_grid`` the controller's ``last`` and ``last_reference`` are those of the call it replaces."""
    compared = 0
    for policy, m, d in _expert_states("rough", ExpertConfig(), steps=200, every=5):
        ctrl = policy.controller
        tau_ok = np.zeros(12)
        args = (policy._grid, policy._t_start, policy._t_end, d.sensordata, policy._foot_sensor_adr, tau_ok)
        tau = ctrl.step_on_grid(m, d, *args)
        if tau is None:
            assert not tau_ok.any()
            continue
        np.testing.assert_array_equal(tau, tau_ok)
        last, ref = ctrl.last, ctrl.last_reference
        np.testing.assert_array_equal(tau, ctrl(m, d))
        assert isinstance(ctrl._last_reference, PackedReference)
        np.testing.assert_array_equal(last.tau, ctrl.last.tau)
        np.testing.assert_array_equal(last.contact_forces, ctrl.last.contact_forces)
        assert (last.stance, last.distribution, last.relaxed) == (
            ctrl.last.stance,
            ctrl.last.distribution,
            ctrl.last.relaxed,
        )
        assert ref.t == ctrl.last_reference.t and ref.stance == ctrl.last_reference.stance
        for name, _ in PACKED_FIELDS:
            np.testing.assert_array_equal(getattr(ref, name), getattr(ctrl.last_reference, name), err_msg=name)
        compared += 1
    assert compared >= 20


def test_the_contact_pairs_have_one_numba_type_whatever_the_contact_count():
    """``contact_pairs`` hands the compiled kernels one array type with no contact and with several, where
    MuJoCo's own view changes layout (so each kernel would compile again at the first airborne step); the
    pairs are MuJoCo's."""
    import numba

    from agents.control.fast_path import contact_pairs

    env = gym.make("QuadUneven-v0", terrain="rough")
    env.reset(seed=0)
    u = env.unwrapped
    standing = u.data
    airborne = mujoco.MjData(u.model)
    airborne.qpos[:] = standing.qpos
    airborne.qpos[2] += 1.0
    mujoco.mj_forward(u.model, standing)
    mujoco.mj_forward(u.model, airborne)
    assert standing.ncon >= 2 and airborne.ncon == 0
    assert numba.typeof(standing.contact.geom) != numba.typeof(airborne.contact.geom)  # what it guards against
    assert numba.typeof(contact_pairs(standing)) == numba.typeof(contact_pairs(airborne))
    np.testing.assert_array_equal(contact_pairs(standing), standing.contact.geom)
    assert contact_pairs(airborne).shape == (0, 2)
