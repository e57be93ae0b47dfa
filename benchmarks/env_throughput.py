"""Env throughput of QuadUneven-v0 against raw mj_step and Gymnasium's Ant-v5, in one run.

Prints env steps/s, mj_step/s and the overhead ratio env_step_time / (frame_skip x mj_step_time)
for both environments, QuadUneven-v0 also with the ``mild`` randomization preset (the replay runs on the
same randomized model, so the ratio is the env's overhead over the physics it steps).
Usage: ``python benchmarks/env_throughput.py [--steps N]``.
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import mujoco
import numpy as np

import quad_uneven_env  # noqa: F401  (registers QuadUneven-v0)


def measure(env_id: str, steps: int, **kwargs) -> dict[str, float]:
    """Time ``steps`` env steps with zero action, then replay the identical physics with raw mj_step.

    Each episode segment starts from a saved MuJoCo state (controls included) and is replayed
    in a separate MjData with ``frame_skip`` x ``mj_step`` per env step, so both timings cover
    exactly the same trajectory, contacts included. Resets are excluded from both.
    """
    env = gym.make(env_id, **kwargs)
    u = env.unwrapped
    zero = np.zeros(env.action_space.shape, dtype=env.action_space.dtype)
    spec = mujoco.mjtState.mjSTATE_INTEGRATION
    state = np.empty(mujoco.mj_stateSize(u.model, spec))
    replay = mujoco.MjData(u.model)
    t_env = t_mj = 0.0
    done = 0
    env.reset(seed=0)
    for _ in range(20):  # warm-up: compiled kernels are built on first use
        env.step(zero)
    env.reset(seed=0)
    while done < steps:
        mujoco.mj_getState(u.model, u.data, state, spec)
        n, ended = 0, False
        t0 = time.perf_counter()
        while done + n < steps and not ended:
            _, _, terminated, truncated, _ = env.step(zero)
            n += 1
            ended = terminated or truncated
        t_env += time.perf_counter() - t0
        mujoco.mj_setState(u.model, replay, state, spec)
        mujoco.mj_forward(u.model, replay)
        t0 = time.perf_counter()
        for _ in range(n * u.frame_skip):
            mujoco.mj_step(u.model, replay)
        t_mj += time.perf_counter() - t0
        done += n
        if ended:
            env.reset()
    env.close()
    per_env, per_mj = t_env / steps, t_mj / (steps * u.frame_skip)
    return {
        "env_steps_per_s": 1.0 / per_env,
        "mj_steps_per_s": 1.0 / per_mj,
        "frame_skip": u.frame_skip,
        "ratio": per_env / (u.frame_skip * per_mj),
    }


def main(argv: list[str] | None = None) -> None:
    """Run the benchmark and print a table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=2000, help="env steps per measurement")
    args = parser.parse_args(argv)
    rows = {
        "QuadUneven-v0 (rough, torque, zero action)": measure("QuadUneven-v0", args.steps, terrain="rough"),
        "QuadUneven-v0 (rough, joint_pd, standing)": measure(
            "QuadUneven-v0", args.steps, terrain="rough", action_mode="joint_pd"
        ),
        "QuadUneven-v0 (rough, torque, zero, mild)": measure(
            "QuadUneven-v0", args.steps, terrain="rough", randomization="mild"
        ),
        "QuadUneven-v0 (rough, joint_pd, standing, mild)": measure(
            "QuadUneven-v0", args.steps, terrain="rough", action_mode="joint_pd", randomization="mild"
        ),
        "Ant-v5 (Gymnasium reference)": measure("Ant-v5", args.steps),
    }
    print(f"{'env':46s} {'env steps/s':>12s} {'mj_step/s':>12s} {'frame_skip':>10s} {'overhead ratio':>15s}")
    for name, r in rows.items():
        print(
            f"{name:46s} {r['env_steps_per_s']:12.0f} {r['mj_steps_per_s']:12.0f} "
            f"{r['frame_skip']:10d} {r['ratio']:15.2f}"
        )
    print(
        "overhead ratio = env_step_time / (frame_skip x mj_step_time); target for QuadUneven-v0 <= 1.25, "
        "<= 1.3 with randomization (mild: latency, pushes and observation noise on)"
    )


if __name__ == "__main__":
    main()
