"""Output folders and paths at the command line's boundary: relative paths mean the working directory's, an output
folder has one owner at a time, and a name the file system cannot hold is one line in every command.

- a relative ``--out`` (and a relative suite path) works as written, wherever the command writes inside;
- a second run into a folder another run holds is refused in one line naming the holder (pid, command), whether it
  starts, resumes or overwrites, and whichever command it is; the holder's files are untouched;
- a 300-character ``--out`` (or ``--gif``, ``--plot``, ...) is one ``error:`` line naming the option, no traceback.
"""

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

from agents.cli import absolute_paths, build_parser, main
from agents.outputs import LOCK_FILE, OutputError, OutputInUse, output_dir

ROOT = Path(__file__).resolve().parents[2]
LONG = "x" * 300
"""A file name longer than any file system allows (255 bytes)."""


def tiny_suite(path: Path, seeds: int = 1, time_limit: float = 0.2) -> Path:
    """A suite of ``seeds`` flat episodes of ``time_limit`` s."""
    raw = {"name": "tiny", "goal_distance": 0.5, "time_limit": time_limit,
           "terrains": [{"kind": "flat", "seeds": list(range(seeds))}]}  # fmt: skip
    path.write_text(yaml.safe_dump(raw))
    return path


def one_error_line(rc: int, err: str, *fields: str) -> str:
    assert rc == 2, err
    assert "Traceback" not in err
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    missing = [f for f in fields if f not in lines[0]]
    assert not missing, lines[0]
    return lines[0]


def run_cli(argv: list[str], capsys) -> tuple[int, str]:
    capsys.readouterr()
    rc = main(argv)
    return rc, capsys.readouterr().err


# ------------------------------------------------------------------------------------------- relative paths
def test_collect_into_a_relative_out_from_another_folder(tmp_path, monkeypatch, capsys):
    """The documented ``collect --out out/data``: the dataset lands in ./out/data/DATASET_ID/data (once, not nested)."""
    pytest.importorskip("minari")
    monkeypatch.chdir(tmp_path)
    tiny_suite(tmp_path / "tiny.yaml")
    rc, err = run_cli(["collect", "--policy", "expert", "--suite", "tiny.yaml", "--out", "out/data", "--no-progress"],
                      capsys)  # fmt: skip
    assert rc == 0, err
    summary = json.loads((tmp_path / "out" / "data" / "collect.json").read_text())
    data = tmp_path / "out" / "data" / "quad-uneven-tiny-expert-v0" / "data"
    assert Path(summary["dataset_path"]) == data and (data / "main_data.hdf5").is_file()
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["data"]


def test_every_path_argument_is_made_absolute_and_names_are_kept(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    parse = build_parser().parse_args
    args = absolute_paths(parse(["evaluate", "--policy", "runs/a/model.zip", "--suite", "s.yaml", "--out", "o",
                                 "--robot", "go1"]))  # fmt: skip
    assert (args.policy, args.suite, args.out, args.robot) == (
        str(tmp_path / "runs/a/model.zip"), str(tmp_path / "s.yaml"), tmp_path / "o", "go1"
    )  # fmt: skip
    args = absolute_paths(parse(["evaluate", "--policy", "expert", "--suite", "smoke", "--out", "/abs/o"]))
    assert (args.policy, args.suite, args.out) == ("expert", "smoke", Path("/abs/o"))
    args = absolute_paths(parse(["train", "--config", "c.yaml", "--terrain", "rough", "t.yaml", "--init-from", "r",
                                 "--out", "../up", "--tensorboard", "tb"]))  # fmt: skip
    assert args.config == str(tmp_path / "c.yaml") and args.init_from == str(tmp_path / "r")
    assert args.terrain == ["rough", str(tmp_path / "t.yaml")] and args.randomization is None
    assert args.out == tmp_path / ".." / "up" and args.tensorboard == tmp_path / "tb"  # '..' kept as written
    args = absolute_paths(parse(["compare", "--baseline", "a", "b", "--candidate", "c", "d", "--out", "o"]))
    assert args.baseline == [tmp_path / "a", tmp_path / "b"] and args.candidate == [tmp_path / "c", tmp_path / "d"]
    args = absolute_paths(parse(["plot-curves", "r1", "r2", "--labels", "from models/x", "y", "--out", "f.png"]))
    assert args.runs == [tmp_path / "r1", tmp_path / "r2"] and args.labels == ["from models/x", "y"]


# ---------------------------------------------------------------------------------------------------- the lock
def wait_for(path: Path, proc: subprocess.Popen, seconds: float = 300.0) -> None:
    deadline = time.monotonic() + seconds
    while not path.exists():
        assert proc.poll() is None, proc.communicate()[1]
        assert time.monotonic() < deadline, f"{path} did not appear"
        time.sleep(0.1)


@pytest.fixture
def running_evaluation(tmp_path):
    """A real ``quad-uneven evaluate`` process writing into tmp_path/out (ten 60 s episodes of the zero policy), once
    it has started its run (run.json written); ended with SIGKILL afterwards."""
    suite = tiny_suite(tmp_path / "long.yaml", seeds=10, time_limit=60.0)
    out = tmp_path / "out"
    argv = ["evaluate", "--policy", "zero", "--suite", str(suite), "--out", str(out), "--no-progress"]
    proc = subprocess.Popen([sys.executable, "-m", "agents.cli", *argv], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)  # fmt: skip
    try:
        wait_for(out / "run.json", proc)
        yield proc, out, suite
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.communicate(timeout=60)


def test_a_second_run_into_a_held_folder_is_refused_naming_the_holder(running_evaluation, tmp_path, capsys):
    """While one evaluation writes into DIR, another (plain, --resume, --overwrite), a collect and a compare into DIR
    are refused in one line naming the running one; its files are untouched."""
    proc, out, suite = running_evaluation
    holder = (f"(evaluate, pid {proc.pid} on ", "evaluate --policy zero --suite", "wait for it to end")
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file() and p.name != LOCK_FILE}
    evaluate = ["evaluate", "--policy", "zero", "--suite", str(suite), "--out", str(out), "--no-progress"]
    for extra in ([], ["--resume"], ["--overwrite"]):
        rc, err = run_cli([*evaluate, *extra], capsys)
        one_error_line(rc, err, f"--out {str(out)!r} is in use by another run", *holder)
    pytest.importorskip("minari")
    collect = ["collect", "--policy", "expert", "--suite", str(suite), "--out", str(out), "--overwrite"]
    rc, err = run_cli(collect, capsys)
    one_error_line(rc, err, "in use by another run", *holder)
    for path, data in before.items():
        assert path.read_bytes() == data, path
    assert proc.poll() is None  # still running, undisturbed


def test_a_killed_holder_leaves_a_folder_the_next_run_can_take(running_evaluation, tmp_path, capsys):
    proc, out, _ = running_evaluation
    assert json.loads((out / LOCK_FILE).read_text())["pid"] == proc.pid
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait(timeout=60)
    assert (out / LOCK_FILE).is_file()  # left behind, but no process holds it
    rc, err = run_cli(["evaluate", "--policy", "zero", "--suite", str(tiny_suite(tmp_path / "t.yaml")), "--out",
                       str(out), "--no-progress", "--overwrite"], capsys)  # fmt: skip
    assert rc == 0, err
    assert not (out / LOCK_FILE).exists()  # released at the end
    assert json.loads((out / "results.json").read_text())["suite"] == "tiny"


def test_the_lock_is_held_for_the_block_and_released_however_it_ends(tmp_path):
    out = tmp_path / "out"
    with output_dir(out, "evaluate"):
        assert json.loads((out / LOCK_FILE).read_text())["pid"] == os.getpid()
        with pytest.raises(OutputInUse, match=rf"is in use by another run \(evaluate, pid {os.getpid()} on "):
            with output_dir(out, "compare", keep=True):
                pass
    assert not (out / LOCK_FILE).exists()
    with pytest.raises(RuntimeError), output_dir(out, "evaluate"):
        raise RuntimeError("the command failed")
    assert not (out / LOCK_FILE).exists()
    (out / LOCK_FILE).write_text("garbage of a killed run")  # a leftover lock file is neither a holder nor content
    with output_dir(out, "evaluate") as manifest:
        (manifest.out / "a.txt").write_text("x")
    with pytest.raises(OutputError, match=r"is not empty \(a\.txt\)"), output_dir(out, "evaluate"):
        pass


@pytest.mark.slow
def test_two_runs_started_together_into_one_empty_folder(tmp_path):
    """Two evaluations of different policies started at once into one empty DIR: one writes it, the other is
    refused; DIR holds one run (run.json, results.json and the records agree on the policy)."""
    suite = tiny_suite(tmp_path / "s.yaml", seeds=4, time_limit=2.0)
    out = tmp_path / "out"
    argv = [sys.executable, "-m", "agents.cli", "evaluate", "--suite", str(suite), "--out", str(out), "--no-progress"]
    pipe = subprocess.PIPE
    procs = [
        subprocess.Popen([*argv, "--policy", policy], cwd=ROOT, stdout=pipe, stderr=pipe, text=True)
        for policy in ("zero", "expert")
    ]
    results = [(p.wait(timeout=600), p.communicate()[1]) for p in procs]
    assert sorted(rc for rc, _ in results) == [0, 2], results
    err = next(e for rc, e in results if rc == 2)
    assert "in use by another run" in err or "is not empty" in err, err
    policy = json.loads((out / "run.json").read_text())["policy"]
    assert json.loads((out / "results.json").read_text())["policy"] == policy
    records = [json.loads(p.read_text()) for p in sorted((out / "episodes").glob("ep*.json"))]
    assert len(records) == 4 and {r.get("policy", policy) for r in records} == {policy}


# ------------------------------------------------------------------------------------------------ long names
def long_name_inputs(tmp: Path) -> None:
    """The inputs the commands of LONG_CASES read: a suite, a training run's monitor file, an evaluation folder."""
    tiny_suite(tmp / "s.yaml")
    (tmp / "run" / "monitor").mkdir(parents=True)
    (tmp / "run" / "monitor" / "0.monitor.csv").write_text('#{"t_start": 0}\nr,l,t\n1.0,10,0.5\n')
    (tmp / "eval").mkdir()
    results = {"suite": "s", "policy": "zero", "episodes": [], "meta": {"entries": []}}
    (tmp / "eval" / "results.json").write_text(json.dumps(results))


LONG_CASES: dict[str, tuple[str, list[str]]] = {
    "evaluate": ("--out", ["evaluate", "--policy", "zero", "--suite", "s.yaml", "--out", LONG]),
    "collect": ("--out", ["collect", "--policy", "expert", "--suite", "s.yaml", "--out", LONG]),
    "train": ("--out", ["train", "--timesteps", "64", "--out", LONG]),
    "distill": ("--out", ["distill", "--suite", "s.yaml", "--out", LONG]),
    "plot-curves": ("--out", ["plot-curves", "run", "--out", LONG + ".png"]),
    "compare": ("--out", ["compare", "--baseline", "eval", "--candidate", "eval", "--out", LONG]),
    "plan-paper": ("--out", ["plan-paper", "--out", LONG]),
    "paper": ("--out", ["paper", "--out", LONG]),
    "robustness": ("--out", ["robustness", "--factor", "push", "--out", LONG]),
    "export": ("--out", ["export", "--policy", str(ROOT / "models/ppo_scratch/model.zip"), "--out", LONG + ".onnx"]),
    "fit-strength --plot": ("--plot", ["fit-strength", "--from-data", "none.npz", "--out", "e.npz", "--plot", LONG]),
    "demo --gif": ("--gif", ["demo", "--out", "demo", "--gif", LONG + ".gif"]),
    "a long folder in --out": ("--out", ["evaluate", "--policy", "zero", "--suite", "s.yaml", "--out", LONG + "/o"]),
}
"""Commands given a 300-character name: (the option named in the error, the command line, run in tmp_path)."""


@pytest.mark.parametrize("case", list(LONG_CASES))
def test_a_name_the_file_system_cannot_hold_is_one_line(case, tmp_path, monkeypatch, capsys):
    if case == "collect":
        pytest.importorskip("minari")
    long_name_inputs(tmp_path)
    monkeypatch.chdir(tmp_path)
    field, argv = LONG_CASES[case]
    rc, err = run_cli(argv, capsys)
    line = one_error_line(rc, err, field, "bytes; the file system allows at most 255")
    assert len(line) < 400
    assert not any(p.name.startswith("xxx") for p in tmp_path.iterdir())
