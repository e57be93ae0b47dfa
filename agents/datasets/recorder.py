"""What ``quad-uneven collect`` records of one expert episode: per control step, the env's transition, the torques
the expert applied at physics rate, and its plan; the recorded action derived from those torques.

The expert acts through the env's physics-rate hook (its ``predict`` returns zeros), so the action a dataset holds is
derived: :func:`recorded_action` is the mean torque applied over the control step in the env's torque action scale
(torque / motor limit). :class:`TorqueRecorder` collects those torques: it wraps the expert as the env's controller,
forwards every call and reset to it, and copies ``data.ctrl`` (the torques MuJoCo applies, N m; after the
randomized latency's delay, if any) once per physics step. Formats, units and what can be replayed:
docs/datasets.md.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import mujoco
import numpy as np

from quad_uneven_env import constants as C
from quad_uneven_env.fields import excerpt

__all__ = ["INFO_FIELDS", "EpisodeRecorder", "TorqueRecorder", "TorqueReplay", "info_fields", "recorded_action"]

INFO_FIELDS: dict[str, tuple[str, str]] = {
    "time": ("s", "simulated time of the observation"),
    "stability_index": ("N m", "the paper's stability index (smallest edge moment; negative: tipping)"),
    "stability_index_normalized": ("m", "stability_index / (total mass x g)"),
    "edge_moments": ("N m", "(4,) tumbling moment about each clockwise support edge; +inf beyond the stance count"),
    "contact_forces": ("N", "(4, 3) contact force on each foot, world frame (zero in the air)"),
    "foot_contact": ("-", "(4,) foot touches the terrain"),
    "cog": ("m", "(3,) centre of gravity, world frame"),
    "cog_vel": ("m/s", "(3,) COG velocity, world frame"),
    "feet_pos": ("m", "(4, 3) foot centres, world frame"),
    "distance": ("m", "COG travel along +x since the reset"),
    "push_force": ("N", "(3,) mean push force on the trunk over the step just taken, world frame"),
    "diverged": ("-", "the step failed and was undone (the episode ends there)"),
    "torques": (
        "N m",
        "(frame_skip, 12) joint torques applied at each physics step of the control step just taken (zeros at the "
        "reset)",
    ),
    "planned_stance": ("-", "(4,) feet the expert's current plan has in stance at the observation's time"),
    "gait_phase": ("-", "phase of the expert's current gait cycle in [0, 1]"),
    "joint_reference": ("rad", "(12,) the plan's joint angles at the observation's time"),
    "joint_velocity_reference": ("rad/s", "(12,) the plan's joint velocities at the observation's time"),
    "command": ("m/s, rad/s", "(3,) vx, vy, yaw rate to follow (only in an env with a command)"),
    "reward_terms": ("-", "each reward term of the step just taken (zeros at the reset)"),
}
"""The infos of a collected step: name -> (unit, meaning); one row per observation (the reset's and each step's)."""

_DTYPES = {"foot_contact": bool, "planned_stance": bool, "diverged": bool}
"""Infos stored as booleans (the others as float64: the torques exactly as applied, so that replaying them at
physics rate reproduces the episode, :class:`TorqueReplay`)."""

_COPIED = ("edge_moments", "contact_forces", "foot_contact", "cog", "cog_vel", "feet_pos", "push_force")
"""Arrays of the env's ``info`` copied as they are."""


def info_fields(command: bool) -> list[str]:
    """The names of the infos of a collected step (``command`` only for an env with a command)."""
    return [k for k in INFO_FIELDS if command or k != "command"]


def recorded_action(torques: np.ndarray, torque_limit: np.ndarray) -> np.ndarray:
    """The recorded action of a control step: the mean applied torque in the env's torque action scale.

    :param torques: (frame_skip, 12) N m, the torques applied at each physics step.
    :param torque_limit: (12,) N m, the motor limits (``env.unwrapped.idx.torque_limit``).
    :return: (12,) float32 in [-1, 1]: mean torque / limit (what ``action_mode="torque"`` multiplies by the limit).
    """
    mean = np.asarray(torques, dtype=np.float64).mean(axis=0) / np.asarray(torque_limit, dtype=np.float64)
    return np.clip(mean, -1.0, 1.0).astype(np.float32)


class TorqueRecorder:
    """The expert as the env's physics-rate controller, keeping the torques applied at every physics step.

    It forwards ``reset``, the call and the fast lane (``torques_into``) to the expert, whose ``check_attached``
    accepts it (it holds the expert as ``.expert``). The env tries the lane first at every physics step, so the
    lane is where the step count lives: at physics step j > 0 of a control step, ``data.ctrl`` still holds the
    torques applied at step j - 1; :meth:`end_step` takes the last one after ``env.step``. A copy of 12 floats per
    physics step is all it adds to the expert's compiled lane.

    :param expert: an :class:`agents.expert.ExpertPolicy` built for the env.
    :param frame_skip: physics steps per control step.
    """

    def __init__(self, expert: Any, frame_skip: int) -> None:
        self.expert = expert
        self.torques = np.zeros((frame_skip, C.N_JOINTS))
        """(frame_skip, 12) N m: the torques applied at each physics step of the current control step."""
        self._j = 0  # physics steps of the current control step that reached the controller

    def reset(self, model: mujoco.MjModel, data: mujoco.MjData, terrain: Any) -> None:
        """The env's reset, forwarded to the expert."""
        self._j = 0
        self.expert.reset(model, data, terrain)

    def __call__(self, model: mujoco.MjModel, data: mujoco.MjData, action: np.ndarray) -> np.ndarray:
        """The expert's torques (N m); called by the env only after the lane declined the same physics step."""
        return self.expert(model, data, action)

    def torques_into(
        self, model: mujoco.MjModel, data: mujoco.MjData, action: Any, out: np.ndarray, limit: np.ndarray
    ) -> bool:
        """Keep the torques applied at the previous physics step, then the expert's fast lane."""
        j = self._j
        if 0 < j <= self.torques.shape[0]:
            self.torques[j - 1] = data.ctrl
        self._j = j + 1
        return self.expert.torques_into(model, data, action, out, limit)

    def end_step(self, data: mujoco.MjData) -> np.ndarray:
        """(frame_skip, 12) N m: the torques applied over the control step just taken (a copy; rows of physics steps
        a failed step never reached are zero)."""
        j, fs = self._j, self.torques.shape[0]
        if 0 < j <= fs:
            self.torques[j - 1] = data.ctrl
        self.torques[max(j, 0) :] = 0.0
        self._j = 0
        return self.torques.copy()


class EpisodeRecorder:
    """Records an expert episode run by :func:`agents.evaluation.episode.run_task` (its ``EpisodeObserver``).

    :meth:`start` installs a :class:`TorqueRecorder` around the expert; :meth:`arrays` returns the episode as the
    arrays of a Minari episode: ``observations`` (N + 1, obs) float32, ``actions`` (N, 12) float32, ``rewards`` (N,),
    ``terminations`` and ``truncations`` (N,) bool, and ``infos/NAME`` (N + 1, ...) for every :data:`INFO_FIELDS`
    name (``infos/reward_terms/TERM`` for the reward terms).
    """

    def __init__(self) -> None:
        self.env: Any = None
        self.env_kwargs: dict[str, Any] = {}
        self.expert: Any = None
        self.torque_recorder: TorqueRecorder | None = None
        self.obs: list[np.ndarray] = []
        self.actions: list[np.ndarray] = []
        self.rewards: list[float] = []
        self.terminations: list[bool] = []
        self.truncations: list[bool] = []
        self.infos: dict[str, list[Any]] = {}
        self.reward_terms: dict[str, list[float]] = {}
        self._limit = np.ones(C.N_JOINTS)
        self._prev_action: slice | None = None

    def start(self, env: gym.Env, policy: Any) -> None:
        """Wrap the expert ``policy`` (installed by ``attach_expert``) in a :class:`TorqueRecorder`.

        :raises ValueError: if ``policy`` is not the expert, or the env is not in ``action_mode="torque"``.
        """
        u = env.unwrapped
        if u.controller is not policy or not hasattr(policy, "planned_now"):
            raise ValueError(f"collect records the scripted expert only, got a {type(policy).__name__}")
        if u.action_mode != "torque":
            raise ValueError(
                f"env_kwargs.action_mode must be 'torque' to collect the expert, got {excerpt(u.action_mode)}"
            )
        self.env, self.expert = u, policy
        spec = env.spec
        steps = None if spec is None else spec.max_episode_steps
        self.env_kwargs = {**(spec.kwargs if spec is not None else {}), "max_episode_steps": steps}
        """the QuadUneven-v0 arguments the episode's env was made with (``gym.make`` rebuilds it)."""
        self.torque_recorder = TorqueRecorder(policy, u.frame_skip)
        u.set_controller(self.torque_recorder)
        self._limit = np.asarray(u.idx.torque_limit, dtype=np.float64)
        self._prev_action = u.observation_structure["prev_action"]

    def _add_info(self, info: dict[str, Any], torques: np.ndarray) -> None:
        u, rows = self.env, self.infos
        ref, phase = self.expert.planned_now(float(u.data.time))
        row: dict[str, Any] = {
            "time": float(u.data.time),
            "stability_index": float(info["stability_index"]),
            "stability_index_normalized": float(info["stability_index_normalized"]),
            **{k: np.asarray(info[k]).copy() for k in _COPIED},
            "distance": float(info["distance"]),
            "diverged": bool(info["diverged"]),
            "torques": torques,
            "planned_stance": np.asarray(ref.stance, dtype=bool),
            "gait_phase": float(phase),
            "joint_reference": np.asarray(ref.q_joints, dtype=np.float64).copy(),
            "joint_velocity_reference": np.asarray(ref.qd_joints, dtype=np.float64).copy(),
        }
        if "command" in info:
            row["command"] = np.asarray(info["command"], dtype=np.float64).copy()
        for k, v in row.items():
            rows.setdefault(k, []).append(v)
        for k, v in info["reward_terms"].items():
            self.reward_terms.setdefault(k, []).append(float(v))

    def reset(self, obs: np.ndarray, info: dict[str, Any]) -> None:
        """The reset's observation and info (torques and reward terms zero)."""
        self.obs.append(np.asarray(obs, dtype=np.float32).copy())
        self._add_info(info, np.zeros_like(self.torque_recorder.torques))

    def step(
        self, action: np.ndarray, obs: np.ndarray, reward: float, terminated: bool, truncated: bool, info: dict
    ) -> None:
        """One ``env.step``: the recorded action from the applied torques, the transition, the infos."""
        torques = self.torque_recorder.end_step(self.env.data)
        self.actions.append(recorded_action(torques, self._limit))
        self.obs.append(np.asarray(obs, dtype=np.float32).copy())
        self.rewards.append(float(reward))
        self.terminations.append(bool(terminated))
        self.truncations.append(bool(truncated))
        self._add_info(info, torques)

    def arrays(self) -> dict[str, np.ndarray]:
        """The episode as flat arrays (see the class docstring); ``truncations[-1]`` is set when the episode ended
        without the env's termination or truncation (the suite's goal or waypoints reached, the wall-time limit, an
        error). The observations' ``prev_action`` field holds the previous recorded action (see docs/datasets.md)."""
        # an error inside a step can leave one list a row longer than the others: keep the whole steps only
        n = min(len(self.actions), len(self.rewards), len(self.obs) - 1, *(len(v) - 1 for v in self.infos.values()))
        n = min(n, *(len(v) - 1 for v in self.reward_terms.values())) if self.reward_terms else n
        obs = np.asarray(self.obs[: n + 1], dtype=np.float32)
        actions = np.asarray(self.actions[:n], dtype=np.float32).reshape(-1, C.N_JOINTS)
        if len(actions) and self._prev_action is not None:  # what the plain env shows a policy taking these actions
            sl = self._prev_action
            obs[1:, sl] = np.clip(obs[1:, sl] + actions, -1.0, 1.0)
        truncations = np.asarray(self.truncations[:n], dtype=bool)
        terminations = np.asarray(self.terminations[:n], dtype=bool)
        if len(truncations) and not (terminations[-1] or truncations[-1]):
            truncations[-1] = True
        out: dict[str, np.ndarray] = {
            "observations": obs,
            "actions": actions,
            "rewards": np.asarray(self.rewards[:n], dtype=np.float64),
            "terminations": terminations,
            "truncations": truncations,
        }
        for k, v in self.infos.items():
            out[f"infos/{k}"] = np.asarray(v[: n + 1], dtype=_DTYPES.get(k, np.float64))
        for k, v in self.reward_terms.items():
            out[f"infos/reward_terms/{k}"] = np.asarray(v[: n + 1], dtype=np.float64)
        return out


class TorqueReplay:
    """A physics-rate controller that applies an episode's recorded torques again, one row per physics step.

    Installed in the episode's env (``env.unwrapped.set_controller``) before the reset with the episode's seed, it
    reproduces the episode's trajectory when the env applies torques without delay (no ``latency`` in its
    randomization; with a latency of k physics steps the env would apply each row k steps late). Past the last row
    it applies zero torques.

    :param torques: (N, frame_skip, 12) N m, the episode's ``infos["torques"][1:]`` (or (N x frame_skip, 12)).
    """

    def __init__(self, torques: np.ndarray) -> None:
        self.torques = np.asarray(torques, dtype=np.float64).reshape(-1, C.N_JOINTS)
        self._n = 0

    def reset(self, model: mujoco.MjModel, data: mujoco.MjData, terrain: Any) -> None:
        """Start from the first row again."""
        self._n = 0

    def __call__(self, model: mujoco.MjModel, data: mujoco.MjData, action: np.ndarray) -> np.ndarray:
        """The next row (N m)."""
        n = self._n
        self._n = n + 1
        return self.torques[n].copy() if n < len(self.torques) else np.zeros(C.N_JOINTS)
