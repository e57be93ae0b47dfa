"""Foothold selection on the (privileged) height map.

Each leg's nominal foothold is under its hip at the end of the cycle (body moved by the
stride). Candidates on a grid in a window around it are kept when the terrain is locally flat
(plane slope and roughness limits), away from step edges and holes (small height range in a
disc larger than the foot), not at the bottom of a hole (deep below its neighbourhood), and reachable from the hip at
touch-down and at the end of the cycle along the (straight-line) body path, with the hips
level or pitched (see ``pitch_start``), with the shank clear of the terrain in both poses (a
foot just past a step edge would rest its shank on the nosing); the kept candidate nearest
the nominal point wins. Returns 3-D points on the terrain surface.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from planners.gait import PAPER_DURATIONS, walk_cycle
from planners.pitch import BodyPitch, terrain_pitch
from planners.terrain_query import capsule_clearance, max_height_in_disk
from planners.types import HeightMap, PlanningError
from quad_uneven_env.config import RobotConfig
from quad_uneven_env.constants import KNEE_SIGN, LEG_NAMES
from quad_uneven_env.robot.kinematics import hip_positions_B, leg_fk_hip, leg_ik_hip

SHANK_RADIUS_SCALE = 0.7
"""shank capsule radius / ``RobotConfig.link_radius`` (as built by :mod:`quad_uneven_env.robot.model`)."""


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
    shank_clearance: float = 0.005
    """smallest gap (m) between the stance leg's shank capsule and the terrain at touch-down and at
    the end of the cycle: a foot just past a step edge (or a knee folded below its foot) would rest
    the shank on the nosing and unload the foot."""


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


def shank_clearance(
    terrain: HeightMap, cfg: RobotConfig, leg: str, site: np.ndarray, hip: np.ndarray, R: np.ndarray
) -> np.ndarray:
    """Lower bound (m) of the gap between the shank capsule of ``leg`` and the terrain.

    :param site: (N, 3) foot-site positions (m, world).
    :param hip: (3,) or (N, 3) hip position (m, world).
    :param R: (3, 3) base orientation R_WB.
    :return: (N,) gap (m); the knee comes from the leg's IK (its knee branch) for that hip and site.
    """
    site = np.asarray(site, dtype=float).reshape(-1, 3)
    hip = np.asarray(hip, dtype=float)
    l1, l2 = cfg.thigh.length, cfg.shank.length
    q = leg_ik_hip((site - hip) @ R, l1, l2, KNEE_SIGN[leg])
    knee = hip + leg_fk_hip(q, l1, 0.0) @ R.T
    low_end = site + (knee - site) * (cfg.foot_radius / l2)  # the capsule stops short of the foot sphere
    return capsule_clearance(terrain, low_end, knee, SHANK_RADIUS_SCALE * cfg.link_radius)


def _best_clear_candidate(
    terrain: HeightMap,
    cfg: RobotConfig,
    leg: str,
    site: np.ndarray,
    candidates: np.ndarray,
    cost: np.ndarray,
    poses: list[tuple[np.ndarray, np.ndarray]],
    min_gap: float,
    batch: int = 4,
) -> int | None:
    """The cheapest of ``candidates`` whose shank clears the terrain by ``min_gap`` (m) in every pose, or None.

    Candidates are checked in order of cost, ``batch`` at a time (the clearance is the costly test).

    :param poses: (hip position (3,) m, R_WB (3, 3)) at touch-down and at the end of the cycle.
    """
    order = candidates[np.argsort(cost[candidates], kind="stable")]
    for start in range(0, len(order), batch):
        idx = order[start : start + batch]
        clear = np.ones(len(idx), dtype=bool)
        for hip, R in poses:
            clear &= shank_clearance(terrain, cfg, leg, site[idx], hip, R) >= min_gap
        if np.any(clear):
            return int(idx[np.argmax(clear)])
    return None


def choose_footholds(
    terrain: HeightMap,
    cfg: RobotConfig,
    feet_start: np.ndarray,
    cog_start: np.ndarray,
    goal_xy: np.ndarray,
    cog_height: float,
    durations: tuple[float, ...] = PAPER_DURATIONS,
    limits: FootholdLimits | None = None,
    pitch_start: float | None = None,
) -> np.ndarray:
    """Target footholds (4, 3) on the terrain surface for one walk cycle (m, world, leg order).

    :param feet_start: (4, 3) current footholds (m).
    :param cog_start: (3,) COG at the cycle start (m).
    :param goal_xy: (2,) planned COG (x, y) at the cycle end (m).
    :param cog_height: nominal COG height above the footholds (m).
    :param pitch_start: None: the body stays level (the paper); else its pitch (rad) at the start,
        going to the slope of the nominal footholds by the end (:class:`planners.pitch.BodyPitch`).
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
    pitch = None
    if pitch_start is not None:
        pitch = BodyPitch(pitch_start, terrain_pitch(np.column_stack([nominal, h_nom])), total)
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
        poses = []
        for frac in (t_touch / total, 1.0):
            # Height: the COG optimiser may lower the body early (stairs down), so no higher than the goal.
            z_body = min(cog_start[2] + frac * (z_goal - cog_start[2]), z_goal)
            body = np.append(cog_start[:2] + frac * (goal_xy - cog_start[:2]), z_body)
            R = np.eye(3) if pitch is None else pitch.rotation(np.array(frac * total))
            poses.append((body + R @ hips[i], R))
            ok &= np.linalg.norm(site - poses[-1][0], axis=1) <= lim.reach * cfg.leg_length
        cost = gx**2 + gy**2 + 0.01 * slope + 0.5 * rough
        k = _best_clear_candidate(terrain, cfg, leg, site, np.flatnonzero(ok), cost, poses, lim.shank_clearance)
        if k is None:
            raise PlanningError(
                f"footholds: no acceptable foothold for {leg} within {lim.window} m of the nominal "
                f"{nominal[i].round(3).tolist()} (flat, edge-free, reachable, shank clear of the terrain); "
                f"{int(np.sum(slope <= lim.max_slope))} candidates pass the slope limit, "
                f"{int(np.sum(rng_h <= lim.max_step))} the edge limit, {int(np.sum(ok))} all but the shank clearance"
            )
        out[i] = (x[k], y[k], h[k])
    return out
