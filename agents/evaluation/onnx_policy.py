"""An ONNX file written by ``quad-uneven export`` as a policy ``evaluate`` runs (``--policy PATH.onnx``).

The file's ``metadata_props`` (:mod:`agents.rl.export`) say the env it acts in: ``env_id``, ``env_kwargs`` and
``robot``; its graph maps ``obs (N, n_obs) float32`` to ``action (N, 12) float32``, the normalisation folded in.
A policy from scratch or a distilled one (``env_id`` ``QuadUneven-v0``) runs here; a residual one needs the expert
of its training around it: evaluate its ``model.zip``. onnxruntime is the ``export`` extra.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from quad_uneven_env import ENV_ID

__all__ = ["OnnxPolicy", "OnnxPolicyError", "make_onnx_env", "onnx_metadata"]


class OnnxPolicyError(ValueError):
    """An ONNX file that cannot be used as a policy (``agents.evaluation.policies`` raises it as a ``PolicyError``)."""


def _error(message: str) -> OnnxPolicyError:
    return OnnxPolicyError(message)


def _session(path: str | Path) -> Any:
    try:
        import onnxruntime as ort
    except ImportError as err:
        raise _error(
            f'policy {str(path)!r}: an ONNX policy needs onnxruntime: pip install -e ".[export]" ({err})'
        ) from None
    if not Path(path).is_file():
        raise _error(f"policy: ONNX file {str(path)!r} does not exist")
    options = ort.SessionOptions()
    options.intra_op_num_threads = 1  # a tiny network: one thread contends less with the simulation
    options.inter_op_num_threads = 1
    try:
        return ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])
    except Exception as err:  # onnxruntime raises its own exception types for unreadable files
        raise _error(f"policy {str(path)!r}: not a readable ONNX file ({' '.join(str(err).split())[:200]})") from None


def onnx_metadata(path: str | Path) -> dict[str, Any]:
    """``env_id`` (str), ``env_kwargs`` (dict), ``robot`` (str) and ``residual`` (bool) of an exported ONNX policy.

    :raises OnnxPolicyError: on a missing or unreadable file, or metadata ``quad-uneven export`` did not write.
    """
    props = _session(path).get_modelmeta().custom_metadata_map
    try:
        meta = {
            "env_id": str(props["env_id"]),
            "env_kwargs": json.loads(props["env_kwargs"]),
            "robot": str(props["robot"]),
            "residual": bool(json.loads(props.get("residual", "false"))),
        }
    except (KeyError, ValueError) as err:
        raise _error(
            f"policy {str(path)!r}: metadata_props must hold env_id, env_kwargs and robot as quad-uneven export writes "
            f"them, got {sorted(props)} ({err})"
        ) from None
    if not isinstance(meta["env_kwargs"], dict):
        raise _error(f"policy {str(path)!r}: metadata_props env_kwargs must be a JSON object")
    return meta


def make_onnx_env(path: str | Path, **kwargs: Any) -> gym.Env:
    """The env the ONNX policy at ``path`` acts in: its ``env_id`` with its ``env_kwargs``, ``kwargs`` over them.

    :raises OnnxPolicyError: for a residual policy, or an env of another robot than the policy's.
    """
    meta = onnx_metadata(path)
    if meta["residual"] or meta["env_id"] != ENV_ID:
        raise _error(
            f"policy {str(path)!r}: a residual ONNX policy (env_id {meta['env_id']!r}) acts beside the expert of its "
            "training: evaluate its model.zip"
        )
    env = gym.make(ENV_ID, **{**meta["env_kwargs"], **kwargs})
    robot = env.unwrapped.robot.name
    if robot != meta["robot"]:
        env.close()
        raise _error(
            f"robot must be {meta['robot']!r}, the robot {str(path)!r} acts for, got {robot!r}: a policy acts for the "
            "robot it was trained on (drop --robot, or give its robot)"
        )
    return env


class OnnxPolicy:
    """An exported policy with SB3's ``predict``: the graph's action for one observation (deterministic).

    :param path: the ``.onnx`` file.
    :param env: the env it acts in (:func:`make_onnx_env`); its observation size must be the graph's input size.
    :raises OnnxPolicyError: if the sizes differ.
    """

    def __init__(self, path: str | Path, env: gym.Env) -> None:
        self.session = _session(path)
        inp = self.session.get_inputs()[0]
        self.input_name = inp.name
        n_obs = env.observation_space.shape[0]
        if inp.shape[-1] != n_obs:
            raise _error(f"policy {str(path)!r}: its input has {inp.shape[-1]} values, the env observes {n_obs}")

    def predict(self, observation, state=None, episode_start=None, deterministic=True):
        """(action (12,) float32, None) for one observation."""
        obs = np.asarray(observation, dtype=np.float32).reshape(1, -1)
        return self.session.run(None, {self.input_name: obs})[0][0], None
