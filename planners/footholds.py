"""Foothold selection on the (privileged) height map.

Each leg's nominal foothold is under its hip at the end of the cycle (body moved by the
stride). Candidates on a grid in a window around it are kept when the terrain is locally flat
(plane slope and roughness limits), away from step edges and holes (small height range in a
disc larger than the foot), not at the bottom of a hole (deep below its neighbourhood), and reachable from the hip at
touch-down and at the end of the cycle along the (straight-line) body path; the kept candidate
nearest the nominal point wins. Returns 3-D points on the terrain surface.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from planners.errors import PlanningError
from planners.gait import PAPER_DURATIONS, walk_cycle
from planners.terrain_query import HeightMap, max_height_in_disk
from quad_uneven_env.config import RobotConfig
from quad_uneven_env.constants import LEG_NAMES
from quad_uneven_env.robot.kinematics import hip_positions_B


@dataclasses.dataclass(frozen=True)
class FootholdLimits:
    """Acceptance limits of a foothold (SI units)."""

    window: float = 0.1
    """half width (m) of the square search window around the nominal foothold."""
    step: float = 0.01
    """candidate spacing (m)."""
    max_slope: float = 0.4
    """largest plane slope (rad) under the foot."""
    max_roughness: float = 0.01
    """largest deviation (m) of the terrain from its local plane under the foot."""
    edge_radius: float = 0.045
    """radius (m) of the disc that must hold no step edge or hole."""
    max_step: float = 0.02
    """largest height range (m) within ``edge_radius`` (edges of steps, stones, holes)."""
    max_drop: float = 0.2
    """a candidate more than this (m) below the highest terrain within ``hole_radius`` is in a hole
    (deeper than a stair riser, shallower than the gaps between stepping stones)."""
    hole_radius: float = 0.08
    """radius (m) of the neighbourhood of the hole test."""
    reach: float = 0.97
    """fraction of the stretched leg length allowed from hip to foot site."""


def _patch(terrain: HeightMap, x: np.ndarray, y: np.ndarray, radius: float):
    """(plane slope (rad), roughness (m), height range (m)) in a disc; exact for a ``HeightField``."""
    if hasattr(terrain, "patch_stats"):
        s = terrain.patch_stats(x, y, radius)
        return s.plane_slope, s.roughness, s.height_max - s.height_min
    # Generic height maps: sampled disc.
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
    return slope, np.abs(h - plane).max(axis=-1), h.max(axis=-1) - h.min(axis=-1)


def choose_footholds(
    terrain: HeightMap,
    cfg: RobotConfig,
    feet_start: np.ndarray,
    cog_start: np.ndarray,
    goal_xy: np.ndarray,
    cog_height: float,
    durations: tuple[float, ...] = PAPER_DURATIONS,
    limits: FootholdLimits | None = None,
) -> np.ndarray:
    """Target footholds (4, 3) on the terrain surface for one walk cycle (m, world, leg order).

    :param feet_start: (4, 3) current footholds (m).
    :param cog_start: (3,) COG at the cycle start (m).
    :param goal_xy: (2,) planned COG (x, y) at the cycle end (m).
    :param cog_height: nominal COG height above the footholds (m).
    :raises PlanningError: naming the leg when no candidate in the window is acceptable.
    """
    lim = limits or FootholdLimits()
    hips = hip_positions_B(cfg)
    cog_start = np.asarray(cog_start, dtype=float)
    goal_xy = np.asarray(goal_xy, dtype=float)
    nominal = goal_xy + hips[:, :2]
    h_nom = terrain.height(nominal[:, 0], nominal[:, 1])
    # Body height at the end: nominal above the mean, but the lowest foothold must stay in reach (stairs).
    z_goal = float(min(np.mean(h_nom), np.min(h_nom) + 0.02)) + cog_height
    phases = walk_cycle(durations)
    total = phases[-1].t_end
    offs = np.arange(-lim.window, lim.window + 1e-9, lim.step)
    gx, gy = np.meshgrid(offs, offs, indexing="ij")
    gx, gy = gx.ravel(), gy.ravel()
    out = np.zeros((4, 3))
    for i, leg in enumerate(LEG_NAMES):
        x, y = nominal[i, 0] + gx, nominal[i, 1] + gy
        h = terrain.height(x, y)
        slope, rough, rng_h = _patch(terrain, x, y, lim.edge_radius)
        ok = (slope <= lim.max_slope) & (rough <= lim.max_roughness) & (rng_h <= lim.max_step)
        ok &= h >= max_height_in_disk(terrain, np.column_stack([x, y]), lim.hole_radius) - lim.max_drop
        # Sphere must rest on this spot without the surroundings lifting it; on a slope the
        # uphill side of the disc is legitimately higher by up to radius * tan(slope).
        ok &= max_height_in_disk(terrain, np.column_stack([x, y]), cfg.foot_radius) <= (
            h + 0.005 + cfg.foot_radius * np.tan(slope)
        )
        # Reach from the hip at touch-down and at the end of the cycle (straight-line body path).
        t_touch = next(p.t_end for p in phases if p.swing_leg == leg)
        site = np.column_stack([x, y, h + cfg.foot_radius])
        for frac in (t_touch / total, 1.0):
            # Height: the COG optimiser may lower the body early (stairs down), so no higher than the goal.
            z_body = min(cog_start[2] + frac * (z_goal - cog_start[2]), z_goal)
            body = np.append(cog_start[:2] + frac * (goal_xy - cog_start[:2]), z_body)
            dist = np.linalg.norm(site - (body + hips[i]), axis=1)
            ok &= dist <= lim.reach * cfg.leg_length
        if not np.any(ok):
            raise PlanningError(
                f"footholds: no acceptable foothold for {leg} within {lim.window} m of the nominal "
                f"{nominal[i].round(3).tolist()} (flat, edge-free, reachable); {int(np.sum(slope <= lim.max_slope))} "
                f"candidates pass the slope limit, {int(np.sum(rng_h <= lim.max_step))} the edge limit"
            )
        cost = gx**2 + gy**2 + 0.01 * slope + 0.5 * rough
        k = int(np.argmin(np.where(ok, cost, np.inf)))
        out[i] = (x[k], y[k], h[k])
    return out
