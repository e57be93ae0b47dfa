"""QuadUneven-v0: the paper's 18-DOF quadruped walking along +x over generated uneven terrain.

The task (reset, step, reward, info) over a composition of parts: the arguments
(:class:`~quad_uneven_env.env_config.EnvConfig`), the compiled scene, the action map
(:mod:`~quad_uneven_env.actuation`), the physics loop (:class:`~quad_uneven_env.stepper.PhysicsStepper`), the
episode's simulated world (:class:`~quad_uneven_env.world.SimulatedWorld`), the measurement
(:class:`~quad_uneven_env.measurement.StepMeasurement`) and the renderer
(:class:`~quad_uneven_env.rendering.SceneRenderer`).
"""

from __future__ import annotations

import dataclasses
import inspect
import math
import operator
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np
from gymnasium import spaces

from quad_uneven_env import constants as C
from quad_uneven_env.actuation import ActionMap, make_servos
from quad_uneven_env.command import CommandConfig, CommandSchedule, command_arguments_table
from quad_uneven_env.config import HeightScanConfig, RewardWeights, TerminationLimits
from quad_uneven_env.env_config import EnvConfig, arguments_table
from quad_uneven_env.fields import excerpt
from quad_uneven_env.history import ProprioHistory, history_fields
from quad_uneven_env.measurement import StepMeasurement
from quad_uneven_env.measurement_kernels import clip_finite_into
from quad_uneven_env.observations import (
    height_scan_points_B,
    observation_fields,
    observation_space,
    observation_structure,
    observation_table,
)
from quad_uneven_env.physics import RobotIndex
from quad_uneven_env.randomization import EpisodeDraw, ModelRandomizer, Push, RandomizationConfig
from quad_uneven_env.rendering import RENDER_MODES, SceneRenderer
from quad_uneven_env.rewards import COMMAND_REWARD_TERMS, REWARD_TERMS, command_reward_terms, reward_terms
from quad_uneven_env.robot.description import RobotDescription
from quad_uneven_env.scene import compile_scene
from quad_uneven_env.spatial import yaw_of_quat
from quad_uneven_env.stepper import PhysicsController, PhysicsStepper, check_controller
from quad_uneven_env.termination import FallCheck
from quad_uneven_env.terrain import Terrain
from quad_uneven_env.world import SimulatedWorld

_INF_MOMENTS = np.full(C.N_LEGS, np.inf)
"""the padding of ``info["edge_moments"]`` (copied, never written)."""


def _argument(name: str, doc: str) -> Any:
    """A read-only attribute of the env: its argument ``name`` as checked, ``env.config.<name>``."""
    return property(operator.attrgetter(f"config.{name}"), doc=doc)


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
    centre line). The default observation does not change. With ``proprio_history=H`` (0-50 control steps)
    ``joint_pos_history``, ``joint_vel_history`` and ``prev_action_history`` (H x 12 each: the H previous
    observations' values, oldest first; :mod:`quad_uneven_env.history`) are appended after everything else.

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

    **Arguments** (the keywords of ``gym.make``; checked at make time into ``env.unwrapped.config``, a
    :class:`~quad_uneven_env.env_config.EnvConfig`): ``terrain`` (kind name or ``{"kind": ..., **params}``, see
    docs/terrain.md; default ``"rough"``), ``robot`` (a name of :func:`quad_uneven_env.robots`, or a robot YAML
    path: a Table-1 config or a URDF robot's, see docs/robots.md; default ``"paper"``), ``controller``
    (None or a :class:`PhysicsController`), ``reward_weights``, ``termination``, ``height_scan``
    (mappings of :mod:`quad_uneven_env.config`'s fields; ``termination.min_base_height`` and
    ``max_base_height`` default to the robot's, a third of its standing height and 2.78 times it: 0.12 and 1 m
    for the paper's robot), and the scalars below, each checked by type and range (a bool is not a number; the
    error names the argument and its allowed values):

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

    **Copies** (``copy.deepcopy``, pickle): the model, the data, the terrain, the random generator and the
    episode's state are copied (without the renderer's GL context: a copy opens its own at its first ``render``),
    so a copy steps exactly as the original would from here. A physics-rate controller is copied with it and must
    support copying too.
    """

    metadata = {"render_modes": list(RENDER_MODES), "render_fps": 50}  # noqa: RUF012

    def __init__(
        self, *, controller: PhysicsController | Callable[..., np.ndarray] | None = None, **arguments: Any
    ) -> None:
        self.config = config = EnvConfig(**arguments)
        """the arguments, checked (see **Arguments**)."""
        check_controller(controller, config.action_mode)
        self.terrain = Terrain(config.terrain)
        self._command = None if config.command is None else CommandSchedule(config.command)
        self.model = compile_scene(config.robot, self.terrain, config.timestep)
        self.data = mujoco.MjData(self.model)
        self.idx = RobotIndex.from_model(self.model)
        self._dt = float(self.model.opt.timestep) * config.frame_skip
        self._g = float(-self.model.opt.gravity[2])
        joint_lo, joint_hi = self.model.jnt_range[1:, 0].copy(), self.model.jnt_range[1:, 1].copy()
        self.action_map = ActionMap(
            config.action_mode, self.idx.torque_limit, joint_lo, joint_hi, config.pd_action_scale
        )
        """the map from an action to the actuators' command (``home_joints``: the episode's standing pose)."""
        if config.action_mode == "joint_pd":
            make_servos(self.model, config.pd_kp, config.pd_kd, joint_lo, joint_hi)
        self._stepper = PhysicsStepper(
            self.model, self.data, self.idx, config.frame_skip, self.action_map, config.randomization
        )
        self._stepper.controller = controller
        self._fall = FallCheck(config.termination)

        self.action_space = spaces.Box(-1.0, 1.0, (C.N_JOINTS,), dtype=np.float32)
        # the measured fields, then the proprioceptive history the env keeps of them
        measured = observation_fields(
            config.height_scan, C.N_JOINTS, command=self._command is not None, course_frame=config.course_frame
        )
        self._fields = measured + history_fields(measured, config.proprio_history)
        self.observation_structure: dict[str, slice] = observation_structure(self._fields)
        self.observation_space = observation_space(self._fields)
        # Row 0 of the terrain queries is the point under the base, the rest the height scan grid.
        self._scan_B = np.vstack([np.zeros((1, 2)), height_scan_points_B(config.height_scan)])
        space = observation_space(measured)
        self._meas = StepMeasurement(
            self.model, self.data, self.idx, config.robot.foot_radius, self._scan_B, measured, space.low, space.high
        )
        servo = config.action_mode == "joint_pd"
        self._world = SimulatedWorld(self.model, self.idx, config.randomization, servo, self._dt, measured, space)
        self._history = ProprioHistory(observation_structure(measured), config.proprio_history)

        self.render_mode = config.render_mode
        self.metadata = dict(self.metadata, render_fps=round(1.0 / self.dt))
        self._view = SceneRenderer(
            self.model, self.data, config.render_mode, config.width, config.height, self.idx.hfield
        )

        self._unit_bounds = np.ones(C.N_JOINTS)
        self._tau_frac = np.zeros(C.N_JOINTS)  # the reward's scratch buffers
        self._joint_power = np.zeros(C.N_JOINTS)
        self._prev_action = np.zeros(C.N_JOINTS)
        self._last_obs = np.zeros(self.observation_space.shape, dtype=np.float32)
        self._last_index_norm = self._start_x = self._mg = 0.0
        self._episode_steps = 0
        self._needs_reset = True

    # ------------------------------------------------------------------ the arguments, as attributes
    robot: RobotDescription = _argument(
        "robot", "the robot's description (any robot: the paper's, a shipped URDF robot's or a user's YAML)."
    )
    action_mode: str = _argument("action_mode", "what an action commands (see **Action**).")
    frame_skip: int = _argument("frame_skip", "physics steps per control step.")
    gait_period: float = _argument("gait_period", "s, the period of the observation's gait clock.")
    reset_noise_scale: float = _argument("reset_noise_scale", "rad, rad/s: the reset's joint noise.")
    pd_action_scale: float = _argument("pd_action_scale", "rad per unit of action (``joint_pd``).")
    episode_step_cap: int = _argument("episode_step_cap", "control steps after which the env truncates an episode.")
    course_frame: bool = _argument("course_frame", "the observation ends with the course frame (**Observation**).")
    proprio_history: int = _argument("proprio_history", "control steps of proprioception kept (**Observation**).")
    reward_weights: RewardWeights = _argument("reward_weights", "the reward's weights (**Reward**).")
    termination: TerminationLimits = _argument("termination", "when an episode ends in a fall (**Episode end**).")
    height_scan: HeightScanConfig = _argument("height_scan", "the observation's terrain scan grid.")
    command_config: CommandConfig | None = _argument("command", "the ``command`` argument (None: no command).")
    randomization: RandomizationConfig | None = _argument(
        "randomization", "the randomization in SI units for this robot (a preset's ``scale: robot`` ranges scaled)."
    )

    # ------------------------------------------------------ timing, controller, the episode's world and command
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
        return self._stepper.controller

    def set_controller(self, controller: PhysicsController | Callable[..., np.ndarray] | None) -> None:
        """Install (or remove, with None) the physics-rate controller; takes effect at the next step.

        :raises ValueError: if ``controller`` is not callable, or the env is in ``action_mode="joint_pd"``.
        """
        check_controller(controller, self.action_mode)
        self._stepper.controller = controller

    @property
    def total_mass(self) -> float:
        """kg, the simulated whole-robot mass of this episode (the nominal one unless masses are randomized)."""
        return self._world.total_mass

    @property
    def episode_draw(self) -> EpisodeDraw:
        """This episode's drawn world (nominal values where a factor is off)."""
        return self._world.episode_draw

    @property
    def model_randomizer(self) -> ModelRandomizer:
        """Writes each episode's draw into ``model`` and restores the nominal model (``restore()``)."""
        return self._world.randomizer

    @property
    def pushes(self) -> list[Push]:
        """The pushes started so far this episode (start time, impulse, direction, duration, force)."""
        return self._stepper.pushes

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

    # ------------------------------------------------------------------ reset
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Regenerate the terrain from ``np_random``, stand the robot at the spawn point, draw the episode's world.

        :param seed: None or an integer >= 0 (not a bool); see :meth:`gymnasium.Env.reset`.
        """
        if seed is not None and (
            isinstance(seed, bool | np.bool_) or not isinstance(seed, int | np.integer) or seed < 0
        ):
            raise ValueError(f"seed must be None or an integer >= 0, got {excerpt(seed)} of type {type(seed).__name__}")
        super().reset(seed=None if seed is None else int(seed))
        if options:
            raise ValueError(f"reset options are not supported (got keys {sorted(options)}); pass terrain to make()")
        m, d = self.model, self.data
        self._world.restore_model()
        self._new_terrain()
        mujoco.mj_resetData(m, d)
        d.qpos[:] = self._spawn_qpos()
        noise = self.reset_noise_scale
        if noise > 0:
            lo, hi = self.action_map.joint_lo, self.action_map.joint_hi
            d.qpos[7:] = np.clip(d.qpos[7:] + self.np_random.uniform(-noise, noise, C.N_JOINTS), lo, hi)
            d.qvel[6:] = self.np_random.uniform(-noise, noise, C.N_JOINTS)
        self.action_map.stand(d)
        # One child of np_random per reset, for the randomized world and (through its own child) the command:
        # spawning draws nothing from np_random, and the world keeps the child it has without a command.
        child = self.np_random.spawn(1)[0] if self.randomization is not None or self._command is not None else None
        self._world.draw(child)
        self._meas.mass = self.total_mass
        self._mg = self.total_mass * self._g  # N, the episode's weight: the stability index's normaliser
        if self._command is not None:
            self._command.reset(child.spawn(1)[0])
            self._command.steer(yaw_of_quat(d.qpos[3:7]))
        mujoco.mj_forward(m, d)
        self._stepper.reset(self._world.episode_draw.latency_steps, self._world.rng)
        if self.controller is not None and hasattr(self.controller, "reset"):
            self.controller.reset(m, d, self.terrain)

        self._prev_action[:] = 0.0
        self._episode_steps = 0
        self._needs_reset = False
        meas = self._measure()
        self._start_x = float(meas.cog[0])
        self._last_index_norm = meas.index / self._mg
        self._last_obs = self._history.reset(self._world.observe(meas.obs))
        names = REWARD_TERMS if self._command is None else REWARD_TERMS + COMMAND_REWARD_TERMS
        info = self._info(meas, terms=dict.fromkeys(names, 0.0), diverged=False, reason=None)
        return self._last_obs.copy(), info

    def _spawn_qpos(self) -> np.ndarray:
        """Standing pose over the spawn point: each foot on the terrain below its standing point."""
        x0, y0 = self.terrain.spawn_xy
        feet_xy = self.robot.standing_feet_B[:, :2] + np.array([x0, y0])
        ground = np.asarray(self.terrain.height(feet_xy[:, 0], feet_xy[:, 1]), dtype=float)
        base_z, joints = self.robot.stand_on(ground)
        qpos = np.zeros(C.NQ)
        qpos[:4] = (x0, y0, base_z, 1.0)
        qpos[7:] = np.clip(joints, self.action_map.joint_lo, self.action_map.joint_hi)
        return qpos

    def _new_terrain(self) -> None:
        """This episode's terrain from ``np_random``, in the model and the renderer; the fall check's edges."""
        self.terrain.generate(self.np_random)
        self.terrain.upload(self.model)
        (xmin, xmax), (ymin, ymax) = self.terrain.heightfield.extent
        margin = 0.3  # m: the robot has left the terrain before its trunk reaches the edge
        self._fall.inside_xy = (xmin + margin, xmax - margin, ymin + margin, ymax - margin)
        self._view.upload_terrain()

    # ------------------------------------------------------------------ step
    def step(self, action: np.ndarray):
        """Advance ``frame_skip`` physics steps under ``action``; see the class docstring."""
        a = self._checked_action(action)
        x_before = float(self._meas.cog[0])
        command = None if self._command is None else self._command.value.copy()  # in effect during this step
        reason = self._stepper.step(a)  # a failed control step is undone: the state is the last good one again
        if reason is None:
            self._prev_action[:] = a
            if self._command is not None:
                self._command.update(float(self.data.time))
                self._command.steer(yaw_of_quat(self.data.qpos[3:7]))
            reason = self._measure_safely()
        diverged = reason is not None

        meas = self._meas
        if diverged:
            index_norm = self._last_index_norm  # the buffers still hold the last good measurement
        else:
            reason = self._fall.reason(meas.base, meas.ground, meas.R, meas.trunk_contact)
            index_norm = meas.index / self._mg
        fell = reason is not None
        self._episode_steps += 1
        truncated = not fell and self._episode_steps >= self.episode_step_cap
        if truncated:
            reason = f"step cap: {self.episode_step_cap} control steps (episode_step_cap)"

        terms = self._reward_terms(x_before, index_norm, fell, diverged, command)
        reward = float(sum(terms.values()))
        if not diverged:  # after a failed step the observation is the last good one (that of the restored state)
            self._last_obs = self._history.push(self._world.observe(meas.obs), self._last_obs)
            self._last_index_norm = index_norm
        info = self._info(meas, terms, diverged, reason)
        if self.render_mode == "human":
            self.render()
        return self._last_obs.copy(), reward, fell, truncated, info

    def _checked_action(self, action: np.ndarray) -> np.ndarray:
        """``action`` clipped to [-1, 1] as a read-only (12,) float64 array; raises before anything runs."""
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
        clipped.setflags(write=False)  # a controller is handed this array: it may read it, not change the action
        return clipped

    # ------------------------------------------------------------------ measurement and reward
    def _measure(self) -> StepMeasurement:
        """Refresh :attr:`_meas` (contacts, COG, stability, terrain scan, observation) from ``data``."""
        mujoco.mj_subtreeVel(self.model, self.data)
        command = None if self._command is None else self._command.value
        self._meas.update(
            self.terrain.heightfield, self._prev_action, self.gait_period, command, self.terrain.spawn_xy[1]
        )
        return self._meas

    def _measure_safely(self) -> str | None:
        """:meth:`_measure`, with any error it raises turned into a failure reason (None when it succeeds)."""
        try:
            self._measure()
        except Exception as err:  # a measurement bug must end the episode, not a training run
            return f"diverged: measurement failed ({type(err).__name__}: {err})"
        return None

    def _reward_terms(
        self, x_before: float, index_norm: float, fell: bool, diverged: bool, command: np.ndarray | None
    ) -> dict[str, float]:
        """The named reward terms of the step just taken (see **Reward**); ``x_before``: m, the COG's x before it."""
        meas, d, tau_frac = self._meas, self.data, self._tau_frac
        cog_vel_x = 0.0 if diverged else (float(meas.cog[0]) - x_before) / self.dt
        if diverged:
            tau_frac[:] = 0.0
            power = 0.0
        else:
            torque = d.actuator_force
            np.divide(torque, self.idx.torque_limit, out=tau_frac)
            joint_power = np.multiply(torque, d.qvel[6:], out=self._joint_power)
            power = float(np.abs(joint_power, out=joint_power).sum())
        terms = reward_terms(self.reward_weights, cog_vel_x, index_norm, tau_frac, power, self._mg, fell)
        if command is not None:
            terms.update(self._command_terms(meas, command, diverged))
        return terms

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

    def _info(
        self, meas: StepMeasurement, terms: dict[str, float], diverged: bool, reason: str | None
    ) -> dict[str, Any]:
        index = meas.index
        return {
            "stability_index": index,
            "stability_index_normalized": index / self._mg,
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
            "randomization": dict(self._world.draw_info),
            "push_force": self._stepper.push_force.copy(),
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

    # ------------------------------------------------------------------ rendering
    def render(self):
        """Render a frame from the tracking camera (``rgb_array``/``depth_array``) or to a window."""
        return self._view.render()

    def close(self) -> None:
        """Release the renderer."""
        self._view.close()


# What inspect and help() show as the signature: ``controller`` and the config's fields, with their defaults.
QuadUnevenEnv.__init__.__signature__ = inspect.Signature(
    [
        inspect.Parameter("self", inspect.Parameter.POSITIONAL_OR_KEYWORD),
        inspect.Parameter("controller", inspect.Parameter.KEYWORD_ONLY, default=None),
    ]
    + [
        inspect.Parameter(f.name, inspect.Parameter.KEYWORD_ONLY, default=f.default)
        for f in dataclasses.fields(EnvConfig)
    ]
)

if QuadUnevenEnv.__doc__:
    QuadUnevenEnv.__doc__ = (
        QuadUnevenEnv.__doc__.replace(
            "OBSERVATION_TABLE",
            observation_table(observation_fields(HeightScanConfig(), command=True)).replace("\n", "\n    "),
        )
        .replace("ARGUMENTS_TABLE", arguments_table().replace("\n", "\n    "))
        .replace("COMMAND_TABLE", command_arguments_table().replace("\n", "\n    "))
    )
