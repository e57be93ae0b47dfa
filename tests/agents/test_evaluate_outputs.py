"""The evaluation's output directory: records as episodes end, interrupts keep them, --resume, --overwrite."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

import agents.evaluation.run as run_module
from agents.cli import main
from agents.evaluation.episode import EvalConfig, run_task
from agents.evaluation.machine import machine_info
from agents.evaluation.run import EvaluationInterrupted, evaluate
from agents.evaluation.suites import EpisodeTask
from agents.outputs import OutputError

ROOT = Path(__file__).resolve().parents[2]
WALL_CLOCK_FIELDS = ("wall_time", "realtime_factor", "planner_ms_median", "planner_ms_p95")


def six_episode_suite(path: Path, time_limit: float = 0.1) -> Path:
    raw = {
        "name": "six",
        "goal_distance": 0.5,
        "time_limit": time_limit,
        "terrains": [{"kind": "flat", "seeds": [0, 1, 2]}, {"kind": "rough", "seeds": [4, 5, 6]}],
    }
    path.write_text(yaml.safe_dump(raw))
    return path


def strip(records):
    return [{k: v for k, v in r.items() if k not in WALL_CLOCK_FIELDS} for r in records]


class CountingRunTask:
    """``run_task`` that counts its calls and raises KeyboardInterrupt (Ctrl-C) at call ``interrupt_at``."""

    def __init__(self, interrupt_at: int | None = None) -> None:
        self.calls: list[int] = []
        self.interrupt_at = interrupt_at

    def __call__(self, task, cfg):
        if self.interrupt_at is not None and len(self.calls) == self.interrupt_at:
            raise KeyboardInterrupt
        self.calls.append(task.index)
        return run_task(task, cfg)


def record_files(out: Path) -> list[str]:
    return sorted(p.name for p in (out / "episodes").glob("ep*.json"))


def test_an_interrupt_keeps_the_finished_episodes_and_resume_runs_only_the_rest(tmp_path, monkeypatch):
    suite = six_episode_suite(tmp_path / "six.yaml")
    reference = evaluate(suite, "zero", tmp_path / "reference", progress=False)

    out = tmp_path / "out"
    first = CountingRunTask(interrupt_at=3)
    monkeypatch.setattr(run_module, "run_task", first)
    with pytest.raises(EvaluationInterrupted, match="3 of 6 episodes"):
        evaluate(suite, "zero", out, progress=False)
    assert first.calls == [0, 1, 2]
    assert record_files(out) == ["ep000.json", "ep001.json", "ep002.json"]
    assert sorted(p.name for p in (out / "traces").iterdir()) == ["ep000.npz", "ep001.npz", "ep002.npz"]
    assert not (out / "results.json").exists() and (out / "run.json").is_file()
    kept = [json.loads((out / "episodes" / f).read_text()) for f in record_files(out)]
    assert strip(kept) == strip(reference["episodes"][:3])

    with pytest.raises(OutputError, match=r"not empty.*--resume"):  # neither --resume nor --overwrite
        evaluate(suite, "zero", out, progress=False)

    second = CountingRunTask()
    monkeypatch.setattr(run_module, "run_task", second)
    res = evaluate(suite, "zero", out, progress=False, resume=True)
    assert second.calls == [3, 4, 5]
    assert strip(res["episodes"]) == strip(reference["episodes"])
    assert res["meta"]["resumed_episodes"] == 3
    assert res["meta"]["machines"] == [machine_info()]  # every episode's record names this machine
    on_disk = json.loads((out / "results.json").read_text())
    assert strip(on_disk["episodes"]) == strip(reference["episodes"])
    assert (out / "report.md").is_file() and (out / "paths_entry1.png").stat().st_size > 10_000

    third = CountingRunTask()  # everything finished: a resume only rebuilds results.json and the report
    monkeypatch.setattr(run_module, "run_task", third)
    assert strip(evaluate(suite, "zero", out, progress=False, resume=True)["episodes"]) == strip(res["episodes"])
    assert third.calls == []


def test_the_cli_reports_an_interrupt_in_one_line_with_exit_130(tmp_path, monkeypatch, capsys):
    suite = six_episode_suite(tmp_path / "six.yaml")
    monkeypatch.setattr(run_module, "run_task", CountingRunTask(interrupt_at=2))
    argv = ["evaluate", "--policy", "zero", "--suite", str(suite), "--out", str(tmp_path / "o"), "--no-progress"]
    assert main(argv) == 130
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "2 of 6 episodes" in err and "--resume" in err
    assert len(record_files(tmp_path / "o")) == 2


def test_resume_refuses_another_run_and_reruns_an_unfinished_episode(tmp_path, monkeypatch):
    suite = six_episode_suite(tmp_path / "six.yaml")
    out = tmp_path / "out"
    monkeypatch.setattr(run_module, "run_task", CountingRunTask(interrupt_at=4))
    with pytest.raises(KeyboardInterrupt):
        evaluate(suite, "zero", out, progress=False)
    for kwargs, field in (
        ({"env_kwargs": {"frame_skip": 5}}, "env_kwargs"),
        ({"seed": 3}, "seed_offset"),
        ({"episodes": 2}, "episodes_per_entry"),
        ({"expert_config": {"model": "oracle"}}, "expert_config"),
        ({"policy": "expert"}, "policy"),
    ):
        with pytest.raises(OutputError, match=f"--resume: {field} differs"):
            evaluate(suite, kwargs.pop("policy", "zero"), out, progress=False, resume=True, **kwargs)
    other = six_episode_suite(tmp_path / "other.yaml", time_limit=0.2)
    with pytest.raises(OutputError, match="--resume: suite differs"):
        evaluate(other, "zero", out, progress=False, resume=True)

    (out / "traces" / "ep001.npz").unlink()  # a record without its trace is not a finished episode
    again = CountingRunTask()
    monkeypatch.setattr(run_module, "run_task", again)
    evaluate(suite, "zero", out, progress=False, resume=True)
    assert again.calls == [1, 4, 5]


def test_overwrite_deletes_the_old_run_only(tmp_path):
    suite = six_episode_suite(tmp_path / "six.yaml")
    out = tmp_path / "out"
    evaluate(suite, "zero", out, progress=False)
    (out / "notes.txt").write_text("mine")
    evaluate(suite, "zero", out, episodes=1, progress=False, overwrite=True)
    assert record_files(out) == ["ep000.json", "ep001.json"]  # no episode of the six-episode run is left
    assert sorted(p.name for p in (out / "traces").iterdir()) == ["ep000.npz", "ep001.npz"]
    assert (out / "notes.txt").read_text() == "mine"
    assert len(json.loads((out / "results.json").read_text())["episodes"]) == 2


def test_results_json_that_cannot_be_written_leaves_the_records(tmp_path, monkeypatch):
    suite = six_episode_suite(tmp_path / "six.yaml")
    out = tmp_path / "out"

    def disk_full(out_dir, results):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(run_module, "write_results", disk_full)
    with pytest.raises(OutputError, match="the 6 episode records are kept"):
        evaluate(suite, "zero", out, progress=False)
    assert len(record_files(out)) == 6 and not (out / "results.json").exists()

    monkeypatch.undo()
    rerun = CountingRunTask()
    monkeypatch.setattr(run_module, "run_task", rerun)
    res = evaluate(suite, "zero", out, progress=False, resume=True)
    assert rerun.calls == [] and len(res["episodes"]) == 6 and (out / "results.json").is_file()


def test_out_is_checked_before_the_first_episode(tmp_path, monkeypatch):
    suite = six_episode_suite(tmp_path / "six.yaml")
    never = CountingRunTask(interrupt_at=0)  # any episode would raise
    monkeypatch.setattr(run_module, "run_task", never)
    (tmp_path / "file").write_text("x")
    with pytest.raises(OutputError, match="is a file"):
        evaluate(suite, "zero", tmp_path / "file", progress=False)
    assert never.calls == []


def test_the_wall_clock_limit_ends_an_episode():
    task = EpisodeTask(0, 0, "flat", {}, 0, False)
    cfg = EvalConfig("zero", goal_distance=1.0, time_limit=10.0, wall_time_limit=1e-6)
    r = run_task(task, cfg).record
    assert r["end_reason"] == "wall_time_limit" and r["success"] is False and r["fall_reason"] is None
    assert r["sim_time"] == pytest.approx(0.02)  # one control step (10 x 2 ms) and the check ends it


@pytest.mark.slow
def test_sigterm_with_workers_keeps_the_finished_episodes(tmp_path):
    """A real process with --workers 2, killed with SIGTERM after 3 records: exit 130, the records kept."""
    suite = six_episode_suite(tmp_path / "six.yaml", time_limit=8.0)
    out = tmp_path / "out"
    argv = ["evaluate", "--policy", "zero", "--suite", str(suite), "--out", str(out), "--no-progress", "--workers", "2"]
    proc = subprocess.Popen(
        [sys.executable, "-m", "agents.cli", *argv], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    deadline = time.monotonic() + 600
    while time.monotonic() < deadline and proc.poll() is None and len(record_files(out) if out.exists() else []) < 3:
        time.sleep(0.2)
    os.kill(proc.pid, signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    kept = record_files(out)
    assert proc.returncode == 130, err
    assert 3 <= len(kept) < 6 and f"{len(kept)} of 6 episodes" in err
    res = evaluate(suite, "zero", out, progress=False, resume=True)
    assert len(res["episodes"]) == 6 and res["meta"]["resumed_episodes"] == len(kept)
