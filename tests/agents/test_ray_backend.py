"""quad-uneven evaluate --backend ray: the same episode records as the process pool, resume, the missing extra."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from agents.cli import main
from agents.evaluation.ray_backend import SHIPPED, RayUnavailable, code_runtime_env, import_ray, ray_session
from agents.evaluation.run import evaluate

WALL_CLOCK_FIELDS = ("wall_time", "realtime_factor", "planner_ms_median", "planner_ms_p95")


def write_suite(path: Path) -> Path:
    """Three seeded 1 s episodes on two terrain kinds."""
    raw = {
        "name": "tiny",
        "goal_distance": 0.5,
        "time_limit": 1.0,
        "terrains": [
            {"kind": "flat", "seeds": [0]},
            {"kind": "rough", "params": {"amplitude": 0.04, "wavelength": 0.6}, "seeds": [3, 4]},
        ],
    }
    path.write_text(yaml.safe_dump(raw))
    return path


def records(out: Path) -> list[dict]:
    """The per-episode records of DIR/episodes/, in index order, without the wall-clock fields."""
    files = sorted((out / "episodes").glob("ep*.json"))
    return [{k: v for k, v in json.loads(f.read_text()).items() if k not in WALL_CLOCK_FIELDS} for f in files]


@pytest.mark.slow  # the pool's 2 spawned processes and the Ray workers each import the simulator: 24-43 s here
def test_ray_gives_the_records_of_the_process_pool(tmp_path, local_ray):
    suite = write_suite(tmp_path / "s.yaml")
    pool = evaluate(suite, "zero", tmp_path / "pool", workers=2, progress=False)
    on_ray = evaluate(suite, "zero", tmp_path / "ray", workers=2, backend="ray", progress=False)
    assert len(records(tmp_path / "ray")) == 3
    assert records(tmp_path / "ray") == records(tmp_path / "pool")
    assert [e["index"] for e in on_ray["episodes"]] == [0, 1, 2]
    # The rough seeds differ, so equal records are not equal by accident.
    assert on_ray["episodes"][1]["mean_stability_index"] != on_ray["episodes"][2]["mean_stability_index"]
    strip = set(WALL_CLOCK_FIELDS)
    for group in ("overall", "by_kind"):
        a, b = pool["summary"][group], on_ray["summary"][group]
        if group == "overall":
            a, b = {"_": a}, {"_": b}
        for key in a:
            assert {k: v for k, v in a[key].items() if k not in strip} == {
                k: v for k, v in b[key].items() if k not in strip
            }
    assert on_ray["meta"]["backend"] == "ray" and pool["meta"]["backend"] == "pool"
    assert (tmp_path / "ray" / "report.md").is_file()


def test_ray_resume_runs_only_the_missing_episodes(tmp_path, local_ray):
    suite = write_suite(tmp_path / "s.yaml")
    evaluate(suite, "zero", tmp_path / "o", backend="ray", progress=False)
    first = records(tmp_path / "o")
    (tmp_path / "o" / "episodes" / "ep001.json").unlink()
    res = evaluate(suite, "zero", tmp_path / "o", backend="ray", resume=True, progress=False)
    assert res["meta"]["resumed_episodes"] == 2
    assert records(tmp_path / "o") == first


def test_cli_backend_ray_end_to_end(tmp_path, capsys, local_ray):
    suite = write_suite(tmp_path / "s.yaml")
    rc = main(["evaluate", "--policy", "zero", "--suite", str(suite), "--out", str(tmp_path / "o"), "--backend", "ray",
               "--no-progress"])  # fmt: skip
    assert rc == 0, capsys.readouterr().err
    assert json.loads((tmp_path / "o" / "results.json").read_text())["meta"]["backend"] == "ray"
    assert "report written" in capsys.readouterr().out


def test_ray_session_reuses_the_running_ray_and_keeps_our_sigterm_handler(local_ray):
    with ray_session(num_cpus=1) as r:
        assert r.is_initialized()
    assert local_ray.is_initialized()  # not shut down: it was not ours
    assert local_ray.cluster_resources()["CPU"] == 2
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL  # ray.init's own handler was removed


def test_without_ray_the_cli_names_the_extra_and_exits_2(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` now raises ImportError
    with pytest.raises(RayUnavailable, match=r"distributed"):
        import_ray()
    suite = write_suite(tmp_path / "s.yaml")
    rc = main(["evaluate", "--policy", "zero", "--suite", str(suite), "--out", str(tmp_path / "o"), "--backend", "ray",
               "--no-progress"])  # fmt: skip
    err = capsys.readouterr().err
    assert rc == 2
    assert err.count("\n") == 1 and 'pip install -e ".[distributed]"' in err
    assert not (tmp_path / "o").exists()  # refused before anything is written


def test_address_needs_the_ray_backend(tmp_path, capsys):
    suite = write_suite(tmp_path / "s.yaml")
    rc = main(["evaluate", "--policy", "zero", "--suite", str(suite), "--out", str(tmp_path / "o"),
               "--address", "auto"])  # fmt: skip
    assert rc == 2 and "--backend ray" in capsys.readouterr().err
    rc = main(["evaluate", "--policy", "zero", "--suite", str(suite), "--out", str(tmp_path / "o"), "--ship-code"])
    assert rc == 2 and "--backend ray" in capsys.readouterr().err
    with pytest.raises(ValueError, match="backend"):
        evaluate(suite, "zero", tmp_path / "o", backend="dask")


SHIPPED_PROBE = """
import json, ray
from agents.evaluation.ray_backend import ray_session

@ray.remote
def probe():
    import quad_uneven_env
    from quad_uneven_env.config import CONFIG_DIR
    return quad_uneven_env.__file__, sorted(p.name for p in CONFIG_DIR.iterdir())

with ray_session(num_cpus=1, ship_code=True):
    print(json.dumps(ray.get(probe.remote())))
"""
"""A new Ray session (runtime envs that upload a folder are per session) asked where its worker's package is."""


def test_ship_code_uploads_the_packages_and_configs_only(tmp_path):
    pytest.importorskip("ray")
    import quad_uneven_env

    env = code_runtime_env()
    root = Path(quad_uneven_env.__file__).resolve().parents[1]
    assert env["working_dir"] == str(root)
    assert "/tests" in env["excludes"] and not any(f"/{name}" in env["excludes"] for name in SHIPPED)
    run = subprocess.run([sys.executable, "-c", SHIPPED_PROBE], capture_output=True, text=True, cwd=tmp_path,
                         env={**os.environ, "PYTHONPATH": str(root)}, timeout=300)  # fmt: skip
    assert run.returncode == 0, run.stderr[-2000:]
    where, configs = json.loads(run.stdout.strip().splitlines()[-1])
    assert not where.startswith(str(root)) and where.endswith("quad_uneven_env/__init__.py")  # the uploaded copy
    assert configs == sorted(p.name for p in (root / "configs").iterdir())
    assert not (Path(where).parents[1] / "tests").exists()


@pytest.mark.slow  # the interrupt kills the Ray workers (as the pool's terminate): the resume starts new ones
def test_an_interrupt_keeps_the_finished_episodes_and_resume_ends_the_run(tmp_path, monkeypatch, local_ray):
    import agents.evaluation.run as run

    suite = write_suite(tmp_path / "s.yaml")
    written = run.write_episode

    def write_then_interrupt(out, result):
        written(out, result)
        raise KeyboardInterrupt  # as Ctrl-C (or SIGTERM) right after the first record

    monkeypatch.setattr(run, "write_episode", write_then_interrupt)
    with pytest.raises(run.EvaluationInterrupted, match="--resume"):
        evaluate(suite, "zero", tmp_path / "o", backend="ray", progress=False)
    assert len(list((tmp_path / "o" / "episodes").glob("ep*.json"))) == 1
    monkeypatch.setattr(run, "write_episode", written)
    res = evaluate(suite, "zero", tmp_path / "o", backend="ray", resume=True, progress=False)
    assert res["meta"]["resumed_episodes"] == 1 and len(records(tmp_path / "o")) == 3
