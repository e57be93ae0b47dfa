"""Trained SB3 models on disk: the metadata ``quad-uneven train`` writes, and loading a model as a policy.

A training run writes ``DIR/rl_meta.json`` (and a copy in ``DIR/checkpoints/`` and ``DIR/best/``)::

    {"format": "quad-uneven-rl/1", "algo": "ppo", "residual": true, "residual_scale": 0.1,
     "env_id": "QuadUnevenResidual-v0", "env_kwargs": {...}, "normalize_obs": true, ...}

:func:`load_sb3_policy` reads it for a model ``.zip`` in the same folder: a residual model gets the
expert plus residual installed as the env's physics-rate controller (so ``quad-uneven evaluate`` runs
the expert in the loop), and observations are normalised with the saved VecNormalize statistics.
A model without metadata is loaded as a plain SB3 policy on the env as given.
"""

from __future__ import annotations

import json
import pickle
import re
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

META_FILE = "rl_meta.json"
"""Name of the metadata file next to the model(s) of a training run."""

META_FORMAT = "quad-uneven-rl/1"
"""Value of the metadata's ``format`` field."""


class ModelError(ValueError):
    """A model file, its metadata or its normalisation statistics cannot be used."""


def read_metadata(model_path: str | Path) -> dict[str, Any] | None:
    """The ``rl_meta.json`` next to ``model_path`` (None if there is none).

    :raises ModelError: if the file exists but is not valid metadata.
    """
    path = Path(model_path).parent / META_FILE
    if not path.is_file():
        return None
    try:
        meta = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as err:
        raise ModelError(f"{path}: unreadable metadata ({err})") from None
    if not isinstance(meta, dict) or meta.get("format") != META_FORMAT:
        raise ModelError(f"{path}: format must be {META_FORMAT!r}")
    return _check_metadata(meta, path)


def _check_metadata(meta: dict[str, Any], path: Path) -> dict[str, Any]:
    """``meta`` with the fields the evaluation uses checked (``algo``, ``residual``, ``residual_scale``, ...)."""
    from agents.rl.config import ALGOS

    if meta.get("algo") not in (None, *ALGOS):
        raise ModelError(f"{path}: algo must be one of {list(ALGOS)}, got {meta.get('algo')!r}")
    if not isinstance(meta.get("residual", False), bool):
        raise ModelError(f"{path}: residual must be true or false, got {meta.get('residual')!r}")
    if meta.get("residual"):
        scale = meta.get("residual_scale")
        if isinstance(scale, bool) or not isinstance(scale, int | float) or not 0.0 < scale <= 1.0:
            raise ModelError(
                f"{path}: residual_scale must be a number in (0, 1] (fraction of the torque limit) for a residual "
                f"model, got {scale!r}" + (" (missing)" if "residual_scale" not in meta else "")
            )
    env_kwargs = meta.get("env_kwargs")
    if env_kwargs is not None and not isinstance(env_kwargs, dict):
        raise ModelError(f"{path}: env_kwargs must be a mapping of QuadUneven-v0 arguments, got {env_kwargs!r}")
    if not isinstance(meta.get("normalize_obs", False), bool):
        raise ModelError(f"{path}: normalize_obs must be true or false, got {meta.get('normalize_obs')!r}")
    return meta


def write_metadata(folder: Path, meta: dict[str, Any]) -> Path:
    """Write ``meta`` (with ``format`` set) as ``folder/rl_meta.json``; :return: its path."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / META_FILE
    path.write_text(json.dumps({"format": META_FORMAT, **meta}, indent=2, allow_nan=False))
    return path


def vecnormalize_path(model_path: str | Path) -> Path | None:
    """The VecNormalize statistics saved with ``model_path``, if any.

    ``X.zip`` -> ``X_vecnormalize.pkl``; an SB3 checkpoint ``P_N_steps.zip`` -> ``P_vecnormalize_N_steps.pkl``.
    """
    p = Path(model_path)
    candidates = [p.with_name(f"{p.stem}_vecnormalize.pkl")]
    m = re.fullmatch(r"(.*)_(\d+)_steps", p.stem)
    if m:
        candidates.append(p.with_name(f"{m[1]}_vecnormalize_{m[2]}_steps.pkl"))
    return next((c for c in candidates if c.is_file()), None)


def metadata_env_kwargs(model_path: str | Path) -> dict[str, Any]:
    """QuadUneven-v0 arguments the model was trained with (``{}`` without metadata or model file)."""
    try:
        meta = read_metadata(model_path)
    except ModelError:
        return {}  # reported by load_sb3_policy
    if meta is None:
        return {}
    kwargs = dict(meta.get("env_kwargs") or {})
    if meta.get("residual"):
        kwargs["action_mode"] = "torque"
    return kwargs


class SB3Policy:
    """An SB3 model with its observation normalisation (and, for a residual model, the expert it rides on).

    :param model: the loaded SB3 algorithm.
    :param obs_normalizer: a VecNormalize whose ``normalize_obs`` is applied before ``model.predict``, or None.
    :param expert: the :class:`agents.expert.ExpertPolicy` in the loop of a residual model, or None.
    """

    def __init__(self, model: Any, obs_normalizer: Any = None, expert: Any = None) -> None:
        self.model = model
        self.obs_normalizer = obs_normalizer
        self.expert = expert

    @property
    def planner_times_ms(self) -> list[float] | None:
        """The expert's plan times (ms), for the evaluation record; None without an expert."""
        return None if self.expert is None else self.expert.planner_times_ms

    @property
    def failure_log(self) -> list[str] | None:
        """The expert's failure log; None without an expert."""
        return None if self.expert is None else self.expert.failure_log

    def predict(
        self,
        observation: np.ndarray,
        state: Any = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = True,
    ) -> tuple[np.ndarray, Any]:
        """SB3's predict on the (normalised) observation; :return: action in [-1, 1]^12 and the state."""
        obs = observation if self.obs_normalizer is None else self.obs_normalizer.normalize_obs(observation)
        return self.model.predict(obs, state=state, episode_start=episode_start, deterministic=deterministic)


def _load_normalizer(model_path: Path, meta: dict[str, Any] | None) -> Any:
    path = vecnormalize_path(model_path)
    if path is None:
        if meta is not None and meta.get("normalize_obs"):
            raise ModelError(
                f"policy: {model_path} was trained with normalised observations but "
                f"{model_path.stem}_vecnormalize.pkl is missing next to it"
            )
        return None
    try:
        with path.open("rb") as f:
            normalizer = pickle.load(f)  # our own file, written by VecNormalize.save
        normalizer.training = False
        norm_obs = normalizer.norm_obs
    except Exception as err:  # a truncated or foreign pickle raises anything from EOFError to AttributeError
        raise ModelError(
            f"policy: {path} is not readable VecNormalize statistics ({type(err).__name__}: {err})"
        ) from None
    return normalizer if norm_obs else None


def _load_model(path: Path, algo: str) -> Any:
    """``algo``'s ``load`` of ``path``, any failure of a corrupt or truncated file as a :class:`ModelError`."""
    import stable_baselines3

    try:
        return getattr(stable_baselines3, algo.upper()).load(path, device="cpu")
    except Exception as err:  # zipfile, pickle, torch and SB3 each raise their own types for a bad file
        msg = " ".join(str(err).split())[:200]
        raise ModelError(
            f"policy: {path} is not a readable SB3 {algo.upper()} model ({type(err).__name__}: {msg})"
        ) from None


def _describe(space: Any) -> str:
    shape = getattr(space, "shape", None)
    return f"{type(space).__name__} of shape {shape}" if space is not None else "none"


def check_spaces(model: Any, env: gym.Env, path: Path) -> None:
    """Refuse a model whose observation or action space is not ``env``'s (it was trained for another env).

    :raises ModelError: naming the space and both shapes (or that the bounds differ).
    """
    for name in ("observation_space", "action_space"):
        want, got = getattr(env, name), getattr(model, name, None)
        if got is None or type(got) is not type(want) or getattr(got, "shape", None) != want.shape:
            raise ModelError(
                f"policy: {path} was trained for another {name} ({_describe(got)}) than this env's "
                f"({_describe(want)}); evaluate it with the env kwargs it was trained with"
            )
        if isinstance(want, gym.spaces.Box) and not (
            np.array_equal(got.low, want.low) and np.array_equal(got.high, want.high)
        ):
            raise ModelError(
                f"policy: {path} was trained for an {name} with other bounds than this env's "
                f"({_describe(want)}); evaluate it with the env kwargs it was trained with"
            )


def load_sb3_policy(path: str | Path, env: gym.Env, algo: str) -> SB3Policy:
    """Load the SB3 model ``path`` as a policy for ``env`` (a ``QuadUneven-v0`` env, before ``reset``).

    With ``rl_meta.json`` saying ``residual``, installs the expert plus the residual
    (:func:`agents.rl.residual_env.install_residual_controller`) on ``env.unwrapped``.

    :param algo: ``"ppo"`` or ``"sac"``; must match the metadata's ``algo`` if there is one.
    :raises ModelError: on an algo mismatch, bad metadata, missing or unreadable normalisation statistics, a
        corrupt or truncated model file, or a model for another observation or action space.
    """
    path = Path(path)
    meta = read_metadata(path)
    if meta is not None and meta.get("algo") not in (None, algo):
        raise ModelError(f"algo: {path} was trained with {meta['algo']!r}; pass --algo {meta['algo']}, got {algo!r}")
    normalizer = _load_normalizer(path, meta)
    model = _load_model(path, algo)
    check_spaces(model, env, path)
    expert = None
    if meta is not None and meta.get("residual"):
        from agents.rl.residual_env import install_residual_controller

        expert, _ = install_residual_controller(env, float(meta["residual_scale"]))
    return SB3Policy(model, normalizer, expert)


__all__ = [
    "META_FILE",
    "META_FORMAT",
    "ModelError",
    "SB3Policy",
    "check_spaces",
    "load_sb3_policy",
    "metadata_env_kwargs",
    "read_metadata",
    "vecnormalize_path",
    "write_metadata",
]
