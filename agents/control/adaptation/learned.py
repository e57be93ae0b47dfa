"""A learned estimate of each motor's strength from how its joint tracks, driving adaptive gains on the expert.

The hand-made knee law (:mod:`agents.control.adaptation.knee`) drives one statistic, the slope of a knee's tracking
error on its load, to zero. This module learns the map instead, by supervision on worlds whose motors are known
(the second phase of RMA, Kumar et al. 2021: a student that infers the privileged parameters from the recent
history of the robot's own signals). Per joint, running means of its load u (the expert's torque over the torque
limit), its tracking error e (planned minus measured angle, rad) and their products over two time constants give
:data:`FEATURE_NAMES`; a small MLP shared by the joints (their kind, HAA, HFE or KFE, one of its inputs) maps
them to ``log(s g m0 / m)``, the log of the joint's *effective* strength: its motor's strength s times the gain g
the adaptation currently puts on the expert's torque, relative to the load, the robot's mass m over the mass m0
of the expert's model (a stance joint carries a share of the weight, and the expert's torques are sized for m0).
Learning the effective strength, not s, keeps the estimate right while the gain moves, and makes the adaptation
law an integrator with its fixed point at ``g = (m / m0) / s``:

    log g <- clip(log g - k dt log(s g m0 / m)_estimated, log g_min, log g_max)

The gains multiply the expert's joint torques (``ExpertConfig(adaptation="learned")``). The estimator is fitted
on episodes run with a fixed gain per joint drawn around the ideal one (``quad-uneven fit-strength``,
:mod:`agents.rl.strength_fit`), on seeds disjoint from every validation and held-out set. Its parameters ship as
package data, a plain ``.npz`` (no pickled objects).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from agents.control.adaptation.knee import EPS, GAIN_BOUNDS, START_TIME
from quad_uneven_env import constants as C
from quad_uneven_env.fields import excerpt

TIME_CONSTANTS = (0.5, 2.0)
"""s: time constants of the running means (a short window that follows a change, a long one that averages)."""

STAT_NAMES = ("slope", "mean_e", "mean_u", "rms_u", "rms_e")
"""Per time constant: B / (A + eps) with A = mean(u^2), B = mean(u e) (rad); mean(e) (rad); mean(u) (-);
sqrt(A) (-); sqrt(mean(e^2)) (rad)."""

_OWN = tuple(f"{name}_{t:g}s" for t in TIME_CONSTANTS for name in STAT_NAMES)
FEATURE_NAMES = _OWN + tuple(f"joint_mean_{name}" for name in _OWN)
"""The estimator's inputs per joint, in order: the joint's own statistics, then their means over the twelve joints
(what the whole body does: a heavier trunk loads every stance joint). The gain itself is not one: the data's gains
are drawn from the strengths, so it would leak them."""

N_KINDS = len(C.JOINT_KINDS)
JOINT_KIND = np.arange(C.N_JOINTS) % N_KINDS
"""(12,) index into :data:`quad_uneven_env.constants.JOINT_KINDS` of each joint (HAA 0, HFE 1, KFE 2)."""

ADAPTATION_RATE = 0.5
"""k (1/s): rate of the log-gain integrator (a 2 s time constant, the long window's)."""

DEFAULT_ESTIMATOR = Path(__file__).resolve().parent / "data" / "strength_estimator.npz"
"""The shipped estimator (fitted by ``quad-uneven fit-strength``)."""

WARMUP = 1.0
"""s of statistics after :data:`~agents.control.adaptation.knee.START_TIME` before the gains move."""


class JointStatistics:
    """Running means of every joint's load and tracking error over :data:`TIME_CONSTANTS` (bias-corrected, as
    Adam's moments, so they are means of what was seen from the first update on).

    :param period: s between two updates (the control step).
    """

    def __init__(self, period: float) -> None:
        if not period > 0.0:
            raise ValueError(f"period must be a positive number of seconds, got {excerpt(period)}")
        self.period = float(period)
        self._w = np.array([min(1.0, period / t) for t in TIME_CONSTANTS])[:, None]
        self._m = np.zeros((len(TIME_CONSTANTS), 5, C.N_JOINTS))  # u^2, u e, e, u, e^2
        self._decay = np.ones((len(TIME_CONSTANTS), 1))  # (1 - w)^n: the bias correction
        self.count = 0

    def reset(self) -> None:
        """No history (a new episode)."""
        self._m[:] = 0.0
        self._decay[:] = 1.0
        self.count = 0

    def update(self, joint_pos_error: np.ndarray, load: np.ndarray) -> None:
        """Add one control step: ``joint_pos_error`` (12,) rad, ``load`` (12,) the expert's torque / limit."""
        e = np.asarray(joint_pos_error, dtype=float)
        u = np.asarray(load, dtype=float)
        x = np.stack([u * u, u * e, e, u, e * e])
        self._m += self._w[:, :, None] * (x[None] - self._m)
        self._decay *= 1.0 - self._w
        self.count += 1

    def features(self) -> np.ndarray:
        """(12, len(FEATURE_NAMES)): the statistics per joint (see :data:`STAT_NAMES`), then their joint means."""
        m = self._m / np.maximum(1.0 - self._decay, 1e-12)[:, :, None]
        uu, ue, e, u, ee = m[:, 0], m[:, 1], m[:, 2], m[:, 3], m[:, 4]
        stats = np.stack([ue / (uu + EPS), e, u, np.sqrt(uu), np.sqrt(np.maximum(ee, 0.0))], axis=1)
        own = stats.reshape(-1, C.N_JOINTS).T  # (12, T x 5), time constant major
        return np.concatenate([own, np.broadcast_to(own.mean(axis=0), own.shape)], axis=1)


@dataclass(frozen=True)
class StrengthEstimator:
    """A small MLP shared by the twelve joints, from a joint's :data:`FEATURE_NAMES` (standardised) and the one-hot
    of its kind to log(effective strength relative to the load): ``tanh`` hidden layers, a linear output.

    ``mean``, ``scale`` (F,): the standardisation; ``weights`` and ``biases``: one (n_in, n_out) matrix and (n_out,)
    vector per layer, the first with F + N_KINDS inputs, the last with one output.
    """

    mean: np.ndarray
    scale: np.ndarray
    weights: tuple[np.ndarray, ...]
    biases: tuple[np.ndarray, ...]

    def __post_init__(self) -> None:
        n_in = len(FEATURE_NAMES)
        for name in ("mean", "scale"):
            value = np.asarray(getattr(self, name), dtype=float)
            if value.shape != (n_in,) or not np.all(np.isfinite(value)):
                raise ValueError(f"strength estimator: {name} must be finite with shape ({n_in},), got {value.shape}")
        if np.any(np.asarray(self.scale) <= 0.0):
            raise ValueError("strength estimator: scale must be positive")
        if not self.weights or len(self.weights) != len(self.biases):
            raise ValueError("strength estimator: weights and biases must be one per layer (at least one)")
        width = n_in + N_KINDS
        for i, (w, b) in enumerate(zip(self.weights, self.biases, strict=True)):
            if w.ndim != 2 or w.shape[0] != width or b.shape != (w.shape[1],):
                raise ValueError(f"strength estimator: layer {i} must map {width} inputs, got {w.shape} and {b.shape}")
            if not (np.all(np.isfinite(w)) and np.all(np.isfinite(b))):
                raise ValueError(f"strength estimator: layer {i} must be finite")
            width = w.shape[1]
        if width != 1:
            raise ValueError(f"strength estimator: the last layer must have one output, got {width}")

    def predict_kind(self, features: np.ndarray, kind: np.ndarray) -> np.ndarray:
        """log(effective strength relative to the load) (N,) of N samples ``features`` (N, F) of joints of kind
        ``kind`` (N,)."""
        x = np.concatenate([(features - self.mean) / self.scale, np.eye(N_KINDS)[kind]], axis=1)
        for w, b in zip(self.weights[:-1], self.biases[:-1], strict=True):
            x = np.tanh(x @ w + b)
        return (x @ self.weights[-1] + self.biases[-1])[:, 0]

    def predict(self, features: np.ndarray) -> np.ndarray:
        """log(effective strength relative to the load) (12,) of the joints whose features are ``features`` (12, F)."""
        return self.predict_kind(features, JOINT_KIND)

    def save(self, path: Path) -> None:
        """Write the parameters as a plain ``.npz`` with the feature names."""
        path.parent.mkdir(parents=True, exist_ok=True)
        layers = {f"w{i}": w for i, w in enumerate(self.weights)} | {f"b{i}": b for i, b in enumerate(self.biases)}
        np.savez(path, mean=self.mean, scale=self.scale, feature_names=np.array(FEATURE_NAMES), **layers)

    @classmethod
    def load(cls, path: Path = DEFAULT_ESTIMATOR) -> StrengthEstimator:
        """Read an estimator written by :meth:`save` (no pickles).

        :raises ValueError: naming the file and what is wrong with it.
        """
        try:
            with np.load(path, allow_pickle=False) as f:
                names = tuple(str(n) for n in f["feature_names"])
                mean, scale = np.array(f["mean"], dtype=float), np.array(f["scale"], dtype=float)
                n_layers = sum(1 for k in f.files if k.startswith("w"))
                weights = tuple(np.array(f[f"w{i}"], dtype=float) for i in range(n_layers))
                biases = tuple(np.array(f[f"b{i}"], dtype=float) for i in range(n_layers))
        except (OSError, KeyError, ValueError) as err:
            raise ValueError(f"{path}: not a strength estimator ({err})") from None
        if names != FEATURE_NAMES:
            raise ValueError(f"{path}: feature_names must be {list(FEATURE_NAMES)}, got {list(names)}")
        return cls(mean, scale, weights, biases)


def estimator_digest(path: Path = DEFAULT_ESTIMATOR) -> str:
    """sha256 (hex) of the estimator file ``path``: recorded in a model's ``rl_meta.json`` so that a model is never
    evaluated with an estimator other than the one it was made with."""
    import hashlib

    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


class LearnedGainAdaptation:
    """Adaptive gains on all twelve of the expert's joint torques, driven by a :class:`StrengthEstimator`
    (the interface of :class:`~agents.control.adaptation.knee.KneeGainAdaptation`).

    :param period: s between two updates (the control step).
    :param estimator: the fitted estimator (default: the shipped one).
    """

    def __init__(self, period: float, estimator: StrengthEstimator | None = None) -> None:
        self.stats = JointStatistics(period)
        self.period = self.stats.period
        self.estimator = StrengthEstimator.load() if estimator is None else estimator
        self.gain = np.ones(C.N_JOINTS)
        """(12,) -, the gain per joint on the expert's torque."""
        self._log_bounds = np.log(GAIN_BOUNDS)

    def reset(self) -> None:
        """Back to gain 1 and no history."""
        self.gain[:] = 1.0
        self.stats.reset()

    def update(self, joint_pos_error: np.ndarray, expert_torque: np.ndarray, time_since_reset: float) -> None:
        """One control step: statistics, then the log-gain integrator (from :data:`WARMUP` s of statistics on).

        :param joint_pos_error: (12,) rad, planned minus measured joint angles.
        :param expert_torque: (12,) -, the expert's joint torques over the torque limit (before the gains).
        :param time_since_reset: s since the episode's reset (nothing before ``START_TIME``).
        """
        if time_since_reset < START_TIME:
            return
        self.stats.update(joint_pos_error, expert_torque)
        if time_since_reset < START_TIME + WARMUP:
            return
        log_effective = self.estimator.predict(self.stats.features())
        log_gain = np.log(self.gain) - ADAPTATION_RATE * self.period * np.nan_to_num(log_effective)
        self.gain[:] = np.exp(np.clip(log_gain, *self._log_bounds))


__all__ = [
    "ADAPTATION_RATE",
    "DEFAULT_ESTIMATOR",
    "FEATURE_NAMES",
    "JOINT_KIND",
    "N_KINDS",
    "STAT_NAMES",
    "TIME_CONSTANTS",
    "WARMUP",
    "JointStatistics",
    "LearnedGainAdaptation",
    "StrengthEstimator",
    "estimator_digest",
]
