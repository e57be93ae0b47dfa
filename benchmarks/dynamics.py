"""Microseconds per call (median of many) of the dynamics backends, the inverse dynamics and mj_step.

Run: ``.venv/bin/python benchmarks/dynamics.py [--repeats N] [--robot NAME]``. Prints one table; no assertion.
The state is the standing robot (``--robot``: any of ``quad_uneven_env.robots()``, default the paper's) on the
env's rough terrain (4 cm), after settling for 0.2 s.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # tiny matrices: BLAS threads only add overhead

import argparse
import platform
import time
from collections.abc import Callable

import gymnasium as gym
import mujoco
import numpy as np
import pinocchio as pin

import quad_uneven_env  # noqa: F401  (registers QuadUneven-v0)
from agents.control.controller import ComputedTorqueController, InverseDynamics
from agents.control.references import track_in_env
from planners.types import ReferenceSample
from quad_uneven_env.robot.conventions import qpos_mj_to_pin, qvel_mj_to_pin
from quad_uneven_env.robot.dynamics import BACKENDS, make_dynamics
from quad_uneven_env.robot.dynamics.pinocchio_backend import build_pinocchio_model


def median_us(fn: Callable[[], object], repeats: int, inner: int = 20) -> float:
    """Median over ``repeats`` blocks of the mean time of ``inner`` calls, in microseconds."""
    for _ in range(inner):
        fn()
    samples = np.empty(repeats)
    for k in range(repeats):
        t0 = time.perf_counter_ns()
        for _ in range(inner):
            fn()
        samples[k] = (time.perf_counter_ns() - t0) / inner / 1e3
    return float(np.median(samples))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=300, help="timed blocks per figure (each of 20 calls)")
    parser.add_argument(
        "--acceptance", action="store_true", help="also print the controller's acceptance figures (about 2 min)"
    )
    parser.add_argument("--robot", default="paper", help="robot name or YAML path (default: the paper's robot)")
    args = parser.parse_args()
    if args.acceptance:
        acceptance_figures()

    env = gym.make("QuadUneven-v0", robot=args.robot, terrain={"kind": "rough", "amplitude": 0.04, "spawn_radius": 0.0})
    env.reset(seed=0)
    u = env.unwrapped
    m, d = u.model, u.data
    rng = np.random.default_rng(0)
    for _ in range(100):  # settle: zero-torque steps are enough to load the feet
        mujoco.mj_step(m, d)
    d.qvel[:] += rng.normal(0.0, 0.1, m.nv)  # non-zero velocities for the Coriolis terms
    mujoco.mj_step1(m, d)
    qpos, qvel = d.qpos.copy(), d.qvel.copy()
    stance = (True,) * 4
    bdd = np.zeros(6)

    rows: list[tuple[str, float]] = []
    dyns = {b: make_dynamics(b, m) for b in BACKENDS}
    for b, dyn in dyns.items():
        rows.append((f"terms() backend={b}", median_us(lambda dyn=dyn: dyn.terms(qpos, qvel), args.repeats)))
    mj_dyn = dyns["mujoco"]
    rows.append(
        (
            "terms_from_data() backend=mujoco (after mj_step1)",
            median_us(lambda: mj_dyn.terms_from_data(d), args.repeats),
        )
    )
    for dist in ("pinv", "qp"):
        ID = InverseDynamics(mj_dyn, dist)
        rows.append(
            (
                f"ID solve backend=mujoco {dist} (terms_from_data + solve_terms)",
                median_us(lambda ID=ID: ID.solve_terms(mj_dyn.terms_from_data(d), bdd, stance), args.repeats),
            )
        )
    for b in ("explicit", "pinocchio"):
        ID = InverseDynamics(dyns[b], "pinv")
        rows.append(
            (f"ID solve backend={b} pinv", median_us(lambda ID=ID: ID.solve(qpos, qvel, bdd, stance), args.repeats))
        )

    z3, z12 = np.zeros(3), np.zeros(12)
    hold = ReferenceSample(0.0, qpos[:3].copy(), qpos[3:7].copy(), z3, z3, z3, z3, qpos[7:].copy(), z12, z12, stance)
    for dist in ("pinv", "qp"):
        ctrl = ComputedTorqueController(lambda t: hold, backend="mujoco", distribution=dist)
        ctrl.reset(m, d, u.terrain)
        rows.append(
            (
                f"controller call backend=mujoco {dist} (same state, after mj_step1)",
                median_us(lambda c=ctrl: c(m, d), args.repeats),
            )
        )

    n_batch = 1000
    qpos_b = np.repeat(qpos[None], n_batch, 0)
    qvel_b = qvel[None] + rng.normal(0.0, 0.5, (n_batch, m.nv))
    t_batch = median_us(lambda: dyns["explicit"].terms(qpos_b, qvel_b), max(5, args.repeats // 20), inner=1)
    rows.append((f"terms() backend=explicit, batch of {n_batch}, per state", t_batch / n_batch))

    pm = build_pinocchio_model(u.robot)
    pd = pm.createData()
    q, v = qpos_mj_to_pin(qpos), qvel_mj_to_pin(qpos, qvel)
    a = np.zeros(pm.nv)

    def pin_ref() -> None:
        pin.crba(pm, pd, q)
        pin.rnea(pm, pd, q, v, a)
        pin.computeJointJacobians(pm, pd, q)

    t_pin = median_us(pin_ref, args.repeats)
    rows.append(("Pinocchio crba + rnea + computeJointJacobians (reference)", t_pin))

    d2 = mujoco.MjData(m)
    d2.qpos[:], d2.qvel[:] = qpos, qvel

    def step() -> None:
        mujoco.mj_step(m, d2)
        d2.qpos[:], d2.qvel[:] = qpos, qvel  # stay at the same standing state

    t_step = median_us(step, args.repeats)
    rows.append((f"mj_step (scene on rough terrain, ncon={d.ncon})", t_step))

    ctrl_us, phys_us = closed_loop_split(u, env)
    rows.append(("closed loop (standing): controller call, pinv, backend=mujoco", ctrl_us))
    rows.append(("closed loop (standing): mj_step1 + mj_step2", phys_us))

    width = max(len(r[0]) for r in rows)
    print(
        f"# robot {u.robot.name}, {platform.processor() or platform.machine()}, numpy {np.__version__}, "
        f"mujoco {mujoco.__version__}"
    )
    print(f"{'what':<{width}}  us/call")
    for name, t in rows:
        print(f"{name:<{width}}  {t:8.1f}")
    id_pinv = dict(rows)["ID solve backend=mujoco pinv (terms_from_data + solve_terms)"]
    ctrl_pinv = dict(rows)["controller call backend=mujoco pinv (same state, after mj_step1)"]
    print(f"\nID pinv (mujoco) / mj_step = {id_pinv / t_step:.2f}  (target <= 1.0)")
    print(f"controller call pinv (mujoco) / mj_step = {ctrl_pinv / t_step:.2f}  (target <= 1.0)")
    print(f"controller / (mj_step1 + mj_step2) in the loop = {ctrl_us / phys_us:.2f}")
    print(
        f"explicit terms / Pinocchio reference = {dict(rows)['terms() backend=explicit'] / t_pin:.1f}  (target <= 20)"
    )
    env.close()


def acceptance_figures(seconds: float = 10.0) -> None:
    """Standing and base-wave tracking on rough terrain (4 cm), 10 s each, "pinv" and "qp"."""
    print(f"# acceptance, {seconds:g} s each, rough terrain 4 cm, seed 3, frame_skip 1")
    print("scenario       dist  rms_pos_mm  rms_rot_mrad  max_site_drift_mm  min_Fn_N  cone_excess_N  fallbacks")
    for wave, name in ((0.0, "stand"), (1.0, "z+roll+pitch")):
        for dist in ("pinv", "qp"):
            o = track_in_env(seconds, dist, wave)
            print(
                f"{name:<14} {dist:<5} {o['rms_pos'] * 1e3:10.3f} {o['rms_rot'] * 1e3:13.3f} "
                f"{o['slip'].max() * 1e3:18.2f} {o['min_fn']:9.1f} {o['cone_violation']:14.1f} {o['fallbacks']:10d}"
                + (f"  ENDED: {o['termination_reason']}" if o["termination_reason"] else "")
            )
    print()


def closed_loop_split(u, env, steps: int = 3000) -> tuple[float, float]:
    """Median us per physics step spent in the controller and in mj_step1 + mj_step2, standing under control."""
    env.reset(seed=1)
    m, d = u.model, u.data
    p0, q0, j0 = d.qpos[:3].copy(), d.qpos[3:7].copy(), d.qpos[7:].copy()
    z3, z12 = np.zeros(3), np.zeros(12)
    sample = ReferenceSample(0.0, p0, q0, z3, z3, z3, z3, j0, z12, z12, (True,) * 4)
    ctrl = ComputedTorqueController(lambda t: sample, backend="mujoco", distribution="pinv")
    ctrl.reset(m, d, u.terrain)
    t_ctrl = np.empty(steps)
    t_phys = np.empty(steps)
    a = np.zeros(12)
    for k in range(steps):
        t0 = time.perf_counter_ns()
        mujoco.mj_step1(m, d)
        t1 = time.perf_counter_ns()
        d.ctrl[:] = ctrl(m, d, a)
        t2 = time.perf_counter_ns()
        mujoco.mj_step2(m, d)
        t3 = time.perf_counter_ns()
        t_ctrl[k] = (t2 - t1) / 1e3
        t_phys[k] = (t1 - t0 + t3 - t2) / 1e3
    return float(np.median(t_ctrl)), float(np.median(t_phys))


if __name__ == "__main__":
    main()
