"""A trained agent's deterministic policy as an ONNX file, observation normalisation folded in.

``quad-uneven export --policy DIR/model.zip --out policy.onnx`` writes a graph ``obs (N, n_obs) float32 ->
action (N, 12) float32`` that computes exactly what :class:`agents.rl.model_io.SB3Policy.predict` returns
(normalisation, the network, and SB3's action post-processing: PPO clips to the action bounds, SAC
squashes with tanh and rescales), the format Isaac Lab, MuJoCo Playground and mjlab users deploy. The
metadata travels in the ONNX ``metadata_props``: ``observation_layout`` (JSON name -> [start, stop]),
``action_low``/``action_high``, ``residual``, ``residual_scale``, ``residual_legs`` and ``residual_basis`` (a
residual action is added to the expert's torques as ``residual_scale x action x torque_limit``, or with
``residual_basis`` "expert_torque" as ``residual_scale x action x`` the expert's torque; with ``residual_legs``
"stance" only on the legs whose foot touches the ground), ``expert`` (the expert's config: its fields that
differ from :class:`agents.expert.ExpertConfig`'s defaults; with ``adaptation`` "knee" or "learned" its torques are
first multiplied by the adaptive gains of :mod:`agents.control.adaptation`, which a deployment must run too),
``torque_limit`` (N m), ``algo``, ``env_id``, ``env_kwargs``, ``robot`` (the name of the robot the policy acts
for), ``observation_normalization`` ("folded" or "none").
"""

from __future__ import annotations

import contextlib
import json
import logging
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from agents.rl.model_io import (
    META_DEFAULTS,
    META_FILE,
    ModelError,
    check_model_env,
    load_obs_normalization,
    load_sb3_model,
    make_model_env,
    read_metadata,
)


def _policy_module(model: Any, norm: Any, low: np.ndarray, high: np.ndarray) -> Any:
    """A torch module: normalised observation -> SB3's deterministic action, post-processed as ``predict`` does."""
    import torch

    policy = model.policy
    if getattr(policy, "use_sde", False):
        raise ModelError("policy: gSDE policies are not exported")

    class DeterministicPolicy(torch.nn.Module):
        def __init__(self) -> None:
            super().__init__()
            self.policy = policy
            f32 = torch.float32
            self.register_buffer("low", torch.as_tensor(low, dtype=f32))
            self.register_buffer("high", torch.as_tensor(high, dtype=f32))
            n_obs = policy.observation_space.shape[0]
            self.normalized = norm is not None
            mean = np.zeros(n_obs) if norm is None else norm.mean
            scale = np.ones(n_obs) if norm is None else 1.0 / np.sqrt(norm.var + norm.epsilon)
            self.register_buffer("mean", torch.as_tensor(mean, dtype=f32))
            self.register_buffer("scale", torch.as_tensor(scale, dtype=f32))
            self.clip = 0.0 if norm is None else float(norm.clip)

        def forward(self, obs: torch.Tensor) -> torch.Tensor:
            x = obs
            if self.normalized:
                x = torch.clamp((x - self.mean) * self.scale, -self.clip, self.clip)
            if hasattr(self.policy, "action_net"):  # PPO / A2C: Gaussian mean, then clipped to the bounds
                features = self.policy.extract_features(x, self.policy.pi_features_extractor)
                action = self.policy.action_net(self.policy.mlp_extractor.forward_actor(features))
                return torch.maximum(torch.minimum(action, self.high), self.low)
            actor = self.policy.actor  # SAC: tanh-squashed mean, rescaled to the bounds
            features = actor.extract_features(x, actor.features_extractor)
            squashed = torch.tanh(actor.mu(actor.latent_pi(features)))
            return self.low + 0.5 * (squashed + 1.0) * (self.high - self.low)

    return DeterministicPolicy().eval()


@contextlib.contextmanager
def _quiet_exporter() -> Iterator[None]:
    """torch's ONNX exporter without its notes on optional torchvision operators (never in a policy network) and
    the deprecation warnings of its own internals: nothing a user of ``export`` can act on."""
    registration = logging.getLogger("torch.onnx._internal.exporter._registration")
    level = registration.level
    registration.setLevel(logging.ERROR)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", FutureWarning)
            warnings.simplefilter("ignore", DeprecationWarning)
            yield
    finally:
        registration.setLevel(level)


def export_onnx(
    model_path: str | Path,
    out: str | Path,
    algo: str | None = None,
    allow_pickle: bool = False,
    out_field: str = "out",
) -> Path:
    """Write the ONNX file of the SB3 model ``model_path`` (with its ``rl_meta.json`` and statistics) to ``out``.

    The model folder is read and checked by :mod:`agents.rl.model_io`, and the graph is traced in the env the model
    was trained in (:func:`~agents.rl.model_io.make_model_env`, on its robot); ``out`` is written once, at the end.

    :param algo: ``"ppo"`` or ``"sac"`` (default: the metadata's, else ppo).
    :param allow_pickle: load pickled files of older runs (trusted files only; see :mod:`agents.rl.model_io`).
    :param out_field: the name messages give ``out`` (the CLI's ``--out``).
    :return: the path written.
    :raises ModelError: on an unusable model folder, or ``out`` that cannot be written (naming ``out_field``).
    """
    import onnx
    import torch

    model_path, out = Path(model_path), Path(out)
    if not model_path.is_file():
        raise ModelError(f"policy: SB3 model file {str(model_path)!r} does not exist")
    meta = read_metadata(model_path) or {}
    algo = algo or meta.get("algo") or "ppo"
    try:
        env = make_model_env(model_path)
    except (ValueError, TypeError) as err:  # the env's own checks of the recorded arguments
        msg = str(err).split(" was raised from the environment creator")[0]
        raise ModelError(f"policy: {model_path.parent / META_FILE}: env_kwargs: {msg}") from None
    try:
        if meta:
            check_model_env(meta, env, model_path)
        model = load_sb3_model(model_path, algo, env, allow_pickle)
        norm = load_obs_normalization(model_path, meta or None, allow_pickle, env.observation_space.shape)
        space = env.action_space
        module = _policy_module(model, norm, np.asarray(space.low, float), np.asarray(space.high, float))
        n_obs = env.observation_space.shape[0]
        structure = env.get_wrapper_attr("observation_structure")
        layout = {k: [s.start, s.stop] for k, s in structure.items()}
        torque_limit = env.unwrapped.idx.torque_limit.tolist()
        env_id, robot = env.spec.id, env.unwrapped.robot.name
    finally:
        env.close()
    dummy = torch.zeros(1, n_obs, dtype=torch.float32)
    batch = torch.export.Dim("batch", min=1)
    with _quiet_exporter():
        program = torch.onnx.export(
            module, (dummy,), None, input_names=["obs"], output_names=["action"],
            dynamic_shapes=({0: batch},), dynamo=True, verbose=False,
        )  # fmt: skip
    graph = program.model_proto
    props = {
        "observation_layout": json.dumps(layout),
        "observation_normalization": "folded" if norm is not None else "none",
        "action_low": json.dumps(np.asarray(space.low, float).tolist()),
        "action_high": json.dumps(np.asarray(space.high, float).tolist()),
        "residual": json.dumps(bool(meta.get("residual", False))),
        "residual_scale": json.dumps(meta.get("residual_scale")),
        **{  # the residual's settings (defaults for older models' metadata); None for a model from scratch
            name: json.dumps(meta.get(name, META_DEFAULTS[name]) if meta.get("residual") else None)
            for name in ("residual_legs", "residual_basis", "expert")
        },
        "torque_limit": json.dumps(torque_limit),
        "algo": algo,
        "env_id": env_id,
        "robot": robot,
        "env_kwargs": json.dumps(meta.get("env_kwargs", {})),
    }
    onnx.helper.set_model_props(graph, props)
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        onnx.save(graph, str(out))
    except OSError as err:
        raise ModelError(f"{out_field} {str(out)!r} cannot be written ({err.strerror or err})") from None
    return out


__all__ = ["export_onnx"]
