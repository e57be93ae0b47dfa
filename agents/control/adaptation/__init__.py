"""Adaptive control of the expert: gains on its joint torques that learn the robot's motors as it walks.

``ExpertConfig(adaptation=...)`` picks one of :data:`ADAPTATIONS`: ``"knee"`` (:mod:`.knee`, a gradient law on
the four knees' tracking error against their load) or ``"learned"`` (:mod:`.learned`, a strength estimator fitted
on training worlds drives gains on all twelve joints; its parameters are package data,
``data/strength_estimator.npz``, refitted by ``quad-uneven fit-strength``). :class:`AdaptiveGains` applies a law's
gains to the torques, updated once per control step (:mod:`.torques`).
"""

from agents.control.adaptation.knee import KneeGainAdaptation
from agents.control.adaptation.learned import LearnedGainAdaptation, StrengthEstimator, estimator_digest
from agents.control.adaptation.torques import ADAPTATIONS, AdaptiveGains, make_adaptation

__all__ = [
    "ADAPTATIONS",
    "AdaptiveGains",
    "KneeGainAdaptation",
    "LearnedGainAdaptation",
    "StrengthEstimator",
    "estimator_digest",
    "make_adaptation",
]
