"""Observation layout and assembly for QuadUneven-v0.

The layout is data (:data:`OBSERVATION_FIELDS`), from which the Box bounds, the
``observation_structure`` mapping and the table in the env docstring all come. Every entry is
clipped to its documented bounds so observations always lie in the space.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from gymnasium import spaces

from quad_uneven_env.config import HeightScanConfig

STABILITY_CLIP = 0.5
"""m: the normalised stability index and edge moments are clipped to [-0.5, 0.5]."""


@dataclasses.dataclass(frozen=True)
class ObsField:
    """One named slice of the flat observation vector."""

    name: str
    size: int
    low: float
    high: float
    unit: str
    description: str


COMMAND_FIELD = ObsField(
    "command",
    3,
    -2.0,
    2.0,
    "m/s, rad/s",
    "commanded vx, vy (m/s) and yaw rate (rad/s), yaw-aligned base frame; only with ``command``",
)
"""The commanded base velocity (:mod:`quad_uneven_env.command`), appended last when the env has a command."""

COURSE_LATERAL_LIMIT = 10.0
"""m: the lateral offset from the course's centre line is clipped to [-10, 10]."""

COURSE_FRAME_FIELDS = (
    ObsField(
        "course_heading",
        2,
        -1.0,
        1.0,
        "-",
        "sin and cos of the trunk's yaw about world z from the course's +x axis; only with ``course_frame``",
    ),
    ObsField(
        "course_lateral",
        1,
        -COURSE_LATERAL_LIMIT,
        COURSE_LATERAL_LIMIT,
        "m",
        "trunk origin's world y minus the spawn point's (the course's centre line, along +x); only with "
        "``course_frame``",
    ),
)
"""Where the trunk is on the course (:class:`quad_uneven_env.env.QuadUnevenEnv`'s ``course_frame``): its heading
and its sideways offset from the line the robot is spawned on and walks along (+x), appended last."""


def observation_fields(
    scan: HeightScanConfig, n_actions: int = 12, command: bool = False, course_frame: bool = False
) -> tuple[ObsField, ...]:
    """The observation layout, in order; ``command``: append :data:`COMMAND_FIELD` (the env has a command);
    ``course_frame``: append :data:`COURSE_FRAME_FIELDS` (the env's ``course_frame``).

    Optional fields go last, so the default layout does not depend on them and the fields before them keep
    their slices when one is added. The env never has both (a commanded robot has no course to follow).
    """
    nx, ny = scan.shape
    base = (
        ObsField("base_height", 1, -1.0, 2.0, "m", "trunk origin above the terrain directly below it"),
        ObsField("projected_gravity", 3, -1.0, 1.0, "-", "unit gravity direction in the base frame"),
        ObsField("base_lin_vel", 3, -10.0, 10.0, "m/s", "trunk linear velocity, base frame"),
        ObsField("base_ang_vel", 3, -20.0, 20.0, "rad/s", "trunk angular velocity, base frame"),
        ObsField("joint_pos", 12, -np.pi, np.pi, "rad", "joint angles, LF RF LH RH x HAA HFE KFE"),
        ObsField("joint_vel", 12, -40.0, 40.0, "rad/s", "joint velocities, same order"),
        ObsField("foot_contact", 4, 0.0, 1.0, "-", "1 if the foot touches the terrain, leg order"),
        ObsField(
            "stability_index",
            1,
            -STABILITY_CLIP,
            STABILITY_CLIP,
            "m",
            "normalised stability index (index / m g); -0.5 without a support polygon",
        ),
        ObsField(
            "edge_moments",
            4,
            -STABILITY_CLIP,
            STABILITY_CLIP,
            "m",
            "normalised tumbling moments of the support polygon edges (clockwise), 0-padded to 4",
        ),
        ObsField("gait_clock", 2, -1.0, 1.0, "-", "sin and cos of 2 pi t / gait_period"),
        ObsField(
            "height_scan",
            nx * ny,
            -1.0,
            1.0,
            "m",
            f"terrain height minus trunk height on a {nx} x {ny} grid (x fastest) of spacing "
            f"{scan.resolution} m in the yaw-aligned base frame",
        ),
        ObsField("prev_action", n_actions, -1.0, 1.0, "-", "previous (clipped) action"),
    )
    return base + ((COMMAND_FIELD,) if command else ()) + (COURSE_FRAME_FIELDS if course_frame else ())


def observation_structure(fields: tuple[ObsField, ...]) -> dict[str, slice]:
    """Machine-readable layout: field name -> slice of the flat observation."""
    out, start = {}, 0
    for f in fields:
        out[f.name] = slice(start, start + f.size)
        start += f.size
    return out


def observation_space(fields: tuple[ObsField, ...]) -> spaces.Box:
    """Finite float32 Box of the layout."""
    low = np.concatenate([np.full(f.size, f.low) for f in fields]).astype(np.float32)
    high = np.concatenate([np.full(f.size, f.high) for f in fields]).astype(np.float32)
    return spaces.Box(low, high, dtype=np.float32)


def observation_table(fields: tuple[ObsField, ...]) -> str:
    """Markdown table of the layout (for docs)."""
    rows = ["| index | name | size | bounds | unit | description |", "|---|---|---|---|---|---|"]
    for name, sl in observation_structure(fields).items():
        f = next(x for x in fields if x.name == name)
        rows.append(
            f"| {sl.start}-{sl.stop - 1} | {name} | {f.size} | [{f.low:g}, {f.high:g}] | {f.unit} | {f.description} |"
        )
    return "\n".join(rows)


def height_scan_points_B(scan: HeightScanConfig) -> np.ndarray:
    """(nx * ny, 2) scan points in the yaw-aligned base frame (x fastest), m."""
    nx, ny = scan.shape
    xs = np.linspace(-scan.size_x / 2, scan.size_x / 2, nx)
    ys = np.linspace(-scan.size_y / 2, scan.size_y / 2, ny)
    gx, gy = np.meshgrid(xs, ys)  # rows along y, x fastest
    return np.stack([gx.ravel(), gy.ravel()], axis=1)
