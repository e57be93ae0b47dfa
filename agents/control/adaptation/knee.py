"""The knee law: an adaptive gain on the expert's knee torques, its estimate of its own knee motors.

The expert's model assumes nominal motors. In the extreme world a knee motor delivers 50-130 % of the torque
it is sent, and a loaded knee then sags: its tracking error (planned minus measured angle) follows the torque
it carries. The adaptation integrates that correlation into a gain per knee (a normalised gradient law, as
in model-reference adaptive control),

    A <- A + (dt / T) (u^2 - A),   B <- B + (dt / T) (u e - B),   g <- clip(g + k dt B / (A + eps), g_min, g_max)

with ``u`` the expert's knee torque over the torque limit and ``e`` the knee's tracking error (rad), once per
control step ``dt``. It stops moving where the knee's error no longer follows its load: a knee at strength s
settles near g = 1/s (an overloaded knee higher). The gains multiply the expert's knee torques
(``ExpertConfig(adaptation="knee")``). Only the knees: on the validation worlds an oracle that undoes the drawn
strength of the four knee motors recovers most of what undoing all twelve does (docs/rl.md), and the knees'
error follows their strength most closely (``benchmarks/knee_strength_signal.py``); the same law on all twelve
joints did no better on the validation worlds.
"""

from __future__ import annotations

import numpy as np

from quad_uneven_env import constants as C
from quad_uneven_env.fields import excerpt

KNEE_JOINTS = np.arange(C.JOINT_KINDS.index("KFE"), C.N_JOINTS, len(C.JOINT_KINDS))
"""Indices of the knee (KFE) joints in the 12-joint order LF RF LH RH x HAA HFE KFE."""

ADAPTATION_RATE = 0.5
"""k: gain change per second per unit of the normalised correlation B / A (1/s per rad)."""
CORRELATION_TIME = 0.5
"""T (s): time constant of the running means A and B."""
GAIN_BOUNDS = (0.75, 2.0)
"""(g_min, g_max): the inverses of the strongest (1.3) and the weakest (0.5) motor of the extreme world."""
START_TIME = 0.5
"""s after a reset before the first update: the robot settles on its spawn pose first."""
EPS = 1e-4
"""Regulariser of the normalisation (a knee carrying no load does not move its gain)."""


class KneeGainAdaptation:
    """The adaptive knee gains (12 joint gains of which the knees move; the others stay 1).

    :param period: s between two updates (the control step).
    """

    def __init__(self, period: float) -> None:
        if not period > 0.0:
            raise ValueError(f"period must be a positive number of seconds, got {excerpt(period)}")
        self.period = float(period)
        self.gain = np.ones(12)
        """(12,) -, the gain per joint on the expert's torque."""
        self._a = np.zeros(len(KNEE_JOINTS))
        self._b = np.zeros(len(KNEE_JOINTS))

    def reset(self) -> None:
        """Back to gain 1 and no history (every episode: a new robot)."""
        self.gain[:] = 1.0
        self._a[:] = 0.0
        self._b[:] = 0.0

    def update(self, joint_pos_error: np.ndarray, expert_torque: np.ndarray, time_since_reset: float) -> None:
        """One control step of the law.

        :param joint_pos_error: (12,) rad, planned minus measured joint angles.
        :param expert_torque: (12,) -, the expert's joint torques over the torque limit.
        :param time_since_reset: s since the episode's reset (no update before :data:`START_TIME`).
        """
        if time_since_reset < START_TIME:
            return
        u = np.asarray(expert_torque, dtype=float)[KNEE_JOINTS]
        e = np.asarray(joint_pos_error, dtype=float)[KNEE_JOINTS]
        w = self.period / CORRELATION_TIME
        self._a += w * (u * u - self._a)
        self._b += w * (u * e - self._b)
        step = ADAPTATION_RATE * self.period * self._b / (self._a + EPS)
        self.gain[KNEE_JOINTS] = np.clip(self.gain[KNEE_JOINTS] + step, *GAIN_BOUNDS)


__all__ = [
    "ADAPTATION_RATE",
    "CORRELATION_TIME",
    "EPS",
    "GAIN_BOUNDS",
    "KNEE_JOINTS",
    "START_TIME",
    "KneeGainAdaptation",
]
