"""Data for the learned strength estimator of ``ExpertConfig(adaptation="learned")``, and its fit
(``quad-uneven fit-strength``).

Runs the expert in the extreme world (``robust_extreme``'s three terrains) on training seeds, disjoint from every
validation and held-out set, with a fixed gain per joint on its torque drawn around the ideal one, and records the
joint statistics of :mod:`agents.control.adaptation.learned` with the effective strength relative to the load,
``s g m0 / m``, they should reveal. Fits the estimator (a supervised MLP, torch) on four fifths of the seeds,
reports it on the last fifth, then fits it on all and writes it (by default over the shipped package data).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from agents.control.adaptation.knee import GAIN_BOUNDS, START_TIME
from agents.control.adaptation.learned import (
    DEFAULT_ESTIMATOR,
    FEATURE_NAMES,
    JOINT_KIND,
    N_KINDS,
    WARMUP,
    JointStatistics,
    StrengthEstimator,
)
from quad_uneven_env import constants as C
from quad_uneven_env.fields import excerpt


class FixedGainRecorder:
    """Data collection: fixed gains on the expert's torques (set after each reset), and the features of every
    ``stride``-th control step from ``START_TIME + WARMUP`` on (the interface of
    :class:`~agents.control.adaptation.learned.LearnedGainAdaptation`)."""

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
        """One control step (see :meth:`~agents.control.adaptation.learned.LearnedGainAdaptation.update`); the gains
        do not move."""
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
    from agents.control.adaptation import AdaptiveGains
    from agents.expert import attach_expert

    entry, seed, seconds = job
    env = gym.make("QuadUneven-v0", terrain=ENTRIES[entry], randomization="extreme", max_episode_steps=10**6)
    base = env.unwrapped
    recorder = FixedGainRecorder(base.dt)
    expert = attach_expert(env)
    expert.adaptation = AdaptiveGains(recorder, base.idx.torque_limit)  # its gains on the expert's torques
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


def parse_seeds(text: str) -> list[int]:
    """``"FIRST-LAST"`` (inclusive) or ``"SEED"`` as a list of seeds.

    :raises ValueError: naming ``--seeds`` and the accepted form.
    """
    first, _, last = str(text).partition("-")
    try:
        seeds = list(range(int(first), int(last or first) + 1))
    except ValueError:
        seeds = []
    if not seeds:
        raise ValueError(f"--seeds must be FIRST-LAST with FIRST <= LAST (integers), got {excerpt(text)}")
    return seeds


def collect(seeds: list[int], seconds: float, workers: int, test_every: int) -> dict[str, np.ndarray]:
    """Every entry x seed episode (:func:`collect_episode`, ``workers`` processes, a progress bar), flattened to one
    row per joint and sample: ``features`` (N, F), ``target``, ``kind``, ``test`` (the seed is a multiple of
    ``test_every``) and ``episode`` (N,)."""
    from multiprocessing import get_context

    from tqdm import tqdm

    jobs = [(entry, seed, seconds) for seed in seeds for entry in ENTRIES]
    with get_context("spawn").Pool(workers) as pool:
        results = list(tqdm(pool.imap(collect_episode, jobs), total=len(jobs), desc="episodes"))
    rows: dict[str, list[np.ndarray]] = {"features": [], "target": [], "kind": [], "test": [], "episode": []}
    for i, ((_, seed, _), (f, y)) in enumerate(zip(jobs, results, strict=True)):
        for j in range(C.N_JOINTS):
            rows["features"].append(f[:, j])
            rows["target"].append(np.full(len(f), y[j]))
            rows["kind"].append(np.full(len(f), JOINT_KIND[j]))
            rows["test"].append(np.full(len(f), seed % test_every == 0))
            rows["episode"].append(np.full(len(f), i))
    return {name: np.concatenate(parts) for name, parts in rows.items()}


def plot_fit(target: np.ndarray, estimate: np.ndarray, kind: np.ndarray, path: Path) -> None:
    """Held-out estimate against target, one panel per joint kind, written to ``path`` (png)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(C.JOINT_KINDS), figsize=(12, 4), sharex=True, sharey=True)
    for k, (ax, name) in enumerate(zip(axes, C.JOINT_KINDS, strict=True)):
        m = kind == k
        ax.hexbin(target[m], estimate[m], gridsize=40, mincnt=1, cmap="viridis", bins="log")
        lo, hi = np.percentile(target, [0.5, 99.5])
        ax.plot([lo, hi], [lo, hi], "r--", lw=1)
        ax.set_title(f"{name}: corr {np.corrcoef(target[m], estimate[m])[0, 1]:.2f}")
        ax.set_xlabel("log(s g m0 / m), drawn")
    axes[0].set_ylabel("estimated")
    fig.suptitle("learned strength estimator on held-out training-world seeds")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)


def fit_estimator(
    features: np.ndarray,
    target: np.ndarray,
    kind: np.ndarray,
    hidden: tuple[int, ...] = (64, 64),
    epochs: int = 40,
    seed: int = 0,
) -> StrengthEstimator:
    """Fit the MLP by Adam on the squared error (torch, CPU, seeded; weight decay 1e-4, batches of 1024).

    :param features: (N, F) samples; ``target`` (N,) log(effective strength relative to the load); ``kind`` (N,)
        joint kind index.
    :param hidden: widths of the hidden layers.
    :param epochs: passes over the samples.
    """
    import torch

    if len(target) < 10 * features.shape[1]:
        raise ValueError(f"fit_estimator: {len(target)} samples are too few for {features.shape[1]} features")
    mean, scale = features.mean(axis=0), np.maximum(features.std(axis=0), 1e-9)
    x = np.concatenate([(features - mean) / scale, np.eye(N_KINDS)[kind]], axis=1)
    gen = torch.Generator().manual_seed(seed)
    torch.manual_seed(seed)
    sizes = (x.shape[1], *hidden, 1)
    layers: list[torch.nn.Module] = []
    for i in range(len(sizes) - 1):
        layers.append(torch.nn.Linear(sizes[i], sizes[i + 1]))
        if i < len(sizes) - 2:
            layers.append(torch.nn.Tanh())
    net = torch.nn.Sequential(*layers).double()
    opt = torch.optim.Adam(net.parameters(), lr=1e-3, weight_decay=1e-4)
    xt, yt = torch.from_numpy(x), torch.from_numpy(np.asarray(target, dtype=float))
    for _ in range(epochs):
        perm = torch.randperm(len(yt), generator=gen)
        for i in range(0, len(yt), 1024):
            batch = perm[i : i + 1024]
            loss = ((net(xt[batch])[:, 0] - yt[batch]) ** 2).mean()
            opt.zero_grad()
            loss.backward()
            opt.step()
    linear = [m for m in net if isinstance(m, torch.nn.Linear)]
    weights = tuple(m.weight.detach().numpy().T.copy() for m in linear)
    biases = tuple(m.bias.detach().numpy().copy() for m in linear)
    return StrengthEstimator(mean, scale, weights, biases)


def fit_strength_estimator(
    seeds: list[int],
    seconds: float = 10.0,
    workers: int = 2,
    test_every: int = 5,
    out: Path = DEFAULT_ESTIMATOR,
    data: Path | None = None,
    from_data: Path | None = None,
    plot: Path | None = None,
) -> dict:
    """Collect (or read ``from_data``) the samples, fit on the seeds that are not multiples of ``test_every`` and
    report on those that are, then fit on all and write ``out``; ``data`` keeps the samples, ``plot`` draws the
    held-out fit (``quad-uneven fit-strength``).

    :return: the report: episodes, samples, per joint kind the held-out correlation, rms error and target std.
    """
    if workers < 1 or test_every < 2 or not seconds > START_TIME + WARMUP:
        raise ValueError(
            f"workers must be >= 1, test_every >= 2 and seconds > {START_TIME + WARMUP:g}, got {workers}, "
            f"{test_every} and {excerpt(seconds)}"
        )
    t0 = time.perf_counter()
    if from_data is not None:
        try:
            with np.load(from_data, allow_pickle=False) as f:
                samples = {name: f[name] for name in ("features", "target", "kind", "test", "episode")}
        except (OSError, KeyError, ValueError) as err:
            raise ValueError(f"--from-data {from_data}: not samples written by --data ({err})") from None
    else:
        samples = collect(seeds, seconds, workers, test_every)
    if data is not None:
        np.savez(data, **samples)
    x, y, k, test = samples["features"], samples["target"], samples["kind"], samples["test"]
    est = fit_estimator(x[~test], y[~test], k[~test])
    pred = est.predict_kind(x[test], k[test])
    report: dict = {"episodes": len(np.unique(samples["episode"])), "samples": len(y)}
    for kind, name in enumerate(C.JOINT_KINDS):
        m = test & (k == kind)
        slope = x[m, FEATURE_NAMES.index("slope_0.5s")]
        report[name] = {
            "held-out corr(estimate, target)": float(np.corrcoef(pred[k[test] == kind], y[m])[0, 1]),
            "held-out corr(slope 0.5 s, target)": float(np.corrcoef(slope, y[m])[0, 1]),
            "held-out rms error": float(np.sqrt(np.mean((pred[k[test] == kind] - y[m]) ** 2))),
            "target std": float(y[m].std()),
        }
    if plot is not None:
        plot_fit(y[test], pred, k[test], plot)
    fit_estimator(x, y, k).save(out)
    report["minutes"] = (time.perf_counter() - t0) / 60
    return report
