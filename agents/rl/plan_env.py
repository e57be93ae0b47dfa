"""Plan-level residual RL on top of the scripted expert: ``QuadUnevenPlan-v0``.

The expert (:class:`agents.expert.ExpertPolicy`) drives the robot alone, at physics rate; the agent adjusts its plan
instead of its torques. One env step is one gait cycle: the action (:data:`~agents.rl.plan_config.PLAN_ACTIONS`, 5
entries in [-1, 1]: stride, cycle time, stability margin epsilon, COG height, swing clearance) sets the
:class:`~agents.expert.config.ExpertConfig` the expert's cycle planner plans with
(:func:`~agents.rl.plan_config.cycle_config`, bounded by :class:`~agents.rl.plan_config.PlanConfig`), and the env runs
the control steps of ``QuadUneven-v0`` until the next control step would start a new cycle. The stability-constrained
planner still enforces every constraint on the adjusted settings (a plan it finds infeasible falls back as the
expert's does). A zero action is the expert of ``PlanConfig.expert`` exactly (default: the adaptive expert,
``adaptation="learned"``; tested bit for bit against it in ``QuadUneven-v0``).

The first step's action plans only the replans of the first cycle (planned at the reset with the expert's own
settings): from the second step on, each step's action plans the cycle that step walks.

**Observation**: ``QuadUneven-v0``'s, then the expert features (:mod:`agents.rl.expert_features`: its plan now and
the tracking error), then the plan features (:mod:`agents.rl.plan_features`: the plan's margins, the expert's
friction and strength estimates, the current cycle's action). **Reward**: the sum over the cycle's control steps of
``QuadUneven-v0``'s named terms (progress, stability index, torque, energy, alive, fall), each summed in
``info["reward_terms"]``. **Episode end**: ``QuadUneven-v0``'s termination; truncated after
``PlanConfig.max_control_steps`` control steps. **Info**: the last control step's, with the summed reward terms,
``control_steps`` (this step's) and ``plan_action`` (5,), the same keys and shapes at every step and reset.

Usage::

    import gymnasium as gym
    import agents.rl  # registers QuadUnevenPlan-v0
    from agents.rl.plan_config import PlanConfig

    env = gym.make("QuadUnevenPlan-v0", config=PlanConfig(stride_range=0.2), terrain="rough")
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.envs.registration import register, registry

from agents.expert import ExpertConfig, ExpertPolicy
from agents.rl.expert_features import EXPERT_FEATURE_FIELDS, augmented_space, expert_features
from agents.rl.plan_config import PLAN_ACTION_SIZE, PlanConfig, check_plan_action, cycle_config
from agents.rl.plan_features import PLAN_FEATURE_FIELDS, augmented_plan_space, plan_features
from agents.rl.residual_config import expert_overrides, split_config
from quad_uneven_env.env import QuadUnevenEnv
from quad_uneven_env.fields import excerpt

PLAN_ENV_ID = "QuadUnevenPlan-v0"
"""Gymnasium id of the plan-level env (registered when this module is imported)."""


def install_plan_expert(env: gym.Env, config: PlanConfig) -> ExpertPolicy:
    """Put the expert of ``config`` (scaled to the env's robot) on ``env.unwrapped``'s physics-rate hook (call before
    ``reset``).

    :raises ValueError: on an env that is not ``QuadUneven-v0`` in ``action_mode="torque"``, or a config that is not
        a :class:`PlanConfig`.
    """
    if not isinstance(config, PlanConfig):
        raise ValueError(f"config must be a PlanConfig, got {excerpt(config)}")
    base = env.unwrapped
    if not isinstance(base, QuadUnevenEnv):
        raise ValueError(f"the plan env needs a QuadUneven-v0 env, got {type(base).__name__}")
    if base.action_mode != "torque":
        raise ValueError(
            f"action_mode must be 'torque' for the plan env (expert torques), got {excerpt(base.action_mode)}"
        )
    settings = config.expert
    if ExpertConfig.for_robot(base.robot) != ExpertConfig():
        settings = ExpertConfig.for_robot(base.robot, expert_overrides(settings))
    expert = ExpertPolicy(env, settings)
    base.set_controller(expert)
    return expert


class PlanExpertEnv(gym.Wrapper):
    """``QuadUneven-v0`` driven by the expert; one step is one gait cycle whose plan settings the action adjusts.

    :param env: a ``QuadUneven-v0`` env in torque mode, without a controller of its own (wrappers allowed).
    :param config: the plan action's ranges, the expert, the episode length (default :class:`PlanConfig`).
    """

    def __init__(self, env: gym.Env, config: PlanConfig | None = None) -> None:
        super().__init__(env)
        self.config = PlanConfig() if config is None else config
        self.expert = install_plan_expert(env, self.config)
        self.settings: ExpertConfig = self.expert.config
        """the expert's own settings (what a zero action plans with)."""
        self.action_space = spaces.Box(-1.0, 1.0, shape=(PLAN_ACTION_SIZE,), dtype=np.float32)
        self.observation_space = augmented_plan_space(augmented_space(env.observation_space))
        self.observation_structure: dict[str, slice] = dict(env.unwrapped.observation_structure)
        """name -> slice of every part of the observation: the env's, the expert features', the plan features'."""
        offset = int(env.observation_space.shape[0])
        for f in EXPERT_FEATURE_FIELDS + PLAN_FEATURE_FIELDS:
            self.observation_structure[f.name] = slice(offset, offset + f.size)
            offset += f.size
        self._zero_torque = np.zeros(env.action_space.shape, dtype=env.action_space.dtype)
        self._action = np.zeros(PLAN_ACTION_SIZE)
        self._control_steps = 0
        u = env.unwrapped
        self._last_physics_step = (u.frame_skip - 0.5) * float(u.model.opt.timestep)

    def _observation(self, obs: np.ndarray) -> np.ndarray:
        data = self.env.unwrapped.data
        return np.concatenate([obs, expert_features(self.expert, data), plan_features(self.expert, self._action)])

    def _next_step_starts_cycle(self) -> bool:
        """Whether the next control step reaches the end of the current cycle (controller time), with half a physics
        step of margin: cycle ends lie on the physics steps' grid."""
        t = float(self.env.unwrapped.data.time) - self.expert.controller.t0
        return t + self._last_physics_step >= self.expert.planner.t_end

    def reset(self, **kwargs: Any):
        """Reset the env (the expert plans its first cycle with its own settings); the info has the step's keys."""
        self.expert.planner.cycle_config = None
        self._action = np.zeros(PLAN_ACTION_SIZE)
        self._control_steps = 0
        obs, info = self.env.reset(**kwargs)
        info["control_steps"] = 0
        info["plan_action"] = self._action.copy()
        return self._observation(obs), info

    def step(self, action: np.ndarray):
        """One gait cycle planned with ``action``: the control steps of the env until the next one would start a new
        cycle (at least one), or the episode ends.

        :raises ValueError: on an action that is not 5 finite numbers (before anything runs).
        """
        a = check_plan_action(action)
        self._action = a
        self.expert.planner.cycle_config = cycle_config(self.settings, a, self.config)
        reward, terms, n = 0.0, None, 0
        while True:
            obs, r, terminated, truncated, info = self.env.step(self._zero_torque)
            n += 1
            self._control_steps += 1
            reward += float(r)
            step_terms = info["reward_terms"]
            terms = dict(step_terms) if terms is None else {k: terms[k] + step_terms[k] for k in terms}
            truncated = truncated or self._control_steps >= self.config.max_control_steps
            if terminated or truncated or self._next_step_starts_cycle():
                break
        info["reward_terms"] = terms
        info["control_steps"] = n
        info["plan_action"] = a.copy()
        return self._observation(obs), reward, terminated, truncated, info


def make_plan_env(config: PlanConfig | Mapping[str, Any] | None = None, **kwargs: Any) -> PlanExpertEnv:
    """The plan-level env (entry point of ``QuadUnevenPlan-v0``).

    :param config: a :class:`PlanConfig`, or a mapping of its fields; None: the defaults, or the :class:`PlanConfig`
        fields among ``kwargs``.
    :param kwargs: :class:`PlanConfig` fields (without ``config``), then ``QuadUnevenEnv`` arguments (``terrain``,
        ``randomization``, ``reward_weights``, ...); ``action_mode`` must be ``"torque"`` and ``controller`` is not
        accepted.
    :raises ValueError: on a bad argument (named).
    """
    if "controller" in kwargs:
        raise ValueError("controller is not accepted by the plan env: the expert is its controller")
    config = split_config(PlanConfig, config, kwargs, "plan env's settings")
    return PlanExpertEnv(QuadUnevenEnv(**kwargs), config)


if PLAN_ENV_ID not in registry:
    register(id=PLAN_ENV_ID, entry_point="agents.rl.plan_env:make_plan_env")

__all__ = ["PLAN_ENV_ID", "PlanExpertEnv", "install_plan_expert", "make_plan_env"]
