"""An adaptation law's gains on a controller's joint torques, updated once per control step.

:class:`AdaptiveGains` holds one law (:class:`~agents.control.adaptation.knee.KneeGainAdaptation`,
:class:`~agents.control.adaptation.learned.LearnedGainAdaptation`, or any object with their interface: a ``gain``
(12,) array, ``period`` (s), ``reset()`` and ``update(joint_pos_error, load, time_since_reset)``). At the first
physics step of every control step it feeds the law the tracking error of that step (planned minus measured joint
angles, rad) and the controller's torques over the torque limit (before the gains); at every physics step it
returns the torques times the gains:

    tau = g * tau_controller   (N m, per joint),   g updated at t = t_reset + k dt, k = 1, 2, ...
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from agents.control.adaptation.knee import KneeGainAdaptation
from agents.control.adaptation.learned import LearnedGainAdaptation
from quad_uneven_env.fields import excerpt

ADAPTATIONS = ("none", "knee", "learned")
"""Values of ``ExpertConfig.adaptation``: no gains, the knee law (:mod:`agents.control.adaptation.knee`), or
gains on all twelve joints from the learned strength estimator (:mod:`agents.control.adaptation.learned`)."""

_CLOCK_SLACK = 1e-9
"""s: a physics step this close to the next update time counts as the control step's first."""


class AdaptiveGains:
    """The gains of ``law`` applied to a controller's joint torques (see the module docstring).

    :param law: the adaptation law (``gain``, ``period``, ``reset()``, ``update(error, load, t)``).
    :param torque_limit: (12,) N m, the motors' limits: the law sees the torques over them.
    """

    def __init__(self, law: Any, torque_limit: np.ndarray) -> None:
        self.law = law
        self.torque_limit = np.asarray(torque_limit, dtype=np.float64).copy()
        self._t_reset = 0.0
        self._next_update = 0.0

    @property
    def gain(self) -> np.ndarray:
        """(12,) -: the law's gains on the joint torques now."""
        return self.law.gain

    def reset(self, time: float) -> None:
        """A new episode at simulator time ``time`` (s): the law back to its start; the first update one control
        step later."""
        self.law.reset()
        self._t_reset = float(time)
        self._next_update = self._t_reset + self.law.period

    def apply(
        self, tau: np.ndarray, time: float, q_joints: np.ndarray, planned_now: Callable[[float], tuple[Any, float]]
    ) -> np.ndarray:
        """The torques ``tau`` (12, N m) times the gains (a new array); the law updated first when a control step
        has begun.

        :param time: s, the simulator's clock.
        :param q_joints: (12,) rad, the measured joint angles.
        :param planned_now: the plan at a simulator time: ``planned_now(t)[0].q_joints`` (12,) rad
            (:meth:`agents.expert.ExpertPolicy.planned_now`); called only at an update.
        """
        if time >= self._next_update - _CLOCK_SLACK:
            law = self.law
            ref, _ = planned_now(time)
            law.update(ref.q_joints - q_joints, tau / self.torque_limit, time - self._t_reset)
            self._next_update += law.period
            if self._next_update <= time:  # a jump of the clock (never in a rollout): back on the control grid
                self._next_update = time + law.period
        return tau * self.law.gain


def make_adaptation(name: str, period: float, torque_limit: np.ndarray) -> AdaptiveGains | None:
    """The adaptation ``name`` (one of :data:`ADAPTATIONS`) updated every ``period`` s, or None for ``"none"``.

    :param torque_limit: (12,) N m, the motors' limits.
    :raises ValueError: naming ``adaptation`` and its allowed values on another name.
    """
    if name == "knee":
        return AdaptiveGains(KneeGainAdaptation(period), torque_limit)
    if name == "learned":
        return AdaptiveGains(LearnedGainAdaptation(period), torque_limit)
    if name == "none":
        return None
    raise ValueError(f"adaptation must be one of {list(ADAPTATIONS)}, got {excerpt(name)}")


__all__ = ["ADAPTATIONS", "AdaptiveGains", "make_adaptation"]
