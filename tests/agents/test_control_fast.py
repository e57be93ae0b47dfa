"""The controller's compiled step (``grid_step_into`` -> ``controller_kernels.grid_control_step``) against its
readable reference (``ComputedTorqueController.__call__``)."""

from __future__ import annotations

import itertools

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import quad_uneven_env  # noqa: F401  (registers QuadUneven-v0)
from agents.control import controller_kernels as FK
from agents.control import inverse_dynamics as ID
from agents.control.controller import STANCE_MODES, ComputedTorqueController, contact_pairs
from agents.control.controller_kernels import select_stance_mask
from agents.expert import ExpertConfig, attach_expert
from agents.expert.hook import PhysicsHook
from agents.expert.recovery import NO_OFF_PLAN_CHECK
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


def _grid_step(policy, m, d, tau_ok, out, limit=None, off_plan=NO_OFF_PLAN_CHECK):
    """The compiled step on the expert's current plan (its result code)."""
    p, ctrl = policy.planner, policy.controller
    limit = ctrl.torque_limit if limit is None else limit
    args = (p.grid, p.t_start, p.t_end, d.sensordata, p.foot_sensor_adr, tau_ok, limit, out, off_plan)
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
        if _grid_step(policy, m, d, tau_ok, out, limit) != 1:
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


def test_the_compiled_steps_off_plan_check():
    """With the off-plan tolerances the compiled step returns ``OFF_PLAN`` and writes nothing when the base is
    farther than the tolerance from the grid row (as ``DisturbanceRecovery.check`` decides), else it steps."""
    compared = off = 0
    for policy, m, d in _expert_states("rough", ExpertConfig(), steps=200, every=5):
        p = policy.planner
        packed = p.row_of(float(d.time) - policy.controller.t0 - p.t_start)
        if packed is None:
            continue
        row = packed[0]
        dp2 = (d.qpos[0] - row[0]) ** 2 + (d.qpos[1] - row[1]) ** 2
        out = np.full(12, np.nan)
        if _grid_step(policy, m, d, np.zeros(12), out) != 1:
            continue
        for tol2, expected in ((dp2 * 1.01, 1), (dp2 * 0.99, FK.OFF_PLAN)):
            out[:] = np.nan
            assert _grid_step(policy, m, d, np.zeros(12), out, off_plan=(tol2, 1e6)) == expected
            assert np.isnan(out).all() == (expected == FK.OFF_PLAN)
            off += expected == FK.OFF_PLAN
        compared += 1
    assert compared >= 20 and off == compared


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
        if done == 1:
            break
    assert done == 1, "the compiled step took no step"
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
    assert _grid_step(policy, m, d, np.zeros(12), np.zeros(12)) == 1
    calls = []

    def refuse(*args):
        calls.append(1)
        raise TypeError("No matching definition for argument type(s)")

    monkeypatch.setattr(FK, "grid_control_step", refuse)
    ctrl._grid_calls.clear()  # the cached entry point would bypass the dispatcher patched above
    tau_ok = np.zeros(12)
    assert _grid_step(policy, m, d, tau_ok, np.zeros(12)) == 0 and not tau_ok.any()
    assert _grid_step(policy, m, d, tau_ok, np.zeros(12)) == 0
    assert len(calls) == 1
    ctrl.set_friction(ctrl.mu)  # rebuilds the arguments: tried again
    assert _grid_step(policy, m, d, tau_ok, np.zeros(12)) == 0
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
    """The expert with its compiled step (the env's fast lane, ``PhysicsHook.torques_into``, and the compiled step in
    its full call, the disturbance check compiled in) against the same expert with the readable controller call
    at every physics step (``hook.compiled = False``): the same torques, trajectory, log and recoveries, bit for
    bit, in the simulator's data and in the nominal model's copy (measured contacts handed in). Both branches
    are taken: the lane and the full call, and in the full call the compiled step and the readable path (late
    touch-downs, plan ends, QPs left to DAQP); with ``push`` the base is knocked off its plan (0.3 m/s sideways)
    so that a check inside the lane finds it off and the full call replans."""
    runs = []
    for compiled in (True, False):
        env = gym.make("QuadUneven-v0", terrain=terrain)
        policy = attach_expert(env, ExpertConfig(distribution=distribution, share_nominal_world=share))
        policy.hook.compiled = compiled
        answers, readable = [], []
        lane, call = PhysicsHook.torques_into, ComputedTorqueController.__call__

        def counted_lane(self, *args, _lane=lane, _answers=answers):
            _answers.append(_lane(self, *args))
            return _answers[-1]

        def counted_call(self, *args, _call=call, _readable=readable):
            _readable.append(1)
            return _call(self, *args)

        monkeypatch.setattr(PhysicsHook, "torques_into", counted_lane)
        monkeypatch.setattr(ComputedTorqueController, "__call__", counted_call)
        obs, _ = env.reset(seed=0)
        assert policy.shares_simulator_data is share
        d = env.unwrapped.data
        qpos, torques = [], []
        for step in range(260):
            if push and step == 150:
                d.qvel[1] += 0.3
            obs, _, fell, *_ = env.step(policy.predict(obs)[0])
            qpos.append(d.qpos.copy())
            torques.append(d.ctrl.copy())
            if fell:  # the "pinv" expert tips over after ~2.2 s, either way
                break
        if compiled:  # the lane's later calls went to the kernel's compiled entry point, past numba's dispatcher
            assert policy.controller._grid_calls
        runs.append((np.array(qpos), np.array(torques), answers, readable, list(policy.failure_log), policy.recoveries))
        monkeypatch.undo()
    (q_fast, u_fast, answers, readable, log_fast, rec_fast), (q_ref, u_ref, _, readable_ref, log_ref, rec_ref) = runs
    np.testing.assert_array_equal(u_fast, u_ref)
    np.testing.assert_array_equal(q_fast, q_ref)
    assert log_fast == log_ref and rec_fast == rec_ref
    assert rec_fast >= 1 or not push
    n = len(answers)
    assert 0.5 * n < sum(answers) < n, "the lane and the full call must both run"
    assert 0 < len(readable) <= n - sum(answers)
    if distribution == "qp":  # (the "pinv" walk ends before its first plan's end)
        assert len(readable) < n - sum(answers), "the full call must take both the compiled step and the readable one"
    assert len(readable_ref) == n


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
