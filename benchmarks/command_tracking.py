"""How well the expert follows a commanded (vx, vy): falls, velocity tracking error and the stability index.

For each fixed command and seed: ``QuadUneven-v0(terrain, command={"vx": ..., "vy": ...})`` with the expert
attached, walked for ``--seconds``. Printed per command, over the seeds:

- falls (episodes that terminated), short (cycle plans that failed at the commanded stride, then retried
  shorter) and stalls (cycles the expert stood still: "no feasible plan");
- cycle-mean tracking error (m/s): per whole gait cycle after the first (which starts from rest), the norm of
  (COG displacement over the cycle / cycle duration - commanded (vx, vy)), yaw-aligned frame; mean over the
  cycles and episodes (a crawl's velocity within a cycle is not constant, so this is the error of the speed
  the robot actually travels at);
- velocity RMSE (m/s): the root mean square over the control steps after the first cycle of the COG's
  horizontal velocity (yaw-aligned frame) minus the command: the crawl's start-stop profile within a cycle
  is part of it (what a per-step tracking reward sees);
- index >= 0: the fraction of control steps with the measured stability index >= 0.

The terrain is rough with its grid centred on the spawn point (``x_start`` -5 m, 10 m x 5 m, flat spawn
disc of radius ``--spawn-radius``), so that walking backwards or sideways does not leave it (an episode that
leaves it anyway is counted under "off", not as a fall).

Usage: ``python benchmarks/command_tracking.py [--seeds 5] [--seconds 20] [--amplitude 0.05]
[--spawn-radius 0.4] [--durations 0.5,0.5,0.5,0.1,0.5,0.5,0.5] [--commands="0.1,0 -0.1,0 0,0.05"]``
(commands: space-separated ``vx,vy`` pairs, m/s; durations: the expert's 7 phases, s).
"""

from __future__ import annotations

import argparse
import json
import math

import gymnasium as gym
import numpy as np

import quad_uneven_env  # noqa: F401
from agents.expert import ExpertConfig, attach_expert


def terrain_spec(amplitude: float, spawn_radius: float) -> dict:
    """Rough terrain of ``amplitude`` (m) on an 8 m x 5 m grid centred on the spawn point."""
    return {
        "kind": "rough",
        "amplitude": amplitude,
        "x_start": -5.0,
        "length": 10.0,
        "width": 5.0,
        "spawn_radius": spawn_radius,
    }


def run_episode(command: dict, seed: int, seconds: float, terrain: dict, config: ExpertConfig) -> dict:
    """One episode of the expert (``config``) under ``command`` (the env's argument); its figures."""
    env = gym.make("QuadUneven-v0", terrain=terrain, command=command, max_episode_steps=10**7)
    expert = attach_expert(env, config)
    _, info = env.reset(seed=seed)
    period = float(sum(config.durations))
    dt = env.unwrapped.dt
    steps_per_cycle = round(period / dt)
    cog, yaw, index_ok, fell, off = [info["cog"][:2].copy()], [0.0], 0, False, False
    vel, cmds = [info["cog_vel"][:2].copy()], [info["command"][:2].copy()]
    n = round(seconds / dt)
    for _ in range(n):
        _, _, term, trunc, info = env.step(expert.predict(None)[0])
        cog.append(info["cog"][:2].copy())
        vel.append(info["cog_vel"][:2].copy())
        cmds.append(info["command"][:2].copy())
        q = env.unwrapped.data.qpos[3:7]
        yaw.append(math.atan2(2 * (q[0] * q[3] + q[1] * q[2]), 1 - 2 * (q[2] ** 2 + q[3] ** 2)))
        index_ok += info["stability_index"] >= 0.0
        if term or trunc:
            fell = bool(term) and not str(info["termination_reason"]).startswith("left the terrain")
            off = bool(term) and not fell
            break
    cog, cmds = np.array(cog), np.array(cmds)
    errors = []  # the expert reads the command at each cycle's start (step a): it holds for the whole cycle
    for k in range(1, (len(cog) - 1) // steps_per_cycle):
        a, b = k * steps_per_cycle, (k + 1) * steps_per_cycle
        c, s = math.cos(yaw[a]), math.sin(yaw[a])
        v_W = (cog[b] - cog[a]) / period
        v_H = np.array([c * v_W[0] + s * v_W[1], -s * v_W[0] + c * v_W[1]])
        errors.append(float(np.linalg.norm(v_H - cmds[a])))
    whole = (len(cog) - 1) // steps_per_cycle
    a, b = steps_per_cycle, whole * steps_per_cycle
    mean_v = (cog[b] - cog[a]) / ((b - a) * dt) if b > a else np.full(2, np.nan)
    yaw_a, vel_a = np.array(yaw[a:]), np.array(vel[a:])
    v_H = np.column_stack(
        [
            np.cos(yaw_a) * vel_a[:, 0] + np.sin(yaw_a) * vel_a[:, 1],
            -np.sin(yaw_a) * vel_a[:, 0] + np.cos(yaw_a) * vel_a[:, 1],
        ]
    )
    rmse = float(np.sqrt(np.mean(np.sum((v_H - cmds[a:]) ** 2, axis=1)))) if len(v_H) else math.nan
    stalls = sum("no feasible plan" in m for m in expert.failure_log)
    short = len({m.split(",")[0] for m in expert.failure_log if ", stride " in m})  # one per cycle start time
    env.close()
    return {
        "fell": fell,
        "off": off,
        "stalls": stalls,
        "short": short,
        "cycle_errors": errors,
        "rmse": rmse,
        "index_ok": index_ok / max(len(cog) - 1, 1),
        "mean_v": mean_v,
    }


def label(command: dict) -> str:
    """``  vx     vy`` of a fixed command, ``drawn`` for ranges."""
    if "ranges" in command:
        return " drawn       "
    return f"{command['vx']:6.3f} {command['vy']:6.3f}"


def main(argv: list[str] | None = None) -> None:
    """Run every command over the seeds and print one line each."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--seconds", type=float, default=20.0, help="simulated seconds per episode")
    parser.add_argument("--amplitude", type=float, default=0.05, help="rough terrain amplitude (m)")
    parser.add_argument(
        "--ranges", default=None, help="drawn commands instead: JSON ranges, e.g. '{\"vx\": [-0.2, 0.2]}'"
    )
    parser.add_argument("--resample-interval", type=float, default=10.0, help="s, with --ranges")
    parser.add_argument("--durations", default=None, help="the expert's 7 phase durations (s), comma-separated")
    parser.add_argument("--spawn-radius", type=float, default=0.4, help="flat disc around the spawn point (m)")
    parser.add_argument(
        "--commands",
        default="0.2,0 0.15,0 0.106,0 0.05,0 0,0 -0.05,0 -0.106,0 -0.15,0 -0.2,0 0,0.05 0,-0.05 0,0.1 0,-0.1 "
        "0.07,0.04 -0.07,-0.04",
    )
    args = parser.parse_args(argv)
    terrain = terrain_spec(args.amplitude, args.spawn_radius)
    config = (
        ExpertConfig()
        if args.durations is None
        else ExpertConfig(durations=tuple(map(float, args.durations.split(","))))
    )
    print(
        f"terrain {json.dumps(terrain)}, {args.seeds} seeds, {args.seconds} s per episode, durations {config.durations}"
    )
    print("    vx     vy | falls off short stalls | cycle err (m/s)  | RMSE (m/s) | mean v (m/s)     | index>=0")
    if args.ranges is not None:
        commands = [{"ranges": json.loads(args.ranges), "resample_interval": args.resample_interval}]
    else:
        commands = [dict(zip(("vx", "vy"), map(float, pair.split(",")), strict=True)) for pair in args.commands.split()]
    for command in commands:
        runs = [run_episode(command, seed, args.seconds, terrain, config) for seed in range(args.seeds)]
        cycle = [e for r in runs for e in r["cycle_errors"]]
        mean_v = np.nanmean([r["mean_v"] for r in runs], axis=0)
        counts = [sum(r[k] for r in runs) for k in ("fell", "off", "short", "stalls")]
        print(
            f"{label(command)} | {counts[0]:5d} {counts[1]:3d} {counts[2]:5d} {counts[3]:6d} | "
            f"{np.mean(cycle):6.3f} max {np.max(cycle):5.3f} | {np.mean([r['rmse'] for r in runs]):10.3f} | "
            f"({mean_v[0]:6.3f}, {mean_v[1]:6.3f}) | {np.mean([r['index_ok'] for r in runs]):.4f}",
            flush=True,
        )


if __name__ == "__main__":
    main()
