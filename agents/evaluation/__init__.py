"""Evaluation: suites of terrains x seeds, one episode, metrics, targets, the run with workers, report.md.

Typical use::

    from agents.evaluation import evaluate, load_suite
    results = evaluate(load_suite("rough"), "expert", "out/rough", workers=2)
"""

from agents.evaluation.episode import EnvArgumentError, EpisodeResult, EvalConfig, run_task
from agents.evaluation.policies import PolicyError, make_policy
from agents.evaluation.results_io import ResultsError, load_results
from agents.evaluation.run import EvaluationInterrupted, evaluate
from agents.evaluation.suites import (
    EpisodeTask,
    Suite,
    SuiteError,
    TerrainEntry,
    load_suite,
    suite_from_dict,
    suite_names,
)

__all__ = [
    "EnvArgumentError",
    "EpisodeResult",
    "EpisodeTask",
    "EvalConfig",
    "EvaluationInterrupted",
    "PolicyError",
    "ResultsError",
    "Suite",
    "SuiteError",
    "TerrainEntry",
    "evaluate",
    "load_results",
    "load_suite",
    "make_policy",
    "run_task",
    "suite_from_dict",
    "suite_names",
]
