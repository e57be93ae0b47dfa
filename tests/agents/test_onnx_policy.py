"""``evaluate --policy PATH.onnx``: an exported policy acts as its model.zip does; a residual export and another
robot are refused with one line."""

from __future__ import annotations

import numpy as np
import pytest

import quad_uneven_env  # noqa: F401  (registers QuadUneven-v0)
from agents.cli import main
from agents.evaluation.policies import PolicyError, make_policy, make_policy_env
from agents.evaluation.run import evaluate
from agents.evaluation.suites import suite_from_dict

pytest.importorskip("stable_baselines3")
pytest.importorskip("onnx")
pytest.importorskip("onnxruntime")

SUITE = {
    "name": "tiny",
    "goal_distance": 5.0,
    "time_limit": 0.3,
    "terrains": [{"kind": "flat", "seeds": [0]}, {"kind": "rough", "params": {"amplitude": 0.04}, "seeds": [1]}],
}


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """The shipped distilled student and its ONNX export."""
    out = tmp_path_factory.mktemp("onnx") / "distilled.onnx"
    assert main(["export", "--policy", "models/distilled/model.zip", "--out", str(out)]) == 0
    return "models/distilled/model.zip", out


def test_the_onnx_policy_acts_as_its_model_zip(exported):
    zip_path, onnx_path = exported
    env_zip = make_policy_env(zip_path, terrain="rough")
    env_onnx = make_policy_env(str(onnx_path), terrain="rough")
    assert env_onnx.observation_space.shape == env_zip.observation_space.shape
    p_zip, p_onnx = make_policy(zip_path, env_zip), make_policy(str(onnx_path), env_onnx)
    obs, _ = env_zip.reset(seed=3)
    obs_onnx, _ = env_onnx.reset(seed=3)
    np.testing.assert_array_equal(obs, obs_onnx)  # the same env from the file's metadata
    for _ in range(20):
        a, _ = p_zip.predict(obs, deterministic=True)
        b, _ = p_onnx.predict(obs, deterministic=True)
        np.testing.assert_allclose(b, a, atol=1e-5)
        obs, *_ = env_zip.step(a)
    assert np.abs(a).max() > 0.01  # a policy that acts, not zeros


def test_evaluate_runs_an_onnx_policy_on_the_episodes_of_its_zip(exported, tmp_path):
    zip_path, onnx_path = exported
    suite = suite_from_dict(SUITE, source="test")
    a = evaluate(suite, zip_path, tmp_path / "zip", progress=False)
    b = evaluate(suite, str(onnx_path), tmp_path / "onnx", progress=False)
    assert [e["error"] for e in b["episodes"]] == [None, None]
    for ea, eb in zip(a["episodes"], b["episodes"], strict=True):
        assert eb["seed"] == ea["seed"] and eb["distance"] == pytest.approx(ea["distance"], abs=1e-3)


def test_a_residual_export_and_another_robot_are_refused(exported, tmp_path, capsys):
    import onnx

    _, onnx_path = exported
    with pytest.raises(PolicyError, match="robot must be 'paper'"):
        make_policy_env(str(onnx_path), terrain="flat", robot="go1")
    graph = onnx.load(str(onnx_path))
    onnx.helper.set_model_props(graph, {p.key: p.value for p in graph.metadata_props} | {"residual": "true"})
    residual = tmp_path / "residual.onnx"
    onnx.save(graph, str(residual))
    rc = main(["evaluate", "--policy", str(residual), "--suite", "smoke", "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert rc == 2 and "evaluate its model.zip" in err and err.count("\n") == 1, err
    rc = main(["evaluate", "--policy", str(tmp_path / "none.onnx"), "--suite", "smoke", "--out", str(tmp_path / "p")])
    err = capsys.readouterr().err
    assert rc == 2 and "does not exist" in err, err
