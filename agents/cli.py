"""The ``quad-uneven`` command line: every argparse parser of the project, and the thin handlers behind them
(with the ``agents/cli_*.py`` modules: shared options, and subcommands of their own).

Subcommands (see ``--help`` of each):

- ``demo``: the scripted expert walks the default rough terrain; a report;
- ``evaluate``: a policy over a terrain suite: results.json, report.md, plots, videos;
- ``collect``: the scripted expert over a suite's episodes as a Minari dataset;
- ``train``: a residual RL agent (SB3 PPO or SAC) on top of the expert, or a policy from scratch;
- ``distill``: the expert distilled into a network policy (behaviour cloning, then DAgger);
- ``export``: a trained agent's deterministic policy as ONNX;
- ``paper``: the paper's §6 cycle in the simulator (Figs. 4-9);
- ``plan-paper``: the paper's §6 plan without the simulator (Figs. 4-6);
- ``robustness``: one factor of the simulated world swept: success and stability index curves;
- ``compare``: two evaluations of the same episodes side by side;
- ``select``: a training run's checkpoint chosen on validation episodes;
- ``fit-strength``: the learned motor-strength estimator fitted on expert episodes;
- ``sweep``: a grid of training runs on Ray Tune, each model evaluated on a suite;
- ``plot-curves``: several training runs' learning curves in one figure;
- ``baselines``: several policies on the same episodes of several suites: one markdown table.

The library modules expose typed functions only; this module turns arguments into their calls and their
errors into one line on stderr with exit code 2: every validation error of the project is a ``ValueError``
(``SuiteError``, ``PolicyError``, ``EnvArgumentError``, ``TrainConfigError``, ``OutputError``, ...) whose
message names the field. An interrupt (Ctrl-C, or SIGTERM during ``evaluate`` and ``train``) exits with 130
after the command has kept what it finished.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
from pathlib import Path
from typing import Any, NoReturn

from agents.cli_backend import add_backend_arguments, backend_options
from agents.cli_baselines import add_baselines_parser
from agents.evaluation.episode import DEFAULT_WALL_TIME_LIMIT
from agents.evaluation.policies import SB3_ALGOS
from agents.evaluation.ray_backend import DEFAULT_LOCAL_CPUS
from agents.evaluation.run import evaluate
from agents.evaluation.suites import Suite, SuiteError, load_suite, suite_from_dict, suite_names
from agents.interrupts import sigterm_as_keyboard_interrupt
from agents.outputs import output_dir, output_file
from agents.paper.simulation import DISTRIBUTIONS as PAPER_DISTRIBUTIONS
from agents.plotting import video_to_gif
from agents.rl.config import ALGOS, load_train_config, validate
from quad_uneven_env.fields import excerpt

EXIT_USAGE = 2
"""Exit code of an invalid argument, file or output directory (argparse's own code for bad options)."""

EXIT_INTERRUPTED = 130
"""Exit code after Ctrl-C or SIGTERM (128 + SIGINT), once the finished work has been kept."""


class UsageError(ValueError):
    """A command line that argparse refuses (an unknown option, a value of the wrong type, a missing option)."""


class ArgumentParser(argparse.ArgumentParser):
    """argparse's parser whose errors are :class:`UsageError` (one ``error: ...`` line from :func:`main`, exit
    code 2, as every other invalid input) instead of the usage text; ``--help`` prints the help as usual."""

    def error(self, message: str) -> NoReturn:
        """Raise :class:`UsageError` naming the option, with where to find the allowed forms."""
        raise UsageError(f"{message} (see {self.prog} --help)")


def demo(out: Path, terrain: str, seed: int, distance: float, video: bool) -> dict:
    """The expert walks ``distance`` m over ``terrain``; report, plots and video go to ``out`` (replaced).

    :return: the episode record of results.json.
    :raises SuiteError: on an unknown terrain, a negative seed or an unreachable distance (field named).
    """
    suite = suite_from_dict(
        {
            "name": "demo",
            "goal_distance": distance,
            "time_limit": max(20.0, 2.5 * distance / 0.1),
            "terrains": [{"kind": terrain, "params": {}, "seeds": [seed]}],
        },
        source="demo",
    )
    results = evaluate(suite, "expert", out, video=video, overwrite=True)
    return results["episodes"][0]


# ---------------------------------------------------------------------------------------------- demo
DEMO_OPTIONS = (
    ("terrains[0].seeds[0]", "--seed"),
    ("terrains[0].params.length", "the terrain's length"),
    ("terrains[0].kind", "--terrain"),
    ("terrains[0]", "--terrain"),
    ("goal_distance", "--distance"),
)
"""Suite fields of the demo's one-entry suite and the options they come from (for error messages)."""


def add_demo_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register the ``demo`` subcommand on ``sub``."""
    p = sub.add_parser("demo", help="the scripted expert walks the default rough terrain; writes a report")
    p.add_argument(
        "--out",
        type=Path,
        default=Path("out/demo"),
        help="output directory (default out/demo; a previous demo there is replaced)",
    )
    p.add_argument("--terrain", default="rough", help="terrain kind with its defaults (default: rough)")
    p.add_argument("--seed", type=int, default=0, help="terrain seed")
    p.add_argument("--distance", type=float, default=2.0, help="goal distance along +x (m)")
    p.add_argument("--no-video", action="store_true", help="skip the MP4 (rendering is the slow part)")
    p.add_argument(
        "--gif",
        type=Path,
        default=None,
        metavar="PATH",
        help="also write the walk as a small time-lapse GIF to PATH (320x240, 10 fps, 4 s; made from the MP4)",
    )
    p.set_defaults(func=run_demo_command)
    return p


def run_demo_command(args: argparse.Namespace) -> int:
    """Handler of ``quad-uneven demo``."""
    if args.gif is not None and args.no_video:
        raise ValueError(f"--gif is made from the video: drop --no-video, got --gif {args.gif} --no-video")
    if args.gif is not None:
        output_file(args.gif, "--gif")
    try:
        ep = demo(args.out, args.terrain, args.seed, args.distance, not args.no_video)
    except SuiteError as err:  # name the demo's options, not the suite fields it builds from them
        msg = str(err)
        for field, option in DEMO_OPTIONS:
            msg = msg.replace(field, option)
        raise SuiteError(msg) from None
    keys = ("terrain", "seed", "success", "distance", "sim_time", "mean_speed", "min_stability_index",
            "mean_stability_index", "time_index_negative", "cost_of_transport", "fall_reason",
            "planner_ms_median")  # fmt: skip
    for k in keys:
        print(f"{k:24s} {ep.get(k)}")
    print(f"report: {(args.out / 'report.md').resolve()}")
    for video in sorted((args.out / "videos").glob("*.mp4")):
        print(f"video:  {video.resolve()}")
        if args.gif is not None:
            print(f"gif:    {video_to_gif(video, args.gif).resolve()}")
    return 0


# ------------------------------------------------------------------------------------------ evaluate
def add_suite_run_arguments(p: argparse.ArgumentParser) -> None:
    """``--suite``, ``--out``, ``--episodes``, ``--seed`` and ``--episode-wall-limit``: which episodes of a suite a
    command runs, where to, and how long one may take."""
    p.add_argument("--suite", required=True, help=f"shipped suite name {suite_names()} or the path of a suite .yaml")
    p.add_argument("--out", type=Path, required=True, help="output directory DIR")
    p.add_argument("--episodes", type=int, default=None, help="at most N seeds per terrain entry (default: all)")
    p.add_argument("--seed", type=int, default=0, help="offset added to every seed of the suite (default 0)")
    p.add_argument(
        "--episode-wall-limit",
        type=float,
        default=DEFAULT_WALL_TIME_LIMIT,
        help="s of wall-clock time after which an episode is ended as 'wall_time_limit' "
        f"(default {DEFAULT_WALL_TIME_LIMIT:g})",
    )


def add_evaluate_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register the ``evaluate`` subcommand on ``sub`` (its handler is in ``func``)."""
    p = sub.add_parser(
        "evaluate",
        help="run a policy over a terrain suite and write results.json, report.md, plots (and videos)",
        description="Run a policy over every (terrain, seed) of a suite; write each episode's record as it finishes "
        "(DIR/episodes/, DIR/traces/), then DIR/results.json, DIR/report.md and PNG plots built from them. "
        "Exit code 2 on an invalid suite, policy, env kwargs or output directory; 130 when interrupted (the "
        "finished episodes are kept: continue with --resume).",
    )
    p.add_argument(
        "--policy", required=True, help="'zero', 'expert', the path of an SB3 model .zip or of an exported .onnx"
    )
    add_suite_run_arguments(p)
    add_backend_arguments(p)
    p.add_argument(
        "--video",
        action="store_true",
        help="write an MP4 (DIR/videos/) for the first episode of each terrain entry only (MuJoCo offscreen)",
    )
    p.add_argument(
        "--algo",
        choices=SB3_ALGOS,
        default=None,
        help="SB3 class of a model .zip (default: the one its rl_meta.json records, else ppo)",
    )
    p.add_argument(
        "--env-kwargs", default="{}", help="JSON object of extra QuadUneven-v0 arguments, e.g. '{\"frame_skip\": 5}'"
    )
    p.add_argument(
        "--robot",
        default=None,
        help="the robot: a shipped name (quad_uneven_env.robots(): paper, go1, anymal_c, hyq, solo12) or a robot YAML "
        "path; the env kwarg 'robot' (default: the paper's robot); docs/robots.md",
    )
    p.add_argument(
        "--scale-terrain",
        action="store_true",
        help="run the suite at the robot's scale: its lengths (terrain parameters, goal distance) times the robot's "
        "leg length over the paper robot's 0.42 m, its time limit times the square root (the suite's 'scale: "
        "leg_length')",
    )
    p.add_argument(
        "--expert-config",
        default="{}",
        help="JSON object of agents.expert.ExpertConfig fields for --policy expert, e.g. '{\"friction\": 0.8}' "
        "(default: the defaults)",
    )
    p.add_argument(
        "--resume",
        action="store_true",
        help="continue the run recorded in DIR: its finished episodes are kept, the others run (refused if the "
        "suite, policy, env kwargs, --episodes or --seed differ)",
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="DIR may hold an earlier evaluation: delete the files its manifest (DIR/.quad-uneven-manifest.json) "
        "lists first, other files are kept; without it, or --resume, a non-empty DIR is refused",
    )
    p.add_argument(
        "--allow-pickle",
        action="store_true",
        help="load pickled files of a model folder (older runs' *_vecnormalize.pkl); they can run code: trusted only",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=run_evaluate_command)
    return p


def _json_object(text: str, option: str) -> dict:
    """``text`` parsed as a JSON object with distinct keys; :raises ValueError: naming ``option``."""

    def no_duplicates(pairs: list) -> dict:
        keys = [k for k, _ in pairs]
        repeated = sorted({k for k in keys if keys.count(k) > 1})
        if repeated:
            raise ValueError(f"{option}: key(s) {repeated} given more than once")
        return dict(pairs)

    try:
        value = json.loads(text, object_pairs_hook=no_duplicates)
    except json.JSONDecodeError as err:
        raise ValueError(f"{option} is not valid JSON ({err}), got {excerpt(text)}") from None
    if not isinstance(value, dict):
        raise ValueError(f"{option} must be a JSON object, got {excerpt(text)}")
    return value


def _model_file_options(args: argparse.Namespace) -> None:
    """Refuse ``--algo`` and ``--allow-pickle`` for a named policy (they only concern a model .zip)."""
    if args.policy in ("zero", "expert"):
        for option, given in (("--algo", args.algo is not None), ("--allow-pickle", args.allow_pickle)):
            if given:
                raise ValueError(
                    f"{option} is for a model .zip (--policy PATH.zip), got --policy {args.policy!r}: drop {option}"
                )


def _suite_option(name: str) -> Suite:
    """The suite of a ``--suite`` option; :raises SuiteError: naming it."""
    try:
        return load_suite(name)
    except SuiteError as e:
        raise SuiteError(f"invalid suite {name!r}: {e}") from None


def _env_kwargs_option(args: argparse.Namespace) -> dict[str, Any]:
    """The env kwargs of ``--env-kwargs`` with ``--robot`` as ``robot``; :raises ValueError: if they name two robots."""
    env_kwargs = _json_object(args.env_kwargs, "--env-kwargs")
    if args.robot is not None:
        if env_kwargs.get("robot", args.robot) != args.robot:
            raise ValueError(
                f"--robot {excerpt(args.robot)} and --env-kwargs robot {excerpt(env_kwargs['robot'])} differ: give one"
            )
        env_kwargs["robot"] = args.robot
    return env_kwargs


def run_evaluate_command(args: argparse.Namespace) -> int:
    """Handler of ``quad-uneven evaluate``: 0 on success, 2 on an invalid suite, policy or argument."""
    env_kwargs = _env_kwargs_option(args)
    expert_config = _json_object(args.expert_config, "--expert-config")
    if expert_config and args.policy != "expert":
        raise ValueError(f"--expert-config is for --policy expert only, got --policy {args.policy!r}")
    if args.episodes is not None and args.episodes < 1:
        raise ValueError(f"--episodes must be >= 1, got {args.episodes}")
    workers = backend_options(args)["workers"]
    _model_file_options(args)
    if not args.episode_wall_limit > 0:  # also refuses nan
        raise ValueError(f"--episode-wall-limit must be a number > 0 (s), got {args.episode_wall_limit}")
    suite = _suite_option(args.suite)
    if args.scale_terrain:
        suite = dataclasses.replace(suite, scale="leg_length")
    with sigterm_as_keyboard_interrupt():
        results = evaluate(
            suite,
            args.policy,
            args.out,
            episodes=args.episodes,
            seed=args.seed,
            workers=workers,
            video=args.video,
            algo=args.algo,
            env_kwargs=env_kwargs,
            progress=not args.no_progress,
            resume=args.resume,
            overwrite=args.overwrite,
            wall_time_limit=args.episode_wall_limit,
            allow_pickle=args.allow_pickle,
            backend=args.backend,
            address=args.address,
            ship_code=args.ship_code,
            expert_config=expert_config,
        )
    for kind, g in results["summary"]["by_kind"].items():
        speed = g["mean_speed"]
        print(
            f"{kind:16s} success {g['successes']}/{g['episodes']}  mean distance {g['mean_distance']:.2f} m  "
            f"mean speed {speed if speed is None else round(speed, 3)} m/s"
        )
    for g in results["summary"]["by_factor"]:
        if g["factor"] == "friction":
            print(f"friction {g['bin']:9s} success {g['successes']}/{g['episodes']}")
    for t in results["targets"]:
        verdict = "PASS" if t["passed"] else f"FAIL ({t['why_not']})"
        print(f"target {t['target']:18s} entry {t['entry']}: {verdict}")
    for t in results.get("command_targets", []):
        verdict = "PASS" if t["passed"] else f"FAIL ({t['why_not']})"
        measured = ", ".join(f"{k} {v:.4g}" if v is not None else f"{k} -" for k, v in t["measured"].items())
        print(f"target {t['target']}: {measured}: {verdict}")
    print(f"report written to {Path(args.out).resolve()}/report.md")
    return 0


# ------------------------------------------------------------------------------------------- collect
def add_collect_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register the ``collect`` subcommand on ``sub`` (its handler is in ``func``)."""
    p = sub.add_parser(
        "collect",
        help="record the scripted expert over a suite's episodes as a Minari dataset (the 'datasets' extra)",
        description="Run the scripted expert over every (terrain, seed) of a suite as 'quad-uneven evaluate' does and "
        "record each step (observation, action = mean applied torque / motor limit, reward, termination, "
        "truncation, and infos: physics-rate torques, stability, contact forces, the expert's plan) into the "
        "Minari dataset DIR/DATASET_ID/data (load it with MINARI_DATASETS_PATH=DIR, or "
        "agents.datasets.load_collected(DIR); docs/datasets.md). Exit code 2 on an invalid suite, policy, env kwargs "
        "or output directory; 130 when interrupted (the finished episodes are kept: continue with --resume).",
    )
    p.add_argument("--policy", required=True, help="'expert' (the scripted expert; the only policy collect records)")
    add_suite_run_arguments(p)
    add_backend_arguments(p)
    p.add_argument(
        "--env-kwargs", default="{}", help="JSON object of extra QuadUneven-v0 arguments, e.g. '{\"frame_skip\": 5}'"
    )
    p.add_argument(
        "--expert-config",
        default="{}",
        help="JSON object of agents.expert.ExpertConfig fields, e.g. '{\"friction\": 0.8}' (default: the defaults)",
    )
    p.add_argument(
        "--resume",
        action="store_true",
        help="continue the collection recorded in DIR: its finished episodes are kept, the others run (refused if "
        "the suite, env kwargs, expert config, --episodes or --seed differ)",
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="DIR may hold an earlier collection: delete the files its manifest (DIR/.quad-uneven-manifest.json) "
        "lists first, other files are kept; without it, or --resume, a non-empty DIR is refused",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=run_collect_command)
    return p


def run_collect_command(args: argparse.Namespace) -> int:
    """Handler of ``quad-uneven collect``: 0 on success, 2 on an invalid suite, policy, argument or missing extra."""
    from agents.datasets import collect  # its module imports Minari only when it writes

    env_kwargs = _json_object(args.env_kwargs, "--env-kwargs")
    expert_config = _json_object(args.expert_config, "--expert-config")
    if args.episodes is not None and args.episodes < 1:
        raise ValueError(f"--episodes must be >= 1, got {args.episodes}")
    backend = backend_options(args)
    if not args.episode_wall_limit > 0:  # also refuses nan
        raise ValueError(f"--episode-wall-limit must be a number > 0 (s), got {args.episode_wall_limit}")
    if args.policy != "expert":
        raise ValueError(f"--policy must be 'expert' (collect records the scripted expert), got {args.policy!r}")
    suite = _suite_option(args.suite)
    with sigterm_as_keyboard_interrupt():
        summary = collect(
            suite,
            args.out,
            policy=args.policy,
            episodes=args.episodes,
            seed=args.seed,
            env_kwargs=env_kwargs,
            expert_config=expert_config,
            progress=not args.no_progress,
            resume=args.resume,
            overwrite=args.overwrite,
            wall_time_limit=args.episode_wall_limit,
            **backend,
        )
    print(
        f"{summary['episodes']} episodes, {summary['steps']} steps ({summary['successes']} reached the goal) in "
        f"dataset {summary['dataset_id']}: {summary['dataset_path']}"
    )
    return 0


# --------------------------------------------------------------------------------------------- train
def add_train_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register the ``train`` subcommand on ``sub`` (its handler is in ``func``)."""
    p = sub.add_parser(
        "train",
        help="train a residual RL agent (SB3 PPO or SAC) on top of the scripted expert",
        description="Train a residual agent on QuadUnevenResidual-v0 (expert torques + residual_scale x action x "
        "torque limit). Writes DIR/model.zip, DIR/rl_meta.json, DIR/learning_curve.png and more (docs/rl.md). "
        "Options override single fields of the config (default configs/rl/ALGO_residual.yaml). Ctrl-C or SIGTERM "
        "stops training and saves the model (exit code 130). Exit code 2 on an invalid option, config or DIR.",
    )
    p.add_argument("--algo", choices=ALGOS, default=None, help="SB3 algorithm (default: the config's, else ppo)")
    p.add_argument(
        "--terrain",
        nargs="+",
        default=None,
        help="terrain kind, preset or YAML path; several: a mix, each episode on one (default: the config's)",
    )
    p.add_argument(
        "--randomization",
        default=None,
        help="randomization of the training world: a preset (mild, hard), a YAML path, or 'none' (default: the "
        "config's)",
    )
    p.add_argument("--timesteps", type=int, default=None, help="total env steps over all envs")
    p.add_argument("--out", type=Path, required=True, help="output directory DIR")
    p.add_argument("--seed", type=int, default=None, help="seed of the model and envs (default: the config's)")
    p.add_argument("--n-envs", type=int, default=None, help="parallel envs (default: the config's)")
    p.add_argument("--residual-scale", type=float, default=None, help="residual torque per unit action / limit")
    p.add_argument(
        "--residual-legs",
        choices=("all", "stance"),
        default=None,
        help="which legs take the residual: all, or only those whose foot touches the ground (default: the config's)",
    )
    p.add_argument(
        "--residual-basis",
        choices=("torque_limit", "expert_torque"),
        default=None,
        help="a unit of residual action: a fraction of the torque limit, or of the expert's own torque (a gain) "
        "(default: the config's)",
    )
    p.add_argument(
        "--expert-config",
        default=None,
        help="JSON object of agents.expert.ExpertConfig fields for the expert under the residual, e.g. "
        "'{\"adaptation\": \"knee\"}' (replaces the config's expert:; default: the config's)",
    )
    p.add_argument(
        "--robot",
        default=None,
        help="the robot: a shipped name (quad_uneven_env.robots()) or a robot YAML path; sets the config's env_kwargs "
        "robot (default: the config's, else the paper's robot); docs/robots.md",
    )
    p.add_argument(
        "--time-limit-min", type=float, default=None, help="stop (and save) after this many minutes of training"
    )
    p.add_argument("--config", default=None, help="training config YAML (default configs/rl/ALGO_residual.yaml)")
    p.add_argument(
        "--init-from",
        default=None,
        help="continue from a saved model (a run's folder or .zip): its weights, optimizers and observation "
        "statistics; trained for the same env (default: the config's, else a new model)",
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="DIR may hold an earlier run: delete the files its manifest (DIR/.quad-uneven-manifest.json) lists "
        "first, other files are kept; without it a non-empty DIR is refused",
    )
    p.add_argument(
        "--tensorboard", type=Path, default=None, help="log SB3's scalars and our episode figures here (TensorBoard)"
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=run_train_command)
    return p


def run_train_command(args: argparse.Namespace) -> int:
    """Handler of ``quad-uneven train``: 0 on success, 2 on an invalid option or config."""
    terrain = args.terrain if args.terrain is None or len(args.terrain) > 1 else args.terrain[0]
    overrides = {
        "algo": args.algo,
        "terrain": terrain,
        "timesteps": args.timesteps,
        "seed": args.seed,
        "n_envs": args.n_envs,
        "residual_scale": args.residual_scale,
        "residual_legs": args.residual_legs,
        "residual_basis": args.residual_basis,
        "expert": None if args.expert_config is None else _json_object(args.expert_config, "--expert-config"),
        "time_limit_min": args.time_limit_min,
        "init_from": args.init_from,
    }
    cfg = load_train_config(args.config, overrides)
    if not cfg.residual and args.residual_scale is not None:
        raise ValueError(
            f"--residual-scale is for a residual agent; the config {args.config or 'default'!r} has residual: "
            f"false (a policy from scratch): drop --residual-scale {args.residual_scale}"
        )
    if args.randomization is not None:
        randomization = None if args.randomization.lower() == "none" else args.randomization
        cfg = validate(dataclasses.replace(cfg, randomization=randomization))
    if args.robot is not None:
        cfg = validate(dataclasses.replace(cfg, env_kwargs={**cfg.env_kwargs, "robot": args.robot}))
    from agents.rl.training import train  # deferred: SB3, torch and the expert's kernels

    summary = train(
        cfg, args.out, progress=not args.no_progress, tensorboard=args.tensorboard, overwrite=args.overwrite
    )
    if summary["interrupted"]:
        print(f"interrupted: the model trained so far is saved in {Path(summary['model']).resolve()}", file=sys.stderr)
    for key in ("timesteps", "wall_time", "steps_per_s", "episodes", "mean_return", "mean_stability_index",
                "mean_distance", "fall_rate"):  # fmt: skip
        value = summary[key]
        print(f"{key:22s} {round(value, 3) if isinstance(value, float) else value}")
    print(f"model: {Path(summary['model']).resolve()}")
    print(f"learning curve: {(Path(args.out) / 'learning_curve.png').resolve()}")
    return EXIT_INTERRUPTED if summary["interrupted"] else 0


# ------------------------------------------------------------------------------------------- distill
def add_distill_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register the ``distill`` subcommand on ``sub`` (its handler is in ``func``)."""
    p = sub.add_parser(
        "distill",
        help="distil the scripted expert into a network policy (joint_pd, gait clock): behaviour cloning, then DAgger",
        description="Roll out the expert over a suite's episodes (the suite's seeds + --seed-offset: its own seeds "
        "stay held out), fit a PPO policy network to the expert's labels (the plan's joint angles plus the expert's "
        "torque / pd_kp, as joint_pd actions), then run DAgger rounds in which the student acts and the expert labels "
        "the states it visits. Writes DIR/model.zip, model_obs_norm.npz, rl_meta.json (read by evaluate, export and "
        "train --init-from), distill_summary.json and distill_curve.png (docs/rl.md). Exit code 2 on an invalid "
        "option, suite or DIR.",
    )
    p.add_argument("--suite", required=True, help=f"shipped suite name {suite_names()} or the path of a suite .yaml")
    p.add_argument("--out", type=Path, required=True, help="output directory DIR")
    p.add_argument(
        "--budget-min", type=float, default=60.0, help="minutes of wall-clock time after which no round starts (60)"
    )
    p.add_argument("--dagger-rounds", type=int, default=3, help="DAgger rounds after behaviour cloning (default 3)")
    p.add_argument(
        "--beta-decay",
        type=float,
        default=0.5,
        help="the expert acts at a step of round k with probability BETA_DECAY**k (default 0.5)",
    )
    p.add_argument("--episodes", type=int, default=2, help="episodes per suite entry per round (default 2)")
    p.add_argument("--epochs", type=int, default=20, help="passes over the aggregated data after each round (20)")
    p.add_argument(
        "--net-arch", default="256,256", help="comma-separated hidden layer sizes of the policy (default 256,256)"
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the network, minibatches and draws (default 0)")
    p.add_argument(
        "--seed-offset", type=int, default=1000, help="added to the suite's seeds in the rollouts (default 1000)"
    )
    add_backend_arguments(p, "rollout")
    p.add_argument(
        "--env-kwargs",
        default="{}",
        help='JSON object of extra QuadUneven-v0 arguments of the student\'s env, e.g. \'{"robot": "go1"}\'',
    )
    p.add_argument(
        "--robot",
        default=None,
        help="the robot the student learns on: a shipped name (quad_uneven_env.robots()) or a robot YAML path; the "
        "env kwarg 'robot' (default: the paper's robot); the teacher is the expert scaled to it; docs/robots.md",
    )
    p.add_argument(
        "--scale-terrain",
        action="store_true",
        help="roll out the suite at the robot's scale (the suite's 'scale: leg_length', as evaluate --scale-terrain)",
    )
    p.add_argument(
        "--pd-action-scale",
        type=float,
        default=1.0,
        help="rad of joint target per unit of the student's action (default 1.0; Go1 needs 2.0: each round reports the "
        "share of expert labels clipped to +-1, docs/rl.md)",
    )
    p.add_argument(
        "--no-course-frame",
        dest="course_frame",
        action="store_false",
        help="the student does not observe its heading and sideways offset on the course (env course_frame=False)",
    )
    p.add_argument(
        "--height-scan",
        default=None,
        help="JSON object of the student env's height_scan grid, e.g. '{\"resolution\": 0.05}' (size_x, size_y, "
        "resolution in m; default: the env's 1.0 x 0.6 m grid at 0.1 m)",
    )
    p.add_argument(
        "--expert-config",
        default='{"recovery": false}',
        help="JSON object of agents.expert.ExpertConfig fields of the teacher (default '{\"recovery\": false}')",
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="DIR may hold an earlier distillation: delete the files its manifest lists first",
    )
    p.add_argument(
        "--resume",
        action="store_true",
        help="continue the distillation in DIR after its last finished round, with the same options (only "
        "--budget-min, --dagger-rounds and where the rollouts run may change); the same result as an unstopped run",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=run_distill_command)
    return p


MAX_LAYER_SIZE = 4096
"""The widest hidden layer ``--net-arch`` takes."""


def _layer_sizes(text: str, option: str) -> tuple[int, ...]:
    """``"256,256"`` -> (256, 256); :raises ValueError: naming ``option`` unless 1-8 integers in [1, 4096]."""
    parts = text.split(",")
    if not 1 <= len(parts) <= 8 or not all(p.strip().isdigit() and 1 <= int(p) <= MAX_LAYER_SIZE for p in parts):
        raise ValueError(
            f"{option} must be 1 to 8 comma-separated layer sizes in [1, {MAX_LAYER_SIZE}], e.g. 256,256; got "
            f"{excerpt(text)}"
        )
    return tuple(int(p) for p in parts)


def run_distill_command(args: argparse.Namespace) -> int:
    """Handler of ``quad-uneven distill``: 0 on success, 2 on an invalid option, suite or DIR."""
    for name, value, low in (("--dagger-rounds", args.dagger_rounds, 0), ("--episodes", args.episodes, 1),
                             ("--epochs", args.epochs, 1),
                             ("--seed", args.seed, 0), ("--seed-offset", args.seed_offset, 0)):  # fmt: skip
        if value < low:
            raise ValueError(f"{name} must be an integer >= {low}, got {value}")
    if not args.budget_min > 0:  # also refuses nan
        raise ValueError(f"--budget-min must be a number > 0 (min), got {args.budget_min}")
    if not 0.0 <= args.beta_decay <= 1.0:
        raise ValueError(f"--beta-decay must be in [0, 1], got {args.beta_decay}")
    if not 0.0 < args.pd_action_scale <= math.pi:
        raise ValueError(f"--pd-action-scale must be in (0, pi] (rad), got {args.pd_action_scale}")
    expert = _json_object(args.expert_config, "--expert-config")
    net_arch = _layer_sizes(args.net_arch, "--net-arch")
    height_scan = None if args.height_scan is None else _json_object(args.height_scan, "--height-scan")
    env_kwargs = _env_kwargs_option(args)
    backend = backend_options(args)
    suite = _suite_option(args.suite)
    if args.scale_terrain:
        suite = dataclasses.replace(suite, scale="leg_length")
    from agents.rl.distill import DistillConfig, distill  # deferred: SB3 and torch

    cfg = DistillConfig(
        dagger_rounds=args.dagger_rounds, beta_decay=args.beta_decay, episodes=args.episodes, epochs=args.epochs,
        seed=args.seed, seed_offset=args.seed_offset, budget_min=args.budget_min, expert=expert, net_arch=net_arch,
        course_frame=args.course_frame, height_scan=height_scan, env_kwargs=env_kwargs,
        pd_action_scale=args.pd_action_scale, **backend,
    )  # fmt: skip
    try:
        cfg.expert_config()
    except TypeError as err:  # an unknown field
        raise ValueError(f"--expert-config: {err}") from None
    with sigterm_as_keyboard_interrupt():
        summary = distill(
            suite, args.out, cfg, overwrite=args.overwrite, resume=args.resume, progress=not args.no_progress
        )
    print(f"model: {(Path(args.out) / 'model.zip').resolve()}")
    print(f"curve: {(Path(args.out) / 'distill_curve.png').resolve()}")
    print(f"wall time: {summary['wall_time_s']:.0f} s")
    return 0


# -------------------------------------------------------------------------------------------- export
def add_export_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register the ``export`` subcommand on ``sub``."""
    p = sub.add_parser(
        "export",
        help="write a trained agent's deterministic policy as ONNX (observation normalisation folded in)",
        description="Export DIR/model.zip (with its rl_meta.json and observation statistics) as an ONNX graph "
        "obs (N, n_obs) -> action (N, 12), equal to the evaluation's predict; metadata in the ONNX metadata_props.",
    )
    p.add_argument("--policy", type=Path, required=True, help="the SB3 model .zip of a training run")
    p.add_argument("--out", type=Path, required=True, help="the .onnx file to write")
    p.add_argument("--algo", choices=SB3_ALGOS, default=None, help="SB3 class (default: the run's metadata)")
    p.add_argument("--allow-pickle", action="store_true", help="load pickled files of older runs (trusted only)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing --out file")
    p.set_defaults(func=run_export_command)
    return p


def run_export_command(args: argparse.Namespace) -> int:
    """Handler of ``quad-uneven export``: 0 on success, 2 on an unusable model folder."""
    from agents.rl.export import export_onnx
    from agents.rl.model_io import ModelError

    output_file(args.out, overwrite=args.overwrite)
    try:
        path = export_onnx(args.policy, args.out, args.algo, args.allow_pickle, out_field="--out")
    except ImportError as err:
        raise ModelError(f"export needs the 'export' extra (pip install -e \".[export]\"): {err}") from None
    print(f"onnx: {path.resolve()}")
    return 0


# --------------------------------------------------------------------------------------------- paper
def run_paper_command(args: argparse.Namespace) -> int:
    """Handler of ``quad-uneven paper``: 0 on success (also when the robot fell: see paper.json), 2 on bad input."""
    from agents.paper.simulation import PaperRunConfig, run_paper_sim, write_paper_outputs

    config = PaperRunConfig(
        distribution=args.distribution,
        epsilon=args.epsilon,
        duration=args.duration,
        hold=args.hold,
        settle=args.settle,
        seed=args.seed,
    )
    with output_dir(args.out, "paper", keep=True):  # a file or an uncreatable path fails before the run
        run = run_paper_sim(config, progress=not args.no_progress)
        info = write_paper_outputs(run, args.out, fps=args.fps)
    keys = (
        "fell", "min_stability_index_planned_Nm", "min_stability_index_measured_Nm", "time_without_support_s",
        "min_normal_force_stance_N", "max_normal_force_swing_N", "cog_tracking_error_max_m",
        "cog_tracking_error_rms_m", "torque_peak_max_Nm",
    )  # fmt: skip
    for k in keys:
        print(f"{k:34s} {info[k]}")
    print(f"outputs: {Path(args.out).resolve()}")
    return 0


def add_paper_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register the ``paper`` subcommand on ``sub`` (its handler is in ``func``)."""
    p = sub.add_parser(
        "paper",
        help="the paper's §6 cycle in the simulator: Figs 4-9 and paper.json",
        description="Plan the paper's §6 gait cycle on the 'paper' terrain, track it with the computed-torque "
        "controller in QuadUneven-v0, and write Figs 4-9 (PNG, GIF) and DIR/paper.json (key numbers).",
    )
    p.add_argument("--out", type=Path, required=True, help="output directory DIR (created if missing)")
    p.add_argument("--distribution", choices=PAPER_DISTRIBUTIONS, default="qp", help="torque distribution (default qp)")
    p.add_argument("--epsilon", type=float, default=10.0, help="planned stability margin, N m (default 10; paper: 0.1)")
    p.add_argument("--duration", type=float, default=None, help="s of the cycle to run (default: all 6.1 s + hold)")
    p.add_argument("--hold", type=float, default=0.5, help="s holding the final pose after the cycle (default 0.5)")
    p.add_argument("--settle", type=float, default=0.1, help="s holding the start pose first (default 0.1)")
    p.add_argument("--seed", type=int, default=0, help="env reset seed (terrain beyond x = 0.6 m)")
    p.add_argument("--fps", type=float, default=20.0, help="frames per second of the stick animation (default 20)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=run_paper_command)
    return p


def add_plan_paper_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register the ``plan-paper`` subcommand on ``sub``."""
    p = sub.add_parser("plan-paper", help="plan the paper's §6 scenario (no simulator): Figs. 4-6, plan.json")
    p.add_argument("--out", type=Path, required=True, help="output directory (created if missing)")
    p.set_defaults(func=run_plan_paper_command)
    return p


def run_plan_paper_command(args: argparse.Namespace) -> int:
    """Handler of ``quad-uneven plan-paper``."""
    from agents.paper.planned import write_planned_outputs

    with output_dir(args.out, "plan-paper", keep=True):
        info = write_planned_outputs(args.out)
    print(json.dumps({k: info[k] for k in ("min_stability_index_Nm", "junction_jump_max", "swing_min_clearance_m")}))
    return 0


# ---------------------------------------------------------------------------------------- robustness
def add_robustness_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register the ``robustness`` subcommand on ``sub``."""
    from agents.evaluation.robustness import FACTORS

    p = sub.add_parser(
        "robustness",
        help="sweep one factor of the simulated world (others nominal): success rate and stability index curves",
        description="Run the expert (or a policy) on rough terrain for every value of one factor, the rest of the "
        "world nominal; write DIR/robustness_FACTOR.json, DIR/robustness_FACTOR.png and each value's evaluation "
        "under DIR/FACTOR/ (one suite entry per value). With --robot, at the robot's scale: terrain and goal "
        "magnified by its leg length, values written for the paper's robot and scaled as the presets' (payload x "
        "mass ratio). Exit code 2 on invalid input.",
    )
    p.add_argument("--factor", required=True, choices=list(FACTORS), help="the factor to sweep")
    p.add_argument("--out", type=Path, required=True, help="output directory DIR")
    p.add_argument("--workers", type=int, default=1, help="parallel episode processes (default 1)")
    p.add_argument("--seeds", type=int, default=5, help="episodes (seeds 0..N-1) per value (default 5)")
    p.add_argument("--values", default=None, help="comma-separated values in the factor's unit (default: its sweep)")
    p.add_argument("--goal", type=float, default=3.0, help="goal distance along +x (m, default 3)")
    p.add_argument("--policy", default="expert", help="'expert' (default), 'zero' or an SB3 model .zip")
    p.add_argument("--model", choices=("nominal", "oracle"), default=None, help="the expert's model (default nominal)")
    p.add_argument(
        "--expert-config",
        default="{}",
        help='JSON object of agents.expert.ExpertConfig fields for --policy expert, e.g. \'{"adaptation": '
        '"learned"}\' (default: the defaults)',
    )
    p.add_argument(
        "--terrain",
        default=None,
        help="terrain kind, preset (configs/terrain/) or YAML path (default: rough, 5 cm amplitude, 0.6 m wavelength)",
    )
    p.add_argument(
        "--robot",
        default=None,
        help="the robot: a shipped name (quad_uneven_env.robots()) or a robot YAML path; swept at its scale "
        "(default: the paper's robot); docs/robots.md",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=run_robustness_command)
    return p


def _number_list(text: str, option: str) -> list[float]:
    """``text`` as comma-separated finite numbers; :raises ValueError: naming ``option`` and the allowed form."""
    values = []
    for item in (v.strip() for v in text.split(",")):
        try:
            value = float(item)
        except ValueError:
            value = math.nan
        if not math.isfinite(value):
            raise ValueError(
                f"{option} must be comma-separated finite numbers (e.g. 0.8,0.6,0.4), got {excerpt(text)} "
                f"({excerpt(item)} is not)"
            )
        values.append(value)
    return values


def run_robustness_command(args: argparse.Namespace) -> int:
    """Handler of ``quad-uneven robustness``: 0 on success, 2 on invalid input."""
    from agents.evaluation.robustness import robustness_sweep

    values = None if args.values is None else _number_list(args.values, "--values")
    if args.workers < 1:
        raise ValueError(f"--workers must be >= 1, got {args.workers}")
    if args.model is not None and args.policy != "expert":
        raise ValueError(f"--model is the expert's model, for --policy expert only, got --policy {args.policy!r}")
    expert_config = _json_object(args.expert_config, "--expert-config")
    if expert_config and args.policy != "expert":
        raise ValueError(f"--expert-config is for --policy expert only, got --policy {args.policy!r}")
    if args.model is not None:
        if expert_config.get("model", args.model) != args.model:
            raise ValueError(f"--model {args.model} and --expert-config model {excerpt(expert_config['model'])} differ")
        expert_config["model"] = args.model
    terrain = None
    if args.terrain is not None:
        from quad_uneven_env.terrain import parse_terrain_spec

        try:
            spec = parse_terrain_spec(args.terrain)
        except ValueError as err:
            raise ValueError(f"--terrain: {err}") from None
        terrain = {"kind": spec.kind, "params": dict(spec.params)}
    summary = robustness_sweep(
        args.factor,
        args.out,
        values=values,
        seeds=args.seeds,
        workers=args.workers,
        policy=args.policy,
        goal_distance=args.goal,
        terrain=terrain,
        expert_config=expert_config or None,
        robot=args.robot,
        progress=not args.no_progress,
    )
    for pt in summary["points"]:
        index = pt["mean_stability_index"]
        print(
            f"{args.factor} {pt['value']:8g}: success {pt['successes']}/{pt['episodes']}  mean index "
            f"{index if index is None else round(index, 1)} N m"
        )
    print(f"curves: {(Path(args.out) / f'robustness_{args.factor}.png').resolve()}")
    return 0


# ------------------------------------------------------------------------------------------- compare
def add_compare_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register the ``compare`` subcommand on ``sub``."""
    p = sub.add_parser(
        "compare",
        help="two evaluations of the same episodes side by side (e.g. the expert vs expert + residual)",
        description="Pair the episodes of two `quad-uneven evaluate` folders by (entry, seed) and write "
        "DIR/comparison.md, DIR/comparison.json and DIR/comparison.png: success, falls, divergences, stalls, "
        "stability index and residual torque, overall, per entry and per randomization factor, the episodes "
        "whose outcome differs and McNemar's exact test of the paired successes. Several folder pairs (one suite, "
        "other --seed offsets) pool into one comparison. Exit code 2 if the folders do not hold the same episodes.",
    )
    p.add_argument(
        "--baseline",
        type=Path,
        nargs="+",
        required=True,
        help="evaluation folder(s) of the baseline (e.g. the expert); several folders of one suite (other --seed "
        "offsets) are pooled",
    )
    p.add_argument(
        "--candidate",
        type=Path,
        nargs="+",
        required=True,
        help="evaluation folder(s) of the candidate, one per baseline folder, in the same order",
    )
    p.add_argument(
        "--out", type=Path, required=True, help="output directory DIR (created; the comparison's files are replaced)"
    )
    p.set_defaults(func=run_compare_command)
    return p


def run_compare_command(args: argparse.Namespace) -> int:
    """Handler of ``quad-uneven compare``: 0 on success, 2 on folders that cannot be compared."""
    from agents.evaluation.compare import compare_runs, policy_label, write_comparison

    comp = compare_runs(args.baseline, args.candidate)
    paths = write_comparison(comp, args.out)
    for who in ("baseline", "candidate"):
        g = comp["overall"][who]
        print(
            f"{who:9s} {policy_label(comp[who]['policy'])}: success {g['successes']}/{g['episodes']}, "
            f"falls {g['falls']}, divergences {g['divergences']}, stalls {g['stalls']}, "
            f"time index < 0 {g['mean_time_index_negative']:.3f} s"
        )
    paired = comp["overall"]["paired"]
    ratio = paired["failure_ratio"]
    print(
        f"paired: {paired['fixed']} baseline failures fixed, {paired['broken']} baseline successes lost "
        f"(McNemar p = {paired['mcnemar_p']:.3g}); failures {'-' if ratio is None else f'{ratio:.2f}'} x the baseline's"
    )
    if comp["machines_differ"]:
        print(f"warning: the runs were made on different machines ({', '.join(comp['machines_differ'])}); see the page")
    print(f"comparison: {paths['md'].resolve()}")
    return 0


# -------------------------------------------------------------------------------------------- select
def add_select_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register the ``select`` subcommand on ``sub``."""
    p = sub.add_parser(
        "select",
        help="choose a training run's checkpoint on validation episodes; copy it to OUT/selected/",
        description="Evaluate every checkpoint of a 'quad-uneven train' run (DIR/checkpoints/model_<N>_steps.zip) "
        "and its final model on the same validation episodes; rank them by successes, then fewer falls, then more "
        "training steps; copy the best with its statistics and metadata to OUT/selected/ and write "
        "OUT/selection.md, selection.json and selection.png. Evaluations found in OUT are reused or resumed. Use "
        "validation seeds, never the seeds the model will be reported on. Exit code 2 on a run without models or "
        "a bad option.",
    )
    p.add_argument("--run", type=Path, required=True, help="the training run's output directory DIR")
    p.add_argument("--suite", required=True, help=f"shipped suite name {suite_names()} or the path of a suite .yaml")
    p.add_argument(
        "--seed", type=int, required=True, help="offset added to every seed of the suite: the validation seeds"
    )
    p.add_argument("--out", type=Path, default=None, help="output directory OUT (default DIR/selection)")
    p.add_argument("--episodes", type=int, default=None, help="at most N seeds per terrain entry (default: all)")
    p.add_argument("--workers", type=int, default=1, help="parallel episode processes (default 1)")
    p.add_argument(
        "--reference",
        type=Path,
        nargs="+",
        default=[],
        help="evaluation folder(s) of other policies on the same episodes (e.g. the expert's), listed and drawn "
        "beside the candidates",
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="delete the files OUT's manifest lists (earlier evaluations and selection) first; other files are kept",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress output")
    p.set_defaults(func=run_select_command)
    return p


def run_select_command(args: argparse.Namespace) -> int:
    """Handler of ``quad-uneven select``: 0 on success, 2 on a run without models or a bad option."""
    from agents.rl.selection import select_checkpoint

    if args.episodes is not None and args.episodes < 1:
        raise ValueError(f"--episodes must be >= 1, got {args.episodes}")
    if args.workers < 1:
        raise ValueError(f"--workers must be >= 1, got {args.workers}")
    suite = _suite_option(args.suite)
    with sigterm_as_keyboard_interrupt():
        result = select_checkpoint(
            args.run, suite, args.seed, out=args.out, episodes=args.episodes, workers=args.workers,
            overwrite=args.overwrite, progress=not args.no_progress, references=args.reference,
        )  # fmt: skip
    for c in result["candidates"]:
        print(f"{c['name']:24s} success {c['successes']}/{c['episodes']}  falls {c['falls']}  rank {c['rank']}")
    for r in result["references"]:
        print(f"{'reference ' + str(r['policy']):24s} success {r['successes']}/{r['episodes']}  falls {r['falls']}")
    print(f"selected: {result['selected_model']}")
    return 0


# -------------------------------------------------------------------------------------- fit-strength
def add_fit_strength_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register the ``fit-strength`` subcommand on ``sub``."""
    p = sub.add_parser(
        "fit-strength",
        help="collect expert episodes in the extreme world and fit the learned strength estimator",
        description="Run the expert with fixed gains drawn around each joint's ideal one on training seeds of "
        "robust_extreme's terrains, fit the strength estimator of the expert's adaptation 'learned' on four fifths "
        "of the seeds, report it on the rest, then fit it on all and write it (default: over the shipped one, "
        "agents/control/adaptation/data/strength_estimator.npz). Models made with another estimator then refuse to "
        "load. "
        "Exit code 2 on a bad option.",
    )
    p.add_argument("--seeds", default="1000-1199", help="FIRST-LAST: world seeds per terrain entry (default 1000-1199)")
    p.add_argument("--seconds", type=float, default=10.0, help="simulated s per episode (default 10)")
    p.add_argument("--workers", type=int, default=2, help="parallel episode processes (default 2)")
    p.add_argument("--test-every", type=int, default=5, help="every N-th seed reports the fit (default 5)")
    p.add_argument("--out", type=Path, default=None, help="the fitted estimator (.npz; default: the shipped one)")
    p.add_argument("--data", type=Path, default=None, help="also save the samples (.npz) here")
    p.add_argument("--from-data", type=Path, default=None, help="fit samples saved by --data instead of collecting")
    p.add_argument("--plot", type=Path, default=None, help="draw the held-out fit (.png) here")
    p.set_defaults(func=run_fit_strength_command)
    return p


def run_fit_strength_command(args: argparse.Namespace) -> int:
    """Handler of ``quad-uneven fit-strength``: 0 on success, 2 on a bad option."""
    import json

    from agents.control.adaptation.learned import DEFAULT_ESTIMATOR
    from agents.rl.strength_fit import fit_strength_estimator, parse_seeds

    out = DEFAULT_ESTIMATOR if args.out is None else args.out
    seeds = parse_seeds(args.seeds)
    for field, path in (("--out", out), ("--data", args.data), ("--plot", args.plot)):
        if path is not None:
            output_file(path, field)
    with sigterm_as_keyboard_interrupt():
        report = fit_strength_estimator(
            seeds, args.seconds, args.workers, args.test_every, out, args.data, args.from_data, args.plot
        )
    print(json.dumps(report, indent=1))
    print(f"wrote {out}" + ("" if args.plot is None else f" and {args.plot}"))
    return 0


# --------------------------------------------------------------------------------------------- sweep
def add_sweep_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register the ``sweep`` subcommand on ``sub``."""
    p = sub.add_parser(
        "sweep",
        help="a grid of training runs on Ray Tune, each model evaluated on a suite; summary table and plot",
        description="Train every run of a sweep file (a grid or list of training-config fields) as a Ray Tune "
        "trial, exactly as 'quad-uneven train' does, into DIR/runs/NAME/; evaluate every model on the sweep's "
        "suite into DIR/evals/NAME/; write DIR/summary.md, summary.json, summary.csv and summary.png. Needs the "
        "'distributed' extra. Exit code 1 if a run failed (its row says why), 2 on an invalid sweep file or DIR "
        "(docs/distributed.md).",
    )
    p.add_argument("--config", required=True, type=Path, help="the sweep YAML (e.g. configs/sweeps/example.yaml)")
    p.add_argument("--out", type=Path, required=True, help="output directory DIR")
    p.add_argument(
        "--address",
        default=None,
        help="the Ray cluster to join ('auto', HOST:6379 or ray://HOST:10001); default: a local Ray",
    )
    p.add_argument(
        "--ship-code",
        action="store_true",
        help="upload this source tree (packages and configs) to the Ray workers instead of using the package "
        "installed on each node",
    )
    p.add_argument(
        "--num-cpus",
        type=int,
        default=None,
        help=f"CPUs of the local Ray (no --address; default {DEFAULT_LOCAL_CPUS})",
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="DIR may hold an earlier sweep: delete the files its manifest (DIR/.quad-uneven-manifest.json) lists "
        "first (other files are kept)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress output")
    p.set_defaults(func=run_sweep_command)
    return p


def run_sweep_command(args: argparse.Namespace) -> int:
    """Handler of ``quad-uneven sweep``: 0 when every run was trained and evaluated, 1 if one failed, 2 on bad input."""
    from agents.evaluation.ray_backend import import_tune
    from agents.rl.sweep import load_sweep, run_sweep

    import_tune("sweep")
    if args.num_cpus is not None and args.num_cpus < 1:
        raise ValueError(f"--num-cpus must be >= 1, got {args.num_cpus}")
    if args.num_cpus is not None and args.address is not None:
        raise ValueError("--num-cpus is for a local Ray; a cluster given by --address has its own CPUs")
    sweep = load_sweep(args.config)
    summary = run_sweep(
        sweep, args.out, address=args.address, num_cpus=args.num_cpus, overwrite=args.overwrite,
        progress=not args.no_progress, ship_code=args.ship_code,
    )  # fmt: skip
    for row in summary["runs"]:
        e = row["evaluation"]
        index = e["mean_stability_index"]
        index = index if index is None else round(index, 1)
        result = f"success {e['successes']}/{e['episodes']}  mean index {index} N m"
        print(f"{row['name']:40s} {'error: ' + row['error'] if row['error'] else result}")
    print(f"summary: {(Path(args.out) / 'summary.md').resolve()}")
    return 1 if any(row["error"] for row in summary["runs"]) else 0


def add_plot_curves_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register the ``plot-curves`` subcommand on ``sub``."""
    p = sub.add_parser(
        "plot-curves",
        help="several training runs' learning curves in one figure",
        description="Draw the learning curves of several `quad-uneven train` folders side by side: the rolling "
        "mean of the training episodes' return, distance and fall rate, and the evaluations' mean return, against "
        "env steps.",
    )
    p.add_argument("runs", nargs="+", type=Path, metavar="RUN", help="a quad-uneven train output folder")
    p.add_argument("--out", type=Path, required=True, help="the figure (.png)")
    p.add_argument("--labels", nargs="+", default=None, help="one legend label per RUN (default: the folder names)")
    p.add_argument("--title", default="", help="the figure's title")
    p.set_defaults(func=run_plot_curves_command)
    return p


def run_plot_curves_command(args: argparse.Namespace) -> int:
    """Handler of ``quad-uneven plot-curves``: 0, or 2 on bad input."""
    from agents.rl.learning_curve import plot_learning_curves

    labels = args.labels or [run.name for run in args.runs]
    if len(labels) != len(args.runs):
        raise ValueError(f"--labels: {len(labels)} labels for {len(args.runs)} runs; give one per RUN")
    output_file(args.out, suffix=".png")
    out = plot_learning_curves(list(zip(labels, args.runs, strict=True)), args.out, title=args.title)
    print(f"wrote {out}")
    return 0


# ---------------------------------------------------------------------------------------------- main
def build_parser() -> argparse.ArgumentParser:
    """The ``quad-uneven`` parser with every subcommand."""
    parser = ArgumentParser(prog="quad-uneven", description="Quadruped locomotion on uneven terrain")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=ArgumentParser)
    for add in (
        add_demo_parser, add_evaluate_parser, add_collect_parser, add_train_parser, add_export_parser, add_paper_parser,
        add_plan_paper_parser, add_robustness_parser, add_compare_parser, add_select_parser, add_sweep_parser,
        add_fit_strength_parser, add_distill_parser, add_plot_curves_parser, add_baselines_parser,
    ):  # fmt: skip
        add(sub)
    return parser


POLICY_NAMES = ("zero", "expert")
"""The named policies of ``--policy``; any other value is a model's path."""

CONFIG_SUFFIXES = (".yaml", ".yml")
"""A ``--suite``, ``--robot``, ``--terrain`` or ``--randomization`` value with one of these suffixes is a file's path,
any other a shipped name (:func:`quad_uneven_env.config.resolve_config_path`)."""

NAME_OR_PATH = {
    "policy": lambda v: v not in POLICY_NAMES,
    "suite": lambda v: Path(v).suffix in CONFIG_SUFFIXES,
    "robot": lambda v: Path(v).suffix in CONFIG_SUFFIXES,
    "terrain": lambda v: Path(v).suffix in CONFIG_SUFFIXES,
    "randomization": lambda v: Path(v).suffix in CONFIG_SUFFIXES,
    "config": lambda v: True,
    "init_from": lambda v: True,
}
"""Options given as text that name a file: when the value names one."""


def absolute_paths(args: argparse.Namespace) -> argparse.Namespace:
    """``args`` with every path made absolute against the working directory, once, right after parsing.

    Paths (``type=Path`` options, and the text options of :data:`NAME_OR_PATH` when they name a file) then mean the
    same wherever they are used: in worker processes, on Ray nodes, and in libraries that join or change folders.
    Nothing is read or created; ``..`` and symbolic links are kept as written.
    """

    def absolute(value: object, names_file: object = None) -> object:
        if isinstance(value, list):
            return [absolute(v, names_file) for v in value]
        if isinstance(value, Path):
            return value if value.is_absolute() else Path.cwd() / value
        if isinstance(value, str) and names_file is not None and value and names_file(value):
            return value if Path(value).is_absolute() else str(Path.cwd() / value)
        return value

    for dest, value in vars(args).items():
        setattr(args, dest, absolute(value, NAME_OR_PATH.get(dest)))
    return args


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``quad-uneven``: the subcommand's exit code; 2 (one line on stderr) on invalid input."""
    try:
        args = absolute_paths(build_parser().parse_args(argv))
        return args.func(args)
    except ValueError as err:  # every validation error of the library (SuiteError, PolicyError, OutputError, ...)
        print(f"error: {_one_line(err)}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt as err:
        print(_one_line(err) if str(err).startswith("interrupted") else "interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED


if __name__ == "__main__":
    sys.exit(main())
