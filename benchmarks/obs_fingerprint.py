"""Fingerprint of QuadUneven-v0's observations and rewards under a fixed seed and fixed random actions.

Prints one SHA-256 per path of the physics loop (``torque`` and ``joint_pd`` action modes, the
physics-rate controller hook): run it on two checkouts to check that a change leaves the default env
bit-identical. Usage: ``python benchmarks/obs_fingerprint.py [--randomization PRESET] [--steps N]``.
"""

from __future__ import annotations

import argparse
import hashlib

import gymnasium as gym
import numpy as np

import quad_uneven_env  # noqa: F401  (registers QuadUneven-v0)


class JointPD:
    """A physics-rate PD controller about the joints' reset pose plus 20 N m per unit action."""

    def __init__(self) -> None:
        self.home = np.zeros(12)

    def reset(self, model, data, terrain) -> None:
        self.home = data.qpos[7:].copy()

    def __call__(self, model, data, action) -> np.ndarray:
        return -80.0 * (data.qpos[7:] - self.home) - 3.0 * data.qvel[6:] + 20.0 * action


def fingerprint(path: str, steps: int, randomization: str | None) -> str:
    """SHA-256 of every observation and reward of two seeded episodes (resetting after an episode ends)."""
    kwargs = {"controller": JointPD()} if path == "controller" else {"action_mode": path}
    if randomization is not None:  # not passed otherwise: the script also runs on checkouts without it
        kwargs["randomization"] = randomization
    env = gym.make("QuadUneven-v0", **kwargs)
    rng = np.random.default_rng(1234)
    h = hashlib.sha256()
    for seed in (7, 8):
        obs, _ = env.reset(seed=seed)
        h.update(obs.tobytes())
        for _ in range(steps):
            obs, reward, terminated, truncated, _ = env.step(rng.uniform(-0.3, 0.3, 12).astype(np.float32))
            h.update(obs.tobytes())
            h.update(np.float64(reward).tobytes())
            if terminated or truncated:
                obs, _ = env.reset()
                h.update(obs.tobytes())
    return h.hexdigest()


def main(argv: list[str] | None = None) -> None:
    """Print the fingerprints."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=150, help="control steps per episode")
    parser.add_argument("--randomization", default=None, help="a randomization preset (default: none)")
    args = parser.parse_args(argv)
    for path in ("torque", "joint_pd", "controller"):
        print(f"{path:10s} {fingerprint(path, args.steps, args.randomization)}")


if __name__ == "__main__":
    main()
