"""Observation normalisation statistics as plain arrays: saved as ``.npz``, never as a pickle.

SB3's ``VecNormalize.save`` pickles the whole wrapper, and unpickling a downloaded file runs whatever
code it carries. A trained model's statistics are therefore written as an ``.npz`` of arrays
(loaded with ``allow_pickle=False``), and :class:`ObsNormalization` applies them exactly as
``VecNormalize.normalize_obs`` does: ``clip((obs - mean) / sqrt(var + epsilon), -clip, clip)``.
"""

from __future__ import annotations

import dataclasses
import re
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

NORM_SUFFIX = "_obs_norm.npz"
"""``X.zip`` -> ``X_obs_norm.npz``; an SB3 checkpoint ``P_N_steps.zip`` -> ``P_obs_norm_N_steps.npz``."""


@dataclasses.dataclass(frozen=True)
class ObsNormalization:
    """Running observation statistics of a training run (float64 arrays of the observation's shape)."""

    mean: np.ndarray
    """per-entry running mean."""
    var: np.ndarray
    """per-entry running variance."""
    epsilon: float
    """added to ``var`` before the square root."""
    clip: float
    """normalised observations are clipped to [-clip, clip]."""

    def normalize(self, obs: np.ndarray) -> np.ndarray:
        """Normalised ``obs`` as float32 (what ``VecNormalize.normalize_obs`` returns)."""
        out = np.clip((np.asarray(obs) - self.mean) / np.sqrt(self.var + self.epsilon), -self.clip, self.clip)
        return out.astype(np.float32)

    @classmethod
    def from_vecnormalize(cls, vn: Any) -> ObsNormalization:
        """The statistics of an SB3 ``VecNormalize`` (Box observations)."""
        rms = vn.obs_rms
        mean, var = np.array(rms.mean, dtype=float), np.array(rms.var, dtype=float)
        return cls(mean, var, float(vn.epsilon), float(vn.clip_obs))

    def save(self, path: str | Path) -> Path:
        """Write the statistics to ``path`` (.npz)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        with path.open("wb") as f:
            np.savez(f, mean=self.mean, var=self.var, epsilon=self.epsilon, clip=self.clip)
        return path

    @classmethod
    def load(cls, path: str | Path) -> ObsNormalization:
        """Read statistics written by :meth:`save` (no pickles: a crafted file cannot run code).

        :raises ValueError: naming the file and what is wrong with it.
        """
        try:
            with np.load(Path(path), allow_pickle=False) as z:
                mean, var = np.asarray(z["mean"], dtype=float), np.asarray(z["var"], dtype=float)
                epsilon, clip = float(z["epsilon"]), float(z["clip"])
        except (OSError, KeyError, ValueError, EOFError, zipfile.BadZipFile) as err:
            raise ValueError(f"observation statistics {str(path)!r} are unreadable: {err}") from None
        if mean.shape != var.shape or not (np.isfinite(mean).all() and np.isfinite(var).all() and (var >= 0).all()):
            raise ValueError(f"observation statistics {str(path)!r}: mean/var must be finite, var >= 0, same shape")
        if not (epsilon > 0 and clip > 0):
            raise ValueError(f"observation statistics {str(path)!r}: epsilon and clip must be > 0")
        return cls(mean, var, epsilon, clip)


def norm_path(model_path: str | Path) -> Path:
    """Where the statistics of ``model_path`` are written (:data:`NORM_SUFFIX`)."""
    p = Path(model_path)
    m = re.fullmatch(r"(.*)_(\d+)_steps", p.stem)
    if m:
        return p.with_name(f"{m[1]}_obs_norm_{m[2]}_steps.npz")
    return p.with_name(f"{p.stem}{NORM_SUFFIX}")


def pickle_path(model_path: str | Path) -> Path | None:
    """SB3's pickled VecNormalize next to ``model_path`` (older runs), if any."""
    p = Path(model_path)
    candidates = [p.with_name(f"{p.stem}_vecnormalize.pkl")]
    m = re.fullmatch(r"(.*)_(\d+)_steps", p.stem)
    if m:
        candidates.append(p.with_name(f"{m[1]}_vecnormalize_{m[2]}_steps.pkl"))
    return next((c for c in candidates if c.is_file()), None)


__all__ = ["NORM_SUFFIX", "ObsNormalization", "norm_path", "pickle_path"]
