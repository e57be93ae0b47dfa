"""One evaluation episode: build the env and the policy, walk until goal, fall or time limit, measure.

Runs in a worker process (``--workers``), so its inputs (:class:`EvalConfig`, an ``EpisodeTask``)
and its output (:class:`EpisodeResult`) are plain picklable data.
"""

from __future__ import annotations

import dataclasses
import time
import traceback
from pathlib import Path
from typing import Any, Protocol

import gymnasium as gym
import numpy as np

import quad_uneven_env  # noqa: F401  (registers QuadUneven-v0)
from agents.evaluation.machine import machine_info
from agents.evaluation.metrics import (
    COMMAND_METRICS,
    command_metrics,
    cost_of_transport,
    stability_metrics,
    timing_metrics,
    torque_peak_fractions,
)
from agents.evaluation.policies import expert_model_of, make_policy, make_policy_env
from agents.evaluation.suites import EpisodeTask
from agents.waypoints import WaypointFollower, load_waypoints
from quad_uneven_env.constants import JOINT_NAMES, LEG_NAMES
from quad_uneven_env.fields import clip, excerpt
from quad_uneven_env.randomization import factor_values
from quad_uneven_env.spatial import wrap_angle, yaw_of_quat

VIDEO_FPS = 25
"""Frames per second of the MP4s (one frame every 1 / VIDEO_FPS s of simulated time: real-time playback)."""

VIDEO_SIZE = (480, 360)
"""Width and height (pixels) of the MP4s."""

MAX_FAILURE_LOG = 200
"""At most this many entries of the policy's ``failure_log`` go into an episode record."""

DEFAULT_WALL_TIME_LIMIT = 3600.0
"""s of wall-clock time after which an episode ends (``end_reason = "wall_time_limit"``), whatever its sim time."""

EVALUATION_ENV_KWARGS = {
    "terrain": "the suite's terrains[i] entry",
    "max_episode_steps": "the suite's time_limit",
    "controller": "the policy (the expert installs its own)",
    "render_mode": "--video",
}
"""QuadUneven-v0 arguments the evaluation sets itself, with who owns each; ``env_kwargs`` may not set them."""


class EnvArgumentError(ValueError):
    """Environment arguments the evaluation cannot use; the message starts with ``env_kwargs``."""


def check_env_kwargs(env_kwargs: Any) -> dict[str, Any]:
    """``env_kwargs`` checked for names: a mapping of QuadUneven-v0 arguments the evaluation does not set itself.

    The values are checked by the environment when the preflight builds it.

    :raises EnvArgumentError: on a non-mapping, an unknown argument or one of ``EVALUATION_ENV_KWARGS``.
    """
    import inspect

    from quad_uneven_env.env import QuadUnevenEnv

    if not isinstance(env_kwargs, dict) or not all(isinstance(k, str) for k in env_kwargs):
        raise EnvArgumentError(
            f"env_kwargs must be a JSON object of QuadUneven-v0 arguments, got {excerpt(env_kwargs)}"
        )
    allowed = [n for n in inspect.signature(QuadUnevenEnv.__init__).parameters if n != "self"]
    for key in env_kwargs:
        if key in EVALUATION_ENV_KWARGS:
            raise EnvArgumentError(f"env_kwargs.{key} is set by {EVALUATION_ENV_KWARGS[key]}; remove it")
        if key not in allowed:
            settable = [n for n in allowed if n not in EVALUATION_ENV_KWARGS]
            raise EnvArgumentError(f"env_kwargs.{clip(key, 40)}: unknown QuadUneven-v0 argument; allowed: {settable}")
    return dict(env_kwargs)


@dataclasses.dataclass(frozen=True)
class EvalConfig:
    """What every episode of one evaluation shares."""

    policy: str
    """``"zero"``, ``"expert"`` or an SB3 model path (see :func:`agents.evaluation.policies.make_policy`)."""
    goal_distance: float
    """m of COG travel along +x that ends the episode as a success."""
    time_limit: float
    """s of simulated time per episode."""
    algo: str = "ppo"
    """SB3 class for a model path."""
    env_kwargs: dict[str, Any] = dataclasses.field(default_factory=dict)
    """extra QuadUneven-v0 arguments (override the policy's own)."""
    video_dir: str | None = None
    """directory for MP4s of the first episode of each terrain entry (None: no video)."""
    wall_time_limit: float = DEFAULT_WALL_TIME_LIMIT
    """s of wall-clock time per episode (env and policy construction included); the episode then ends."""
    allow_pickle: bool = False
    """load pickled files of a model folder (they can run code: trusted files only)."""
    expert_config: dict[str, Any] = dataclasses.field(default_factory=dict)
    """fields of :class:`agents.expert.ExpertConfig` for the ``"expert"`` policy (e.g. ``{"model": "oracle"}``)."""


@dataclasses.dataclass
class EpisodeResult:
    """An episode's JSON record plus the arrays the report plots."""

    record: dict[str, Any]
    """the results.json episode record (JSON-safe)."""
    trace: dict[str, np.ndarray]
    """per control step: ``time`` (s), ``cog`` (N, 3, m, world), ``feet`` (N, 4, 3, m, world), ``index`` (N m),
    ``contact`` (N, 4) foot contact flags, ``yaw`` (N,) trunk heading (rad, unwrapped); with a command also
    ``command`` (N - 1, 3) the command in effect during each step, with waypoints ``waypoints`` (K, 2) (m)."""
    terrain: dict[str, Any] | None
    """for an entry's first episode: ``heights`` (m), ``origin`` (m), ``cell_size`` (m) of its surface."""


class EpisodeObserver(Protocol):
    """What :func:`run_task` hands each step of an episode to (``quad-uneven collect`` records them with one).

    ``start`` runs once the env and the policy are built, before the reset (it may install a physics-rate
    controller that wraps the policy's); ``reset`` sees the reset's observation and info, ``step`` every
    ``env.step``'s return right after it. An exception raised by ``reset`` or ``step`` ends the episode as an
    ``error``, as one of the policy would.
    """

    def start(self, env: gym.Env, policy: Any) -> None: ...

    def reset(self, obs: np.ndarray, info: dict[str, Any]) -> None: ...

    def step(
        self, action: np.ndarray, obs: np.ndarray, reward: float, terminated: bool, truncated: bool, info: dict
    ) -> None: ...


def make_env(task: EpisodeTask, cfg: EvalConfig, render: bool = False) -> gym.Env:
    """The env of ``task`` for the policy (:func:`~agents.evaluation.policies.make_policy_env`: for an SB3 model the
    env it was trained in) with ``cfg.env_kwargs`` and a time limit of ``cfg.time_limit``.

    The entry's ``randomization`` and ``command`` (if any) override those given in ``cfg.env_kwargs``; an entry
    with waypoints and no command gets the command ``{}`` (all zero, steered by the waypoint follower) unless
    ``cfg.env_kwargs`` gives one.
    """
    kwargs = dict(cfg.env_kwargs)
    if task.randomization is not None:
        kwargs["randomization"] = task.randomization
    if task.command is not None:
        kwargs["command"] = task.command
    elif task.waypoints is not None and kwargs.get("command") is None:
        kwargs["command"] = {}
    try:
        dt = float(kwargs.get("timestep", 0.002)) * int(kwargs.get("frame_skip", 10))
        steps = max(1, round(cfg.time_limit / dt))
    except (TypeError, ValueError, ZeroDivisionError, OverflowError):
        steps = 1  # invalid timestep or frame_skip: the env's own check below names the field
    if render:
        kwargs.update(render_mode="rgb_array", width=VIDEO_SIZE[0], height=VIDEO_SIZE[1])
    kwargs.update(terrain={"kind": task.kind, **task.params}, max_episode_steps=steps)
    return make_policy_env(cfg.policy, **kwargs)


def _factors(drawn: dict[str, float] | None, pushes: list[dict[str, Any]]) -> dict[str, float] | None:
    """One value per randomization factor (the report's grouping), pushes as their count and largest impulse."""
    if drawn is None:
        return None
    return {
        **factor_values(drawn),
        "push_count": float(len(pushes)),
        "push_impulse_max": max((float(p["impulse"]) for p in pushes), default=0.0),
    }


def _strength(drawn: dict[str, Any] | None) -> np.ndarray:
    """-, (12,): each motor's drawn strength (1 where the world does not randomize it)."""
    return np.array([(drawn or {}).get(f"motor_strength_{name}", 1.0) for name in JOINT_NAMES])


def _end_reason(info: dict[str, Any]) -> str:
    if info["diverged"]:
        return "diverged"
    reason = info["termination_reason"] or ""
    return "left_terrain" if reason.startswith("left") else "fall"


def _policy_phase(policy: Any) -> str | None:
    for name in ("phase", "current_phase"):
        value = getattr(policy, name, None)
        if value is not None and not callable(value):
            return str(value)
    return None


def run_task(task: EpisodeTask, cfg: EvalConfig, observer: EpisodeObserver | None = None) -> EpisodeResult:
    """Run one episode; never raises for a policy or env error inside the episode (recorded as ``error``).

    ``observer`` (optional) sees the episode's reset and every step (:class:`EpisodeObserver`).

    Success: the COG has travelled ``goal_distance`` along +x (``info["distance"]``) before any fall and
    within the time limit; for an entry with waypoints, every waypoint reached (in order) before any fall and
    within the time limit; for an entry with a command (and no waypoints), no fall (nor leaving the terrain)
    until the time limit. ``cfg.wall_time_limit`` s of wall-clock time end it as ``wall_time_limit``.
    Energy for the cost of transport is |tau . qd| sampled once per control step.
    """
    wall0 = time.perf_counter()
    video = cfg.video_dir is not None and task.first_of_entry
    env = make_env(task, cfg, render=video)
    u = env.unwrapped
    policy = make_policy(cfg.policy, env, cfg.algo, cfg.allow_pickle, cfg.expert_config)
    if observer is not None:
        observer.start(env, policy)
    dt = u.dt
    g = float(-u.model.opt.gravity[2])
    writer, video_path, frame_every = None, None, max(1, round(1.0 / (VIDEO_FPS * dt)))
    if video:
        import imageio.v2 as iio2

        video_path = Path(cfg.video_dir) / f"ep{task.index:03d}_{task.kind}_seed{task.seed}.mp4"
        video_path.parent.mkdir(parents=True, exist_ok=True)
        writer = iio2.get_writer(
            video_path, format="FFMPEG", fps=round(1.0 / (frame_every * dt)), codec="libx264", macro_block_size=8
        )

    obs, info = env.reset(seed=task.seed)
    mass = u.total_mass  # kg, this episode's (randomized masses included)
    drawn = dict(info["randomization"]) if u.randomization is not None else None
    terrain = None
    if task.first_of_entry:
        hf = u.terrain.heightfield
        terrain = {"heights": hf.heights.astype(np.float32), "origin": tuple(hf.origin), "cell_size": hf.cell_size}
    times, cogs, feet, index = [0.0], [info["cog"]], [info["feet_pos"]], []
    contact = [info["foot_contact"]]
    index0 = float(info["stability_index"])
    yaws = [yaw_of_quat(u.data.qpos[3:7])]
    commands: list[np.ndarray] | None = [] if u.command is not None else None
    follower = None
    if task.waypoints is not None:
        follower = WaypointFollower(load_waypoints(task.waypoints))
        follower.reset(yaws[0])
    tracked = task.command is not None or task.waypoints is not None
    state, start = None, np.ones(1, dtype=bool)
    work, success, end_reason, fall_reason, error = 0.0, False, "time_limit", None, None
    step = 0
    residual = "residual_torque" in info  # a residual model's env reports its residual torque (N m)
    peak_torque = np.zeros(len(u.idx.torque_limit))  # N m, per joint, sampled at every control step
    residual_sum = 0.0
    try:
        if observer is not None:
            observer.reset(obs, info)
        if writer is not None:
            writer.append_data(env.render())
        while True:
            if follower is not None:
                u.set_command(follower.update(np.asarray(info["cog"][:2]), yaws[-1]))
                if follower.done:
                    success, end_reason = True, "waypoints"
                    break
            if commands is not None:
                commands.append(u.command)  # in effect during the step
            action, state = policy.predict(obs, state=state, episode_start=start, deterministic=True)
            start = np.zeros(1, dtype=bool)
            obs, reward, terminated, truncated, info = env.step(action)
            step += 1
            if observer is not None:
                observer.step(action, obs, reward, terminated, truncated, info)
            if residual:
                residual_sum += float(info["residual_torque"])
            times.append(float(u.data.time))
            cogs.append(info["cog"])
            feet.append(info["feet_pos"])
            contact.append(info["foot_contact"])
            index.append(info["stability_index"])
            y = yaw_of_quat(u.data.qpos[3:7])
            yaws.append(yaws[-1] + wrap_angle(y - yaws[-1]))  # unwrapped
            if not info["diverged"]:
                work += float(np.abs(u.data.actuator_force * u.data.qvel[6:]).sum()) * dt
                np.maximum(peak_torque, np.abs(u.data.actuator_force), out=peak_torque)
            if writer is not None and step % frame_every == 0:
                writer.append_data(env.render())
            if terminated:
                end_reason, fall_reason = _end_reason(info), info["termination_reason"]
                break
            if not tracked and info["distance"] >= cfg.goal_distance:
                success, end_reason = True, "goal"
                break
            if truncated:
                success = task.command is not None and task.waypoints is None  # walked the whole time limit
                break
            if time.perf_counter() - wall0 > cfg.wall_time_limit:
                end_reason = "wall_time_limit"
                break
    except Exception as e:  # a crashing policy must not lose the other episodes of a suite
        end_reason, error = "error", f"{type(e).__name__}: {e}"
        fall_reason = f"error: {error}"
        traceback.print_exc()
    finally:
        if writer is not None:
            writer.close()
        env.close()

    distance = float(info["distance"])
    sim_time = float(u.data.time)
    failure_log = getattr(policy, "failure_log", None)
    pushes = [dataclasses.asdict(p) for p in u.pushes]
    record: dict[str, Any] = {
        "index": task.index,
        "entry": task.entry,
        "terrain": task.kind,
        "params": task.params,
        "seed": task.seed,
        "success": success,
        "distance": distance,
        "sim_time": sim_time,
        "mean_speed": distance / sim_time if sim_time > 0 else None,
        **stability_metrics(np.asarray(index, dtype=float), dt),
        "cost_of_transport": cost_of_transport(work, mass, g, distance),
        "mechanical_work": work,
        "fall_reason": fall_reason,
        "end_reason": end_reason,
        "end_position": [float(v) for v in info["cog"]],
        "end_phase": _policy_phase(policy),
        "end_stance": [leg for leg, c in zip(LEG_NAMES, info["foot_contact"], strict=True) if c],
        **timing_metrics(getattr(policy, "planner_times_ms", None)),
        "failure_log": [str(s) for s in failure_log[:MAX_FAILURE_LOG]] if failure_log is not None else None,
        "failure_count": len(failure_log) if failure_log is not None else None,
        "expert_model": expert_model_of(policy),
        "mean_residual_torque": residual_sum / step if residual and step else None,
        "torque_peak_fraction": torque_peak_fractions(peak_torque, u.idx.torque_limit, _strength(drawn)),
        "command": task.command,
        "waypoints_reached": follower.reached if follower is not None else None,
        "waypoints_total": len(follower.config.points) if follower is not None else None,
        **_tracking(commands, cogs, yaws, dt),
        "error": error,
        "machine": machine_info(),
        "randomization": drawn,
        "factors": _factors(drawn, pushes),
        "pushes": pushes if drawn is not None else None,
        "video": video_path.name if video_path is not None else None,
        "wall_time": time.perf_counter() - wall0,
    }
    record["realtime_factor"] = sim_time / record["wall_time"] if record["wall_time"] > 0 else None
    trace = {
        "time": np.asarray(times),
        "cog": np.asarray(cogs, dtype=np.float32).reshape(-1, 3),
        "feet": np.asarray(feet, dtype=np.float32).reshape(-1, 4, 3),
        "index": np.asarray([index0, *index], dtype=np.float64),
        "contact": np.asarray(contact, dtype=bool).reshape(-1, 4),
        "yaw": np.asarray(yaws, dtype=np.float64),
    }
    if commands is not None:
        trace["command"] = np.asarray(commands, dtype=np.float64).reshape(-1, 3)
    if follower is not None:
        trace["waypoints"] = np.asarray(follower.config.points, dtype=np.float64).reshape(-1, 2)
        trace["waypoint_radius"] = np.float64(follower.config.radius)
    return EpisodeResult(record, trace, terrain)


def _tracking(commands: list[np.ndarray] | None, cogs: list, yaws: list[float], dt: float) -> dict[str, Any]:
    """The command-tracking fields of the record (:func:`agents.evaluation.metrics.command_metrics`; None
    without a command). Only the steps taken count (an error before a step leaves a command without one)."""
    if commands is None:
        return dict.fromkeys(COMMAND_METRICS)
    n = min(len(commands), len(cogs) - 1)
    xy = np.asarray(cogs, dtype=float)[: n + 1, :2]
    return command_metrics(dt, xy, np.asarray(yaws[: n + 1]), np.asarray(commands[:n]).reshape(-1, 3))
