"""Data for the learned strength estimator, and its fit: ``python -m agents.rl.strength_data``.

Runs the expert in the extreme world (``robust_extreme``'s three terrains) on training seeds, disjoint from every
validation and held-out set, with a fixed gain per joint on its torque drawn around the ideal one, and records the
joint statistics of :mod:`agents.rl.strength_estimator` with the effective strength relative to the load,
``s g m0 / m``, they should reveal. Fits the estimator on four fifths of the seeds, reports it on the last fifth,
then fits it on all and writes it (by default over the shipped one).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from agents.rl.gain_adaptation import GAIN_BOUNDS, START_TIME
from agents.rl.strength_estimator import (
    DEFAULT_ESTIMATOR,
    FEATURE_NAMES,
    JOINT_KIND,
    WARMUP,
    JointStatistics,
    fit_estimator,
)
from quad_uneven_env import constants as C


class FixedGainRecorder:
    """Data collection: fixed gains on the expert's torques (set after each reset), and the features of every
    ``stride``-th control step from ``START_TIME + WARMUP`` on (the interface of :class:`LearnedGainAdaptation`)."""

    def __init__(self, period: float, stride: int = 5) -> None:
        self.stats = JointStatistics(period)
        self.period, self.stride = self.stats.period, int(stride)
        self.gain = np.ones(C.N_JOINTS)
        self.samples: list[np.ndarray] = []

    def reset(self) -> None:
        """No history, no samples; the gains are left as they are (the caller sets them)."""
        self.stats.reset()
        self.samples = []

    def update(self, joint_pos_error: np.ndarray, expert_torque: np.ndarray, time_since_reset: float) -> None:
        """One control step (see :meth:`LearnedGainAdaptation.update`); the gains do not move."""
        if time_since_reset < START_TIME:
            return
        self.stats.update(joint_pos_error, expert_torque)
        if time_since_reset >= START_TIME + WARMUP and self.stats.count % self.stride == 0:
            self.samples.append(self.stats.features())


ENTRIES = {
    "rough": {"kind": "rough", "amplitude": 0.05, "wavelength": 0.6},
    "stairs_up": {"kind": "stairs", "direction": "up", "riser": 0.08, "tread": 0.3, "n_steps": 5},
    "stairs_down": {"kind": "stairs", "direction": "down", "riser": 0.08, "tread": 0.3, "n_steps": 5},
}
"""robust_extreme's terrain entries (the data's terrains)."""

GAIN_SPREAD = 0.15
"""Standard deviation of the log-gain noise of the data's gains (see :func:`collect_episode`)."""

FALL_MARGIN = 1.0
"""s of samples dropped before a fall (the last moments of a fall are not a joint's ordinary tracking)."""


def collect_episode(job: tuple[str, int, float]) -> tuple[np.ndarray, np.ndarray]:
    """One episode of the expert in the extreme world with fixed gains drawn around (m / m0) / s:
    log g = lam log((m / m0) / s) + n, lam ~ U(0, 1.2) per episode (from the expert's own torques, lam = 0, to past
    the correction, lam = 1.2) and n ~ N(0, :data:`GAIN_SPREAD`) per joint.

    :param job: (entry of :data:`ENTRIES`, seed, simulated seconds).
    :return: features (K, 12, F) and targets log(s g m0 / m) (12,), with m the drawn robot's mass and m0 the
        nominal one.
    """
    import gymnasium as gym

    import quad_uneven_env  # noqa: F401  (registers QuadUneven-v0)
    from agents.expert import ExpertPolicy
    from agents.rl.residual_env import ResidualController

    entry, seed, seconds = job
    env = gym.make("QuadUneven-v0", terrain=ENTRIES[entry], randomization="extreme", max_episode_steps=10**6)
    base = env.unwrapped
    recorder = FixedGainRecorder(base.dt)
    controller = ResidualController(
        ExpertPolicy(env), base.idx.torque_limit, update_period=base.dt, adaptation=recorder
    )
    base.set_controller(controller)
    nominal_mass = float(base.model.body_subtreemass[base.idx.trunk_body])  # before the first draw
    env.reset(seed=seed)
    strength = base.episode_draw.motor_strength.copy()
    load = base.episode_draw.total_mass / nominal_mass
    rng = np.random.default_rng([seed, list(ENTRIES).index(entry), 7])
    lam = rng.uniform(0.0, 1.2)
    log_gain = lam * np.log(load / strength) + rng.normal(0.0, GAIN_SPREAD, 12)
    recorder.gain[:] = np.exp(np.clip(log_gain, *np.log(GAIN_BOUNDS)))
    zero = np.zeros(base.action_space.shape)
    fell = False
    for _ in range(round(seconds / base.dt)):
        _, _, terminated, truncated, _ = env.step(zero)
        if terminated or truncated:
            fell = terminated
            break
    env.close()
    samples = recorder.samples
    if fell:
        samples = samples[: max(0, len(samples) - round(FALL_MARGIN / (base.dt * recorder.stride)))]
    features = np.array(samples).reshape(-1, C.N_JOINTS, len(FEATURE_NAMES))
    return features, np.log(strength * recorder.gain / load)


def _seeds(text: str) -> list[int]:
    first, _, last = text.partition("-")
    try:
        return list(range(int(first), int(last or first) + 1))
    except ValueError:
        raise SystemExit(f"--seeds must be FIRST-LAST (integers), got {text!r}") from None


def main(argv: list[str] | None = None) -> None:
    """Collect episodes on training seeds, fit the estimator on some and report it on the others, save it."""
    from multiprocessing import get_context

    from tqdm import tqdm

    ap = argparse.ArgumentParser(description="Fit the learned strength estimator (docs/rl.md).")
    ap.add_argument("--seeds", default="1000-1199", help="FIRST-LAST: world seeds per terrain entry (training)")
    ap.add_argument("--test-every", type=int, default=5, help="every N-th seed is held out to report the fit")
    ap.add_argument("--seconds", type=float, default=10.0, help="simulated s per episode")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", type=Path, default=DEFAULT_ESTIMATOR)
    ap.add_argument("--data", type=Path, default=None, help="also save the samples (npz) here")
    args = ap.parse_args(argv)
    seeds = _seeds(args.seeds)
    jobs = [(entry, seed, args.seconds) for seed in seeds for entry in ENTRIES]
    t0 = time.perf_counter()
    with get_context("spawn").Pool(args.workers) as pool:
        results = list(tqdm(pool.imap(collect_episode, jobs), total=len(jobs), desc="episodes"))
    feats, targets, kinds, tests, groups = [], [], [], [], []
    for i, ((_, seed, _), (f, y)) in enumerate(zip(jobs, results, strict=True)):
        for j in range(C.N_JOINTS):
            feats.append(f[:, j])
            targets.append(np.full(len(f), y[j]))
            kinds.append(np.full(len(f), JOINT_KIND[j]))
            tests.append(np.full(len(f), seed % args.test_every == 0))
            groups.append(np.full(len(f), i))
    x, y, k = np.concatenate(feats), np.concatenate(targets), np.concatenate(kinds)
    test, group = np.concatenate(tests), np.concatenate(groups)
    if args.data is not None:
        np.savez(args.data, features=x, target=y, kind=k, test=test, episode=group)
    est = fit_estimator(x[~test], y[~test], k[~test])
    pred = est.predict_kind(x[test], k[test])
    report = {"episodes": len(jobs), "samples": len(y), "minutes": (time.perf_counter() - t0) / 60}
    for kind, name in enumerate(C.JOINT_KINDS):
        m = test & (k == kind)
        slope = x[m, FEATURE_NAMES.index("slope_0.5s")]
        report[name] = {
            "held-out corr(estimate, target)": float(np.corrcoef(pred[k[test] == kind], y[m])[0, 1]),
            "held-out corr(slope 0.5 s, target)": float(np.corrcoef(slope, y[m])[0, 1]),
            "held-out rms error": float(np.sqrt(np.mean((pred[k[test] == kind] - y[m]) ** 2))),
        }
    est = fit_estimator(x, y, k)
    est.save(args.out)
    print(json.dumps(report, indent=1))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
