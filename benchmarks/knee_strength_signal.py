"""Diagnostic: which joints' tracking error tells how strong their motor is (the signal of the knee adaptation).

Runs the expert alone in the extreme world (robust_extreme's terrains) and, per joint, forms the running
regression slope of its tracking error on its load, B / A with A = mean(u^2), B = mean(u e) over a window of
``--window`` s (u: the expert's torque over the torque limit, e: planned minus measured angle, once per control
step), the quantity ``agents.control.adaptation.knee`` integrates. Prints, per joint type, the correlation of that
slope (from 2 s into each episode on) with the strength drawn for the joint's motor, and the least-squares line
strength ~ w0 + w1 x slope: a joint type whose correlation is near 0 gives the adaptation nothing to follow.

Usage: ``python benchmarks/knee_strength_signal.py [--seeds 0-19] [--seconds 8] [--window 2]``.
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np
from stance_torque_boost import ENTRIES

import quad_uneven_env  # noqa: F401  (registers QuadUneven-v0)
from agents.expert import ExpertConfig, attach_expert
from agents.rl.expert_features import EXPERT_FEATURE_FIELDS, expert_features
from quad_uneven_env import constants as C
from quad_uneven_env.observations import observation_structure

FEATURES = observation_structure(EXPERT_FEATURE_FIELDS)
JOINT_TYPES = {kind: list(range(i, C.N_JOINTS, len(C.JOINT_KINDS))) for i, kind in enumerate(C.JOINT_KINDS)}


def slopes(entry: str, seed: int, seconds: float, window: float) -> tuple[np.ndarray, np.ndarray]:
    """One expert episode: the per-joint slopes B / A at each control step from 2 s on (K, 12) and the drawn
    strengths (12,)."""
    env = gym.make("QuadUneven-v0", terrain=ENTRIES[entry], randomization="extreme", max_episode_steps=10**6)
    policy = attach_expert(env, ExpertConfig())
    base = env.unwrapped
    obs, _ = env.reset(seed=seed)
    w = base.dt / window
    a, b, out = np.zeros(12), np.zeros(12), []
    for k in range(round(seconds / base.dt)):
        obs, _, terminated, _, _ = env.step(policy.predict(obs)[0])
        f = expert_features(policy, base.data)
        e, u = f[FEATURES["expert_joint_pos_error"]], f[FEATURES["expert_torque"]]
        a += w * (u * u - a)
        b += w * (u * e - b)
        if (k + 1) * base.dt >= 2.0:
            out.append(b / (a + 1e-4))
        if terminated:
            break
    return np.array(out).reshape(-1, 12), base.episode_draw.motor_strength.copy()


def main() -> None:
    """Run the episodes and print the correlations."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0-19", help="first-last (inclusive), per terrain entry")
    ap.add_argument("--seconds", type=float, default=8.0, help="simulated seconds per episode")
    ap.add_argument("--window", type=float, default=2.0, help="s, time constant of the running means")
    args = ap.parse_args()
    first, last = (int(v) for v in args.seeds.split("-"))
    runs = []
    for entry in ENTRIES:
        for seed in range(first, last + 1):
            runs.append(slopes(entry, seed, args.seconds, args.window))
        print(f"{entry}: {last - first + 1} episodes", flush=True)
    print(f"{'joint type':<12} {'corr(slope, strength)':>22} {'w0':>7} {'w1':>7} {'samples':>8}")
    for name, joints in JOINT_TYPES.items():
        x = np.concatenate([s[:, j] for s, _ in runs for j in joints])
        y = np.concatenate([np.full(len(s), st[j]) for s, st in runs for j in joints])
        w1, w0 = np.polyfit(x, y, 1)
        print(f"{name:<12} {np.corrcoef(x, y)[0, 1]:>22.2f} {w0:>7.3f} {w1:>7.3f} {len(x):>8}")


if __name__ == "__main__":
    main()
