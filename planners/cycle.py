"""One gait cycle end to end: footholds -> COG path -> swing paths (paper §3-5), pure functions."""

from __future__ import annotations

import dataclasses
import time
from typing import Any

import numpy as np

from planners.blas import single_blas_thread
from planners.cog import CogProblem, CogStats, plan_cog
from planners.footholds import choose_footholds
from planners.gait import Phase, phase_index, walk_cycle
from planners.geometry import clip_convex, convex_hull_ccw, polygon_centroid
from planners.pitch import BodyPitch, terrain_pitch
from planners.polynomial import PiecewisePolynomial
from planners.robot_geometry import RobotGeometry
from planners.scenario import Scenario
from planners.swing import SwingPath, plan_swing
from planners.terrain_query import foot_site_on
from planners.types import HeightMap
from planners.wholebody import WholeBody
from quad_uneven_env.constants import LEG_NAMES
from quad_uneven_env.stability import stability_index

STANCE_REACH = 0.96
"""fraction of the stretched leg length a stance leg may reach (knee bent >= ~0.55 rad)."""
REACH_MARGIN = 0.99
"""fraction of the stretched leg length allowed for swing knots."""


@dataclasses.dataclass(frozen=True)
class GaitCyclePlan:
    """A planned walk cycle (times in s from the cycle start, world frame, SI units)."""

    phases: tuple[Phase, ...]
    """the 7 phases with stance flags and swing leg."""
    cog: PiecewisePolynomial
    """whole-robot COG path: ``position(t)``, ``velocity(t)``, ``acceleration(t)`` -> (T, 3)."""
    swing: dict[str, SwingPath]
    """foot-site swing path per leg name over that leg's swing phase."""
    feet_start: np.ndarray
    """(4, 3) footholds (surface points, m) at the start."""
    footholds: np.ndarray
    """(4, 3) target footholds (surface points, m)."""
    targets: np.ndarray
    """(6, 3) desired COG points at the junctions (m)."""
    terrain: HeightMap
    """the height map planned on."""
    mass: float
    """mass (kg) used in the stability index."""
    epsilon: float
    """stability margin (N m)."""
    foot_radius: float
    """foot sphere radius (m)."""
    stats: dict[str, Any]
    """cog_solve_time (s), swing_solve_time (s), total_time (s), iterations, refinements,
    min_stability (N m), min_clearance (m), method."""
    robot: RobotGeometry | None = None
    """the robot planned for (the reference's default)."""
    pitch: BodyPitch | None = None
    """the base pitch and yaw over the cycle; None: level and unturned (identity orientation, the paper)."""

    @property
    def duration(self) -> float:
        """Cycle length (s)."""
        return self.phases[-1].t_end

    def feet_in_phase(self, k: int) -> np.ndarray:
        """(4, 3) footholds (surface points) of every leg during phase ``k`` (a swing leg: its lift-off)."""
        return np.where(np.asarray(self.phases[k].moved)[:, None], self.footholds, self.feet_start)

    def stability(self, t: np.ndarray) -> np.ndarray:
        """Stability index (N m) of the planned COG at times ``t`` (s) over each phase's support polygon.

        Computed with ``quad_uneven_env.stability.stability_index``; a junction time is judged
        against the later phase.
        """
        t = np.atleast_1d(np.asarray(t, dtype=float))
        out = np.empty(t.shape)
        idx = phase_index(self.phases, t)
        p, a = self.cog.position(t), self.cog.acceleration(t)
        for k, ph in enumerate(self.phases):
            sel = idx == k
            if np.any(sel):
                feet = self.feet_in_phase(k)[np.asarray(ph.stance)]
                out[sel] = stability_index(p[sel], a[sel], feet, self.mass)[0]
        return out

    def reference(self, cfg=None):
        """The joint reference for the controller (:class:`planners.reference.Reference`); cfg: the robot (default:
        the one planned for)."""
        from planners.reference import Reference

        return Reference(self, cfg or self.robot)


def _junction_targets(phases, feet_phase, cog_height: float) -> np.ndarray:
    """Desired COG points at the junctions (m).

    Horizontal: the centroid of the overlap of the support polygons of the nearest three-leg
    phases on either side of the junction (four-leg phases are skipped: around the short middle
    support this is the diagonal both triangles share, where the COG has to cross). Height:
    ``cog_height`` above the mean foothold height at the junction.
    """
    swing_k = [k for k, p in enumerate(phases) if p.swing_leg is not None]
    out = []
    for j in range(len(phases) - 1):
        before = [k for k in swing_k if k <= j][-1:] or [j]
        after = [k for k in swing_k if k >= j + 1][:1] or [j + 1]
        polys = [convex_hull_ccw(feet_phase[k][np.asarray(phases[k].stance)][:, :2]) for k in (before[0], after[0])]
        inter = clip_convex(polys[0], polys[1])
        if len(inter) == 0:
            xy = 0.5 * (polys[0].mean(0) + polys[1].mean(0))
        else:
            xy = polygon_centroid(inter)
        z = feet_phase[j + 1][:, 2].mean() + cog_height
        out.append([xy[0], xy[1], z])
    return np.array(out)


@single_blas_thread
def plan_gait_cycle(scenario: Scenario) -> GaitCyclePlan:
    """Plan one walk cycle: footholds (given or chosen), stable COG path, collision-free swings.

    :raises PlanningError: naming the phase and support edge (COG) or the leg (swing) when infeasible.
    """
    t_all = time.perf_counter()
    cfg = scenario.robot_geometry()
    terrain = scenario.height_map()
    mass = float(scenario.mass or cfg.mass)
    phases = walk_cycle(scenario.durations, order=scenario.swing_order)
    start = np.asarray(scenario.feet_start, dtype=float)
    wb = WholeBody(cfg)
    q_nom = cfg.standing_legs(min(scenario.cog_height, 0.95 * cfg.leg_length))
    com_to_base = -wb.com_offset(q_nom)  # base minus whole-body COM (m), nominal pose
    cog0 = scenario.start_boundary()
    follow = scenario.body_pitch == "terrain"
    yaw0, yaw1 = scenario.yaw_start, scenario.yaw_start + scenario.turn
    if scenario.footholds is not None:
        target = np.asarray(scenario.footholds, dtype=float)
    else:
        goal_xy = cog0[0, :2] + np.asarray(scenario.stride)
        target = choose_footholds(
            terrain, cfg, start, cog0[0], goal_xy, scenario.cog_height,
            limits=scenario.foothold_limits, pitch_start=scenario.pitch_start if follow else None,
            yaw_start=yaw0, yaw_end=yaw1,
        )  # fmt: skip
    pitch = None
    if follow or yaw0 != 0.0 or yaw1 != 0.0:
        pitch = BodyPitch(
            scenario.pitch_start if follow else 0.0,
            terrain_pitch(target, yaw=yaw1) if follow else 0.0,
            phases[-1].t_end, yaw0, yaw1,
        )  # fmt: skip
    rotation = None if pitch is None else pitch.rotation
    hips_com = cfg.hips_B + com_to_base  # HAA origins minus whole-body COM (m, base frame): the leg IK's origin
    hip_offsets = cfg.shoulders_B + com_to_base  # shoulders (reach centres) minus whole-body COM (m, base frame)

    def hips_at(t: float) -> np.ndarray:
        """(4, 3) shoulders minus COG (m, world) at plan time ``t`` (s)."""
        return hip_offsets if rotation is None else hip_offsets @ rotation(np.array(t)).T

    goal = scenario.goal_boundary()
    if goal is None:
        goal = np.zeros((3, 3))
        goal[0, :2] = target[:, :2].mean(axis=0)
        goal[0, 2] = target[:, 2].mean() + scenario.cog_height
        # ... but low enough for every leg to reach its foothold (stairs: the hind feet a step lower).
        sites_end = foot_site_on(terrain, target, cfg.foot_radius)
        hips_end = hips_at(phases[-1].t_end)
        horiz = np.linalg.norm(goal[0, :2] + hips_end[:, :2] - sites_end[:, :2], axis=1)
        reach_end = STANCE_REACH * cfg.leg_length - 0.005
        z_max = sites_end[:, 2] - hips_end[:, 2] + np.sqrt(np.maximum(reach_end**2 - horiz**2, 0.0))
        goal[0, 2] = min(goal[0, 2], float(z_max.min()))
    feet_phase = [np.where(np.asarray(p.moved)[:, None], target, start) for p in phases]
    supports = [f[np.asarray(p.stance)] for f, p in zip(feet_phase, phases, strict=True)]
    names = [[leg for leg, s in zip(LEG_NAMES, p.stance, strict=True) if s] for p in phases]
    targets = _junction_targets(phases, feet_phase, scenario.cog_height)
    t_knots = np.array([phases[0].t_start] + [p.t_end for p in phases])
    r = cfg.foot_radius
    sites = [foot_site_on(terrain, s, r) for s in supports]
    offsets = [hip_offsets[np.asarray(p.stance)] for p in phases]
    # The given start and goal COGs may already ask for more reach (e.g. a measured state): never
    # let the reach limit make the boundary itself infeasible.
    # The goal's need is capped at REACH_MARGIN; the start's is not: a measured start (the planner's
    # nominal hips differ from the real ones by a centimetre or two with stretched legs) that already
    # exceeds the cap would otherwise fail every replan from it, and the robot would stand still forever.
    need = []
    for k, c, t in ((0, cog0[0], 0.0), (len(phases) - 1, goal[0], phases[-1].t_end)):
        hips_k = hips_at(t)[np.asarray(phases[k].stance)]
        need.append(float(np.linalg.norm(c + hips_k - sites[k], axis=1).max()) + 1e-3)
    reach = max(min(max(STANCE_REACH * cfg.leg_length, need[1]), REACH_MARGIN * cfg.leg_length), need[0])
    problem = CogProblem(
        t_knots, supports, names, targets, cog0, goal, mass, scenario.epsilon,
        tuple(scenario.weights), scenario.smoothing, [p.name() for p in phases],
        sites, offsets, reach, rotation,
    )  # fmt: skip
    cog, cstats = plan_cog(problem, method=scenario.method)
    t_sw = time.perf_counter()
    swings: dict[str, SwingPath] = {}
    for ph in phases:
        if ph.swing_leg is None:
            continue
        i = LEG_NAMES.index(ph.swing_leg)
        hip = hip_offsets[i]

        def hip_path(t, hip=hip):
            return cog.position(t) + (hip if rotation is None else rotation(np.asarray(t)) @ hip)

        def range_excess(t, sites, i=i):
            return _joint_range_excess(cfg, i, cog.position(t), rotation, t, hips_com[i], sites)

        # Two-link legs (the paper's robot) are planned as the paper plans them (reach only); a chain model's swing
        # knots are also tested against its joint ranges.
        joint_test = range_excess if cfg.tests_joint_ranges else None

        swings[ph.swing_leg] = plan_swing(
            ph.swing_leg, foot_site_on(terrain, start[i], r), foot_site_on(terrain, target[i], r),
            ph.t_start, ph.t_end, terrain, scenario.clearance, r, hip_path,
            (cfg.min_reach, REACH_MARGIN * cfg.leg_length), range_excess=joint_test,
        )  # fmt: skip
    t_end = time.perf_counter()
    stats = _stats(cstats, t_end - t_sw, t_end - t_all, swings)
    return GaitCyclePlan(
        phases, cog, swings, start, target, targets, terrain, mass, scenario.epsilon, r, stats, cfg, pitch
    )  # fmt: skip


def _joint_range_excess(
    cfg: RobotGeometry, i: int, cog: np.ndarray, rotation, t: np.ndarray, hip: np.ndarray, sites: np.ndarray
) -> np.ndarray:
    """How far (rad) leg ``i``'s joints pass their ranges (<= 0: inside) with its foot site at ``sites`` (K, M, 3)
    (world, m) and the base at the planned COG ``cog`` (K, 3) at times ``t`` (K,) (s), turned by ``rotation``
    (None: level); ``hip``: the leg's HAA origin minus the whole-body COM (base frame, nominal pose). (K, M)."""
    if rotation is None:
        R = np.broadcast_to(np.eye(3), (len(t), 3, 3))
    else:
        R = np.broadcast_to(rotation(np.asarray(t)), (len(t), 3, 3))
    hip_W = cog + R @ hip  # (K, 3)
    e_B = np.einsum("kji,kmj->kmi", R, sites - hip_W[:, None])  # R^T (site - hip)
    q = cfg.leg_ik(i, e_B)
    lo, hi = cfg.joint_ranges[3 * i : 3 * i + 3].T  # type: ignore[index]
    return np.maximum(q - hi, lo - q).max(axis=-1)


def _stats(c: CogStats, swing_time: float, total: float, swings: dict[str, SwingPath]) -> dict[str, Any]:
    return {
        "cog_solve_time": c.solve_time,
        "swing_solve_time": swing_time,
        "total_time": total,
        "iterations": c.iterations,
        "refinements": c.refinements,
        "min_stability": c.min_stability,
        "min_clearance": min((s.min_clearance for s in swings.values()), default=np.inf),
        "n_constraints": c.n_constraints,
        "method": c.method,
    }
