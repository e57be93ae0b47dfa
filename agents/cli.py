"""The ``quad-uneven`` command line: ``demo``, ``evaluate``, ``train``, ``paper`` (see ``--help`` of each)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from agents.evaluate import add_evaluate_parser, evaluate
from agents.paper_sim import add_paper_parser
from agents.suites import suite_from_dict
from agents.train_cli import add_train_parser


def demo(out: Path, terrain: str, seed: int, distance: float, video: bool) -> dict:
    """The expert walks ``distance`` m over ``terrain``; report, plots and video go to ``out``.

    :return: the episode record of results.json.
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
    results = evaluate(suite, "expert", out, video=video)
    return results["episodes"][0]


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``quad-uneven``."""
    parser = argparse.ArgumentParser(prog="quad-uneven", description="Quadruped locomotion on uneven terrain")
    sub = parser.add_subparsers(dest="command", required=True)
    p_demo = sub.add_parser("demo", help="the scripted expert walks the default rough terrain; writes a report")
    p_demo.add_argument("--out", type=Path, default=Path("out/demo"), help="output directory (default out/demo)")
    p_demo.add_argument("--terrain", default="rough", help="terrain kind with its defaults (default: rough)")
    p_demo.add_argument("--seed", type=int, default=0, help="terrain seed")
    p_demo.add_argument("--distance", type=float, default=2.0, help="goal distance along +x (m)")
    p_demo.add_argument("--no-video", action="store_true", help="skip the MP4 (rendering is the slow part)")
    add_evaluate_parser(sub)
    add_train_parser(sub)
    add_paper_parser(sub)
    p_plan = sub.add_parser("plan-paper", help="plan the paper's §6 scenario (no simulator): Figs. 4-6, plan.json")
    p_plan.add_argument("--out", required=True, help="output directory (created if missing)")
    args = parser.parse_args(argv)
    if args.command == "plan-paper":
        from planners.paper_figures import main as plan_paper

        return plan_paper(["--out", args.out])
    if getattr(args, "func", None) is not None:
        return args.func(args)
    if args.command == "demo":
        ep = demo(args.out, args.terrain, args.seed, args.distance, not args.no_video)
        keys = ("terrain", "seed", "success", "distance", "sim_time", "mean_speed", "min_stability_index",
                "mean_stability_index", "time_index_negative", "cost_of_transport", "fall_reason",
                "planner_ms_median")  # fmt: skip
        for k in keys:
            print(f"{k:24s} {ep.get(k)}")
        print(f"report: {(args.out / 'report.md').resolve()}")
        for video in sorted((args.out / "videos").glob("*.mp4")):
            print(f"video:  {video.resolve()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
