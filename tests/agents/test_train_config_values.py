"""Training configs are checked before Stable-Baselines3 sees them: every hyperparameter and policy argument with its
type and range, and the ones that depend on the budget; one line naming the field, exit code 2."""

from __future__ import annotations

import inspect
import math

import pytest
import yaml

from agents.cli import main
from agents.rl.config import TrainConfigError, default_config_path, load_train_config
from agents.rl.hyperparams import HYPERPARAMS, POLICY_KWARGS, SAC_SPECIAL


def write(tmp_path, algo: str = "ppo", **changes):
    raw = yaml.safe_load(default_config_path(algo).read_text())
    for key, value in changes.items():
        if key in ("hyperparams", "policy_kwargs"):
            raw[key] = {**raw.get(key, {}), **value}
        else:
            raw[key] = value
    path = tmp_path / "c.yaml"
    path.write_text(yaml.safe_dump(raw))
    return path


PPO_CASES = [
    # values SB3 trains with, quietly
    ({"hyperparams": {"gamma": 2}}, r"hyperparams\.gamma must be a number in \[0, 1\], got 2"),
    ({"hyperparams": {"gae_lambda": 5}}, r"hyperparams\.gae_lambda must be a number in \[0, 1\], got 5"),
    ({"hyperparams": {"clip_range": -0.2}}, r"hyperparams\.clip_range must be a number in \(0, 1\], got -0\.2"),
    ({"hyperparams": {"target_kl": -1}}, r"hyperparams\.target_kl must be a number in \(0, inf\) or null, got -1"),
    ({"hyperparams": {"max_grad_norm": -1}}, r"hyperparams\.max_grad_norm must be a number in \(0, inf\), got -1"),
    # values SB3 fails on with AssertionError, TypeError or UnboundLocalError
    ({"hyperparams": {"batch_size": 0}}, r"hyperparams\.batch_size must be an integer in \[2, inf\), got 0"),
    ({"n_envs": 1, "hyperparams": {"n_steps": 1}}, r"hyperparams\.n_steps must be an integer >= 2 with n_envs = 1"),
    ({"hyperparams": {"n_epochs": 0}}, r"hyperparams\.n_epochs must be an integer in \[1, inf\), got 0"),
    ({"hyperparams": {"learning_rate": "abc"}}, r"hyperparams\.learning_rate must be a number in .*'abc' of type str"),
    ({"hyperparams": {"n_steps": 2.5}}, r"hyperparams\.n_steps must be an integer in \[1, inf\), got 2\.5"),
    ({"hyperparams": {"normalize_advantage": "yes"}}, r"hyperparams\.normalize_advantage must be true or false"),
    # NaN and infinity from YAML (.nan, .inf)
    ({"hyperparams": {"learning_rate": math.nan}}, r"hyperparams\.learning_rate must be a number in \(0, 1\], got nan"),
    ({"hyperparams": {"ent_coef": math.inf}}, r"hyperparams\.ent_coef must be a number in \[0, inf\), got inf"),
    ({"policy_kwargs": {"log_std_init": math.nan}}, r"policy_kwargs\.log_std_init must be a number in \[-20, 2\]"),
    # arguments the trainer sets, and ones YAML cannot give
    ({"hyperparams": {"tensorboard_log": "tb"}}, r"hyperparams may not set 'tensorboard_log'"),
    ({"hyperparams": {"rollout_buffer_class": "x"}}, r"hyperparams\.rollout_buffer_class: not an SB3 PPO argument"),
    ({"policy_kwargs": {"activation_fn": "relu"}}, r"policy_kwargs\.activation_fn: not a policy argument"),
    ({"policy_kwargs": {"net_arch": [64, 0]}}, r"policy_kwargs\.net_arch must be a list of layer widths"),
    ({"policy_kwargs": {"net_arch": {"pi": [64], "qf": [64]}}}, r"policy_kwargs\.net_arch must be .*\['pi', 'vf'\]"),
    ({"policy_kwargs": {"net_arch": [True]}}, r"policy_kwargs\.net_arch must be a list of layer widths"),
    # dependent on other fields and on the budget
    ({"hyperparams": {"batch_size": 4096}}, r"hyperparams\.batch_size must be an integer in \[2, 2048\]"),
    ({"critic_warmup_steps": 300_000}, r"critic_warmup_steps must be an integer in \[0, timesteps = 200000\)"),
]


@pytest.mark.parametrize(("changes", "message"), PPO_CASES)
def test_a_bad_ppo_value_is_refused_naming_the_field(tmp_path, changes, message):
    with pytest.raises(TrainConfigError, match=f"^{message}"):
        load_train_config(write(tmp_path, **changes))


SAC_CASES = [
    ({"hyperparams": {"tau": 0}}, r"hyperparams\.tau must be a number in \(0, 1\], got 0"),
    ({"hyperparams": {"buffer_size": 0}}, r"hyperparams\.buffer_size must be an integer in \[1, inf\), got 0"),
    ({"hyperparams": {"gradient_steps": 0}}, r"hyperparams\.gradient_steps must be an integer >= 1 or -1, got 0"),
    ({"hyperparams": {"train_freq": [1, "minute"]}}, r"hyperparams\.train_freq must be an integer >= 1 or \[n, "),
    ({"hyperparams": {"ent_coef": "auto_-1"}}, r"hyperparams\.ent_coef must be a number >= 0, 'auto' or 'auto_<"),
    ({"hyperparams": {"ent_coef": -0.1}}, r"hyperparams\.ent_coef must be a number >= 0"),
    ({"hyperparams": {"target_entropy": "low"}}, r"hyperparams\.target_entropy must be a finite number or 'auto'"),
    ({"hyperparams": {"target_entropy": math.nan}}, r"hyperparams\.target_entropy must be a finite number or 'auto'"),
    ({"hyperparams": {"learning_starts": 100_000}}, r"hyperparams\.learning_starts must be an integer in \[0, time"),
    ({"hyperparams": {"n_epochs": 3}}, r"hyperparams\.n_epochs: not an SB3 SAC argument"),
    ({"policy_kwargs": {"n_critics": 0}}, r"policy_kwargs\.n_critics must be an integer in \[1, 16\], got 0"),
    ({"policy_kwargs": {"net_arch": {"pi": [64], "vf": [64]}}}, r"policy_kwargs\.net_arch must be .*\['pi', 'qf'\]"),
]


@pytest.mark.parametrize(("changes", "message"), SAC_CASES)
def test_a_bad_sac_value_is_refused_naming_the_field(tmp_path, changes, message):
    with pytest.raises(TrainConfigError, match=f"^{message}"):
        load_train_config(write(tmp_path, "sac", **changes))


@pytest.mark.parametrize(
    ("algo", "changes"),
    [
        ("ppo", {"hyperparams": {"target_kl": None, "clip_range_vf": 0.2, "gamma": 1, "learning_rate": 1}}),
        ("ppo", {"policy_kwargs": {"net_arch": {"pi": [32], "vf": [64, 64]}, "ortho_init": False}}),
        ("sac", {"hyperparams": {"train_freq": [4, "episode"], "gradient_steps": -1, "ent_coef": "auto_0.5"}}),
        ("sac", {"hyperparams": {"ent_coef": 0.0, "target_entropy": -6}, "policy_kwargs": {"net_arch": {"qf": [8]}}}),
    ],
)
def test_values_at_the_edges_of_the_ranges_are_taken(tmp_path, algo, changes):
    cfg = load_train_config(write(tmp_path, algo, **changes))
    given = {**changes.get("hyperparams", {}), **changes.get("policy_kwargs", {})}
    assert {**cfg.hyperparams, **cfg.policy_kwargs}.items() >= given.items()


def test_train_with_a_bad_config_exits_2_with_one_line_and_writes_nothing(tmp_path, capsys):
    out = tmp_path / "run"
    rc = main(["train", "--config", str(write(tmp_path, hyperparams={"gamma": 2})), "--out", str(out)])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1, err
    assert err.startswith("error: hyperparams.gamma must be a number in [0, 1], got 2")
    assert not out.exists()


@pytest.mark.parametrize("algo", ["ppo", "sac"])
def test_the_tables_name_arguments_of_the_sb3_classes_with_their_defaults(algo):
    """Every declared hyperparameter is a keyword of ``stable_baselines3.PPO``/``SAC`` with the same default, every
    policy argument one of the algorithm's policy class (the reference: SB3's own signatures)."""
    import stable_baselines3

    cls = getattr(stable_baselines3, algo.upper())
    signature = inspect.signature(cls.__init__).parameters
    for p in HYPERPARAMS[algo]:
        assert p.name in signature, p.name
        assert p.default == signature[p.name].default, p.name
    assert algo == "ppo" or all(name in signature for name in SAC_SPECIAL)
    policy = inspect.signature(cls.policy_aliases["MlpPolicy"].__init__).parameters
    for p in POLICY_KWARGS[algo]:
        assert p.name in policy, p.name
        if p.name != "log_std_init":  # its range is ours; SB3's defaults differ by algorithm (0 and -3)
            assert p.default == policy[p.name].default, p.name
