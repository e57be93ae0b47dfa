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
import zlib
from pathlib import Path
from typing import Any

import numpy as np

from quad_uneven_env.fields import excerpt

STAT_KEYS = ("mean", "var", "epsilon", "clip")
"""The arrays of a statistics ``.npz`` (:meth:`ObsNormalization.save`)."""

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
    def load(cls, path: str | Path, shape: tuple[int, ...] | None = None) -> ObsNormalization:
        """Read statistics written by :meth:`save` (no pickles: a crafted file cannot run code).

        The file must hold exactly the arrays ``mean``, ``var`` (real, finite, 1-D, of one length; ``var >= 0``),
        ``epsilon`` and ``clip`` (real scalars, finite, > 0).

        :param shape: the observation's shape the statistics must have (None: not checked).
        :raises ValueError: naming the file and the array at fault.
        """
        where = f"observation statistics {str(path)!r}"
        try:
            loaded = np.load(Path(path), allow_pickle=False)
            if not isinstance(loaded, np.lib.npyio.NpzFile):  # a lone .npy array
                raise ValueError("not an .npz archive of named arrays")
            with loaded as z:
                arrays = {k: z[k] for k in z.files}
        except (OSError, KeyError, ValueError, EOFError, zipfile.BadZipFile, zlib.error, NotImplementedError,
                RuntimeError) as err:  # fmt: skip
            # a damaged or foreign file; ValueError also for a pickled (object) array, which is never loaded
            raise ValueError(f"{where} are unreadable: {err}") from None
        if sorted(arrays) != sorted(STAT_KEYS):
            raise ValueError(f"{where} must hold the arrays {list(STAT_KEYS)}, got {sorted(arrays)}")
        for key, a in arrays.items():
            if a.dtype.kind not in "iuf":
                raise ValueError(f"{where}: {key} must hold real numbers, got dtype {a.dtype}")
            if not np.isfinite(a).all():
                raise ValueError(f"{where}: {key} must be finite, got NaN or inf")
        mean, var = arrays["mean"].astype(float), arrays["var"].astype(float)
        if mean.ndim != 1 or var.shape != mean.shape:
            raise ValueError(f"{where}: mean and var must be 1-D of one length, got shapes {mean.shape}, {var.shape}")
        if (var < 0).any():
            raise ValueError(f"{where}: var must be >= 0")
        if shape is not None and mean.shape != tuple(shape):
            raise ValueError(
                f"{where}: mean and var must have the observation's shape {tuple(shape)}, got {mean.shape} "
                "(statistics of a model for another observation)"
            )
        for key in ("epsilon", "clip"):
            if arrays[key].shape != () or not arrays[key] > 0:
                raise ValueError(f"{where}: {key} must be a number > 0, got {excerpt(arrays[key])}")
        return cls(mean, var, float(arrays["epsilon"]), float(arrays["clip"]))


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


__all__ = ["NORM_SUFFIX", "STAT_KEYS", "ObsNormalization", "norm_path", "pickle_path"]
