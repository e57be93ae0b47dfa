"""Crafted inputs at the command line's boundary: exit code 2, one ``error:`` line naming the file, option or field,
no traceback, and nothing of the user's lost.

Results files that quad-uneven did not write (``compare``, ``--resume``), argparse's own errors, options that would
be ignored in combination, YAML with a key given twice, and ``--overwrite`` next to the user's own files.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest
import yaml

from agents.cli import main
from agents.outputs import MANIFEST_FILE

ROOT = Path(__file__).resolve().parents[2]


def episode(entry: int, seed: int, success=True, **changes) -> dict:
    """A results.json episode as compare reads it (the fields of tests/agents/test_compare.py)."""
    return {
        "entry": entry, "seed": seed, "success": success, "end_reason": "goal" if success is True else "fall",
        "mean_stability_index": 50.0, "min_stability_index": -10.0, "time_index_negative": 0.1,
        "fraction_index_nonnegative": 0.99, "mean_speed": 0.1, "mean_residual_torque": None,
        "factors": {"friction": 1.0}, **changes,
    }  # fmt: skip


def results(episodes: list | None = None, **changes) -> dict:
    eps = [episode(0, 100), episode(0, 101, False)] if episodes is None else episodes
    return {"suite": "s", "policy": "expert", "episodes": eps, "meta": {"entries": ["rough"], "seed_offset": 100},
            **changes}  # fmt: skip


def folder(tmp: Path, name: str, content: object | str) -> Path:
    """An evaluation folder whose results.json holds ``content`` (JSON-encoded unless a string)."""
    d = tmp / name
    d.mkdir(exist_ok=True)
    (d / "results.json").write_text(content if isinstance(content, str) else json.dumps(content))
    return d


def compare_argv(tmp: Path, candidate: object | str, out: Path | None = None) -> list[str]:
    base = folder(tmp, "base", results())
    cand = folder(tmp, "cand", candidate)
    return ["compare", "--baseline", str(base), "--candidate", str(cand), "--out", str(out or tmp / "cmp")]


def a_file(tmp: Path) -> Path:
    path = tmp / "not_a_dir"
    path.write_text("the user's file")
    return path


def suite_file(tmp: Path, text: str | None = None) -> Path:
    path = tmp / "suite.yaml"
    raw = {"name": "tiny", "goal_distance": 0.5, "time_limit": 0.1, "terrains": [{"kind": "flat", "seeds": [0, 1]}]}
    path.write_text(text if text is not None else yaml.safe_dump(raw))
    return path


def evaluate_argv(tmp: Path, *extra: str, policy: str = "zero", out: Path | None = None) -> list[str]:
    return ["evaluate", "--policy", policy, "--suite", str(suite_file(tmp)), "--out", str(out or tmp / "out"),
            "--no-progress", *extra]  # fmt: skip


def train_from_scratch_config(tmp: Path) -> Path:
    raw = yaml.safe_load(default_config_path("ppo").read_text())
    raw.update(residual=False, expert_features=False, residual_penalty=0.0, residual_legs="all",
               residual_basis="torque_limit", expert={})  # fmt: skip
    path = tmp / "scratch.yaml"
    path.write_text(yaml.safe_dump(raw))
    return path


def default_config_path(algo: str) -> Path:
    from agents.rl.config import default_config_path as path

    return path(algo)


Case = tuple[Callable[[Path], list[str]], tuple[str, ...]]

CASES: dict[str, Case] = {
    # -- compare: results.json files it did not write
    "results a JSON list": (lambda t: compare_argv(t, [1, 2]), ("cand/results.json", "the top level", "JSON object")),
    "results without episodes": (lambda t: compare_argv(t, {"meta": {}}), ("cand/results.json", "episodes is missing")),
    "results without meta": (lambda t: compare_argv(t, {"episodes": []}), ("cand/results.json", "meta is missing")),
    "episodes not a list": (
        lambda t: compare_argv(t, results(episodes={"0": 1})),
        ("cand/results.json", "episodes must be a list"),
    ),
    "episode not an object": (lambda t: compare_argv(t, results(episodes=[3])), ("episodes[0] must be a JSON object",)),
    "success as a string": (
        lambda t: compare_argv(t, results([episode(0, 100, "yes"), episode(0, 101, False)])),
        ("cand/results.json", "episodes[0].success", "JSON bool", "'yes'"),
    ),
    "success missing": (
        lambda t: compare_argv(t, results([{"entry": 0, "seed": 100}, episode(0, 101)])),
        ("episodes[0].success is missing",),
    ),
    "entry as a string": (
        lambda t: compare_argv(t, results([episode("0", 100), episode(0, 101)])),
        ("episodes[0].entry", "integer"),
    ),
    "seed as a float": (
        lambda t: compare_argv(t, results([episode(0, 100.5), episode(0, 101)])),
        ("episodes[0].seed", "integer"),
    ),
    "index figure as a string": (
        lambda t: compare_argv(t, results([episode(0, 100, mean_stability_index="high"), episode(0, 101)])),
        ("episodes[0].mean_stability_index", "finite number"),
    ),
    "factor as a string": (
        lambda t: compare_argv(t, results([episode(0, 100, factors={"friction": "low"}), episode(0, 101)])),
        ("episodes[0].factors",),
    ),
    "pushes not a list": (
        lambda t: compare_argv(t, results([episode(0, 100, pushes={"start": 1}), episode(0, 101)])),
        ("episodes[0].pushes",),
    ),
    "machine not an object": (
        lambda t: compare_argv(t, results([episode(0, 100, machine="x86"), episode(0, 101)])),
        ("episodes[0].machine",),
    ),
    "end reason unknown": (
        lambda t: compare_argv(t, results([episode(0, 100, end_reason="tired"), episode(0, 101)])),
        ("episodes[0].end_reason", "'goal'"),
    ),
    "meta entries not strings": (
        lambda t: compare_argv(t, results(meta={"entries": [1]})),
        ("cand/results.json", "meta.entries"),
    ),
    "an episode twice": (
        lambda t: compare_argv(t, results([episode(0, 100), episode(0, 100)])),
        ("episodes[1] repeats entry 0, seed 100",),
    ),
    "NaN in the file": (
        lambda t: compare_argv(t, json.dumps(results()).replace("50.0", "NaN", 1)),
        ("cand/results.json", "NaN"),
    ),
    "a key twice": (
        lambda t: compare_argv(t, '{"episodes": [], "episodes": [], "meta": {}}'),
        ("cand/results.json", "'episodes' given more than once"),
    ),
    "truncated file": (lambda t: compare_argv(t, json.dumps(results())[:40]), ("cand/results.json", "not a JSON")),
    "no results.json": (
        lambda t: ["compare", "--baseline", str(folder(t, "b", results())), "--candidate", str(t), "--out", str(t)],
        ("no results.json", "quad-uneven evaluate --out"),
    ),
    "compare out is a file": (lambda t: compare_argv(t, results(), out=a_file(t)), ("--out", "not_a_dir", "a file")),
    "compare out under a file": (lambda t: compare_argv(t, results(), out=a_file(t) / "sub"), ("--out", "sub")),
    # -- argparse's own errors
    "not an integer": (lambda t: evaluate_argv(t, "--seed", "abc"), ("--seed", "invalid int value: 'abc'")),
    "unknown option": (lambda t: evaluate_argv(t, "--sede", "1"), ("unrecognized arguments: --sede",)),
    "missing option": (lambda t: ["evaluate", "--policy", "zero"], ("--suite", "--out", "required")),
    "unknown choice": (lambda t: evaluate_argv(t, "--backend", "mpi"), ("--backend", "'mpi'", "'pool'")),
    "unknown command": (lambda t: ["evalute"], ("'evalute'", "evaluate")),
    "no command": (lambda t: [], ("command",)),
    # -- options refused in combination or form
    "robustness values": (
        lambda t: ["robustness", "--factor", "push", "--values", "a,b", "--out", str(t / "r")],
        ("--values", "comma-separated finite numbers", "'a'"),
    ),
    "robustness model without the expert": (
        lambda t: ["robustness", "--factor", "push", "--policy", "zero", "--model", "oracle", "--out", str(t / "r")],
        ("--model", "--policy expert", "'zero'"),
    ),
    "evaluate algo for a named policy": (
        lambda t: evaluate_argv(t, "--algo", "sac", policy="expert"),
        ("--algo", "--policy 'expert'"),
    ),
    "evaluate allow-pickle for a named policy": (
        lambda t: evaluate_argv(t, "--allow-pickle"),
        ("--allow-pickle", "--policy 'zero'"),
    ),
    "evaluate workers with a cluster": (
        lambda t: evaluate_argv(t, "--backend", "ray", "--address", "auto", "--workers", "3"),
        ("--workers", "--address"),
    ),
    "train residual scale from scratch": (
        lambda t: [
            "train",
            "--config",
            str(train_from_scratch_config(t)),
            "--residual-scale",
            "0.2",
            "--out",
            str(t / "run"),
        ],
        ("--residual-scale", "residual: false"),
    ),
    # -- YAML with a key given twice
    "suite with time_limit twice": (
        lambda t: [
            "evaluate",
            "--policy",
            "zero",
            "--out",
            str(t / "out"),
            "--suite",
            str(suite_file(t, "name: x\ntime_limit: 1\ngoal_distance: 0.5\nterrains: []\ntime_limit: 2\n")),
        ],
        ("suite.yaml", "'time_limit'", "line 5", "line 2"),
    ),
    "training config with a key twice": (
        lambda t: ["train", "--config", str(suite_file(t, "algo: ppo\nseed: 1\nseed: 2\n")), "--out", str(t / "r")],
        ("suite.yaml", "'seed'", "line 3"),
    ),
}


def run_cli(argv: list[str], capsys) -> tuple[int, str]:
    capsys.readouterr()
    rc = main(argv)
    return rc, capsys.readouterr().err


def assert_one_error_line(rc: int, err: str, fields: tuple[str, ...]) -> None:
    assert rc == 2, err
    assert "Traceback" not in err
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    missing = [f for f in fields if f not in lines[0]]
    assert not missing, lines[0]


@pytest.mark.parametrize("name", list(CASES))
def test_crafted_input_exits_2_with_one_line_naming_it(name, tmp_path, capsys):
    build, fields = CASES[name]
    argv = build(tmp_path)
    before = {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()}
    rc, err = run_cli(argv, capsys)
    assert_one_error_line(rc, err, fields)
    for path, data in before.items():  # nothing of the user's is lost or changed
        assert path.read_bytes() == data, path


def test_success_as_a_string_is_never_counted(tmp_path, capsys):
    """``"success": "yes"`` is refused by the loader, not counted as a success."""
    from agents.evaluation.results_io import ResultsError, load_results

    bad = folder(tmp_path, "bad", results([episode(0, 100, "yes")]))
    with pytest.raises(ResultsError, match=r"episodes\[0\]\.success must be true or false"):
        load_results(bad)
    assert load_results(folder(tmp_path, "good", results()))["episodes"][0]["success"] is True


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_compare_into_a_read_only_out(tmp_path, capsys):
    out = tmp_path / "ro"
    out.mkdir()
    out.chmod(0o500)
    try:
        rc, err = run_cli(compare_argv(tmp_path, results(), out=out), capsys)
    finally:
        out.chmod(0o700)
    assert_one_error_line(rc, err, ("--out", "ro"))


def test_help_still_prints_the_help(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["evaluate", "--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith("usage: quad-uneven evaluate") and "--overwrite" in out


def test_argparse_errors_through_a_real_process(tmp_path):
    proc = subprocess.run(
        [sys.executable, "-m", "agents.cli", "evaluate", "--policy", "zero", "--suite", "flat", "--out",
         str(tmp_path / "o"), "--seed", "abc"],
        capture_output=True, text=True, cwd=ROOT, timeout=300,
    )  # fmt: skip
    assert proc.returncode == 2
    assert proc.stderr.startswith("error: argument --seed") and proc.stderr.count("\n") == 1
    assert "usage:" not in proc.stderr and "Traceback" not in proc.stderr


# ---------------------------------------------------------------------------------------- --resume
@pytest.fixture
def finished_run(tmp_path) -> Path:
    """A finished two-episode evaluation of the zero policy on flat ground (0.1 s each)."""
    out = tmp_path / "run"
    assert main(evaluate_argv(tmp_path, out=out)) == 0
    return out


def test_resume_refuses_a_record_it_did_not_write(tmp_path, finished_run, capsys):
    path = finished_run / "episodes" / "ep001.json"
    record = json.loads(path.read_text())
    path.write_text(json.dumps({**record, "success": "yes"}))
    rc, err = run_cli(evaluate_argv(tmp_path, "--resume", out=finished_run), capsys)
    assert_one_error_line(rc, err, ("--resume", "ep001.json", "success", "JSON bool", "--overwrite"))
    assert json.loads(path.read_text())["success"] == "yes"  # left for the user to look at

    path.write_text(json.dumps({**record, "seed": 7}))
    rc, err = run_cli(evaluate_argv(tmp_path, "--resume", out=finished_run), capsys)
    assert_one_error_line(rc, err, ("ep001.json", "seed must be 1", "got 7"))


def test_resume_refuses_a_trace_the_report_cannot_read(tmp_path, finished_run, capsys):
    trace = finished_run / "traces" / "ep000.npz"
    trace.write_bytes(trace.read_bytes()[:100])
    rc, err = run_cli(evaluate_argv(tmp_path, "--resume", out=finished_run), capsys)
    assert_one_error_line(rc, err, ("ep000.npz",))


# -------------------------------------------------------------------------------------- --overwrite
def test_overwrite_keeps_the_users_files_and_replaces_its_own(tmp_path, finished_run, capsys):
    manifest = json.loads((finished_run / MANIFEST_FILE).read_text())
    assert {"results.json", "report.md", "run.json", "episodes/ep001.json", "traces/ep001.npz"} <= set(
        manifest["files"]
    )
    note = finished_run / "episodes" / "ep001_notes.txt"  # matches nothing, but sits among the records
    note.write_text("my notes")
    png = finished_run / "my_plot.png"  # matches the command's *.png
    png.write_bytes(b"\x89PNG mine")
    sub = finished_run / "episodes" / "mine"
    sub.mkdir()
    (sub / "ep000.json").write_text("{}")  # the name of a record, in a folder of the user's
    old_results = (finished_run / "results.json").read_text()

    rc, err = run_cli([*evaluate_argv(tmp_path, "--episodes", "1", "--seed", "5", out=finished_run),
                       "--overwrite"], capsys)  # fmt: skip
    assert rc == 0, err
    assert note.read_text() == "my notes" and png.read_bytes() == b"\x89PNG mine"
    assert (sub / "ep000.json").read_text() == "{}"
    new = json.loads((finished_run / "results.json").read_text())
    assert (finished_run / "results.json").read_text() != old_results and new["meta"]["seed_offset"] == 5
    assert sorted(p.name for p in (finished_run / "episodes").glob("ep*.json")) == ["ep000.json"]
    assert sorted(p.name for p in (finished_run / "traces").iterdir()) == ["ep000.npz"]
    assert set(json.loads((finished_run / MANIFEST_FILE).read_text())["files"]).isdisjoint(
        {"episodes/ep001_notes.txt", "my_plot.png"}
    )


def test_overwrite_removes_the_folders_it_made_once_empty(tmp_path, finished_run, capsys):
    other = tmp_path / "other.yaml"
    other.write_text(yaml.safe_dump({"name": "o", "goal_distance": 0.5, "time_limit": 0.1,
                                     "terrains": [{"kind": "flat", "seeds": [3]}]}))  # fmt: skip
    (finished_run / "traces" / "keep.txt").write_text("mine")
    argv = ["evaluate", "--policy", "zero", "--suite", str(other), "--out", str(finished_run), "--no-progress",
            "--overwrite"]  # fmt: skip
    rc, err = run_cli(argv, capsys)
    assert rc == 0, err
    assert (finished_run / "traces" / "keep.txt").read_text() == "mine"
    assert sorted(p.name for p in (finished_run / "traces").iterdir()) == ["ep000.npz", "keep.txt"]


def test_overwrite_refuses_an_older_run_without_a_manifest(tmp_path, finished_run, capsys):
    (finished_run / MANIFEST_FILE).unlink()  # as an older version left it
    files = sorted(p for p in finished_run.rglob("*") if p.is_file())
    rc, err = run_cli([*evaluate_argv(tmp_path, out=finished_run), "--overwrite"], capsys)
    assert_one_error_line(rc, err, (str(finished_run), "no .quad-uneven-manifest.json", "nothing was deleted"))
    assert sorted(p for p in finished_run.rglob("*") if p.is_file()) == files


def test_overwrite_refuses_a_file_of_the_users_where_it_writes_one(tmp_path, finished_run, capsys):
    manifest = json.loads((finished_run / MANIFEST_FILE).read_text())
    manifest["files"].remove("report.md")  # report.md is then the user's
    (finished_run / MANIFEST_FILE).write_text(json.dumps(manifest))
    rc, err = run_cli([*evaluate_argv(tmp_path, out=finished_run), "--overwrite"], capsys)
    assert_one_error_line(rc, err, ("report.md", "does not list", "nothing was deleted"))
    assert (finished_run / "results.json").is_file()


def test_a_manifest_that_leaves_the_folder_deletes_nothing(tmp_path, finished_run, capsys):
    outside = tmp_path / "precious.txt"
    outside.write_text("mine")
    manifest = json.loads((finished_run / MANIFEST_FILE).read_text())
    manifest["files"].append("../precious.txt")
    (finished_run / MANIFEST_FILE).write_text(json.dumps(manifest))
    rc, err = run_cli([*evaluate_argv(tmp_path, out=finished_run), "--overwrite"], capsys)
    assert_one_error_line(rc, err, (MANIFEST_FILE, "'../precious.txt'", "nothing was deleted"))
    assert outside.read_text() == "mine" and (finished_run / "results.json").is_file()


def test_compare_records_its_files_beside_the_users(tmp_path, capsys):
    out = tmp_path / "cmp"
    out.mkdir()
    (out / "comparison_notes.md").write_text("mine")
    rc, err = run_cli(compare_argv(tmp_path, results(), out=out), capsys)
    assert rc == 0, err
    files = json.loads((out / MANIFEST_FILE).read_text())["files"]
    assert files == ["comparison.json", "comparison.md", "comparison.png"]
    assert (out / "comparison_notes.md").read_text() == "mine"
