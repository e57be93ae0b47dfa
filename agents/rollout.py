"""Run one episode of any SB3-style policy and record what a report needs."""

from __future__ import annotations

import dataclasses
from typing import Any, Protocol

import gymnasium as gym
import numpy as np
from tqdm.auto import tqdm


class Policy(Protocol):
    """SB3's predict protocol: the scripted expert and learned agents both follow it."""

    def predict(
        self,
        observation: np.ndarray,
        state: Any = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = True,
    ) -> tuple[np.ndarray, Any]: ...


class ZeroActionPolicy:
    """Always the zero action: in ``joint_pd`` mode the robot holds its standing pose."""

    def __init__(self, action_space: gym.spaces.Box) -> None:
        self._zero = np.zeros(action_space.shape, dtype=action_space.dtype)

    def predict(self, observation, state=None, episode_start=None, deterministic=True):
        """:return: the zero action and the unchanged state."""
        return self._zero.copy(), state


@dataclasses.dataclass
class EpisodeRecord:
    """Time series of one episode (one row per control step, SI units, world frame)."""

    time: np.ndarray
    cog: np.ndarray
    cog_vel: np.ndarray
    stability_index: np.ndarray
    feet_pos: np.ndarray
    foot_contact: np.ndarray
    contact_forces: np.ndarray
    torques: np.ndarray
    rewards: np.ndarray
    termination_reason: str | None
    diverged: bool
    frames: list[np.ndarray]


def run_episode(
    env: gym.Env,
    policy: Policy,
    seed: int | None = None,
    max_steps: int | None = None,
    frame_every: int = 0,
    progress: bool = True,
) -> EpisodeRecord:
    """Roll ``policy`` out in ``env`` until termination, truncation or ``max_steps``.

    :param frame_every: keep a rendered frame every this many steps (0: none; needs render_mode="rgb_array").
    """
    obs, info = env.reset(seed=seed)
    u = env.unwrapped
    rows: dict[str, list] = {
        k: [] for k in ("time", "cog", "cog_vel", "index", "feet", "contact", "forces", "tau", "r")
    }
    frames: list[np.ndarray] = []
    state, start = None, np.ones(1, dtype=bool)
    limit = max_steps or getattr(env.spec, "max_episode_steps", None) or 1000
    reason, diverged = None, False
    for step in tqdm(range(limit), desc="rollout", disable=not progress, unit="step"):
        action, state = policy.predict(obs, state=state, episode_start=start, deterministic=True)
        start = np.zeros(1, dtype=bool)
        obs, reward, terminated, truncated, info = env.step(action)
        rows["time"].append(u.data.time)
        rows["cog"].append(info["cog"])
        rows["cog_vel"].append(info["cog_vel"])
        rows["index"].append(info["stability_index"])
        rows["feet"].append(info["feet_pos"])
        rows["contact"].append(info["foot_contact"])
        rows["forces"].append(info["contact_forces"])
        rows["tau"].append(u.data.actuator_force.copy())
        rows["r"].append(reward)
        if frame_every and step % frame_every == 0:
            frames.append(env.render())
        if terminated or truncated:
            reason, diverged = info["termination_reason"], info["diverged"]
            break
    return EpisodeRecord(
        time=np.asarray(rows["time"]),
        cog=np.asarray(rows["cog"]).reshape(-1, 3),
        cog_vel=np.asarray(rows["cog_vel"]).reshape(-1, 3),
        stability_index=np.asarray(rows["index"]),
        feet_pos=np.asarray(rows["feet"]).reshape(-1, 4, 3),
        foot_contact=np.asarray(rows["contact"]).reshape(-1, 4),
        contact_forces=np.asarray(rows["forces"]).reshape(-1, 4, 3),
        torques=np.asarray(rows["tau"]).reshape(-1, 12),
        rewards=np.asarray(rows["r"]),
        termination_reason=reason,
        diverged=diverged,
        frames=frames,
    )
