"""Configuration of ``quad-uneven train``: one frozen dataclass, loaded from ``configs/rl/*.yaml``.

The YAML holds every field of :class:`TrainConfig`; command-line options override single fields
(:func:`load_train_config`). Every value is validated here, and a bad one raises
:class:`TrainConfigError` whose message starts with the field name.
"""

from __future__ import annotations

import dataclasses
import os
import warnings
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from agents.rl.hyperparams import HYPERPARAMS, check_hyperparams, check_policy_kwargs
from agents.rl.plan_config import PlanConfig
from agents.rl.residual_config import RESIDUAL_BASES, RESIDUAL_LEGS, ResidualConfig, expert_config
from quad_uneven_env.config import CONFIG_DIR, read_yaml
from quad_uneven_env.fields import check_fields, clip, excerpt, param
from quad_uneven_env.randomization import load_randomization
from quad_uneven_env.terrain import parse_terrain_spec

RL_CONFIG_DIR = CONFIG_DIR / "rl"
"""Directory of the shipped training configs (``configs/rl/NAME.yaml``)."""

ALGOS = ("ppo", "sac")
"""Stable-Baselines3 algorithms ``quad-uneven train`` supports."""

RESIDUAL_LEVELS = ("torque", "plan")
"""What a residual agent adjusts: the expert's joint torques (``QuadUnevenResidual-v0``, every control step) or its
plan (``QuadUnevenPlan-v0``, the settings of every gait cycle)."""

VEC_ENVS = ("auto", "dummy", "subproc")
"""VecEnv classes: ``auto`` is SubprocVecEnv for n_envs > 1, else DummyVecEnv."""

FORBIDDEN_ENV_KWARGS = ("terrain", "randomization", "controller", "action_mode", "render_mode")
"""QuadUneven-v0 arguments that ``env_kwargs`` may not set (the trainer or the residual env owns them)."""


class TrainConfigError(ValueError):
    """An invalid training option; the message starts with the field name."""


@dataclasses.dataclass(frozen=True)
class TrainConfig:
    """Everything one training run needs (SI units; steps are control steps of 20 ms)."""

    algo: str = param("ppo", kind="choice", choices=ALGOS)
    """``ppo`` or ``sac``."""
    residual: bool = param(True, kind="bool")
    """true: a residual on the expert (``QuadUnevenResidual-v0``); false: a policy from scratch on
    ``QuadUneven-v0`` in ``joint_pd`` mode (the reference RL users compare with; no expert in the loop,
    so ``expert_features`` and ``residual_penalty`` must be off)."""
    residual_level: str = param("torque", kind="choice", choices=RESIDUAL_LEVELS)
    """with ``residual: true``: ``torque`` (a residual on the expert's joint torques, ``QuadUnevenResidual-v0``:
    ``residual_*``) or ``plan`` (offsets of the expert's plan settings per gait cycle, ``QuadUnevenPlan-v0``:
    ``plan``; one env step is one cycle, ``timesteps`` count cycles)."""
    plan: dict[str, Any] = dataclasses.field(default_factory=dict)
    """with ``residual_level: plan``: fields of :class:`agents.rl.plan_config.PlanConfig` (the ranges of the plan
    action, e.g. ``{stride_range: 0.2}``; not ``expert`` nor ``max_control_steps``, which ``expert`` and
    ``max_episode_steps`` give); ``{}``: its defaults."""
    terrain: Any = "rough"
    """terrain kind, preset (``configs/terrain/``), YAML path or ``{kind: ..., params}`` mapping, or a list of
    them (a terrain mix: each episode on one drawn uniformly, :class:`agents.rl.terrain_mix.TerrainMixEnv`);
    a new surface is drawn at every reset."""
    randomization: Any = None
    """domain randomization of the training world: None (nominal), a preset of ``configs/randomization/``
    (``mild``, ``hard``), a YAML path or a mapping; drawn at every reset. Not applied by ``evaluate``,
    whose suites say their own world."""
    residual_penalty: float = param(0.0, "per mean(action^2)", lo=0.0, hi=1e6)
    """reward penalty on the residual: minus this x the mean over the 12 joints of action^2, every step."""
    expert_features: bool = param(True, kind="bool")
    """append the expert features (its plan now, the tracking error, its torques) to the observation."""
    timesteps: int = param(100_000, "steps", kind="int", lo=1)
    """total environment steps over all parallel envs."""
    time_limit_min: float = param(0.0, "min", lo=0.0, hi=1e6, hi_open=True)
    """wall-clock budget of the training loop (minutes); training stops there and saves; 0: none."""
    seed: int = param(0, kind="int", lo=0)
    """seed of the model and of the envs (env i gets seed + i; the evaluation env seed + 1000)."""
    n_envs: int = param(2, kind="int", lo=1, hi=1024)
    """parallel training envs."""
    vec_env: str = param("auto", kind="choice", choices=VEC_ENVS)
    """``auto``, ``dummy`` or ``subproc``."""
    residual_scale: float = param(0.1, "of the torque limit", lo=0.0, hi=1.0, lo_open=True)
    """residual torque per unit action as a fraction of the torque limit, in (0, 1]."""
    residual_legs: str = param("all", kind="choice", choices=RESIDUAL_LEGS)
    """``all``: every leg takes the residual; ``stance``: only a leg whose foot touches the ground, at each
    physics step (the residual then cannot move a swinging foot)."""
    residual_basis: str = param("torque_limit", kind="choice", choices=RESIDUAL_BASES)
    """``torque_limit``: residual torque = residual_scale x action x the motor limit; ``expert_torque``:
    residual_scale x action x the expert's own torque (per joint and physics step: a gain on the expert)."""
    expert: dict[str, Any] = dataclasses.field(default_factory=dict)
    """fields of :class:`agents.expert.ExpertConfig` for the expert under the residual, e.g. ``{adaptation: knee}``
    (adaptive gains on its knee torques, :mod:`agents.control.adaptation`: the residual then acts on the adapted
    torques); ``{}``: its defaults."""
    max_episode_steps: int = param(1000, "steps", kind="int", lo=1)
    """control steps per training episode (1000 = 20 s), with either residual level."""
    env_kwargs: dict[str, Any] = dataclasses.field(default_factory=dict)
    """extra QuadUneven-v0 arguments (e.g. ``reward_weights``), also used by ``quad-uneven evaluate``."""
    normalize_obs: bool = param(True, kind="bool")
    """VecNormalize the observations (statistics saved next to the model)."""
    normalize_reward: bool = param(True, kind="bool")
    """VecNormalize the rewards (training only)."""
    eval_freq: int = param(20_000, "steps", kind="int", lo=0)
    """env steps (all envs) between evaluations of the deterministic policy; 0: none."""
    eval_episodes: int = param(2, kind="int", lo=1)
    """episodes per evaluation."""
    checkpoint_freq: int = param(50_000, "steps", kind="int", lo=0)
    """env steps (all envs) between checkpoints; 0: none."""
    hyperparams: dict[str, Any] = dataclasses.field(default_factory=dict)
    """keyword arguments of the SB3 algorithm class (``learning_rate``, ``n_steps``, ...), each checked against
    :data:`agents.rl.hyperparams.HYPERPARAMS` (its type and range)."""
    policy_kwargs: dict[str, Any] = dataclasses.field(default_factory=dict)
    """SB3 ``policy_kwargs`` (``net_arch``, ``log_std_init``, ...), checked against
    :data:`agents.rl.hyperparams.POLICY_KWARGS`."""
    init_from: str | None = None
    """a warm start: a saved model (a training run's folder or its ``.zip``) whose weights, optimizer states and
    observation statistics this run starts from (:mod:`agents.rl.warm_start`); it must have been trained for the
    same env (``algo``, ``residual_*``, ``expert``, ``expert_features``, ``normalize_obs``, ``env_kwargs``). None: a
    new model."""
    init_log_std: float | None = param(None, "log(action units)", kind="float", lo=-20.0, hi=2.0, none_ok=True)
    """PPO: the log standard deviation of the policy's action noise at the start of training, set after the
    model is built and warm-started (a warm start otherwise keeps the saved model's, e.g. a distilled policy's
    untrained -1); None: the saved model's, or ``policy_kwargs.log_std_init`` for a new model."""
    freeze_obs_norm: bool = param(False, kind="bool")
    """keep the observation statistics fixed during training (those of ``init_from``): the policy's inputs keep
    the meaning its weights were trained for. Needs ``init_from`` and ``normalize_obs``; the rewards are still
    normalised."""
    critic_warmup_steps: int = param(0, "steps", kind="int", lo=0)
    """PPO: env steps (all envs) at the start of training during which only the value function learns (the
    actor's layers and log std are frozen): a warm-started actor then meets a critic that has seen its returns.
    Counted in ``timesteps``; 0: none."""

    def to_dict(self) -> dict[str, Any]:
        """A JSON-serialisable copy."""
        return dataclasses.asdict(self)

    def residual_config(self) -> ResidualConfig:
        """The residual env's :class:`~agents.rl.residual_config.ResidualConfig` of this run (``residual: true``).

        :raises ValueError: naming ``expert.field`` on a bad expert setting (:func:`validate` checks it first).
        """
        fields = ("residual_scale", "residual_legs", "residual_basis", "expert_features", "residual_penalty", "expert")
        return ResidualConfig.from_dict({name: getattr(self, name) for name in fields}, where="")

    def plan_config(self) -> PlanConfig:
        """The plan env's :class:`~agents.rl.plan_config.PlanConfig` of this run (``residual_level: plan``): ``plan``,
        with ``expert`` and ``max_episode_steps`` (as ``max_control_steps``).

        :raises ValueError: naming ``plan.field`` or ``expert.field`` (:func:`validate` checks them first).
        """
        raw = {**self.plan, "max_control_steps": self.max_episode_steps}
        config = PlanConfig.from_dict(raw, where="plan")
        return dataclasses.replace(config, expert=expert_config(self.expert, "expert"))

    def env_config(self) -> ResidualConfig | PlanConfig | None:
        """The settings of this run's env: a :class:`ResidualConfig` (torque level), a :class:`PlanConfig` (plan
        level), or None (``residual: false``, no expert)."""
        if not self.residual:
            return None
        return self.plan_config() if self.residual_level == "plan" else self.residual_config()


def _mapping(name: str, value: Any) -> dict[str, Any]:
    if value is None:
        return {}
    if not isinstance(value, Mapping) or not all(isinstance(k, str) for k in value):
        raise TrainConfigError(f"{name} must be a mapping with string keys, got {excerpt(value)}")
    return dict(value)


def validate(cfg: TrainConfig) -> TrainConfig:
    """``cfg`` checked field by field.

    :raises TrainConfigError: naming the first invalid field and its allowed values.
    """
    try:
        check_fields(cfg, where="")
    except ValueError as err:
        raise TrainConfigError(str(err)) from None
    terrains = terrain_list(cfg.terrain)
    if not terrains:
        raise TrainConfigError("terrain: the terrain mix needs at least one terrain")
    for i, spec in enumerate(terrains):
        try:
            parse_terrain_spec(spec)
        except ValueError as err:
            where = "terrain" if isinstance(cfg.terrain, str | Mapping) else f"terrain[{i}]"
            raise TrainConfigError(f"{where}: {err}") from None
    try:
        load_randomization(cfg.randomization)
    except ValueError as err:
        raise TrainConfigError(str(err)) from None
    env_kwargs = _mapping("env_kwargs", cfg.env_kwargs)
    bad = sorted(set(env_kwargs) & set(FORBIDDEN_ENV_KWARGS))
    if bad:
        raise TrainConfigError(f"env_kwargs may not set {bad} (the trainer and the residual env own them)")
    if not cfg.residual and (
        cfg.expert_features
        or cfg.residual_penalty
        or cfg.residual_legs != "all"
        or cfg.residual_basis != "torque_limit"
        or cfg.expert
    ):
        raise TrainConfigError(
            "residual: false trains from scratch without the expert, so expert_features must be false, "
            "residual_penalty 0, residual_legs 'all', residual_basis 'torque_limit' and expert {}, got "
            f"expert_features={cfg.expert_features}, residual_penalty={cfg.residual_penalty}, "
            f"residual_legs={excerpt(cfg.residual_legs)}, residual_basis={excerpt(cfg.residual_basis)}, "
            f"expert={excerpt(cfg.expert)}"
        )
    if cfg.init_from is not None and (not isinstance(cfg.init_from, str) or not cfg.init_from):
        raise TrainConfigError(
            f"init_from must be a path to a saved model (folder or .zip) or null, got {excerpt(cfg.init_from)}"
        )
    for name, value, unset in (
        ("init_log_std", cfg.init_log_std, None),
        ("critic_warmup_steps", cfg.critic_warmup_steps, 0),
    ):
        if value != unset and cfg.algo != "ppo":
            raise TrainConfigError(
                f"{name} applies to PPO only, got algo={excerpt(cfg.algo)} with {name}={excerpt(value)}"
            )
    if cfg.freeze_obs_norm and (cfg.init_from is None or not cfg.normalize_obs):
        raise TrainConfigError(
            "freeze_obs_norm keeps the observation statistics of init_from, so it needs init_from and "
            f"normalize_obs: true, got init_from={excerpt(cfg.init_from)}, normalize_obs={cfg.normalize_obs}"
        )
    expert = _mapping("expert", cfg.expert)
    if expert:
        try:
            expert_config(expert, "expert")
        except ValueError as err:
            raise TrainConfigError(str(err)) from None
    _check_plan_level(cfg)
    _check_sb3_arguments(cfg)
    if cfg.algo == "sac" and "log_std_init" in cfg.policy_kwargs and not cfg.hyperparams.get("use_sde"):
        warnings.warn(
            "policy_kwargs.log_std_init has no effect on SAC without use_sde (SB3): the untrained actor explores "
            "with a std of about 1",
            stacklevel=2,
        )
    return cfg


def _check_plan_level(cfg: TrainConfig) -> None:
    """``plan`` and the torque residual's fields checked against ``residual_level``.

    :raises TrainConfigError: naming the field that does not fit the level.
    """
    plan = _mapping("plan", cfg.plan)
    if cfg.residual_level != "plan" or not cfg.residual:
        if cfg.residual_level == "plan" or plan:
            raise TrainConfigError(
                "plan and residual_level: plan need residual: true and residual_level: plan, got "
                f"residual={cfg.residual}, residual_level={excerpt(cfg.residual_level)}, plan={excerpt(cfg.plan)}"
            )
        return
    torque = {"residual_scale": 0.1, "residual_legs": "all", "residual_basis": "torque_limit", "residual_penalty": 0.0}
    for name, default in torque.items():
        if getattr(cfg, name) != default:
            raise TrainConfigError(
                f"{name} applies to residual_level torque only: with residual_level plan it must be left at "
                f"{excerpt(default)}, got {excerpt(getattr(cfg, name))}"
            )
    if not cfg.expert_features:
        raise TrainConfigError("expert_features must be true with residual_level plan (its observation has them)")
    for name in ("expert", "max_control_steps"):
        if name in plan:
            raise TrainConfigError(
                f"plan.{name} is not accepted: the config's {'expert' if name == 'expert' else 'max_episode_steps'} "
                "gives it"
            )
    try:
        PlanConfig.from_dict(plan, where="plan")
    except ValueError as err:
        raise TrainConfigError(str(err)) from None


OWN_FIELDS = ("policy_kwargs", "env", "seed", "verbose", "device", "policy", "tensorboard_log")
"""SB3 arguments ``hyperparams`` may not set: the config fields or ``train`` options of that name set them."""


def _check_sb3_arguments(cfg: TrainConfig) -> None:
    """``hyperparams`` and ``policy_kwargs`` checked against the algorithm's tables (:mod:`agents.rl.hyperparams`),
    then the ones that depend on each other or on the budget: PPO's ``batch_size`` within a rollout of
    ``n_steps x n_envs`` steps, ``critic_warmup_steps`` and SAC's ``learning_starts`` below ``timesteps`` (else
    the actor never trains).

    :raises TrainConfigError: naming the field and its allowed values.
    """
    hyperparams = _mapping("hyperparams", cfg.hyperparams)
    policy_kwargs = _mapping("policy_kwargs", cfg.policy_kwargs)
    for key in OWN_FIELDS:
        if key in hyperparams:
            raise TrainConfigError(f"hyperparams may not set {key!r} (use the config field or option of that name)")
    try:
        check_hyperparams(cfg.algo, hyperparams)
        check_policy_kwargs(cfg.algo, policy_kwargs)
    except ValueError as err:
        raise TrainConfigError(str(err)) from None
    defaults = {p.name: p.default for p in HYPERPARAMS[cfg.algo]}
    value = {**defaults, **hyperparams}.__getitem__
    if cfg.algo == "ppo":
        rollout = value("n_steps") * cfg.n_envs
        if rollout < 2:
            raise TrainConfigError(
                f"hyperparams.n_steps must be an integer >= 2 with n_envs = 1 (SB3 needs a rollout of 2 steps or "
                f"more), got {value('n_steps')}"
            )
        if value("batch_size") > rollout:
            raise TrainConfigError(
                f"hyperparams.batch_size must be an integer in [2, {rollout}] (a minibatch of the rollout's n_steps x "
                f"n_envs = {value('n_steps')} x {cfg.n_envs} steps), got {value('batch_size')}"
            )
    if cfg.critic_warmup_steps >= cfg.timesteps:
        raise TrainConfigError(
            f"critic_warmup_steps must be an integer in [0, timesteps = {cfg.timesteps}) (the actor trains only after "
            f"it), got {cfg.critic_warmup_steps}"
        )
    if cfg.algo == "sac" and value("learning_starts") >= cfg.timesteps:
        raise TrainConfigError(
            f"hyperparams.learning_starts must be an integer in [0, timesteps = {cfg.timesteps}) (SAC learns only "
            f"after it), got {value('learning_starts')}"
        )


def terrain_list(terrain: Any) -> list[Any]:
    """The terrain specs of ``TrainConfig.terrain``: one spec, or the entries of a list (a mix)."""
    if isinstance(terrain, list | tuple):
        return list(terrain)
    return [terrain]


def terrain_label(spec: Any) -> str:
    """A short name of one terrain spec: the string itself, or a mapping's ``kind``."""
    return spec if isinstance(spec, str) else str(dict(spec).get("kind"))


def default_config_path(algo: str) -> Path:
    """``configs/rl/{algo}_residual.yaml``."""
    return RL_CONFIG_DIR / f"{algo}_residual.yaml"


def load_train_config(
    path: str | os.PathLike[str] | None = None, overrides: Mapping[str, Any] | None = None
) -> TrainConfig:
    """Read a training config and apply ``overrides`` (None values are ignored), then validate.

    :param path: a YAML file; None: :func:`default_config_path` of the ``algo`` override (default ppo).
    :param overrides: field -> value, e.g. from the command line.
    :raises TrainConfigError: on an unknown or invalid field, or an ``algo`` override that differs from the file's.
    """
    overrides = {k: v for k, v in (overrides or {}).items() if v is not None}
    if path is None:
        algo = overrides.get("algo", "ppo")
        if algo not in ALGOS:
            raise TrainConfigError(f"algo must be one of {list(ALGOS)}, got {excerpt(algo)}")
        path = default_config_path(algo)
    try:
        raw = read_yaml(path)
    except ValueError as err:
        raise TrainConfigError(f"config: {err}") from None
    names = {f.name for f in dataclasses.fields(TrainConfig)}
    unknown = sorted((set(raw) | set(overrides)) - names, key=str)
    if unknown:
        raise TrainConfigError(f"{clip(str(unknown[0]), 40)}: unknown field; allowed: {sorted(names)}")
    if "algo" in raw and "algo" in overrides and raw["algo"] != overrides["algo"]:
        raise TrainConfigError(
            f"algo: the config {str(path)!r} is for {raw['algo']!r}, got {overrides['algo']!r} "
            f"(use {default_config_path(overrides['algo']).name} or a config of that algo)"
        )
    return validate(TrainConfig(**{**raw, **overrides}))


__all__ = [
    "ALGOS",
    "RL_CONFIG_DIR",
    "TrainConfig",
    "TrainConfigError",
    "default_config_path",
    "load_train_config",
    "terrain_label",
    "terrain_list",
]
