"""Planning speed and success: COG time per gait cycle, swing time per leg, fraction solved.

Usage: ``.venv/bin/python benchmarks/planning.py [--robot NAME] [--cycles 50] [--fd-cycles 10] [--slsqp-cycles N]
[--seed 0]``

For each terrain (rough, amplitude 5 cm; stepping stones; a 25 deg slope; stones with 15 cm gaps
and +-5 cm tops), ``--cycles`` random gait cycles:
a random start position on the course, feet on the surface under the hips, footholds chosen
automatically, the COG goal above them. Each problem is solved by the SQP (default solver), by
plain SLSQP with analytic gradients and by SLSQP with finite-difference gradients (the
reference, on the first ``--fd-cycles`` problems: it is slow) in the same run. Prints a
Markdown table.

``--robot NAME`` (a shipped robot or a robot YAML; default ``paper``) plans for that robot as the expert sees it
(:func:`planners.robot_geometry.robot_geometry` of its description) on the same terrains magnified by its scale
``s`` = leg length / 0.42 m (:func:`agents.evaluation.suites.scale_terrain_params`), with the settings above scaled
by the expert's rules (:meth:`agents.expert.ExpertConfig.for_robot`: the phases, swing clearance, stability margin,
COG height and the start area in proportion to the robot's expert settings over the paper robot's). The paper
robot's problems are the same with or without ``--robot paper``, and only its run adds the continuous-walking
table.
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

from planners import PAPER_DURATIONS, PlanningError, Scenario, choose_footholds, plan_gait_cycle  # noqa: E402
from quad_uneven_env.robot.description import load_robot  # noqa: E402
from quad_uneven_env.terrain import Terrain, parse_terrain_spec  # noqa: E402

TERRAINS = {
    "rough (5 cm)": {"kind": "rough", "amplitude": 0.05},
    "stepping stones": {"kind": "stepping_stones"},
    "slope 25 deg": {"kind": "slope", "angle_deg": 25, "ramp_length": 1.2, "plateau_length": 0.5},
    "stones, 15 cm gaps": {"kind": "stepping_stones", "gap": 0.15, "height_jitter": 0.1},
}


def _paper_feet_xy() -> np.ndarray:
    return load_robot("paper").hip_positions_B[:, :2]


@dataclasses.dataclass(frozen=True)
class Setting:
    """The random cycles' settings for one robot (the paper robot's: the values below)."""

    robot: object = None
    """the robot as the planners see it (None: the paper's Table 1)."""
    feet_xy_B: np.ndarray = dataclasses.field(default_factory=lambda: _paper_feet_xy())
    """(4, 2) m, the standing feet in the trunk frame."""
    scale: float = 1.0
    """-, lengths (terrain, start area) x scale."""
    cog_height: float = 0.36
    """m, COG above the mean foothold."""
    epsilon: float = 0.1
    """N m, the stability margin."""
    clearance: float = 0.05
    """m, swing clearance."""
    durations: tuple[float, ...] = PAPER_DURATIONS
    """s, the seven phases."""


def robot_setting(name: str) -> Setting:
    """The paper robot's :class:`Setting` scaled to robot ``name`` by the expert's rules (the paper's: unchanged)."""
    from agents.expert.config import ExpertConfig
    from planners.robot_geometry import robot_geometry

    desc = load_robot(name)
    paper, mine = ExpertConfig(), ExpertConfig.for_robot(desc)
    geometry = robot_geometry(desc)
    t = sum(mine.durations) / sum(paper.durations)
    base = Setting()
    return Setting(
        robot=geometry,
        feet_xy_B=geometry.feet_B[:, :2].copy(),
        scale=geometry.scale,
        cog_height=base.cog_height * mine.cog_height / paper.cog_height,
        epsilon=base.epsilon * mine.epsilon / paper.epsilon,
        clearance=base.clearance * mine.clearance / paper.clearance,
        durations=tuple(max(round(d * t, 2), 0.01) for d in base.durations),
    )


def robot_terrain(spec: dict, setting: Setting) -> dict:
    """``spec`` magnified by the robot's scale (every length of the terrain, the grid's included)."""
    if setting.scale == 1.0:
        return spec
    from agents.evaluation.suites import scale_terrain_params

    kind = spec["kind"]
    return {"kind": kind, **scale_terrain_params(kind, {k: v for k, v in spec.items() if k != "kind"}, setting.scale)}


def random_scenario(hf, cfg, rng: np.random.Generator, setting: Setting | None = None) -> Scenario:
    """A cycle starting at a random x on the course with the feet under the hips (lengths x the robot's scale)."""
    st = setting or Setting()
    s, h = st.scale, st.cog_height
    robot = cfg if st.robot is None else st.robot
    (x0, x1), _ = hf.extent
    bx = rng.uniform(max(x0 + 1.0 * s, 0.0), min(x1 - 1.5 * s, 4.0 * s))
    by = rng.uniform(-0.2 * s, 0.2 * s)
    feet = np.column_stack([st.feet_xy_B + np.array([bx, by]), np.zeros(4)])
    feet[:, 2] = hf.height(feet[:, 0], feet[:, 1])
    # Start on acceptable footholds near the hips (on stepping stones, not in the gaps).
    cog0 = np.array([bx, by, feet[:, 2].mean() + h])
    feet = choose_footholds(hf, robot, feet, cog0, np.array([bx, by]), h, st.durations)
    cog = np.array([*feet[:, :2].mean(axis=0), feet[:, 2].mean() + h])
    return Scenario(
        terrain=hf, feet_start=feet, cog_start={"pos": cog}, epsilon=st.epsilon, clearance=st.clearance,
        durations=st.durations, cog_height=h, robot=st.robot,
    )  # fmt: skip


def pct(a, q):
    return float(np.percentile(a, q)) * 1e3 if len(a) else float("nan")


def main() -> str:
    """Run the table of random cycles; return the robot's name (``--robot``)."""
    ap = argparse.ArgumentParser()
    ap.add_argument("--cycles", type=int, default=50)
    ap.add_argument("--fd-cycles", type=int, default=10)
    ap.add_argument("--slsqp-cycles", type=int, default=None, help="cycles also solved by SLSQP (default: all)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--robot", default="paper", help="a shipped robot or a robot YAML (default: paper)")
    args = ap.parse_args()
    cfg = load_robot("paper")
    setting = robot_setting(args.robot)
    rng = np.random.default_rng(args.seed)
    rows = []
    if setting.robot is not None:
        print(f"robot {args.robot}: lengths x {setting.scale:.3f}, cycle {sum(setting.durations):.2f} s\n")
    for name, spec in TERRAINS.items():
        spec = robot_terrain(spec, setting)
        hf = Terrain(parse_terrain_spec(spec)).generate(np.random.default_rng(int(rng.integers(1 << 31))))
        cog_t, swing_t, total_t, slsqp_t, fd_t, iters = [], [], [], [], [], []
        solved, dev_slsqp, dev_fd, failures = 0, [], [], []
        for k in range(args.cycles + 1):  # the first cycle only warms the caches
            try:
                sc = random_scenario(hf, cfg, rng, setting)
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
        "cycle total median / p95 (ms) | SLSQP analytic median / p95 (ms) | SLSQP finite-diff median (ms) "
        "| max |ΔP| vs SLSQP (mm) |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for name, n, solved, cog_t, swing_t, total_t, slsqp_t, fd_t, iters, dev_s, dev_f, _ in rows:
        print(
            f"| {name} | {solved}/{n} ({100 * solved / n:.0f} %) | {pct(cog_t, 50):.1f} / {pct(cog_t, 95):.1f} | "
            f"{np.mean(iters) if iters else float('nan'):.2f} | {pct(swing_t, 50):.2f} | "
            f"{pct(total_t, 50):.1f} / {pct(total_t, 95):.1f} | "
            f"{pct(slsqp_t, 50):.1f} / {pct(slsqp_t, 95):.1f} | {pct(fd_t, 50):.0f} (n={len(fd_t)}) | "
            f"{1e3 * max(dev_s + dev_f, default=float('nan')):.3f} |"
        )
    for name, *_, failures in rows:
        for f in failures[:5]:
            print(f"- {name} failure: {f}")
    return args.robot


def walk(n_cycles: int = 16) -> None:
    """Continuous walking: chain cycles (each starts where the last ended), footholds chosen automatically."""
    cfg = load_robot("paper")
    print(f"\n| terrain (seed 0) | cycles planned in a row (of {n_cycles}) | distance (m) | first failure |")
    print("|---|---|---|---|")
    for spec in ("flat", "rough", "slope", "stairs", {"kind": "stairs", "riser": 0.1}, "stepping_stones", "paper"):
        terr = Terrain(parse_terrain_spec(spec))
        hf = terr.generate(np.random.default_rng(0))
        sx, sy = terr.spawn_xy
        feet = np.column_stack([cfg.hip_positions_B[:, :2] + [sx, sy], np.zeros(4)])
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
    if main() == "paper":
        walk()
