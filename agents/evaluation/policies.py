"""Policies the evaluation can run, by name, and the environment arguments each one needs."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import gymnasium as gym

from agents.policy import Policy, ZeroActionPolicy
from quad_uneven_env import ENV_ID
from quad_uneven_env.fields import excerpt

POLICY_ENV_KWARGS: dict[str, dict[str, Any]] = {
    # The zero action in joint_pd mode holds the standing pose.
    "zero": {"action_mode": "joint_pd"},
    # The expert installs its computed-torque controller as the env's physics-rate hook.
    "expert": {"action_mode": "torque"},
}
"""QuadUneven-v0 keyword arguments per named policy (the one table; user env kwargs override it). A learned agent
runs in the env it was trained in (:func:`agents.rl.model_io.make_model_env`)."""

NAMED_POLICIES = ("zero", "expert")
"""Policy names; anything else must be the path of an SB3 model ``.zip``."""

SB3_ALGOS = ("ppo", "sac")
"""Algorithms an SB3 model file may be loaded with (``--algo``)."""


class PolicyError(ValueError):
    """A policy name, model file or algorithm that cannot be used."""


def policy_kind(name: str) -> str:
    """``"zero"``, ``"expert"``, ``"sb3"`` (a path to a ``.zip`` model) or ``"onnx"`` (a ``quad-uneven export`` file).

    :raises PolicyError: for anything else.
    """
    if name in NAMED_POLICIES:
        return name
    if str(name).endswith(".zip"):
        return "sb3"
    if str(name).endswith(".onnx"):
        return "onnx"
    raise PolicyError(
        f"policy must be one of {list(NAMED_POLICIES)}, the path of an SB3 model .zip or of an exported .onnx, got "
        f"{excerpt(name)}"
    )


def make_policy_env(name: str, **kwargs: Any) -> gym.Env:
    """The env the policy ``name`` runs in, with ``kwargs`` over its own arguments.

    ``"zero"`` and ``"expert"``: ``QuadUneven-v0`` with their :data:`POLICY_ENV_KWARGS` row. An SB3 model: the env
    it was trained in, rebuilt from its ``rl_meta.json`` (:func:`agents.rl.model_io.make_model_env`: for a residual
    model ``QuadUnevenResidual-v0`` with the expert and residual of its training).

    :raises PolicyError: on an unknown name or unreadable model metadata; the env's ``ValueError`` or
        ``TypeError`` on a bad argument.
    """
    kind = policy_kind(name)
    if kind == "onnx":
        from agents.evaluation.onnx_policy import OnnxPolicyError, make_onnx_env

        try:
            return make_onnx_env(name, **kwargs)
        except OnnxPolicyError as err:
            raise PolicyError(str(err)) from None
    if kind != "sb3":
        return gym.make(ENV_ID, **{**POLICY_ENV_KWARGS[kind], **kwargs})
    from agents.rl.model_io import ModelError, make_model_env

    try:
        return make_model_env(name, **kwargs)
    except ModelError as err:
        raise PolicyError(str(err)) from None


def _expert(env: gym.Env, expert_config: Mapping[str, Any] | None) -> Policy:
    from agents.expert import ExpertConfig, attach_expert  # deferred: compiling the kernels takes seconds

    # the env's robot's settings (the paper's robot: the defaults), then the given fields
    config = ExpertConfig.for_robot(env.unwrapped.robot, expert_config) if expert_config else None
    return attach_expert(env, config)


def expert_model_of(policy: Any) -> str | None:
    """``"nominal"`` or ``"oracle"``: the model the expert in ``policy`` plans and controls with (None: no expert)."""
    expert = getattr(policy, "expert", policy)
    return getattr(getattr(expert, "config", None), "model", None)


def model_algo(path: str | Path, algo: str | None = None) -> str:
    """The SB3 class an SB3 model file is loaded with: ``algo``, or (None) the one its ``rl_meta.json`` records,
    else ``"ppo"`` (a model folder without metadata).

    :raises PolicyError: on an ``algo`` not in :data:`SB3_ALGOS`, or unreadable metadata.
    """
    if algo is None:
        from agents.rl.model_io import ModelError, read_metadata

        try:
            meta = read_metadata(path)
        except ModelError as err:
            raise PolicyError(str(err)) from None
        algo = (meta or {}).get("algo") or "ppo"
    if algo not in SB3_ALGOS:
        raise PolicyError(f"algo must be one of {list(SB3_ALGOS)}, got {excerpt(algo)}")
    return algo


def _sb3(path: str, env: gym.Env, algo: str | None, allow_pickle: bool) -> Policy:
    algo = model_algo(path, algo)
    if not Path(path).is_file():
        raise PolicyError(f"policy: SB3 model file {path!r} does not exist")
    import torch

    from agents.rl.model_io import ModelError, load_sb3_policy

    # One intra-op thread: the policy MLP is tiny, and with several threads each predict contends with the
    # simulation (and with the other episode workers) for the cores.
    torch.set_num_threads(1)
    try:
        return load_sb3_policy(path, env, algo, allow_pickle)
    except ModelError as err:
        raise PolicyError(str(err)) from None


def make_policy(
    name: str,
    env: gym.Env,
    algo: str | None = None,
    allow_pickle: bool = False,
    expert_config: Mapping[str, Any] | None = None,
) -> Policy:
    """A policy with SB3's ``predict`` for ``env`` (built by :func:`make_policy_env` of ``name``).

    :param name: ``"zero"`` (the zero action), ``"expert"`` (``agents.expert.attach_expert(env)``: the expert,
        installed as the physics-rate controller of ``env.unwrapped``), or the path of an SB3 model ``.zip``, loaded
        for the env it was trained in, which ``env`` must be (:func:`agents.rl.model_io.load_sb3_policy`: its robot,
        and for a residual model ``QuadUnevenResidual-v0`` with the expert and residual of its training), or of an
        ONNX file of ``quad-uneven export`` (:class:`agents.evaluation.onnx_policy.OnnxPolicy`, not a residual one).
    :param algo: ``"ppo"`` or ``"sac"``: the class an SB3 model file is loaded with (None: :func:`model_algo`).
    :param allow_pickle: unpickle files of the model folder (trusted files only; default: refused).
    :param expert_config: fields of :class:`agents.expert.ExpertConfig` for ``"expert"`` (e.g.
        ``{"model": "oracle"}``); None: the defaults.
    :raises PolicyError: on an unknown name, a missing model file or expert module, an unknown algo, or an env the
        model was not trained in.
    """
    kind = policy_kind(name)
    if kind == "zero":
        return ZeroActionPolicy(env.action_space)
    if kind == "expert":
        return _expert(env, expert_config)
    if kind == "onnx":
        from agents.evaluation.onnx_policy import OnnxPolicy, OnnxPolicyError

        try:
            return OnnxPolicy(name, env)
        except OnnxPolicyError as err:
            raise PolicyError(str(err)) from None
    return _sb3(name, env, algo, allow_pickle)
