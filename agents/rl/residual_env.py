"""Residual RL on top of the scripted expert: ``QuadUnevenResidual-v0``.

The expert (:class:`agents.expert.ExpertPolicy`: planner + computed-torque controller) runs at
physics rate through the env's controller hook; the RL action is added on top of its torques:

    tau = clip(tau_expert + residual_scale * action * torque_limit, -torque_limit, torque_limit)   (N m)

at every 2 ms physics step, with ``action`` in [-1, 1]^12 (joint order LF RF LH RH x HAA HFE KFE) held over
the control step (``residual_basis="expert_torque"`` makes the residual a gain on the expert instead:
``tau = clip(tau_expert * (1 + residual_scale * action), ...)``, per joint). With ``action = 0`` the env
reproduces the expert exactly (the expert of ``ResidualConfig.expert``, with its adaptive gains if its
``adaptation`` says so: then ``tau_expert`` is the adapted torque). Reward, termination and info are those of
``QuadUneven-v0``; the observation is ``QuadUneven-v0``'s followed by the expert features
(:mod:`agents.rl.expert_features`: the expert's plan now, the tracking error and its torques), or the env's alone
with ``expert_features=False``. The settings travel as one frozen :class:`ResidualConfig`.

``residual_scale`` (default 0.1: up to 12 N m on top of the expert, with 120 N m motors) bounds how
far the learned agent can move away from the expert. ``residual_legs="stance"`` applies the residual only
to the legs whose foot touches the ground at that physics step (the robot's contact switches): it can
then change how the robot carries itself, but not where a swinging foot goes.

Two bases for one unit of action, because they suit different model errors: ``torque_limit`` can add torque
in any direction, also where the expert commands none; ``expert_torque`` scales what the expert already
commands, which is the shape of a weaker motor or a heavier body than the expert's model (a motor at 70 % of
its torque is undone by ``action = 0.3 / 0.7 / residual_scale``), and needs no sign from the policy.

Usage::

    import gymnasium as gym
    import agents.rl  # registers QuadUnevenResidual-v0
    from agents.expert import ExpertConfig
    from agents.rl import ResidualConfig

    config = ResidualConfig(residual_scale=0.1, expert=ExpertConfig(adaptation="knee"))
    env = gym.make("QuadUnevenResidual-v0", config=config, terrain="rough")
    # or, from a bare interpreter: gym.make("agents.rl:QuadUnevenResidual-v0")
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np
from gymnasium.envs.registration import register, registry

from agents.expert import ExpertConfig, ExpertPolicy
from agents.rl import residual_kernels as RK
from agents.rl.expert_features import EXPERT_FEATURE_FIELDS, augmented_space, expert_features
from agents.rl.residual_config import (
    DEFAULT_RESIDUAL_SCALE,
    ResidualConfig,
    check_residual_basis,
    check_residual_legs,
    check_residual_scale,
    expert_overrides,
    split_config,
)
from quad_uneven_env.env import QuadUnevenEnv
from quad_uneven_env.fields import excerpt
from quad_uneven_env.measurement_kernels import clip_finite_into

RESIDUAL_ENV_ID = "QuadUnevenResidual-v0"
"""Gymnasium id of the residual env (registered when this module is imported)."""

DEFAULT_MAX_EPISODE_STEPS = 1000
"""Control steps per episode of the registered env (20 s at the default 50 Hz)."""


class ResidualController:
    """Physics-rate controller: the expert's torques plus ``residual_scale`` x action x torque limit (or x the
    expert's torque with ``residual_basis="expert_torque"``).

    :param expert: a callable ``(model, data, action) -> (12,)`` torques (N m), e.g. :class:`ExpertPolicy`;
        its ``reset(model, data, terrain)`` is forwarded.
    :param torque_limit: (12,) motor limits (N m).
    :param residual_scale: residual torque per unit action as a fraction of ``torque_limit``, in (0, 1].
    :param residual_legs: ``"all"``, or ``"stance"``: a leg takes its residual only at the physics steps
        where its foot touches the ground (``data.sensordata[foot_sensor_adr]``).
    :param foot_sensor_adr: (4,) sensordata addresses of the feet's contact switches, leg order (needed
        for ``"stance"``).
    :param residual_basis: ``"torque_limit"`` (residual = scale x action x ``torque_limit``) or
        ``"expert_torque"`` (residual = scale x action x the expert's torque, joint by joint).

    An expert with adaptive gains (``ExpertConfig.adaptation``) returns its adapted torques: the residual acts on
    those.
    """

    def __init__(
        self,
        expert: Any,
        torque_limit: np.ndarray,
        residual_scale: float = DEFAULT_RESIDUAL_SCALE,
        residual_legs: str = "all",
        foot_sensor_adr: Any = None,
        residual_basis: str = "torque_limit",
    ) -> None:
        self.expert = expert
        self.residual_scale = check_residual_scale(residual_scale)
        self.residual_legs = check_residual_legs(residual_legs)
        self.residual_basis = check_residual_basis(residual_basis)
        self.torque_limit = np.asarray(torque_limit, dtype=np.float64).copy()
        self.gain = self.residual_scale * self.torque_limit
        """(12,) N m of residual torque per unit action (``torque_limit`` basis)."""
        self._tau = np.zeros_like(self.torque_limit)
        self._foot_adr = None
        if self.residual_legs == "stance":
            if foot_sensor_adr is None or len(foot_sensor_adr) != len(self.torque_limit) // 3:
                raise ValueError("residual_legs='stance' needs the feet's contact sensor addresses, one per leg")
            self._foot_adr = np.asarray(foot_sensor_adr, dtype=np.intp)
        self._foot_adr_or_none = self._foot_adr if self._foot_adr is not None else np.zeros(4, dtype=np.intp)
        self._touch = np.zeros(1)  # stands in for the contact switches when no leg is gated
        self._tau_expert = np.zeros_like(self.torque_limit)  # the expert's lane writes here
        self._no_limit = np.full_like(self.torque_limit, np.inf)  # its torques, unclipped as its call returns them
        self._expert_gain = np.ones_like(self.torque_limit)  # the kernel's gain on the expert: none here
        # Per physics step only where the applied residual varies within a control step (gated, or a gain).
        self._track_applied = self._foot_adr is not None or self.residual_basis == "expert_torque"
        self._applied_sum = 0.0  # mean |applied residual| (N m) summed over physics steps since the last query
        self._applied_n = 0

    def reset(self, model: mujoco.MjModel, data: mujoco.MjData, terrain: Any) -> None:
        """Forwarded to the expert at every env reset."""
        self._applied_sum, self._applied_n = 0.0, 0
        if hasattr(self.expert, "reset"):
            self.expert.reset(model, data, terrain)

    def residual_torque(self, action: np.ndarray) -> float:
        """N m: mean over the 12 joints of |residual torque| before the motor limit (what is added to the
        expert's torque, adapted if its config says so). With ``"all"`` legs in the ``torque_limit`` basis it is
        what ``action`` (clipped to [-1, 1]) commands; otherwise the mean of what was applied over the physics
        steps since the previous call (what ``action`` would command in the ``torque_limit`` basis if there were
        none)."""
        if self._applied_n:
            value = self._applied_sum / self._applied_n
            self._applied_sum, self._applied_n = 0.0, 0
            return value
        return float(np.mean(np.abs(np.clip(np.asarray(action, dtype=float), -1.0, 1.0) * self.gain)))

    def __call__(self, model: mujoco.MjModel, data: mujoco.MjData, action: np.ndarray) -> np.ndarray:
        """Joint torques (12, N m): expert + residual, clipped to the motor limits (in one compiled call,
        :func:`~agents.rl.residual_kernels.residual_torques_into`, the twin of :func:`residual_torques`).

        :param action: (12,) residual action in [-1, 1] (the env has clipped it).
        """
        tau_expert = np.asarray(self.expert(model, data, action), dtype=np.float64)
        return self._add_residual(data, action, tau_expert)

    def torques_into(
        self, model: mujoco.MjModel, data: mujoco.MjData, action: np.ndarray, out: np.ndarray, limit: np.ndarray
    ) -> bool:
        """The hook's fast lane (:class:`~quad_uneven_env.env.PhysicsController`): the call's torques, clipped to
        ``±limit`` (N m), into ``out``, where the expert's own lane answers (``expert.torques_into``); False
        otherwise (as the expert's lane: then the call runs)."""
        lane = getattr(self.expert, "torques_into", None)
        if lane is None or not lane(model, data, action, self._tau_expert, self._no_limit):
            return False
        tau = self._add_residual(data, action, self._tau_expert)
        return bool(clip_finite_into(tau, limit, out))  # finite: the expert's torques and the action are

    def _add_residual(self, data: mujoco.MjData, action: np.ndarray, tau_expert: np.ndarray) -> np.ndarray:
        """Expert + residual in ``self._tau`` (N m, clipped to the motor limits), the applied residual counted."""
        action = np.asarray(action, dtype=np.float64)
        applied = RK.residual_torques_into(
            action, tau_expert, self._expert_gain, self.gain, self.residual_scale,
            self.residual_basis == "expert_torque",
            self._touch if self._foot_adr is None else data.sensordata, self._foot_adr_or_none,
            self._foot_adr is not None, self.torque_limit, self._tau,
        )  # fmt: skip
        if self._track_applied:
            self._applied_sum += applied
            self._applied_n += 1
        return self._tau


def residual_torques(
    action: np.ndarray,
    tau_expert: np.ndarray,
    expert_gain: np.ndarray,
    per_unit: np.ndarray,
    scale: float,
    expert_basis: bool,
    stance_legs: np.ndarray | None,
    limit: np.ndarray,
) -> tuple[np.ndarray, float]:
    """The residual composition in numpy (the twin of the compiled
    :func:`~agents.rl.residual_kernels.residual_torques_into`).

    :param expert_gain: (12,) gains on the expert's torques (ones in :class:`ResidualController`).
    :param per_unit: (12,) N m of residual per unit action in the ``torque_limit`` basis.
    :param stance_legs: (4,) bool, the legs whose foot touches (None: every leg takes its residual).
    :return: the torques (12, N m, clipped to ``±limit``) and mean |torque - tau_expert| before the clip.
    """
    tau_base = tau_expert * expert_gain
    tau = action * tau_base * scale if expert_basis else action * per_unit
    if stance_legs is not None:
        tau = tau * np.repeat(stance_legs, 3)
    tau = tau + tau_base
    applied = float(np.mean(np.abs(tau - tau_expert)))
    return np.clip(tau, -limit, limit), applied


def install_residual_controller(
    env: gym.Env, config: ResidualConfig | None = None
) -> tuple[ExpertPolicy, ResidualController]:
    """Put the expert plus a residual on ``env.unwrapped``'s physics-rate hook (call before ``reset``).

    :param env: a ``QuadUneven-v0`` env (wrapped or not) in ``action_mode="torque"``.
    :param config: the residual's settings and the expert's (default :class:`ResidualConfig`); the expert's
        adaptive gains, if any, are updated once per control step of ``env``.
    :return: the expert (planner times, failure log) and the installed controller.
    :raises ValueError: on another action mode or a config that is not a :class:`ResidualConfig`.
    """
    config = ResidualConfig() if config is None else config
    if not isinstance(config, ResidualConfig):
        raise ValueError(f"config must be a ResidualConfig, got {excerpt(config)}")
    base = env.unwrapped
    if not isinstance(base, QuadUnevenEnv):
        raise ValueError(f"the residual controller needs a QuadUneven-v0 env, got {type(base).__name__}")
    if base.action_mode != "torque":
        raise ValueError(
            f"action_mode must be 'torque' for the residual env (expert torques), got {excerpt(base.action_mode)}"
        )
    # the given settings over the robot's scaled ones (docs/robots.md); where those are the defaults (the paper
    # robot's), the given settings as they are
    settings = config.expert
    if ExpertConfig.for_robot(base.robot) != ExpertConfig():
        settings = ExpertConfig.for_robot(base.robot, expert_overrides(settings))
    expert = ExpertPolicy(env, settings)
    controller = ResidualController(
        expert,
        base.idx.torque_limit,
        config.residual_scale,
        config.residual_legs,
        base.idx.foot_sensor_adr,
        config.residual_basis,
    )
    base.set_controller(controller)
    return expert, controller


class ResidualExpertEnv(gym.Wrapper):
    """``QuadUneven-v0`` with the expert in the loop; the action is a residual on the expert's torques.

    Action space, reward, termination and info are the wrapped env's, plus ``info["residual_scale"]`` and
    ``info["residual_torque"]`` (N m: mean over the 12 joints of |residual torque| commanded this step,
    before the motor limit). The observation is the wrapped env's followed by the expert features
    (:data:`agents.rl.expert_features.EXPERT_FEATURE_FIELDS`) unless ``config.expert_features`` is False.
    With ``config.residual_penalty`` > 0, that times mean(action^2) over the 12 joints is subtracted from the
    reward (``info["reward_terms"]["residual"]``).

    :param env: a ``QuadUneven-v0`` env in torque mode, without a controller of its own.
    :param config: the residual's settings and the expert's (default :class:`ResidualConfig`).
    """

    def __init__(self, env: gym.Env, config: ResidualConfig | None = None) -> None:
        super().__init__(env)
        self.config = ResidualConfig() if config is None else config
        self.expert, self.controller = install_residual_controller(env, self.config)
        self.residual_scale = self.controller.residual_scale
        self.residual_penalty = self.config.residual_penalty
        self.expert_features = self.config.expert_features
        self.observation_structure: dict[str, slice] = dict(env.unwrapped.observation_structure)
        """name -> slice of every part of the observation: the wrapped env's, then the expert features'."""
        if self.expert_features:
            self.observation_space = augmented_space(env.observation_space)
            offset = int(env.observation_space.shape[0])
            for f in EXPERT_FEATURE_FIELDS:
                self.observation_structure[f.name] = slice(offset, offset + f.size)
                offset += f.size

    def _observation(self, obs: np.ndarray) -> np.ndarray:
        if not self.expert_features:
            return obs
        return np.concatenate([obs, expert_features(self.expert, self.env.unwrapped.data)])

    def reset(self, **kwargs: Any):
        """Reset the env (the expert plans its first cycle); the info has the step's keys (residual zero)."""
        obs, info = self.env.reset(**kwargs)
        info["residual_scale"] = self.residual_scale
        info["residual_torque"] = 0.0
        if self.residual_penalty > 0:
            info["reward_terms"]["residual"] = 0.0
        return self._observation(obs), info

    def step(self, action: np.ndarray):
        """One control step of expert + residual ``action``; see :meth:`QuadUnevenEnv.step`."""
        obs, reward, terminated, truncated, info = self.env.step(action)
        info["residual_scale"] = self.residual_scale
        info["residual_torque"] = self.controller.residual_torque(action)
        if self.residual_penalty > 0:
            a = np.clip(np.asarray(action, dtype=float), -1.0, 1.0)
            term = -self.residual_penalty * float(np.mean(a * a))
            info["reward_terms"]["residual"] = term
            reward = float(reward) + term
        return self._observation(obs), reward, terminated, truncated, info


def make_residual_env(config: ResidualConfig | Mapping[str, Any] | None = None, **kwargs: Any) -> ResidualExpertEnv:
    """The residual env (entry point of ``QuadUnevenResidual-v0``).

    :param config: a :class:`ResidualConfig`, or a mapping of its fields (``expert`` a mapping of
        :class:`ExpertConfig` fields); None: the defaults, or the :class:`ResidualConfig` fields among ``kwargs``
        (``gym.make(RESIDUAL_ENV_ID, residual_scale=0.2, expert=ExpertConfig(adaptation="knee"))``).
    :param kwargs: :class:`ResidualConfig` fields (without ``config``), then ``QuadUnevenEnv`` arguments
        (``terrain``, ``reward_weights``, ...); ``action_mode`` must be ``"torque"`` and ``controller`` is not
        accepted.
    :raises ValueError: on a bad argument (named).
    """
    if "controller" in kwargs:
        raise ValueError("controller is not accepted by the residual env: expert plus residual is its controller")
    config = split_config(ResidualConfig, config, kwargs, "residual's settings")
    return ResidualExpertEnv(QuadUnevenEnv(**kwargs), config)


if RESIDUAL_ENV_ID not in registry:
    register(
        id=RESIDUAL_ENV_ID,
        entry_point="agents.rl.residual_env:make_residual_env",
        max_episode_steps=DEFAULT_MAX_EPISODE_STEPS,
    )

__all__ = [
    "RESIDUAL_ENV_ID",
    "ResidualController",
    "ResidualExpertEnv",
    "install_residual_controller",
    "make_residual_env",
    "residual_torques",
]
