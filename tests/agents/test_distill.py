"""``quad-uneven distill``: the labels, the teacher controller, the student's files, determinism, CLI errors; and the
observation's gait clock the student reads."""

from __future__ import annotations

import json
import math

import gymnasium as gym
import numpy as np
import pytest

import quad_uneven_env  # noqa: F401  (registers QuadUneven-v0)
from agents.cli import main
from agents.evaluation.suites import episode_tasks, suite_from_dict

pytest.importorskip("stable_baselines3")

TINY = {
    "name": "tiny",
    "goal_distance": 5.0,
    "time_limit": 1.0,
    "terrains": [{"kind": "flat", "seeds": [0]}, {"kind": "rough", "params": {"amplitude": 0.04}, "seeds": [1]}],
}
"""Two episodes of 50 control steps each: 100 steps a round."""


def tiny_config(**changes):
    from agents.rl.distill import DistillConfig

    base = dict(dagger_rounds=1, episodes=1, epochs=2, net_arch=(16,), seed=3, budget_min=30.0)
    return DistillConfig(**{**base, **changes})


# --------------------------------------------------------------------------------------------- gait clock
def test_gait_clock_period_is_an_env_option_with_hand_computed_values():
    """``gait_period`` sets the clock's period; after 7 control steps (0.14 s) with the 3.1 s expert cycle the
    field holds sin and cos of 2 pi 0.14 / 3.1 = 0.28376 rad: x - x^3/6 = 0.27996 and 1 - x^2/2 + x^4/24 = 0.96001;
    the space and shape stay those of the default."""
    env = gym.make("QuadUneven-v0", terrain="flat", gait_period=3.1, action_mode="joint_pd")
    default = gym.make("QuadUneven-v0", terrain="flat", action_mode="joint_pd")
    assert env.observation_space == default.observation_space and env.observation_space.shape == (134,)
    sl = env.unwrapped.observation_structure["gait_clock"]
    assert (sl.start, sl.stop) == (43, 45)
    obs, _ = env.reset(seed=0)
    np.testing.assert_allclose(obs[sl], [0.0, 1.0], atol=1e-7)
    for _ in range(7):
        obs, *_ = env.step(np.zeros(12))
    np.testing.assert_allclose(obs[sl], [0.27996, 0.96001], atol=2e-5)
    assert obs[sl] == pytest.approx([math.sin(2 * math.pi * 0.14 / 3.1), math.cos(2 * math.pi * 0.14 / 3.1)])


def test_default_gait_clock_is_unchanged():
    """The default observation is the one with gait_period=6.1 (the paper's cycle), bit for bit."""
    a = gym.make("QuadUneven-v0", terrain="rough")
    b = gym.make("QuadUneven-v0", terrain="rough", gait_period=6.1)
    oa, _ = a.reset(seed=4)
    ob, _ = b.reset(seed=4)
    for _ in range(5):
        oa, *_ = a.step(np.full(12, 0.1))
        ob, *_ = b.step(np.full(12, 0.1))
    assert oa.tobytes() == ob.tobytes()
    sl = a.unwrapped.observation_structure["gait_clock"]
    assert oa[sl] == pytest.approx([math.sin(2 * math.pi * 0.1 / 6.1), math.cos(2 * math.pi * 0.1 / 6.1)])


# ----------------------------------------------------------------------------------------------- labels
def test_expert_label_hand_case():
    """(q_ref + tau / kp - q_home) / scale, clipped: 0.3 + 20/100 - 0.1 = 0.4 rad -> 0.8 at 0.5 rad per unit;
    0.9 + 60/100 = 1.5 rad -> clipped to 1."""
    from agents.rl.distill import expert_label

    q_ref, tau, home = np.zeros(12), np.zeros(12), np.zeros(12)
    q_ref[0], tau[0], home[0] = 0.3, 20.0, 0.1
    q_ref[1], tau[1] = 0.9, 60.0
    label = expert_label(q_ref, tau, home, kp=100.0, scale=0.5)
    assert label.dtype == np.float32 and label[0] == pytest.approx(0.8) and label[1] == 1.0
    assert np.all(label[2:] == 0.0)


def test_clipped_label_shares_per_joint_type_hand_case():
    """Two steps: step 0 has both knees of legs 0 and 1 at +-1 and a hip at 0.999 (inside), step 1 one HFE at -1:
    KFE 2 of 8 leg-steps, HFE 1 of 8, HAA 0."""
    from agents.rl.distill import clipped_label_shares

    labels = np.zeros((2, 12), np.float32)
    labels[0, 2], labels[0, 5], labels[0, 0] = 1.0, -1.0, 0.999
    labels[1, 7] = -1.0
    assert clipped_label_shares(labels) == {"HAA": 0.0, "HFE": 1 / 8, "KFE": 2 / 8}


def test_a_round_with_clipped_labels_warns_naming_the_option(tmp_path):
    """At 0.05 rad per unit the standing robot's knee labels (tau / kp alone is ~0.1 rad) sit at the bound: the
    summary's share is high and the log names --pd-action-scale; at 1 rad the same episode clips nothing."""
    from agents.rl.distill import distill

    suite = suite_from_dict(TINY, source="test")
    for scale, out in ((0.05, tmp_path / "narrow"), (1.0, tmp_path / "wide")):
        lines: list[str] = []
        summary = distill(suite, out, tiny_config(dagger_rounds=0, pd_action_scale=scale), log=lines.append)
        clipped = summary["rounds"][0]["labels_clipped"]
        warned = [line for line in lines if line.startswith("warning:")]
        if scale < 1:
            assert clipped["KFE"] > 0.5 and len(warned) == 1 and "--pd-action-scale" in warned[0]
        else:
            assert max(clipped.values()) == 0.0 and not warned


def test_labels_are_the_expert_references_and_torques_in_the_action_scale():
    """With the expert acting, the rollout's observations are those of the expert attached alone, and each label
    is (plan's joint angles + the torque the expert applied at the step's first physics step / kp - standing
    pose) / scale, computed here from the dataset recorder's torques and the plan the expert reports."""
    from agents.datasets.recorder import TorqueRecorder
    from agents.expert import ExpertConfig, ExpertPolicy
    from agents.rl.distill import RolloutJob, rollout

    cfg = tiny_config(pd_kp=150.0, pd_action_scale=0.8)
    suite = suite_from_dict(TINY, source="test")
    task = episode_tasks(suite, 1, 1000)[1]
    res = rollout(RolloutJob(task, suite.goal_distance, 0.4, cfg, 1.0, None, (0,)))
    assert res["steps"] == 20 and not res["student_acted"].any()

    env = gym.make("QuadUneven-v0", terrain=task.params | {"kind": task.kind}, gait_period=3.1, course_frame=True)
    expert = ExpertPolicy(env, ExpertConfig(recovery=False))
    rec = TorqueRecorder(expert, env.unwrapped.frame_skip)
    env.unwrapped.set_controller(rec)
    obs, _ = env.reset(seed=task.seed)
    u = env.unwrapped
    home = obs[u.observation_structure["joint_pos"]].astype(float)
    prev = u.observation_structure["prev_action"]
    keep = np.ones(obs.shape, bool)
    keep[prev] = False
    for n in range(20):
        np.testing.assert_array_equal(res["obs"][n][keep], obs[keep])
        ref, _ = expert.planned_now(float(u.data.time))
        obs, *_ = env.step(np.zeros(12))
        tau0 = rec.end_step(u.data)[0]
        want = np.clip((ref.q_joints + tau0 / 150.0 - home) / 0.8, -1, 1)
        np.testing.assert_allclose(res["labels"][n], want, atol=2e-5)
        if n > 0:  # what the student's env shows: the executed (here the expert's) previous action
            np.testing.assert_array_equal(res["obs"][n][prev], res["labels"][n - 1])
    assert np.abs(res["labels"]).max() > 0.05  # not a trivial zero label


def test_teacher_applies_the_joint_pd_servo_when_the_student_acts():
    """A student holding a constant action under the teacher moves the joints as the env's own joint_pd servo does
    (MuJoCo integrates the servo's damping implicitly, the teacher explicitly: within 2 mrad over 0.2 s)."""
    from agents.expert import ExpertConfig
    from agents.rl.distill import DaggerTeacher

    a = np.full(12, 0.05)
    kwargs = dict(terrain="flat", pd_kp=100.0, pd_kd=3.0, pd_action_scale=1.0)
    pd = gym.make("QuadUneven-v0", action_mode="joint_pd", **kwargs)
    tq = gym.make("QuadUneven-v0", **kwargs)
    teacher = DaggerTeacher(tq, ExpertConfig(recovery=False), 100.0, 3.0, 1.0)
    tq.unwrapped.set_controller(teacher)
    pd.reset(seed=2)
    tq.reset(seed=2)
    np.testing.assert_array_equal(pd.unwrapped.data.qpos, tq.unwrapped.data.qpos)
    start = pd.unwrapped.data.qpos[7:].copy()
    for _ in range(10):
        teacher.begin_step(True)
        pd.step(a)
        tq.step(a)
    np.testing.assert_allclose(tq.unwrapped.data.qpos[7:], pd.unwrapped.data.qpos[7:], atol=2e-3)
    assert np.abs(pd.unwrapped.data.qpos[7:] - start).max() > 0.02  # the joints did move
    assert np.abs(teacher.first_tau).max() > 1.0  # the expert kept computing its torques meanwhile


# ------------------------------------------------------------------------------------------ the run itself
@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    from agents.rl.distill import distill

    out = tmp_path_factory.mktemp("distill") / "run"
    summary = distill(suite_from_dict(TINY, source="test"), out, tiny_config(), log=lambda _: None)
    return out, summary


def test_a_tiny_run_writes_a_train_folder_that_evaluate_and_export_read(tiny_run, tmp_path, capsys):
    from agents.evaluation.run import evaluate
    from agents.rl.model_io import load_sb3_policy, make_model_env, read_metadata

    out, summary = tiny_run
    for name in ("model.zip", "model_obs_norm.npz", "rl_meta.json", "distill_summary.json", "distill_curve.png"):
        assert (out / name).is_file(), name
    assert [r["round"] for r in summary["rounds"]] == [0, 1]
    r0, r1 = summary["rounds"]
    assert r0["steps"] == 100 and r0["student_steps"] == 0 and r1["beta"] == 0.5
    assert 0 < r1["student_steps"] < r1["steps"] and r1["dataset"] == 100 + r1["steps"]
    assert math.isfinite(r1["label_rmse_on_policy"])
    clipped = r1["labels_clipped"]
    assert set(clipped) == {"HAA", "HFE", "KFE"} and all(0 <= v <= 1 for v in clipped.values())
    meta = read_metadata(out / "model.zip")
    assert meta["residual"] is False and meta["algo"] == "ppo" and meta["env_id"] == "QuadUneven-v0"
    assert meta["env_kwargs"] == {
        "action_mode": "joint_pd", "pd_kp": 100.0, "pd_kd": 3.0, "pd_action_scale": 1.0, "gait_period": 3.1,
        "course_frame": True,
    }  # fmt: skip
    assert policy_obs_size(out / "model.zip") == 137  # the default layout (134) + course_heading + course_lateral
    # each round's student in rounds/round_K, the last one the folder's own
    for k in (0, 1):
        assert read_metadata(out / "rounds" / f"round_{k}" / "model.zip") == meta
    last, final = policy_weights(out / "rounds" / "round_1" / "model.zip"), policy_weights(out / "model.zip")
    first = policy_weights(out / "rounds" / "round_0" / "model.zip")
    assert all(np.array_equal(last[k], final[k]) for k in final)
    assert not all(np.array_equal(first[k], final[k]) for k in final)

    # the loaded policy acts as the student did in the rollouts (numpy forward == SB3 predict)
    from agents.rl.distill import mlp_forward, policy_params

    assert meta["robot"] == "paper"
    env = make_model_env(out / "model.zip", terrain="flat")
    policy = load_sb3_policy(out / "model.zip", env, "ppo")
    obs, _ = env.reset(seed=0)
    action, _ = policy.predict(obs, deterministic=True)
    np.testing.assert_allclose(action, mlp_forward(policy_params(policy.model), policy.obs_normalizer, obs), atol=1e-5)

    suite = suite_from_dict({**TINY, "time_limit": 0.3}, source="test")
    res = evaluate(suite, str(out / "model.zip"), tmp_path / "eval", progress=False)
    assert [e["error"] for e in res["episodes"]] == [None, None]
    assert all(e["planner_calls"] is None for e in res["episodes"])  # no expert in the loop

    pytest.importorskip("onnx")
    pytest.importorskip("onnxruntime")
    assert main(["export", "--policy", str(out / "model.zip"), "--out", str(tmp_path / "s.onnx")]) == 0
    import onnxruntime as ort

    sess = ort.InferenceSession(str(tmp_path / "s.onnx"))
    got = sess.run(None, {sess.get_inputs()[0].name: obs[None].astype(np.float32)})[0][0]
    np.testing.assert_allclose(got, action, atol=1e-5)


def test_the_same_seed_gives_the_same_student(tiny_run, tmp_path):
    """Two runs with one seed: the same rollouts, losses and weights (a different seed: other weights)."""
    from agents.rl.distill import distill

    out, summary = tiny_run
    again = distill(suite_from_dict(TINY, source="test"), tmp_path / "b", tiny_config(), log=lambda _: None)
    for r, s in zip(summary["rounds"], again["rounds"], strict=True):
        for key in ("steps", "student_steps", "loss", "loss_first", "mean_distance", "label_rmse_on_policy"):
            assert r.get(key) == s.get(key), key
    a = np.load(out / "model_obs_norm.npz")["mean"]
    b = np.load(tmp_path / "b" / "model_obs_norm.npz")["mean"]
    np.testing.assert_array_equal(a, b)
    wa, wb = policy_weights(out / "model.zip"), policy_weights(tmp_path / "b" / "model.zip")
    assert wa.keys() == wb.keys() and all(np.array_equal(wa[k], wb[k]) for k in wa)
    other = distill(
        suite_from_dict(TINY, source="test"), tmp_path / "c", tiny_config(seed=4, dagger_rounds=0), log=lambda _: None
    )
    assert other["rounds"][0]["steps"] == summary["rounds"][0]["steps"]  # the expert's rollouts: no seed in them
    wc = policy_weights(tmp_path / "c" / "model.zip")
    assert not np.array_equal(wa["action_net.weight"], wc["action_net.weight"])


def test_a_stopped_run_resumes_to_the_same_student(tiny_run, tmp_path, capsys):
    """Behaviour cloning only (the budget stops it after round 0), then ``--resume``: the student, the data and the
    summary of the run that was never stopped; a resume with another option is refused naming it."""
    from agents.rl.distill import ROUND_STATE, distill

    out, summary = tiny_run
    part = tmp_path / "part"
    first = distill(suite_from_dict(TINY, source="test"), part, tiny_config(budget_min=1e-9), log=lambda _: None)
    assert [r["round"] for r in first["rounds"]] == [0] and first["stopped_by_budget"]
    assert (part / "rounds" / "round_0" / ROUND_STATE).is_file()
    suite_file = tmp_path / "tiny.yaml"
    suite_file.write_text(json.dumps(TINY))
    argv = ["distill", "--suite", str(suite_file), "--out", str(part), "--dagger-rounds", "1", "--episodes", "1",
            "--epochs", "2", "--net-arch", "16", "--resume"]  # fmt: skip
    assert main([*argv, "--seed", "4"]) == 2  # the run's seed is 3
    err = capsys.readouterr().err
    assert err.startswith("error: --resume: seed is 4 here but 3 in DIR's run") and err.count("\n") == 1
    resumed = distill(suite_from_dict(TINY, source="test"), part, tiny_config(), resume=True, log=lambda _: None)
    for r, s in zip(summary["rounds"], resumed["rounds"], strict=True):
        for key in ("steps", "student_steps", "loss", "loss_first", "mean_distance", "label_rmse_on_policy"):
            assert r.get(key) == s.get(key), key
    wa, wb = policy_weights(out / "model.zip"), policy_weights(part / "model.zip")
    assert wa.keys() == wb.keys() and all(np.array_equal(wa[k], wb[k]) for k in wa)
    with pytest.raises(ValueError, match="resume and overwrite exclude each other"):
        distill(suite_from_dict(TINY, source="test"), part, tiny_config(), resume=True, overwrite=True)
    with pytest.raises(ValueError, match="distillation's summary"):
        distill(suite_from_dict(TINY, source="test"), tmp_path / "empty", tiny_config(), resume=True)


def test_the_course_frame_is_the_students_default_and_can_be_left_out(monkeypatch, tmp_path):
    """``DistillConfig.course_frame`` (True by default) puts the env's ``course_frame`` into the student's env;
    ``--no-course-frame`` leaves it out (the env's default layout)."""
    from agents.rl import distill as module

    assert tiny_config().student_env_kwargs()["course_frame"] is True
    assert "course_frame" not in tiny_config(course_frame=False).student_env_kwargs()
    with pytest.raises(ValueError, match=r"distill\.course_frame must be True or False, got 1"):
        tiny_config(course_frame=1)
    seen = []
    monkeypatch.setattr(module, "distill", lambda suite, out, cfg, **_: seen.append(cfg) or {"wall_time_s": 0})
    assert main(["distill", "--suite", "smoke", "--out", str(tmp_path / "a"), "--no-course-frame"]) == 0
    assert main(["distill", "--suite", "smoke", "--out", str(tmp_path / "b")]) == 0
    assert [c.course_frame for c in seen] == [False, True]


def policy_obs_size(path):
    import io
    import zipfile

    import torch

    with zipfile.ZipFile(path) as z:
        state = torch.load(io.BytesIO(z.read("policy.pth")), weights_only=True)
    return state["mlp_extractor.policy_net.0.weight"].shape[1]


def policy_weights(path):
    import io
    import zipfile

    import torch

    with zipfile.ZipFile(path) as z:
        state = torch.load(io.BytesIO(z.read("policy.pth")), weights_only=True)
    return {k: v.numpy() for k, v in state.items()}


# ------------------------------------------------------------------------------------------------- CLI
@pytest.mark.parametrize(
    ("extra", "field"),
    [
        (["--dagger-rounds", "-1"], "--dagger-rounds"),
        (["--budget-min", "0"], "--budget-min"),
        (["--budget-min", "nan"], "--budget-min"),
        (["--beta-decay", "1.5"], "--beta-decay"),
        (["--pd-action-scale", "0"], "--pd-action-scale"),
        (["--pd-action-scale", "nan"], "--pd-action-scale"),
        (["--pd-action-scale", "4"], "--pd-action-scale"),
        (["--episodes", "0"], "--episodes"),
        (["--workers", "0"], "--workers"),
        (["--height-scan", "{bad"], "--height-scan"),
        (["--height-scan", '{"resolution": 0}'], "distill.height_scan.resolution"),
        (["--height-scan", '{"nope": 1}'], "nope"),
        (["--expert-config", "{bad"], "--expert-config"),
        (["--expert-config", '{"nope": 1}'], "nope"),
        (["--expert-config", '{"stride": -1}'], "stride"),
        (["--suite", "no_such_suite"], "no_such_suite"),
        (["--suite", "command"], "command or waypoints"),
        (["--net-arch", "256,,256"], "--net-arch"),
        (["--net-arch", "0"], "--net-arch"),
        (["--net-arch", "99999"], "--net-arch"),
        (["--net-arch", "-5,3"], "--net-arch"),
    ],
)
def test_bad_distill_options_exit_2_with_one_line(tmp_path, capsys, extra, field):
    argv = ["distill", "--suite", "smoke", "--out", str(tmp_path / "o"), *extra]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1 and field in err and "Traceback" not in err


def test_a_non_empty_out_is_refused(tmp_path, capsys):
    (tmp_path / "o").mkdir()
    (tmp_path / "o" / "x.txt").write_text("x")
    assert main(["distill", "--suite", "smoke", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "not empty" in err and err.count("\n") == 1
    assert json.dumps(sorted(p.name for p in (tmp_path / "o").iterdir())) == '["x.txt"]'


# ------------------------------------------------------------------------------------------ height scan
def test_the_height_scan_option_in_a_tiny_run(tmp_path):
    """Through the CLI: a 0.4 x 0.2 m height scan at 0.05 m (9 x 5 = 45 points instead of 77)
    is the student's observation (137 - 77 + 45 = 105 inputs) and is recorded for evaluate; one hidden layer of 16."""
    from agents.rl.model_io import read_metadata

    scan = {"size_x": 0.4, "size_y": 0.2, "resolution": 0.05}
    assert main([
        "distill", "--suite", _tiny_suite_file(tmp_path), "--out", str(tmp_path / "o"), "--dagger-rounds", "1",
        "--episodes", "1", "--epochs", "1", "--net-arch", "16",
        "--height-scan", json.dumps(scan),
    ]) == 0  # fmt: skip
    assert policy_obs_size(tmp_path / "o" / "model.zip") == 105
    assert read_metadata(tmp_path / "o" / "model.zip")["env_kwargs"]["height_scan"] == scan
    summary = json.loads((tmp_path / "o" / "distill_summary.json").read_text())
    assert summary["config"]["height_scan"] == scan and len(summary["rounds"]) == 2
    assert summary["config"]["net_arch"] == [16]


def _tiny_suite_file(tmp_path):
    import yaml

    path = tmp_path / "tiny.yaml"
    path.write_text(yaml.safe_dump(TINY))
    return str(path)


def test_the_rollouts_history_of_actions_is_the_executed_one():
    """With ``proprio_history``, the student sees the actions executed before (the expert's labels while it acts,
    its own where it acts): the env's own record holds the action passed to ``step``, which the teacher ignores."""
    from agents.rl.distill import RolloutJob, rollout

    cfg = tiny_config(env_kwargs={"proprio_history": 3})
    suite = suite_from_dict(TINY, source="test")
    task = episode_tasks(suite, 1, 1000)[0]
    res = rollout(RolloutJob(task, suite.goal_distance, 0.3, cfg, 1.0, None, (0,)))
    env = gym.make("QuadUneven-v0", terrain="flat", **cfg.student_env_kwargs())
    st = env.unwrapped.observation_structure
    executed = np.vstack([np.zeros((4, 12), np.float32), res["labels"]])  # zeros before the first step
    for n in range(res["steps"]):
        np.testing.assert_array_equal(res["obs"][n][st["prev_action_history"]].reshape(3, 12), executed[n : n + 3])
        np.testing.assert_array_equal(res["obs"][n][st["prev_action"]], executed[n + 3])
    assert np.abs(res["obs"][-1][st["prev_action_history"]]).max() > 0.05
