"""Diagnostic: can a torque residual help the expert in the extreme world at all?

A fixed, hand-made residual: the expert's own torque times ``gain - 1`` on the legs whose foot touches the
ground (the contact switches, every physics step), zero on swinging legs; ``--gain-hind`` gives the hind
legs (LH, RH) their own gain. Run on one terrain of the ``robust_extreme`` suite with chosen seeds, it tells
whether the residual space holds a policy better than the expert (run 5's additive residual did not find one;
run 6 starts from gain 1.3; docs/rl.md compares fixed gains on validation seeds 200-219). ``--gain 1`` is the
expert alone and reproduces the suite's episodes (same seeds, same worlds).

Usage: ``python benchmarks/stance_torque_boost.py --gain 1.3 [--gain-hind 1.15] [--entry stairs_up]
[--seeds 100-119]``, or on another suite's entry (its world, goal and time limit): ``--suite targets --entry 5
--seeds 0-9``. ``--oracle all`` (or ``knee``) replaces the fixed gain by an oracle that knows the drawn world:
every joint's (or every knee's) torque, on every leg, divided by the strength drawn for its motor, the
correction a residual could at best learn for the motors (docs/rl.md, run 7).
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np

import quad_uneven_env  # noqa: F401  (registers QuadUneven-v0)
from agents.control.adaptation.knee import KNEE_JOINTS
from agents.evaluation.suites import load_suite
from agents.expert import ExpertConfig, attach_expert

ENTRIES = {
    "rough": {"kind": "rough", "amplitude": 0.05, "wavelength": 0.6},
    "stairs_up": {"kind": "stairs", "direction": "up", "riser": 0.08, "tread": 0.3, "n_steps": 5},
    "stairs_down": {"kind": "stairs", "direction": "down", "riser": 0.08, "tread": 0.3, "n_steps": 5},
}
"""robust_extreme's terrain entries."""


class StanceTorqueBoost:
    """Physics-rate controller: the expert's torques (N m) times ``gain`` on the legs whose foot touches
    (``gain``: a number, or one per joint (12,))."""

    def __init__(self, expert, foot_sensor_adr: np.ndarray, gain: float | np.ndarray) -> None:
        self.expert, self.adr, self.gain = expert, np.asarray(foot_sensor_adr), np.broadcast_to(gain, (12,))

    def reset(self, model, data, terrain) -> None:
        self.expert.reset(model, data, terrain)

    def __call__(self, model, data, action) -> np.ndarray:
        tau = self.expert(model, data, action).copy()
        stance = np.repeat(data.sensordata[self.adr] > 0.0, 3)
        tau[stance] *= self.gain[stance]
        return tau  # the env clips to the motor limits


class InverseStrength:
    """Physics-rate controller (an oracle): the expert's torques (N m) divided by the drawn strength of each motor
    in ``joints`` (12 joint indices or fewer), on every leg; the strengths are read from the env at each reset."""

    def __init__(self, expert, env, joints: np.ndarray) -> None:
        self.expert, self.env, self.joints = expert, env, np.asarray(joints)
        self.gain = np.ones(12)

    def reset(self, model, data, terrain) -> None:
        self.expert.reset(model, data, terrain)
        self.gain = np.ones(12)
        self.gain[self.joints] = 1.0 / self.env.episode_draw.motor_strength[self.joints]

    def __call__(self, model, data, action) -> np.ndarray:
        return self.expert(model, data, action) * self.gain


ORACLE_JOINTS = {"all": np.arange(12), "knee": KNEE_JOINTS}
"""--oracle choices: the joints whose motor strength the oracle undoes."""


def episode(
    terrain: dict,
    seed: int,
    gain: float | np.ndarray,
    goal: float = 3.0,
    time_limit: float = 90.0,
    randomization: str = "extreme",
    oracle: str | None = None,
) -> tuple[str, float]:
    """One episode (robust_extreme's world by default): ("goal" | "fall" | "stall", distance in m).

    :param oracle: None (the fixed ``gain`` on stance legs), or a key of :data:`ORACLE_JOINTS`.
    """
    env = gym.make("QuadUneven-v0", terrain=terrain, randomization=randomization, max_episode_steps=10**6)
    policy = attach_expert(env, ExpertConfig())
    base = env.unwrapped
    if oracle is None:
        base.set_controller(StanceTorqueBoost(policy, base.idx.foot_sensor_adr, gain))
    else:
        base.set_controller(InverseStrength(policy, base, ORACLE_JOINTS[oracle]))
    obs, _ = env.reset(seed=seed)
    info = {"distance": 0.0}
    for _ in range(round(time_limit / base.dt)):
        obs, _, terminated, _, info = env.step(policy.predict(obs)[0])
        if info["distance"] >= goal:
            return "goal", float(info["distance"])
        if terminated:
            return "fall", float(info["distance"])
    return "stall", float(info["distance"])


def main() -> None:
    """Run every seed and print one line each, then the counts."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--gain", type=float, default=1.3, help="stance-leg torque factor (1: the expert alone)")
    ap.add_argument("--gain-hind", type=float, default=None, help="the hind legs' factor (default: --gain)")
    ap.add_argument("--entry", default="stairs_up", help=f"one of {sorted(ENTRIES)}, or an entry index with --suite")
    ap.add_argument("--suite", default=None, help="a suite name: --entry is then the index of its terrain entry")
    ap.add_argument("--seeds", default="100-119", help="first-last (inclusive)")
    ap.add_argument(
        "--oracle", choices=sorted(ORACLE_JOINTS), default=None, help="undo the drawn motor strengths instead of --gain"
    )
    args = ap.parse_args()
    first, last = (int(v) for v in args.seeds.split("-"))
    if args.suite is None:
        if args.entry not in ENTRIES:
            ap.error(f"--entry must be one of {sorted(ENTRIES)} without --suite, got {args.entry!r}")
        terrain, world = ENTRIES[args.entry], dict(randomization="extreme")
    else:
        suite = load_suite(args.suite)
        try:
            entry = suite.terrains[int(args.entry)]
        except (ValueError, IndexError):
            ap.error(f"--entry must be an index in 0..{len(suite.terrains) - 1} with --suite, got {args.entry!r}")
        terrain = {"kind": entry.kind, **entry.params}
        world = dict(goal=suite.goal_distance, time_limit=suite.time_limit, randomization=entry.randomization)
    hind = args.gain if args.gain_hind is None else args.gain_hind
    gain = np.repeat([args.gain, args.gain, hind, hind], 3)  # LF, RF, LH, RH
    label = f"gain {args.gain:g}" + ("" if args.gain_hind is None else f" hind {hind:g}")
    if args.oracle is not None:
        label = f"oracle {args.oracle}"
    counts = {"goal": 0, "fall": 0, "stall": 0}
    for seed in range(first, last + 1):
        end, dist = episode(terrain, seed, gain, oracle=args.oracle, **world)
        counts[end] += 1
        print(f"{label} {args.entry} seed {seed}: {end} at {dist:.2f} m", flush=True)
    print(f"{label} {args.entry} seeds {args.seeds}: {counts}")


if __name__ == "__main__":
    main()
