"""Crafted collections: ``collect`` runs a suite's episodes as ``evaluate`` does (its robot scale included), and
``--resume`` and ``load_collected`` trust no file of the folder they did not verify.

A damaged dataset (truncated or deleted ``main_data.hdf5``, garbage ``metadata.json``) is not a finished
collection: ``--resume`` builds it again, identical. An episode file that is not one the collection wrote (a
truncated record, a field missing or of the wrong type, arrays of another shape, a truncated ``.npz``) stops
``--resume`` with exit code 2 and one line naming the file and the field.
"""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml

from agents.cli import main

pytest.importorskip("minari", reason="the 'datasets' extra (Minari) is not installed")

import agents.datasets.run as collect_module
from agents.datasets import CollectInterrupted, collect, episode_metadata, load_collected
from agents.datasets.minari_io import DatasetError

TIME_LIMIT = 0.2  # s: 10 control steps per episode
DATASET = "quad-uneven-tiny-expert-v0"


def write_suite(path: Path) -> Path:
    """A flat and a rough entry, one seed each, 0.2 s per episode."""
    raw = {"name": "tiny", "goal_distance": 1.0, "time_limit": TIME_LIMIT,
           "terrains": [{"kind": "flat", "seeds": [0]},
                        {"kind": "rough", "params": {"amplitude": 0.04, "wavelength": 0.6}, "seeds": [0]}]}  # fmt: skip
    path.write_text(yaml.safe_dump(raw))
    return path


def collect_argv(suite: Path, out: Path, *extra: str) -> list[str]:
    return ["collect", "--policy", "expert", "--suite", str(suite), "--out", str(out), "--no-progress", *extra]


def assert_same_dataset(a, b) -> None:
    assert a.total_episodes == b.total_episodes and a.total_steps == b.total_steps
    for i in range(a.total_episodes):
        ea, eb = a[i], b[i]
        for name in ("observations", "actions", "rewards", "terminations", "truncations"):
            np.testing.assert_array_equal(getattr(ea, name), getattr(eb, name), err_msg=name)


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    """A finished collection of the two episodes: (suite, folder)."""
    root = tmp_path_factory.mktemp("finished")
    suite = write_suite(root / "suite.yaml")
    assert main(collect_argv(suite, root / "out")) == 0
    return suite, root / "out"


@pytest.fixture(scope="module")
def interrupted(tmp_path_factory):
    """A collection interrupted after its first episode (its record and arrays on disk): (suite, folder)."""
    root = tmp_path_factory.mktemp("interrupted")
    suite = write_suite(root / "suite.yaml")
    real, calls = collect_module.collect_task, []

    def interrupted_after_one(task, cfg):
        calls.append(task.index)
        if len(calls) > 1:
            raise KeyboardInterrupt
        return real(task, cfg)

    collect_module.collect_task = interrupted_after_one
    try:
        with pytest.raises(CollectInterrupted):
            collect(suite, root / "out", progress=False)
    finally:
        collect_module.collect_task = real
    assert (root / "out" / "episodes" / "ep000.npz").is_file() and (root / "out" / "episodes" / "ep000.json").is_file()
    return suite, root / "out"


def copy_of(folder: Path, tmp_path: Path) -> Path:
    return Path(shutil.copytree(folder, tmp_path / "copy"))


def test_collect_runs_a_leg_length_suite_at_the_robots_scale(tmp_path):
    """As evaluate does (tests/agents/test_expert_robots.py): on Solo12 (s = leg length / 0.42 m) every length of
    the written terrain is x s, the goal x s, the time limit x sqrt(s)."""
    from quad_uneven_env.robot.description import load_robot

    s = load_robot("solo12").leg_length / 0.42
    suite = tmp_path / "suite.yaml"
    suite.write_text(yaml.safe_dump({
        "name": "stones", "scale": "leg_length", "goal_distance": 1.0, "time_limit": 0.1,
        "terrains": [{"kind": "stepping_stones", "params": {"gap": 0.05}, "seeds": [0]}],
    }))  # fmt: skip
    summary = collect(suite, tmp_path / "o", env_kwargs={"robot": "solo12"}, progress=False)
    dataset = load_collected(tmp_path / "o")
    params = episode_metadata(dataset, 0)["terrain"]
    assert params["gap"] == pytest.approx(0.05 * s) and params["cell_size"] == pytest.approx(0.02 * s)
    assert params["length"] == pytest.approx(8.0 * s) and params["stone_size"] == pytest.approx(0.25 * s)
    meta = dataset.storage.metadata["quad_uneven"]
    assert meta["goal_distance"] == pytest.approx(s) and meta["time_limit"] == pytest.approx(0.1 * math.sqrt(s))
    assert summary["episodes"] == 1


def truncate(path: Path) -> None:
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])


DAMAGES = {
    "truncated main_data.hdf5": lambda data: truncate(data / "main_data.hdf5"),
    "deleted main_data.hdf5": lambda data: (data / "main_data.hdf5").unlink(),
    "garbage metadata.json": lambda data: (data / "metadata.json").write_text("{not json"),
    "metadata.json of other totals": lambda data: (data / "metadata.json").write_text(
        json.dumps({**json.loads((data / "metadata.json").read_text()), "total_steps": 3})
    ),
}


@pytest.mark.parametrize("damage", list(DAMAGES))
def test_a_damaged_dataset_is_refused_by_load_collected_and_rebuilt_by_resume(finished, tmp_path, damage, capsys):
    suite, out = finished
    target = copy_of(out, tmp_path)
    DAMAGES[damage](target / DATASET / "data")
    with pytest.raises(DatasetError) as err:
        load_collected(target)
    assert str(target / DATASET / "data") in str(err.value) and "\n" not in str(err.value)

    assert main(collect_argv(suite, target, "--resume")) == 0
    warning = [line for line in capsys.readouterr().err.splitlines() if line.startswith("warning:")]
    assert len(warning) == 1 and "the dataset is built again" in warning[0]
    assert_same_dataset(load_collected(out), load_collected(target))


def test_a_garbage_summary_is_refused_by_load_collected(finished, tmp_path):
    _, out = finished
    target = copy_of(out, tmp_path)
    (target / "collect.json").write_text(json.dumps({"dataset_id": DATASET, "episodes": "2"}))
    with pytest.raises(DatasetError, match=r"collect\.json: .*(episodes|dataset_path)"):
        load_collected(target)


def edit_record(change):
    def edit(out: Path) -> None:
        path = out / "episodes" / "ep000.json"
        saved = json.loads(path.read_text())
        change(saved)
        path.write_text(json.dumps(saved))

    return edit


def narrow_observations(out: Path) -> None:
    path = out / "episodes" / "ep000.npz"
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["observations"] = arrays["observations"][:, :10]
    with path.open("wb") as f:
        np.savez(f, **arrays)


TAMPERED = {
    "success as a string": (edit_record(lambda s: s["record"].update(success="false")), "record.success must be"),
    "record without distance": (edit_record(lambda s: s["record"].pop("distance")), "record.distance is missing"),
    "no step count": (edit_record(lambda s: s.pop("steps")), "steps is missing"),
    "another episode's record": (edit_record(lambda s: s["record"].update(seed=7)), "seed must be 0"),
    "truncated record": (lambda out: truncate(out / "episodes" / "ep000.json"), "not a JSON file"),
    "10 observation columns": (narrow_observations, "observations must have shape (11, 134)"),
    "truncated arrays": (lambda out: truncate(out / "episodes" / "ep000.npz"), "not an array file"),
    "steps of another episode": (edit_record(lambda s: s.update(steps=4)), "observations must have shape (5, 134)"),
}


@pytest.mark.parametrize("case", list(TAMPERED))
def test_resume_refuses_an_episode_file_the_collection_did_not_write(interrupted, tmp_path, case, capsys):
    suite, out = interrupted
    target = copy_of(out, tmp_path)
    tamper, message = TAMPERED[case]
    tamper(target)
    assert main(collect_argv(suite, target, "--resume")) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: --resume: ") and err.count("\n") == 1, err
    assert str(target / "episodes" / "ep000.") in err and message in err, err
    assert not (target / DATASET).exists()


def test_resume_of_an_untouched_interrupted_collection_finishes_it(interrupted, finished, tmp_path):
    """The reference for the cases above: the same copy, not tampered with, resumes to the uninterrupted dataset."""
    suite, out = interrupted
    target = copy_of(out, tmp_path)
    assert main(collect_argv(suite, target, "--resume")) == 0
    assert_same_dataset(load_collected(finished[1]), load_collected(target))
