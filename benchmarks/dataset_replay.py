"""A collected dataset of the expert: collection speed, size, and how far an open-loop replay of its actions drifts.

1. ``quad-uneven collect`` of a suite (``collect``, in this process): env steps per wall second of the whole
   collection and bytes of the Minari dataset per 1000 steps; and, on the suite's first episodes, the speed of the
   same episode run by ``evaluate``'s episode function without recording, for the recording's cost.
2. For every episode: its env rebuilt (``episode_env``), reset with its seed, stepped open loop with the recorded
   actions (the mean applied torque / motor limit, held over each control step) in the plain env, against the
   recorded trajectory: distance walked, whether and when it fell, the COG's distance from the recorded one, and
   the time until that passes 5 cm. The same with the physics-rate torques of the infos (``TorqueReplay``), which
   must follow the recorded trajectory exactly.

Usage: ``python benchmarks/dataset_replay.py [--suite smoke] [--episodes 1] [--seed 0] [--out DIR]
[--speed-episodes 2]``
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from agents.datasets import TorqueReplay, collect, collect_task, episode_env, episode_metadata, load_collected
from agents.evaluation.episode import EvalConfig, run_task
from agents.evaluation.suites import episode_tasks, load_suite

DRIFT = 0.05
"""m: the COG distance from the recorded one that counts as having drifted off."""


def replay(dataset, i: int, physics_rate: bool) -> dict:
    """Episode ``i`` replayed open loop; its distance walked, fall and COG drift against the recorded episode."""
    ep, meta = dataset[i], episode_metadata(dataset, i)
    env = episode_env(dataset, i)
    u = env.unwrapped
    if physics_rate:
        u.set_controller(TorqueReplay(ep.infos["torques"][1:]))
    env.reset(seed=meta["seed"])
    recorded = ep.infos["cog"]
    drift, fell_at, info = [], None, None
    for t, action in enumerate(ep.actions):
        _, _, terminated, _, info = env.step(action)
        drift.append(float(np.linalg.norm(info["cog"] - recorded[t + 1])))
        if terminated:
            fell_at = (t + 1) * u.dt
            break
    drift = np.asarray(drift)
    off = np.flatnonzero(drift > DRIFT)
    return {
        "recorded_distance": float(ep.infos["distance"][-1]),
        "recorded_fell": bool(ep.terminations[-1]),
        "replay_distance": float(info["distance"]),
        "fell_at": fell_at,
        "drift_end": float(drift[-1]),
        "drift_1s": float(drift[min(len(drift), round(1.0 / u.dt)) - 1]),
        "off_after": None if not len(off) else (off[0] + 1) * u.dt,
        "duration": len(ep.actions) * u.dt,
    }


def main(argv: list[str] | None = None) -> None:
    """Collect, measure, replay; print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--suite", default="smoke")
    parser.add_argument("--episodes", type=int, default=1, help="seeds per entry")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=None, help="dataset directory (default: a temporary one)")
    parser.add_argument("--speed-episodes", type=int, default=2, help="episodes timed with and without recording")
    args = parser.parse_args(argv)
    out = args.out or Path(tempfile.mkdtemp(prefix="dataset_replay_"))

    summary = collect(args.suite, out, episodes=args.episodes, seed=args.seed, overwrite=True, progress=False)
    print(
        f"collect --suite {args.suite} --episodes {args.episodes}: {summary['episodes']} episodes, {summary['steps']} "
        f"steps, {summary['steps_per_second']:.0f} env steps/s (wall, whole collection incl. env builds), "
        f"{summary['bytes_per_1000_steps'] / 1e6:.2f} MB per 1000 steps ({summary['dataset_bytes'] / 1e6:.1f} MB)"
    )

    suite = load_suite(args.suite)
    cfg = EvalConfig(policy="expert", goal_distance=suite.goal_distance, time_limit=suite.time_limit)
    for task in episode_tasks(suite, args.episodes, args.seed)[: args.speed_episodes]:
        t0 = time.perf_counter()
        steps = len(collect_task(task, cfg).arrays["actions"])
        t1 = time.perf_counter()
        run_task(task, cfg)
        t2 = time.perf_counter()
        print(
            f"  episode {task.index} ({task.kind}, {steps} steps): recorded {steps / (t1 - t0):.0f} steps/s, "
            f"evaluate's episode {steps / (t2 - t1):.0f} steps/s"
        )

    dataset = load_collected(out)
    for physics_rate in (False, True):
        what = "physics-rate torques (infos)" if physics_rate else "recorded actions (mean torque), open loop"
        print(f"replay of the {what}:")
        print(
            "  ep  terrain          recorded m (fell)  replay m  replay fell at  COG drift at 1 s  at the end  "
            f"> {DRIFT * 100:.0f} cm after"
        )
        rows = []
        for i in range(dataset.total_episodes):
            r = replay(dataset, i, physics_rate)
            rows.append(r)
            kind = episode_metadata(dataset, i)["terrain_kind"]
            fell = "-" if r["fell_at"] is None else f"{r['fell_at']:.2f} s"
            off = "never" if r["off_after"] is None else f"{r['off_after']:.2f} s"
            print(
                f"  {i:2d}  {kind:16s} {r['recorded_distance']:6.2f} ({'yes' if r['recorded_fell'] else 'no '})"
                f"      {r['replay_distance']:6.2f}  {fell:>14s}  {r['drift_1s']:13.3f} m  {r['drift_end']:8.3f} m  "
                f"{off:>10s}"
            )
        falls = sum(r["fell_at"] is not None for r in rows)
        rec = np.mean([r["recorded_distance"] for r in rows])
        rep = np.mean([r["replay_distance"] for r in rows])
        print(f"  mean distance recorded {rec:.2f} m, replayed {rep:.2f} m; falls {falls}/{len(rows)}")


if __name__ == "__main__":
    main()
