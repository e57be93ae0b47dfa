"""Planning speed and success: COG time per gait cycle, swing time per leg, fraction solved.

Usage: ``.venv/bin/python benchmarks/planning.py [--cycles 50] [--fd-cycles 10] [--slsqp-cycles N] [--seed 0]``

For each terrain (rough, amplitude 5 cm; stepping stones; a 25 deg slope; stones with 15 cm gaps
and +-5 cm tops), ``--cycles`` random gait cycles:
a random start position on the course, feet on the surface under the hips, footholds chosen
automatically, the COG goal above them. Each problem is solved by the SQP (default solver), by
plain SLSQP with analytic gradients and by SLSQP with finite-difference gradients (the
reference, on the first ``--fd-cycles`` problems: it is slow) in the same run. Prints a
Markdown table.
"""

from __future__ import annotations

import os

# The planner's matrices are small (~117 x 600): multi-threaded BLAS only adds overhead (and
# thrashes on a loaded machine). One thread, unless the caller set it.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import dataclasses  # noqa: E402

import numpy as np  # noqa: E402

from planners import PlanningError, Scenario, choose_footholds, plan_gait_cycle  # noqa: E402
from quad_uneven_env.config import load_robot_config  # noqa: E402
from quad_uneven_env.robot.kinematics import hip_positions_B  # noqa: E402
from quad_uneven_env.terrain import Terrain, parse_terrain_spec  # noqa: E402

TERRAINS = {
    "rough (5 cm)": {"kind": "rough", "amplitude": 0.05},
    "stepping stones": {"kind": "stepping_stones"},
    "slope 25 deg": {"kind": "slope", "angle_deg": 25, "ramp_length": 1.2, "plateau_length": 0.5},
    "stones, 15 cm gaps": {"kind": "stepping_stones", "gap": 0.15, "height_jitter": 0.1},
}


def random_scenario(hf, cfg, rng: np.random.Generator) -> Scenario:
    """A cycle starting at a random x on the course with the feet under the hips."""
    (x0, x1), _ = hf.extent
    bx = rng.uniform(max(x0 + 1.0, 0.0), min(x1 - 1.5, 4.0))
    by = rng.uniform(-0.2, 0.2)
    feet = np.column_stack([hip_positions_B(cfg)[:, :2] + [bx, by], np.zeros(4)])
    feet[:, 2] = hf.height(feet[:, 0], feet[:, 1])
    # Start on acceptable footholds near the hips (on stepping stones, not in the gaps).
    feet = choose_footholds(hf, cfg, feet, np.array([bx, by, feet[:, 2].mean() + 0.36]), np.array([bx, by]), 0.36)
    cog = np.array([*feet[:, :2].mean(axis=0), feet[:, 2].mean() + 0.36])
    return Scenario(terrain=hf, feet_start=feet, cog_start={"pos": cog}, epsilon=0.1, clearance=0.05)


def pct(a, q):
    return float(np.percentile(a, q)) * 1e3 if len(a) else float("nan")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--cycles", type=int, default=50)
    ap.add_argument("--fd-cycles", type=int, default=10)
    ap.add_argument("--slsqp-cycles", type=int, default=None, help="cycles also solved by SLSQP (default: all)")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    cfg = load_robot_config("paper")
    rng = np.random.default_rng(args.seed)
    rows = []
    for name, spec in TERRAINS.items():
        hf = Terrain(parse_terrain_spec(spec)).generate(np.random.default_rng(int(rng.integers(1 << 31))))
        cog_t, swing_t, total_t, slsqp_t, fd_t, iters = [], [], [], [], [], []
        solved, dev_slsqp, dev_fd, failures = 0, [], [], []
        for k in range(args.cycles + 1):  # the first cycle only warms the caches
            try:
                sc = random_scenario(hf, cfg, rng)
                plan = plan_gait_cycle(sc)
                if k == 0:
                    continue
            except PlanningError as err:
                if k > 0:
                    failures.append(str(err)[:150])
                continue
            solved += 1
            cog_t.append(plan.stats["cog_solve_time"])
            swing_t.append(plan.stats["swing_solve_time"] / 4.0)
            total_t.append(plan.stats["total_time"])
            iters.append(plan.stats["iterations"])
            # Same COG problem with the baselines (footholds fixed to the ones chosen).
            fixed = dataclasses.replace(sc, footholds=plan.footholds)
            t_grid = np.linspace(0, plan.duration, 601)
            for method, times, devs, limit in (
                ("slsqp", slsqp_t, dev_slsqp, args.cycles if args.slsqp_cycles is None else args.slsqp_cycles),
                ("slsqp-fd", fd_t, dev_fd, args.fd_cycles),
            ):
                if len(times) >= limit:
                    continue
                try:
                    other = plan_gait_cycle(dataclasses.replace(fixed, method=method))
                except PlanningError:
                    continue
                times.append(other.stats["cog_solve_time"])
                devs.append(np.abs(other.cog.position(t_grid) - plan.cog.position(t_grid)).max())
        rows.append(
            (name, args.cycles, solved, cog_t, swing_t, total_t, slsqp_t, fd_t, iters, dev_slsqp, dev_fd, failures)
        )

    print(
        "| terrain | solved | COG SQP median / p95 (ms) | SQP iters (mean) | swing per leg median (ms) | "
        "cycle total median (ms) | SLSQP analytic median / p95 (ms) | SLSQP finite-diff median (ms) "
        "| max |ΔP| vs SLSQP (mm) |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for name, n, solved, cog_t, swing_t, total_t, slsqp_t, fd_t, iters, dev_s, dev_f, _ in rows:
        print(
            f"| {name} | {solved}/{n} ({100 * solved / n:.0f} %) | {pct(cog_t, 50):.1f} / {pct(cog_t, 95):.1f} | "
            f"{np.mean(iters) if iters else float('nan'):.2f} | {pct(swing_t, 50):.2f} | {pct(total_t, 50):.1f} | "
            f"{pct(slsqp_t, 50):.1f} / {pct(slsqp_t, 95):.1f} | {pct(fd_t, 50):.0f} (n={len(fd_t)}) | "
            f"{1e3 * max(dev_s + dev_f, default=float('nan')):.3f} |"
        )
    for name, *_, failures in rows:
        for f in failures[:5]:
            print(f"- {name} failure: {f}")


def walk(n_cycles: int = 16) -> None:
    """Continuous walking: chain cycles (each starts where the last ended), footholds chosen automatically."""
    cfg = load_robot_config("paper")
    print(f"\n| terrain (seed 0) | cycles planned in a row (of {n_cycles}) | distance (m) | first failure |")
    print("|---|---|---|---|")
    for spec in ("flat", "rough", "slope", "stairs", {"kind": "stairs", "riser": 0.1}, "stepping_stones", "paper"):
        terr = Terrain(parse_terrain_spec(spec))
        hf = terr.generate(np.random.default_rng(0))
        sx, sy = terr.spawn_xy
        feet = np.column_stack([hip_positions_B(cfg)[:, :2] + [sx, sy], np.zeros(4)])
        feet[:, 2] = hf.height(feet[:, 0], feet[:, 1])
        if spec == "paper":
            from quad_uneven_env.terrain import PAPER_BLOCKS

            feet = np.array(PAPER_BLOCKS["start"])
        cog = {"pos": np.array([*feet[:, :2].mean(0), feet[:, 2].mean() + 0.36])}
        x0, ok, why = cog["pos"][0], 0, ""
        for _ in range(n_cycles):
            sc = Scenario(
                terrain=hf, feet_start=feet, cog_start=cog, durations=(0.4, 0.8, 0.8, 0.2, 0.8, 0.8, 0.4), epsilon=5.0
            )
            try:
                plan = plan_gait_cycle(sc)
            except PlanningError as err:
                why = str(err)[:120]
                break
            ok += 1
            end = np.array([plan.duration])
            feet = plan.footholds
            cog = {
                "pos": plan.cog.position(end)[0],
                "vel": plan.cog.velocity(end)[0],
                "acc": plan.cog.acceleration(end)[0],
            }
        print(f"| {spec} | {ok} | {cog['pos'][0] - x0:.2f} | {why} |")


if __name__ == "__main__":
    main()
    walk()
