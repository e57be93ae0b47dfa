"""``quad-uneven baselines``: the table's figures are those of ``evaluate`` on the same episodes; a rerun resumes;
a model of another robot gets ``n/a``; bad items exit 2 with one line."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml

import quad_uneven_env  # noqa: F401  (registers QuadUneven-v0)
from agents.cli import main
from agents.evaluation.run import evaluate

SUITE = {
    "name": "tiny",
    "goal_distance": 0.1,
    "time_limit": 2.0,
    "terrains": [{"kind": "flat", "seeds": [0, 1]}, {"kind": "rough", "params": {"amplitude": 0.03}, "seeds": [2]}],
}
"""Three short episodes on two entries."""


@pytest.fixture(scope="module")
def table(tmp_path_factory):
    root = tmp_path_factory.mktemp("baselines")
    suite = root / "tiny.yaml"
    suite.write_text(yaml.safe_dump(SUITE))
    argv = ["baselines", "--policies", "zero,expert,models/distilled/model.zip", "--suites", f"{suite},{suite}@go1",
            "--episodes", "1", "--out", str(root / "out"), "--no-progress"]  # fmt: skip
    assert main(argv) == 0
    return root, suite, argv


def test_the_table_has_the_figures_of_evaluate_on_the_same_episodes(table, tmp_path):
    root, suite, _ = table
    content = json.loads((root / "out" / "baselines.json").read_text())
    col = str(suite)
    for policy in ("zero", "expert"):
        ref = evaluate(suite, policy, tmp_path / policy, episodes=1, progress=False)["summary"]
        cell = content["cells"][policy][col]
        assert (cell["successes"], cell["episodes"]) == (ref["overall"]["successes"], 2)
        assert cell["by_entry"] == {e["label"]: [e["successes"], e["episodes"]] for e in ref["by_entry"]}
    assert content["cells"]["zero"][col]["successes"] == 0 and content["cells"]["expert"][col]["successes"] == 2
    md = (root / "out" / "baselines.md").read_text()
    assert f"| policy | {col} | {col}@go1 |" in md
    assert "| zero | 0/2 (0 %) |" in md and "| expert | 2/2 (100 %) |" in md
    assert "## " + col + " by entry" in md and "| policy | flat | rough(amplitude=0.03) |" in md


def test_a_model_of_another_robot_gets_no_figure_there(table):
    root, suite, _ = table
    content = json.loads((root / "out" / "baselines.json").read_text())
    cells = content["cells"]["models/distilled/model.zip"]
    assert cells[f"{suite}@go1"] == {"n/a": "a model of the robot 'paper'"}
    assert cells[str(suite)]["episodes"] == 2
    assert not (root / "out" / "runs" / "models_distilled_model" / f"{Path(str(suite)).stem}@go1").exists()
    assert content["cells"]["expert"][f"{suite}@go1"]["episodes"] == 2  # the expert runs on any robot


def test_a_rerun_resumes_every_evaluation(table, capsys):
    root, _, argv = table
    assert main(argv) == 0
    for results in (root / "out" / "runs").glob("*/*/results.json"):
        meta = json.loads(results.read_text())["meta"]
        assert meta["resumed_episodes"] == 2, results


@pytest.mark.parametrize(
    ("extra", "says"),
    [
        (["--policies", "zero,expert:magic", "--suites", "smoke"], "expert:ADAPTATION must have ADAPTATION in"),
        (["--policies", "zero,walker", "--suites", "smoke"], "policies items must be"),
        (["--policies", "zero,no/such.zip", "--suites", "smoke"], "does not exist"),
        (["--policies", "zero,zero", "--suites", "smoke"], "policies must be distinct"),
        (["--policies", "zero", "--suites", "no_such_suite"], "no_such_suite"),
        (["--policies", "zero", "--suites", "smoke@no_such_robot"], "suites: robot of 'smoke@no_such_robot'"),
        (["--policies", "zero", "--suites", "smoke", "--episodes", "0"], "--episodes must be >= 1"),
    ],
)
def test_bad_items_exit_2_with_one_line(tmp_path, capsys, extra, says):
    rc = main(["baselines", "--out", str(tmp_path / "o"), *extra])
    err = capsys.readouterr().err
    assert rc == 2 and says in err and err.count("\n") == 1, err
    assert not (tmp_path / "o").exists()
