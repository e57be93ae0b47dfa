"""How deep feet and limbs sink into the height field under uniform random torques, per contact model.

For every model of ``env_throughput.CONTACT_VARIANTS`` and the current one: ``--steps`` env steps of
uniform random actions (torque mode, rough terrain, resets included) per seed; after each step the
true penetration of every foot, ``terrain.height(x, y) - (foot site z - foot radius)`` (m, the height
field's own surface, not MuJoCo's contact distance), and the contacts per step with the share whose
normal is within 60° of horizontal (|n_z| < 0.5: a prism's side wall rather than its top).

Usage: ``python benchmarks/contact_depth.py [--steps 1500] [--seeds 3]``. No assertions: the figures are
in docs/results.md section 7.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable

import gymnasium as gym
import mujoco
import numpy as np
from env_throughput import CONTACT_VARIANTS

import quad_uneven_env  # noqa: F401  (registers QuadUneven-v0)
from quad_uneven_env import constants as C


def measure_depth(steps: int, seed: int, setup: Callable[[gym.Env], None] | None) -> dict[str, np.ndarray | float]:
    """Foot penetrations (m, one per foot and step), contacts per step and the side-wall share of one run."""
    env = gym.make("QuadUneven-v0", terrain="rough")
    u = env.unwrapped
    if setup is not None:
        setup(env)
    m, d = u.model, u.data
    sites = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, C.foot_site(leg)) for leg in C.LEG_NAMES]
    radius = u.robot.foot_radius
    env.action_space.seed(seed)
    env.reset(seed=seed)
    depth, ncon, side = [], 0, 0
    for _ in range(steps):
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        p = d.site_xpos[sites]
        depth.append(u.terrain.height(p[:, 0], p[:, 1]) - (p[:, 2] - radius))
        ncon += d.ncon
        side += int(np.count_nonzero(np.abs(d.contact.frame[: d.ncon, 2]) < 0.5))
        if terminated or truncated:
            env.reset()
    env.close()
    return {"depth": np.concatenate(depth), "contacts": ncon / steps, "side": side / max(ncon, 1)}


def main(argv: list[str] | None = None) -> None:
    """Print one row per contact model."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=1500, help="env steps per seed")
    parser.add_argument("--seeds", type=int, default=3, help="seeds 0..K-1")
    args = parser.parse_args(argv)
    variants: dict[str, Callable[[gym.Env], None] | None] = {**CONTACT_VARIANTS, "current": None}
    print(f"uniform random torques on rough terrain, {args.steps} env steps x {args.seeds} seeds")
    print(
        f"{'contact model':40s} {'feet > 1 cm deep':>16s} {'> 2 cm':>7s} {'p99 depth mm':>12s} "
        f"{'max mm':>7s} {'contacts':>8s} {'side walls':>10s}"
    )
    for name, setup in variants.items():
        runs = [measure_depth(args.steps, s, setup) for s in range(args.seeds)]
        depth = np.concatenate([r["depth"] for r in runs])
        print(
            f"{name:40s} {np.mean(depth > 0.01):16.1%} {np.mean(depth > 0.02):7.1%} "
            f"{1e3 * np.percentile(depth, 99):12.1f} {1e3 * depth.max():7.1f} "
            f"{np.mean([r['contacts'] for r in runs]):8.1f} {np.mean([r['side'] for r in runs]):10.0%}"
        )


if __name__ == "__main__":
    main()
