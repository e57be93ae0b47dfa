"""The proprioceptive history of the observation: the last control steps' joint angles, velocities and actions.

A policy that cannot see the world's friction, payload or motor strength can infer them from how its joints
answered its last actions (teacher-student locomotion: Lee et al. 2020, Kumar et al. 2021). With
``proprio_history=H`` the env appends the H previous observations' ``joint_pos``, ``joint_vel`` and
``prev_action`` (as observed: noise included), oldest first, as three fields of H x 12 values
(:func:`history_fields`). After a reset every row holds the reset's values (the robot stood still).
"""

from __future__ import annotations

import numpy as np

from quad_uneven_env.observations import ObsField

HISTORY_SOURCES = ("joint_pos", "joint_vel", "prev_action")
"""Observation fields whose past values the history keeps, in the order of :func:`history_fields`."""

MAX_HISTORY = 50
"""The longest history, in control steps (1 s at the default 50 Hz)."""


def history_fields(fields: tuple[ObsField, ...], steps: int) -> tuple[ObsField, ...]:
    """The history fields of ``steps`` control steps for the layout ``fields`` (which holds
    :data:`HISTORY_SOURCES`): ``<source>_history`` of ``steps x size`` values, oldest step first."""
    if steps == 0:
        return ()
    by_name = {f.name: f for f in fields}
    return tuple(
        ObsField(
            f"{name}_history",
            steps * by_name[name].size,
            by_name[name].low,
            by_name[name].high,
            by_name[name].unit,
            f"``{name}`` of the {steps} previous control steps, oldest first; only with ``proprio_history``",
        )
        for name in HISTORY_SOURCES
    )


class ProprioHistory:
    """A ring of the last ``steps`` observations' :data:`HISTORY_SOURCES`, written after the current observation.

    :param structure: the slices of the observation without the history (``observation_structure``).
    :param steps: H, control steps kept (0: none; then :meth:`observe` returns its input).
    """

    def __init__(self, structure: dict[str, slice], steps: int) -> None:
        self.steps = int(steps)
        self._sources = [structure[name] for name in HISTORY_SOURCES]
        self._rows = np.zeros((self.steps, sum(s.stop - s.start for s in self._sources)), dtype=np.float32)

    def _current(self, obs: np.ndarray) -> np.ndarray:
        return np.concatenate([obs[s] for s in self._sources])

    def reset(self, obs: np.ndarray) -> np.ndarray:
        """Fill every row with ``obs``'s values; :return: ``obs`` with the history appended (float32)."""
        self._rows[:] = self._current(obs)
        return self._append(obs)

    def push(self, obs: np.ndarray, previous: np.ndarray) -> np.ndarray:
        """Shift in the ``previous`` observation's values (the step before ``obs``); :return: ``obs`` with the
        history appended (float32)."""
        if self.steps:
            self._rows[:-1] = self._rows[1:]
            self._rows[-1] = self._current(previous)
        return self._append(obs)

    def _append(self, obs: np.ndarray) -> np.ndarray:
        if not self.steps:
            return obs
        n = [s.stop - s.start for s in self._sources]
        parts = np.split(self._rows, np.cumsum(n)[:-1], axis=1)  # per source: (H, size), oldest row first
        return np.concatenate([obs, *(p.ravel() for p in parts)]).astype(np.float32, copy=False)
