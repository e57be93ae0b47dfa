"""Speed of the expert in the loop: simulated seconds per wall second on rough terrain.

Measured in one run, on the same model: (1) the expert walking (planner every gait cycle +
computed-torque controller at every 2 ms physics step, through QuadUneven-v0's hook);
(2) the same model stepped with zero torques by raw ``mj_step`` from the same standing state
(restarted every 2 s so it keeps simulating contacts rather than a pile on the ground).
Targets: expert >= 0.5 x the zero-torque rate and >= 10 x real time.

Usage: ``python benchmarks/expert.py [--seconds 30] [--terrain rough] [--model nominal|oracle] [--copy]``
(``--copy``: the nominal expert copies the measured state into its own model every physics step even in
the nominal world, as it does whenever the simulated robot differs from the nominal one).
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import mujoco
import numpy as np

import quad_uneven_env  # noqa: F401
from agents.expert import attach_expert


def main(argv: list[str] | None = None) -> None:
    """Run both measurements and print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=30.0, help="simulated seconds of walking")
    parser.add_argument("--terrain", default="rough")
    parser.add_argument("--distribution", default="qp", choices=["qp", "pinv"])
    parser.add_argument("--model", default="nominal", choices=["nominal", "oracle"])
    parser.add_argument("--copy", action="store_true", help="never share the simulator's data (nominal model)")
    args = parser.parse_args(argv)

    from agents.expert import ExpertConfig

    env = gym.make("QuadUneven-v0", terrain=args.terrain, max_episode_steps=10**7)
    config = ExpertConfig(distribution=args.distribution, model=args.model, share_nominal_world=not args.copy)
    policy = attach_expert(env, config)
    # Warm-up: numba kernels compile on first use; keep that out of the timing.
    obs, _ = env.reset(seed=1)
    for _ in range(5):
        obs, *_ = env.step(policy.predict(obs)[0])
    obs, info = env.reset(seed=0)
    u = env.unwrapped
    standing = mujoco.MjData(u.model)
    standing.qpos[:] = u.data.qpos
    x0 = info["cog"][0]
    n = int(args.seconds / u.dt)
    t0 = time.perf_counter()
    for _ in range(n):
        obs, _, terminated, _, info = env.step(policy.predict(obs)[0])
        if terminated:
            break
    wall_expert = time.perf_counter() - t0
    sim_expert = u.data.time
    planner_s = sum(policy.planner_times_ms) / 1e3

    d = mujoco.MjData(u.model)
    steps = round(sim_expert / u.model.opt.timestep)
    per_restart = round(2.0 / u.model.opt.timestep)
    wall_zero = 0.0
    done = 0
    while done < steps:
        mujoco.mj_resetData(u.model, d)
        d.qpos[:] = standing.qpos
        mujoco.mj_forward(u.model, d)
        k = min(per_restart, steps - done)
        t1 = time.perf_counter()
        for _ in range(k):
            mujoco.mj_step(u.model, d)
        wall_zero += time.perf_counter() - t1
        done += k
    rate_expert = sim_expert / wall_expert
    rate_zero = sim_expert / wall_zero
    print(
        f"terrain {args.terrain}, distribution {args.distribution}, model {args.model} "
        f"({'simulator data shared' if policy.shares_simulator_data else 'own copy'}), {sim_expert:.1f} s simulated"
    )
    print(f"expert walked {info['cog'][0] - x0:.2f} m, ended: {info['termination_reason'] or 'no fall'}")
    print(f"{'':34s} {'sim s / wall s':>15s}")
    print(f"{'expert in the loop':34s} {rate_expert:15.1f}")
    print(f"{'zero torques, raw mj_step':34s} {rate_zero:15.1f}")
    print(
        f"ratio expert / zero-torque: {rate_expert / rate_zero:.2f} (target >= 0.5); real-time factor "
        f"{rate_expert:.1f} (target >= 10)"
    )
    print(
        f"planning: {len(policy.planner_times_ms)} plans, {planner_s:.2f} s of the {wall_expert:.2f} s wall "
        f"(median {np.median(policy.planner_times_ms):.0f} ms per cycle)"
    )


if __name__ == "__main__":
    main()
