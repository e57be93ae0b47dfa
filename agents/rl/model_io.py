"""Trained SB3 models on disk: the metadata ``quad-uneven train`` writes, and loading a model as a policy.

A training run writes ``DIR/rl_meta.json`` (and a copy in ``DIR/checkpoints/`` and ``DIR/best/``)::

    {"format": "quad-uneven-rl/1", "algo": "ppo", "residual": true, "residual_scale": 0.1,
     "expert": {"adaptation": "knee"}, "env_id": "QuadUnevenResidual-v0", "env_kwargs": {...},
     "robot": "paper", "normalize_obs": true, ...}

It says which env the model was trained in: ``env_id`` and ``env_kwargs``, ``robot`` (the name of the robot; a
model without the field was trained on ``env_kwargs.robot``, else on the paper's robot: :func:`model_robot`) and,
for a residual model, its :class:`~agents.rl.residual_config.ResidualConfig`: the ``residual_*``,
``expert_features`` and ``expert`` fields (``expert``: the :class:`~agents.expert.ExpertConfig` fields that differ
from the defaults; with ``adaptation: learned`` also ``strength_estimator_sha256``, the estimator it was made with).

A model is evaluated in that env, as SB3's ``VecNormalize.load(path, venv)`` wraps an env rather than copying its
transform: :func:`make_model_env` rebuilds it (``QuadUnevenResidual-v0`` with the expert and residual of the
training, whose observation carries the expert features, or ``QuadUneven-v0``), and :func:`load_sb3_policy` loads
the model for it, checking (never changing) the env it is given: the model's robot, its kind of env and its residual.
Observations are normalised with the saved statistics (:mod:`agents.rl.normalization`). Nothing from the folder is
unpickled unless the user opts in. A model without metadata is loaded as a plain SB3 policy on the env as given.
"""

from __future__ import annotations

import collections
import dataclasses
import io
import json
import math
import pickle
import re
import warnings
import zipfile
import zlib
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from agents.rl.normalization import ObsNormalization, norm_path, pickle_path
from agents.rl.plan_config import PlanConfig
from agents.rl.plan_env import PLAN_ENV_ID, PlanExpertEnv
from agents.rl.residual_config import ResidualConfig
from agents.rl.residual_env import RESIDUAL_ENV_ID, ResidualExpertEnv
from quad_uneven_env import ENV_ID as PLAIN_ENV_ID
from quad_uneven_env.fields import excerpt

META_FILE = "rl_meta.json"
"""Name of the metadata file next to the model(s) of a training run."""

META_FORMAT = "quad-uneven-rl/1"
"""Value of the metadata's ``format`` field."""

META_DEFAULTS: dict[str, Any] = {
    "residual_legs": "all",
    "residual_basis": "torque_limit",
    "expert_features": False,
    "residual_penalty": 0.0,
    "expert": {},
    "env_kwargs": {},
}
"""Values of the fields a model's metadata may leave out."""

RESIDUAL_META_FIELDS = (
    "residual_scale",
    "residual_legs",
    "residual_basis",
    "expert_features",
    "residual_penalty",
    "expert",
)
"""The metadata fields of a residual model that make its :class:`~agents.rl.residual_config.ResidualConfig`."""

UNRECORDED_ROBOT = "paper"
"""The robot of a model whose metadata names none (neither ``robot`` nor ``env_kwargs.robot``): the env's default
robot, which every such model was trained on (the shipped models among them)."""

NOT_READ = {"gain_adaptation": "none", "adaptation_features": False}
"""Metadata fields this reader refuses unless they hold these values (which it can ignore): the adaptation is
the expert's (``expert: {adaptation: ...}``), and the adapted gains are no observation."""


class ModelError(ValueError):
    """A model file, its metadata or its normalisation statistics cannot be used."""


META_FIELD_TYPES: dict[str, tuple[str, ...]] = {
    "format": ("string",),
    "algo": ("string",),
    "residual": ("bool",),
    "residual_level": ("string",),
    "plan": ("object",),
    "residual_scale": ("number",),
    "residual_legs": ("string",),
    "residual_basis": ("string",),
    "expert_features": ("bool",),
    "residual_penalty": ("number",),
    "expert": ("object",),
    "strength_estimator_sha256": ("string",),
    "env_id": ("string",),
    "env_kwargs": ("object",),
    "robot": ("string",),
    "normalize_obs": ("bool",),
    "terrain": ("string", "object", "list"),
    "randomization": ("string", "object", "null"),
    "max_episode_steps": ("integer", "null"),
    "seed": ("integer", "null"),
    "stable_baselines3": ("string",),
    "init_from": ("string",),
    "gain_adaptation": ("string",),
    "adaptation_features": ("bool",),
}
"""The JSON type(s) of every field ``quad-uneven train`` records in ``rl_meta.json`` (other fields are not read).
A bool is a JSON ``true``/``false`` (never ``"no"`` or ``0``), a number a finite JSON number."""

_JSON_TYPES: dict[str, tuple[str, Any]] = {
    "bool": ("true or false", lambda v: isinstance(v, bool)),
    "number": ("a finite number", lambda v: type(v) in (int, float) and math.isfinite(v)),
    "integer": ("an integer", lambda v: type(v) is int),
    "string": ("a string", lambda v: isinstance(v, str)),
    "object": ("a JSON object", lambda v: isinstance(v, dict)),
    "list": ("a list", lambda v: isinstance(v, list)),
    "null": ("null", lambda v: v is None),
}
"""JSON type name -> (its description in messages, its test on a decoded value)."""


def check_json_type(value: Any, kinds: tuple[str, ...], where: str) -> None:
    """Refuse ``value`` unless it is of one of the JSON types ``kinds`` (names of :data:`_JSON_TYPES`).

    :raises ModelError: ``where must be <types>, got <value> of type <type>``.
    """
    if not any(_JSON_TYPES[k][1](value) for k in kinds):
        allowed = " or ".join(_JSON_TYPES[k][0] for k in kinds)
        raise ModelError(f"{where} must be {allowed}, got {excerpt(value)} of type {type(value).__name__}")


def read_metadata(model_path: str | Path) -> dict[str, Any] | None:
    """The ``rl_meta.json`` next to ``model_path`` (None if there is none), every field checked.

    The file must be UTF-8 JSON, an object with ``format`` :data:`META_FORMAT`, each field of
    :data:`META_FIELD_TYPES` of its JSON type, and the fields the evaluation uses valid (:func:`_check_metadata`).

    :raises ModelError: naming the file and the field if the file exists but is not valid metadata.
    """
    path = Path(model_path).parent / META_FILE
    if not path.is_file():
        return None
    try:
        meta = json.loads(path.read_bytes().decode("utf-8"), parse_constant=_refuse_constant)
    except OSError as err:
        raise ModelError(f"{path}: unreadable metadata ({err.strerror or err})") from None
    except UnicodeDecodeError as err:
        raise ModelError(f"{path}: metadata must be UTF-8 text, byte {err.start} is not ({err.reason})") from None
    except (json.JSONDecodeError, RecursionError) as err:
        raise ModelError(f"{path}: metadata is not valid JSON ({err})") from None
    except ValueError as err:  # NaN or Infinity (_refuse_constant)
        raise ModelError(f"{path}: metadata is not strict JSON ({err})") from None
    if not isinstance(meta, dict) or meta.get("format") != META_FORMAT:
        raise ModelError(f"{path}: format must be {META_FORMAT!r}")
    for name, kinds in META_FIELD_TYPES.items():
        if name in meta:
            check_json_type(meta[name], kinds, f"{path}: {name}")
    return _check_metadata(meta, path)


def _refuse_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a JSON number")


def _check_metadata(meta: dict[str, Any], path: Path) -> dict[str, Any]:
    """``meta`` with the fields the evaluation uses checked (``algo``, ``residual``, the residual's config, ...)."""
    from agents.rl.config import ALGOS

    if meta.get("algo") not in (None, *ALGOS):
        raise ModelError(f"{path}: algo must be one of {list(ALGOS)}, got {excerpt(meta.get('algo'))}")
    if not isinstance(meta.get("residual", False), bool):
        raise ModelError(f"{path}: residual must be true or false, got {excerpt(meta.get('residual'))}")
    level = meta.get("residual_level", "torque")
    if level not in ("torque", "plan") or (level == "plan" and not meta.get("residual")):
        raise ModelError(
            f"{path}: residual_level must be 'torque' or 'plan' (with residual: true), got {excerpt(level)}"
        )
    env_id = (PLAN_ENV_ID if level == "plan" else RESIDUAL_ENV_ID) if meta.get("residual") else PLAIN_ENV_ID
    if meta.get("env_id", env_id) != env_id:
        raise ModelError(
            f"{path}: env_id must be {env_id!r} for a model with residual: {str(meta.get('residual', False)).lower()}, "
            f"residual_level: {level}, got {excerpt(meta['env_id'])}"
        )
    if level == "plan":
        config = plan_config_of(meta, path)
        _check_estimator(meta, config.expert, path)
    elif meta.get("residual"):
        if "residual_scale" not in meta:
            raise ModelError(f"{path}: residual_scale is missing (a residual model needs a number in (0, 1])")
        for name, value in NOT_READ.items():
            if name in meta and meta[name] != value:
                raise ModelError(
                    f"{path}: {name} must be absent or {excerpt(value)}, got {excerpt(meta[name])} "
                    "(the expert's adaptation is "
                    "expert: {adaptation: ...})"
                )
        _check_estimator(meta, residual_config_of(meta, path).expert, path)
    return meta


def _check_estimator(meta: dict[str, Any], expert: Any, path: Path) -> None:
    """Refuse a model whose expert's learned adaptation used another strength estimator than the installed one."""
    if expert.adaptation != "learned":
        return
    from agents.control.adaptation.learned import DEFAULT_ESTIMATOR, estimator_digest

    digest = meta.get("strength_estimator_sha256")
    if digest != estimator_digest():
        raise ModelError(
            f"{path}: strength_estimator_sha256 must be the sha256 of {DEFAULT_ESTIMATOR.name} the model was "
            f"made with ({estimator_digest()[:12]}... is installed), got {str(digest)[:12]!r}: the model's "
            "gains would come from another estimator"
        )


def plan_config_of(meta: dict[str, Any], path: str | Path = META_FILE) -> PlanConfig:
    """The :class:`~agents.rl.plan_config.PlanConfig` a plan-level model's metadata records (``plan`` and
    ``expert``; ``max_control_steps`` is the evaluation's, given by :func:`make_model_env`).

    :raises ModelError: naming ``path`` and the bad field (e.g. ``plan.stride_range``) with its allowed values.
    """
    raw = dict(meta.get("plan") or {})
    raw.pop("max_control_steps", None)
    raw["expert"] = meta.get("expert") or {}
    try:
        return PlanConfig.from_dict(raw, where="plan")
    except ValueError as err:
        raise ModelError(f"{path}: {err}") from None


def residual_config_of(meta: dict[str, Any], path: str | Path = META_FILE) -> ResidualConfig:
    """The :class:`~agents.rl.residual_config.ResidualConfig` a residual model's metadata records
    (:data:`RESIDUAL_META_FIELDS`, the absent ones from :data:`META_DEFAULTS`).

    :raises ModelError: naming ``path`` and the bad field (e.g. ``expert.adaptation``) with its allowed values.
    """
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


def model_robot(meta: dict[str, Any]) -> str:
    """The name of the robot a model with metadata ``meta`` was trained on: its ``robot`` field; without one (as in
    the shipped models' metadata), the stem of its ``env_kwargs.robot``, else :data:`UNRECORDED_ROBOT`."""
    if "robot" in meta:
        return str(meta["robot"])
    return Path(str((meta.get("env_kwargs") or {}).get("robot", UNRECORDED_ROBOT))).stem


def model_env_spec(meta: dict[str, Any] | None, path: str | Path = META_FILE) -> tuple[str, dict[str, Any]]:
    """The Gymnasium id and arguments of the env a model with metadata ``meta`` was trained in.

    A residual model's env is ``QuadUnevenResidual-v0`` with the recorded ``env_kwargs`` and its
    :class:`~agents.rl.residual_config.ResidualConfig` as ``config`` (the expert of its training, with its
    residual); any other model's is ``QuadUneven-v0`` with the recorded ``env_kwargs``. Without metadata (a bare SB3
    zip): ``QuadUneven-v0`` with its defaults.

    :raises ModelError: naming ``path`` and the field, on a residual config the metadata cannot give.
    """
    if meta is None:
        return PLAIN_ENV_ID, {}
    kwargs = dict(meta.get("env_kwargs") or {})
    if meta.get("residual_level") == "plan":
        return PLAN_ENV_ID, {**kwargs, "config": plan_config_of(meta, path)}
    if meta.get("residual"):
        return RESIDUAL_ENV_ID, {**kwargs, "config": residual_config_of(meta, path)}
    return PLAIN_ENV_ID, kwargs


def make_model_env(model_path: str | Path, **kwargs: Any) -> gym.Env:
    """The env the SB3 model ``model_path`` was trained in, rebuilt from its ``rl_meta.json``
    (:func:`model_env_spec`): the observation the model was trained on is the env's own, expert features included.

    :param kwargs: arguments over the recorded ones (``terrain``, ``max_episode_steps``, ``randomization``,
        ``render_mode``, ...); ``robot`` other than the model's is refused when the policy is loaded
        (:func:`load_sb3_policy`).
    :raises ModelError: on unreadable metadata; the env's own ``ValueError`` or ``TypeError`` on a bad argument.
    """
    import quad_uneven_env  # noqa: F401  (registers QuadUneven-v0)

    env_id, recorded = model_env_spec(read_metadata(model_path), Path(model_path).parent / META_FILE)
    if env_id == PLAN_ENV_ID and "max_episode_steps" in kwargs:  # control steps: the plan env's steps are cycles
        steps = kwargs.pop("max_episode_steps")
        recorded["config"] = dataclasses.replace(recorded["config"], max_control_steps=steps)
    return gym.make(env_id, **{**recorded, **kwargs})


class SB3Policy:
    """An SB3 model with its observation normalisation, for the env it was trained in (:func:`make_model_env`).

    :param model: the loaded SB3 algorithm.
    :param obs_normalizer: the :class:`ObsNormalization` applied before ``model.predict``, or None.
    :param expert: the :class:`agents.expert.ExpertPolicy` of a residual model's env (for its plan times and failure
        log in the evaluation's record), or None.
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
        """SB3's predict on the (normalised) observation of the model's env; :return: action in [-1, 1]^12 and the
        state."""
        obs = observation if self.obs_normalizer is None else self.obs_normalizer.normalize(observation)
        return self.model.predict(obs, state=state, episode_start=episode_start, deterministic=deterministic)


def load_obs_normalization(
    model_path: Path, meta: dict[str, Any] | None, allow_pickle: bool = False, shape: tuple[int, ...] | None = None
) -> Any:
    """The observation statistics saved with ``model_path`` (an :class:`ObsNormalization`), or None.

    Reads ``X_obs_norm.npz`` (arrays only, checked by :meth:`ObsNormalization.load`). A run from before that
    format has SB3's pickled ``X_vecnormalize.pkl``: unpickling can run code from the file, so it is read only
    with ``allow_pickle`` (``quad-uneven evaluate --allow-pickle``), for files you trust.

    :param shape: the model's observation shape (its env's), which the statistics must have.
    :raises ModelError: when the statistics are missing, unreadable, of another shape, or a pickle without
        ``allow_pickle``.
    """
    npz = norm_path(model_path)
    if npz.is_file():
        try:
            return ObsNormalization.load(npz, shape)
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
            norm = ObsNormalization.from_vecnormalize(vn) if vn.norm_obs else None
        except Exception as err:  # a truncated or foreign pickle raises anything from EOFError to AttributeError
            raise ModelError(f"policy: {pkl} is not readable VecNormalize statistics ({type(err).__name__})") from None
        if norm is not None and shape is not None and norm.mean.shape != tuple(shape):
            raise ModelError(
                f"policy: {pkl}: the statistics have shape {norm.mean.shape}, the model's observation {tuple(shape)}"
            )
        return norm
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


MAX_ENTRY_BYTES = 256 * 2**20
"""Largest uncompressed entry of a model zip read (bytes): far above the networks ``quad-uneven train`` makes."""

MAX_ENTRIES = 64
"""Most entries a model zip may hold (SB3 writes 5 to 9)."""

ZIP_ENTRIES = ("data", "_stable_baselines3_version", "system_info.txt")
"""Entries of an SB3 model zip besides its ``NAME.pth`` tensor files."""

_PTH_ENTRY = re.compile(r"(?P<name>[A-Za-z_]\w*(?:\.[A-Za-z_]\w*)*)\.pth")
"""A tensor file: ``policy.pth``, ``policy.optimizer.pth``, ``pytorch_variables.pth``, ... (an attribute path)."""

_VARIABLES = ("pytorch_variables", "tensors")
"""Names of the ``.pth`` file of an SB3 zip that holds loose tensors (SAC's ``log_ent_coef``) and not a state
dict (``tensors`` in SB3 < 0.9)."""

DATA_FIELD_TYPES: dict[str, tuple[str, ...]] = {
    "policy_kwargs": ("object",),
    "verbose": ("integer",),
    "num_timesteps": ("integer",),
    "seed": ("integer", "null"),
    "n_envs": ("integer",),
    "n_steps": ("integer",),
    "batch_size": ("integer",),
    "n_epochs": ("integer",),
    "buffer_size": ("integer",),
    "learning_starts": ("integer",),
    "gradient_steps": ("integer",),
    "target_update_interval": ("integer",),
    "sde_sample_freq": ("integer",),
    "use_sde": ("bool",),
    "normalize_advantage": ("bool",),
    "optimize_memory_usage": ("bool",),
    "learning_rate": ("number",),
    "gamma": ("number",),
    "gae_lambda": ("number",),
    "tau": ("number",),
    "vf_coef": ("number",),
    "max_grad_norm": ("number",),
}
"""JSON types of the plain fields of an SB3 zip's ``data`` that building the model reads (when not pickled)."""

_POSITIVE_DATA_FIELDS = ("n_envs", "n_steps", "batch_size", "n_epochs", "buffer_size")
"""``data`` fields that size the model's buffers: integers >= 1."""


@dataclasses.dataclass(frozen=True)
class ModelZip:
    """The checked content of an SB3 model zip (:func:`read_model_zip`): JSON data and tensors, nothing unpickled."""

    data: dict[str, Any]
    """the ``data`` entry: SB3's attributes, pickled ones still as ``{":serialized:": ...}`` entries."""
    params: dict[str, dict[str, Any]]
    """state dicts by attribute path (``policy``, ``policy.optimizer``, ``actor.optimizer``, ...)."""
    variables: dict[str, Any]
    """loose tensors by attribute path (``pytorch_variables.pth``; SAC's ``log_ent_coef``), else empty."""


def read_model_zip(path: str | Path, where: str = "policy") -> ModelZip:
    """Read and check the SB3 model zip ``path`` without running code from it.

    Checked: that it is a zip, its entry names (:data:`ZIP_ENTRIES` and ``NAME.pth``, each once) and
    sizes (:data:`MAX_ENTRY_BYTES`), that ``data`` is a UTF-8 JSON object whose plain fields have their
    JSON types (:data:`DATA_FIELD_TYPES`), and that every ``.pth`` entry loads with
    ``torch.load(weights_only=True)`` (a pickled object in it is refused, never run) as a dict of tensors
    (a state dict, an optimizer's state dict, or loose tensors).

    :param where: the name the messages start with (the option that gave ``path``).
    :raises ModelError: ``where: PATH: ...`` naming the entry (and field) at fault.
    """
    path = Path(path)
    try:
        with zipfile.ZipFile(path) as z:
            infos = z.infolist()
            _check_entries(infos, path, where)
            raw = {info.filename: _read_entry(z, info) for info in infos}
    except ModelError:
        raise
    except FileNotFoundError:
        raise ModelError(f"{where}: SB3 model file {str(path)!r} does not exist") from None
    except (zipfile.BadZipFile, zipfile.LargeZipFile, zlib.error, EOFError, OSError, RuntimeError,
            NotImplementedError, ValueError) as err:  # fmt: skip
        # a damaged archive (BadZipFile, zlib.error, EOFError), an encrypted entry (RuntimeError), a compression
        # method zipfile lacks (NotImplementedError), or a file that cannot be read (OSError)
        raise ModelError(f"{where}: {path} is not a readable SB3 model zip ({type(err).__name__}: {err})") from None
    data = _parse_data(raw["data"], path, where)
    params: dict[str, dict[str, Any]] = {}
    variables: dict[str, Any] = {}
    for name, blob in raw.items():
        m = _PTH_ENTRY.fullmatch(name)
        if m is None:
            continue
        content = _load_tensors(blob, path, name, where)
        if m["name"] in _VARIABLES:
            variables = content
        else:
            params[m["name"]] = content
    return ModelZip(data, params, variables)


def _check_entries(infos: list[zipfile.ZipInfo], path: Path, where: str) -> None:
    if len(infos) > MAX_ENTRIES:
        raise ModelError(f"{where}: {path} holds {len(infos)} entries; an SB3 model zip holds at most {MAX_ENTRIES}")
    names = [info.filename for info in infos]
    repeated = sorted(n for n, count in collections.Counter(names).items() if count > 1)
    if repeated:
        raise ModelError(f"{where}: {path} holds the entry {repeated[0]!r} more than once")
    for info in infos:
        if info.filename not in ZIP_ENTRIES and not _PTH_ENTRY.fullmatch(info.filename):
            raise ModelError(
                f"{where}: {path} holds an entry {excerpt(info.filename)}; an SB3 model zip holds "
                f"{', '.join(ZIP_ENTRIES)} and NAME.pth tensor files (NAME an attribute path such as policy.optimizer)"
            )
        if info.file_size > MAX_ENTRY_BYTES:
            raise ModelError(
                f"{where}: {path} entry {info.filename!r} is {info.file_size} bytes uncompressed, more than the "
                f"{MAX_ENTRY_BYTES} this loader reads"
            )
    if "data" not in names:
        raise ModelError(f"{where}: {path} has no 'data' entry (not an SB3 model zip)")


def _read_entry(z: zipfile.ZipFile, info: zipfile.ZipInfo) -> bytes:
    """The bytes of one entry, never more than :data:`MAX_ENTRY_BYTES` (whatever its header says)."""
    with z.open(info) as f:
        blob = f.read(MAX_ENTRY_BYTES + 1)
    if len(blob) > MAX_ENTRY_BYTES:
        raise zipfile.BadZipFile(f"entry {info.filename!r} is longer than its header says")
    return blob


def _parse_data(blob: bytes, path: Path, where: str) -> dict[str, Any]:
    try:
        data = json.loads(blob.decode("utf-8"))
    except UnicodeDecodeError as err:
        raise ModelError(f"{where}: {path} entry 'data' must be UTF-8 JSON, byte {err.start} is not") from None
    except (json.JSONDecodeError, RecursionError) as err:
        raise ModelError(f"{where}: {path} entry 'data' is not valid JSON ({err})") from None
    if not isinstance(data, dict):
        raise ModelError(f"{where}: {path} entry 'data' must be a JSON object, got a {type(data).__name__}")
    for key, kinds in DATA_FIELD_TYPES.items():
        value = data.get(key)
        if key in data and not _is_serialized(value):
            check_json_type(value, kinds, f"{where}: {path} data.{key}")
            if key in _POSITIVE_DATA_FIELDS and value < 1:
                raise ModelError(f"{where}: {path} data.{key} must be an integer >= 1, got {excerpt(value)}")
    return data


def _is_serialized(entry: Any) -> bool:
    """Is ``entry`` of an SB3 zip's ``data`` a pickled object (``{":type:": ..., ":serialized:": base64}``)?"""
    return isinstance(entry, dict) and ":serialized:" in entry


def _load_tensors(blob: bytes, path: Path, entry: str, where: str) -> dict[str, Any]:
    """A ``.pth`` entry read by ``torch.load(weights_only=True)``: tensors and plain containers, no other object."""
    import torch

    try:
        with warnings.catch_warnings():  # torch's notes on a crafted file's pickle protocol: the error says it all
            warnings.simplefilter("ignore")
            content = torch.load(io.BytesIO(blob), map_location="cpu", weights_only=True)
    except Exception as err:  # torch's parser of untrusted bytes: any failure means unreadable
        # weights_only refuses every pickled object (pickle.UnpicklingError) without running it; a damaged file
        # raises RuntimeError, EOFError, KeyError, ... from torch's zip reader and unpickler
        raise ModelError(
            f"{where}: {path} entry {entry!r} is not a tensor file torch.load(weights_only=True) reads "
            f"({_torch_reason(err)}); pickled objects in it are never loaded"
        ) from None
    if not isinstance(content, dict) or not all(isinstance(k, str) for k in content):
        raise ModelError(
            f"{where}: {path} entry {entry!r} must hold a dict of named tensors, got {type(content).__name__}"
        )
    if Path(entry).stem in _VARIABLES or not Path(entry).stem.endswith("optimizer"):
        bad = [k for k, v in content.items() if not (isinstance(v, torch.Tensor) or v is None)]
        if bad:
            raise ModelError(f"{where}: {path} entry {entry!r}: {bad[0]!r} must be a tensor")
    elif not (isinstance(content.get("state"), dict) and isinstance(content.get("param_groups"), list)):
        raise ModelError(f"{where}: {path} entry {entry!r} must be an optimizer state dict (state, param_groups)")
    return content


_TORCH_REFUSAL = re.compile(r"Unsupported (?:global: GLOBAL \S+|operand \d+)")
"""What torch's weights-only unpickler refused, in its long message."""


def _torch_reason(err: Exception) -> str:
    """``err`` of ``torch.load`` in a few words: its type and what the weights-only unpickler refused (or its
    first line)."""
    refused = _TORCH_REFUSAL.search(str(err))
    lines = str(err).strip().splitlines()
    detail = refused[0] if refused else excerpt(lines[0], 120) if lines else ""
    return f"{type(err).__name__}: {detail}" if detail else type(err).__name__


def zip_data(path: Path, where: str = "policy") -> dict[str, Any]:
    """The ``data`` JSON of an SB3 model zip, checked (:func:`read_model_zip`), without deserialising anything."""
    return read_model_zip(path, where).data


def recorded_shape(data: dict[str, Any], key: str, path: Path, where: str = "policy") -> tuple[int, ...]:
    """The shape an SB3 zip's ``data`` records for its space ``key`` (``observation_space`` or ``action_space``).

    :raises ModelError: if the space or its ``_shape`` (a list of integers >= 0) is not recorded.
    """
    entry = data.get(key)
    shape = entry.get("_shape") if _is_serialized(entry) else None
    if not (isinstance(shape, list) and all(type(n) is int and n >= 0 for n in shape)):
        raise ModelError(f"{where}: {path} data.{key}._shape must be a list of integers, got {excerpt(shape)}")
    return tuple(shape)


_SPACE_TYPES = {"observation_space": "observation space", "action_space": "action space"}


def _check_recorded_spaces(data: dict[str, Any], env: Any, path: Path) -> None:
    """The spaces a model zip records (JSON beside their pickle): present, of ``env``'s space class and shape.

    :raises ModelError: naming the space, what the file records and what the env has.
    """
    for key, label in _SPACE_TYPES.items():
        space, entry = getattr(env, key), data.get(key)
        if not _is_serialized(entry):
            raise ModelError(f"policy: {path} data.{key} must be a recorded space, got {excerpt(entry)}")
        recorded, want = entry.get(":type:"), type(space).__qualname__
        if not (isinstance(recorded, str) and recorded.endswith(f".{want}'>")):  # gym's or gymnasium's class
            raise ModelError(f"policy: {path} data.{key} is a {excerpt(recorded)}, the env's {label} a {want}")
        shape = recorded_shape(data, key, path)
        if shape != tuple(space.shape):
            raise ModelError(
                f"policy: {path} was trained for an {label} of shape {tuple(shape)}, the env has {tuple(space.shape)}"
            )
    if not _is_serialized(data.get("policy_class")):
        raise ModelError(f"policy: {path} data.policy_class must be a recorded policy class")


def _safe_custom_objects(data: dict[str, Any], path: Path, cls: Any, env: gym.Env) -> dict[str, Any]:
    """Replacements for every pickled entry of the zip's ``data``, so that SB3 unpickles nothing.

    The observation and action spaces come from ``env`` (checked against the recorded ones before), the policy
    and buffer classes are the algorithm's own, schedules are constants (unused by ``predict``).

    :raises ModelError: on a pickled entry this loader does not know.
    """
    from stable_baselines3.common.buffers import ReplayBuffer, RolloutBuffer
    from stable_baselines3.common.utils import ConstantSchedule

    custom: dict[str, Any] = {}
    for key, entry in data.items():
        if not _is_serialized(entry):
            continue
        if key in ("observation_space", "action_space"):
            custom[key] = getattr(env, key)
        elif key == "policy_class":
            custom[key] = cls.policy_aliases["MlpPolicy"]
            if entry.get("__module__") not in (None, custom[key].__module__):  # JSON beside the pickle
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


_BUILD_ERRORS = (ValueError, KeyError, TypeError, AttributeError, IndexError, ArithmeticError, MemoryError,
                 RuntimeError, EOFError, OSError, ImportError, pickle.UnpicklingError, zipfile.BadZipFile)  # fmt: skip
"""What SB3's ``load`` raises on a zip whose checked content still does not build a model (a ``data`` field of
the right type but a value the algorithm rejects; with ``allow_pickle``, anything a pickle raises on loading)."""


def load_sb3_model(path: str | Path, algo: str, env: gym.Env, allow_pickle: bool = False) -> Any:
    """An SB3 model loaded for prediction on ``env``'s spaces, without running code from the file.

    The zip is checked first (:func:`read_model_zip`: entries, ``data``, tensors), and its recorded spaces must
    be of ``env``'s types and shapes. SB3 zips hold cloudpickled entries (spaces, schedules, classes) beside
    the weights; they are replaced (:func:`_safe_custom_objects`), and the weights are read by
    ``torch.load(weights_only=True)``. ``allow_pickle`` unpickles those ``data`` entries as SB3 does (trusted
    files only); the ``.pth`` tensor files are never unpickled.

    :raises ModelError: naming the file (and entry or field) on an unreadable or crafted zip, a space mismatch or
        an unknown pickled entry.
    """
    import stable_baselines3

    path = Path(path)
    cls = getattr(stable_baselines3, algo.upper())
    content = read_model_zip(path)
    _check_recorded_spaces(content.data, env, path)
    custom = None if allow_pickle else _safe_custom_objects(content.data, path, cls, env)
    try:
        return cls.load(path, device="cpu", custom_objects=custom)
    except _BUILD_ERRORS as err:
        first = (str(err).strip().splitlines() or [""])[0]
        raise ModelError(
            f"policy: {path} cannot be loaded as {algo.upper()} ({type(err).__name__}: {excerpt(first, 160)})"
        ) from None


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


def _residual_wrapper(env: gym.Env) -> ResidualExpertEnv | PlanExpertEnv | None:
    """The :class:`~agents.rl.residual_env.ResidualExpertEnv` or :class:`~agents.rl.plan_env.PlanExpertEnv` among
    ``env``'s wrappers, or None."""
    while isinstance(env, gym.Wrapper):
        if isinstance(env, ResidualExpertEnv | PlanExpertEnv):
            return env
        env = env.env
    return None


def check_model_env(meta: dict[str, Any], env: gym.Env, path: Path) -> ResidualExpertEnv | PlanExpertEnv | None:
    """Refuse an env the model (with metadata ``meta``) was not trained in; :return: a residual model's
    :class:`~agents.rl.residual_env.ResidualExpertEnv` or :class:`~agents.rl.plan_env.PlanExpertEnv` (None for any
    other model).

    The env's robot must be the model's (:func:`model_robot`); a residual model needs ``QuadUnevenResidual-v0`` with
    its recorded residual and expert, a plan-level one (``residual_level: plan``) ``QuadUnevenPlan-v0`` with its
    recorded plan ranges and expert (:func:`make_model_env` builds either), any other model an env without an
    expert.

    :raises ModelError: naming ``robot`` or the env, with what the model needs.
    """
    robot = model_robot(meta)
    env_robot = getattr(getattr(env.unwrapped, "robot", None), "name", None)
    if env_robot is not None and env_robot != robot:
        raise ModelError(
            f"robot must be {excerpt(robot)}, the robot {path} was trained on, got {excerpt(env_robot)}: a policy "
            "acts for the robot it was trained on (drop --robot, or give its robot)"
        )
    wrapper = _residual_wrapper(env)
    if not meta.get("residual"):
        if wrapper is not None:
            raise ModelError(
                f"policy: {path} was trained without the expert ({PLAIN_ENV_ID}), the env is {RESIDUAL_ENV_ID}"
            )
        return None
    plan = meta.get("residual_level") == "plan"
    env_id, kind = (PLAN_ENV_ID, PlanExpertEnv) if plan else (RESIDUAL_ENV_ID, ResidualExpertEnv)
    if not isinstance(wrapper, kind):
        raise ModelError(
            f"policy: {path} is a residual model: it runs in {env_id} with the expert of its training "
            "(agents.rl.model_io.make_model_env builds it)"
        )
    if plan:
        want, got = plan_config_of(meta, path).to_dict(), wrapper.config.to_dict()
        differ = [k for k in want if k != "max_control_steps" and want[k] != got[k]]
        if differ:
            name = differ[0]
            raise ModelError(
                f"policy: {path} was trained with {name}={excerpt(want[name])}, the env has "
                f"{name}={excerpt(got[name])} (agents.rl.model_io.make_model_env builds the model's env)"
            )
        return wrapper
    want = residual_config_of(meta, path).to_dict()
    got = wrapper.config.to_dict()
    differ = [k for k in want if k != "residual_penalty" and want[k] != got[k]]
    if differ:
        name = differ[0]
        raise ModelError(
            f"policy: {path} was trained with {name}={excerpt(want[name])}, the env has {name}={excerpt(got[name])} "
            "(agents.rl.model_io.make_model_env builds the model's env)"
        )
    return wrapper


def load_sb3_policy(path: str | Path, env: gym.Env, algo: str, allow_pickle: bool = False) -> SB3Policy:
    """Load the SB3 model ``path`` as a policy for ``env``, the env it was trained in (:func:`make_model_env`).

    The env is checked, not changed (:func:`check_model_env`): for a residual model it is ``QuadUnevenResidual-v0``,
    whose expert and residual are its own physics-rate controller and whose observation has the expert features
    the model was trained with. Nothing in the model folder is unpickled unless ``allow_pickle`` (see
    :func:`load_sb3_model`). A model without metadata is loaded as a plain SB3 policy on the env as given.

    :param algo: ``"ppo"`` or ``"sac"``; must match the metadata's ``algo`` if there is one.
    :raises ModelError: on an algo mismatch, bad metadata, an env of another robot or kind, missing or unreadable
        normalisation statistics, a corrupt or truncated model file, or a model for another observation or action
        space.
    """
    path = Path(path)
    meta = read_metadata(path)
    if meta is not None and meta.get("algo") not in (None, algo):
        raise ModelError(f"algo: {path} was trained with {meta['algo']!r}; pass --algo {meta['algo']}, got {algo!r}")
    wrapper = None if meta is None else check_model_env(meta, env, path)
    normalizer = load_obs_normalization(path, meta, allow_pickle, env.observation_space.shape)
    model = load_sb3_model(path, algo, env, allow_pickle)
    check_spaces(model, env, path)
    return SB3Policy(model, normalizer, None if wrapper is None else wrapper.expert)


__all__ = [
    "DATA_FIELD_TYPES",
    "MAX_ENTRIES",
    "MAX_ENTRY_BYTES",
    "META_DEFAULTS",
    "META_FIELD_TYPES",
    "META_FILE",
    "META_FORMAT",
    "RESIDUAL_META_FIELDS",
    "ZIP_ENTRIES",
    "ModelError",
    "ModelZip",
    "SB3Policy",
    "check_json_type",
    "check_model_env",
    "check_spaces",
    "load_obs_normalization",
    "load_sb3_model",
    "load_sb3_policy",
    "make_model_env",
    "model_env_spec",
    "model_robot",
    "plan_config_of",
    "read_metadata",
    "read_model_zip",
    "recorded_shape",
    "residual_config_of",
    "write_metadata",
    "zip_data",
]
