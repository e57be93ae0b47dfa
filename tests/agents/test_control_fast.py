"""The controller's compiled step (``grid_step_into`` -> ``controller_kernels.grid_control_step``) against its
readable reference (``ComputedTorqueController.__call__``)."""

from __future__ import annotations

import itertools

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import quad_uneven_env  # noqa: F401  (registers QuadUneven-v0)
from agents.control import controller_kernels
from agents.control import inverse_dynamics as ID
from agents.control.controller import STANCE_MODES, ComputedTorqueController, contact_pairs
from agents.control.controller_kernels import select_stance_mask
from agents.expert import ExpertConfig, attach_expert
from agents.expert.hook import PhysicsHook
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
    expert falls on rough ground); at every ``every``-th step (the first included) within the current plan (not a
    hold) ``(policy, model, data)`` with the derived quantities the hook sees after ``mj_step1``."""
    env = gym.make("QuadUneven-v0", terrain=terrain)
    policy = attach_expert(env, config)
    u = env.unwrapped
    obs, _ = env.reset(seed=0)
    for step in range(steps):
        obs, _, terminated, truncated, _ = env.step(policy.predict(obs)[0])
        if terminated or truncated:  # a fallen robot's replan is no state to compare controllers on
            return
        on_plan = policy.planner.grid is not None and u.data.time - policy.controller.t0 < policy.planner.t_end
        if step % every == 0 and on_plan:
            mujoco.mj_forward(u.model, u.data)
            yield policy, u.model, u.data


def _grid_step(policy, m, d, tau_ok, out, limit=None):
    """The compiled step on the expert's current plan (whether it took the step)."""
    p, ctrl = policy.planner, policy.controller
    limit = ctrl.torque_limit if limit is None else limit
    args = (p.grid, p.t_start, p.t_end, d.sensordata, p.foot_sensor_adr, tau_ok, limit, out)
    return ctrl.grid_step_into(m, d, *args)


STAIRS = {"kind": "stairs", "riser": 0.08, "direction": "down"}


@pytest.mark.parametrize("distribution, terrain", [("pinv", "rough"), ("qp", "rough"), ("qp", STAIRS)])
def test_the_compiled_step_gives_the_readable_calls_torques_and_diagnostics(distribution, terrain, monkeypatch):
    """Where the compiled step takes a step, its torques (clipped to the limit it is given), contact forces and
    reference are the readable call's, bit for bit, and for "qp" within the solvers' tolerance of the readable
    call with DAQP (the compiled QP inside the kernel against the reference solver)."""
    daqp_solves = []
    solve = ID._StanceQP.solve
    monkeypatch.setattr(ID._StanceQP, "solve", lambda self: daqp_solves.append(1) or solve(self))
    compared = declined = 0
    for policy, m, d in _expert_states(terrain, ExpertConfig(distribution=distribution), steps=300, every=5):
        ctrl = policy.controller
        tau_ok, out, limit = np.zeros(12), np.full(12, np.nan), np.full(12, 20.0)
        if not _grid_step(policy, m, d, tau_ok, out, limit):
            assert np.isnan(out).all() and not tau_ok.any()
            declined += 1
            continue
        compiled, ref_compiled = ctrl.last, ctrl.last_reference
        tau_readable = ctrl(m, d)
        readable, ref_readable = ctrl.last, ctrl.last_reference
        ctrl.id.qp_solver = "daqp"
        try:
            tau_daqp = ctrl(m, d)
            with_daqp = ctrl.last
        finally:
            ctrl.id.qp_solver = "compiled"
        np.testing.assert_array_equal(tau_ok, tau_readable)
        np.testing.assert_array_equal(out, np.clip(tau_readable, -limit, limit))
        np.testing.assert_array_equal(compiled.tau, readable.tau)
        np.testing.assert_array_equal(compiled.contact_forces, readable.contact_forces)
        np.testing.assert_allclose(tau_ok, tau_daqp, rtol=0, atol=1e-7)
        np.testing.assert_allclose(compiled.contact_forces, with_daqp.contact_forces, rtol=0, atol=1e-5)
        for other in (readable, with_daqp):
            assert (compiled.stance, compiled.distribution, compiled.relaxed) == (
                other.stance,
                other.distribution,
                other.relaxed,
            )
        for name, _ in PACKED_FIELDS:
            np.testing.assert_array_equal(getattr(ref_compiled, name), getattr(ref_readable, name), err_msg=name)
        assert ref_compiled.stance == ref_readable.stance
        compared += 1
    assert compared >= 10
    assert distribution == "pinv" or len(daqp_solves) >= 3, "no compared step needed the QP"


def test_the_grid_codes_fields_read_back_as_written():
    """:func:`decode_grid_code` reads back every field of a code laid out as ``grid_control_step`` writes it
    (``control_step``'s code, then the planned stance and the grid row), over the fields' whole ranges: no two
    fields overlap."""
    ck = controller_kernels
    rng = np.random.default_rng(0)
    for stance, status, planned in itertools.product(range(16), range(8), range(16)):
        n_beta, row, relaxed = int(rng.integers(6, 19)), int(rng.integers(0, 1 << 20)), bool(rng.integers(2))
        code = stance | status << ck.STATUS_SHIFT | n_beta << ck.N_BETA_SHIFT | ck.INSIDE_CONES
        code |= (ck.QP_DONE | ck.QP_RELAXED) if relaxed else 0
        code |= planned << ck.GRID_PLANNED_SHIFT | row << ck.GRID_ROW_SHIFT
        assert ck.decode_grid_code(code) == (stance, status, relaxed, planned, row)


def test_lazy_last_result_refuses_overwritten_buffers():
    env = gym.make("QuadUneven-v0", terrain="flat")
    policy = attach_expert(env, ExpertConfig(distribution="pinv"))
    ctrl, u = policy.controller, env.unwrapped
    obs, _ = env.reset(seed=0)
    m, d = u.model, u.data
    done = 0
    for _ in range(50):  # until the compiled step takes a step (not at a late touch-down)
        obs, *_ = env.step(policy.predict(obs)[0])
        mujoco.mj_forward(m, d)
        done = _grid_step(policy, m, d, np.zeros(12), np.zeros(12))
        if done:
            break
    assert done, "the compiled step took no step"
    stance = (True, True, True, True)
    ctrl.id.solve(d.qpos, d.qvel, np.zeros(6), stance)  # reuses the work buffers
    with pytest.raises(RuntimeError, match="reused"):
        _ = ctrl.last
    ctrl(m, d)
    tau = ctrl.last.tau  # read right after the call: fine
    assert tau.shape == (12,) and np.isfinite(tau).all()


def test_a_failing_compiled_step_declines_and_is_not_retried(monkeypatch):
    """The kernel refusing its inputs (numba dispatch) declines (the readable call then runs), and is not tried
    again until its arguments are rebuilt (here by ``set_friction``)."""
    env = gym.make("QuadUneven-v0", terrain="rough")
    policy = attach_expert(env, ExpertConfig())
    ctrl, u = policy.controller, env.unwrapped
    obs, _ = env.reset(seed=0)
    for _ in range(20):
        obs, *_ = env.step(policy.predict(obs)[0])
    m, d = u.model, u.data
    mujoco.mj_forward(m, d)
    assert _grid_step(policy, m, d, np.zeros(12), np.zeros(12))
    calls = []

    def refuse(*args):
        calls.append(1)
        raise TypeError("No matching definition for argument type(s)")

    monkeypatch.setattr(controller_kernels, "grid_control_step", refuse)
    ctrl._grid_calls.clear()  # the cached entry point would bypass the dispatcher patched above
    tau_ok = np.zeros(12)
    assert not _grid_step(policy, m, d, tau_ok, np.zeros(12)) and not tau_ok.any()
    assert not _grid_step(policy, m, d, tau_ok, np.zeros(12))
    assert len(calls) == 1
    ctrl.set_friction(ctrl.mu)  # rebuilds the arguments: tried again
    assert not _grid_step(policy, m, d, tau_ok, np.zeros(12))
    assert len(calls) == 2
    np.testing.assert_array_equal(policy(m, d, None), ctrl(m, d))  # the hook's readable call


@pytest.mark.parametrize(
    "distribution, terrain, share, push",
    [
        ("qp", "rough", True, True),
        ("qp", STAIRS, False, False),
        ("qp", "rough", False, True),
        ("pinv", "flat", True, False),
    ],
)
def test_the_expert_walks_exactly_as_with_the_readable_step(distribution, terrain, share, push, monkeypatch):
    """The expert with its compiled step (``grid_step_into``, tried once per physics step, the readable call in its
    place where it declines) against the same expert with the readable controller call at every physics step
    (``hook.compiled = False``): the same torques, trajectory, log and recoveries, bit for bit, in the simulator's
    data and in the nominal model's copy (measured contacts handed in). The env's fast lane
    (``PhysicsHook.torques_into``) answers every physics step; each step is one compiled step or one readable call;
    both kinds are taken (late touch-downs, plan ends, QPs left to DAQP); with ``push`` the base is knocked off its
    plan (0.3 m/s sideways) so that the disturbance check replans."""
    runs = []
    for compiled in (True, False):
        env = gym.make("QuadUneven-v0", terrain=terrain)
        policy = attach_expert(env, ExpertConfig(distribution=distribution, share_nominal_world=share))
        policy.hook.compiled = compiled
        answers, tries, readable = [], [], []
        lane, step, call = (
            PhysicsHook.torques_into,
            ComputedTorqueController.grid_step_into,
            ComputedTorqueController.__call__,
        )

        def counted_lane(self, *args, _lane=lane, _answers=answers):
            _answers.append(_lane(self, *args))
            return _answers[-1]

        def counted_step(self, *args, _step=step, _tries=tries):
            _tries.append(_step(self, *args))
            return _tries[-1]

        def counted_call(self, *args, _call=call, _readable=readable):
            _readable.append(1)
            return _call(self, *args)

        monkeypatch.setattr(PhysicsHook, "torques_into", counted_lane)
        monkeypatch.setattr(ComputedTorqueController, "grid_step_into", counted_step)
        monkeypatch.setattr(ComputedTorqueController, "__call__", counted_call)
        obs, _ = env.reset(seed=0)
        assert policy.shares_simulator_data is share
        d = env.unwrapped.data
        qpos, torques = [], []
        for i in range(260):
            if push and i == 150:
                d.qvel[1] += 0.3
            obs, _, fell, *_ = env.step(policy.predict(obs)[0])
            qpos.append(d.qpos.copy())
            torques.append(d.ctrl.copy())
            if fell:  # the "pinv" expert tips over after ~2.2 s, either way
                break
        if compiled:  # the later steps went to the kernel's compiled entry point, past numba's dispatcher
            assert policy.controller._grid_calls
        runs.append(
            (np.array(qpos), np.array(torques), answers, tries, readable, list(policy.failure_log), policy.recoveries)
        )
        monkeypatch.undo()
    (q_fast, u_fast, answers, tries, readable, log_fast, rec_fast), reference = runs
    q_ref, u_ref, answers_ref, tries_ref, readable_ref, log_ref, rec_ref = reference
    np.testing.assert_array_equal(u_fast, u_ref)
    np.testing.assert_array_equal(q_fast, q_ref)
    assert log_fast == log_ref and rec_fast == rec_ref
    assert rec_fast >= 1 or not push
    n = len(answers)
    assert all(answers) and all(answers_ref) and len(answers_ref) == n == len(q_fast) * env.unwrapped.frame_skip
    taken = sum(tries)
    assert len(tries) <= n and taken + len(readable) == n, "one compiled step or one readable call per physics step"
    assert 0.5 * n < taken < n
    if distribution == "qp":  # (the "pinv" walk ends before its first plan's end)
        assert len(tries) > taken, "the readable call must also run where the compiled step declined"
    assert len(readable_ref) == n and not tries_ref


@pytest.mark.parametrize("share", [True, False])
def test_the_lane_and_the_call_are_one_path(share, monkeypatch):
    """The expert through the env's fast lane (``torques_into``) and with the lane removed (the env's call at every
    physics step): the same motor commands, trajectory, log and recoveries bit for bit, pushed off its plan, in the
    simulator's data and in the nominal model's copy; both count one step per physics step."""
    runs = []
    for lane in (True, False):
        env = gym.make("QuadUneven-v0", terrain="rough")
        policy = attach_expert(env, ExpertConfig(share_nominal_world=share))
        if not lane:
            monkeypatch.setattr(policy, "torques_into", lambda *args: False, raising=False)
        obs, _ = env.reset(seed=4)
        d = env.unwrapped.data
        trace = []
        for i in range(200):
            if i == 120:
                d.qvel[1] += 0.3
            obs, _, fell, *_ = env.step(policy.predict(obs)[0])
            trace.append((d.qpos.copy(), d.ctrl.copy()))
            assert not fell
        assert policy._steps == 200 * env.unwrapped.frame_skip
        runs.append((trace, list(policy.failure_log), policy.recoveries))
        monkeypatch.undo()
    (with_lane, log_lane, rec_lane), (without, log_call, rec_call) = runs
    for (q1, u1), (q2, u2) in zip(with_lane, without, strict=True):
        np.testing.assert_array_equal(u1, u2)
        np.testing.assert_array_equal(q1, q2)
    assert log_lane == log_call and rec_lane == rec_call >= 1


def test_the_contact_pairs_have_one_numba_type_whatever_the_contact_count():
    """``contact_pairs`` hands the compiled kernels one array type with no contact and with several, where
    MuJoCo's own view changes layout (so each kernel would compile again at the first airborne step); the
    pairs are MuJoCo's."""
    import numba

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
