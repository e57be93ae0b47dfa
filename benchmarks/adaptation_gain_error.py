"""Diagnostic: how close an adaptation's gains come to the ideal gain of each joint, in closed loop.

Runs the expert with ``ExpertConfig(adaptation=...)`` in the extreme world on
``robust_extreme``'s three terrains and, from 5 s to 10 s of each episode, averages per joint |log(g / g_ideal)|
with g_ideal = 1/s (``--ideal strength``: undo the motor) or (m / m0) / s (``--ideal load``: undo the motor and the
extra mass, the learned estimator's target). Prints the mean per joint kind, and the same for gain 1 (the expert's
own torques). Episodes that fall before 10 s are left out (and counted).

Usage: ``python benchmarks/adaptation_gain_error.py --adaptation knee|learned [--ideal strength|load]
[--seeds 1200-1209]`` (training-world seeds: no validation or held-out set).
"""

from __future__ import annotations

import argparse
from multiprocessing import get_context

import numpy as np

from agents.rl.strength_fit import ENTRIES
from quad_uneven_env import constants as C


def episode(job: tuple[str, str, int, str]) -> tuple[np.ndarray, np.ndarray] | None:
    """Mean |log(g / g_ideal)| over 5-10 s (12,) and |log g_ideal| (12,), or None after a fall."""
    import gymnasium as gym

    import quad_uneven_env  # noqa: F401  (registers QuadUneven-v0)
    from agents.expert import ExpertConfig, attach_expert

    adaptation, entry, seed, ideal = job
    env = gym.make("QuadUneven-v0", terrain=ENTRIES[entry], randomization="extreme", max_episode_steps=10**6)
    expert = attach_expert(env, ExpertConfig(adaptation=adaptation))
    nominal_mass = float(env.unwrapped.model.body_subtreemass[env.unwrapped.idx.trunk_body])
    env.reset(seed=seed)
    draw = env.unwrapped.episode_draw
    log_ideal = -np.log(draw.motor_strength)
    if ideal == "load":
        log_ideal = log_ideal + np.log(draw.total_mass / nominal_mass)
    errors = []
    for k in range(500):
        *_, terminated, _, _ = env.step(np.zeros(12, dtype=np.float32))
        if terminated:
            return None
        if k >= 250:
            errors.append(np.abs(np.log(expert.adaptation.gain) - log_ideal))
    return np.mean(errors, axis=0), np.abs(log_ideal)


def main() -> None:
    """Run the episodes on two processes and print the means per joint kind."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--adaptation", choices=("knee", "learned"), required=True)
    ap.add_argument("--ideal", choices=("strength", "load"), default="strength")
    ap.add_argument("--seeds", default="1200-1209", help="first-last (inclusive), per terrain entry")
    args = ap.parse_args()
    first, last = (int(v) for v in args.seeds.split("-"))
    jobs = [(args.adaptation, entry, seed, args.ideal) for seed in range(first, last + 1) for entry in ENTRIES]
    with get_context("spawn").Pool(2) as pool:
        results = pool.map(episode, jobs)
    kept = [r for r in results if r is not None]
    if not kept:
        raise SystemExit("every episode fell before 10 s")
    err, base = np.array([r[0] for r in kept]), np.array([r[1] for r in kept])
    print(f"{args.adaptation} adaptation, ideal gain from {args.ideal}: {len(kept)} of {len(jobs)} episodes kept")
    for k, name in enumerate(C.JOINT_KINDS):
        print(f"  {name}: mean |log(g / g_ideal)| {err[:, k::3].mean():.3f}   (gain 1: {base[:, k::3].mean():.3f})")


if __name__ == "__main__":
    main()
