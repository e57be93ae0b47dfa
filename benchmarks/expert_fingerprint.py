"""Fingerprint of the expert's trajectories: one SHA-256 per (robot, terrain, world, adaptation, path) walk.

Each walk resets ``QuadUneven-v0`` with a fixed seed, attaches the expert and takes ``--steps`` control steps,
hashing every qpos, qvel, ctrl, observation and reward. Run it on two checkouts to check that a change leaves the
expert's motion bit-identical; ``--tolerance`` instead prints the final qpos so two runs can be compared to a
tolerance where a floating-point reordering is expected.

Usage: ``python benchmarks/expert_fingerprint.py [--steps 300] [--quick]``
"""

from __future__ import annotations

import argparse
import hashlib
import itertools

import gymnasium as gym
import numpy as np

import quad_uneven_env  # noqa: F401  (registers QuadUneven-v0)
from agents.expert import ExpertConfig, attach_expert

ROBOTS = ("paper", "hyq", "anymal_c", "go1", "solo12")
TERRAINS = ("rough", "stairs_up", "stepping_stones", "slope")
WORLDS = (None, "hard")
ADAPTATIONS = ("none", "learned", "knee")


def walk(
    robot: str, terrain: str, world: str | None, adaptation: str, steps: int, readable: bool
) -> tuple[str, np.ndarray]:
    """SHA-256 of one seeded expert walk, and its final qpos."""
    env = gym.make("QuadUneven-v0", robot=robot, terrain=terrain, randomization=world)
    config = ExpertConfig.for_robot(env.unwrapped.robot)
    if adaptation != "none":
        config = config.replace(adaptation=adaptation) if hasattr(config, "replace") else _replace(config, adaptation)
    expert = attach_expert(env, config)
    if readable:
        expert.hook.compiled = False
    obs, _ = env.reset(seed=3)
    u = env.unwrapped
    h = hashlib.sha256(obs.tobytes())
    for _ in range(steps):
        action, _ = expert.predict(obs)
        obs, reward, terminated, truncated, _ = env.step(action)
        for a in (u.data.qpos, u.data.qvel, u.data.ctrl, obs, np.float64(reward)):
            h.update(np.ascontiguousarray(a).tobytes())
        if terminated or truncated:
            break
    qpos = u.data.qpos.copy()
    env.close()
    return h.hexdigest()[:16], qpos


def _replace(config: ExpertConfig, adaptation: str) -> ExpertConfig:
    import dataclasses

    return dataclasses.replace(config, adaptation=adaptation)


def main(argv: list[str] | None = None) -> None:
    """Print one fingerprint per walk."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=300, help="control steps per walk")
    parser.add_argument("--quick", action="store_true", help="rough terrain only, nominal world, no adaptation")
    parser.add_argument("--readable", action="store_true", help="the controller's readable call at every step")
    parser.add_argument("--qpos", action="store_true", help="print the final qpos too (for a tolerance check)")
    args = parser.parse_args(argv)
    cases = [
        (robot, terrain, world, adaptation)
        for robot, terrain, world, adaptation in itertools.product(ROBOTS, TERRAINS, WORLDS, ADAPTATIONS)
        if not args.quick or (terrain == "rough" and world is None and adaptation == "none")
        if adaptation == "none" or (terrain == "rough")
    ]
    for robot, terrain, world, adaptation in cases:
        digest, qpos = walk(robot, terrain, world, adaptation, args.steps, args.readable)
        line = f"{robot:9s} {terrain:10s} {world or 'nominal':8s} {adaptation:8s} {digest}"
        if args.qpos:
            line += " " + " ".join(f"{x:.17g}" for x in qpos)
        print(line, flush=True)


if __name__ == "__main__":
    main()
