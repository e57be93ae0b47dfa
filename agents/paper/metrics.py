"""Key numbers of a simulated §6 run (:class:`agents.paper.simulation.PaperRun`) -> ``paper.json``."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from quad_uneven_env.constants import JOINT_NAMES, LEG_NAMES

TRANSITION_WINDOW = 0.02
"""s before and after a planned lift-off or touch-down that the "_settled" force figures leave out (the
contact force of a lifting foot decays over a few ms, a landing foot touches a few ms early or late)."""


def time_to_switch(time: np.ndarray, stance: np.ndarray) -> np.ndarray:
    """(N, 4) s from each sample to the nearest change of that leg's planned stance flag (inf if none).

    :param time: (N,) s, increasing.
    :param stance: (N, 4) bool planned stance.
    """
    time = np.asarray(time, dtype=float)
    stance = np.asarray(stance, dtype=bool)
    out = np.full(stance.shape, np.inf)
    for i in range(stance.shape[1]):
        # a switch happens at the first sample of the new phase
        t_switch = time[1:][stance[1:, i] != stance[:-1, i]]
        if t_switch.size:
            out[:, i] = np.abs(time[:, None] - t_switch[None, :]).min(axis=1)
    return out


def _finite_min(x: np.ndarray) -> float | None:
    x = x[np.isfinite(x)]
    return float(x.min()) if x.size else None


def _max_or(x: np.ndarray, default: float = 0.0) -> float:
    return float(x.max()) if x.size else default


def _min_or_none(x: np.ndarray) -> float | None:
    return float(x.min()) if x.size else None


def summarize(run) -> dict[str, Any]:
    """paper.json content (JSON-safe) of a :class:`agents.paper.simulation.PaperRun`.

    Forces are normal (vertical) forces (N); stance and swing are the PLANNED phases. ``*_settled``
    figures leave out the samples within ``TRANSITION_WINDOW`` s of a planned lift-off or touch-down.
    The measured stability index is ``-inf`` while fewer than three feet touch:
    ``min_stability_index_measured_Nm`` is the minimum over the other samples and
    ``time_without_support_s`` says how long that lasted.
    """
    a, dt = run.arrays, run.dt
    t = a["time"]
    stance = a["stance"]
    fn = a["normal_force"]
    settled = time_to_switch(t, stance) >= TRANSITION_WINDOW
    err = np.linalg.norm(a["cog"] - a["cog_plan"], axis=1)
    index = a["index"]
    peaks = np.abs(a["tau"]).max(axis=0) if len(t) else np.zeros(len(JOINT_NAMES))
    saturated = np.abs(a["tau"]) >= run.torque_limit - 1e-6
    contact = a["contact"]
    plan = run.plan
    landed = t[:, None] >= np.array([plan.swing[leg].t_end for leg in LEG_NAMES])[None, :]
    planned_xy = np.where(landed[..., None], plan.footholds[None, :, :2], plan.feet_start[None, :, :2])
    slip = np.linalg.norm(a["feet"][..., :2] - planned_xy, axis=-1)
    t_dense = np.linspace(0.0, min(plan.duration, max(float(t[-1]), 0.0)) if len(t) else 0.0, 6001)
    return {
        "scenario": "paper §6: footholds PAPER_BLOCKS start -> target, phases 1, 1, 1, 0.1, 1, 1, 1 s",
        "config": dataclasses.asdict(run.config),
        "simulated_time_s": float(t[-1] + dt) if len(t) else 0.0,
        "physics_dt_s": dt,
        "mass_kg": run.mass,
        "fell": run.fall_reason is not None,
        "fall_reason": run.fall_reason,
        "start_foot_site_error_max_m": float(np.abs(run.start_site_error).max()),
        "start_foot_site_error_m": run.start_site_error.tolist(),
        "settle_cog_drift_m": run.settle_cog_drift,
        "epsilon_Nm": plan.epsilon,
        "min_stability_index_planned_Nm": float(plan.stability(t_dense).min()),
        "min_stability_index_measured_Nm": _finite_min(index),
        "time_without_support_s": float(np.count_nonzero(np.isneginf(index)) * dt),
        "time_index_measured_below_epsilon_s": float(np.count_nonzero(~(index > plan.epsilon)) * dt),
        "time_index_measured_negative_s": float(np.count_nonzero(~(index >= 0.0)) * dt),
        "min_normal_force_stance_N": _min_or_none(fn[stance]),
        "min_normal_force_stance_settled_N": _min_or_none(fn[stance & settled]),
        "max_normal_force_swing_N": _max_or(fn[~stance]),
        "max_normal_force_swing_settled_N": _max_or(fn[~stance & settled]),
        "transition_window_s": TRANSITION_WINDOW,
        "stance_without_contact_s": {
            leg: float(np.count_nonzero(stance[:, i] & ~contact[:, i]) * dt) for i, leg in enumerate(LEG_NAMES)
        },
        "swing_with_contact_s": {
            leg: float(np.count_nonzero(~stance[:, i] & contact[:, i]) * dt) for i, leg in enumerate(LEG_NAMES)
        },
        "stance_foot_xy_error_max_m": {
            leg: _max_or(slip[stance[:, i] & settled[:, i], i]) for i, leg in enumerate(LEG_NAMES)
        },
        "cog_tracking_error_max_m": _max_or(err),
        "cog_tracking_error_rms_m": float(np.sqrt(np.mean(err**2))) if len(err) else 0.0,
        "cog_tracking_error_max_xyz_m": np.abs(a["cog"] - a["cog_plan"]).max(axis=0).tolist() if len(t) else None,
        "torque_peaks_Nm": {name: float(p) for name, p in zip(JOINT_NAMES, peaks, strict=True)},
        "torque_peak_max_Nm": float(peaks.max()),
        "torque_limit_Nm": float(run.torque_limit.max()),
        "torque_saturated_fraction": float(saturated.any(axis=1).mean()) if len(t) else 0.0,
        "plan_cog_solve_time_s": float(plan.stats["cog_solve_time"]),
        "plan_min_swing_clearance_m": float(plan.stats["min_clearance"]),
    }
