"""The Stable-Baselines3 arguments a training config may set, each with its type and allowed range.

``hyperparams`` of a training config are keyword arguments of ``stable_baselines3.PPO`` or ``SAC``, and
``policy_kwargs`` those of its policy class. Each one the project accepts is declared here as a
:class:`~quad_uneven_env.fields.Param` (one table per algorithm), so that a bad value is refused before SB3 sees
it, in one line naming the field (``hyperparams.gamma must be a number in [0, 1], got 2``), instead of training
quietly with it (a discount above 1, a negative clip range) or failing inside SB3 (an ``AssertionError`` on
``batch_size: 0``, a ``TypeError`` on ``learning_rate: abc``). Arguments that take Python objects (schedules,
classes, noise processes, buffers) cannot come from YAML and are not accepted; those the trainer sets itself
(``seed``, ``device``, ``verbose``, ``tensorboard_log``, ``policy_kwargs``) neither.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Mapping
from typing import Any

from quad_uneven_env.fields import Param, excerpt


def _p(name: str, default: Any, doc: str, **check: Any) -> Param:
    return Param(name, default, "-", doc, **check)


_SHARED = (
    _p("learning_rate", 3e-4, "Adam step size", lo=0.0, hi=1.0, lo_open=True),
    _p("gamma", 0.99, "discount factor", lo=0.0, hi=1.0),
    _p("use_sde", False, "state-dependent exploration (gSDE)", kind="bool"),
    _p("sde_sample_freq", -1, "control steps between gSDE noise draws (-1: once per rollout)", kind="int", lo=-1),
    _p("stats_window_size", 100, "episodes averaged in SB3's logs", kind="int", lo=1),
)

PPO_HYPERPARAMS: tuple[Param, ...] = (
    *_SHARED,
    _p("n_steps", 2048, "control steps per env and rollout (n_steps x n_envs >= 2)", kind="int", lo=1),
    _p("batch_size", 64, "minibatch size (samples), at most n_steps x n_envs", kind="int", lo=2),
    _p("n_epochs", 10, "passes over each rollout", kind="int", lo=1),
    _p("gae_lambda", 0.95, "GAE bias-variance trade-off", lo=0.0, hi=1.0),
    _p("clip_range", 0.2, "PPO's clip of the probability ratio, 1 +- this", lo=0.0, hi=1.0, lo_open=True),
    _p("clip_range_vf", None, "clip of the value update (null: none)", lo=0.0, lo_open=True, none_ok=True),
    _p("normalize_advantage", True, "normalise advantages per minibatch", kind="bool"),
    _p("ent_coef", 0.0, "entropy bonus weight", lo=0.0),
    _p("vf_coef", 0.5, "value loss weight", lo=0.0),
    _p("max_grad_norm", 0.5, "gradient norm clip", lo=0.0, lo_open=True),
    _p("target_kl", None, "stop an update's epochs past this KL (null: never)", lo=0.0, lo_open=True, none_ok=True),
)
"""``stable_baselines3.PPO`` keyword arguments a config may set."""

SAC_HYPERPARAMS: tuple[Param, ...] = (
    *_SHARED,
    _p("batch_size", 256, "minibatch size (samples)", kind="int", lo=1),
    _p("buffer_size", 1_000_000, "replay buffer capacity (transitions)", kind="int", lo=1),
    _p("learning_starts", 100, "env steps of random actions before learning", kind="int", lo=0),
    _p("tau", 0.005, "target network update rate", lo=0.0, hi=1.0, lo_open=True),
    _p("optimize_memory_usage", False, "SB3's memory-efficient replay buffer", kind="bool"),
    _p("n_steps", 1, "n-step returns", kind="int", lo=1),
    _p("target_update_interval", 1, "gradient steps between target updates", kind="int", lo=1),
    _p("use_sde_at_warmup", False, "gSDE instead of uniform actions before learning_starts", kind="bool"),
)
"""``stable_baselines3.SAC`` keyword arguments a config may set besides :data:`SAC_SPECIAL`."""

SAC_SPECIAL = ("train_freq", "gradient_steps", "ent_coef", "target_entropy")
"""SAC arguments checked by :func:`_check_sac_special` (not a single number type)."""

_POLICY_SHARED = (
    _p("log_std_init", 0.0, "initial log std of the action noise", lo=-20.0, hi=2.0),
    _p("use_expln", False, "gSDE: expln instead of exp for a positive std", kind="bool"),
    _p("normalize_images", True, "divide image observations by 255 (none here)", kind="bool"),
)

PPO_POLICY_KWARGS: tuple[Param, ...] = (
    *_POLICY_SHARED,
    _p("ortho_init", True, "orthogonal initialisation", kind="bool"),
    _p("share_features_extractor", True, "actor and critic share the features extractor", kind="bool"),
    _p("full_std", True, "gSDE: a std per input and action", kind="bool"),
    _p("squash_output", False, "tanh on the action (gSDE)", kind="bool"),
)
"""``policy_kwargs`` of PPO's ``ActorCriticPolicy`` a config may set (besides ``net_arch``)."""

SAC_POLICY_KWARGS: tuple[Param, ...] = (
    *_POLICY_SHARED,
    _p("clip_mean", 2.0, "gSDE: clip of the mean action before tanh", lo=0.0, lo_open=True),
    _p("n_critics", 2, "Q networks", kind="int", lo=1, hi=16),
    _p("share_features_extractor", False, "actor and critics share the features extractor", kind="bool"),
)
"""``policy_kwargs`` of SAC's ``SACPolicy`` a config may set (besides ``net_arch``)."""

NET_ARCH_KEYS = {"ppo": ("pi", "vf"), "sac": ("pi", "qf")}
"""The keys of a ``net_arch`` mapping per algorithm (actor, critic)."""

MAX_LAYER_WIDTH = 65_536
"""Widest hidden layer a ``net_arch`` may give (units)."""

HYPERPARAMS = {"ppo": PPO_HYPERPARAMS, "sac": SAC_HYPERPARAMS}
POLICY_KWARGS = {"ppo": PPO_POLICY_KWARGS, "sac": SAC_POLICY_KWARGS}


def check_hyperparams(algo: str, hyperparams: Mapping[str, Any]) -> None:
    """Refuse a ``hyperparams`` entry that ``algo``'s table does not declare or whose value it does not allow.

    :raises ValueError: ``hyperparams.<name> must be <allowed>, got <value>`` or ``hyperparams.<name>: unknown ...``.
    """
    table = {p.name: p for p in HYPERPARAMS[algo]}
    special = SAC_SPECIAL if algo == "sac" else ()
    for name, value in hyperparams.items():
        if name in special:
            _check_sac_special(name, value)
        elif name in table:
            table[name].check(value, "hyperparams")
        else:
            allowed = sorted([*table, *special])
            raise ValueError(
                f"hyperparams.{name}: not an SB3 {algo.upper()} argument a config sets; allowed: {allowed}"
            )


def check_policy_kwargs(algo: str, policy_kwargs: Mapping[str, Any]) -> None:
    """Refuse a ``policy_kwargs`` entry that ``algo``'s policy table does not declare or allow (``net_arch``: a list
    of layer widths, or a mapping of :data:`NET_ARCH_KEYS` to such lists).

    :raises ValueError: naming ``policy_kwargs.<name>`` and what it must be.
    """
    table = {p.name: p for p in POLICY_KWARGS[algo]}
    for name, value in policy_kwargs.items():
        if name == "net_arch":
            _check_net_arch(algo, value)
        elif name in table:
            table[name].check(value, "policy_kwargs")
        else:
            allowed = sorted(["net_arch", *table])
            raise ValueError(f"policy_kwargs.{name}: not a policy argument a config sets; allowed: {allowed}")


def _check_net_arch(algo: str, value: Any) -> None:
    keys = NET_ARCH_KEYS[algo]
    allowed = f"a list of layer widths (integers in [1, {MAX_LAYER_WIDTH}]) or a mapping of {list(keys)} to such lists"
    layers = [value] if isinstance(value, list) else list(value.values()) if isinstance(value, Mapping) else None
    ok = layers is not None and all(isinstance(v, list) and all(_is_width(w) for w in v) for v in layers)
    if isinstance(value, Mapping) and not (value and set(value) <= set(keys)):
        ok = False
    if not ok:
        raise ValueError(f"policy_kwargs.net_arch must be {allowed}, got {excerpt(value)}")


def _is_width(w: Any) -> bool:
    return isinstance(w, int) and not isinstance(w, bool) and 1 <= w <= MAX_LAYER_WIDTH


def _is_number(v: Any) -> bool:
    return isinstance(v, numbers.Real) and not isinstance(v, bool) and math.isfinite(v)


def _check_sac_special(name: str, value: Any) -> None:
    """``train_freq`` (an integer >= 1 or ``[n, "step" | "episode"]``), ``gradient_steps`` (an integer >= 1, or -1:
    as many as env steps per rollout), ``ent_coef`` (a number >= 0, ``"auto"`` or ``"auto_<initial value > 0>"``),
    ``target_entropy`` (a number or ``"auto"``)."""
    if name == "gradient_steps":
        if not (isinstance(value, int) and not isinstance(value, bool) and (value >= 1 or value == -1)):
            raise ValueError(f"hyperparams.gradient_steps must be an integer >= 1 or -1, got {excerpt(value)}")
    elif name == "train_freq":
        pair = value if isinstance(value, list | tuple) and len(value) == 2 else (value, "step")
        ok = isinstance(pair[0], int) and not isinstance(pair[0], bool) and pair[0] >= 1
        if not (ok and pair[1] in ("step", "episode")):
            raise ValueError(
                f"hyperparams.train_freq must be an integer >= 1 or [n, 'step' or 'episode'], got {excerpt(value)}"
            )
    elif name == "ent_coef":
        if isinstance(value, str) and (value == "auto" or (value.startswith("auto_") and _positive(value[5:]))):
            return
        if not (_is_number(value) and value >= 0):
            raise ValueError(
                "hyperparams.ent_coef must be a number >= 0, 'auto' or 'auto_<initial value > 0>', "
                f"got {excerpt(value)}"
            )
    elif not (value == "auto" or _is_number(value)):
        raise ValueError(f"hyperparams.target_entropy must be a finite number or 'auto', got {excerpt(value)}")


def _positive(text: str) -> bool:
    try:
        v = float(text)
    except ValueError:
        return False
    return math.isfinite(v) and v > 0


__all__ = [
    "HYPERPARAMS",
    "NET_ARCH_KEYS",
    "POLICY_KWARGS",
    "PPO_HYPERPARAMS",
    "PPO_POLICY_KWARGS",
    "SAC_HYPERPARAMS",
    "SAC_POLICY_KWARGS",
    "check_hyperparams",
    "check_policy_kwargs",
]
