"""How much action noise a trained network policy walks through: the start of a PPO fine-tuning.

PPO explores with Gaussian noise of std ``exp(log_std)`` around the policy's mean action. For a policy learned
by imitation (``models/distilled``) that noise is not part of what it learned; if its rollouts fall, PPO starts
from a policy that no longer walks. Each row runs the policy's mean action plus that noise (clipped to [-1, 1])
on one terrain for ``--episodes`` episodes of ``--steps`` control steps (20 ms), seeds 100, 101, ..., and prints
the steps survived, whether it fell and the distance walked (m). ``log_std`` -99 is the deterministic policy.

Usage: ``python benchmarks/policy_noise.py [--policy models/distilled/model.zip] [--log-stds -99,-1,-2,-3,-4,-5]
[--terrains 1,3] [--episodes 2] [--steps 1000]`` (``--terrains``: indices into the model's ``rl_meta.json``
terrain list; for ``models/distilled`` 1 is rough 4 cm, 3 stairs 8 cm up).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import torch

import quad_uneven_env  # noqa: F401  (registers QuadUneven-v0)
from agents.rl.model_io import load_sb3_policy, make_model_env


def main() -> None:
    """Print one line per (terrain, log std, episode)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--policy", default="models/distilled/model.zip")
    parser.add_argument("--log-stds", default="-99,-1,-2,-3,-4,-5")
    parser.add_argument("--terrains", default="1,3")
    parser.add_argument("--episodes", type=int, default=2)
    parser.add_argument("--steps", type=int, default=1000)
    args = parser.parse_args()
    torch.set_num_threads(1)
    meta = json.loads((Path(args.policy).parent / "rl_meta.json").read_text())
    terrains = meta["terrain"] if isinstance(meta["terrain"], list) else [meta["terrain"]]
    print("terrain  log_std  episode  steps  fell  distance_m")
    for t in (int(i) for i in args.terrains.split(",")):
        env = make_model_env(args.policy, terrain=terrains[t], max_episode_steps=args.steps)
        policy = load_sb3_policy(args.policy, env, meta.get("algo", "ppo"))
        for log_std in (float(x) for x in args.log_stds.split(",")):
            rng = np.random.default_rng(0)
            for episode in range(args.episodes):
                obs, _ = env.reset(seed=100 + episode)
                x0, steps, fell = float(env.unwrapped.data.qpos[0]), 0, False
                while True:
                    action, _ = policy.predict(obs, deterministic=True)
                    if log_std > -50:
                        action = np.clip(action + np.exp(log_std) * rng.standard_normal(action.shape), -1.0, 1.0)
                    obs, _, fell, truncated, _ = env.step(action)
                    steps += 1
                    if fell or truncated:
                        break
                distance = float(env.unwrapped.data.qpos[0]) - x0
                print(f"{t:7d}  {log_std:7.1f}  {episode:7d}  {steps:5d}  {int(fell):4d}  {distance:10.2f}")
        env.close()


if __name__ == "__main__":
    main()
