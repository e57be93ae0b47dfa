"""QuadUneven-v0's arguments as one frozen config: the keyword arguments of ``gym.make("QuadUneven-v0", ...)``.

Each field is declared once, with its default; a scalar's check, error message and row of the env docstring's
Arguments table (:func:`arguments_table`) come from its :func:`~quad_uneven_env.fields.param` declaration, the
structured arguments (terrain, robot, reward weights, ...) are loaded and checked by their own modules. Defaults
that depend on the robot are derived from it in one place each (:func:`default_pd_gains`,
:func:`default_base_height_limits`).
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Mapping

from quad_uneven_env.actuation import ACTION_MODES
from quad_uneven_env.command import CommandConfig, load_command
from quad_uneven_env.config import HeightScanConfig, RewardWeights, TerminationLimits
from quad_uneven_env.fields import check_fields, excerpt, from_mapping, param, params_of
from quad_uneven_env.history import MAX_HISTORY
from quad_uneven_env.randomization import RandomizationConfig, load_randomization, randomization_for_robot
from quad_uneven_env.rendering import RENDER_MODES
from quad_uneven_env.rewards import COMMAND_REWARD_TERMS
from quad_uneven_env.robot.description import RobotDescription, load_robot
from quad_uneven_env.terrain import TerrainSpec, parse_terrain_spec

MAX_EPISODE_STEPS = 10**9
"""Upper bound of ``episode_step_cap`` (control steps)."""


PAPER_BASE_HEIGHT_LIMITS = (0.12, 1.0)
"""m: the paper robot's fall rule: a base height below the first or above the second ends an episode (a third of
its 0.36 m stand, and 2.78 times it)."""
PAPER_PD_GAINS = (100.0, 3.0)
"""(N m/rad, N m s/rad): the paper robot's ``joint_pd`` servo gains."""


def default_base_height_limits(robot: RobotDescription) -> tuple[float, float]:
    """m, the default ``termination.min_base_height`` and ``max_base_height`` on ``robot``: the paper robot's
    :data:`PAPER_BASE_HEIGHT_LIMITS` in units of its standing height (a third of it, and 2.78 times it)."""
    k = robot.height_ratio
    return PAPER_BASE_HEIGHT_LIMITS[0] * k, PAPER_BASE_HEIGHT_LIMITS[1] * k


def default_pd_gains(robot: RobotDescription) -> tuple[float, float]:
    """(N m/rad, N m s/rad), the default ``joint_pd`` gains on ``robot``: the paper robot's :data:`PAPER_PD_GAINS`
    scaled with its weight times leg length (stiffness) and with the same damping ratio at a natural frequency
    ~ 1 / sqrt(leg length) (damping ~ mass x leg length^1.5)."""
    m, s = robot.mass_ratio, robot.length_ratio
    return PAPER_PD_GAINS[0] * m * s, PAPER_PD_GAINS[1] * m * s**1.5


@dataclasses.dataclass(frozen=True)
class EnvConfig:
    """The env's arguments, validated and loaded: ``EnvConfig(**kwargs)`` checks what ``gym.make`` was given (all
    but ``controller``, a live object that the env's physics loop holds).

    Each structured argument is given as a name, a path or a mapping and held as its config object; an object
    given already is taken as it is.

    :raises ValueError: naming the argument (``frame_skip must be ...``, ``reward_weights.alive must be ...``) and
        its allowed values.
    """

    terrain: TerrainSpec = "rough"
    """a kind name, a preset name or YAML path, or ``{"kind": ..., **params}`` (docs/terrain.md); held parsed."""
    robot: RobotDescription = "paper"
    """a name of :func:`quad_uneven_env.robots` or a robot YAML path (docs/robots.md); held as its description."""
    frame_skip: int = param(10, "-", "physics steps per control step", kind="int", lo=1, hi=1000)
    timestep: float = param(0.002, "s", "physics timestep", lo=0.0, hi=0.002, lo_open=True)
    action_mode: str = param("torque", "-", "what an action commands (see Action)", kind="choice", choices=ACTION_MODES)
    reward_weights: RewardWeights = None
    """a mapping of :class:`~quad_uneven_env.config.RewardWeights` fields (None: the defaults)."""
    termination: TerminationLimits = None
    """a mapping of :class:`~quad_uneven_env.config.TerminationLimits` fields; ``min_base_height`` and
    ``max_base_height`` not given are the robot's (:func:`default_base_height_limits`)."""
    height_scan: HeightScanConfig = None
    """a mapping of :class:`~quad_uneven_env.config.HeightScanConfig` fields (None: the defaults)."""
    gait_period: float = param(
        6.1, "s", "period of the observation's gait clock (the paper's cycle)", lo=0.0, hi=1000.0, lo_open=True
    )
    reset_noise_scale: float = param(
        0.02, "rad, rad/s", "uniform noise on the joint angles and velocities at reset", lo=0.0, hi=1.0
    )
    pd_kp: float = param(
        None,
        "N m/rad",
        "``joint_pd`` servo stiffness (None: the robot's, docs/robots.md; 100 for the paper robot)",
        lo=0.0,
        hi=1e5,
        lo_open=True,
    )
    pd_kd: float = param(
        None, "N m s/rad", "``joint_pd`` servo damping (None: the robot's; 3 for the paper robot)", lo=0.0, hi=1e4
    )
    pd_action_scale: float = param(
        0.5, "rad", "``joint_pd`` target offset per unit of action", lo=0.0, hi=math.pi, lo_open=True
    )
    render_mode: str | None = param(
        None, "-", "how ``render()`` draws", kind="choice", choices=RENDER_MODES, none_ok=True
    )
    width: int = param(640, "px", "rendered image width", kind="int", lo=1, hi=4096)
    height: int = param(480, "px", "rendered image height", kind="int", lo=1, hi=4096)
    episode_step_cap: int = param(
        1_000_000,
        "-",
        "control steps after which the env itself truncates an episode, whatever time limit a wrapper sets",
        kind="int",
        lo=1,
        hi=MAX_EPISODE_STEPS,
    )
    randomization: RandomizationConfig | None = None
    """None (the nominal world), a preset name of ``configs/randomization/``, a YAML path or a mapping of
    :class:`~quad_uneven_env.randomization.RandomizationConfig` fields; held in SI units for the robot."""
    command: CommandConfig | None = None
    """None (no command) or a mapping of :class:`~quad_uneven_env.command.CommandConfig` fields."""
    course_frame: bool = param(
        False,
        "-",
        "append the trunk's heading and sideways offset on the course to the observation (not with ``command``)",
        kind="bool",
    )

    proprio_history: int = param(
        0,
        "control steps",
        "append the joint angles, velocities and actions of this many previous control steps to the observation",
        kind="int",
        lo=0,
        hi=MAX_HISTORY,
    )

    def __post_init__(self) -> None:
        robot = self.robot
        if not isinstance(robot, RobotDescription):
            if not isinstance(robot, str | os.PathLike):
                raise ValueError(
                    f"robot must be a config name or a .yaml path, got {robot!r} of type {type(robot).__name__}"
                )
            robot = load_robot(robot)
        kp, kd = default_pd_gains(robot)
        termination = self.termination
        if termination is None or isinstance(termination, Mapping):
            lo, hi = default_base_height_limits(robot)
            termination = {"min_base_height": lo, "max_base_height": hi, **(termination or {})}
        loaded = {
            "robot": robot,
            "pd_kp": kp if self.pd_kp is None else self.pd_kp,
            "pd_kd": kd if self.pd_kd is None else self.pd_kd,
        }
        for name, value in loaded.items():
            object.__setattr__(self, name, value)
        check_fields(self, "")
        loaded = {
            "randomization": randomization_for_robot(load_randomization(self.randomization), robot),
            "terrain": parse_terrain_spec(self.terrain),
            "reward_weights": from_mapping(RewardWeights, self.reward_weights, "reward_weights"),
            "termination": from_mapping(TerminationLimits, termination, "termination"),
            "height_scan": from_mapping(HeightScanConfig, self.height_scan, "height_scan"),
            "command": load_command(self.command),
        }
        for name, value in loaded.items():
            object.__setattr__(self, name, value)
        self._check_command()

    def _check_command(self) -> None:
        """The arguments that need a command (or its absence) agree with ``command``."""
        if self.course_frame and self.command is not None:
            raise ValueError(
                "course_frame must be False with a command: a commanded robot walks where the command takes it, "
                "not along the course's +x line, so its heading and offset from that line mean nothing; got "
                "course_frame=True and command=..."
            )
        if self.command is None:
            for name in COMMAND_REWARD_TERMS:
                if getattr(self.reward_weights, name) != 0.0:
                    raise ValueError(
                        f"reward_weights.{name} must be 0 without a command (command=None), got "
                        f"{excerpt(getattr(self.reward_weights, name))}; pass command=... to make()"
                    )


def arguments_table() -> str:
    """Markdown table of the scalar arguments (argument, default, allowed, unit, meaning)."""
    rows = ["| argument | default | allowed | unit | meaning |", "|---|---|---|---|---|"]
    for q in params_of(EnvConfig):
        default = "None" if q.default is None else f"{q.default!r}"
        rows.append(f"| ``{q.name}`` | ``{default}`` | {q.allowed()} | {q.unit} | {q.doc} |")
    return "\n".join(rows)
