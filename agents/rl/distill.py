"""``quad-uneven distill``: a network policy distilled from the scripted expert (behaviour cloning, then DAgger).

The student acts at the env's rate (50 Hz) in ``action_mode="joint_pd"``: its action is a joint target
``q_home + pd_action_scale x a`` that PD servos track at physics rate. It observes ``QuadUneven-v0``'s own
observation with the gait clock's period set to the expert's cycle (``gait_period`` = the sum of
``ExpertConfig.durations``, 3.1 s by default) and, with ``course_frame`` (the default), the trunk's heading and
sideways offset on the course (the env's ``course_frame`` fields): no planner state. The expert without a command
plans every cycle at yaw 0 and tracks its plan's base pose, so it turns a heading error back to the course's +x axis;
without these fields the student cannot see that error.

**Labels.** A PD servo cannot follow the plan's joint angles alone: the stance legs carry the robot's weight, and
at ``pd_kp`` = 100 N m/rad a 40 N m knee torque costs 0.4 rad of sag (docs/rl.md has what that does to a walk).
The label folds the expert's torque into the target::

    label = clip((q_ref(t) + tau_expert(t) / pd_kp - q_home) / pd_action_scale, -1, 1)

with ``q_ref`` the plan's joint angles at the observation's time and ``tau_expert`` the expert's joint torques
(N m) at the observed state (its first physics step of the control step). Held over the step, the servo then
applies the expert's torque plus a PD pull towards the plan (docs/rl.md: how the expert choosing these targets
walks).

**Rollouts.** The env runs in ``action_mode="torque"`` with :class:`DaggerTeacher` as its physics-rate controller:
at every physics step it runs the expert's hook (so the expert's plan and state follow the robot, whoever acts)
and applies either the expert's torques or the student's PD torques, ``kp (target - q) - kd qd``, the servo of
``joint_pd`` (which MuJoCo integrates with implicit damping; the difference is one explicit 2 ms damping step).
Round 0 is behaviour cloning (the expert acts); in DAgger round k the student acts at each control step with
probability ``1 - beta_decay ** k`` and the expert labels every visited state. The expert used as the teacher
replans only at its cycle ends (``recovery=False`` by default): a replan within the cycle would restart the plan's
phase away from the student's clock.

The student is SB3's PPO ``ActorCriticPolicy`` (only its mean-action path is trained, by mean squared error on
the aggregated labels), written as a ``quad-uneven train`` folder: ``model.zip``, ``model_obs_norm.npz``,
``rl_meta.json``; ``quad-uneven evaluate``, ``export`` and ``train --init-from`` read it unchanged.
"""

from __future__ import annotations

import collections
import concurrent.futures
import dataclasses
import json
import math
import multiprocessing
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np
from tqdm.auto import tqdm

from agents.evaluation.ray_backend import check_backend, map_on_ray
from agents.evaluation.run import suite_episodes
from agents.evaluation.suites import EpisodeTask, Suite
from agents.expert import ExpertConfig, ExpertPolicy
from agents.outputs import output_dir
from agents.rl.model_io import write_metadata
from agents.rl.normalization import ObsNormalization, norm_path
from quad_uneven_env import constants as C
from quad_uneven_env.fields import excerpt

STUDENT_ENV_FIELDS = ("action_mode", "pd_kp", "pd_kd", "pd_action_scale", "gait_period", "course_frame", "height_scan")
"""``QuadUneven-v0`` arguments of the student's env that :class:`DistillConfig`'s own fields set."""

DISTILL_OUTPUTS = (
    "model.zip", "model_obs_norm.npz", "rl_meta.json", "distill_summary.json", "distill_curve.png", "rounds",
)  # fmt: skip
"""Top-level names ``distill`` writes in its ``--out`` (``--overwrite`` deletes what the manifest lists)."""

NORM_EPSILON = 1e-8
"""``epsilon`` of the saved observation statistics."""

NORM_CLIP = 10.0
"""Normalised observations are clipped to [-10, 10] (SB3's ``VecNormalize`` default)."""

MIN_OBS_VAR = 1e-4
"""Floor of the saved per-entry variance (an entry constant in the data would otherwise scale by 1e4)."""


@dataclasses.dataclass(frozen=True)
class DistillConfig:
    """Settings of a distillation run (units in each field's docstring)."""

    dagger_rounds: int = 3
    """DAgger rounds after behaviour cloning (0: behaviour cloning only)."""
    beta_decay: float = 0.5
    """the expert acts at a control step of DAgger round k with probability beta_decay ** k."""
    episodes: int | None = 2
    """episodes per suite entry per round (the entry's first seeds; None: all)."""
    seed_offset: int = 1000
    """added to the suite's seeds in every rollout: the suite's own seeds stay held out for ``evaluate``."""
    epochs: int = 20
    """passes over the aggregated data after each round."""
    batch_size: int = 512
    """samples per gradient step."""
    learning_rate: float = 1e-3
    """Adam's step size."""
    net_arch: tuple[int, ...] = (256, 256)
    """hidden layer sizes of the policy (and of the untrained value) network."""
    log_std_init: float = -1.0
    """initial log standard deviation of the Gaussian policy (for a PPO fine-tuning; unused by the labels)."""
    pd_kp: float | None = None
    """N m/rad, the student's servo stiffness (``joint_pd``'s ``pd_kp``; None: the robot's default, 100 for the
    paper robot: :func:`quad_uneven_env.env_config.default_pd_gains`)."""
    pd_kd: float | None = None
    """N m s/rad, the student's servo damping (``pd_kd``; None: the robot's default, 3 for the paper robot)."""
    pd_action_scale: float = 1.0
    """rad per unit of action (``pd_action_scale``). A label beyond [-1, 1] is clipped and the servo cannot apply
    the expert's torque: each round reports the share of clipped labels per joint type (``labels_clipped``). The
    paper robot's labels stay within [-1, 1] at 1.0; Go1's knees need 2.0."""
    gait_period: float | None = None
    """s, the observation's gait clock (None: the teacher expert's cycle, the sum of its ``durations``)."""
    course_frame: bool = True
    """the student observes its heading and sideways offset on the course (the env's ``course_frame``)."""
    height_scan: dict[str, float] | None = None
    """the student env's ``height_scan`` grid (``size_x``, ``size_y``, ``resolution``, m; None: the env's default,
    1.0 x 0.6 m at 0.1 m)."""
    expert: dict[str, Any] = dataclasses.field(default_factory=lambda: {"recovery": False})
    """the teacher's :class:`agents.expert.ExpertConfig` fields (over :meth:`ExpertConfig.for_robot` of the robot)."""
    env_kwargs: dict[str, Any] = dataclasses.field(default_factory=dict)
    """extra ``QuadUneven-v0`` arguments of the student's and the rollouts' env, e.g. ``{"robot": "go1"}`` (the
    robot the student learns on; not the fields this config sets: :data:`STUDENT_ENV_FIELDS`)."""
    seed: int = 0
    """seed of the network's initialisation, the minibatches and the expert/student draws."""
    budget_min: float = 60.0
    """minutes of wall-clock time: no round starts after it (the model of the last finished round is kept)."""
    workers: int = 1
    """rollout processes, or the CPUs of a local Ray with ``backend="ray"`` (the result does not depend on it)."""
    backend: str = "pool"
    """where the rollouts run: ``"pool"`` (processes here) or ``"ray"`` (one Ray task per episode; the same result)."""
    address: str | None = None
    """the Ray cluster to join (``backend="ray"``; None: the running session, else a local Ray)."""
    ship_code: bool = False
    """a Ray session started here uploads this source tree to its workers."""

    def __post_init__(self) -> None:
        checks = (
            ("dagger_rounds", self.dagger_rounds >= 0, "an integer >= 0"),
            ("beta_decay", 0.0 <= self.beta_decay <= 1.0, "in [0, 1]"),
            ("episodes", self.episodes is None or self.episodes >= 1, "None or an integer >= 1"),
            ("seed_offset", self.seed_offset >= 0, "an integer >= 0"),
            ("epochs", self.epochs >= 1, "an integer >= 1"),
            ("batch_size", self.batch_size >= 1, "an integer >= 1"),
            ("learning_rate", self.learning_rate > 0, "a number > 0"),
            ("net_arch", len(self.net_arch) >= 1 and all(n >= 1 for n in self.net_arch), "sizes >= 1"),
            ("pd_kp", self.pd_kp is None or self.pd_kp > 0, "None or a number > 0 (N m/rad)"),
            ("pd_kd", self.pd_kd is None or self.pd_kd >= 0, "None or a number >= 0 (N m s/rad)"),
            ("pd_action_scale", 0 < self.pd_action_scale <= math.pi, "in (0, pi] (rad)"),
            ("gait_period", self.gait_period is None or self.gait_period > 0, "None or a number > 0 (s)"),
            ("course_frame", isinstance(self.course_frame, bool), "True or False"),
            ("budget_min", self.budget_min > 0, "a number > 0 (min)"),
            ("workers", self.workers >= 1, "an integer >= 1"),
            ("env_kwargs", isinstance(self.env_kwargs, dict), "a mapping of QuadUneven-v0 arguments"),
        )
        for name, ok, allowed in checks:
            if not ok:
                raise ValueError(f"distill.{name} must be {allowed}, got {excerpt(getattr(self, name))}")
        if self.height_scan is not None:
            from quad_uneven_env.config import HeightScanConfig
            from quad_uneven_env.fields import from_mapping

            from_mapping(HeightScanConfig, self.height_scan, "distill.height_scan")  # its errors name the field
        taken = sorted(set(self.env_kwargs) & {*STUDENT_ENV_FIELDS, "terrain", "randomization"})
        if taken:
            raise ValueError(
                f"distill.env_kwargs must not set {taken}: the distill options set the student's "
                f"{list(STUDENT_ENV_FIELDS)}, the suite its terrain and randomization"
            )
        check_backend(self.backend, self.address, self.ship_code)

    def robot(self) -> Any:
        """The :class:`~quad_uneven_env.robot.description.RobotDescription` of ``env_kwargs["robot"]`` (default: the
        paper's); :raises ValueError: naming ``distill.env_kwargs.robot`` if it cannot be loaded."""
        from quad_uneven_env.robot.description import load_robot

        try:
            return load_robot(self.env_kwargs.get("robot", "paper"))
        except (ValueError, TypeError) as err:
            raise ValueError(f"distill.env_kwargs.robot: {err}") from None

    def expert_config(self) -> ExpertConfig:
        """The teacher's :class:`ExpertConfig`: :meth:`ExpertConfig.for_robot` of :meth:`robot` with :attr:`expert`
        over it (its fields checked, the error naming the field)."""
        return ExpertConfig.for_robot(self.robot(), self.expert)

    def clock_period(self) -> float:
        """s: the observation's gait clock period."""
        return float(self.gait_period or sum(self.expert_config().durations))

    def servo_gains(self) -> tuple[float, float]:
        """(N m/rad, N m s/rad): the student's servo stiffness and damping, the robot's defaults where not given."""
        from quad_uneven_env.env_config import default_pd_gains

        kp, kd = default_pd_gains(self.robot())
        return (kp if self.pd_kp is None else self.pd_kp), (kd if self.pd_kd is None else self.pd_kd)

    def student_env_kwargs(self) -> dict[str, Any]:
        """The ``QuadUneven-v0`` arguments the student acts with (recorded in ``rl_meta.json``)."""
        kp, kd = self.servo_gains()
        return {
            **self.env_kwargs,
            "action_mode": "joint_pd",
            "pd_kp": kp,
            "pd_kd": kd,
            "pd_action_scale": self.pd_action_scale,
            "gait_period": self.clock_period(),
            **({"course_frame": True} if self.course_frame else {}),
            **({"height_scan": dict(self.height_scan)} if self.height_scan is not None else {}),
        }


# ------------------------------------------------------------------------------------------------- labels
CLIPPED_LABELS_WARN = 0.01
"""Share of a joint type's labels clipped to +-1 above which a round warns (raise ``pd_action_scale``)."""


def clipped_label_shares(labels: np.ndarray) -> dict[str, float]:
    """The share of ``labels`` (N, 12) at the action bound (|label| >= 1 - 1e-6), per joint type (HAA, HFE, KFE)."""
    at_bound = np.abs(np.asarray(labels).reshape(-1, C.N_LEGS, C.N_LEG_JOINTS)) >= 1.0 - 1e-6
    return {kind: float(at_bound[:, :, i].mean()) if len(at_bound) else 0.0 for i, kind in enumerate(C.JOINT_KINDS)}


def expert_label(q_ref: np.ndarray, tau: np.ndarray, q_home: np.ndarray, kp: float, scale: float) -> np.ndarray:
    """The ``joint_pd`` action that stands for the expert: ``clip((q_ref + tau / kp - q_home) / scale, -1, 1)``.

    :param q_ref: (12,) rad, the plan's joint angles.
    :param tau: (12,) N m, the expert's joint torques at the observed state.
    :param q_home: (12,) rad, the env's standing pose of the episode (``joint_pd``'s zero action).
    :param kp: N m/rad, the servo stiffness.
    :param scale: rad per unit of action.
    :return: (12,) float32 in [-1, 1].
    """
    return np.clip((np.asarray(q_ref) + np.asarray(tau) / kp - q_home) / scale, -1.0, 1.0).astype(np.float32)


class DaggerTeacher:
    """A physics-rate controller (:class:`quad_uneven_env.env.PhysicsController`) for an env in
    ``action_mode="torque"``: the expert's hook runs at every physics step; the torques applied are the expert's,
    or, while :attr:`student_acts`, the ``joint_pd`` servo's towards the action.

    :param env: the env (wrapped or not) it is installed on.
    :param expert_config: the teacher's settings.
    :param kp: N m/rad, servo stiffness.
    :param kd: N m s/rad, servo damping.
    :param scale: rad per unit of action.
    """

    def __init__(self, env: gym.Env, expert_config: ExpertConfig, kp: float, kd: float, scale: float) -> None:
        self.env = env.unwrapped
        self.expert = ExpertPolicy(env, expert_config)
        """the teacher (held as ``.expert``: the env's reset reaches it through :meth:`reset`)."""
        self.kp, self.kd, self.scale = kp, kd, scale
        self.student_acts = False
        """apply the servo's torques (True) or the expert's (False) during the coming control step."""
        self.first_tau = np.zeros(C.N_JOINTS)
        """(12,) N m: the expert's torques at the first physics step of the last control step (its observed state)."""
        self._tau = np.zeros(C.N_JOINTS)
        self._first = True

    def begin_step(self, student_acts: bool) -> None:
        """Say who acts in the coming control step; the next physics step's expert torques go to :attr:`first_tau`."""
        self.student_acts = bool(student_acts)
        self._first = True

    def reset(self, model: mujoco.MjModel, data: mujoco.MjData, terrain: Any) -> None:
        """Called by the env at every reset: the expert plans its first cycle."""
        self.expert.reset(model, data, terrain)

    def __call__(self, model: mujoco.MjModel, data: mujoco.MjData, action: np.ndarray) -> np.ndarray:
        """Joint torques (N m): the servo's towards ``q_home + scale x action`` or the expert's."""
        u = self.env
        if not self.expert.torques_into(model, data, action, self._tau, u.idx.torque_limit):
            self._tau[:] = np.clip(self.expert(model, data, action), -u.idx.torque_limit, u.idx.torque_limit)
        if self._first:
            self.first_tau[:] = self._tau
            self._first = False
        if not self.student_acts:
            return self._tau.copy()
        target = np.empty(C.N_JOINTS)
        u.action_map.joint_targets_into(np.asarray(action), self.scale, target)
        return self.kp * (target - data.qpos[7:]) - self.kd * data.qvel[6:]


# ------------------------------------------------------------------------------------------------ student
def mlp_forward(params: Sequence[tuple[np.ndarray, np.ndarray]], norm: ObsNormalization, obs: np.ndarray) -> np.ndarray:
    """The student's deterministic action in numpy (what SB3's ``predict(deterministic=True)`` returns).

    :param params: (weight, bias) of each linear layer of the policy path, the action head last; tanh between.
    :param norm: the observation statistics.
    :param obs: (n_obs,) or (N, n_obs) raw observation(s).
    :return: action(s) clipped to [-1, 1], float32.
    """
    x = norm.normalize(obs).astype(np.float32)
    for i, (w, b) in enumerate(params):
        x = x @ w.T + b
        if i < len(params) - 1:
            x = np.tanh(x)
    return np.clip(x, -1.0, 1.0).astype(np.float32)


def policy_params(model: Any) -> list[tuple[np.ndarray, np.ndarray]]:
    """(weight, bias) arrays of a PPO policy's mean-action path: ``mlp_extractor.policy_net``'s linear layers,
    then ``action_net`` (copies, float32)."""
    import torch

    layers = [m for m in model.policy.mlp_extractor.policy_net if isinstance(m, torch.nn.Linear)]
    layers.append(model.policy.action_net)
    return [(m.weight.detach().cpu().numpy().copy(), m.bias.detach().cpu().numpy().copy()) for m in layers]


# ------------------------------------------------------------------------------------------------ rollouts
@dataclasses.dataclass(frozen=True)
class RolloutJob:
    """One episode to roll out (picklable: sent to a worker process)."""

    task: EpisodeTask
    goal_distance: float
    """m: the episode ends when the COG has travelled this far along +x."""
    time_limit: float
    """s of simulated time."""
    config: DistillConfig
    beta: float
    """probability that the expert acts at a control step."""
    student: tuple[list[tuple[np.ndarray, np.ndarray]], ObsNormalization] | None
    """the student's parameters and statistics (None: the expert acts throughout)."""
    rng_seed: tuple[int, ...]
    """seed sequence of the expert/student draws."""


def rollout(job: RolloutJob) -> dict[str, Any]:
    """Run one episode: the expert or the student acts (see the module docstring); every step is labelled.

    :return: ``obs`` (N, n_obs) float32 (``prev_action`` holds the previous executed action and
        ``prev_action_history`` those before it), ``labels`` (N, 12),
        ``student_action`` (N, 12) (zeros without a student), ``student_acted`` (N,) bool, and the episode's
        ``distance`` (m), ``success``, ``fell``, ``reason``, ``steps``, ``seed``, ``entry``.
    """
    cfg, task = job.config, job.task
    env = gym.make(
        "QuadUneven-v0",
        terrain={"kind": task.kind, **task.params},
        randomization=task.randomization,
        max_episode_steps=max(1, round(job.time_limit / 0.02)),
        **{**cfg.student_env_kwargs(), "action_mode": "torque"},
    )
    u = env.unwrapped
    kp, kd = cfg.servo_gains()
    teacher = DaggerTeacher(env, cfg.expert_config(), kp, kd, cfg.pd_action_scale)
    u.set_controller(teacher)
    rng = np.random.default_rng(list(job.rng_seed))
    obs, info = env.reset(seed=task.seed)
    prev = u.observation_structure["prev_action"]
    prev_history = u.observation_structure.get("prev_action_history")
    rows_obs, rows_label, rows_student, rows_acted = [], [], [], []
    executed = np.zeros(C.N_JOINTS, dtype=np.float32)
    # the actions executed before the previous one, oldest first (the env's history holds the student's actions)
    earlier = collections.deque([executed] * u.proprio_history, maxlen=max(1, u.proprio_history))
    reason, fell, success = None, False, False
    while True:
        obs = obs.copy()
        obs[prev] = executed  # what the student's env shows: the previous executed joint_pd action
        if prev_history is not None:
            obs[prev_history] = np.concatenate(earlier)
        t = float(u.data.time)
        ref, _ = teacher.expert.planned_now(t)
        student_action = np.zeros(C.N_JOINTS, dtype=np.float32)
        if job.student is not None:
            student_action = mlp_forward(job.student[0], job.student[1], obs)
        student_acts = job.student is not None and rng.random() >= job.beta
        teacher.begin_step(student_acts)
        obs_next, _, terminated, truncated, info = env.step(student_action)
        label = expert_label(ref.q_joints, teacher.first_tau, u.action_map.home_joints, kp, cfg.pd_action_scale)
        rows_obs.append(obs)
        rows_label.append(label)
        rows_student.append(student_action)
        rows_acted.append(student_acts)
        earlier.append(executed)
        executed = student_action if student_acts else label
        obs = obs_next
        if info["distance"] >= job.goal_distance:
            success, reason = True, "goal"
        elif terminated or truncated:
            fell, reason = bool(terminated), info["termination_reason"] or "time limit"
        if success or terminated or truncated:
            break
    env.close()
    return {
        "obs": np.array(rows_obs, dtype=np.float32),
        "labels": np.array(rows_label, dtype=np.float32),
        "student_action": np.array(rows_student, dtype=np.float32),
        "student_acted": np.array(rows_acted, dtype=bool),
        "distance": float(info["distance"]),
        "success": success,
        "fell": fell,
        "reason": reason,
        "steps": len(rows_obs),
        "seed": task.seed,
        "entry": task.entry,
    }


def run_rollouts(
    jobs: list[RolloutJob],
    workers: int,
    backend: str = "pool",
    address: str | None = None,
    ship_code: bool = False,
    done: Callable[[], None] | None = None,
) -> list[dict[str, Any]]:
    """:func:`rollout` of every job, in order (``workers`` processes, or Ray tasks with ``backend="ray"``:
    :func:`agents.evaluation.ray_backend.map_on_ray`; the results do not depend on either); ``done`` is called as
    each episode finishes (a progress bar)."""
    tick = done or (lambda: None)
    if backend == "ray":
        results: list[dict[str, Any] | None] = [None] * len(jobs)

        def keep(i: int, result: dict[str, Any]) -> None:
            results[i] = result
            tick()

        map_on_ray(rollout, jobs, keep, address=address, num_cpus=workers, ship_code=ship_code)
        return [r for r in results if r is not None]
    if workers <= 1 or len(jobs) <= 1:
        ordered = []
        for j in jobs:
            ordered.append(rollout(j))
            tick()
        return ordered
    ctx = multiprocessing.get_context("spawn")
    with concurrent.futures.ProcessPoolExecutor(min(workers, len(jobs)), mp_context=ctx) as pool:
        futures = [pool.submit(rollout, j) for j in jobs]
        for f in concurrent.futures.as_completed(futures):
            f.result()
            tick()
        return [f.result() for f in futures]


# ------------------------------------------------------------------------------------------------ training
def fit_normalization(obs: np.ndarray) -> ObsNormalization:
    """Observation statistics of ``obs`` (N, n_obs): mean and variance (floored at :data:`MIN_OBS_VAR`)."""
    mean = obs.astype(np.float64).mean(axis=0)
    var = np.maximum(obs.astype(np.float64).var(axis=0), MIN_OBS_VAR)
    return ObsNormalization(mean, var, NORM_EPSILON, NORM_CLIP)


def make_student(cfg: DistillConfig, terrain: dict[str, Any]) -> Any:
    """An untrained SB3 PPO for the student's env (``joint_pd``, the clock), on CPU, seeded with ``cfg.seed``."""
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import DummyVecEnv

    kwargs = cfg.student_env_kwargs()
    venv = DummyVecEnv([lambda: gym.make("QuadUneven-v0", terrain=terrain, **kwargs)])
    arch = list(cfg.net_arch)
    return PPO(
        "MlpPolicy",
        venv,
        seed=cfg.seed,
        device="cpu",
        verbose=0,
        policy_kwargs={"net_arch": {"pi": arch, "vf": arch}, "log_std_init": cfg.log_std_init},
    )


def fit_student(
    model: Any, norm: ObsNormalization, obs: np.ndarray, labels: np.ndarray, cfg: DistillConfig, seed: int
) -> list[float]:
    """Train the policy's mean action on (``obs``, ``labels``) by mean squared error, ``cfg.epochs`` passes.

    :return: the mean training loss of each epoch.
    """
    import torch

    torch.manual_seed(seed)
    policy = model.policy
    net, head = policy.mlp_extractor.policy_net, policy.action_net
    params = list(net.parameters()) + list(head.parameters())
    opt = torch.optim.Adam(params, lr=cfg.learning_rate)
    x = torch.as_tensor(norm.normalize(obs))
    y = torch.as_tensor(labels)
    gen = torch.Generator().manual_seed(seed)
    losses = []
    policy.train()
    for _ in range(cfg.epochs):
        order = torch.randperm(len(x), generator=gen)
        total = 0.0
        for i in range(0, len(x), cfg.batch_size):
            idx = order[i : i + cfg.batch_size]
            loss = torch.nn.functional.mse_loss(head(net(x[idx])), y[idx])
            opt.zero_grad()
            loss.backward()
            opt.step()
            total += loss.item() * len(idx)
        losses.append(total / len(x))
    policy.eval()
    return losses


def _metadata(cfg: DistillConfig, suite: Suite, robot: str) -> dict[str, Any]:
    """The student's ``rl_meta.json`` (:mod:`agents.rl.model_io`) on the robot named ``robot``."""
    import stable_baselines3

    return {
        "algo": "ppo",
        "robot": robot,
        "residual": False,
        "env_id": "QuadUneven-v0",
        "env_kwargs": cfg.student_env_kwargs(),
        "normalize_obs": True,
        "terrain": [e.spec for e in suite.terrains],
        "randomization": None,
        "max_episode_steps": max(1, round(suite.time_limit / 0.02)),
        "seed": cfg.seed,
        "stable_baselines3": stable_baselines3.__version__,
    }


def save_student(model: Any, norm: ObsNormalization, out: Path, meta: dict[str, Any]) -> Path:
    """Write ``model.zip``, ``model_obs_norm.npz`` and ``rl_meta.json`` into ``out`` (created); :return: the model's
    path."""
    out.mkdir(parents=True, exist_ok=True)
    path = out / "model.zip"
    model.save(path)
    norm.save(norm_path(path))
    write_metadata(out, meta)
    return path


def _check_suite(suite: Suite) -> None:
    for i, e in enumerate(suite.terrains):
        if e.command is not None or e.waypoints is not None:
            raise ValueError(
                f"suite terrains[{i}] ({e.label}) has a command or waypoints; distill takes suites of plain entries "
                "(the student observes no command)"
            )


def distill(
    suite: Suite,
    out: str | Path,
    cfg: DistillConfig,
    overwrite: bool = False,
    resume: bool = False,
    log: Callable[[str], None] = print,
    progress: bool = False,
) -> dict[str, Any]:
    """Behaviour cloning from the expert on ``suite``'s episodes, then ``cfg.dagger_rounds`` DAgger rounds.

    The episodes are those ``evaluate`` runs on the robot of ``cfg.env_kwargs`` with the seeds moved by
    ``cfg.seed_offset`` (:func:`agents.evaluation.run.suite_episodes`: a suite with ``scale: leg_length`` is scaled
    to the robot); the teacher is :meth:`DistillConfig.expert_config`, and ``rl_meta.json`` records the robot.

    Writes into ``out``: the student (``model.zip``, ``model_obs_norm.npz``, ``rl_meta.json``, after every round;
    each round's also in ``rounds/round_K/``, a folder ``evaluate`` reads, for selection on validation episodes),
    ``distill_summary.json`` (per round: data, rollouts, losses) and ``distill_curve.png``. Each round folder also
    keeps ``round_state.npz`` (the round's samples and the network's weights): with ``resume`` a stopped run
    continues after its last finished round, with the same result as a run never stopped (the rollouts and the
    fits are seeded by round).

    :param progress: a progress bar over the rollout episodes of every round.
    :param resume: continue the run in ``out`` (its config must equal ``cfg`` but for ``budget_min``,
        ``dagger_rounds`` and where the rollouts run: :data:`RESUME_FREE_FIELDS`).
    :return: the summary.
    :raises ValueError: on a suite with commands or waypoints, an invalid expert field, an unusable ``out``, or a
        ``resume`` whose run is missing or differs.
    """
    import torch

    _check_suite(suite)
    cfg.expert_config()  # its errors before any work
    if resume and overwrite:
        raise ValueError("resume and overwrite exclude each other: resume keeps DIR's rounds, overwrite deletes them")
    suite, tasks = suite_episodes(suite, cfg.env_kwargs, cfg.episodes, cfg.seed_offset)
    start = time.perf_counter()
    with output_dir(out, "distill", DISTILL_OUTPUTS, overwrite=overwrite, keep=resume) as manifest:
        out = manifest.out
        torch.set_num_threads(1)
        model = make_student(cfg, {"kind": tasks[0].kind, **tasks[0].params})
        meta = _metadata(cfg, suite, model.get_env().envs[0].unwrapped.robot.name)
        data_obs: list[np.ndarray] = []
        data_labels: list[np.ndarray] = []
        norm: ObsNormalization | None = None
        rounds: list[dict[str, Any]] = []
        summary: dict[str, Any] = {"config": _config_dict(cfg), "suite": suite.name, "rounds": rounds}
        if resume:
            rounds[:], norm = _resume(out, cfg, suite.name, model, data_obs, data_labels)
            log(f"resumed after round {len(rounds) - 1}: {sum(len(o) for o in data_obs)} samples")
        remaining = max(cfg.dagger_rounds + 1 - len(rounds), 0) * len(tasks)
        bar = tqdm(total=remaining, desc="rollouts", unit="ep", disable=not progress)
        for k in range(len(rounds), cfg.dagger_rounds + 1):
            elapsed = (time.perf_counter() - start) / 60.0
            if k > 0 and elapsed >= cfg.budget_min:
                log(f"budget of {cfg.budget_min:g} min reached after round {k - 1}")
                summary["stopped_by_budget"] = True
                break
            beta = 1.0 if k == 0 else cfg.beta_decay**k
            student = None if k == 0 else (policy_params(model), norm)
            jobs = [
                RolloutJob(t, suite.goal_distance, suite.time_limit, cfg, beta, student, (cfg.seed, k, t.index))
                for t in tasks
            ]
            t0 = time.perf_counter()
            results = run_rollouts(jobs, cfg.workers, cfg.backend, cfg.address, cfg.ship_code, done=bar.update)
            rollout_s = time.perf_counter() - t0
            obs = np.concatenate([r["obs"] for r in results])
            labels = np.concatenate([r["labels"] for r in results])
            acted = np.concatenate([r["student_acted"] for r in results])
            row: dict[str, Any] = {
                "round": k,
                "labels_clipped": clipped_label_shares(labels),
                "beta": beta,
                "steps": len(obs),
                "student_steps": int(acted.sum()),
                "successes": sum(r["success"] for r in results),
                "falls": sum(r["fell"] for r in results),
                "episodes": len(results),
                "mean_distance": float(np.mean([r["distance"] for r in results])),
                "rollout_s": rollout_s,
            }
            if student is not None:  # the student's error on the states this round visited, before training on them
                err = np.concatenate([r["student_action"] for r in results]) - labels
                row["label_rmse_on_policy"] = float(np.sqrt(np.mean(err**2)))
            data_obs.append(obs)
            data_labels.append(labels)
            all_obs, all_labels = np.concatenate(data_obs), np.concatenate(data_labels)
            if norm is None:
                norm = fit_normalization(all_obs)
            t0 = time.perf_counter()
            losses = fit_student(model, norm, all_obs, all_labels, cfg, cfg.seed + k)
            row.update(train_s=time.perf_counter() - t0, dataset=len(all_obs), loss_first=losses[0], loss=losses[-1])
            rounds.append(row)
            log(
                f"round {k} (beta {beta:.3f}): {row['steps']} steps ({row['student_steps']} by the student), "
                f"{row['successes']}/{row['episodes']} reached the goal, {row['falls']} fell, mean distance "
                f"{row['mean_distance']:.2f} m"
                + (f", on-policy label rmse {row['label_rmse_on_policy']:.3f}" if "label_rmse_on_policy" in row else "")
                + f"; loss {losses[-1]:.4f} on {len(all_obs)} samples"
            )
            worst = max(row["labels_clipped"], key=row["labels_clipped"].get)
            if row["labels_clipped"][worst] > CLIPPED_LABELS_WARN:
                log(
                    f"warning: {row['labels_clipped'][worst]:.1%} of the {worst} labels are clipped to +-1: the "
                    f"student cannot ask for the expert's torque there; raise --pd-action-scale "
                    f"(now {cfg.pd_action_scale:g} rad)"
                )
            save_student(model, norm, out, meta)
            round_dir = out / "rounds" / f"round_{k}"
            save_student(model, norm, round_dir, meta)  # each round's student, to select from
            _save_round_state(round_dir, model, obs, labels)
            summary["wall_time_s"] = time.perf_counter() - start
            (out / "distill_summary.json").write_text(json.dumps(summary, indent=2))
            manifest.add_new()
        bar.close()
        plot_distill_curve(rounds, out / "distill_curve.png", title=f"distillation on {suite.name}")
        summary["model"] = str(out / "model.zip")
        summary["wall_time_s"] = time.perf_counter() - start
        (out / "distill_summary.json").write_text(json.dumps(summary, indent=2))
    return summary


ROUND_STATE = "round_state.npz"
"""In each ``rounds/round_K/``: the round's samples (``obs``, ``labels``) and the student's weights after it
(``weight:NAME``), what ``resume`` reads."""

RESUME_FREE_FIELDS = ("budget_min", "dagger_rounds", "workers", "backend", "address", "ship_code")
"""The :class:`DistillConfig` fields a resumed run may change (none changes what a round computes)."""


def _save_round_state(round_dir: Path, model: Any, obs: np.ndarray, labels: np.ndarray) -> None:
    weights = {f"weight:{k}": v.detach().cpu().numpy() for k, v in model.policy.state_dict().items()}
    tmp = round_dir / f".{ROUND_STATE}.tmp.npz"
    np.savez(tmp, obs=obs, labels=labels, **weights)
    tmp.replace(round_dir / ROUND_STATE)  # a run stopped while writing leaves the round unfinished, not corrupt


def _resume(
    out: Path,
    cfg: DistillConfig,
    suite_name: str,
    model: Any,
    data_obs: list[np.ndarray],
    data_labels: list[np.ndarray],
) -> tuple[list[dict[str, Any]], ObsNormalization]:
    """Load the finished rounds of the run in ``out`` into ``data_obs``/``data_labels`` and ``model``; :return: their
    summary rows and the observation statistics. :raises ValueError: naming what is missing or differs."""
    import torch

    path = out / "distill_summary.json"
    try:
        summary = json.loads(path.read_text())
        rows, recorded = list(summary["rounds"]), dict(summary["config"])
    except (OSError, ValueError, KeyError, TypeError) as err:
        raise ValueError(f"--resume: {path} is not a distillation's summary ({type(err).__name__}: {err})") from None
    if summary.get("suite") != suite_name:
        raise ValueError(f"--resume: DIR's run distilled suite {summary.get('suite')!r}, not {suite_name!r}")
    wanted = json.loads(json.dumps(_config_dict(cfg)))
    for name in sorted(set(wanted) | set(recorded)):
        if name not in RESUME_FREE_FIELDS and wanted.get(name) != recorded.get(name):
            raise ValueError(
                f"--resume: {name} is {excerpt(wanted.get(name))} here but {excerpt(recorded.get(name))} in DIR's "
                f"run; only {list(RESUME_FREE_FIELDS)} may change"
            )
    if not rows:
        raise ValueError("--resume: DIR's run has no finished round; start it again without --resume")
    for k in range(len(rows)):
        state = out / "rounds" / f"round_{k}" / ROUND_STATE
        if not state.is_file():
            raise ValueError(f"--resume: {state} is missing (written by every finished round)")
        with np.load(state) as f:
            data_obs.append(f["obs"])
            data_labels.append(f["labels"])
            if k == len(rows) - 1:
                weights = {n.split(":", 1)[1]: torch.as_tensor(f[n]) for n in f.files if n.startswith("weight:")}
    model.policy.load_state_dict(weights)
    last = out / "rounds" / f"round_{len(rows) - 1}" / "model.zip"
    return rows, ObsNormalization.load(norm_path(last))


def _config_dict(cfg: DistillConfig) -> dict[str, Any]:
    d = dataclasses.asdict(cfg)
    d["net_arch"] = list(cfg.net_arch)
    d["gait_period"] = cfg.clock_period()
    return d


def plot_distill_curve(rounds: list[dict[str, Any]], path: Path, title: str) -> Path:
    """Per round: the rollouts' goal fraction and falls, the student's on-policy label error and the final loss."""
    from agents.plotting import pyplot, save

    plt = pyplot()
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(9, 3.4))
    k = [r["round"] for r in rounds]
    a1.plot(k, [r["successes"] / r["episodes"] for r in rounds], "o-", label="reached the goal")
    a1.plot(k, [r["falls"] / r["episodes"] for r in rounds], "s-", label="fell")
    a1.plot(k, [r["student_steps"] / max(1, r["steps"]) for r in rounds], "^--", label="steps the student acted")
    a1.set_xlabel("round (0: behaviour cloning)")
    a1.set_ylabel("fraction of the round's episodes / steps")
    a1.set_ylim(-0.05, 1.05)
    a1.legend(fontsize=8)
    a2.plot(k, [r.get("label_rmse_on_policy", math.nan) for r in rounds], "o-", label="on-policy label rmse")
    a2.plot(k, [math.sqrt(r["loss"]) for r in rounds], "s-", label="training rmse (aggregated)")
    a2.set_xlabel("round")
    a2.set_ylabel("action rmse (units of pd_action_scale)")
    a2.legend(fontsize=8)
    fig.suptitle(title)
    return save(fig, path)


__all__ = [
    "DaggerTeacher",
    "DistillConfig",
    "RolloutJob",
    "distill",
    "expert_label",
    "fit_normalization",
    "mlp_forward",
    "policy_params",
    "rollout",
]
