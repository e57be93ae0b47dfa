"""Env throughput of QuadUneven-v0 against raw mj_step and Gymnasium's Ant-v5, in one run.

Prints env steps/s, mj_step/s and the overhead ratio env_step_time / (frame_skip x mj_step_time)
for both environments. Usage: ``python benchmarks/env_throughput.py [--steps N]``.
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import mujoco
import numpy as np

import quad_uneven_env  # noqa: F401  (registers QuadUneven-v0)


def time_env(env: gym.Env, steps: int, seed: int = 0) -> float:
    """Seconds per env.step with zero action (resets excluded)."""
    env.reset(seed=seed)
    zero = np.zeros(env.action_space.shape, dtype=env.action_space.dtype)
    total, done_steps = 0.0, 0
    while done_steps < steps:
        t0 = time.perf_counter()
        _, _, terminated, truncated, _ = env.step(zero)
        total += time.perf_counter() - t0
        done_steps += 1
        if terminated or truncated:
            env.reset()
    return total / steps


def time_mj_step(model: mujoco.MjModel, qpos: np.ndarray, steps: int) -> float:
    """Seconds per raw mj_step from the given state, zero control, restarting every 500 steps."""
    data = mujoco.MjData(model)
    total = 0.0
    done = 0
    while done < steps:
        mujoco.mj_resetData(model, data)
        data.qpos[:] = qpos
        mujoco.mj_forward(model, data)
        n = min(500, steps - done)
        t0 = time.perf_counter()
        for _ in range(n):
            mujoco.mj_step(model, data)
        total += time.perf_counter() - t0
        done += n
    return total / steps


def measure(env_id: str, steps: int, **kwargs) -> dict[str, float]:
    """Env and raw-physics timings of one registered env."""
    env = gym.make(env_id, **kwargs)
    u = env.unwrapped
    env.reset(seed=0)
    qpos = u.data.qpos.copy()
    t_env = time_env(env, steps)
    t_mj = time_mj_step(u.model, qpos, steps * u.frame_skip)
    env.close()
    return {
        "env_steps_per_s": 1.0 / t_env,
        "mj_steps_per_s": 1.0 / t_mj,
        "frame_skip": u.frame_skip,
        "ratio": t_env / (u.frame_skip * t_mj),
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
        "Ant-v5 (Gymnasium reference)": measure("Ant-v5", args.steps),
    }
    print(f"{'env':46s} {'env steps/s':>12s} {'mj_step/s':>12s} {'frame_skip':>10s} {'overhead ratio':>15s}")
    for name, r in rows.items():
        print(
            f"{name:46s} {r['env_steps_per_s']:12.0f} {r['mj_steps_per_s']:12.0f} "
            f"{r['frame_skip']:10d} {r['ratio']:15.2f}"
        )
    print("overhead ratio = env_step_time / (frame_skip x mj_step_time); target for QuadUneven-v0 <= 1.25")


if __name__ == "__main__":
    main()
