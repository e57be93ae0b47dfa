"""QuadUneven-v0: the paper's 18-DOF quadruped walking along +x over generated uneven terrain."""

from __future__ import annotations

import copy
import dataclasses
import logging
import math
import os
import sys
from collections.abc import Callable, Mapping
from typing import Any, Protocol

import gymnasium as gym
import mujoco
import numpy as np
from gymnasium import spaces

from quad_uneven_env import constants as C
from quad_uneven_env.command import CommandConfig, CommandSchedule, command_arguments_table, load_command
from quad_uneven_env.config import (
    HeightScanConfig,
    RewardWeights,
    TerminationLimits,
)
from quad_uneven_env.fields import Param, excerpt, from_mapping
from quad_uneven_env.measurement import StepMeasurement
from quad_uneven_env.measurement_kernels import clip_finite_into
from quad_uneven_env.observations import (
    height_scan_points_B,
    observation_fields,
    observation_space,
    observation_structure,
    observation_table,
)
from quad_uneven_env.physics import BAD_WARNINGS, RobotIndex, instability_warnings
from quad_uneven_env.randomization import (
    EpisodeDraw,
    ModelRandomizer,
    Push,
    PushSchedule,
    RandomizationConfig,
    draw_episode,
    load_randomization,
    randomization_for_robot,
)
from quad_uneven_env.rewards import COMMAND_REWARD_TERMS, REWARD_TERMS, command_reward_terms, reward_terms
from quad_uneven_env.robot.description import RobotDescription, load_robot
from quad_uneven_env.robot.model import PhysicsOptions, scene_mjcf
from quad_uneven_env.spatial import yaw_of_quat
from quad_uneven_env.termination import FallCheck
from quad_uneven_env.terrain import Terrain, parse_terrain_spec

ACTION_MODES = ("torque", "joint_pd")
RENDER_MODES = ("human", "rgb_array", "depth_array")

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


ENV_ARGS: tuple[Param, ...] = (
    Param("frame_skip", 10, "-", "physics steps per control step", kind="int", lo=1, hi=1000),
    Param("timestep", 0.002, "s", "physics timestep", lo=0.0, hi=0.002, lo_open=True),
    Param("action_mode", "torque", "-", "what an action commands (see Action)", kind="choice", choices=ACTION_MODES),
    Param(
        "gait_period",
        6.1,
        "s",
        "period of the observation's gait clock (the paper's cycle)",
        lo=0.0,
        hi=1000.0,
        lo_open=True,
    ),
    Param(
        "reset_noise_scale",
        0.02,
        "rad, rad/s",
        "uniform noise on the joint angles and velocities at reset",
        lo=0.0,
        hi=1.0,
    ),
    Param(
        "pd_kp",
        100.0,
        "N m/rad",
        "``joint_pd`` servo stiffness (None: the robot's, docs/robots.md; the default is the paper robot's)",
        lo=0.0,
        hi=1e5,
        lo_open=True,
    ),
    Param(
        "pd_kd",
        3.0,
        "N m s/rad",
        "``joint_pd`` servo damping (None: the robot's; the default is the paper robot's)",
        lo=0.0,
        hi=1e4,
    ),
    Param(
        "pd_action_scale", 0.5, "rad", "``joint_pd`` target offset per unit of action", lo=0.0, hi=math.pi, lo_open=True
    ),
    Param("render_mode", None, "-", "how ``render()`` draws", kind="choice", choices=RENDER_MODES, none_ok=True),
    Param("width", 640, "px", "rendered image width", kind="int", lo=1, hi=4096),
    Param("height", 480, "px", "rendered image height", kind="int", lo=1, hi=4096),
    Param(
        "episode_step_cap",
        1_000_000,
        "-",
        "control steps after which the env itself truncates an episode, whatever time limit a wrapper sets",
        kind="int",
        lo=1,
        hi=MAX_EPISODE_STEPS,
    ),
    Param(
        "course_frame",
        False,
        "-",
        "append the trunk's heading and sideways offset on the course to the observation (not with ``command``)",
        kind="bool",
    ),
)
"""The env's scalar arguments: their checks at make time, their error messages and the Arguments table."""

_INF_MOMENTS = np.full(C.N_LEGS, np.inf)
"""the padding of ``info["edge_moments"]`` (copied, never written)."""

_STATE = mujoco.mjtState.mjSTATE_INTEGRATION
"""What a failed control step restores: time, qpos, qvel, act, warm start, ctrl, applied forces, ..."""


def arguments_table() -> str:
    """Markdown table of :data:`ENV_ARGS` (argument, default, allowed, unit, meaning)."""
    rows = ["| argument | default | allowed | unit | meaning |", "|---|---|---|---|---|"]
    for q in ENV_ARGS:
        default = "None" if q.default is None else f"{q.default!r}"
        rows.append(f"| ``{q.name}`` | ``{default}`` | {q.allowed()} | {q.unit} | {q.doc} |")
    return "\n".join(rows)


MUJOCO_LOGGER = logging.getLogger("mujoco")
"""Where MuJoCo's warnings go (level INFO) instead of ``MUJOCO_LOG.TXT`` in the working directory: the env
installs :func:`route_mujoco_warnings` unless a warning handler is already set. The env reports what they mean
(``info["diverged"]``, ``info["termination_reason"]``)."""


def _log_mujoco_warning(message: str) -> None:
    MUJOCO_LOGGER.info(message)


def route_mujoco_warnings() -> None:
    """Send MuJoCo's warnings to :data:`MUJOCO_LOGGER` (process-wide; a handler set before, by the user or another
    library, is kept). Without a handler MuJoCo prints them and appends them to ``MUJOCO_LOG.TXT`` in the current
    directory."""
    if mujoco.get_mju_user_warning() is None:
        mujoco.set_mju_user_warning(_log_mujoco_warning)


def display_missing(render_mode: str | None) -> bool:
    """True when ``render_mode="human"`` cannot open a window here (Linux without ``DISPLAY``/``WAYLAND_DISPLAY``).

    Asked before any window or GLFW code: without a display GLFW aborts the process instead of raising.
    """
    if render_mode != "human" or not sys.platform.startswith("linux"):
        return False
    return not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


class PhysicsController(Protocol):
    """A controller run at physics rate inside :meth:`QuadUnevenEnv.step`.

    Called after ``mujoco.mj_step1`` (so ``data`` holds kinematics, the mass matrix,
    ``qfrc_bias`` and contacts of the current state) and before ``mujoco.mj_step2``; returns
    the 12 joint torques (N m, ``JOINT_NAMES`` order), which the env clips to the motor limits.
    An exception it raises, or a return that is not 12 finite numbers, ends the episode as diverged
    (the control step is undone). It needs ``action_mode="torque"``. An optional
    ``reset(model, data, terrain)`` method is called at the end of every reset.

    An optional fast lane ``torques_into(model, data, action, out, limit) -> bool``, tried first at every physics
    step: True when it wrote exactly the torques the call would return, clipped to ``±limit`` (N m), into
    ``out``; False (nothing written) to have the env make the call. It saves the call's Python where a
    controller can do the whole step in compiled code; an exception it raises counts as False.
    """

    def __call__(self, model: mujoco.MjModel, data: mujoco.MjData, action: np.ndarray) -> np.ndarray: ...


class QuadUnevenEnv(gym.Env):
    """The paper's quadruped (Table 1, 18 DOF) on a MuJoCo height-field terrain.

    **Task.** Walk along +x from the spawn point without falling, keeping the paper's
    stability index (tumbling moments about the support polygon edges) positive.

    **Action** (``Box(-1, 1, (12,), float32)``, joint order LF RF LH RH x HAA HFE KFE):

    - ``action_mode="torque"`` (default): joint torque = action x torque limit (N m).
    - ``action_mode="joint_pd"``: joint target = standing pose + ``pd_action_scale`` x action (rad),
      tracked by PD gains ``pd_kp`` (N m/rad), ``pd_kd`` (N m s/rad) at physics rate (MuJoCo
      servo actuators), torques saturated at the motor limits.

    Out-of-range actions are clipped to [-1, 1]; NaN/Inf or a wrong shape raises ``ValueError``
    and leaves the simulation untouched. With a physics-rate ``controller`` (see
    :class:`PhysicsController`), the controller's torques are applied and it receives the action;
    a controller needs ``action_mode="torque"`` (with ``"joint_pd"`` its torques would become servo
    targets: refused with a ``ValueError`` at make and by :meth:`set_controller`).

    **Observation**: a flat finite float32 Box; ``env.observation_structure`` maps each name to
    its slice. Every entry is clipped to its bounds:

    OBSERVATION_TABLE

    With ``course_frame=True`` two fields are appended last instead of ``command`` (refused together with a
    command): ``course_heading`` (2, [-1, 1]: sin and cos of the trunk's yaw about world z, measured from the
    course's +x axis, the direction the robot walks and ``info["distance"]`` counts) and ``course_lateral``
    (1, [-10, 10] m: the trunk origin's world y minus the spawn point's, its sideways offset from the course's
    centre line). The default observation does not change.

    **Reward**: the sum of named terms (weights ``reward_weights``, see
    :class:`quad_uneven_env.config.RewardWeights`), each reported in ``info["reward_terms"]``:
    ``forward_progress`` (COG velocity along +x), ``stability`` (normalised index, clipped),
    ``torque`` (mean squared torque fraction), ``energy`` (|tau qd| / m g), ``alive``, ``fall``; with a
    ``command`` also ``command_tracking_lin`` (exp(-|v_xy - v_cmd|^2 / sigma_lin^2)) and ``command_tracking_yaw``
    (exp(-(yaw_rate - yaw_rate_cmd)^2 / sigma_yaw^2)), of the trunk's velocity at the end of the step in the
    yaw-aligned base frame against the command in effect during the step (weights 0 by default: no tracking term
    unless they are set; nonzero weights without a command are refused).

    **Command** (``command`` not None, see :mod:`quad_uneven_env.command` and docs/commands.md): a commanded
    planar base velocity (vx, vy in m/s, yaw rate in rad/s) in the yaw-aligned base frame, fixed or drawn at
    every reset and every ``resample_interval`` s of episode time from a child of ``np_random``
    (``np_random.spawn``; the terrain, the reset noise and a randomized world are those of the same seed
    without a command). It is appended to the observation as the field ``command`` and reported in
    ``info["command"]``: both show the command to follow from now on (a re-draw at the end of a step is
    already in that step's observation). In heading mode (``heading`` or ``ranges.heading``) the command names
    a world heading and its yaw rate is computed at every step from the measured one (legged_gym's
    ``heading_command``); the target is ``info["command_heading"]`` (rad). With ``command=None`` (the default)
    the observation has no ``command`` field, the reward no tracking terms and ``info`` no command keys. Fields:

    COMMAND_TABLE

    **Episode end**: terminated on a fall (trunk touches the terrain, trunk origin lower than
    ``min_base_height`` or higher than ``max_base_height`` above the terrain below it, tilt beyond
    ``max_tilt_deg``), on leaving the terrain, or when the control step fails (``info["diverged"] =
    True``): a NaN/Inf state or a MuJoCo bad qpos/qvel/qacc warning, an error raised by MuJoCo, or a
    controller that raises any exception or returns anything but 12 finite numbers; the reason is in
    ``info["termination_reason"]``. ``step`` itself never raises for what happens inside the
    simulation or a controller (only for a malformed action, before anything runs). A failed control
    step is undone: the simulation state (time included) is put back to where the step started, so
    the simulation advances by whole control steps only, and the observation and ``info`` repeat the
    last good measurement, which is of that state. Truncation by ``max_episode_steps`` (1000 = 20 s
    by default) and, whatever the time limit, after ``episode_step_cap`` control steps
    (``info["termination_reason"]`` then says so).

    **Info** (the same keys, shapes and dtypes at every step and reset, so that Gymnasium's vector
    envs can stack them; ``gym.make_vec("QuadUneven-v0", num_envs=N)`` gives N copies):

    ==============================  ==========  ===========================================================
    key                             shape       content
    ==============================  ==========  ===========================================================
    ``stability_index``             float       N m; ``-inf`` with fewer than 3 stance feet
    ``stability_index_normalized``  float       m (index / m g)
    ``edge_moments``                (4,)        N m, the clockwise support edges' tumbling moments, padded
                                                with +inf beyond the number of stance feet (an absent edge
                                                never tips, so the index is still their minimum; NaN would
                                                fail Gymnasium's env checker); ``-inf`` entries if < 3 feet
    ``contact_forces``              (4, 3)      N, terrain on each foot, world frame, leg order
    ``foot_contact``                (4,) bool   the foot touches the terrain
    ``cog``, ``cog_vel``,           (3,)        whole-robot COG (m), velocity (m/s), acceleration (m/s^2,
    ``cog_acc``                                 Newton's law with the contact forces), world frame
    ``feet_pos``                    (4, 3)      m, foot sites, world frame
    ``terrain_height_under_base``   float       m
    ``distance``                    float       m, COG x travelled since the reset
    ``diverged``                    bool        the episode ended by numerical divergence
    ``termination_reason``          str / None  why the episode ended (None while it runs)
    ``reward_terms``                dict        the named reward terms of this step (zeros at reset)
    ``randomization``               dict        the episode's drawn world, floats, the same keys for every
                                                config (nominal values where a factor is off)
    ``push_force``                  (3,)        N, world: mean push on the trunk over the step (zeros: none)
    ``command``                     (3,)        only with ``command``: vx, vy (m/s), yaw rate (rad/s), yaw-aligned
                                                base frame, to be followed from now on (the observation's field)
    ==============================  ==========  ===========================================================

    Measured quantities (contacts, COG, feet, stability) are those of the last physics step's
    constraint solve, i.e. at the start of that 2 ms step.

    **Arguments**: ``terrain`` (kind name or ``{"kind": ..., **params}``, see docs/terrain.md;
    default ``"rough"``), ``robot`` (a name of :func:`quad_uneven_env.robots`, or a robot YAML path: a Table-1
    config or a URDF robot's, see docs/robots.md; default ``"paper"``), ``controller``
    (None or a :class:`PhysicsController`), ``reward_weights``, ``termination``, ``height_scan``
    (mappings of :mod:`quad_uneven_env.config`'s fields; ``termination.min_base_height`` and
    ``max_base_height`` default to the robot's, a third of its standing height and 2.78 times it: 0.12 and 1 m
    for the paper's robot), and the scalars below
    (``pd_kp`` and ``pd_kd`` default to the robot's gains, see docs/robots.md), each checked at make
    time by type and range (a bool is not a number; the error names the argument and its allowed
    values):

    ARGUMENTS_TABLE

    ``reset(seed=...)`` takes None or an integer >= 0 (not a bool).
    ``command``: None (no command, the default), or a mapping of :class:`quad_uneven_env.command.CommandConfig`
    (see **Command**).
    ``randomization``: None (the nominal world), a preset name of ``configs/randomization/``, a YAML path or
    a mapping (see :class:`quad_uneven_env.randomization.RandomizationConfig` and docs/randomization.md).

    **Randomization** (``randomization`` not None): drawn at every reset from a child of ``np_random``
    (``np_random.spawn``: a seed gives the same world on every terrain, and the nominal env's terrain and
    start), written into ``model`` and restored exactly before the next draw. Ground friction, payload and
    link masses (``total_mass`` follows: stability index normalisation, COG acceleration), motor strength and
    joint damping/friction are model parameters; actuation latency delays the applied command (``ctrl``) by k
    physics steps in both action modes and for the controller hook; pushes are forces on the trunk's COM
    (``xfrc_applied``); observation noise is added to the returned observation and clipped to the Box.
    """

    metadata = {"render_modes": list(RENDER_MODES), "render_fps": 50}  # noqa: RUF012

    def __init__(
        self,
        terrain: str | Mapping[str, Any] | None = "rough",
        robot: str = "paper",
        frame_skip: int = 10,
        timestep: float = 0.002,
        action_mode: str = "torque",
        controller: PhysicsController | Callable[..., np.ndarray] | None = None,
        reward_weights: Mapping[str, float] | RewardWeights | None = None,
        termination: Mapping[str, Any] | TerminationLimits | None = None,
        height_scan: Mapping[str, float] | HeightScanConfig | None = None,
        gait_period: float = 6.1,
        reset_noise_scale: float = 0.02,
        pd_kp: float | None = None,
        pd_kd: float | None = None,
        pd_action_scale: float = 0.5,
        render_mode: str | None = None,
        width: int = 640,
        height: int = 480,
        episode_step_cap: int = 1_000_000,
        randomization: str | Mapping[str, Any] | RandomizationConfig | None = None,
        command: Mapping[str, Any] | CommandConfig | None = None,
        course_frame: bool = False,
    ) -> None:
        if not isinstance(robot, str | os.PathLike):
            raise ValueError(
                f"robot must be a config name or a .yaml path, got {robot!r} of type {type(robot).__name__}"
            )
        self.robot: RobotDescription = load_robot(robot)
        """the robot's description (any robot: the paper's, a shipped URDF robot's or a user's YAML)."""
        kp0, kd0 = default_pd_gains(self.robot)
        pd_kp = kp0 if pd_kp is None else pd_kp
        pd_kd = kd0 if pd_kd is None else pd_kd
        given = dict(
            frame_skip=frame_skip, timestep=timestep, action_mode=action_mode, gait_period=gait_period,
            reset_noise_scale=reset_noise_scale, pd_kp=pd_kp, pd_kd=pd_kd, pd_action_scale=pd_action_scale,
            render_mode=render_mode, width=width, height=height, episode_step_cap=episode_step_cap,
            course_frame=course_frame,
        )  # fmt: skip
        args = {q.name: q.check(given[q.name], "") for q in ENV_ARGS}
        frame_skip, timestep, action_mode = args["frame_skip"], args["timestep"], args["action_mode"]
        self.action_mode = action_mode
        self._check_controller(controller)

        self.randomization: RandomizationConfig | None = randomization_for_robot(
            load_randomization(randomization), self.robot
        )
        """the randomization in SI units for this robot (a preset's ``scale: robot`` ranges scaled to it)."""
        self.terrain = Terrain(parse_terrain_spec(terrain))
        self.reward_weights: RewardWeights = from_mapping(RewardWeights, reward_weights, "reward_weights")
        if termination is None or isinstance(termination, Mapping):
            # the robot's base-height limits (the paper robot's: the TerminationLimits defaults, 0.12 and 1 m)
            lo, hi = default_base_height_limits(self.robot)
            termination = {"min_base_height": lo, "max_base_height": hi, **(termination or {})}
        self.termination: TerminationLimits = from_mapping(TerminationLimits, termination, "termination")
        self.height_scan: HeightScanConfig = from_mapping(HeightScanConfig, height_scan, "height_scan")
        self.command_config: CommandConfig | None = load_command(command)
        """the ``command`` argument (None: no command)."""
        self._command = None if self.command_config is None else CommandSchedule(self.command_config)
        self.course_frame: bool = args["course_frame"]
        """the observation ends with ``course_heading`` and ``course_lateral`` (see **Observation**)."""
        if self.course_frame and self._command is not None:
            raise ValueError(
                "course_frame must be False with a command: a commanded robot walks where the command takes it, "
                "not along the course's +x line, so its heading and offset from that line mean nothing; got "
                "course_frame=True and command=..."
            )
        if self._command is None:
            for name in COMMAND_REWARD_TERMS:
                if getattr(self.reward_weights, name) != 0.0:
                    raise ValueError(
                        f"reward_weights.{name} must be 0 without a command (command=None), got "
                        f"{excerpt(getattr(self.reward_weights, name))}; pass command=... to make()"
                    )
        self.frame_skip = int(frame_skip)
        self.gait_period = args["gait_period"]
        self.reset_noise_scale = args["reset_noise_scale"]
        self.pd_action_scale = args["pd_action_scale"]
        self.episode_step_cap: int = args["episode_step_cap"]
        """control steps after which the env truncates an episode (see the class docstring)."""
        self._controller = controller
        self._episode_steps = 0

        xml = scene_mjcf(
            self.robot,
            self.terrain.hfield_asset_xml(),
            self.terrain.hfield_geom_xml(self.robot.friction),
            PhysicsOptions(timestep=float(timestep)),
        )
        route_mujoco_warnings()
        self.model = mujoco.MjModel.from_xml_string(xml)
        # Divergence must end the episode visibly, not be hidden by MuJoCo's automatic reset.
        self.model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_AUTORESET
        vis = self.model.vis.global_
        vis.offwidth, vis.offheight = max(vis.offwidth, args["width"]), max(vis.offheight, args["height"])
        self.data = mujoco.MjData(self.model)
        self._saved_state = np.empty(mujoco.mj_stateSize(self.model, _STATE))
        self._bind_data_views()
        self._dt = float(self.model.opt.timestep) * self.frame_skip
        self.idx = RobotIndex.from_model(self.model)
        self._mass = self.idx.total_mass
        self._gravity = self.model.opt.gravity.copy()
        self._g = float(-self._gravity[2])
        self._fall = FallCheck(self.termination)
        # Where each foot stands at reset (trunk frame): where the standing pose puts it.
        self._feet_home_B = self.robot.standing_feet_B
        # Row 0 is the point under the base, the rest the height scan grid.
        self._scan_B = np.vstack([np.zeros((1, 2)), height_scan_points_B(self.height_scan)])

        self._home_joints = np.zeros(C.N_JOINTS)
        self._joint_lo = self.model.jnt_range[1:, 0].copy()
        self._joint_hi = self.model.jnt_range[1:, 1].copy()
        if action_mode == "joint_pd":
            self._make_servos(args["pd_kp"], args["pd_kd"])

        self.action_space = spaces.Box(-1.0, 1.0, (C.N_JOINTS,), dtype=np.float32)
        self._fields = observation_fields(
            self.height_scan, C.N_JOINTS, command=self._command is not None, course_frame=self.course_frame
        )
        self.observation_structure: dict[str, slice] = observation_structure(self._fields)
        self.observation_space = observation_space(self._fields)

        self.render_mode = render_mode
        self.metadata = dict(self.metadata, render_fps=round(1.0 / self.dt))
        self._width, self._height = args["width"], args["height"]
        self._renderer = None
        self._warned_no_display = False

        self._prev_action = np.zeros(C.N_JOINTS)
        self._needs_reset = True
        self._unit_bounds = np.ones(C.N_JOINTS)
        self._tau_frac = np.zeros(C.N_JOINTS)  # the reward's scratch buffers
        self._joint_power = np.zeros(C.N_JOINTS)
        self._meas = StepMeasurement(
            self.model,
            self.data,
            self.idx,
            self.robot.foot_radius,
            self._scan_B,
            self._fields,
            self.observation_space.low,
            self.observation_space.high,
        )
        self._last_obs = np.zeros(self.observation_space.shape, dtype=np.float32)
        self._init_randomization()
        self._last_index_norm = 0.0
        self._start_x = 0.0
        self._warnings_at_reset = 0
        self._pristine_model: mujoco.MjModel | None = None  # the model at the first reset (see _restore_model)
        self._model_views: list[tuple[np.ndarray, np.ndarray]] = []

    # ------------------------------------------------------------------ properties
    @property
    def dt(self) -> float:
        """Control period (s) = frame_skip x physics timestep."""
        return self._dt

    @property
    def physics_dt(self) -> float:
        """Physics timestep (s)."""
        return float(self.model.opt.timestep)

    @property
    def controller(self) -> PhysicsController | None:
        """The physics-rate controller, or None."""
        return self._controller

    @property
    def total_mass(self) -> float:
        """kg, the simulated whole-robot mass of this episode (the nominal one unless masses are randomized)."""
        return self._mass

    @property
    def episode_draw(self) -> EpisodeDraw:
        """This episode's drawn world (nominal values where a factor is off)."""
        return self._draw

    @property
    def command(self) -> np.ndarray | None:
        """(3,) the command to follow now: vx, vy (m/s), yaw rate (rad/s), yaw-aligned base frame (a copy); None
        without a command."""
        return None if self._command is None else self._command.value.copy()

    @property
    def command_heading(self) -> float | None:
        """rad, world frame: heading mode's target heading (the yaw rate of :attr:`command` steers to it); None
        outside heading mode (see :mod:`quad_uneven_env.command`)."""
        c = self._command
        return None if c is None or not c.config.heading_mode else float(c.heading)

    def set_command(self, value: np.ndarray) -> None:
        """Set the command to follow from now on (an outside source: a waypoint follower, a joystick).

        :param value: (3,) vx, vy (m/s, each in [-1, 1]) and yaw rate (rad/s, in [-2, 2]), yaw-aligned base frame.
            It shows in the next step's observation and ``info``; ranged axes are still re-drawn at the next
            resample time, and a reset restores the configured command. In heading mode the yaw rate is
            recomputed from the heading at the end of the next step.
        :raises ValueError: without a command (``command=None``), or on a value of the wrong shape or out of range.
        """
        if self._command is None:
            raise ValueError("set_command needs an env made with a command (command={...}); this one has none")
        self._command.set(value)

    @property
    def pushes(self) -> list[Push]:
        """The pushes started so far this episode (start time, impulse, direction, duration, force)."""
        return self._push_schedule.pushes

    def set_controller(self, controller: PhysicsController | Callable[..., np.ndarray] | None) -> None:
        """Install (or remove, with None) the physics-rate controller; takes effect at the next step.

        :raises ValueError: if ``controller`` is not callable, or the env is in ``action_mode="joint_pd"``.
        """
        self._check_controller(controller)
        self._controller = controller

    def _check_controller(self, controller: Any) -> None:
        if controller is None:
            return
        if not callable(controller):
            raise ValueError(
                f"controller must be None or a callable (model, data, action) -> 12 torques (N m), "
                f"got {excerpt(controller)} of type {type(controller).__name__}"
            )
        for hook in ("reset", "torques_into"):
            if hasattr(controller, hook) and not callable(getattr(controller, hook)):
                raise ValueError(
                    f"controller.{hook} must be a method (see PhysicsController), got "
                    f"{excerpt(getattr(controller, hook))} of type {type(getattr(controller, hook)).__name__}"
                )
        if self.action_mode != "torque":
            raise ValueError(
                f"controller must be None with action_mode={excerpt(self.action_mode)}: a physics-rate controller "
                "returns torques, which would drive the position servos as targets; use action_mode='torque'"
            )

    # ------------------------------------------------------------------ reset
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Regenerate the terrain from ``np_random``, stand the robot at the spawn point.

        :param seed: None or an integer >= 0 (not a bool); see :meth:`gymnasium.Env.reset`.
        """
        if seed is not None and (
            isinstance(seed, bool | np.bool_) or not isinstance(seed, int | np.integer) or seed < 0
        ):
            raise ValueError(f"seed must be None or an integer >= 0, got {excerpt(seed)} of type {type(seed).__name__}")
        super().reset(seed=None if seed is None else int(seed))
        if options:
            raise ValueError(f"reset options are not supported (got keys {sorted(options)}); pass terrain to make()")
        self._restore_model()
        self.terrain.generate(self.np_random)
        self.terrain.upload(self.model)
        (xmin, xmax), (ymin, ymax) = self.terrain.heightfield.extent
        margin = 0.3  # m: the robot has left the terrain before its trunk reaches the edge
        self._fall.inside_xy = (xmin + margin, xmax - margin, ymin + margin, ymax - margin)
        self._upload_terrain_to_renderer()

        mujoco.mj_resetData(self.model, self.data)
        self.data.qpos[:] = self._spawn_qpos()
        noise = self.reset_noise_scale
        if noise > 0:
            self.data.qpos[7:] = np.clip(
                self.data.qpos[7:] + self.np_random.uniform(-noise, noise, C.N_JOINTS), self._joint_lo, self._joint_hi
            )
            self.data.qvel[6:] = self.np_random.uniform(-noise, noise, C.N_JOINTS)
        self._home_joints = self.data.qpos[7:].copy()
        if self.action_mode == "joint_pd":
            self.data.ctrl[:] = self._home_joints
        # One child of np_random per reset, for the randomized world and (through its own child) the command:
        # spawning draws nothing from np_random, and the world keeps the child it has without a command.
        child = self.np_random.spawn(1)[0] if self.randomization is not None or self._command is not None else None
        self._draw_world(child)
        if self._command is not None:
            self._command.reset(child.spawn(1)[0])
            self._command.steer(yaw_of_quat(self.data.qpos[3:7]))
        mujoco.mj_forward(self.model, self.data)
        self._warnings_at_reset = instability_warnings(self._warning_counts)
        if self._controller is not None and hasattr(self._controller, "reset"):
            self._controller.reset(self.model, self.data, self.terrain)

        self._prev_action[:] = 0.0
        self._episode_steps = 0
        self._needs_reset = False
        meas = self._measure()
        self._start_x = float(meas.cog[0])
        self._last_index_norm = meas.index / (self._mass * self._g)
        self._last_obs = self._observe(meas.obs)
        names = REWARD_TERMS if self._command is None else REWARD_TERMS + COMMAND_REWARD_TERMS
        info = self._info(meas, terms=dict.fromkeys(names, 0.0), diverged=False, reason=None)
        return self._last_obs.copy(), info

    def _spawn_qpos(self) -> np.ndarray:
        """Standing pose over the spawn point: each foot on the terrain below its standing point."""
        x0, y0 = self.terrain.spawn_xy
        feet_xy = self._feet_home_B[:, :2] + np.array([x0, y0])
        ground = np.asarray(self.terrain.height(feet_xy[:, 0], feet_xy[:, 1]), dtype=float)
        base_z, joints = self.robot.stand_on(ground)
        qpos = np.zeros(C.NQ)
        qpos[:4] = (x0, y0, base_z, 1.0)
        qpos[7:] = np.clip(joints, self._joint_lo, self._joint_hi)
        return qpos

    # ------------------------------------------------------------------ step
    def step(self, action: np.ndarray):
        """Advance ``frame_skip`` physics steps under ``action``; see the class docstring."""
        if self._needs_reset:
            raise gym.error.ResetNeeded("call reset before step: the env has no episode yet")
        a = np.asarray(action)
        if a.dtype.kind not in "iuf":
            raise ValueError(f"action must hold real numbers (float or int), got dtype {a.dtype}")
        if a.shape != (C.N_JOINTS,):
            raise ValueError(f"action must have shape ({C.N_JOINTS},), got {a.shape}")
        clipped = np.empty(C.N_JOINTS)
        if not clip_finite_into(a.astype(np.float64, copy=False), self._unit_bounds, clipped):  # np.clip, compiled
            raise ValueError(
                f"action must be finite, got NaN/Inf at indices {np.flatnonzero(~np.isfinite(a)).tolist()}"
            )
        a = clipped
        a.setflags(write=False)  # a controller is handed this array: it may read it, not change the step's action
        m, d = self.model, self.data
        x_before = float(self._meas.cog[0])

        command = None if self._command is None else self._command.value.copy()  # in effect during this step
        mujoco.mj_getState(m, d, self._saved_state, _STATE)
        delayed = (self._ctrl_ring.copy(), self._ctrl_prev.copy()) if self._latency else None
        try:
            reason = self._advance(a)
        except Exception as err:  # MuJoCo's own errors (mujoco.FatalError), raised from inside its step
            reason = f"diverged: MuJoCo failed ({type(err).__name__}: {err})"
        except BaseException:  # Ctrl-C and the like still propagate, from a whole-step state
            self._restore_state(delayed)
            raise
        # MuJoCo's own checks (mj_checkPos/Vel/Acc) flag NaN, Inf and huge values in qpos, qvel
        # and qacc; with auto-reset disabled the bad state stays for us to see.
        if reason is None and instability_warnings(self._warning_counts) > self._warnings_at_reset:
            reason = "diverged: MuJoCo reported a bad (NaN, Inf or huge) qpos/qvel/qacc"
        if reason is not None:
            self._restore_state(delayed)  # a failed control step is undone: the state is the last good one again
        else:
            self._physics_step += self.frame_skip
            self._prev_action[:] = a
            if self._command is not None:
                self._command.update(float(d.time))
                self._command.steer(yaw_of_quat(d.qpos[3:7]))
            reason = self._measure_safely()
        diverged = reason is not None

        meas = self._meas
        if diverged:
            index_norm = self._last_index_norm  # the buffers still hold the last good measurement
        else:
            reason = self._fall.reason(meas.base, meas.ground, meas.R, meas.trunk_contact)
            index_norm = meas.index / (self._mass * self._g)
        fell = reason is not None
        self._episode_steps += 1
        truncated = not fell and self._episode_steps >= self.episode_step_cap
        if truncated:
            reason = f"step cap: {self.episode_step_cap} control steps (episode_step_cap)"

        cog_x = float(meas.cog[0])
        cog_vel_x = 0.0 if diverged else (cog_x - x_before) / self.dt
        torque, tau_frac = d.actuator_force, self._tau_frac
        if diverged:
            tau_frac[:] = 0.0
            power = 0.0
        else:
            np.divide(torque, self.idx.torque_limit, out=tau_frac)
            joint_power = np.multiply(torque, self._qvel_joints, out=self._joint_power)
            power = float(np.abs(joint_power, out=joint_power).sum())
        terms = reward_terms(self.reward_weights, cog_vel_x, index_norm, tau_frac, power, self._mass * self._g, fell)
        if command is not None:
            terms.update(self._command_terms(meas, command, diverged))
        reward = float(sum(terms.values()))
        # After a failed step the observation is the last good one (that of the restored state).
        if not diverged:
            self._last_obs = self._observe(meas.obs)
            self._last_index_norm = index_norm
        obs = self._last_obs.copy()
        info = self._info(meas, terms, diverged, reason)
        if self.render_mode == "human":
            self.render()
        return obs, reward, fell, truncated, info

    def _command_terms(self, meas: StepMeasurement, command: np.ndarray, diverged: bool) -> dict[str, float]:
        """The command tracking terms of the step just taken (zeros after a failed step)."""
        if diverged:
            return dict.fromkeys(COMMAND_REWARD_TERMS, 0.0)
        v_W, omega_B, R = self.data.qvel[:3], self.data.qvel[3:6], meas.R
        yaw = math.atan2(R[1, 0], R[0, 0])
        c, s = math.cos(yaw), math.sin(yaw)
        v_H = np.array([c * v_W[0] + s * v_W[1], -s * v_W[0] + c * v_W[1]])
        yaw_rate = float(R[2] @ omega_B)  # world z component of the trunk's angular velocity
        return command_reward_terms(self.reward_weights, v_H, yaw_rate, command)

    # ------------------------------------------------------------------ physics loops
    def _advance(self, a: np.ndarray) -> str | None:
        """``frame_skip`` physics steps under the clipped action ``a``; the failure reason, or None.

        With a controller the loop stops at the first failure (the caller undoes the step). Pushes and
        latency (randomization) go through :meth:`_step_controller` / :meth:`_step_open_loop`; the
        nominal open-loop step is one ``mj_step`` call.
        """
        m, d = self.model, self.data
        segments = self._push_segments()
        if self._controller is not None:
            return self._step_controller(a, segments)
        if segments is None and self._latency == 0:
            if self.action_mode == "torque":
                np.multiply(a, self.idx.torque_limit, out=d.ctrl)
            else:
                np.clip(self._home_joints + self.pd_action_scale * a, self._joint_lo, self._joint_hi, out=d.ctrl)
            mujoco.mj_step(m, d, self.frame_skip)
        else:
            self._step_open_loop(a, segments)
        return None

    def _controller_torques_into(self, a: np.ndarray, out: np.ndarray) -> str | None:
        """Call the controller on the current (``mj_step1``) state and write its torques, clipped to the motor
        limits, into ``out``; the failure reason, or None.

        A failure is any exception the controller raises and any return that is not 12 finite numbers
        (a string, a mapping, None, a wrong shape, NaN/Inf).
        """
        try:
            raw = self._controller(self.model, self.data, a)
        except Exception as err:  # any controller error ends the episode; it never escapes step()
            return f"diverged: controller raised {type(err).__name__}: {err}"
        tau = raw if type(raw) is np.ndarray and raw.dtype == np.float64 else _as_float_array(raw)
        if tau is None or tau.shape != (C.N_JOINTS,):
            return f"diverged: controller returned {_describe(raw)}, not {C.N_JOINTS} finite torques (N m)"
        if not clip_finite_into(tau, self.idx.torque_limit, out):
            bad = np.flatnonzero(~np.isfinite(tau)).tolist()
            return f"diverged: controller returned non-finite torques (NaN/Inf at indices {bad})"
        return None

    def _restore_state(self, delayed: tuple[np.ndarray, np.ndarray] | None = None) -> None:
        """Put the simulation back to the state saved at the start of the control step (and recompute its
        derived quantities: positions, contacts, sensors); ``delayed``: the latency buffers saved with it.

        The push schedule's draw of the failed step is not undone (the episode ends there)."""
        mujoco.mj_setState(self.model, self.data, self._saved_state, _STATE)
        if delayed is not None:
            self._ctrl_ring[:], self._ctrl_prev[:] = delayed
        try:
            mujoco.mj_forward(self.model, self.data)
        except Exception:  # the episode is over: a state MuJoCo cannot evaluate stays as restored
            pass

    def _measure_safely(self) -> str | None:
        """:meth:`_measure`, with any error it raises turned into a failure reason (None when it succeeds)."""
        try:
            self._measure()
        except Exception as err:  # a measurement bug must end the episode, not a training run
            return f"diverged: measurement failed ({type(err).__name__}: {err})"
        return None

    # ------------------------------------------------------------------ physics loops
    def _step_controller(self, a: np.ndarray, segments: list | None) -> str | None:
        """``frame_skip`` physics steps under the physics-rate controller; the divergence reason or None.

        With latency k > 0 the torque the controller returns at physics step n is applied at step n + k
        (a ring of k + 1 commands); pushes set the trunk's ``xfrc_applied`` per step.
        """
        m, d = self.model, self.data
        ctrl = d.ctrl
        k, ring, n = self._latency, self._ctrl_ring, self._physics_step
        forces = None if segments is None else [f for length, f in segments for _ in range(length)]
        lane, limit = getattr(self._controller, "torques_into", None), self.idx.torque_limit
        counts, at_reset = self._warning_view, self._warnings_at_reset
        w0, w1, w2 = BAD_WARNINGS
        step1, step2 = mujoco.mj_step1, mujoco.mj_step2
        for j in range(self.frame_skip):
            if forces is not None and (j == 0 or forces[j] is not forces[j - 1]):
                self._set_push(forces[j])
            step1(m, d)
            if counts[w0] + counts[w1] + counts[w2] > at_reset:  # instability_warnings(data)
                return None  # reported by the caller; the controller must not see a garbage state
            out = ctrl if k == 0 else ring[(n + j) % (k + 1)]
            try:
                fast = lane is not None and lane(m, d, a, out, limit)
            except Exception:  # the lane declines; the call below decides
                fast = False
            if type(fast) is not bool:
                if not isinstance(fast, np.bool_):
                    return f"diverged: controller's torques_into returned {_describe(fast)}, not True or False"
                fast = bool(fast)
            if fast:
                if not clip_finite_into(out, limit, out):  # the lane's torques pass the call's checks too
                    bad = np.flatnonzero(~np.isfinite(out)).tolist()
                    return f"diverged: controller's torques_into wrote non-finite torques (NaN/Inf at indices {bad})"
            else:
                reason = self._controller_torques_into(a, out)
                if reason is not None:
                    return reason
            if k:
                ctrl[:] = ring[(n + j + 1) % (k + 1)]  # the command of k steps ago
            step2(m, d)  # a bad qacc here is caught by the next check (or the caller's)
        return None

    def _step_open_loop(self, a: np.ndarray, segments: list | None) -> None:
        """``frame_skip`` physics steps under action ``a`` with latency and/or pushes, as runs of ``mj_step``.

        The command is constant over the control step, so latency k means: the previous command for the
        first k physics steps, then this one; pushes split the runs where their force starts or stops.
        """
        m, d, cmd = self.model, self.data, self._cmd
        if self.action_mode == "torque":
            np.multiply(a, self.idx.torque_limit, out=cmd)
        else:
            np.clip(self._home_joints + self.pd_action_scale * a, self._joint_lo, self._joint_hi, out=cmd)
        k = self._latency
        runs = [(self.frame_skip, None)] if segments is None else segments
        j = 0
        for length, force in runs:
            self._set_push(force)
            for start, stop in ((j, min(j + length, k)), (max(j, k), j + length)):
                if stop > start:
                    d.ctrl[:] = self._ctrl_prev if start < k else cmd
                    mujoco.mj_step(m, d, stop - start)
            j += length
        self._ctrl_prev[:] = cmd

    def _push_segments(self) -> list | None:
        """This control step's push runs (see :meth:`PushSchedule.segments`) and its mean push force, or None."""
        if not self._push_schedule.on:
            return None
        segments = self._push_schedule.segments(self._world_rng, self._physics_step, self.frame_skip)
        mean = self._push_force
        mean[:] = 0.0
        for length, force in segments:
            if force is not None:
                mean += force * (length / self.frame_skip)
        return segments

    def _set_push(self, force: np.ndarray | None) -> None:
        """Push force (N, world) on the trunk's centre of mass, zero for None."""
        f = self.data.xfrc_applied[self.idx.trunk_body, :3]
        if force is None:
            f[:] = 0.0
        else:
            f[:] = force

    # ------------------------------------------------------------------ randomization
    def _init_randomization(self) -> None:
        """Bind the randomizer to the model (after the servos are made: their gains are nominal)."""
        cfg = self.randomization
        if cfg is not None and cfg.latency is not None and cfg.latency[1] > self._dt * (1 + 1e-9):
            raise ValueError(
                f"randomization.latency must be a [low, high] pair with high <= the control period "
                f"{self._dt:g} s (frame_skip x timestep), got {list(cfg.latency)}"
            )
        self.model_randomizer = ModelRandomizer(self.model, self.idx, servo=self.action_mode == "joint_pd")
        """writes each episode's draw into ``model`` and restores the nominal model (``restore()``)."""
        self._push_schedule = PushSchedule(cfg, self.physics_dt)
        self._push_force = np.zeros(3)
        self._cmd = np.zeros(C.N_JOINTS)
        self._ctrl_prev = np.zeros(C.N_JOINTS)
        self._ctrl_ring = np.zeros((1, C.N_JOINTS))
        self._physics_step = 0
        self._latency = 0
        self._world_rng: np.random.Generator | None = None
        noise = cfg.observation_noise if cfg is not None else None
        self._noise_scale = None
        self._obs_low64 = self.observation_space.low.astype(np.float64)
        self._obs_high64 = self.observation_space.high.astype(np.float64)
        if noise is not None and noise.any():  # the command is an input, not a measurement: never noisy
            self._noise_scale = np.concatenate(
                [np.full(f.size, 0.0 if f.name == "command" else getattr(noise, f.name)) for f in self._fields]
            )
        self._draw = self._nominal_draw()
        self._draw_info = self._draw.as_info()

    def _nominal_draw(self) -> EpisodeDraw:
        r = self.model_randomizer
        nominal = draw_episode(
            None, None, r.nominal_friction, r.nominal_damping, r.nominal_frictionloss, self.physics_dt
        )
        return dataclasses.replace(nominal, total_mass=self._mass)

    def _draw_world(self, rng: np.random.Generator | None) -> None:
        """Draw this episode's world from ``rng`` and apply it (``rng`` may be None without randomization).

        The draws (the world now, pushes and observation noise during the episode) come from a child of
        ``np_random`` (``np_random.spawn``, made by :meth:`reset`): the same seed gives the same world whatever
        the terrain generator consumed, and the terrain and reset noise are those of the nominal env.
        """
        cfg, r = self.randomization, self.model_randomizer
        if cfg is not None:
            self._world_rng = rng
            draw = draw_episode(
                cfg, self._world_rng, r.nominal_friction, r.nominal_damping, r.nominal_frictionloss, self.physics_dt
            )
            self._draw = r.apply(cfg, draw)
            self._draw_info = self._draw.as_info()
            self._mass = self._draw.total_mass
            self._meas.mass = self._mass
        k = self._latency = self._draw.latency_steps
        self._ctrl_ring = np.repeat(self.data.ctrl[None, :], k + 1, axis=0)
        self._ctrl_prev[:] = self.data.ctrl
        self._physics_step = 0
        self._push_force[:] = 0.0
        self._push_schedule.reset(self._world_rng)

    def _observe(self, obs: np.ndarray) -> np.ndarray:
        """The float32 observation of the measured ``obs``, with this config's noise, clipped to the Box."""
        if self._noise_scale is None:
            return obs.astype(np.float32)
        noisy = obs + self._noise_scale * self._world_rng.uniform(-1.0, 1.0, obs.shape[0])
        np.clip(noisy, self._obs_low64, self._obs_high64, out=noisy)
        return noisy.astype(np.float32)

    # ------------------------------------------------------------------ measurement
    def _measure(self) -> StepMeasurement:
        """Refresh :attr:`_meas` (contacts, COG, stability, terrain scan, observation) from ``data``."""
        mujoco.mj_subtreeVel(self.model, self.data)
        command = None if self._command is None else self._command.value
        self._meas.update(
            self.terrain.heightfield, self._prev_action, self.gait_period, command, self.terrain.spawn_xy[1]
        )
        return self._meas

    def _info(
        self, meas: StepMeasurement, terms: dict[str, float], diverged: bool, reason: str | None
    ) -> dict[str, Any]:
        index = meas.index
        return {
            "stability_index": index,
            "stability_index_normalized": index / (self._mass * self._g),
            "edge_moments": self._padded_moments(meas),
            "contact_forces": meas.foot_forces.copy(),
            "foot_contact": meas.foot_contact.copy(),
            "cog": meas.cog.copy(),
            "cog_vel": meas.cog_vel.copy(),
            "cog_acc": meas.cog_acc.copy(),
            "feet_pos": meas.feet_pos.copy(),
            "terrain_height_under_base": meas.ground,
            "distance": float(meas.cog[0]) - self._start_x,
            "diverged": diverged,
            "termination_reason": reason,
            "reward_terms": dict(terms),
            "randomization": dict(self._draw_info),
            "push_force": self._push_force.copy(),
            **({} if self._command is None else {"command": self._command.value.copy()}),
            **({} if self.command_heading is None else {"command_heading": self.command_heading}),
        }

    @staticmethod
    def _padded_moments(meas: StepMeasurement) -> np.ndarray:
        """(4,) edge moments (N m) of the clockwise support edges, +inf beyond the number of stance feet."""
        out = _INF_MOMENTS.copy()
        m = meas.moments
        out[: m.shape[0]] = m
        return out

    # ------------------------------------------------------------------ actuators
    def _make_servos(self, kp: float, kd: float) -> None:
        """Turn the torque motors into PD position servos (MuJoCo affine bias), limits kept."""
        m = self.model
        for i in range(C.N_JOINTS):
            lim = m.actuator_ctrlrange[i, 1]
            m.actuator_gainprm[i, 0] = kp
            m.actuator_biastype[i] = mujoco.mjtBias.mjBIAS_AFFINE
            m.actuator_biasprm[i, :3] = (0.0, -kp, -kd)
            m.actuator_forcelimited[i] = 1
            m.actuator_forcerange[i] = (-lim, lim)
            m.actuator_ctrlrange[i] = (self._joint_lo[i], self._joint_hi[i])

    # ------------------------------------------------------------------ rendering
    def _bind_data_views(self) -> None:
        """Views of ``self.data``'s buffers read every physics step (MuJoCo never reallocates them)."""
        self._warning_counts = self.data.warning.number  # live view of MuJoCo's warning counters
        # the same counters as Python ints at a fraction of numpy's indexing cost (read every physics step)
        self._warning_view = memoryview(self._warning_counts)
        self._qvel_joints = self.data.qvel[6:]

    # Rewritten at every reset anyway (the terrain) or read only by the renderer (textures).
    _NOT_RESTORED = ("hfield_data", "tex_data")

    def _bind_model_views(self) -> None:
        """Pairs (the model's array, the pristine copy's) that :meth:`_restore_model` copies, and the option names."""
        m, p = self.model, self._pristine_model
        if p is None:
            return
        names = [
            n for n in dir(m) if not n.startswith("_") and n not in self._NOT_RESTORED
            and isinstance(getattr(m, n), np.ndarray) and getattr(m, n).size
        ]  # fmt: skip
        self._model_views = [(getattr(m, n), getattr(p, n)) for n in names]
        self._option_names = [n for n in dir(m.opt) if not n.startswith("_")]

    def _restore_model(self) -> None:
        """Every numeric field of the model back to its value at the first reset (~0.25 ms): whatever a physics-rate
        controller or other code changes in ``env.unwrapped.model`` during an episode (a body mass, the timestep)
        lasts until the next reset, not beyond. Changes made between ``make`` and the first reset are kept for every
        episode. The randomized world is drawn after this."""
        if self._pristine_model is None:
            self._pristine_model = copy.deepcopy(self.model)
            self._bind_model_views()
            return
        for live, pristine in self._model_views:
            live[...] = pristine
        opt, saved = self.model.opt, self._pristine_model.opt
        for name in self._option_names:
            setattr(opt, name, getattr(saved, name))

    _DATA_VIEWS = ("_warning_counts", "_warning_view", "_qvel_joints", "_model_views")

    def __getstate__(self) -> dict[str, Any]:
        """``copy.deepcopy`` and pickle: everything but the views of ``data`` (rebound to the copy's own ``data``)
        and the renderer (a GL context; a copy opens its own at its first ``render``). The model, the data, the
        terrain, the random generator and the episode's state are copied, so the copy steps exactly as the
        original would from here. A physics-rate controller is copied with it and must support copying too."""
        state = {k: v for k, v in self.__dict__.items() if k not in self._DATA_VIEWS}
        state["_renderer"] = None
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._bind_data_views()
        self._bind_model_views()

    def _upload_terrain_to_renderer(self) -> None:
        if self._renderer is None:
            return
        for viewer in self._renderer._viewers.values():
            viewer.make_context_current()
            mujoco.mjr_uploadHField(self.model, viewer.con, self.idx.hfield)

    def render(self):
        """Render a frame from the tracking camera (``rgb_array``/``depth_array``) or to a window."""
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode to gym.make")
            return None
        if self._renderer is None:
            if display_missing(self.render_mode):
                if not self._warned_no_display:
                    gym.logger.warn(
                        "render_mode='human' needs a display, but neither DISPLAY nor WAYLAND_DISPLAY is set: no "
                        "window is opened; use render_mode='rgb_array' (offscreen) on a headless machine"
                    )
                    self._warned_no_display = True
                return None
            from gymnasium.envs.mujoco.mujoco_rendering import MujocoRenderer

            self._renderer = MujocoRenderer(
                self.model, self.data, width=self._width, height=self._height, camera_name=C.TRACK_CAMERA
            )
            self._renderer._get_viewer(self.render_mode)
            self._upload_terrain_to_renderer()
        return self._renderer.render(self.render_mode)

    def close(self) -> None:
        """Release the renderer."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None


def _as_float_array(raw: Any) -> np.ndarray | None:
    """``raw`` as a float64 array if it holds plain numbers (not bools, strings or objects), else None."""
    try:
        arr = np.asarray(raw)
    except Exception:  # ragged sequences, objects whose __array__ fails
        return None
    if arr.dtype.kind not in "iuf":
        return None
    return arr.astype(np.float64)


def _describe(raw: Any) -> str:
    """A short description of a malformed controller return, for ``termination_reason``."""
    if isinstance(raw, np.ndarray):
        return f"an array of shape {raw.shape} and dtype {raw.dtype}"
    return f"{excerpt(raw)} of type {type(raw).__name__}"


if QuadUnevenEnv.__doc__:
    QuadUnevenEnv.__doc__ = (
        QuadUnevenEnv.__doc__.replace(
            "OBSERVATION_TABLE",
            observation_table(observation_fields(HeightScanConfig(), command=True)).replace("\n", "\n    "),
        )
        .replace("ARGUMENTS_TABLE", arguments_table().replace("\n", "\n    "))
        .replace("COMMAND_TABLE", command_arguments_table().replace("\n", "\n    "))
    )
