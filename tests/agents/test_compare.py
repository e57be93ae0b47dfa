"""quad-uneven compare: paired episodes of two evaluations, on hand-made result files."""

from __future__ import annotations

import json

import pytest

from agents.cli import main
from agents.evaluation.compare import ComparisonError, compare_runs, failure_kind


def _episode(entry, seed, success, end="goal", index=50.0, neg=0.1, residual=None, friction=1.0):
    return {
        "entry": entry,
        "seed": seed,
        "success": success,
        "end_reason": end,
        "mean_stability_index": index,
        "min_stability_index": index - 60.0,
        "time_index_negative": neg,
        "fraction_index_nonnegative": 1.0 - neg / 30.0,
        "mean_speed": 0.1,
        "mean_residual_torque": residual,
        "factors": {"friction": friction},
    }


def _run(folder, policy, episodes, entries=("rough", "stairs")):
    folder.mkdir()
    results = {
        "suite": "s",
        "policy": policy,
        "episodes": episodes,
        "meta": {"entries": list(entries), "seed_offset": 100},
    }
    (folder / "results.json").write_text(json.dumps(results))
    return folder


def test_counts_rates_and_changed_episodes(tmp_path):
    base = _run(tmp_path / "a", "expert", [
        _episode(0, 100, True, friction=0.3),
        _episode(0, 101, False, "time_limit", friction=0.4, neg=3.0),
        _episode(1, 100, False, "fall", friction=0.9),
        _episode(1, 101, True, friction=1.1),
    ])  # fmt: skip
    cand = _run(tmp_path / "b", "model.zip", [
        _episode(1, 101, True, residual=1.5, friction=1.1),
        _episode(0, 100, True, residual=0.5, friction=0.3),
        _episode(0, 101, True, residual=1.0, friction=0.4, neg=0.3),
        _episode(1, 100, False, "diverged", residual=2.0, friction=0.9),
    ])  # fmt: skip
    comp = compare_runs(base, cand)
    a, b = comp["overall"]["baseline"], comp["overall"]["candidate"]
    assert (a["successes"], a["stalls"], a["falls"], a["divergences"]) == (2, 1, 1, 0)
    assert (b["successes"], b["stalls"], b["falls"], b["divergences"]) == (3, 0, 0, 1)
    assert a["failure_rate"] == 0.5 and b["failure_rate"] == 0.25
    assert b["mean_residual_torque"] == pytest.approx(1.25) and a["mean_residual_torque"] is None
    assert a["mean_time_index_negative"] == pytest.approx((0.1 + 3.0 + 0.1 + 0.1) / 4)
    assert [(e["entry"], e["seed"], e["baseline"], e["candidate"]) for e in comp["changed"]] == [
        (0, 101, "stall", "success"),
        (1, 100, "fall", "diverged"),
    ]
    assert [r["candidate"]["successes"] for r in comp["by_entry"]] == [2, 1]
    friction = [r for r in comp["by_factor"] if r["factor"] == "friction"]
    assert [(r["low"], r["high"]) for r in friction] == [(0.3, 0.4), (0.9, 0.9), (1.1, 1.1)]
    assert [r["baseline"]["successes"] for r in friction] == [1, 0, 1]
    assert [r["candidate"]["successes"] for r in friction] == [2, 0, 1]


def test_runs_of_other_episodes_are_refused_and_the_cli_writes_files(tmp_path, capsys):
    base = _run(tmp_path / "a", "expert", [_episode(0, 100, True), _episode(0, 101, True)])
    other = _run(tmp_path / "b", "expert", [_episode(0, 100, True), _episode(0, 102, True)])
    with pytest.raises(ComparisonError, match="do not hold the same"):
        compare_runs(base, other)
    assert main(["compare", "--baseline", str(base), "--candidate", str(other), "--out", str(tmp_path / "c")]) == 2
    assert "do not hold the same" in capsys.readouterr().err
    assert main(["compare", "--baseline", str(base), "--candidate", str(base), "--out", str(tmp_path / "c")]) == 0
    text = (tmp_path / "c" / "comparison.md").read_text()
    assert "every episode ended the same way" in text
    assert (tmp_path / "c" / "comparison.png").stat().st_size > 1000
    assert json.loads((tmp_path / "c" / "comparison.json").read_text())["changed"] == []


def test_failure_kinds():
    assert failure_kind({"success": True, "end_reason": "goal"}) is None
    assert failure_kind({"success": False, "end_reason": "left_terrain"}) == "fall"
    assert failure_kind({"success": False, "end_reason": "wall_time_limit"}) == "stall"
    assert failure_kind({"success": False, "end_reason": "error"}) == "error"
