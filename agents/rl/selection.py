"""Choose the snapshot of a training run on validation episodes (``quad-uneven select``).

Typical use::

    quad-uneven select --run runs/ppo_residual_adaptive --suite robust_extreme --seed 200 --workers 2

The candidates are the run's checkpoints (``DIR/checkpoints/model_<N>_steps.zip``) and its final model
(``DIR/model.zip``). Each is evaluated on the same episodes (:func:`agents.evaluation.run.evaluate`, into
``OUT/evals/<name>/``; a finished evaluation is reused and an interrupted one resumed, so the command can be
run again after Ctrl-C) and ranked by :func:`rank_key`: more successes, then fewer falls (falls and divergences),
then more training steps. The first is copied to ``OUT/selected/`` with its observation statistics, the run's
metadata and training files, ready for ``quad-uneven evaluate --policy OUT/selected/model.zip``.
``OUT/selection.json``, ``selection.md`` and ``selection.png`` (validation successes against training steps) list
every candidate.

The selection is part of training: the validation seeds must never be the seeds the chosen model is reported on.
SB3's ``EvalCallback`` keeps a "best" model too, but on a few training-world episodes; here the number of
episodes is the user's.
"""

from __future__ import annotations

import itertools
import json
import re
import shutil
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from agents.evaluation.metrics import json_safe
from agents.evaluation.results_io import ResultsError, load_results
from agents.evaluation.run import evaluate
from agents.evaluation.store import RUN_FILE
from agents.evaluation.suites import Suite, load_suite
from agents.outputs import output_dir, write_json_atomic
from agents.plotting import pyplot, save
from agents.rl.model_io import META_FILE
from agents.rl.normalization import norm_path

__all__ = [
    "SELECTION_OUTPUTS",
    "SelectionError",
    "find_candidates",
    "load_reference",
    "rank_key",
    "select_checkpoint",
    "selection_markdown",
]

SELECTION_OUTPUTS = ("evals", "selected", "selection.json", "selection.md", "selection.png")
"""What ``quad-uneven select`` writes in its output directory (``overwrite`` deletes what the manifest lists;
with one of these names present and no manifest, it refuses)."""

RUN_FILES = ("train_config.json", "train_summary.json", "learning_curve.png")
"""Files of the training run copied next to the selected model (those present)."""

_CHECKPOINT = re.compile(r"model_(\d+)_steps\.zip")


class SelectionError(ValueError):
    """A run folder without candidates, or a bad argument of the selection; the message names the field."""


def find_candidates(run: str | Path) -> list[dict[str, Any]]:
    """The run's checkpoints by training steps, then its final model.

    :return: ``[{"name", "path", "steps"}]``; ``steps`` of the final model is the ``timesteps`` of
        ``train_summary.json`` (None without it).
    :raises SelectionError: if ``run`` is not a folder or holds no model.
    """
    run = Path(run)
    if not run.is_dir():
        raise SelectionError(f"run {str(run)!r} is not a folder (a 'quad-uneven train' output directory)")
    found = []
    for path in (run / "checkpoints").glob("model_*_steps.zip"):
        m = _CHECKPOINT.fullmatch(path.name)
        if m:
            found.append({"name": path.stem, "path": path, "steps": int(m[1])})
    found.sort(key=lambda c: c["steps"])
    final = run / "model.zip"
    if final.is_file():
        found.append({"name": "final", "path": final, "steps": _final_steps(run)})
    if not found:
        raise SelectionError(f"run {str(run)!r} holds no model.zip and no checkpoints/model_<N>_steps.zip")
    return found


def _final_steps(run: Path) -> int | None:
    try:
        return int(json.loads((run / "train_summary.json").read_text())["timesteps"])
    except (OSError, ValueError, KeyError, TypeError):
        return None


def rank_key(candidate: Mapping[str, Any]) -> tuple[int, int, int]:
    """Sort key of an evaluated candidate, best first: more successes, fewer falls, more training steps."""
    steps = candidate["steps"] if candidate["steps"] is not None else -1
    return (-int(candidate["successes"]), int(candidate["falls"]), -steps)


def _copy_selected(run: Path, candidate: Mapping[str, Any], folder: Path) -> Path:
    """``candidate``'s model, statistics and metadata (and the run's :data:`RUN_FILES`) into ``folder``."""
    folder.mkdir(parents=True, exist_ok=True)
    model = folder / "model.zip"
    shutil.copyfile(candidate["path"], model)
    stats = norm_path(candidate["path"])
    if stats.is_file():
        shutil.copyfile(stats, norm_path(model))
    meta = candidate["path"].parent / META_FILE
    shutil.copyfile(meta if meta.is_file() else run / META_FILE, folder / META_FILE)
    for name in RUN_FILES:
        if (run / name).is_file():
            shutil.copyfile(run / name, folder / name)
    return model


def load_reference(folder: str | Path, suite: Suite, seed: int, episodes: int | None) -> dict[str, Any]:
    """An evaluation of the same validation episodes by another policy (e.g. the expert), drawn beside the candidates.

    :return: ``{"policy", "dir", "successes", "episodes", "falls", "mean_stability_index"}``.
    :raises SelectionError: if ``folder`` has no results.json, or its suite, entries, seed offset or episode cap
        differ.
    """
    folder = Path(folder)
    try:
        res = load_results(folder, summary=True)
    except ResultsError as err:
        raise SelectionError(f"reference {str(folder)!r}: {err}") from None
    meta = res["meta"]
    found = (res.get("suite"), meta.get("seed_offset"), meta.get("episodes_per_entry"))
    if found != (suite.name, seed, episodes):
        raise SelectionError(
            f"reference {str(folder)!r}: evaluated suite {found[0]!r}, seed offset {found[1]}, episodes per entry "
            f"{found[2]}; the selection uses {suite.name!r}, {seed}, {episodes}"
        )
    if meta.get("entries") != [e.label for e in suite.terrains]:
        raise SelectionError(f"reference {str(folder)!r}: other suite entries than {suite.name!r}'s")
    g = res["summary"]["overall"]
    return {
        "policy": res.get("policy"),
        "dir": str(folder),
        **{k: g[k] for k in ("successes", "episodes", "falls", "mean_stability_index")},
    }


def select_checkpoint(
    run: str | Path,
    suite: Suite | str | Path,
    seed: int,
    out: str | Path | None = None,
    episodes: int | None = None,
    workers: int = 1,
    overwrite: bool = False,
    progress: bool = True,
    references: Sequence[str | Path] = (),
) -> dict[str, Any]:
    """Evaluate every candidate of ``run`` (:func:`find_candidates`) on ``suite`` and copy the best to ``out/selected``.

    :param suite: a :class:`Suite`, a shipped suite name or a suite YAML path: the validation episodes.
    :param seed: offset added to every seed of the suite (validation seeds, never the test seeds).
    :param out: output directory (None: ``run/selection``); earlier evaluations of the same candidates in it are
        reused or resumed.
    :param episodes: at most this many seeds per terrain entry (None: all).
    :param workers: episode processes of each evaluation.
    :param overwrite: delete the earlier outputs in ``out`` (:data:`SELECTION_OUTPUTS`) first.
    :param references: evaluation folders of other policies on the same episodes (:func:`load_reference`), listed
        and drawn beside the candidates; they are not candidates.
    :return: the ``selection.json`` content: ``{"run", "suite", "seed", "candidates": [...], "selected"}``, every
        candidate with ``successes``, ``episodes``, ``falls``, ``mean_stability_index`` (N m) and ``rank`` (1: best).
    :raises SelectionError: on a run without models or a bad argument; the errors of ``evaluate`` otherwise.
    """
    run = Path(run)
    candidates = find_candidates(run)
    if workers < 1:
        raise SelectionError(f"workers must be >= 1, got {workers}")
    if not isinstance(suite, Suite):
        suite = load_suite(suite)
    refs = [load_reference(f, suite, seed, episodes) for f in references]
    out = run / "selection" if out is None else out
    with output_dir(out, "select", SELECTION_OUTPUTS, overwrite, keep=not overwrite, field="out") as manifest:
        out = manifest.out
        for c in candidates:
            folder = out / "evals" / c["name"]
            started = (folder / RUN_FILE).is_file()
            if progress:
                print(f"{c['name']}: {'resuming' if started else 'evaluating'} {c['path']}", flush=True)
            res = evaluate(suite, str(c["path"]), folder, episodes=episodes, seed=seed, workers=workers,
                           progress=progress, resume=started)  # fmt: skip
            g = res["summary"]["overall"]
            c.update(successes=g["successes"], episodes=g["episodes"], falls=g["falls"],
                     mean_stability_index=g["mean_stability_index"], evaluation=str(folder))  # fmt: skip
        order = sorted(range(len(candidates)), key=lambda i: (rank_key(candidates[i]), -i))  # a full tie: the later
        for rank, i in enumerate(order, start=1):
            candidates[i]["rank"] = rank
        best = candidates[order[0]]
        selected = _copy_selected(run, best, out / "selected")
        result = {
            "run": str(run),
            "suite": suite.name,
            "seed": seed,
            "episodes_per_entry": episodes,
            "rule": "most successes, then fewest falls (falls and divergences), then most training steps",
            "candidates": [{**c, "path": str(c["path"])} for c in candidates],
            "selected": best["name"],
            "selected_model": str(selected),
            "references": refs,
        }
        write_json_atomic(out / "selection.json", json_safe(result))
        write_json_atomic(out / "selected" / "selection.json", json_safe(result))
        (out / "selection.md").write_text(selection_markdown(result))
        plot_selection(result, out / "selection.png")
    return result


def selection_markdown(result: Mapping[str, Any]) -> str:
    """The candidates of a :func:`select_checkpoint` result as a markdown table."""
    lines = [
        f"# Checkpoint selection of {result['run']}",
        "",
        f"Validation: suite `{result['suite']}`, seed offset {result['seed']}. Rule: {result['rule']}. "
        f"Selected: **{result['selected']}**.",
        "",
        "| candidate | training steps | successes | falls | mean index (N m) | rank |",
        "|---|---|---|---|---|---|",
    ]
    for c in result["candidates"]:
        index = c["mean_stability_index"]
        lines.append(
            f"| {c['name']} | {c['steps'] if c['steps'] is not None else '-'} | {c['successes']}/{c['episodes']} | "
            f"{c['falls']} | {'-' if index is None else f'{index:.1f}'} | {c['rank']} |"
        )
    for r in result.get("references", []):
        index = r["mean_stability_index"]
        lines.append(
            f"| reference: `{r['policy']}` | - | {r['successes']}/{r['episodes']} | {r['falls']} | "
            f"{'-' if index is None else f'{index:.1f}'} | - |"
        )
    return "\n".join(lines) + "\n"


def _policy_name(policy: str) -> str:
    """A short label: a named policy as it is, a model file by its folder (``models/NAME/model.zip``: NAME)."""
    path = Path(str(policy))
    return path.parent.name or path.name if path.suffix == ".zip" else str(policy)


def plot_selection(result: Mapping[str, Any], path: Path) -> Path:
    """Validation successes and falls of the candidates against their training steps (PNG)."""
    plt = pyplot()
    rows: Sequence[Mapping[str, Any]] = [c for c in result["candidates"] if c["steps"] is not None]
    fig, ax = plt.subplots(figsize=(6, 3.5))
    steps = [c["steps"] for c in rows]
    ax.plot(steps, [c["successes"] for c in rows], "o-", label="successes")
    ax.plot(steps, [c["falls"] for c in rows], "s--", label="falls and divergences")
    for c in rows:
        if c["name"] == result["selected"]:
            ax.plot([c["steps"]], [c["successes"]], "r*", markersize=14, label=f"selected: {c['name']}")
    for r, style in zip(result.get("references", []), itertools.cycle((":", "-.", (0, (5, 1, 1, 1)))), strict=False):
        ax.axhline(r["successes"], color="gray", linestyle=style, label=f"successes of {_policy_name(r['policy'])}")
    n = max((c["episodes"] for c in result["candidates"]), default=0)
    title = f"validation: {result['suite']}, seed offset {result['seed']}"
    ax.set(xlabel="training steps", ylabel=f"episodes (of {n})", title=title)
    ax.legend(fontsize=8)
    return save(fig, path)
