"""``quad-uneven baselines``: several policies on the same held-out episodes of several suites, as one markdown table.

Typical use::

    quad-uneven baselines --policies zero,expert,expert:learned,models/distilled/model.zip \\
        --suites targets,robust_hard,targets@go1 --out out/baselines --workers 2

Each (policy, suite) pair is one ``evaluate`` run (:func:`agents.evaluation.run.evaluate`) in
``DIR/runs/POLICY/SUITE/``: a rerun of the same command resumes them (finished episodes are kept), and ``--workers``,
``--backend ray`` are ``evaluate``'s. ``DIR/baselines.md`` has the table (rows policies, columns suites: episodes
that reached the goal / episodes) and one per-entry table per suite; ``DIR/baselines.json`` the same figures.

Policies: ``zero`` (zero action in ``joint_pd``: the standing pose held), ``expert``, ``expert:ADAPTATION`` (the
expert with ``ExpertConfig.adaptation``, e.g. ``expert:learned``), the path of an SB3 model ``.zip`` or of an ONNX
file ``quad-uneven export`` wrote. Suites: a
shipped name or a suite YAML path, with ``@ROBOT`` to run it on that robot at its scale (``evaluate --robot ROBOT
--scale-terrain``). A model trained on another robot than a column's gets no figure there (``n/a``).
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from agents.control.adaptation import ADAPTATIONS
from agents.evaluation.policies import PolicyError, policy_kind
from agents.evaluation.run import evaluate
from agents.evaluation.store import RUN_FILE
from agents.evaluation.suites import Suite, load_suite
from agents.outputs import write_json_atomic
from quad_uneven_env.fields import excerpt

__all__ = ["BaselinePolicy", "BaselineSuite", "baselines", "parse_policy", "parse_suite", "table_markdown"]

PAPER_ROBOT = "paper"
"""The robot a suite column without ``@ROBOT`` runs on."""


@dataclasses.dataclass(frozen=True)
class BaselinePolicy:
    """A row of the table: the policy ``evaluate`` runs and the expert settings it runs with."""

    spec: str
    """as given, e.g. ``expert:learned``."""
    policy: str
    """``evaluate``'s policy: ``zero``, ``expert`` or a model path."""
    expert_config: dict[str, Any]
    """fields of :class:`agents.expert.ExpertConfig` (``expert`` only)."""

    @property
    def slug(self) -> str:
        """Its folder name under ``DIR/runs``."""
        return _slug(
            self.spec.removesuffix(".zip").removesuffix(".onnx") + ("-onnx" if self.spec.endswith(".onnx") else "")
        )


@dataclasses.dataclass(frozen=True)
class BaselineSuite:
    """A column of the table: a suite, run on a robot at the robot's scale (or on the paper robot as it is)."""

    spec: str
    """as given, e.g. ``targets@go1``."""
    suite: Suite
    robot: str | None
    """the robot of ``@ROBOT`` (None: the paper robot, the suite as it is)."""

    @property
    def slug(self) -> str:
        """Its folder name under ``DIR/runs/POLICY``."""
        return _slug(self.spec.removesuffix(".yaml"))

    def run_suite(self) -> Suite:
        """The suite ``evaluate`` runs (``scale: leg_length`` with a robot: scaled to it)."""
        return self.suite if self.robot is None else dataclasses.replace(self.suite, scale="leg_length")

    def env_kwargs(self) -> dict[str, Any]:
        """The env arguments of the column's robot."""
        return {} if self.robot is None else {"robot": self.robot}


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9.@-]+", "_", text).strip("_.") or "_"


def parse_policy(spec: str) -> BaselinePolicy:
    """A ``--policies`` item: ``zero``, ``expert``, ``expert:ADAPTATION``, an SB3 model ``.zip`` or an ONNX file.

    :raises PolicyError: naming the item and the allowed values.
    """
    spec = spec.strip()
    if spec.startswith("expert:"):
        adaptation = spec.split(":", 1)[1]
        if adaptation not in ADAPTATIONS:
            raise PolicyError(
                f"policies: expert:ADAPTATION must have ADAPTATION in {list(ADAPTATIONS)}, got {excerpt(spec)}"
            )
        return BaselinePolicy(spec, "expert", {"adaptation": adaptation})
    try:
        kind = policy_kind(spec)
    except PolicyError:
        raise PolicyError(
            f"policies items must be 'zero', 'expert', 'expert:ADAPTATION' ({list(ADAPTATIONS)}), an SB3 model "
            f".zip path or an exported .onnx path, got {excerpt(spec)}"
        ) from None
    if kind in ("sb3", "onnx") and not Path(spec).is_file():
        raise PolicyError(f"policies: model file {spec!r} does not exist")
    return BaselinePolicy(spec, spec, {})


def parse_suite(spec: str) -> BaselineSuite:
    """A ``--suites`` item: a shipped suite name or YAML path, optionally ``@ROBOT`` (a robot name or YAML path).

    :raises SuiteError: on an unknown or invalid suite; ``ValueError`` naming ``suites`` on an unloadable robot.
    """
    spec = spec.strip()
    name, _, robot = spec.partition("@")
    if robot:
        from quad_uneven_env.robot.description import load_robot

        try:
            load_robot(robot)
        except (ValueError, TypeError) as err:
            raise ValueError(f"suites: robot of {spec!r}: {err}") from None
    return BaselineSuite(spec, load_suite(name), robot or None)


def _model_robot(policy: BaselinePolicy) -> str | None:
    """The robot a model was trained on (None for ``zero`` and ``expert``, which run on any robot)."""
    if policy.policy in ("zero", "expert"):
        return None
    if policy_kind(policy.policy) == "onnx":
        from agents.evaluation.onnx_policy import onnx_metadata

        return onnx_metadata(policy.policy)["robot"]
    from agents.rl.model_io import model_robot, read_metadata

    meta = read_metadata(policy.policy)
    return None if meta is None else model_robot(meta)


def _robot_name(robot: str | None) -> str:
    if robot is None:
        return PAPER_ROBOT
    from quad_uneven_env.robot.description import load_robot

    return load_robot(robot).name


def baselines(
    policies: Sequence[str],
    suites: Sequence[str],
    out: str | Path,
    episodes: int | None = None,
    seed: int = 0,
    workers: int = 1,
    backend: str = "pool",
    address: str | None = None,
    ship_code: bool = False,
    progress: bool = True,
    log: Callable[[str], None] = print,
) -> dict[str, Any]:
    """Evaluate every policy on every suite (the same episodes for all) and write ``out/baselines.md`` and ``.json``.

    :param policies: ``--policies`` items (:func:`parse_policy`).
    :param suites: ``--suites`` items (:func:`parse_suite`).
    :param episodes: at most this many seeds per terrain entry (None: all); ``seed``: offset added to every seed.
    :param workers: ``evaluate``'s processes (or the CPUs of a local Ray with ``backend="ray"``).
    :return: the ``baselines.json`` content: per policy and suite, successes, episodes, per entry, or ``n/a`` and why.
    :raises ValueError: on a bad item (naming it), a repeated one, or an ``evaluate`` error (its message).
    """
    rows = [parse_policy(p) for p in policies]
    cols = [parse_suite(s) for s in suites]
    for what, items in (("policies", rows), ("suites", cols)):
        if not items:
            raise ValueError(f"{what} must name at least one item, got none")
        slugs = [i.slug for i in items]
        repeated = sorted({s for s in slugs if slugs.count(s) > 1})
        if repeated:
            raise ValueError(f"{what} must be distinct, got {repeated} more than once")
    if episodes is not None and (isinstance(episodes, bool) or not isinstance(episodes, int) or episodes < 1):
        raise ValueError(f"episodes must be None or an integer >= 1, got {excerpt(episodes)}")
    out = Path(out)
    cells: dict[str, dict[str, Any]] = {}
    for row in rows:
        trained_on = _model_robot(row)
        cells[row.spec] = {}
        for col in cols:
            if trained_on is not None and trained_on != _robot_name(col.robot):
                cells[row.spec][col.spec] = {"n/a": f"a model of the robot {trained_on!r}"}
                continue
            run_dir = out / "runs" / row.slug / col.slug
            log(f"{row.spec} on {col.spec}: {run_dir}")
            results = evaluate(
                col.run_suite(), row.policy, run_dir, episodes=episodes, seed=seed, workers=workers,
                env_kwargs=col.env_kwargs(), progress=progress, resume=(run_dir / RUN_FILE).is_file(),
                expert_config=row.expert_config or None, backend=backend, address=address, ship_code=ship_code,
            )  # fmt: skip
            summary = results["summary"]
            cells[row.spec][col.spec] = {
                "successes": summary["overall"]["successes"],
                "episodes": summary["overall"]["episodes"],
                "by_entry": {  # by the entry's label in the suite as given (a scaled suite's labels are long)
                    col.suite.terrains[e["entry"]].label: [e["successes"], e["episodes"]] for e in summary["by_entry"]
                },
                "results": str(run_dir / "results.json"),
            }
    content = {
        "policies": [r.spec for r in rows],
        "suites": [c.spec for c in cols],
        "episodes_per_entry": episodes,
        "seed_offset": seed,
        "cells": cells,
    }
    out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(out / "baselines.json", content)
    (out / "baselines.md").write_text(table_markdown(content))
    return content


def _cell(value: dict[str, Any] | None, entry: str | None = None) -> str:
    if value is None or "n/a" in value:
        return "n/a"
    k, n = value["by_entry"][entry] if entry is not None else (value["successes"], value["episodes"])
    return f"{k}/{n} ({100.0 * k / n:.0f} %)" if n else "-"


def table_markdown(content: dict[str, Any]) -> str:
    """The markdown of ``baselines.json``'s content: the overall table, then one table per suite by entry."""
    policies, suites, cells = content["policies"], content["suites"], content["cells"]
    lines = [
        "# Baselines",
        "",
        "Episodes that reached the goal / episodes, on the same episodes for every policy "
        f"(episodes per entry: {content['episodes_per_entry'] or 'all'}, seed offset {content['seed_offset']}).",
        "",
        "| policy | " + " | ".join(suites) + " |",
        "|---|" + "---|" * len(suites),
    ]
    lines += [f"| {p} | " + " | ".join(_cell(cells[p].get(s)) for s in suites) + " |" for p in policies]
    notes = sorted({f"n/a: {v['n/a']}" for p in policies for v in cells[p].values() if "n/a" in v})
    if notes:
        lines += ["", *notes]
    for s in suites:
        entries = next((list(cells[p][s]["by_entry"]) for p in policies if "by_entry" in cells[p].get(s, {})), None)
        if not entries:
            continue
        lines += [
            "",
            f"## {s} by entry",
            "",
            "| policy | " + " | ".join(entries) + " |",
            "|---|" + "---|" * len(entries),
        ]
        lines += [f"| {p} | " + " | ".join(_cell(cells[p].get(s), e) for e in entries) + " |" for p in policies]
    return "\n".join(lines) + "\n"
