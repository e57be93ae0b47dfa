"""Policies and what runs them: the paper's control (:mod:`.control`), the scripted expert (:mod:`.expert`),
evaluation (:mod:`.evaluation`), residual RL (:mod:`.rl`), the paper's §6 run (:mod:`.paper`), the CLI.

``import agents`` stays light (no torch, no Stable-Baselines3, no compiled kernels); the expert is
imported on first use of its names.
"""

from typing import Any

from agents.policy import Policy, ZeroActionPolicy

__all__ = ["ExpertConfig", "ExpertPolicy", "Policy", "ZeroActionPolicy", "attach_expert"]


def __getattr__(name: str) -> Any:
    if name in ("ExpertConfig", "ExpertPolicy", "attach_expert"):  # deferred: the controller's kernels compile
        from agents import expert

        return getattr(expert, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
