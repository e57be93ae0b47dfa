"""The learned strength estimator: its statistics by hand, its fit, its file, its adaptation law on a synthetic
joint, and in the expert (``ExpertConfig(adaptation="learned")``)."""

from __future__ import annotations

import numpy as np
import pytest

from agents.control.adaptation import learned as SE
from agents.control.adaptation.knee import GAIN_BOUNDS, START_TIME
from agents.rl.strength_fit import fit_estimator

F = len(SE.FEATURE_NAMES)


def _ema_by_hand(xs: np.ndarray, w: float) -> np.ndarray:
    """Bias-corrected exponential mean of the rows of ``xs``: sum_i w (1-w)^(n-1-i) x_i / (1 - (1-w)^n)."""
    n = len(xs)
    weights = w * (1.0 - w) ** np.arange(n - 1, -1, -1)
    return weights @ xs / (1.0 - (1.0 - w) ** n)


def test_the_statistics_are_bias_corrected_exponential_means_by_hand():
    rng = np.random.default_rng(0)
    stats = SE.JointStatistics(period=0.02)
    e, u = rng.normal(0, 0.05, (30, 12)), rng.normal(0.1, 0.3, (30, 12))
    for k in range(30):
        stats.update(e[k], u[k])
    got = stats.features()
    assert got.shape == (12, F)
    for t in SE.TIME_CONSTANTS:
        w = 0.02 / t
        uu, ue = _ema_by_hand(u * u, w), _ema_by_hand(u * e, w)
        expected = {
            "slope": ue / (uu + 1e-4), "mean_e": _ema_by_hand(e, w), "mean_u": _ema_by_hand(u, w),
            "rms_u": np.sqrt(uu), "rms_e": np.sqrt(_ema_by_hand(e * e, w)),
        }  # fmt: skip
        for name, value in expected.items():
            np.testing.assert_allclose(got[:, SE.FEATURE_NAMES.index(f"{name}_{t:g}s")], value, rtol=1e-12)
    stats.reset()
    stats.update(e[0], u[0])  # one sample: every mean is that sample, whatever the time constant
    np.testing.assert_allclose(stats.features()[:, SE.FEATURE_NAMES.index("mean_u_2s")], u[0], rtol=1e-12)


def test_the_fit_learns_a_nonlinear_map_and_numpy_runs_it_as_torch_does():
    """Synthetic data with a known map that differs by joint kind; the fitted MLP predicts held-out samples, and
    its numpy forward pass equals the same layers run by torch."""
    import torch

    rng = np.random.default_rng(1)
    x = rng.normal(size=(4000, F)) * rng.uniform(0.01, 2.0, F)
    kind = rng.integers(0, 3, 4000)
    z = x / x.std(axis=0)
    y = np.tanh(z[:, 0]) * np.array([0.3, -0.2, 0.5])[kind] + 0.1 * z[:, 3] + np.array([0.0, 0.1, -0.1])[kind]
    est = fit_estimator(x[:3000], y[:3000], kind[:3000], epochs=150)
    pred = est.predict_kind(x[3000:], kind[3000:])
    assert np.sqrt(np.mean((pred - y[3000:]) ** 2)) < 0.2 * y.std()  # a linear map: 0.73 (the sign flips by kind)
    layers = []
    for i, (w, b) in enumerate(zip(est.weights, est.biases, strict=True)):
        lin = torch.nn.Linear(*w.shape).double()
        lin.weight.data, lin.bias.data = torch.from_numpy(w.T.copy()), torch.from_numpy(b.copy())
        layers += [lin] + ([torch.nn.Tanh()] if i < len(est.weights) - 1 else [])
    inputs = np.concatenate([(x[3000:] - est.mean) / est.scale, np.eye(3)[kind[3000:]]], axis=1)
    with torch.no_grad():
        reference = torch.nn.Sequential(*layers)(torch.from_numpy(inputs))[:, 0].numpy()
    np.testing.assert_allclose(pred, reference, rtol=1e-10, atol=1e-12)
    twelve = x[:12]  # predict() takes one row per joint, the joint's kind from its index
    np.testing.assert_allclose(est.predict(twelve), est.predict_kind(twelve, SE.JOINT_KIND), rtol=1e-12)
    with pytest.raises(ValueError, match="too few"):
        fit_estimator(x[:20], y[:20], kind[:20])


def _estimator(weights: np.ndarray, bias: float = 0.0) -> SE.StrengthEstimator:
    """A linear estimator (one layer): ``weights`` (F,) on the raw features, the same for every joint kind."""
    layer = np.concatenate([weights, np.zeros(3)])[:, None]
    return SE.StrengthEstimator(np.zeros(F), np.ones(F), (layer,), (np.array([bias]),))


def test_the_file_round_trips_and_bad_files_are_named(tmp_path):
    est = _estimator(np.linspace(-1, 1, F), 0.25)
    est.save(tmp_path / "e.npz")
    back = SE.StrengthEstimator.load(tmp_path / "e.npz")
    np.testing.assert_array_equal(back.mean, est.mean)
    np.testing.assert_array_equal(back.weights[0], est.weights[0])
    np.testing.assert_array_equal(back.biases[0], est.biases[0])
    np.savez(tmp_path / "names.npz", mean=est.mean, scale=est.scale, w0=est.weights[0], b0=est.biases[0],
             feature_names=np.array(["slope_0.5s"] * F))  # fmt: skip
    with pytest.raises(ValueError, match="feature_names must be"):
        SE.StrengthEstimator.load(tmp_path / "names.npz")
    np.savez(tmp_path / "pickle.npz", mean=np.array([{"a": 1}], dtype=object))
    with pytest.raises(ValueError, match="not a strength estimator"):
        SE.StrengthEstimator.load(tmp_path / "pickle.npz")
    with pytest.raises(ValueError, match="not a strength estimator"):
        SE.StrengthEstimator.load(tmp_path / "missing.npz")
    with pytest.raises(ValueError, match="layer 0 must be finite"):
        SE.StrengthEstimator(est.mean, est.scale, (np.full((F + 3, 1), np.nan),), est.biases)
    with pytest.raises(ValueError, match="layer 0 must map"):
        SE.StrengthEstimator(est.mean, est.scale, (np.ones((F, 1)),), est.biases)
    with pytest.raises(ValueError, match="one output"):
        SE.StrengthEstimator(est.mean, est.scale, (np.ones((F + 3, 2)),), (np.zeros(2),))
    with pytest.raises(ValueError, match="scale must be positive"):
        SE.StrengthEstimator(est.mean, np.zeros(F), est.weights, est.biases)


def test_the_shipped_estimator_loads_and_reads_a_weak_knee_as_weak():
    """The shipped fit: a knee whose error follows its load (a sag) reads weaker than one tracking as well
    under the same load (statistics of a synthetic joint, e = c (1 - s) u)."""
    est = SE.StrengthEstimator.load()
    reads = []
    for strength in (0.5, 1.0):
        stats = SE.JointStatistics(period=0.02)
        for k in range(200):
            u = np.full(12, 0.3 * np.sin(2 * np.pi * k * 0.02 / 1.1) + 0.3)
            stats.update(0.3 * (1.0 - strength) * u, u)
        reads.append(est.predict(stats.features())[2])
    assert reads[0] < reads[1]


def test_the_law_settles_every_joint_at_one_over_its_strength():
    """A synthetic joint whose sag follows its unmet load, e = c (1 - s g) u, and an estimator that reads
    log(s g) ~ s g - 1 = -slope / c off the short window's slope: every gain settles at 1/s (within the bounds)."""
    c = 3.0
    weights = np.zeros(F)
    weights[SE.FEATURE_NAMES.index("slope_0.5s")] = -1.0 / c
    law = SE.LearnedGainAdaptation(period=0.02, estimator=_estimator(weights))
    strength = np.linspace(0.55, 1.3, 12)
    for k in range(1500):  # 30 s
        u = np.full(12, 0.4 * np.sin(2 * np.pi * k * 0.02 / 1.1) + 0.2)
        law.update(c * (1.0 - strength * law.gain) * u, u, time_since_reset=k * 0.02)
        if k * 0.02 < START_TIME + SE.WARMUP:
            assert np.all(law.gain == 1.0)  # statistics first, then the gains move
    np.testing.assert_allclose(law.gain, 1.0 / strength, rtol=0.03)
    assert np.all((law.gain >= GAIN_BOUNDS[0]) & (law.gain <= GAIN_BOUNDS[1]))
    law.reset()
    assert np.all(law.gain == 1.0) and law.stats.count == 0


@pytest.mark.filterwarnings("ignore:.*different from the unwrapped")
def test_the_learned_adaptation_in_the_expert_raises_the_weak_knee_and_the_residual_env_passes_both_checkers():
    """Extreme world, the shipped estimator: after 3 s the expert's weakest knee carries the largest knee gain,
    above 1 (seed 201's knees: 0.83, 0.95, 1.30, 0.61); the residual env over that expert passes Gymnasium's and
    SB3's checkers."""
    import gymnasium as gym
    from gymnasium.utils.env_checker import check_env
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    from agents.expert import ExpertConfig, attach_expert
    from agents.rl.residual_env import make_residual_env

    env = gym.make("QuadUneven-v0", terrain="rough", randomization="extreme")
    expert = attach_expert(env, ExpertConfig(adaptation="learned"))
    env.reset(seed=201)
    assert isinstance(expert.adaptation.law, SE.LearnedGainAdaptation)
    knees = np.arange(2, 12, 3)
    strength = env.unwrapped.episode_draw.motor_strength[knees]
    for _ in range(150):
        *_, terminated, _, _ = env.step(np.zeros(12, dtype=np.float32))
        assert not terminated
    gain = expert.adaptation.gain
    assert np.argmax(gain[knees]) == np.argmin(strength)
    assert gain[knees][np.argmin(strength)] > 1.1
    residual = make_residual_env(
        terrain="rough", randomization="extreme", residual_scale=0.5, residual_legs="stance",
        residual_basis="expert_torque", expert=ExpertConfig(adaptation="learned"),
    )  # fmt: skip
    check_env(residual, skip_render_check=True)
    sb3_check_env(residual, warn=True)


def test_one_collected_episode_pairs_statistics_with_the_drawn_strengths():
    """The data collection: the features of the episode's control steps and the targets log(s g m0 / m) of its
    world, with gains inside the adaptation's bounds."""
    import gymnasium as gym

    from agents.rl.strength_fit import ENTRIES, collect_episode

    features, target = collect_episode(("rough", 1000, 2.5))
    assert features.shape == (round((2.5 - START_TIME - SE.WARMUP) / 0.02 / 5), 12, F)
    assert np.all(np.isfinite(features))
    env = gym.make("QuadUneven-v0", terrain=ENTRIES["rough"], randomization="extreme")
    nominal_mass = env.unwrapped.model.body_subtreemass[env.unwrapped.idx.trunk_body]
    env.reset(seed=1000)
    draw = env.unwrapped.episode_draw
    assert nominal_mass == pytest.approx(50.0) and draw.total_mass > nominal_mass  # seed 1000 carries a payload
    gain = np.exp(target) * (draw.total_mass / nominal_mass) / draw.motor_strength
    assert np.all((gain >= GAIN_BOUNDS[0] - 1e-9) & (gain <= GAIN_BOUNDS[1] + 1e-9))
    assert np.abs(np.log(gain)).max() > 0.05  # gains were drawn, not left at 1


def test_a_training_run_records_the_estimator_it_adapts_with():
    from agents.rl.config import load_train_config
    from agents.rl.training import _metadata

    meta = _metadata(load_train_config(None, {"expert": {"adaptation": "learned"}}), "paper")
    assert meta["expert"] == {"adaptation": "learned"}
    assert meta["strength_estimator_sha256"] == SE.estimator_digest() and len(meta["strength_estimator_sha256"]) == 64
    assert "strength_estimator_sha256" not in _metadata(
        load_train_config(None, {"expert": {"adaptation": "knee"}}), "paper"
    )


def test_the_estimator_ships_as_package_data():
    """The default estimator is the package's ``data/strength_estimator.npz``, declared as package data."""
    from pathlib import Path

    assert SE.DEFAULT_ESTIMATOR == Path(SE.__file__).parent / "data" / "strength_estimator.npz"
    assert SE.DEFAULT_ESTIMATOR.is_file()
    pyproject = (Path(__file__).resolve().parents[2] / "pyproject.toml").read_text()
    assert '"agents.control.adaptation" = ["data/*.npz"]' in pyproject


def test_the_fit_command_refits_saved_samples_and_names_bad_options(tmp_path, capsys):
    """``quad-uneven fit-strength --from-data``: a fitted file, its report and figure; bad options exit 2, one line."""
    from agents.cli import main

    rng = np.random.default_rng(2)
    x = rng.normal(size=(3000, F))
    kind = rng.integers(0, 3, 3000)
    samples = {"features": x, "target": 0.2 * np.tanh(x[:, 0]) + 0.05 * kind, "kind": kind,
               "test": rng.random(3000) < 0.2, "episode": rng.integers(0, 50, 3000)}  # fmt: skip
    np.savez(tmp_path / "samples.npz", **samples)
    out, plot = tmp_path / "est.npz", tmp_path / "fit.png"
    code = main(["fit-strength", "--from-data", str(tmp_path / "samples.npz"), "--out", str(out), "--plot", str(plot)])
    assert code == 0 and plot.stat().st_size > 0
    report = capsys.readouterr().out
    assert '"held-out corr(estimate, target)"' in report and "KFE" in report
    est = SE.StrengthEstimator.load(out)
    assert np.corrcoef(est.predict_kind(x, kind), samples["target"])[0, 1] > 0.9
    for argv, field in (
        (["--seeds", "9-3"], "--seeds must be FIRST-LAST"),
        (["--workers", "0"], "workers must be >= 1"),
        (["--from-data", str(tmp_path / "missing.npz")], "--from-data"),
    ):
        assert main(["fit-strength", "--out", str(out), *argv]) == 2
        err = capsys.readouterr().err
        assert field in err and len(err.strip().splitlines()) == 1
