"""From the env's command to a gait cycle: its phases, its turn and its stride.

Without a command the expert walks ``ExpertConfig.stride`` along +x at its configured phases. With one
(``env.command``: (vx, vy) m/s in the yaw-aligned base frame and a yaw rate, read at the start of every cycle)
the cycle advances by the commanded velocity times its duration and turns by the yaw rate times it; in heading
mode (``env.command_heading``) it turns towards the commanded heading. A command faster than
:data:`MAX_CYCLE_STRIDE` per cycle shortens the phases instead of lengthening the stride.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from quad_uneven_env.spatial import wrap_angle, yaw_of_quat

SIDE_STEP = 1e-3
"""m: a cycle's advance to the left beyond which the expert lifts its left legs first (the mirrored swing order)."""
MAX_TURN = 1.2
"""rad: the largest yaw change the expert plans in one gait cycle (0.39 rad/s with the default 3.1 s cycle)."""
MAX_CYCLE_STRIDE = 0.45
"""m: the longest body advance per cycle the expert plans at its configured phases (0.145 m/s with the
default 3.1 s cycle); a faster command shortens the phases instead (:func:`cycle_durations`)."""
MIN_PHASE = 0.3
"""s: phases are never shortened below this (nor are phases this short or shorter shortened)."""
HEADING_DEADBAND = 1e-3
"""rad: in heading mode, a heading error below this is not turned (the plans stay those of a straight walk)."""


def cycle_durations(durations: tuple[float, ...], command: Sequence[float] | None) -> tuple[float, ...]:
    """s: the phases of the next cycle. ``durations`` (``ExpertConfig.durations``), or, when the commanded speed
    times their cycle would stride further than :data:`MAX_CYCLE_STRIDE`, the same gait faster: its phases longer
    than :data:`MIN_PHASE` (all but the short four-leg one in the middle) scaled down together so that the stride
    is ``MAX_CYCLE_STRIDE``, but none below ``MIN_PHASE``.

    :param command: the env's command (vx, vy, yaw rate), or None.
    """
    if command is None:
        return durations
    stride = float(np.hypot(command[0], command[1])) * sum(durations)
    if stride <= MAX_CYCLE_STRIDE:
        return durations
    long = [k for k, t in enumerate(durations) if t > MIN_PHASE]
    fixed = sum(t for k, t in enumerate(durations) if k not in long)
    moving = sum(durations[k] for k in long)
    scale = (MAX_CYCLE_STRIDE / stride * sum(durations) - fixed) / moving
    scale = max(scale, MIN_PHASE / min(durations[k] for k in long))
    return tuple(t * scale if k in long else t for k, t in enumerate(durations))


def cycle_turn(
    command: Sequence[float] | None, heading: float | None, planned_yaw: float, durations: tuple[float, ...]
) -> float:
    """rad: the body's yaw change over a whole cycle of phases ``durations`` (s): the commanded yaw rate times the
    cycle's duration (0 without a command), capped at :data:`MAX_TURN`. In heading mode (``heading``, rad, not
    None) the turn closes the whole heading error from ``planned_yaw`` (rad) within the cycle, capped the same
    way."""
    if heading is not None:
        error = wrap_angle(heading - planned_yaw)
        return float(np.clip(error, -MAX_TURN, MAX_TURN)) if abs(error) > HEADING_DEADBAND else 0.0
    if command is None or command[2] == 0.0:
        return 0.0
    return float(np.clip(float(command[2]) * sum(durations), -MAX_TURN, MAX_TURN))


def cycle_stride(
    command: Sequence[float] | None,
    stride: float,
    durations: tuple[float, ...],
    quat: np.ndarray,
    turn: float = 0.0,
) -> tuple[float, float]:
    """(dx, dy) m, world: the body's advance over a cycle of phases ``durations`` (s) that turns it by ``turn``
    (rad).

    Without a command: ``stride`` (``ExpertConfig.stride``, m) along +x. With one: the commanded (vx, vy) (m/s,
    yaw-aligned base frame) times the cycle's duration, turned into the world frame by the measured heading
    (of the base quaternion ``quat``, w x y z) plus half the cycle's turn (the mid-cycle heading), and shortened
    to the chord of the arc a constant yaw rate would drive: ``sin(turn / 2) / (turn / 2)``.
    """
    if command is None:
        return (stride, 0.0)
    period = float(sum(durations))
    yaw = yaw_of_quat(quat)
    if turn != 0.0:
        yaw, period = yaw + 0.5 * turn, period * float(np.sin(0.5 * turn) / (0.5 * turn))
    c, s = float(np.cos(yaw)), float(np.sin(yaw))
    vx, vy = float(command[0]), float(command[1])
    return (period * (c * vx - s * vy), period * (s * vx + c * vy))


def fallback_stride(
    stride: tuple[float, float], fraction: float, shift: float, heading: float, turning: bool
) -> tuple[tuple[float, float], str]:
    """One of the strides tried when a plan fails (``STRIDE_FALLBACKS``), and its swing order.

    :param stride: (dx, dy) m, world: the cycle's advance (:func:`cycle_stride`).
    :param fraction: the fraction of it walked.
    :param shift: m: the sideways body shift, to the body's left (world +y when not ``turning``).
    :param heading: rad: the body's mid-cycle yaw (used when ``turning``: the shift and the side stepped to
        are the body's).
    :return: the stride (dx, dy) m, world, and ``"left_first"`` when it advances more than :data:`SIDE_STEP` to
        the body's left (lead with the legs on that side), else ``"right_first"``.
    """
    sx, sy = stride
    if turning:
        c, s = float(np.cos(heading)), float(np.sin(heading))
        step = (fraction * sx - s * shift, fraction * sy + c * shift)
        left = c * step[1] - s * step[0]
    else:
        step = (fraction * sx, fraction * sy + shift)
        left = step[1]
    return step, "left_first" if left > SIDE_STEP else "right_first"
