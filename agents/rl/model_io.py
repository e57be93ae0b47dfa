"""Trained SB3 models on disk: the metadata ``quad-uneven train`` writes, and loading a model as a policy.

A training run writes ``DIR/rl_meta.json`` (and a copy in ``DIR/checkpoints/`` and ``DIR/best/``)::

    {"format": "quad-uneven-rl/1", "algo": "ppo", "residual": true, "residual_scale": 0.1,
     "expert": {"adaptation": "knee"}, "env_id": "QuadUnevenResidual-v0", "env_kwargs": {...},
     "normalize_obs": true, ...}

A residual model's ``residual_*``, ``expert_features`` and ``expert`` fields are its
:class:`~agents.rl.residual_env.ResidualConfig` (``expert``: the :class:`~agents.expert.ExpertConfig` fields that
differ from the defaults; with ``adaptation: learned`` also ``strength_estimator_sha256``, the estimator it was
made with). :func:`load_sb3_policy` reads it for a model ``.zip`` in the same folder: a residual model gets that
expert plus residual installed as the env's physics-rate controller (so ``quad-uneven evaluate`` runs
the expert in the loop), and observations are normalised with the saved statistics
(:mod:`agents.rl.normalization`). Nothing from the folder is unpickled unless the user opts in.
A model without metadata is loaded as a plain SB3 policy on the env as given.
"""

from __future__ import annotations

import collections
import json
import pickle
import zipfile
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from agents.rl.normalization import ObsNormalization, norm_path, pickle_path

META_FILE = "rl_meta.json"
"""Name of the metadata file next to the model(s) of a training run."""

META_FORMAT = "quad-uneven-rl/1"
"""Value of the metadata's ``format`` field."""

META_DEFAULTS: dict[str, Any] = {
    "residual_legs": "all",
    "residual_basis": "torque_limit",
    "expert_features": False,
    "expert": {},
    "env_kwargs": {},
}
"""Values of the fields a model's metadata may leave out."""

RESIDUAL_META_FIELDS = ("residual_scale", "residual_legs", "residual_basis", "expert_features", "expert")
"""The metadata fields of a residual model that make its :class:`~agents.rl.residual_env.ResidualConfig`."""

NOT_READ = {"gain_adaptation": "none", "adaptation_features": False}
"""Metadata fields this reader refuses unless they hold these values (which it can ignore): the adaptation is
the expert's (``expert: {adaptation: ...}``), and the adapted gains are no observation."""


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
    """``meta`` with the fields the evaluation uses checked (``algo``, ``residual``, the residual's config, ...)."""
    from agents.rl.config import ALGOS

    if meta.get("algo") not in (None, *ALGOS):
        raise ModelError(f"{path}: algo must be one of {list(ALGOS)}, got {meta.get('algo')!r}")
    if not isinstance(meta.get("residual", False), bool):
        raise ModelError(f"{path}: residual must be true or false, got {meta.get('residual')!r}")
    if meta.get("residual"):
        if "residual_scale" not in meta:
            raise ModelError(f"{path}: residual_scale is missing (a residual model needs a number in (0, 1])")
        for name, value in NOT_READ.items():
            if name in meta and meta[name] != value:
                raise ModelError(
                    f"{path}: {name} must be absent or {value!r}, got {meta[name]!r} (the expert's adaptation is "
                    "expert: {adaptation: ...})"
                )
        config = residual_config_of(meta, path)
        if config.expert.adaptation == "learned":
            from agents.control.adaptation.learned import DEFAULT_ESTIMATOR, estimator_digest

            digest = meta.get("strength_estimator_sha256")
            if digest != estimator_digest():
                raise ModelError(
                    f"{path}: strength_estimator_sha256 must be the sha256 of {DEFAULT_ESTIMATOR.name} the model was "
                    f"made with ({estimator_digest()[:12]}... is installed), got {str(digest)[:12]!r}: the model's "
                    "gains would come from another estimator"
                )
    env_kwargs = meta.get("env_kwargs")
    if env_kwargs is not None and not isinstance(env_kwargs, dict):
        raise ModelError(f"{path}: env_kwargs must be a mapping of QuadUneven-v0 arguments, got {env_kwargs!r}")
    if not isinstance(meta.get("normalize_obs", False), bool):
        raise ModelError(f"{path}: normalize_obs must be true or false, got {meta.get('normalize_obs')!r}")
    return meta


def residual_config_of(meta: dict[str, Any], path: str | Path = META_FILE) -> Any:
    """The :class:`~agents.rl.residual_env.ResidualConfig` a residual model's metadata records
    (:data:`RESIDUAL_META_FIELDS`, the absent ones from :data:`META_DEFAULTS`).

    :raises ModelError: naming ``path`` and the bad field (e.g. ``expert.adaptation``) with its allowed values.
    """
    from agents.rl.residual_env import ResidualConfig

    raw = {name: meta.get(name, META_DEFAULTS.get(name)) for name in RESIDUAL_META_FIELDS}
    try:
        return ResidualConfig.from_dict(raw, where="")
    except ValueError as err:
        raise ModelError(f"{path}: {err}") from None


def write_metadata(folder: Path, meta: dict[str, Any]) -> Path:
    """Write ``meta`` (with ``format`` set) as ``folder/rl_meta.json``; :return: its path."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / META_FILE
    path.write_text(json.dumps({"format": META_FORMAT, **meta}, indent=2, allow_nan=False))
    return path


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
    :param obs_normalizer: the :class:`ObsNormalization` applied before ``model.predict``, or None.
    :param expert: the :class:`agents.expert.ExpertPolicy` in the loop of a residual model, or None.
    :param features_of: the env (unwrapped) whose simulator state the expert features are read from, for a
        model trained with them (:mod:`agents.rl.expert_features`); None: the observation is used as given.
    """

    def __init__(self, model: Any, obs_normalizer: Any = None, expert: Any = None, features_of: Any = None) -> None:
        self.model = model
        self.obs_normalizer = obs_normalizer
        self.expert = expert
        self.features_of = features_of

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
        """SB3's predict on the (normalised) observation; :return: action in [-1, 1]^12 and the state.

        For a model trained with the expert features, they are appended to ``observation`` (one env's) first.
        """
        if self.features_of is not None:
            from agents.rl.expert_features import expert_features

            observation = np.concatenate([observation, expert_features(self.expert, self.features_of.data)])
        obs = observation if self.obs_normalizer is None else self.obs_normalizer.normalize(observation)
        return self.model.predict(obs, state=state, episode_start=episode_start, deterministic=deterministic)


def load_obs_normalization(model_path: Path, meta: dict[str, Any] | None, allow_pickle: bool = False) -> Any:
    """The observation statistics saved with ``model_path`` (an :class:`ObsNormalization`), or None.

    Reads ``X_obs_norm.npz`` (arrays only). A run from before that format has SB3's pickled
    ``X_vecnormalize.pkl``: unpickling can run code from the file, so it is read only with
    ``allow_pickle`` (``quad-uneven evaluate --allow-pickle``), for files you trust.

    :raises ModelError: when the statistics are missing, unreadable, or a pickle without ``allow_pickle``.
    """
    npz = norm_path(model_path)
    if npz.is_file():
        try:
            return ObsNormalization.load(npz)
        except ValueError as err:
            raise ModelError(f"policy: {err}") from None
    pkl = pickle_path(model_path)
    if pkl is not None:
        if not allow_pickle:
            raise ModelError(
                f"policy: {pkl.name} is a pickle, and unpickling runs code from the file; re-save the statistics "
                f"as {npz.name} (quad-uneven train writes it), or pass --allow-pickle if you trust the file"
            )
        try:
            with pkl.open("rb") as f:
                vn = pickle.load(f)  # the user opted in for this file
            return ObsNormalization.from_vecnormalize(vn) if vn.norm_obs else None
        except Exception as err:  # a truncated or foreign pickle raises anything from EOFError to AttributeError
            raise ModelError(f"policy: {pkl} is not readable VecNormalize statistics ({type(err).__name__})") from None
    if meta is not None and meta.get("normalize_obs"):
        raise ModelError(
            f"policy: {model_path} was trained with normalised observations but {npz.name} is missing next to it"
        )
    return None


_CONSTANT_KEYS = ("lr_schedule", "clip_range", "clip_range_vf", "exploration_schedule")
"""Pickled schedules in an SB3 zip: not used for prediction, replaced by constants on a safe load."""

_TRAINING_STATE_KEYS = ("_last_obs", "_last_episode_starts", "_last_original_obs", "action_noise")
"""Pickled training state in an SB3 zip (last rollout observations, exploration noise): None on a safe load."""

_BUFFER_KEYS = ("ep_info_buffer", "ep_success_buffer")
"""Pickled episode-statistics deques: empty on a safe load."""


def zip_data(path: Path) -> dict[str, Any]:
    """The ``data`` JSON of an SB3 model zip, without deserialising anything."""
    try:
        with zipfile.ZipFile(path) as z:
            return json.loads(z.read("data"))
    except (zipfile.BadZipFile, KeyError, OSError, json.JSONDecodeError, UnicodeDecodeError) as err:
        raise ModelError(f"policy: {path} is not an SB3 model zip ({type(err).__name__}: {err})") from None


def _safe_custom_objects(path: Path, cls: Any, env: gym.Env) -> dict[str, Any]:
    """Replacements for every pickled entry of the zip's ``data``, so that SB3 unpickles nothing.

    The observation and action spaces come from ``env`` (their recorded shapes must match), the policy
    and buffer classes are the algorithm's own, schedules are constants (unused by ``predict``).

    :raises ModelError: on a shape mismatch or a pickled entry this loader does not know.
    """
    from stable_baselines3.common.buffers import ReplayBuffer, RolloutBuffer
    from stable_baselines3.common.utils import ConstantSchedule

    data = zip_data(path)
    custom: dict[str, Any] = {}
    for key, entry in data.items():
        if not (isinstance(entry, dict) and ":serialized:" in entry):
            continue
        if key in ("observation_space", "action_space"):
            space = getattr(env, key)
            shape = entry.get("_shape")
            if shape is not None and tuple(shape) != tuple(space.shape):
                raise ModelError(
                    f"policy: {path} was trained for an {key.replace('_', ' ')} of shape {tuple(shape)}, "
                    f"the env has {tuple(space.shape)}"
                )
            custom[key] = space
        elif key == "policy_class":
            custom[key] = cls.policy_aliases["MlpPolicy"]
            if entry.get("__module__") not in (None, custom[key].__module__):
                raise ModelError(
                    f"policy: {path} holds a policy class from {entry['__module__']!r}, not {cls.__name__}'s "
                    f"MlpPolicy (a model of another algo? --algo loads {cls.__name__} models)"
                )
        elif key in ("rollout_buffer_class", "replay_buffer_class"):
            custom[key] = RolloutBuffer if key == "rollout_buffer_class" else ReplayBuffer
        elif key in _CONSTANT_KEYS:
            custom[key] = ConstantSchedule(0.0)
        elif key == "train_freq":
            custom[key] = (1, "step")
        elif key in _TRAINING_STATE_KEYS:
            custom[key] = None
        elif key in _BUFFER_KEYS:
            custom[key] = collections.deque(maxlen=100)
        else:
            raise ModelError(
                f"policy: {path} holds a pickled {key!r}, which this loader does not unpickle (it could run code); "
                "pass --allow-pickle if you trust the file"
            )
    return custom


def load_sb3_model(path: str | Path, algo: str, env: gym.Env, allow_pickle: bool = False) -> Any:
    """An SB3 model loaded for prediction on ``env``'s spaces, without running code from the file.

    SB3 zips hold cloudpickled entries (spaces, schedules, classes) beside the weights; they are replaced
    (:func:`_safe_custom_objects`), and the weights are read by ``torch.load(weights_only=True)``.
    ``allow_pickle`` loads the file as SB3 does (trusted files only).

    :raises ModelError: on an unreadable zip, a space mismatch or an unknown pickled entry.
    """
    import stable_baselines3

    path = Path(path)
    cls = getattr(stable_baselines3, algo.upper())
    custom = None if allow_pickle else _safe_custom_objects(path, cls, env)
    try:
        return cls.load(path, device="cpu", custom_objects=custom)
    except (ValueError, KeyError, RuntimeError, zipfile.BadZipFile, EOFError, OSError) as err:
        raise ModelError(f"policy: {path} cannot be loaded as {algo.upper()} ({type(err).__name__}: {err})") from None


def _describe(space: Any) -> str:
    return f"{type(space).__name__} of shape {getattr(space, 'shape', None)}" if space is not None else "none"


def check_spaces(model: Any, env: gym.Env, path: Path) -> None:
    """Refuse a model whose observation or action space is not ``env``'s (it was trained for another env).

    Also after an ``allow_pickle`` load, which takes the spaces from the file.

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


class ModelSpaces:
    """The observation and action spaces of a model trained on ``env`` (with ``meta``), and its layout.

    ``observation_space`` is ``env``'s, with the expert features appended when ``meta`` says
    ``residual`` and ``expert_features``; ``observation_structure`` names the slices of every part.
    """

    def __init__(self, env: gym.Env, meta: dict[str, Any] | None) -> None:
        self.expert_features = bool(meta and meta.get("residual") and meta.get("expert_features", False))
        self.action_space = env.action_space
        self.observation_space = env.observation_space
        self.observation_structure: dict[str, slice] = dict(env.unwrapped.observation_structure)
        if self.expert_features:
            from agents.rl.expert_features import EXPERT_FEATURE_FIELDS, augmented_space

            offset = int(env.observation_space.shape[0])
            self.observation_space = augmented_space(env.observation_space)
            for f in EXPERT_FEATURE_FIELDS:
                self.observation_structure[f.name] = slice(offset, offset + f.size)
                offset += f.size


def load_sb3_policy(path: str | Path, env: gym.Env, algo: str, allow_pickle: bool = False) -> SB3Policy:
    """Load the SB3 model ``path`` as a policy for ``env`` (a ``QuadUneven-v0`` env, before ``reset``).

    With ``rl_meta.json`` saying ``residual``, installs the expert of its recorded config plus the residual
    (:func:`agents.rl.residual_env.install_residual_controller`) on ``env.unwrapped``, and with
    ``expert_features`` the policy appends the expert features to every observation, as the training env
    did. Nothing in the model folder is unpickled unless ``allow_pickle`` (see :func:`load_sb3_model`).

    :param algo: ``"ppo"`` or ``"sac"``; must match the metadata's ``algo`` if there is one.
    :raises ModelError: on an algo mismatch, bad metadata, missing or unreadable normalisation statistics, a
        corrupt or truncated model file, or a model for another observation or action space.
    """
    path = Path(path)
    meta = read_metadata(path)
    if meta is not None and meta.get("algo") not in (None, algo):
        raise ModelError(f"algo: {path} was trained with {meta['algo']!r}; pass --algo {meta['algo']}, got {algo!r}")
    spaces_of = ModelSpaces(env, meta)
    normalizer = load_obs_normalization(path, meta, allow_pickle)
    model = load_sb3_model(path, algo, spaces_of, allow_pickle)  # type: ignore[arg-type]
    check_spaces(model, spaces_of, path)  # type: ignore[arg-type]
    expert = None
    if meta is not None and meta.get("residual"):
        from agents.rl.residual_env import install_residual_controller

        expert, _ = install_residual_controller(env, residual_config_of(meta, path))
    return SB3Policy(model, normalizer, expert, env.unwrapped if spaces_of.expert_features else None)


__all__ = [
    "META_DEFAULTS",
    "META_FILE",
    "META_FORMAT",
    "RESIDUAL_META_FIELDS",
    "ModelError",
    "ModelSpaces",
    "SB3Policy",
    "check_spaces",
    "load_obs_normalization",
    "load_sb3_model",
    "load_sb3_policy",
    "metadata_env_kwargs",
    "read_metadata",
    "residual_config_of",
    "write_metadata",
    "zip_data",
]
