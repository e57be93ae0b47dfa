"""Continue training from a saved model (``quad-uneven train --init-from DIR``): a warm start.

The new run builds its model from its own config, as any run does, and then takes the saved model's
weights, optimizer states and learned variables (SAC's entropy temperature) read by
:func:`agents.rl.model_io.read_model_zip`, which reads tensors only (``torch.load(weights_only=True)``) and
checks every entry: nothing in the file is unpickled. The observation statistics come from the ``.npz`` next to
the model and keep their weight (the saved run's step count), so the first new rollouts do not reset them.
The replay buffer of an off-policy model is not saved and starts empty. With ``freeze_obs_norm`` the statistics
stay fixed for the whole run.

The saved model must have been trained for the same env: every field that changes the observation, the
action or what an action does (:data:`ENV_FIELDS`) must be equal in its ``rl_meta.json`` and in the metadata a
new run of the config would write.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from stable_baselines3.common.running_mean_std import RunningMeanStd

from agents.rl.config import TrainConfigError
from agents.rl.model_io import (
    META_DEFAULTS,
    META_FILE,
    ModelError,
    model_robot,
    read_metadata,
    read_model_zip,
    recorded_shape,
)
from agents.rl.normalization import ObsNormalization, norm_path
from quad_uneven_env.fields import excerpt

ENV_FIELDS = (
    "robot",
    "algo",
    "residual",
    "residual_level",
    "plan",
    "residual_scale",
    "residual_legs",
    "residual_basis",
    "expert",
    "expert_features",
    "normalize_obs",
    "env_kwargs",
)
"""Metadata fields a warm start must share with its config (what the policy's inputs and outputs mean, and for
which robot); ``robot`` as :func:`~agents.rl.model_io.model_robot` reads it, ``env_kwargs`` without ``robot``."""


def init_model_path(init_from: str | Path) -> Path:
    """The model zip of ``init_from``: a training run's folder (its ``model.zip``) or a ``.zip`` file.

    :raises TrainConfigError: ``init_from: ...`` if there is no such file.
    """
    path = Path(init_from)
    if path.is_dir():
        path = path / "model.zip"
    if not path.is_file() or path.suffix != ".zip":
        raise TrainConfigError(f"init_from: {str(init_from)!r} is neither a model .zip nor a folder with model.zip")
    return path


def check_init_model(init_from: str | Path, expected: dict[str, Any]) -> tuple[Path, int]:
    """The saved model ``init_from`` checked against the metadata a new run would write; :return: its zip and
    its step count.

    :param init_from: the config's ``init_from``.
    :param expected: the ``rl_meta.json`` content of the new run (``agents.rl.training``'s metadata of its config).
    :raises TrainConfigError: ``init_from: ...`` naming the first of :data:`ENV_FIELDS` that differs (with both
        values), or why the model cannot be used.
    """
    path = init_model_path(init_from)
    try:
        meta = read_metadata(path)
        data = read_model_zip(path, where="init_from").data
        shape = recorded_shape(data, "observation_space", path, where="init_from")
    except ModelError as err:
        message = str(err)
        raise TrainConfigError(message if message.startswith("init_from") else f"init_from: {message}") from None
    if meta is None:
        raise TrainConfigError(f"init_from: {path} has no {META_FILE} next to it (a model of quad-uneven train?)")
    if meta.get("normalize_obs") and norm_path(path).is_file():  # checked here, before the run's --out is touched
        try:
            ObsNormalization.load(norm_path(path), shape)
        except ValueError as err:
            raise TrainConfigError(f"init_from: {err}") from None
    for name in ENV_FIELDS:
        theirs, mine = _env_field(meta, name), _env_field(expected, name)
        if name == "residual_scale" and theirs is not None and mine is not None:
            theirs, mine = float(theirs), float(mine)
        if theirs != mine:
            raise TrainConfigError(
                f"init_from: {path} was trained with {name}={excerpt(theirs)}, the config has {name}={excerpt(mine)}; "
                f"a warm start needs the same {', '.join(ENV_FIELDS)}"
            )
    steps = data.get("num_timesteps", 0)
    return path, int(steps) if isinstance(steps, int) and steps > 0 else 0


def _env_field(meta: dict[str, Any], name: str) -> Any:
    """The value of the field ``name`` of :data:`ENV_FIELDS` in ``meta`` (its default when absent)."""
    if name == "robot":
        return model_robot(meta)
    value = meta.get(name, META_DEFAULTS.get(name))
    if name == "env_kwargs":
        return {k: v for k, v in (value or {}).items() if k != "robot"}
    return value


class FrozenRunningMeanStd(RunningMeanStd):
    """SB3's running mean and variance with an ``update`` that changes nothing: statistics kept fixed."""

    def __init__(self, mean: np.ndarray, var: np.ndarray, count: float) -> None:
        super().__init__(shape=mean.shape)
        self.mean, self.var, self.count = mean, var, count

    def update(self, arr: np.ndarray) -> None:
        """Ignore ``arr``: the statistics stay those given."""

    def copy(self) -> FrozenRunningMeanStd:
        """A copy (SB3 copies the statistics when it syncs envs)."""
        return FrozenRunningMeanStd(self.mean.copy(), self.var.copy(), self.count)


def warm_start(model: Any, path: Path, steps: int, freeze_obs_norm: bool = False) -> None:
    """Give ``model`` (built from the config) the weights, optimizers and variables saved in ``path``.

    :param model: a fresh SB3 algorithm on the training VecEnv.
    :param path: the saved model zip (:func:`check_init_model`).
    :param steps: the saved run's env steps: the weight of its observation statistics.
    :param freeze_obs_norm: keep the saved observation statistics fixed during training.
    :raises TrainConfigError: ``init_from: ...`` if the networks differ (another ``net_arch``, observation or
        action size), or the model was trained with observation statistics and they are missing.
    """
    from stable_baselines3.common.save_util import recursive_setattr

    try:
        content = read_model_zip(path, where="init_from")  # tensors only, every entry checked
    except ModelError as err:
        raise TrainConfigError(str(err)) from None
    try:
        model.set_parameters(content.params, exact_match=True, device="cpu")
        for name, value in content.variables.items():
            if value is not None:
                recursive_setattr(model, f"{name}.data", value.data)
    except (RuntimeError, ValueError, KeyError, TypeError, AttributeError, IndexError) as err:
        # tensors of other shapes (RuntimeError), other or missing modules (ValueError), an optimizer state of
        # another layout (KeyError, TypeError, IndexError), a variable the model lacks (AttributeError)
        reason = f"{type(err).__name__}: {(str(err).strip().splitlines() or [''])[0][:200]}"
        raise TrainConfigError(f"init_from: {path} does not fit the config's model ({reason})") from None
    vn = model.get_vec_normalize_env()
    if vn is None or not vn.norm_obs:
        return
    try:
        stats = ObsNormalization.load(norm_path(path), vn.obs_rms.mean.shape)
    except ValueError as err:
        raise TrainConfigError(f"init_from: {err}") from None
    if freeze_obs_norm:
        vn.obs_rms = FrozenRunningMeanStd(stats.mean.copy(), stats.var.copy(), float(max(steps, 1)))
        return
    vn.obs_rms.mean = stats.mean.copy()
    vn.obs_rms.var = stats.var.copy()
    vn.obs_rms.count = float(max(steps, 1))


__all__ = ["ENV_FIELDS", "FrozenRunningMeanStd", "check_init_model", "init_model_path", "warm_start"]
