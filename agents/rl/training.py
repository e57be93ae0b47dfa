"""``quad-uneven train``: a residual RL agent (PPO or SAC, Stable-Baselines3) on top of the scripted expert.

Typical use::

    quad-uneven train --algo ppo --terrain rough --timesteps 200000 --out runs/ppo_rough

Writes to ``--out`` DIR: ``model.zip`` (+ ``model_obs_norm.npz``), ``rl_meta.json`` (what
``quad-uneven evaluate`` needs to rebuild the residual env), ``train_config.json``,
``learning_curve.png``, ``train_summary.json``, ``monitor/*.monitor.csv`` (one line per training
episode), ``eval/evaluations.npz`` with ``best/best_model.zip``, and ``checkpoints/``. Details: docs/rl.md.
"""

from __future__ import annotations

import json
import math
import signal
import sys
import threading
import time
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback, CallbackList, CheckpointCallback, EvalCallback
from tqdm.auto import tqdm

from agents.interrupts import sigterm_as_keyboard_interrupt
from agents.outputs import output_dir
from agents.rl.config import TrainConfig, TrainConfigError, terrain_label, terrain_list
from agents.rl.learning_curve import plot_learning_curve
from agents.rl.model_io import write_metadata
from agents.rl.normalization import ObsNormalization, norm_path
from agents.rl.plan_env import PLAN_ENV_ID
from agents.rl.residual_env import RESIDUAL_ENV_ID
from agents.rl.terrain_mix import TerrainMixEnv
from agents.rl.vec_env import EVAL_SEED_OFFSET, SCRATCH_ENV_KWARGS, build_vec_env, make_train_env, normalize
from agents.rl.warm_start import check_init_model, warm_start
from quad_uneven_env.fields import excerpt

__all__ = [
    "TRAIN_OUTPUTS",
    "CheckpointWithStatsCallback",
    "CriticWarmupCallback",
    "EpisodeMetricsCallback",
    "ProgressCallback",
    "SaveObsNormalizationCallback",
    "WallClockLimitCallback",
    "actor_parameters",
    "save_obs_normalization",
    "set_log_std",
    "train",
]

TRAIN_OUTPUTS = (
    "model.zip",
    "model_obs_norm.npz",
    "model_vecnormalize.pkl",
    "rl_meta.json",
    "train_config.json",
    "train_summary.json",
    "learning_curve.png",
    "monitor",
    "eval",
    "best",
    "checkpoints",
)
"""Top-level names a training run writes in its ``--out`` (``--overwrite`` deletes what the manifest lists; with one of
these names present and no manifest, it refuses: :func:`agents.outputs.delete_recorded_outputs`)."""


class ProgressCallback(BaseCallback):
    """A tqdm bar over the env steps, with the mean return of the last 100 training episodes."""

    def __init__(self, enabled: bool = True) -> None:
        super().__init__()
        self.enabled = enabled
        self.bar: Any = None

    def _on_training_start(self) -> None:
        total = int(self.locals.get("total_timesteps", 0)) - self.model.num_timesteps
        self.bar = tqdm(total=total, unit="step", desc="training", disable=not self.enabled, smoothing=0.05)

    def _on_step(self) -> bool:
        self.bar.update(self.training_env.num_envs)
        buf = self.model.ep_info_buffer
        if buf and self.n_calls % 50 == 0:
            self.bar.set_postfix(ep_return=f"{np.mean([e['r'] for e in buf]):.1f}", episodes=len(buf), refresh=False)
        return True

    def _on_training_end(self) -> None:
        self.bar.close()


class WallClockLimitCallback(BaseCallback):
    """Stops training once ``minutes`` of wall-clock time have passed since training started."""

    def __init__(self, minutes: float) -> None:
        super().__init__()
        self.seconds = 60.0 * minutes
        self.start = 0.0
        self.reached = False

    def _on_training_start(self) -> None:
        self.start = time.perf_counter()

    def _on_step(self) -> bool:
        self.reached = time.perf_counter() - self.start >= self.seconds
        return not self.reached


def save_obs_normalization(model: Any, model_path: Path) -> Path | None:
    """Write ``model``'s observation statistics next to ``model_path`` as ``.npz`` (None without VecNormalize)."""
    vn = model.get_vec_normalize_env()
    if vn is None or not vn.norm_obs:
        return None
    return ObsNormalization.from_vecnormalize(vn).save(norm_path(model_path))


class SaveObsNormalizationCallback(BaseCallback):
    """Saves the observation statistics for the model at ``model_path`` (run by EvalCallback on a new best)."""

    def __init__(self, model_path: Path) -> None:
        super().__init__()
        self.model_path = model_path

    def _on_step(self) -> bool:
        save_obs_normalization(self.model, self.model_path)
        return True


class CheckpointWithStatsCallback(CheckpointCallback):
    """SB3's CheckpointCallback, with the observation statistics as ``.npz`` instead of a pickle."""

    def _on_step(self) -> bool:
        if self.n_calls % self.save_freq == 0:
            save_obs_normalization(self.model, Path(self._checkpoint_path(extension="zip")))
        return super()._on_step()


class EpisodeMetricsCallback(BaseCallback):
    """Logs our per-episode figures (:data:`EPISODE_KEYS`) through SB3's logger (TensorBoard, CSV, stdout).

    At every ended episode: ``episode/stability_mean`` and ``episode/stability_min`` (N m),
    ``episode/distance`` (m), ``episode/fall_rate`` and ``episode/divergence_rate`` (0-1, averaged over
    the episodes of the logging interval), ``episode/residual_torque`` (N m).
    """

    NAMES: ClassVar[dict[str, str]] = {
        "ep_stability_mean": "episode/stability_mean",
        "ep_stability_min": "episode/stability_min",
        "ep_distance": "episode/distance",
        "ep_fell": "episode/fall_rate",
        "ep_diverged": "episode/divergence_rate",
        "ep_residual_torque": "episode/residual_torque",
    }

    def _on_step(self) -> bool:
        for info in self.locals.get("infos", ()):
            if "ep_fell" not in info:
                continue
            for key, name in self.NAMES.items():
                value = float(info.get(key, math.nan))
                if math.isfinite(value):
                    self.logger.record_mean(name, value)
        return True


def _save_model(model: Any, out: Path) -> None:
    """``out/model.zip`` and its observation statistics; a second Ctrl-C while saving is ignored."""
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN) if _in_main_thread() else None
    try:
        model.save(out / "model.zip")
        save_obs_normalization(model, out / "model.zip")
    finally:
        if previous is not None:
            signal.signal(signal.SIGINT, previous)


def _in_main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


def _metadata(cfg: TrainConfig, robot: str) -> dict[str, Any]:
    """The ``rl_meta.json`` of a run of ``cfg`` on the robot named ``robot`` (:mod:`agents.rl.model_io`)."""
    import stable_baselines3

    common = {
        "algo": cfg.algo,
        "robot": robot,
        "terrain": cfg.terrain,
        "randomization": cfg.randomization if not isinstance(cfg.randomization, dict) else dict(cfg.randomization),
        "max_episode_steps": cfg.max_episode_steps,
        "normalize_obs": cfg.normalize_obs,
        "seed": cfg.seed,
        "stable_baselines3": stable_baselines3.__version__,
        **({} if cfg.init_from is None else {"init_from": cfg.init_from}),
    }
    if not cfg.residual:
        return {
            **common,
            "residual": False,
            "env_id": "QuadUneven-v0",
            "env_kwargs": {**SCRATCH_ENV_KWARGS, **cfg.env_kwargs},
            "expert_features": False,
        }
    if cfg.residual_level == "plan":
        plan = cfg.plan_config()
        if plan.expert.adaptation == "learned":
            from agents.control.adaptation.learned import estimator_digest

            common = {**common, "strength_estimator_sha256": estimator_digest()}
        recorded = {k: v for k, v in plan.to_dict().items() if k not in ("expert", "max_control_steps")}
        return {
            **common,
            "residual": True,
            "residual_level": "plan",
            "plan": recorded,
            "expert": plan.to_dict()["expert"],
            "env_id": PLAN_ENV_ID,
            "env_kwargs": dict(cfg.env_kwargs),
            "expert_features": True,
        }
    residual = cfg.residual_config()
    if residual.expert.adaptation == "learned":
        from agents.control.adaptation.learned import estimator_digest

        common = {**common, "strength_estimator_sha256": estimator_digest()}
    return {
        **common,
        "residual": True,
        "residual_scale": float(residual.residual_scale),
        "residual_legs": residual.residual_legs,
        "residual_basis": residual.residual_basis,
        "residual_penalty": float(residual.residual_penalty),
        "expert": residual.to_dict()["expert"],
        "env_id": RESIDUAL_ENV_ID,
        "env_kwargs": dict(cfg.env_kwargs),
        "expert_features": bool(cfg.expert_features),
    }


def _terrain_label(terrain: Any) -> str:
    return " + ".join(terrain_label(s) for s in terrain_list(terrain))


def _make_model(cfg: TrainConfig, venv: Any, tensorboard: Path | None = None) -> Any:
    import stable_baselines3

    cls = getattr(stable_baselines3, cfg.algo.upper())
    try:
        model = cls(
            "MlpPolicy",
            venv,
            seed=cfg.seed,
            device="cpu",
            verbose=0,
            tensorboard_log=None if tensorboard is None else str(tensorboard),
            policy_kwargs=dict(cfg.policy_kwargs),
            **cfg.hyperparams,
        )
    except TypeError as err:  # an unknown keyword of the algorithm or of its policy
        raise TrainConfigError(f"hyperparams/policy_kwargs: {err}") from None
    if cfg.residual:
        _zero_mean_action(model)
    return model


def _zero_mean_action(model: Any) -> None:
    """Zero the layer that outputs the mean action (PPO ``action_net``, SAC ``actor.mu``): weights and bias.

    The untrained deterministic agent then commands 0 on every joint: it is exactly the expert. The weights
    still get gradients, since the layer's inputs are not zero.
    """
    import torch

    head = getattr(model.policy, "action_net", None)
    if head is None:
        head = model.actor.mu
    if isinstance(head, torch.nn.Sequential):  # SAC with use_sde: the linear layer, then a Hardtanh
        head = head[0]
    with torch.no_grad():
        head.weight.zero_()
        head.bias.zero_()


def set_log_std(model: Any, value: float) -> None:
    """Set every entry of a PPO policy's ``log_std`` (the log standard deviation of its action noise) to ``value``."""
    import torch

    with torch.no_grad():
        model.policy.log_std.fill_(value)


def actor_parameters(model: Any) -> list[Any]:
    """The parameters of a PPO policy's actor: its hidden layers, action head and log std (not the critic's)."""
    policy = model.policy
    return [
        *policy.mlp_extractor.policy_net.parameters(),
        *policy.action_net.parameters(),
        policy.log_std,
    ]


class CriticWarmupCallback(BaseCallback):
    """Freezes the actor (:func:`actor_parameters`) for the PPO updates on the first ``steps`` env steps: they
    train the value function only.

    The actor thaws at the first rollout end past ``steps`` (before that rollout's update).
    """

    def __init__(self, steps: int) -> None:
        super().__init__()
        self.steps = steps
        self.frozen = False

    def _set(self, frozen: bool) -> None:
        for p in actor_parameters(self.model):
            p.requires_grad_(not frozen)
        self.frozen = frozen

    def _on_training_start(self) -> None:
        self._set(self.model.num_timesteps < self.steps)

    def _on_step(self) -> bool:
        return True

    def _on_rollout_end(self) -> None:
        if self.frozen and self.model.num_timesteps > self.steps:
            self._set(False)


def _callbacks(cfg: TrainConfig, out: Path, progress: bool) -> tuple[list[BaseCallback], Any]:
    callbacks: list[BaseCallback] = [ProgressCallback(progress), EpisodeMetricsCallback()]
    if cfg.critic_warmup_steps > 0:
        callbacks.append(CriticWarmupCallback(cfg.critic_warmup_steps))
    if cfg.time_limit_min > 0:
        callbacks.append(WallClockLimitCallback(cfg.time_limit_min))
    eval_env = None
    if cfg.eval_freq > 0:
        eval_env = normalize(
            build_vec_env(cfg, 1, cfg.seed + EVAL_SEED_OFFSET, None, vec_env="dummy"), cfg, training=False
        )
        callbacks.append(
            EvalCallback(
                eval_env,
                n_eval_episodes=cfg.eval_episodes,
                eval_freq=max(1, cfg.eval_freq // cfg.n_envs),
                log_path=str(out / "eval"),
                best_model_save_path=str(out / "best"),
                deterministic=True,
                callback_on_new_best=SaveObsNormalizationCallback(out / "best" / "best_model.zip"),
                verbose=0,
            )
        )
    if cfg.checkpoint_freq > 0:
        callbacks.append(
            CheckpointWithStatsCallback(
                save_freq=max(1, cfg.checkpoint_freq // cfg.n_envs),
                save_path=str(out / "checkpoints"),
                name_prefix="model",
            )
        )
    return callbacks, eval_env


def _preflight_env(cfg: TrainConfig) -> str:
    """Build one training env in this process, so that an env argument the env refuses (an unknown
    robot, a bad ``env_kwargs`` value) is reported before ``out`` is touched, not as a worker's traceback.

    :return: the name of the env's robot.
    :raises TrainConfigError: naming ``env_kwargs`` and what the env refused.
    """
    try:
        env = make_train_env(
            cfg.terrain, cfg.max_episode_steps, dict(cfg.env_kwargs), cfg.randomization,
            cfg.env_config(),
        )  # fmt: skip
    except (ValueError, TypeError) as err:
        raise TrainConfigError(f"env_kwargs {excerpt(cfg.env_kwargs)}: {err}") from None
    base = env.unwrapped
    if isinstance(base, TerrainMixEnv):  # one env per terrain, all on the config's robot
        base = base.envs[0].unwrapped
    robot = base.robot.name
    env.close()
    return robot


def train(
    cfg: TrainConfig,
    out: str | Path,
    progress: bool = True,
    tensorboard: str | Path | None = None,
    overwrite: bool = False,
) -> dict[str, Any]:
    """Train a residual agent with ``cfg``; write the model, its metadata and the learning curve to ``out``.

    Numerical divergence or a fall ends an episode (``info["diverged"]``), never the run. Ctrl-C, SIGTERM
    or the ``time_limit_min`` budget stops training early and still saves the model (``interrupted`` and
    ``time_limit_reached`` in the summary).

    :param cfg: a validated :class:`TrainConfig` (see :func:`load_train_config`).
    :param out: output directory (created), checked before anything starts: a non-empty one is refused
        unless ``overwrite``, so a new model is never paired with an older run's checkpoints.
    :param progress: show a progress bar.
    :param tensorboard: directory for TensorBoard logs (SB3's scalars plus :class:`EpisodeMetricsCallback`'s),
        one run subfolder per training run; None: none.
    :param overwrite: delete an earlier run's outputs in ``out`` (``TRAIN_OUTPUTS``; other files are kept).
    :return: the ``train_summary.json`` content: ``timesteps`` done, ``wall_time`` (s), ``steps_per_s``,
        ``episodes``, ``mean_return``, ``mean_stability_index`` (N m), ``mean_distance`` (m), ``fall_rate``
        (last 20 training episodes), ``interrupted``, ``time_limit_reached``, ``model`` path.
    :raises TrainConfigError: on hyperparameters the algorithm does not accept, or an ``init_from`` model that
        does not fit the config (:mod:`agents.rl.warm_start`) or lies in ``out``.
    :raises OutputError: if ``out`` is a file, cannot be created, or is not empty without ``overwrite``.
    """
    import torch

    meta = _metadata(cfg, _preflight_env(cfg))
    init = None
    if cfg.init_from is not None:
        init = check_init_model(cfg.init_from, meta)
        if init[0].resolve().is_relative_to(Path(out).resolve()):
            raise TrainConfigError(f"init_from: {init[0]} lies in --out {str(out)!r}, whose outputs this run replaces")
    with output_dir(out, "train", TRAIN_OUTPUTS, overwrite=overwrite) as manifest:
        out = manifest.out
        torch.set_num_threads(1)  # small networks: threads only contend with the env processes on 2 cores
        (out / "train_config.json").write_text(json.dumps(cfg.to_dict(), indent=2))
        for folder in (out, out / "checkpoints", out / "best"):
            write_metadata(folder, meta)

        venv = normalize(build_vec_env(cfg, cfg.n_envs, cfg.seed, out / "monitor"), cfg, training=True)
        eval_env = None
        try:
            model = _make_model(cfg, venv, None if tensorboard is None else Path(tensorboard))
            if init is not None:
                warm_start(model, *init, freeze_obs_norm=cfg.freeze_obs_norm)
            if cfg.init_log_std is not None:
                set_log_std(model, cfg.init_log_std)
            callbacks, eval_env = _callbacks(cfg, out, progress)
            wall0, interrupted = time.perf_counter(), False
            with sigterm_as_keyboard_interrupt():
                try:
                    model.learn(
                        total_timesteps=cfg.timesteps,
                        callback=CallbackList(callbacks),
                        tb_log_name=f"{cfg.algo}_{out.name}",
                    )
                except KeyboardInterrupt:
                    interrupted = True
                    print("\ninterrupted: saving the model trained so far", file=sys.stderr)
                wall = time.perf_counter() - wall0
                _save_model(model, out)
        finally:
            venv.close()
            if eval_env is not None:
                eval_env.close()

        curve = plot_learning_curve(
            out / "monitor",
            out / "eval" / "evaluations.npz",
            out / "learning_curve.png",
            title=(f"residual {cfg.algo.upper()}" if cfg.residual else f"{cfg.algo.upper()} from scratch (joint_pd)")
            + f" on {_terrain_label(cfg.terrain)}"
            + ("" if cfg.randomization is None else f", randomization {cfg.randomization}")
            + (
                ""
                if not cfg.residual
                else " (plan level)"
                if cfg.residual_level == "plan"
                else f" (scale {cfg.residual_scale})"
            ),
        )
        summary = {
            "timesteps": int(model.num_timesteps),
            "wall_time": wall,
            "steps_per_s": model.num_timesteps / wall if wall > 0 else None,
            **{k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in curve.items()},
            "interrupted": interrupted,
            "time_limit_reached": any(getattr(c, "reached", False) for c in callbacks),
            "init_timesteps": 0 if init is None else init[1],
            "model": str(out / "model.zip"),
        }
        (out / "train_summary.json").write_text(json.dumps(summary, indent=2))
        return summary
