"""Residual RL on top of the scripted expert: ``QuadUnevenResidual-v0``.

The expert (:class:`agents.expert.ExpertPolicy`: planner + computed-torque controller) runs at
physics rate through the env's controller hook; the RL action is added on top of its torques:

    tau = clip(tau_expert + residual_scale * action * torque_limit, -torque_limit, torque_limit)   (N m)

at every 2 ms physics step, with ``action`` in [-1, 1]^12 (joint order LF RF LH RH x HAA HFE KFE) held over
the control step (``residual_basis="expert_torque"`` makes the residual a gain on the expert instead:
``tau = clip(tau_expert * (1 + residual_scale * action), ...)``, per joint). With ``action = 0`` the env
reproduces the expert exactly. Reward, termination and info are those of ``QuadUneven-v0``; the observation
is ``QuadUneven-v0``'s followed by the expert features (:mod:`agents.rl.expert_features`: the expert's plan
now, the tracking error and its torques), or the env's alone with ``expert_features=False``.

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

    env = gym.make("QuadUnevenResidual-v0", residual_scale=0.1, terrain="rough")
    # or, from a bare interpreter: gym.make("agents.rl:QuadUnevenResidual-v0")
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import mujoco
import numpy as np
from gymnasium.envs.registration import register, registry

from agents.expert import ExpertConfig, ExpertPolicy
from agents.rl import residual_kernels as RK
from agents.rl.config import RESIDUAL_BASES, RESIDUAL_LEGS
from agents.rl.expert_features import adaptation_features as adaptation_feature_vector
from agents.rl.expert_features import augmented_space, expert_features
from agents.rl.gain_adaptation import KneeGainAdaptation, check_gain_adaptation
from agents.rl.strength_estimator import LearnedGainAdaptation
from quad_uneven_env.env import QuadUnevenEnv
from quad_uneven_env.measurement_kernels import clip_finite_into

RESIDUAL_ENV_ID = "QuadUnevenResidual-v0"
"""Gymnasium id of the residual env (registered when this module is imported)."""

DEFAULT_RESIDUAL_SCALE = 0.1
"""Default residual torque as a fraction of the torque limit (0.1 x 120 N m = 12 N m per joint)."""

DEFAULT_MAX_EPISODE_STEPS = 1000
"""Control steps per episode of the registered env (20 s at the default 50 Hz)."""


def check_residual_legs(residual_legs: Any) -> str:
    """``residual_legs`` if it is one of :data:`RESIDUAL_LEGS`.

    :raises ValueError: naming ``residual_legs`` and its allowed values otherwise.
    """
    if not isinstance(residual_legs, str) or residual_legs not in RESIDUAL_LEGS:
        raise ValueError(f"residual_legs must be one of {list(RESIDUAL_LEGS)}, got {residual_legs!r}")
    return residual_legs


def check_residual_basis(residual_basis: Any) -> str:
    """``residual_basis`` if it is one of :data:`RESIDUAL_BASES`.

    :raises ValueError: naming ``residual_basis`` and its allowed values otherwise.
    """
    if not isinstance(residual_basis, str) or residual_basis not in RESIDUAL_BASES:
        raise ValueError(f"residual_basis must be one of {list(RESIDUAL_BASES)}, got {residual_basis!r}")
    return residual_basis


def check_residual_scale(residual_scale: Any) -> float:
    """``residual_scale`` as a float in (0, 1].

    :raises ValueError: naming ``residual_scale`` otherwise.
    """
    try:
        value = float(residual_scale)
    except (TypeError, ValueError):
        value = float("nan")
    if isinstance(residual_scale, bool) or not (0.0 < value <= 1.0):
        raise ValueError(f"residual_scale must be a number in (0, 1] (of the torque limit), got {residual_scale!r}")
    return value


def make_gain_adaptation(name: str, period: float) -> KneeGainAdaptation | LearnedGainAdaptation | None:
    """The adaptation ``name`` (one of :data:`~agents.rl.config.GAIN_ADAPTATIONS`) updated every ``period`` s,
    or None for ``"none"``."""
    name = check_gain_adaptation(name)
    if name == "knee":
        return KneeGainAdaptation(period)
    if name == "learned":
        return LearnedGainAdaptation(period)
    return None


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
    :param gain_adaptation: ``"none"``, ``"knee"`` or ``"learned"``: the expert's knee torques (``"knee"``) or
        all its joint torques (``"learned"``) are first multiplied by the adaptive gains of
        :class:`~agents.rl.gain_adaptation.KneeGainAdaptation` or
        :class:`~agents.rl.strength_estimator.LearnedGainAdaptation`, updated every ``update_period`` from the
        expert's plan (``expert.planned_now``) and torques; the residual then acts on the adapted torques. With
        an adaptation, action 0 is no longer the expert alone.
    :param update_period: s between two updates of the adaptation (the env's control step).
    :param adaptation: an adaptation object to use instead of the one ``gain_adaptation`` names (its ``gain``
        (12,) array multiplies the expert's torques, its ``reset()`` and ``update(error, load, t)`` are called as
        :class:`~agents.rl.gain_adaptation.KneeGainAdaptation`'s; the strength estimator's data collection).
    """

    def __init__(
        self,
        expert: Any,
        torque_limit: np.ndarray,
        residual_scale: float = DEFAULT_RESIDUAL_SCALE,
        residual_legs: str = "all",
        foot_sensor_adr: Any = None,
        residual_basis: str = "torque_limit",
        gain_adaptation: str = "none",
        update_period: float = 0.02,
        adaptation: Any = None,
    ) -> None:
        self.expert = expert
        self.gain_adaptation = check_gain_adaptation(gain_adaptation)
        if adaptation is None:
            adaptation = make_gain_adaptation(self.gain_adaptation, update_period)
        self.adaptation = adaptation
        if self.adaptation is not None and not hasattr(expert, "planned_now"):
            raise ValueError(
                f"gain_adaptation={self.gain_adaptation!r} needs an expert with a plan (planned_now), like ExpertPolicy"
            )
        self._next_update = self._t_reset = 0.0
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
        self._expert_gain = np.ones_like(self.torque_limit) if self.adaptation is None else self.adaptation.gain
        # Per physics step only where the applied residual varies within a control step (gated, or a gain).
        self._track_applied = (
            self._foot_adr is not None or self.residual_basis == "expert_torque" or self.adaptation is not None
        )
        self._applied_sum = 0.0  # mean |applied residual| (N m) summed over physics steps since the last query
        self._applied_n = 0

    def reset(self, model: mujoco.MjModel, data: mujoco.MjData, terrain: Any) -> None:
        """Forwarded to the expert at every env reset."""
        self._applied_sum, self._applied_n = 0.0, 0
        if hasattr(self.expert, "reset"):
            self.expert.reset(model, data, terrain)
        if self.adaptation is not None:
            self.adaptation.reset()
            self._t_reset = float(data.time)
            self._next_update = self._t_reset + self.adaptation.period

    def residual_torque(self, action: np.ndarray) -> float:
        """N m: mean over the 12 joints of |residual torque| before the motor limit (with ``gain_adaptation``,
        everything added to the expert's torque: the adapted gains' share included). With ``"all"`` legs in the
        ``torque_limit`` basis and no adaptation it is what ``action`` (clipped to [-1, 1]) commands; otherwise
        the mean of what was applied over the physics steps since the previous call (what ``action`` would
        command in the ``torque_limit`` basis if there were none)."""
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
        """Expert + residual in ``self._tau`` (N m, clipped to the motor limits), the adaptive gains updated first
        and the applied residual counted."""
        action = np.asarray(action, dtype=np.float64)
        if self.adaptation is not None:
            self._update_adaptation(data, tau_expert)
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

    def _update_adaptation(self, data: mujoco.MjData, tau_expert: np.ndarray) -> None:
        """Update the adaptive gains if a control step has begun (they multiply the expert's torques)."""
        adaptation = self.adaptation
        t = float(data.time)
        if t >= self._next_update - 1e-9:
            ref, _ = self.expert.planned_now(t)
            adaptation.update(ref.q_joints - data.qpos[7:], tau_expert / self.torque_limit, t - self._t_reset)
            self._next_update += adaptation.period
            if self._next_update <= t:  # a jump of the clock (never in a rollout): back on the control grid
                self._next_update = t + adaptation.period


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

    :param expert_gain: (12,) gains on the expert's torques (the adaptive knee gains, else ones).
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
    env: gym.Env,
    residual_scale: float = DEFAULT_RESIDUAL_SCALE,
    expert_config: ExpertConfig | None = None,
    residual_legs: str = "all",
    residual_basis: str = "torque_limit",
    gain_adaptation: str = "none",
) -> tuple[ExpertPolicy, ResidualController]:
    """Put the expert plus a residual on ``env.unwrapped``'s physics-rate hook (call before ``reset``).

    :param env: a ``QuadUneven-v0`` env (wrapped or not) in ``action_mode="torque"``.
    :param residual_scale: see :class:`ResidualController`.
    :param residual_legs: see :class:`ResidualController`.
    :param residual_basis: see :class:`ResidualController`.
    :param gain_adaptation: see :class:`ResidualController` (updated once per control step of ``env``).
    :return: the expert (planner times, failure log) and the installed controller.
    :raises ValueError: on another action mode or a bad ``residual_scale``.
    """
    base = env.unwrapped
    if not isinstance(base, QuadUnevenEnv):
        raise ValueError(f"the residual controller needs a QuadUneven-v0 env, got {type(base).__name__}")
    if base.action_mode != "torque":
        raise ValueError(
            f"action_mode must be 'torque' for the residual env (expert torques), got {base.action_mode!r}"
        )
    scale = check_residual_scale(residual_scale)
    legs = check_residual_legs(residual_legs)
    basis = check_residual_basis(residual_basis)
    expert = ExpertPolicy(env, expert_config)
    controller = ResidualController(
        expert, base.idx.torque_limit, scale, legs, base.idx.foot_sensor_adr, basis, gain_adaptation, base.dt
    )
    base.set_controller(controller)
    return expert, controller


class ResidualExpertEnv(gym.Wrapper):
    """``QuadUneven-v0`` with the expert in the loop; the action is a residual on the expert's torques.

    Action space, reward, termination and info are the wrapped env's, plus ``info["residual_scale"]`` and
    ``info["residual_torque"]`` (N m: mean over the 12 joints of |residual torque| commanded this step,
    before the motor limit). The observation is the wrapped env's followed by the expert features
    (:data:`agents.rl.expert_features.EXPERT_FEATURE_FIELDS`) unless ``expert_features`` is False.

    :param env: a ``QuadUneven-v0`` env in torque mode, without a controller of its own.
    :param residual_scale: residual torque per unit action as a fraction of the torque limit, in (0, 1].
    :param expert_config: the expert's settings (default :class:`ExpertConfig`).
    :param expert_features: append the expert features to the observation.
    :param residual_penalty: >= 0: subtracted from the reward per unit of mean(action^2) over the 12 joints
        (``info["reward_terms"]["residual"]``); 0 keeps the env's reward.
    :param residual_legs: ``"all"`` or ``"stance"`` (see :class:`ResidualController`).
    :param residual_basis: ``"torque_limit"`` or ``"expert_torque"`` (see :class:`ResidualController`).
    :param gain_adaptation: ``"none"``, ``"knee"`` or ``"learned"`` (see :class:`ResidualController`).
    :param adaptation_features: append the adapted knee gains after the expert features
        (:data:`agents.rl.expert_features.ADAPTATION_FEATURE_FIELDS`); needs ``gain_adaptation="knee"`` and
        ``expert_features``.
    """

    def __init__(
        self,
        env: gym.Env,
        residual_scale: float = DEFAULT_RESIDUAL_SCALE,
        expert_config: ExpertConfig | None = None,
        expert_features: bool = True,
        residual_penalty: float = 0.0,
        residual_legs: str = "all",
        residual_basis: str = "torque_limit",
        gain_adaptation: str = "none",
        adaptation_features: bool = False,
    ) -> None:
        super().__init__(env)
        for name, flag in (("expert_features", expert_features), ("adaptation_features", adaptation_features)):
            if not isinstance(flag, bool):
                raise ValueError(f"{name} must be true or false, got {flag!r}")
        if adaptation_features and not (expert_features and gain_adaptation == "knee"):
            raise ValueError(
                "adaptation_features needs gain_adaptation='knee' and expert_features=True, got "
                f"gain_adaptation={gain_adaptation!r}, expert_features={expert_features}"
            )
        try:
            penalty = float("nan") if isinstance(residual_penalty, bool) else float(residual_penalty)
        except (TypeError, ValueError):
            penalty = float("nan")
        if not (0.0 <= penalty < float("inf")):
            raise ValueError(f"residual_penalty must be a finite number >= 0, got {residual_penalty!r}")
        self.residual_penalty = penalty
        self.expert, self.controller = install_residual_controller(
            env, residual_scale, expert_config, residual_legs, residual_basis, gain_adaptation
        )
        self.residual_scale = self.controller.residual_scale
        self.expert_features = expert_features
        self.adaptation_features = adaptation_features
        if expert_features:
            self.observation_space = augmented_space(env.observation_space, adaptation_features)

    def _observation(self, obs: np.ndarray) -> np.ndarray:
        if not self.expert_features:
            return obs
        parts = [obs, expert_features(self.expert, self.env.unwrapped.data)]
        if self.adaptation_features:
            parts.append(adaptation_feature_vector(self.controller.adaptation.gain))
        return np.concatenate(parts)

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


def make_residual_env(
    residual_scale: float = DEFAULT_RESIDUAL_SCALE,
    expert_config: ExpertConfig | None = None,
    expert_features: bool = True,
    residual_penalty: float = 0.0,
    residual_legs: str = "all",
    residual_basis: str = "torque_limit",
    gain_adaptation: str = "none",
    adaptation_features: bool = False,
    **env_kwargs: Any,
) -> ResidualExpertEnv:
    """The residual env (entry point of ``QuadUnevenResidual-v0``).

    :param residual_scale: residual torque per unit action as a fraction of the torque limit, in (0, 1]
        (default 0.1 = 12 N m per joint).
    :param expert_config: the expert's settings.
    :param expert_features: append the expert features (:mod:`agents.rl.expert_features`) to the observation.
    :param residual_penalty: reward penalty per unit of mean(action^2) (see :class:`ResidualExpertEnv`).
    :param residual_legs: ``"all"`` or ``"stance"``: which legs take the residual (:class:`ResidualController`).
    :param residual_basis: ``"torque_limit"`` or ``"expert_torque"``: what a unit of action is.
    :param gain_adaptation: ``"none"``, ``"knee"`` or ``"learned"``: adaptive gains on the expert under the
        residual.
    :param adaptation_features: append the adapted knee gains to the observation (needs ``"knee"``).
    :param env_kwargs: ``QuadUnevenEnv`` arguments (``terrain``, ``reward_weights``, ...); ``action_mode`` must be
        ``"torque"`` and ``controller`` is not accepted.
    :raises ValueError: on a bad argument (named).
    """
    if "controller" in env_kwargs:
        raise ValueError("controller is not accepted by the residual env: expert plus residual is its controller")
    return ResidualExpertEnv(
        QuadUnevenEnv(**env_kwargs),
        residual_scale,
        expert_config,
        expert_features,
        residual_penalty,
        residual_legs,
        residual_basis,
        gain_adaptation,
        adaptation_features,
    )


if RESIDUAL_ENV_ID not in registry:
    register(
        id=RESIDUAL_ENV_ID,
        entry_point="agents.rl.residual_env:make_residual_env",
        max_episode_steps=DEFAULT_MAX_EPISODE_STEPS,
    )

__all__ = [
    "DEFAULT_RESIDUAL_SCALE",
    "RESIDUAL_ENV_ID",
    "RESIDUAL_LEGS",
    "ResidualController",
    "ResidualExpertEnv",
    "check_residual_basis",
    "check_residual_legs",
    "install_residual_controller",
    "make_residual_env",
    "residual_torques",
]
