"""The simulated world of one episode: the model as made, the randomization's draw written into it, observation noise.

:class:`SimulatedWorld` is the env's side of :mod:`quad_uneven_env.randomization`: at every reset it puts the model
back to its state at the first reset (:meth:`SimulatedWorld.restore_model`), draws the episode's world from a child
of ``np_random`` and writes it into the model (:meth:`SimulatedWorld.draw`), and adds the configured noise to every
returned observation (:meth:`SimulatedWorld.observe`). The latency and the pushes it draws act in the physics loop
(:class:`quad_uneven_env.stepper.PhysicsStepper`).
"""

from __future__ import annotations

import copy
import dataclasses
from typing import Any

import mujoco
import numpy as np
from gymnasium import spaces

from quad_uneven_env.observations import ObsField
from quad_uneven_env.physics import RobotIndex
from quad_uneven_env.randomization import EpisodeDraw, ModelRandomizer, RandomizationConfig, draw_episode

_NOT_RESTORED = ("hfield_data", "tex_data")
"""Model arrays rewritten at every reset anyway (the terrain) or read only by the renderer (textures)."""


class SimulatedWorld:
    """The env's model between episodes and the episode's drawn world.

    :param model: the env's compiled model (its actuators final: ``joint_pd`` servos already made).
    :param idx: the model's resolved robot ids.
    :param randomization: what is drawn per episode (None: the nominal world).
    :param servo: the actuators are ``joint_pd`` servos.
    :param control_dt: s, the env's control period (the latency's upper bound).
    :param fields: the observation layout. :param observation_space: its Box (the noisy observation's bounds).
    :raises ValueError: if the randomization's latency exceeds the control period.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        idx: RobotIndex,
        randomization: RandomizationConfig | None,
        servo: bool,
        control_dt: float,
        fields: tuple[ObsField, ...],
        observation_space: spaces.Box,
    ) -> None:
        cfg = randomization
        if cfg is not None and cfg.latency is not None and cfg.latency[1] > control_dt * (1 + 1e-9):
            raise ValueError(
                f"randomization.latency must be a [low, high] pair with high <= the control period "
                f"{control_dt:g} s (frame_skip x timestep), got {list(cfg.latency)}"
            )
        self.model = model
        self.config = cfg
        self.randomizer = ModelRandomizer(model, idx, servo=servo)
        """writes each episode's draw into ``model`` and restores the nominal model (``restore()``)."""
        self.rng: np.random.Generator | None = None
        """the episode's generator (a child of ``np_random``; None without randomization)."""
        self._physics_dt = float(model.opt.timestep)
        r = self.randomizer
        nominal = draw_episode(
            None, None, r.nominal_friction, r.nominal_damping, r.nominal_frictionloss, self._physics_dt
        )
        self.episode_draw: EpisodeDraw = dataclasses.replace(nominal, total_mass=idx.total_mass)
        """this episode's drawn world (nominal values where a factor is off)."""
        self.draw_info: dict[str, float] = self.episode_draw.as_info()
        """:attr:`episode_draw` as ``info["randomization"]``."""
        noise = cfg.observation_noise if cfg is not None else None
        self._noise_scale = None
        self._obs_low64 = observation_space.low.astype(np.float64)
        self._obs_high64 = observation_space.high.astype(np.float64)
        if noise is not None and noise.any():  # the command is an input, not a measurement: never noisy
            self._noise_scale = np.concatenate(
                [np.full(f.size, 0.0 if f.name == "command" else getattr(noise, f.name)) for f in fields]
            )
        self._pristine_model: mujoco.MjModel | None = None  # the model at the first reset (see restore_model)
        self._model_views: list[tuple[np.ndarray, np.ndarray]] = []

    @property
    def total_mass(self) -> float:
        """kg, the simulated whole-robot mass of this episode."""
        return self.episode_draw.total_mass

    def restore_model(self) -> None:
        """Every numeric field of the model back to its value at the first reset (~0.25 ms): whatever a physics-rate
        controller or other code changes in ``env.unwrapped.model`` during an episode (a body mass, the timestep)
        lasts until the next reset, not beyond. Changes made between ``make`` and the first reset are kept for every
        episode. The randomized world is drawn after this."""
        if self._pristine_model is None:
            self._pristine_model = copy.deepcopy(self.model)
            self._bind_model_views()
            return
        for live, pristine in self._model_views:
            live[...] = pristine
        opt, saved = self.model.opt, self._pristine_model.opt
        for name in self._option_names:
            setattr(opt, name, getattr(saved, name))

    def _bind_model_views(self) -> None:
        """Pairs (the model's array, the pristine copy's) that :meth:`restore_model` copies, and the option names."""
        m, p = self.model, self._pristine_model
        if p is None:
            return
        names = [
            n for n in dir(m) if not n.startswith("_") and n not in _NOT_RESTORED
            and isinstance(getattr(m, n), np.ndarray) and getattr(m, n).size
        ]  # fmt: skip
        self._model_views = [(getattr(m, n), getattr(p, n)) for n in names]
        self._option_names = [n for n in dir(m.opt) if not n.startswith("_")]

    def __getstate__(self) -> dict[str, Any]:
        """Pickle and ``copy.deepcopy``: everything but the views of the models (rebound to the copy's own)."""
        return {k: v for k, v in self.__dict__.items() if k != "_model_views"}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._model_views = []
        self._bind_model_views()

    def draw(self, rng: np.random.Generator | None) -> None:
        """Draw this episode's world from ``rng`` and write it into the model (nothing without randomization).

        ``rng`` is a child of ``np_random`` (``np_random.spawn``, made by the env's reset): the same seed gives the
        same world whatever the terrain generator consumed, and the terrain and reset noise are those of the
        nominal env. The pushes and the observation noise of the episode are drawn from it too.
        """
        cfg, r = self.config, self.randomizer
        if cfg is None:
            return
        self.rng = rng
        draw = draw_episode(cfg, rng, r.nominal_friction, r.nominal_damping, r.nominal_frictionloss, self._physics_dt)
        self.episode_draw = r.apply(cfg, draw)
        self.draw_info = self.episode_draw.as_info()

    def observe(self, obs: np.ndarray) -> np.ndarray:
        """The float32 observation of the measured ``obs``, with this config's noise, clipped to the Box."""
        if self._noise_scale is None:
            return obs.astype(np.float32)
        noisy = obs + self._noise_scale * self.rng.uniform(-1.0, 1.0, obs.shape[0])
        np.clip(noisy, self._obs_low64, self._obs_high64, out=noisy)
        return noisy.astype(np.float32)
