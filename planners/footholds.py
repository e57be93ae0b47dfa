"""Foothold selection on the (privileged) height map: a best-first search over the leg's workspace.

Each leg's nominal foothold is under its hip at the end of the cycle (body moved by the stride).
Candidates lie on a grid (``FootholdLimits.step``) over a square of half width
``FootholdLimits.reach_window`` around it, searched shell by shell: first the inner window
(``window``), then square rings ``ring`` wide further out. A candidate is **acceptable** when it
passes, in this order (the failure message names the first test no candidate passes):

1. ``slope``: the least-squares plane of the terrain in the edge disc (``edge_radius``) is at most
   ``max_slope`` steep;
2. ``edge``: no node of that disc lies more than ``max_edge`` from the plane. An edge is a break in
   the surface (a step, a stone's border, a hole): it leaves nodes off the local plane. A uniform
   slope has none, however steep, so it passes (a raw height range in the disc would not);
3. ``hole``: not more than ``max_drop`` below the highest terrain within ``hole_radius``;
4. ``foot rest``: the foot sphere rests on the spot without the surroundings lifting it;
5. ``reach``: the foot site is within ``reach`` of the stretched leg from the hip at touch-down and
   at the end of the cycle along the (straight-line) body path, with the hips level or pitched (see
   ``pitch_start``);
6. ``shank clearance``: the stance leg's shank clears the terrain in both poses (a foot just past a
   step edge would rest its shank on the nosing).

Among the acceptable candidates the cheapest wins (:func:`foothold_costs`): squared distance from the
nominal point, plus the plane slope, the local roughness (plane residual in the edge disc), the
nearness of an edge (plane residual in the larger ``clear_radius`` disc), the kinematic margin (hip
to foot distance beyond ``reach_comfort`` of the leg) and a shank-clearance margin
(``shank_margin``). Every term is >= 0 and the distance term grows with the shell, so the search
stops at the first shell whose nearest point already costs more than the best candidate found: on
ordinary ground only the inner window is evaluated. The shank clearance, the costly test, is
computed only for the cheapest candidates (best first), never for the whole grid.
Returns 3-D points on the terrain surface.
"""

from __future__ import annotations

import dataclasses
import functools
import itertools

import numpy as np

from planners.gait import PAPER_DURATIONS, walk_cycle
from planners.pitch import BodyPitch, planar_rotation, terrain_pitch
from planners.robot_geometry import RobotGeometry, robot_geometry
from planners.terrain_query import capsule_clearance, max_height_in_disk
from planners.types import FootholdError, HeightMap
from quad_uneven_env.constants import LEG_NAMES
from quad_uneven_env.fields import check_fields, param
from quad_uneven_env.robot.description import RobotDescription

SHANK_RADIUS_SCALE = 0.7
"""shank capsule radius / ``RobotDescription.link_radius`` (as built by :mod:`quad_uneven_env.robot.model`)."""

FOOTHOLD_TESTS: tuple[str, ...] = ("slope", "edge", "hole", "foot rest", "reach", "shank clearance")
"""The acceptance tests of a candidate foothold, in the order they are applied."""


@dataclasses.dataclass(frozen=True)
class FootholdLimits:
    """Acceptance limits and cost weights of a foothold (SI units)."""

    window: float = param(0.1, "m", lo=0.0, hi=1.0, lo_open=True)
    """half width (m) of the inner square searched first around the nominal foothold."""
    reach_window: float = param(0.25, "m", lo=0.0, hi=1.0, lo_open=True)
    """half width (m) of the whole search square; the reach test cuts it down to the leg's workspace."""
    ring: float = param(0.05, "m", lo=0.0, hi=1.0, lo_open=True)
    """width (m) of each square ring searched after the inner window."""
    step: float = param(0.01, "m", lo=0.001, hi=0.1)
    """candidate spacing (m)."""
    max_slope: float = param(0.5, "rad", lo=0.0, hi=1.5)
    """largest plane slope (rad) under the foot (0.5 rad = 28.6 deg)."""
    max_edge: float = param(0.01, "m", lo=0.0, hi=1.0)
    """largest distance (m, along z) of a terrain node within ``edge_radius`` from the disc's
    least-squares plane: an edge, a hole's border or a bump under the foot; 0 on any plane."""
    edge_radius: float = param(0.045, "m", lo=0.0, hi=0.5, lo_open=True)
    """radius (m) of the disc that must hold no edge (the plane fit of the slope and edge tests)."""
    clear_radius: float = param(0.09, "m", lo=0.0, hi=0.5, lo_open=True)
    """radius (m) of the disc whose plane residual is the edge-nearness cost (an edge within it costs)."""
    max_drop: float = param(0.2, "m", lo=0.0, hi=10.0)
    """a candidate more than this (m) below the highest terrain within ``hole_radius`` is in a hole
    (deeper than a stair riser, shallower than the gaps between stepping stones)."""
    hole_radius: float = param(0.08, "m", lo=0.0, hi=0.5, lo_open=True)
    """radius (m) of the neighbourhood of the hole test."""
    reach: float = param(0.97, "-", lo=0.0, hi=1.0, lo_open=True)
    """fraction of the stretched leg length allowed from hip to foot site."""
    shank_clearance: float = param(0.005, "m", lo=-1.0, hi=0.1)
    """smallest gap (m) between the stance leg's shank capsule and the terrain at touch-down and at
    the end of the cycle: a foot just past a step edge (or a knee folded below its foot) would rest
    the shank on the nosing and unload the foot."""
    w_slope: float = param(0.01, "1/rad", lo=0.0)
    """cost (1/rad) of the plane slope."""
    w_roughness: float = param(0.5, "1/m", lo=0.0)
    """cost (1/m) of the plane residual in the edge disc (local roughness)."""
    w_edge: float = param(0.1, "1/m", lo=0.0)
    """cost (1/m) of the plane residual in the ``clear_radius`` disc (nearness of an edge)."""
    reach_comfort: float = param(0.9, "-", lo=0.0, hi=1.0)
    """fraction of the stretched leg length beyond which the kinematic-margin cost starts."""
    w_reach: float = param(1.0, "-", lo=0.0)
    """cost (-) of the squared hip-to-site distance fraction beyond ``reach_comfort``."""
    shank_margin: float = param(0.01, "m", lo=0.0, hi=0.1)
    """shank gap (m) below which the shank-margin cost starts."""
    w_shank: float = param(0.5, "1/m", lo=0.0)
    """cost (1/m) of the shank gap missing to ``shank_margin``."""

    def __post_init__(self) -> None:
        check_fields(self)
        if self.window > self.reach_window:
            raise ValueError(
                f"FootholdLimits.window must be <= reach_window = {self.reach_window:g} (m), got {self.window:g}"
            )


def _plane_fit(terrain: HeightMap, x: np.ndarray, y: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """(plane slope (rad), largest node distance (m, along z) from the plane) of the terrain in a disc.

    Exact least-squares plane for a ``HeightField`` (its ``patch_stats``); for other height maps
    the plane through the centre with the centre's normal, against a sampled disc.
    """
    if hasattr(terrain, "patch_stats"):
        s = terrain.patch_stats(x, y, radius)
        return s.plane_slope, s.roughness
    ang = np.linspace(0.0, 2 * np.pi, 12, endpoint=False)
    px = x[..., None] + np.concatenate([[0.0], radius * np.cos(ang), 0.5 * radius * np.cos(ang)])
    py = y[..., None] + np.concatenate([[0.0], radius * np.sin(ang), 0.5 * radius * np.sin(ang)])
    h = terrain.height(px, py)
    n = terrain.normal(x, y)
    slope = np.arccos(np.clip(n[..., 2], -1.0, 1.0))
    plane = (
        terrain.height(x, y)[..., None]
        - (n[..., 0:1] * (px - x[..., None]) + n[..., 1:2] * (py - y[..., None])) / n[..., 2:3]
    )
    return slope, np.abs(h - plane).max(axis=-1)


def foothold_costs(
    terrain: HeightMap,
    x: np.ndarray,
    y: np.ndarray,
    nominal_xy: np.ndarray,
    foot_radius: float,
    limits: FootholdLimits | None = None,
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Terrain part of the foothold cost (-) of candidates at world (x, y) (m, 1-D arrays), and its tests.

    :param nominal_xy: (2,) the nominal foothold (m, world).
    :param foot_radius: foot sphere radius (m), for the foot-rest test.
    :return: ``cost`` = squared distance (m^2) from the nominal + ``w_slope`` plane slope +
        ``w_roughness`` plane residual in the edge disc + ``w_edge`` :func:`edge_nearness`, and the
        boolean masks ``slope``, ``edge``, ``hole``, ``foot rest`` of the terrain tests (each on its own,
        not cumulative). :func:`choose_footholds` adds the kinematic and shank terms.
    """
    lim = limits or FootholdLimits()
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    cost, tests = _terrain_terms(terrain, x, y, np.asarray(nominal_xy, dtype=float), foot_radius, lim)
    return cost + lim.w_edge * edge_nearness(terrain, x, y, lim), tests


def edge_nearness(terrain: HeightMap, x: np.ndarray, y: np.ndarray, limits: FootholdLimits | None = None) -> np.ndarray:
    """Plane residual (m) of the terrain in the ``clear_radius`` disc around world (x, y) (m): 0 on a plane
    (however steep), about the step height when an edge lies within the disc."""
    lim = limits or FootholdLimits()
    return _plane_fit(terrain, np.asarray(x, dtype=float), np.asarray(y, dtype=float), lim.clear_radius)[1]


def _terrain_terms(terrain, x, y, nominal_xy, foot_radius, lim):
    """:func:`foothold_costs` without the edge-nearness term (the dearest to compute)."""
    h = terrain.height(x, y)
    slope, rough = _plane_fit(terrain, x, y, lim.edge_radius)
    xy = np.column_stack([x.ravel(), y.ravel()])
    tests = {
        "slope": slope <= lim.max_slope,
        "edge": rough <= lim.max_edge,
        "hole": h >= max_height_in_disk(terrain, xy, lim.hole_radius).reshape(h.shape) - lim.max_drop,
        # The sphere must rest on this spot without the surroundings lifting it; on a slope the
        # uphill side of the disc is legitimately higher by up to radius * tan(slope).
        "foot rest": max_height_in_disk(terrain, xy, foot_radius).reshape(h.shape)
        <= h + 0.005 + foot_radius * np.tan(slope),
    }
    d2 = (x - nominal_xy[0]) ** 2 + (y - nominal_xy[1]) ** 2
    return d2 + lim.w_slope * slope + lim.w_roughness * rough, tests


def shank_clearance(
    terrain: HeightMap,
    cfg: RobotDescription | RobotGeometry,
    leg: str,
    site: np.ndarray,
    hip: np.ndarray,
    R: np.ndarray,
) -> np.ndarray:
    """Lower bound (m) of the gap between the shank capsule of ``leg`` and the terrain.

    :param cfg: the robot.
    :param site: (N, 3) foot-site positions (m, world).
    :param hip: (3,) or (N, 3) hip (HAA origin) position (m, world).
    :param R: (3, 3) base orientation R_WB.
    :return: (N,) gap (m); the knee comes from the leg's IK (its knee branch) for that hip and site.
    """
    site = np.asarray(site, dtype=float).reshape(-1, 3)
    hip = np.asarray(hip, dtype=float)
    geom = robot_geometry(cfg)
    i = LEG_NAMES.index(leg)
    q = geom.leg_ik(i, (site - hip) @ R)
    knee = hip + geom.knee(i, q) @ R.T
    low_end = site + (knee - site) * (geom.foot_radius / geom.shank_length)  # it stops short of the foot sphere
    return capsule_clearance(terrain, low_end, knee, SHANK_RADIUS_SCALE * geom.link_radius)


@functools.lru_cache(maxsize=8)
def _search_shells(lim: FootholdLimits) -> list[tuple[float, np.ndarray]]:
    """Grid offsets (K, 2) (m) of each shell and the smallest distance (m) from the nominal of its points.

    Shell 0 is the inner square (Chebyshev distance <= ``window``), then square rings ``ring`` wide
    up to ``reach_window``.
    """
    offs = np.arange(-lim.reach_window, lim.reach_window + 1e-9, lim.step)
    gx, gy = np.meshgrid(offs, offs, indexing="ij")
    grid = np.column_stack([gx.ravel(), gy.ravel()])
    cheb = np.abs(grid).max(axis=1)
    edges = [-1.0, lim.window + 1e-9]
    while edges[-1] < lim.reach_window:
        edges.append(edges[-1] + lim.ring)
    shells = []
    for lo, hi in itertools.pairwise(edges):
        sel = (cheb > lo) & (cheb <= hi)
        if np.any(sel):
            shells.append((float(cheb[sel].min()), grid[sel]))
    return shells


class _LegSearch:
    """Best-first search of one leg's foothold over the shells; counts what every test kept."""

    def __init__(self, terrain, cfg, leg, nominal_xy, poses, lim):
        self.terrain, self.cfg, self.leg, self.nominal, self.poses, self.lim = (
            terrain, cfg, leg, nominal_xy, poses, lim
        )  # fmt: skip
        self.best: np.ndarray | None = None
        self.best_cost = np.inf
        self.evaluated = 0
        self.passed = dict.fromkeys(FOOTHOLD_TESTS, 0)  # candidates passing every test up to this one
        self.slope_blocked = 0  # candidates failing the slope test alone (of those before shank clearance)

    def shell(self, offsets: np.ndarray) -> None:
        """Evaluate one shell of grid ``offsets`` (K, 2) (m) and keep its cheapest acceptable candidate.

        The cheap terms and tests run on the whole shell; the edge-nearness and shank terms (both >= 0)
        only on candidates, cheapest first, whose cheap cost is below the best full cost found so far.
        """
        lim, cfg = self.lim, self.cfg
        x, y = self.nominal[0] + offsets[:, 0], self.nominal[1] + offsets[:, 1]
        cost, tests = _terrain_terms(self.terrain, x, y, self.nominal, cfg.foot_radius, lim)
        h = self.terrain.height(x, y)
        site = np.column_stack([x, y, h + cfg.foot_radius])
        frac = np.max([np.linalg.norm(site - sh, axis=1) for sh, _, _ in self.poses], axis=0) / cfg.leg_length
        tests["reach"] = frac <= lim.reach
        cost = cost + lim.w_reach * np.maximum(frac - lim.reach_comfort, 0.0) ** 2
        self.evaluated += len(x)
        ok = np.ones(len(x), dtype=bool)
        for name in FOOTHOLD_TESTS[1:-1]:
            ok &= tests[name]
        self.slope_blocked += int(np.count_nonzero(ok & ~tests["slope"]))
        ok = np.ones(len(x), dtype=bool)
        for name in FOOTHOLD_TESTS[:-1]:
            ok &= tests[name]
            self.passed[name] += int(np.count_nonzero(ok))
        cand = np.flatnonzero(ok & (cost < self.best_cost))
        order = cand[np.argsort(cost[cand], kind="stable")]
        start, batch = 0, 4
        while start < len(order):
            idx = order[start : start + batch]
            start, batch = start + batch, 2 * batch  # growing batches: few calls where many candidates fail
            if cost[idx[0]] >= self.best_cost:
                break  # every remaining candidate costs at least this much before its last two terms
            full = cost[idx] + lim.w_edge * edge_nearness(self.terrain, x[idx], y[idx], lim)
            idx, full = idx[full < self.best_cost], full[full < self.best_cost]
            if len(idx) == 0:
                continue
            gap = np.full(len(idx), np.inf)
            for _, hip, R in self.poses:  # the next pose only where the previous ones clear
                live = gap >= lim.shank_clearance
                if np.any(live):
                    more = shank_clearance(self.terrain, cfg, self.leg, site[idx[live]], hip, R)
                    gap[live] = np.minimum(gap[live], more)
            clear = gap >= lim.shank_clearance
            self.passed["shank clearance"] += int(np.count_nonzero(clear))
            full = np.where(clear, full + lim.w_shank * np.maximum(lim.shank_margin - gap, 0.0), np.inf)
            j = int(np.argmin(full))
            if full[j] < self.best_cost:
                self.best_cost = float(full[j])
                self.best = np.array([x[idx[j]], y[idx[j]], h[idx[j]]])

    def failed_test(self) -> str:
        """The first acceptance test that no candidate passed."""
        return next((n for n in FOOTHOLD_TESTS if self.passed[n] == 0), FOOTHOLD_TESTS[-1])

    def failure(self) -> str:
        """Why no candidate is acceptable: the first test that none passed, and what each test kept."""
        kept = ", ".join(f"{self.passed[n]} {n}" for n in FOOTHOLD_TESTS)
        return (
            f"failed test: {self.failed_test()}; of {self.evaluated} candidates, passing each test and all before "
            f"it: {kept}; {self.slope_blocked} fail the slope test alone"
        )


def choose_footholds(
    terrain: HeightMap,
    cfg: RobotDescription | RobotGeometry,
    feet_start: np.ndarray,
    cog_start: np.ndarray,
    goal_xy: np.ndarray,
    cog_height: float,
    durations: tuple[float, ...] = PAPER_DURATIONS,
    limits: FootholdLimits | None = None,
    pitch_start: float | None = None,
    yaw_start: float = 0.0,
    yaw_end: float = 0.0,
) -> np.ndarray:
    """Target footholds (4, 3) on the terrain surface for one walk cycle (m, world, leg order).

    Each leg's nominal foothold lies under its standing foot point (the paper's robot: its hip) with the body
    at the goal; the reach test measures from the leg's shoulder (:mod:`planners.robot_geometry`).

    :param feet_start: (4, 3) current footholds (m).
    :param cog_start: (3,) COG at the cycle start (m).
    :param goal_xy: (2,) planned COG (x, y) at the cycle end (m).
    :param cog_height: nominal COG height above the footholds (m).
    :param pitch_start: None: the body stays level (the paper); else its pitch (rad) at the start,
        going to the slope of the nominal footholds by the end (:class:`planners.pitch.BodyPitch`).
    :param yaw_start, yaw_end: body yaw (rad, about world z) at the start and the end of the cycle: each
        nominal foothold is under its hip turned by ``yaw_end`` about the goal COG, and the reach and
        shank tests see the hips turning from ``yaw_start`` to ``yaw_end``; the pitch is the slope
        along the end heading.
    :raises FootholdError: (a PlanningError) naming the leg and the first test no candidate within reach passes.
    """
    lim = limits or FootholdLimits()
    cfg = robot_geometry(cfg)
    hips, shoulders, feet_B = cfg.hips_B, cfg.shoulders_B, cfg.feet_B
    cog_start = np.asarray(cog_start, dtype=float)
    goal_xy = np.asarray(goal_xy, dtype=float)
    nominal = goal_xy + (feet_B[:, :2] if yaw_end == 0.0 else feet_B[:, :2] @ planar_rotation(yaw_end).T)
    h_nom = terrain.height(nominal[:, 0], nominal[:, 1])
    # A nominal point in a hole (a pit between stepping stones) says nothing about where the feet will
    # stand: take the terrain around it instead, for the body height and pitch.
    around = max_height_in_disk(terrain, nominal, lim.hole_radius)
    h_nom = np.where(h_nom < around - lim.max_drop, around, h_nom)
    # Body height at the end: nominal above the mean, but the lowest foothold must stay in reach (stairs).
    z_goal = float(min(np.mean(h_nom), np.min(h_nom) + 0.02)) + cog_height
    phases = walk_cycle(durations)
    total = phases[-1].t_end
    pitch = None
    if pitch_start is not None:
        end = terrain_pitch(np.column_stack([nominal, h_nom]), yaw=yaw_end)
        pitch = BodyPitch(pitch_start, end, total, yaw_start, yaw_end)
    elif yaw_start != 0.0 or yaw_end != 0.0:
        pitch = BodyPitch(0.0, 0.0, total, yaw_start, yaw_end)
    shells = _search_shells(lim)
    out = np.zeros((4, 3))
    for i, leg in enumerate(LEG_NAMES):
        # Hip at touch-down and at the end of the cycle (straight-line body path).
        t_touch = next(p.t_end for p in phases if p.swing_leg == leg)
        poses = []
        for frac in (t_touch / total, 1.0):
            # Height: the COG optimiser may lower the body early (stairs down), so no higher than the goal.
            z_body = min(cog_start[2] + frac * (z_goal - cog_start[2]), z_goal)
            body = np.append(cog_start[:2] + frac * (goal_xy - cog_start[:2]), z_body)
            R = np.eye(3) if pitch is None else pitch.rotation(np.array(frac * total))
            poses.append((body + R @ shoulders[i], body + R @ hips[i], R))
        search = _LegSearch(terrain, cfg, leg, nominal[i], poses, lim)
        for d_min, offsets in shells:
            if search.best_cost <= d_min**2:
                break  # the distance term alone makes every further candidate dearer
            search.shell(offsets)
        if search.best is None:
            raise FootholdError(
                f"footholds: no acceptable foothold for {leg} within {lim.reach_window} m of the nominal "
                f"{nominal[i].round(3).tolist()}: {search.failure()}",
                search.failed_test(),
                search.slope_blocked,
            )
        out[i] = search.best
    return out
