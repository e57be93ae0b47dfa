"""QuadUnevenResidual-v0: zero residual == the expert, the residual law, env checkers, argument errors."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import quad_uneven_env  # noqa: F401  (registers QuadUneven-v0)
from agents.expert import ExpertConfig, ExpertPolicy, attach_expert
from agents.rl.expert_features import EXPERT_FEATURE_SIZE
from agents.rl.residual_env import (
    RESIDUAL_ENV_ID,
    ResidualConfig,
    ResidualController,
    ResidualExpertEnv,
    install_residual_controller,
    make_residual_env,
)

STEPS = 160
"""Control steps of the trajectory comparisons (3.2 s: past the first replanning at 3.1 s)."""


def _rollout(env: gym.Env, actions: np.ndarray, seed: int) -> dict[str, np.ndarray]:
    obs, _ = env.reset(seed=seed)
    traj = {"obs": [obs], "reward": [], "qpos": [env.unwrapped.data.qpos.copy()], "ctrl": [], "done": []}
    for a in actions:
        obs, reward, terminated, truncated, _ = env.step(a)
        traj["obs"].append(obs)
        traj["reward"].append(reward)
        traj["qpos"].append(env.unwrapped.data.qpos.copy())
        traj["ctrl"].append(env.unwrapped.data.ctrl.copy())
        traj["done"].append(terminated or truncated)
        if terminated or truncated:
            break
    return {k: np.asarray(v) for k, v in traj.items()}


@pytest.mark.parametrize("distribution", ["pinv", "qp"])
def test_zero_residual_reproduces_the_expert(distribution):
    """Zero action: the residual env's trajectory equals the plain expert's, bit for bit (both force
    distributions: the QP's solver, DAQP, is deterministic); its observation starts with the plain env's."""
    cfg = ExpertConfig(distribution=distribution)
    plain = gym.make("QuadUneven-v0", terrain="rough", max_episode_steps=STEPS + 1)
    attach_expert(plain, cfg)
    residual = gym.make(RESIDUAL_ENV_ID, terrain="rough", expert=cfg, max_episode_steps=STEPS + 1)
    zeros = np.zeros((STEPS, 12), dtype=np.float32)
    a, b = _rollout(plain, zeros, seed=0), _rollout(residual, zeros, seed=0)
    if distribution == "qp":
        assert len(a["reward"]) == STEPS and a["qpos"][-1, 0] - a["qpos"][0, 0] > 0.15  # the expert walked
    else:
        # The paper's pinv distribution pulls on the ground and tips the robot over after ~2.5-3 s on
        # any terrain (docs/results.md section 7); the comparison runs until that fall.
        assert len(a["reward"]) >= 100
    n_env = a["obs"].shape[1]
    assert b["obs"].shape[1] == n_env + EXPERT_FEATURE_SIZE
    b["obs"] = b["obs"][:, :n_env]
    for key in a:
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)


def test_a_residual_changes_the_trajectory():
    """The comparison above can fail: a constant residual moves the robot away from the expert's path."""
    cfg = ExpertConfig(distribution="pinv")
    steps = 20
    zero = gym.make(RESIDUAL_ENV_ID, terrain="flat", expert=cfg)
    push = gym.make(RESIDUAL_ENV_ID, terrain="flat", expert=cfg)
    a = _rollout(zero, np.zeros((steps, 12), dtype=np.float32), seed=0)
    b = _rollout(push, np.full((steps, 12), 0.5, dtype=np.float32), seed=0)
    assert np.abs(a["qpos"][-1] - b["qpos"][-1]).max() > 1e-3


class _ConstantExpert:
    """A stub expert: fixed torques, records its calls."""

    def __init__(self, tau: np.ndarray) -> None:
        self.tau = tau
        self.resets = 0

    def reset(self, model, data, terrain) -> None:
        self.resets += 1

    def __call__(self, model, data, action) -> np.ndarray:
        return self.tau.copy()


def test_residual_law_and_clipping():
    limit = np.full(12, 120.0)
    tau_expert = np.linspace(-115.0, 115.0, 12)
    ctrl = ResidualController(_ConstantExpert(tau_expert), limit, residual_scale=0.2)
    action = np.linspace(1.0, -1.0, 12)
    expected = np.clip(tau_expert + 0.2 * action * limit, -limit, limit)
    np.testing.assert_allclose(ctrl(None, None, action), expected, rtol=0, atol=1e-12)
    assert np.abs(ctrl(None, None, np.ones(12))).max() == 120.0  # clipped to the motor limit
    np.testing.assert_array_equal(ctrl(None, None, np.zeros(12)), tau_expert)
    ctrl.reset(None, None, None)
    assert ctrl.expert.resets == 1


def _spy_on_expert(env: ResidualExpertEnv) -> list[tuple[np.ndarray, np.ndarray]]:
    """Put a spy between ``env``'s residual controller and its expert; the list it returns fills with the
    expert's torques and the feet's contact switches at every physics step."""
    seen = []

    class Spy:
        def reset(self, model, data, terrain):
            env.expert.reset(model, data, terrain)

        def __call__(self, model, data, action):
            tau = env.expert(model, data, action)
            seen.append((tau.copy(), data.sensordata[env.unwrapped.idx.foot_sensor_adr].copy()))
            return tau

    env.controller.expert = Spy()
    return seen


def test_env_applies_expert_plus_residual_torques():
    """At every physics step the motors get clip(expert + scale x action x limit): checked on the last one."""
    env = make_residual_env(residual_scale=0.15, terrain="flat")
    seen = _spy_on_expert(env)
    env.reset(seed=1)
    action = np.linspace(-1.0, 1.0, 12).astype(np.float32)
    env.step(action)
    lim = env.unwrapped.idx.torque_limit
    expected = np.clip(seen[-1][0] + 0.15 * action.astype(np.float64) * lim, -lim, lim)
    np.testing.assert_allclose(env.unwrapped.data.ctrl, expected, rtol=0, atol=1e-9)
    assert len(seen) == env.unwrapped.frame_skip


@pytest.mark.filterwarnings("ignore:.*different from the unwrapped")  # the wrapper is what we check
def test_gymnasium_env_checker():
    """Gymnasium's checker (spaces, seeding, exact determinism of a seeded reset + step), default expert."""
    from gymnasium.utils.env_checker import check_env

    env = make_residual_env(terrain="rough")
    check_env(env, skip_render_check=True)


def test_sb3_env_checker():
    from stable_baselines3.common.env_checker import check_env

    check_env(gym.make(RESIDUAL_ENV_ID, terrain="rough"), warn=True)


@pytest.mark.filterwarnings("ignore:.*different from the unwrapped")
def test_residual_env_accepts_randomization_and_passes_the_checkers():
    from gymnasium.utils.env_checker import check_env

    env = gym.make(RESIDUAL_ENV_ID, terrain="rough", randomization="mild")
    assert env.unwrapped.randomization.motor_strength == (0.8, 1.2)
    _, info = env.reset(seed=2)
    _, _, _, _, step_info = env.step(np.zeros(12, dtype=np.float32))
    assert list(step_info["randomization"]) == list(info["randomization"])
    assert step_info["randomization"]["latency_steps"] in (0.0, 1.0, 2.0)
    check_env(env.unwrapped, skip_render_check=True)
    with pytest.raises(ValueError, match=r"randomization\.friction"):
        gym.make(RESIDUAL_ENV_ID, terrain="flat", randomization={"friction": [0.0, 1.0]})


@pytest.mark.filterwarnings("ignore:.*different from the unwrapped")
def test_the_shipped_training_world_passes_both_checkers():
    """The residual wrapper itself as run 6 trains it (stance-gated, a gain on the expert's torque), on stairs in
    the extreme world: Gymnasium's checker (with its exact seeded-reset comparison) and SB3's."""
    from gymnasium.utils.env_checker import check_env
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = make_residual_env(
        terrain="stairs",
        randomization="extreme",
        residual_legs="stance",
        residual_scale=0.5,
        residual_basis="expert_torque",
    )
    assert env.unwrapped.randomization.motor_strength == (0.5, 1.3)
    check_env(env, skip_render_check=True)
    sb3_check_env(env, warn=True)


def test_registered_id_and_defaults():
    env = gym.make("agents.rl:QuadUnevenResidual-v0", terrain="flat")
    assert env.spec.max_episode_steps == 1000
    inner = env.unwrapped
    assert isinstance(inner.controller, ResidualController)
    assert inner.controller.residual_scale == pytest.approx(0.1)
    assert isinstance(env.get_wrapper_attr("expert"), ExpertPolicy)
    env.reset(seed=0)
    info = env.step(env.action_space.sample())[4]
    assert info["residual_scale"] == pytest.approx(0.1)


@pytest.mark.parametrize("scale", [0.0, -0.1, 1.5, float("nan"), "big", True])
def test_bad_residual_scale_is_rejected_by_name(scale):
    with pytest.raises(ValueError, match="residual_scale"):
        make_residual_env(residual_scale=scale, terrain="flat")


def test_residual_env_needs_torque_mode_and_no_controller():
    with pytest.raises(ValueError, match="action_mode"):
        make_residual_env(terrain="flat", action_mode="joint_pd")
    with pytest.raises(ValueError, match="controller"):
        make_residual_env(terrain="flat", controller=lambda m, d, a: np.zeros(12))
    with pytest.raises(ValueError, match="QuadUneven-v0"):
        install_residual_controller(gym.make("Pendulum-v1"))
    assert issubclass(ResidualExpertEnv, gym.Wrapper)


def test_residual_penalty_is_a_named_reward_term():
    """reward(penalty w) = reward(no penalty) - w * mean(action^2), the same trajectory otherwise."""
    action = np.linspace(-1.0, 1.0, 12).astype(np.float32)
    plain = gym.make(RESIDUAL_ENV_ID, terrain="flat")
    paid = gym.make(RESIDUAL_ENV_ID, terrain="flat", residual_penalty=2.0)
    _, info0 = paid.reset(seed=0)
    plain.reset(seed=0)
    assert info0["reward_terms"]["residual"] == 0.0 and "residual" not in plain.reset(seed=0)[1]["reward_terms"]
    for _ in range(3):
        _, r_plain, *_ = plain.step(action)
        _, r_paid, _, _, info = paid.step(action)
        want = -2.0 * float(np.mean(action.astype(float) ** 2))
        assert info["reward_terms"]["residual"] == pytest.approx(want)
        assert r_paid == pytest.approx(r_plain + want)
        assert info["residual_torque"] == pytest.approx(float(np.mean(np.abs(action) * 12.0)))
    with pytest.raises(ValueError, match=r"^ResidualConfig\.residual_penalty must be a number in \[0, inf\)"):
        gym.make(RESIDUAL_ENV_ID, terrain="flat", residual_penalty=-1.0)


class _Data:
    """Just the contact switches a stance-gated controller reads (sensordata, 7 values per foot)."""

    def __init__(self, touch: list[float]) -> None:
        self.sensordata = np.zeros(28)
        self.sensordata[[0, 7, 14, 21]] = touch


def test_stance_gated_residual_acts_only_on_legs_whose_foot_touches():
    """residual_legs="stance": leg i gets its residual only while sensordata[foot i] > 0; the reported
    residual torque is the mean of what was applied over the physics steps since the last query."""
    limit = np.full(12, 120.0)
    tau_expert = np.linspace(-30.0, 30.0, 12)
    ctrl = ResidualController(_ConstantExpert(tau_expert), limit, 0.2, "stance", [0, 7, 14, 21])
    action = np.linspace(1.0, -1.0, 12)
    full = tau_expert + 0.2 * action * limit
    got = ctrl(None, _Data([1.0, 0.0, 2.0, 0.0]), action).copy()  # LF and LH touch
    np.testing.assert_allclose(got[0:3], full[0:3], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(got[3:6], tau_expert[3:6])
    np.testing.assert_allclose(got[6:9], full[6:9], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(got[9:12], tau_expert[9:12])
    first = np.mean(np.abs(0.2 * action * limit) * np.repeat([1, 0, 1, 0], 3))
    ctrl(None, _Data([0.0, 0.0, 0.0, 0.0]), action)  # a flight phase: the expert alone
    np.testing.assert_array_equal(ctrl(None, _Data([0.0, 0.0, 0.0, 0.0]), action), tau_expert)
    assert ctrl.residual_torque(action) == pytest.approx(first / 3)
    # no physics step since the query: what the action commands on every leg
    assert ctrl.residual_torque(action) == pytest.approx(np.mean(np.abs(0.2 * action * limit)))
    with pytest.raises(ValueError, match="residual_legs must be one of"):
        ResidualController(_ConstantExpert(tau_expert), limit, 0.2, "swing")
    with pytest.raises(ValueError, match="contact sensor"):
        ResidualController(_ConstantExpert(tau_expert), limit, 0.2, "stance")


def test_stance_gated_env_equals_the_plain_residual_on_touching_legs():
    """In the env, the motors get the expert's torques plus the residual on the legs in contact at that
    physics step (checked on the last one), and zero residual still reproduces the expert exactly."""
    env = make_residual_env(residual_scale=0.2, terrain="flat", residual_legs="stance")
    seen = _spy_on_expert(env)
    env.reset(seed=1)
    action = np.linspace(-1.0, 1.0, 12).astype(np.float32)
    for _ in range(35):  # 0.7 s: RH swings (phase 1, 0.5-1.0 s)
        env.step(action)
    tau, touch = seen[-1]
    lim = env.unwrapped.idx.torque_limit
    gate = np.repeat(touch > 0, 3)
    assert 0 < gate.sum() < 12  # some leg swings, some stands: the gate is exercised
    expected = np.clip(tau + 0.2 * action.astype(np.float64) * lim * gate, -lim, lim)
    np.testing.assert_allclose(env.unwrapped.data.ctrl, expected, rtol=0, atol=1e-9)
    plain = make_residual_env(terrain="rough", expert=ExpertConfig(distribution="pinv"))
    gated = make_residual_env(terrain="rough", expert=ExpertConfig(distribution="pinv"), residual_legs="stance")
    zeros = np.zeros((40, 12), dtype=np.float32)
    np.testing.assert_array_equal(_rollout(plain, zeros, 3)["qpos"], _rollout(gated, zeros, 3)["qpos"])


def test_expert_torque_basis_is_a_gain_on_the_expert():
    """residual_basis="expert_torque": tau = tau_expert x (1 + scale x action) joint by joint (on touching legs
    with "stance"), so a zero expert torque takes no residual; the reported torque is what was applied."""
    limit = np.full(12, 120.0)
    tau_expert = np.linspace(-30.0, 30.0, 12)
    tau_expert[4] = 0.0
    action = np.linspace(1.0, -1.0, 12)
    every = ResidualController(_ConstantExpert(tau_expert), limit, 0.5, residual_basis="expert_torque")
    np.testing.assert_allclose(every(None, _Data([0.0] * 4), action), tau_expert * (1 + 0.5 * action), atol=1e-12)
    assert every.residual_torque(action) == pytest.approx(np.mean(np.abs(0.5 * action * tau_expert)))
    gated = ResidualController(_ConstantExpert(tau_expert), limit, 0.5, "stance", [0, 7, 14, 21], "expert_torque")
    got = gated(None, _Data([0.0, 1.0, 0.0, 1.0]), action).copy()  # RF and RH touch
    gate = np.repeat([0.0, 1.0, 0.0, 1.0], 3)
    np.testing.assert_allclose(got, tau_expert * (1 + 0.5 * action * gate), rtol=0, atol=1e-12)
    assert got[4] == 0.0
    big = ResidualController(_ConstantExpert(np.full(12, 100.0)), limit, 1.0, residual_basis="expert_torque")
    np.testing.assert_array_equal(big(None, _Data([0.0] * 4), np.ones(12)), limit)  # 200 N m clipped to the limit
    with pytest.raises(ValueError, match=r"residual_basis must be one of \['torque_limit', 'expert_torque'\]"):
        ResidualController(_ConstantExpert(tau_expert), limit, 0.5, residual_basis="gain")
    with pytest.raises(ValueError, match="residual_basis must be one of"):
        make_residual_env(terrain="flat", residual_basis=None)


def test_expert_torque_basis_in_the_env_scales_the_experts_motor_commands():
    """In the env (extreme world, stance legs): the motors get the expert's torques scaled on the touching legs
    at that physics step."""
    env = make_residual_env(
        residual_scale=0.5,
        terrain="rough",
        randomization="extreme",
        residual_legs="stance",
        residual_basis="expert_torque",
    )
    seen = _spy_on_expert(env)
    env.reset(seed=3)
    action = np.linspace(-1.0, 1.0, 12).astype(np.float32)
    for _ in range(300):  # until a control step ends with a leg in the air
        env.step(action)
        if 0 < np.count_nonzero(seen[-1][1] > 0) < 4:
            break
    tau, touch = seen[-1]
    lim = env.unwrapped.idx.torque_limit
    gate = np.repeat(touch > 0, 3)
    assert 0 < gate.sum() < 12
    expected = np.clip(tau * (1 + 0.5 * action.astype(np.float64) * gate), -lim, lim)
    # the env's motor model (strength, latency) acts after the controller: compare the controller's output
    np.testing.assert_allclose(env.unwrapped.controller._tau, expected, rtol=0, atol=1e-9)


@pytest.mark.parametrize("basis", ["torque_limit", "expert_torque"])
@pytest.mark.parametrize("gated", [False, True])
@pytest.mark.parametrize("adapted", [False, True])
def test_the_compiled_composition_equals_its_numpy_twin(basis, gated, adapted):
    """``residual_torques_into`` against ``residual_torques`` bit for bit, torques and the applied mean, on
    random actions, expert torques past the limits, knee gains and touch switches (zero, positive, negative)."""
    from agents.rl.residual_env import residual_torques
    from agents.rl.residual_kernels import residual_torques_into

    rng = np.random.default_rng(7)
    limit = rng.uniform(40.0, 160.0, 12)
    foot_adr = np.array([5, 2, 7, 0])
    for _ in range(300):
        action = rng.uniform(-1.0, 1.0, 12)
        action[rng.random(12) < 0.1] = 0.0
        tau_expert = rng.uniform(-1.3, 1.3, 12) * limit
        gain = rng.uniform(0.5, 2.0, 12) if adapted else np.ones(12)
        touch = rng.choice([0.0, 1.5, -0.5, 3.0], 8)
        scale = float(rng.uniform(0.05, 1.0))
        per_unit = scale * limit
        stance = touch[foot_adr] > 0.0 if gated else None
        want, want_applied = residual_torques(
            action, tau_expert, gain, per_unit, scale, basis == "expert_torque", stance, limit
        )
        out = np.full(12, np.nan)
        got_applied = residual_torques_into(
            action, tau_expert, gain, per_unit, scale, basis == "expert_torque", touch, foot_adr, gated, limit, out
        )
        np.testing.assert_array_equal(out, want)
        assert got_applied == want_applied


@pytest.mark.parametrize("n", [1, 5, 8, 12, 13, 16, 17, 100, 128])
def test_the_compiled_abs_sum_is_numpys_pairwise_sum(n):
    """The applied mean's sum, in numpy's summation order: equal to ``np.abs(x - y).sum()`` to the last bit
    (a sequential sum differs on these inputs)."""
    from agents.rl.residual_kernels import pairwise_abs_diff_sum

    rng = np.random.default_rng(n)
    differs = 0
    for _ in range(200):
        x, y = rng.normal(0.0, 10.0, n) * 10.0 ** rng.integers(-3, 4, n), rng.normal(0.0, 1.0, n)
        assert pairwise_abs_diff_sum(x, y) == np.abs(x - y).sum()
        seq = 0.0
        for v in np.abs(x - y):
            seq += v
        differs += seq != np.abs(x - y).sum()
    assert differs > 0 or n < 9


@pytest.mark.parametrize("randomization", [None, "hard"])
def test_the_residual_lane_walks_exactly_as_the_call_it_replaces(randomization, monkeypatch):
    """The residual env with ``ResidualController.torques_into`` (through the expert's lane) against the same env
    with it removed: the same torques, trajectory, observations and applied residual (``info["residual_torque"]``)
    bit for bit, under random residual actions, over the expert with the adaptive knee gains and stance gating, in
    the nominal world and in a randomized one (where the expert steps its own model's copy)."""
    runs = []
    for lane in (True, False):
        env = make_residual_env(
            residual_scale=0.5, terrain="rough", residual_legs="stance", residual_basis="expert_torque",
            expert=ExpertConfig(adaptation="knee"), randomization=randomization,
        )  # fmt: skip
        answers = []
        real = ResidualController.torques_into

        def counted(self, *args, _real=real, _answers=answers, _on=lane):
            done = _real(self, *args) if _on else False
            _answers.append(done)
            return done

        monkeypatch.setattr(ResidualController, "torques_into", counted)
        rng = np.random.default_rng(3)
        obs, _ = env.reset(seed=2)
        d = env.unwrapped.data
        trace = []
        for _ in range(120):
            obs, _, terminated, truncated, info = env.step(rng.uniform(-0.4, 0.4, 12))
            trace.append((d.qpos.copy(), d.ctrl.copy(), obs.copy(), info["residual_torque"]))
            if terminated or truncated:
                break
        runs.append((trace, answers))
        monkeypatch.undo()
    (with_lane, answers), (without, _) = runs
    assert len(with_lane) == len(without) >= 60
    for (q1, u1, o1, r1), (q2, u2, o2, r2) in zip(with_lane, without, strict=True):
        np.testing.assert_array_equal(q1, q2)
        np.testing.assert_array_equal(u1, u2)
        np.testing.assert_array_equal(o1, o2)
        assert r1 == r2
    assert all(answers) and len(answers) == len(with_lane) * env.unwrapped.frame_skip


@pytest.mark.parametrize(
    ("field", "value", "allowed"),
    [
        ("residual_scale", 0.0, r"a number in \(0, 1\]"),
        ("residual_scale", "big", r"a number in \(0, 1\]"),
        ("residual_legs", "swing", r"one of \['all', 'stance'\]"),
        ("residual_basis", None, r"one of \['torque_limit', 'expert_torque'\]"),
        ("expert_features", "yes", "true or false"),
        ("residual_penalty", float("inf"), r"a number in \[0, inf\)"),
        ("expert", {"adaptation": "hips"}, None),
    ],
)
def test_a_bad_residual_config_field_is_refused_by_name(field, value, allowed):
    """ResidualConfig (and the env built from it, and a mapping of its fields) names the bad field and what it
    allows; a mapping's expert names the expert's field."""
    if field == "expert":
        with pytest.raises(ValueError, match=r"^ResidualConfig\.expert must be an ExpertConfig"):
            ResidualConfig(expert=value)
        with pytest.raises(ValueError, match=r"^ResidualConfig\.expert\.adaptation must be one of"):
            ResidualConfig.from_dict({"expert": value})
        return
    message = rf"^ResidualConfig\.{field} must be {allowed}"
    with pytest.raises(ValueError, match=message):
        ResidualConfig(**{field: value})
    with pytest.raises(ValueError, match=message):
        ResidualConfig.from_dict({field: value})
    with pytest.raises(ValueError, match=message):
        make_residual_env(terrain="flat", **{field: value})


def test_the_residual_config_round_trips_and_travels_as_one_object():
    """to_dict / from_dict give back the same frozen config (the expert as its fields that differ from the
    defaults); the env takes it whole, or its fields as keywords, never both; a misspelt field is refused."""
    import dataclasses
    import json

    from agents.control.controller import Gains

    expert = ExpertConfig(adaptation="learned", friction=0.6, durations=(0.4,) * 3 + (0.1,) + (0.4,) * 3,
                          gains=Gains(kp_joint=800.0))  # fmt: skip
    cfg = ResidualConfig(residual_scale=0.3, residual_legs="stance", residual_basis="expert_torque",
                         expert_features=False, residual_penalty=0.5, expert=expert)  # fmt: skip
    raw = json.loads(json.dumps(cfg.to_dict()))
    assert raw["expert"] == {
        "durations": [0.4, 0.4, 0.4, 0.1, 0.4, 0.4, 0.4], "gains": {**dataclasses.asdict(Gains()), "kp_joint": 800.0},
        "friction": 0.6, "adaptation": "learned",
    }  # fmt: skip
    assert ResidualConfig.from_dict(raw) == cfg
    assert ResidualConfig().to_dict()["expert"] == {}
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.residual_scale = 0.2  # type: ignore[misc]
    env = make_residual_env(config=cfg, terrain="flat")
    assert env.config is cfg and env.expert.config is expert and env.controller.residual_legs == "stance"
    assert not env.expert_features and env.residual_penalty == 0.5
    assert make_residual_env(config=raw, terrain="flat").config == cfg
    with pytest.raises(ValueError, match="in config or as keywords, not both"):
        make_residual_env(config=cfg, residual_scale=0.2, terrain="flat")
    with pytest.raises(ValueError, match=r"^ResidualConfig: unknown field\(s\) \['residual_scal'\]"):
        ResidualConfig.from_dict({"residual_scal": 0.2})
