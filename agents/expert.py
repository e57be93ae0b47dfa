"""The scripted expert: the paper's planner and inverse-dynamics controller in the loop.

:class:`ExpertPolicy` replans every gait cycle from the measured state (receding horizon:
footholds, COG path, swing paths) heading +x (or, in an env with a ``command``, advancing by the
commanded (vx, vy) times the cycle's duration and turning by the commanded yaw rate times it: forwards,
backwards, sideways, turning, in place), with the body pitched along the slope of the footholds
(``ExpertConfig.body_pitch``; the paper keeps it level), and runs the computed-torque
controller (:class:`agents.control.controller.ComputedTorqueController`) at physics rate through the env's
control hook.

*Its own model* (``ExpertConfig.model="nominal"``, the default). The expert plans and controls with
a nominal model of the robot (:class:`agents.control.nominal.NominalModel`, compiled from the
robot configuration the env was built from, before any randomization) and nominal assumptions
(``ExpertConfig``: the configuration's masses and centres of mass, and a friction coefficient
``friction`` for its cones, with margin below the nominal 1.0). What it reads from the simulator
is what a robot measures, and nothing else:

- joint angles and velocities (encoders): ``qpos[7:]``, ``qvel[6:]``;
- base pose and twist (state estimator): ``qpos[:7]`` (position, world; quaternion w, x, y, z)
  and ``qvel[:6]`` (linear velocity, world; angular velocity, base frame);
- foot contacts (contact switches), one boolean per foot: whether the foot geom touches the
  terrain in MuJoCo's contact list of the current step, and the feet's contact sensors' found
  flags (the same booleans after the previous step's constraint solve) for late touch-downs;
- the height field as its map (``env.unwrapped.terrain``), and the clock ``data.time``.

Every copy goes into the nominal model's data (:meth:`NominalModel.measure`), whose position and
velocity stages give the mass matrix, bias forces, foot Jacobians and COG the controller and the
planner use. The simulator's masses, inertias, friction, motor strength, contact forces and COG
are never read. When the simulated robot is exactly nominal (checked at every reset by
:meth:`NominalModel.matches`) and ``share_nominal_world`` is on, the controller reads the same
terms straight from the simulator's data: they equal the nominal model's bit for bit (tested), and
the copy would only cost time. ``model="oracle"`` is the expert before it had a model of its own:
it reads the simulator's live model and data, and its cones use the simulated friction
(for comparison; never the default).

It follows SB3's ``predict`` protocol so the evaluation code runs it like a learned agent;
``predict`` returns the zero action because the work is done in the physics-rate hook (the
residual RL agent adds its action on top of it).

When a plan fails (:class:`planners.PlanningError`) the expert degrades: it retries with the
strides of :data:`STRIDE_FALLBACKS` (shorter, longer, half with a sideways body shift, then in
place), then stands still for one cycle (holding the measured pose) and replans; every failure
is recorded in :attr:`ExpertPolicy.failure_log`. Footholds steeper than its friction pyramid holds
are refused (:func:`foothold_limits_for_friction`). It never raises out of a rollout: any other
failure of the planner is handled like a failed plan, and a failure of the controller at a physics
step (logged with its reason) keeps the last good torques for that step.
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np
from threadpoolctl import ThreadpoolController

from agents.control import inverse_dynamics_kernels as IK
from agents.control.adaptation import ADAPTATIONS, make_adaptation
from agents.control.controller import ComputedTorqueController, Gains
from agents.control.inverse_dynamics import DISTRIBUTIONS
from agents.control.nominal import NominalModel
from agents.control.slip import SLIP_DURATION, SlipDetector
from planners import FootholdLimits, PlanningError, Scenario, plan_gait_cycle
from planners.cycle import STANCE_REACH
from planners.gait import validate_durations
from planners.pitch import pitch_of_quaternion, yaw_pitch_of_quaternion
from planners.reference import aim_feet_below_footholds
from planners.scenario import BODY_PITCH_MODES
from planners.types import FootholdError, ReferenceGrid, ReferenceSample
from quad_uneven_env import constants as C
from quad_uneven_env import physics
from quad_uneven_env.fields import check_fields, param
from quad_uneven_env.measurement_kernels import clip_finite_into
from quad_uneven_env.robot.dynamics import BACKENDS
from quad_uneven_env.robot.kinematics import hip_positions_B
from quad_uneven_env.spatial import quat_to_matrix, wrap_angle, yaw_of_quat

EXPERT_MODELS: tuple[str, ...] = ("nominal", "oracle")
"""Allowed values of ``ExpertConfig.model``."""

DISTURBANCE_CHECK_EVERY = 5
"""physics steps between two checks of the base against its plan (``ExpertConfig.recovery``)."""
_NO_OFF_PLAN_CHECK = (-1.0, -1.0)  # ComputedTorqueController.grid_step_into's "no check"

SIDE_STEP = 1e-3
"""m: a cycle's advance to the left beyond which the expert lifts its left legs first (the mirrored swing order)."""

STRIDE_FALLBACKS: tuple[tuple[float, float], ...] = (
    (1.0, 0.0), (0.75, 0.0), (1.25, 0.0), (0.5, 0.0), (0.5, 0.05), (0.5, -0.05), (0.0, 0.0),
)  # fmt: skip
"""Strides tried in turn when a plan fails, closest to the nominal first: (fraction of the cycle's stride (the
commanded one, else ``ExpertConfig.stride`` along +x), sideways body shift (m, world y)); the first feasible
plan is walked. Shorter and longer strides move every nominal foothold (onto the next stone, off a reach
limit), a sideways shift moves the body over its support; 0 steps in place. If none is feasible the expert
stands still for one cycle."""

MAX_TURN = 1.2
"""rad: the largest yaw change the expert plans in one gait cycle (0.39 rad/s with the default 3.1 s cycle)."""

MAX_FAILURE_LOG = 1000
"""At most this many entries are kept in :attr:`ExpertPolicy.failure_log` per episode (then a count)."""
SLIP_CHECK_EVERY = 2
"""physics steps between two slip checks (``ExpertConfig.friction_adapt``): 4 ms."""
SLIP_MIN_TILT_COS = float(np.cos(np.radians(15.0)))
"""cos of the steepest stance foothold tilt at which a slip still lowers the assumed friction: on steeper
ground a slipping foot is not read as a slippery floor (measured on ramps of friction 1: stance feet
that land or are dragged on 20-25 deg slide for 5-12 ms)."""
SLIP_SPAWN_SETTLE = 0.1
"""s: no slip is read in the first this-long of an episode, while the robot settles on its spawn pose (its
joints carry the reset noise; 6 of the 60 `targets` episodes read a slip at 0.01 s on floors of friction 1)."""
SLIP_COOLDOWN = 0.1
"""s: at most one decrease of the assumed friction in this time (a slip is seen at several checks)."""
MAX_CYCLE_STRIDE = 0.45
"""m: the longest body advance per cycle the expert plans at its configured phases (0.145 m/s with the
default 3.1 s cycle); a faster command shortens the phases instead (``ExpertPolicy._cycle_durations``)."""
MIN_PHASE = 0.3
"""s: phases are never shortened below this (nor are phases this short or shorter shortened)."""
AIRBORNE_FOOTHOLD_RADIUS = 0.1
"""m: a foot in the air at a replan lands at the terrain point nearest to it within this horizontal radius."""


def _disc_offsets(radius: float, step: float) -> np.ndarray:
    """(n, 2) m: the points of a square grid of spacing ``step`` (m) within ``radius`` (m) of the origin."""
    k = np.arange(-int(radius / step), int(radius / step) + 1) * step
    grid = np.stack(np.meshgrid(k, k), axis=-1).reshape(-1, 2)
    return grid[np.hypot(grid[:, 0], grid[:, 1]) <= radius + 1e-9]


_AIRBORNE_DISC = _disc_offsets(AIRBORNE_FOOTHOLD_RADIUS, 0.01)
"""(n, 2) m: horizontal offsets on a 1 cm grid within ``AIRBORNE_FOOTHOLD_RADIUS`` (the origin included)."""
HEADING_DEADBAND = 1e-3
"""rad: in heading mode, a heading error below this is not turned (the plans stay those of a straight walk)."""


@dataclasses.dataclass(frozen=True)
class ExpertConfig:
    """Gait and control settings of the expert (SI units), and the nominal assumptions it plans and controls with.

    Nominal assumptions (``model="nominal"``): the robot's masses, inertias and centres of mass are those of
    the robot configuration the env was built from (``env.unwrapped.robot_cfg``; the paper's robot: 50 kg
    in all, link COMs as in Table 1), never the simulator's; a payload, scaled links or a
    shifted COM are disturbances to it. Its friction cones assume ``friction`` (0.5, half the nominal
    floor's 1.0; the inscribed pyramid's ``friction / sqrt(2)`` = 0.35 per tangent axis is the margin that
    covers floors down to about 0.35-0.5 depending on the force's direction). Motor strength, joint
    damping and friction, latency and pushes are not modelled: the feedback and the replanning
    (``recovery``) absorb them.
    """

    durations: tuple[float, ...] = (0.5, 0.5, 0.5, 0.1, 0.5, 0.5, 0.5)
    """s: the 7 phases of the walk cycle (paper order; the paper uses 1, 1, 1, 0.1, 1, 1, 1)."""
    stride: float = param(0.33, "m", lo=0.0, hi=1.0, lo_open=True)
    """m, in (0, 1]: body advance per cycle along +x (0.33 m / 3.1 s = 0.106 m/s nominal); unused in an env with a
    ``command``, whose (vx, vy) times the cycle's duration is the advance instead."""
    cog_height: float = param(0.33, "m", lo=0.1, hi=0.5)
    """m, in [0.1, 0.5]: COG height above the mean foothold height."""
    epsilon: float = param(20.0, "N m", lo=0.0, hi=1000.0)
    """N m, in [0, 1000]: stability margin of the planned COG path (20 N m = 4 cm of static margin for
    50 kg): much more than the paper's 0.1 N m, because the measured index must stay positive under
    tracking errors and the QP needs room to keep every stance force inside its cone."""
    clearance: float = param(0.05, "m", lo=0.0, hi=0.3)
    """m, in [0, 0.3]: swing clearance of the foot sphere above the terrain."""
    touchdown_depth: float = param(0.015, "m", lo=0.0, hi=0.1)
    """m, in [0, 0.1]: how far below its foothold a late foot (planned stance, no contact yet) is aimed."""
    body_pitch: str = param("terrain", kind="choice", choices=BODY_PITCH_MODES)
    """base orientation of the plans: "terrain" (pitch with the slope of the footholds, so the legs on
    the higher steps of a stair are not folded until their shanks rest on the nosing) or "level"
    (identity, the paper); see :mod:`planners.pitch`."""
    distribution: str = param("qp", kind="choice", choices=DISTRIBUTIONS)
    """inverse-dynamics torque distribution: "pinv" (paper) or "qp" (friction cones)."""
    backend: str = param("mujoco", kind="choice", choices=BACKENDS)
    """dynamics backend of the controller."""
    gains: Gains = dataclasses.field(default_factory=Gains)
    """computed-torque gains."""
    model: str = param("nominal", kind="choice", choices=EXPERT_MODELS)
    """what the expert plans and controls with: "nominal" (its own model of the nominal robot: the robot
    configuration's masses, inertias and centres of mass, fed with the measured state only, see the
    module docstring) or "oracle" (the simulator's live model and state, and its friction in the cones)."""
    friction: float = param(0.5, "-", lo=0.0, hi=2.0, lo_open=True)
    """-, in (0, 2]: friction coefficient the nominal model assumes in its "qp" friction cones at the start
    of an episode (the 4-sided pyramid inside the cone, mu / sqrt(2) per axis), and the slope limit of
    its footholds (``foothold_limits_for_friction``). The nominal floor's is 1.0; 0.5 keeps the planned
    forces inside the cones of floors down to about 0.4. With ``friction_adapt`` it is lowered when a
    stance foot slips. Unused by "oracle", which takes the simulator's."""
    steep_friction: float = param(0.8, "-", lo=0.0, hi=2.0)
    """-, in [0, 2]: the friction the nominal model may assume for one gait cycle whose footholds ``friction``
    refuses as too steep (a ramp steeper than atan(friction / sqrt(2)), 19.5 deg at 0.5): such a stride is
    planned again with the slope limit of this friction, and if that plan is feasible its cycle runs with
    cones of this friction. The nominal floor's is 1.0, so 0.8 spends part of the margin only where the
    ground leaves no choice (ramps to 28.6 deg, the foothold search's cap); 0 never does (the expert then
    stands before such ramps). Scaled down with ``friction`` when slips lower it (``friction_adapt``). Unused
    by "oracle"."""
    friction_adapt: bool = False
    """lower the assumed friction when a stance foot slips: a planned-stance foot in contact whose contact
    point moves faster than ``slip_speed`` horizontally for 8 ms (:mod:`agents.control.slip`: measured
    state, the expert's own kinematics, checked every :data:`SLIP_CHECK_EVERY` physics steps) multiplies it
    by ``friction_decrease``, at most once per :data:`SLIP_COOLDOWN` s and never below ``friction_min``; the
    cones and the foothold slope limit follow at once, and every change is logged. It is never raised
    again within the episode. Off by default: it walks floors of 0.3-0.45, but under hard randomization
    pushed feet read as slips and it loses ``robust_hard`` episodes (docs/robustness.md#friction-adaptation)."""
    slip_speed: float = param(0.05, "m/s", lo=0.0, lo_open=True)
    """m/s, > 0: a stance foot's contact point moving faster than this (for ``SLIP_DURATION``) slips; one
    that holds moves < 0.025 m/s on rough terrain."""
    friction_decrease: float = param(0.8, "-", lo=0.0, hi=1.0, lo_open=True, hi_open=True)
    """-, in (0, 1): the factor of one decrease of the assumed friction."""
    friction_min: float = param(0.25, "-", lo=0.0, hi=2.0, lo_open=True)
    """-, in (0, 2]: the assumed friction is never lowered below this."""
    recovery: bool = True
    """replan within the cycle, from the measured state, when the base is pushed off its plan (see
    ``recovery_velocity``, ``recovery_position``): the new cycle starts with four-leg support, so a foot
    in the air is put down below where it is, and its COG path starts with the measured velocity."""
    recovery_velocity: float = param(0.12, "m/s", lo=0.0, lo_open=True)
    """m/s, > 0: horizontal base velocity error (measured minus planned) that triggers a replan."""
    recovery_position: float = param(0.04, "m", lo=0.0, lo_open=True)
    """m, > 0: horizontal base position error that triggers a replan."""
    share_nominal_world: bool = True
    """with "nominal": when the simulated robot's parameters equal the nominal ones exactly (checked at
    every reset), read the dynamics terms from the simulator's data instead of copying the measured
    state into the nominal model: the same numbers bit for bit (tested), about 10 µs a step cheaper."""
    adaptation: str = param("none", kind="choice", choices=ADAPTATIONS)
    """adaptive gains on the controller's joint torques (:mod:`agents.control.adaptation`), updated once per control
    step of the env from the plan's tracking error and the torques: "none", "knee" (the four knees' gains follow
    the correlation of their tracking error with their load) or "learned" (all twelve, driven by the learned
    strength estimator). They undo weak or strong motors and a heavier body than the model's."""

    def __post_init__(self) -> None:
        check_fields(self)
        validate_durations(self.durations)
        if not isinstance(self.gains, Gains):
            raise ValueError(f"ExpertConfig.gains must be a Gains, got {self.gains!r}")
        for name in ("recovery", "friction_adapt"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"ExpertConfig.{name} must be True or False, got {getattr(self, name)!r}")
        if not isinstance(self.share_nominal_world, bool):
            raise ValueError(
                f"ExpertConfig.share_nominal_world must be True or False, got {self.share_nominal_world!r}"
            )


_BLAS: list[ThreadpoolController] = []


def _blas_controller() -> ThreadpoolController:
    """One ThreadpoolController per process: building it scans the loaded libraries."""
    if not _BLAS:
        _BLAS.append(ThreadpoolController())
    return _BLAS[0]


class _HoldReference:
    """Hold a fixed whole-robot pose with all four feet in stance (the stand-still fallback)."""

    def __init__(self, qpos: np.ndarray, duration: float) -> None:
        z3 = np.zeros(3)
        self.duration = duration
        self.sample_value = ReferenceSample(
            t=0.0,
            p_base_W=qpos[:3].copy(),
            quat_WB=qpos[3:7].copy(),
            v_base_W=z3,
            omega_base_B=z3,
            a_base_W=z3,
            domega_base_B=z3,
            q_joints=qpos[7:].copy(),
            qd_joints=np.zeros(12),
            qdd_joints=np.zeros(12),
            stance=(True, True, True, True),
        )

    def sample(self, t: float) -> ReferenceSample:
        return self.sample_value


class ExpertPolicy:
    """Planner + inverse-dynamics controller as an SB3-style policy for ``QuadUneven-v0``.

    :param env: the environment (wrapped or not); the expert installs itself as its
        physics-rate controller, so create it before ``env.reset``.
    :param config: gait and control settings.
    """

    def __init__(self, env: gym.Env, config: ExpertConfig | None = None) -> None:
        self.config = config or ExpertConfig()
        self.env = env.unwrapped
        self.cfg = self.env.robot_cfg
        self._foot_sensor_adr = np.array([int(a) for a in self.env.idx.foot_sensor_adr])
        self._stance_sensor_adr = [
            tuple(int(a) for i, a in enumerate(self._foot_sensor_adr) if mask >> i & 1) for mask in range(16)
        ]  # the stance feet's contact-sensor addresses, per stance bitmask
        self._hips_B = hip_positions_B(self.cfg)
        self._slip = SlipDetector(
            self.config.slip_speed, self.cfg.foot_radius, SLIP_CHECK_EVERY * env.unwrapped.physics_dt
        )
        self._adapt_friction = False
        self._slip_cooldown = 0.0
        self.nominal: NominalModel | None = None
        """the expert's own model (None with ``model="oracle"``)."""
        if self.config.model == "nominal":
            self.nominal = NominalModel(self.cfg, self.env.terrain, self.env.physics_dt)
        self.controller = ComputedTorqueController(
            reference=self._reference,
            reference_row=self._reference_row,
            backend=self.config.backend,
            distribution=self.config.distribution,
            gains=self.config.gains,
            mu=self.config.friction if self.nominal is not None else None,
        )
        self.shares_simulator_data = False
        """this episode's dynamics terms are read from the simulator's data ("oracle", or "nominal" in an
        exactly nominal world with ``share_nominal_world``); False: from the nominal model's copy."""
        self.planner_times_ms: list[float] = []
        """wall time of every gait-cycle plan (ms)."""
        self.failure_log: list[str] = []
        """why plans failed and what the expert did instead."""
        self.plans: list[Any] = []
        """(t_start, plan or hold reference) of every cycle of the current episode."""
        self._current: Any = None
        self._current_ref: Any = None
        self._row_of: Any = None
        self._grid: ReferenceGrid | None = None  # the current plan's rows (None: a hold)
        self._t_start = 0.0
        self._t_end = 0.0
        self._data: mujoco.MjData | None = None  # the data the expert plans and controls with
        self._model: mujoco.MjModel | None = None
        self._sim: mujoco.MjData | None = None  # the simulator's: measured state and contact flags only
        self._terrain: Any = None
        self._zero = np.zeros(env.action_space.shape, dtype=env.action_space.dtype)
        self._tau_ok = np.zeros(C.N_JOINTS)
        self._steps = 0
        self._calm_after = 0.0  # s (controller time): no disturbance replan before
        self._log_dropped = 0
        self._last_controller_error = ""
        self._foothold_limits = FootholdLimits()
        self._base_mu = self.config.friction  # the assumed friction outside steep cycles (lowered by slips)
        self._yaw = 0.0  # rad: the planned base yaw at the end of the current plan (0 until a command turns it)
        self._durations: tuple[float, ...] = self.config.durations  # s: the phases of the current cycle
        self._off_plan_tol2 = (self.config.recovery_position**2, self.config.recovery_velocity**2)
        self.adaptation = make_adaptation(self.config.adaptation, self.env.dt, self.env.idx.torque_limit)
        """the adaptive gains on the torques (:class:`agents.control.adaptation.AdaptiveGains`; None: "none")."""

    # -------------------------------------------------------------- SB3 protocol
    def predict(
        self,
        observation: np.ndarray,
        state: Any = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = True,
    ) -> tuple[np.ndarray, Any]:
        """The zero action: the expert acts through the physics-rate hook."""
        return self._zero.copy(), state

    # -------------------------------------------------------------- env hook
    def reset(self, model: mujoco.MjModel, data: mujoco.MjData, terrain: Any) -> None:
        """Called by the env at every reset: plan the first cycle from the measured stand."""
        self._sim = data
        self._terrain = terrain
        self.planner_times_ms.clear()
        self.failure_log.clear()
        self.plans.clear()
        self._log_dropped = 0
        self._last_controller_error = ""
        self._tau_ok[:] = 0.0
        self._steps = 0
        self._calm_after = 0.0
        self.recoveries = 0
        self._yaw = 0.0
        self._slip_cooldown = 0.0
        nominal = self.nominal
        self._adapt_friction = self.config.friction_adapt and nominal is not None
        if nominal is None:  # oracle: the simulator's model, and the friction of its foot-terrain contacts
            self.shares_simulator_data = True
            self.controller.mu = _contact_friction(model)
            self._model, self._data = model, data
        else:
            self.controller.mu = self.config.friction  # the episode starts from the configured assumption
            self.shares_simulator_data = self.config.share_nominal_world and nominal.matches(model)
            if self.shares_simulator_data:
                self._model, self._data = model, data
            else:
                self._model, self._data = nominal.model, nominal.measure(data.qpos, data.qvel, data.time)
        self.controller.reset(self._model, self._data, terrain)
        self._slip.reset(self._model)
        self._base_mu = float(self.controller.mu)
        self._foothold_limits = foothold_limits_for_friction(self._base_mu)
        self._start_cycle(0.0, cog_start=None)
        if self.adaptation is not None:
            self.adaptation.reset(float(data.time))

    def __call__(self, model: mujoco.MjModel, data: mujoco.MjData, action: np.ndarray) -> np.ndarray:
        """Joint torques (N m) of the computed-torque controller at the measured state, times the adaptive gains
        (``ExpertConfig.adaptation``).

        Never raises: a failing step (logged in :attr:`failure_log`) returns the last good torques.
        """
        tau = self._controller_torques(model, data, action)
        if self.adaptation is None:
            return tau
        return self.adaptation.apply(tau, float(data.time), data.qpos[7:], self.planned_now)

    def _controller_torques(self, model: mujoco.MjModel, data: mujoco.MjData, action: np.ndarray) -> np.ndarray:
        """Joint torques (N m) of the computed-torque controller (the call's, before the adaptive gains)."""
        try:
            own = data if self.shares_simulator_data else self.nominal.measure(data.qpos, data.qvel, data.time)  # type: ignore[union-attr]
            self._steps += 1
            if self.config.recovery and self._steps % DISTURBANCE_CHECK_EVERY == 0:
                self._check_disturbance(own)
            if self._adapt_friction and self._steps % SLIP_CHECK_EVERY == 0:
                self._check_slip(own)
            ctrl = self.controller
            if self.shares_simulator_data:
                contacts = None
            else:
                contacts = ctrl.foot_contact_bits(data)
            grid = self._grid
            if grid is not None:  # the controller's call below when it takes its fast path, in one compiled call
                m = model if contacts is None else self._model
                t0, t1, touch = self._t_start, self._t_end, self._sim.sensordata
                tau = ctrl.step_on_grid(m, own, grid, t0, t1, touch, self._foot_sensor_adr, self._tau_ok, contacts)
                if tau is not None:
                    return tau
            tau = ctrl(model, data, action) if contacts is None else ctrl(self._model, own, action, contacts)
            if tau.shape == self._tau_ok.shape and IK.copy_if_finite(tau, self._tau_ok):
                return tau
            err = "non-finite torques"
        except Exception as exc:  # degrade, never crash a rollout
            err = f"{type(exc).__name__}: {exc}"
        if err != self._last_controller_error:  # one entry per run of equal failures
            self._log(f"t={float(data.time):.3f} s: controller failed ({err}); keeping the last good torques")
        self._last_controller_error = err
        return self._tau_ok.copy()

    def torques_into(
        self, model: mujoco.MjModel, data: mujoco.MjData, action: Any, out: np.ndarray, limit: np.ndarray
    ) -> bool:
        """The hook's fast lane (:class:`~quad_uneven_env.env.PhysicsController`): the torques ``self(model,
        data, action)`` returns, clipped to ``±limit`` (N m), written into ``out`` in one compiled call when the
        step is a plain grid step; False where the full call must run instead (nothing it would not redo the
        same way changed: the own model's copy of the measured state, the inverse-dynamics buffers). The action
        is ignored, as by the call. With an adaptation the lane writes the controller's torques unclipped, and
        the gains and the clip follow here, as in the call.

        Never taken on a slip-check step, and on a disturbance-check step only while the base is on its plan (the
        check is compiled into the call). Outside the nominal world the measured state is first copied into the
        expert's own model, as the call does.
        """
        adaptation = self.adaptation
        if adaptation is not None:
            if not self._lane_torques_into(model, data, adaptation.raw, adaptation.no_limit):
                return False
            tau = adaptation.apply(adaptation.raw, float(data.time), data.qpos[7:], self.planned_now)
            return bool(clip_finite_into(tau, limit, out))
        return self._lane_torques_into(model, data, out, limit)

    def _lane_torques_into(
        self, model: mujoco.MjModel, data: mujoco.MjData, out: np.ndarray, limit: np.ndarray
    ) -> bool:
        """:meth:`torques_into` before the adaptive gains."""
        grid = self._grid
        if grid is None or data is not self._sim:
            return False
        steps = self._steps + 1
        if self._adapt_friction and steps % SLIP_CHECK_EVERY == 0:
            return False
        ctrl = self.controller
        if self.shares_simulator_data:
            own, contacts = data, -1
        else:
            own, model = self.nominal.measure(data.qpos, data.qvel, data.time), self._model  # type: ignore[union-attr]
            contacts = ctrl.foot_contact_bits(data)
        off_plan = _NO_OFF_PLAN_CHECK
        if self.config.recovery and steps % DISTURBANCE_CHECK_EVERY == 0 and own.time - ctrl.t0 >= self._calm_after:
            off_plan = self._off_plan_tol2
        done = ctrl.grid_step_into(
            model, own, grid, self._t_start, self._t_end, data.sensordata, self._foot_sensor_adr, self._tau_ok,
            limit, out, off_plan, contacts,
        )  # fmt: skip
        if done == 1:
            self._steps = steps
        return done == 1

    def _check_disturbance(self, d: mujoco.MjData) -> None:
        """Replan now from the measured state if the base is off its plan (``ExpertConfig.recovery_*``)."""
        t = float(d.time) - self.controller.t0
        if t < self._calm_after or self._row_of is None or t >= self._t_end:
            return
        packed = self._row_of(t - self._t_start)
        if packed is None:
            return
        row, cfgx = packed[0], self.config
        q, v = d.qpos, d.qvel
        dv = (v[0] - row[7]) ** 2 + (v[1] - row[8]) ** 2
        dp = (q[0] - row[0]) ** 2 + (q[1] - row[1]) ** 2
        if dv <= cfgx.recovery_velocity**2 and dp <= cfgx.recovery_position**2:
            return
        self.recoveries += 1
        self._log(
            f"t={t:.2f} s: base {np.sqrt(dp):.3f} m and {np.sqrt(dv):.2f} m/s off its plan: replanning from the "
            "measured state"
        )
        cog = physics.cog(d, self.env.idx).copy()
        vel = np.array([v[0], v[1], 0.0])
        self._start_cycle(t, cog_start={"pos": cog, "vel": vel, "acc": np.zeros(3)}, measured=True)
        self._calm_after = t + self._durations[0]

    def _check_slip(self, d: mujoco.MjData) -> None:
        """Lower the assumed friction if a stance foot slips (``ExpertConfig.friction_adapt``; the reading of
        a slip: :mod:`agents.control.slip`). A slip counts only while every planned stance foot stands on
        terrain tilted less than 15 deg (:data:`SLIP_MIN_TILT_COS`), and not while the robot settles on its
        spawn pose."""
        t = float(d.time)
        if t - self.controller.t0 < SLIP_SPAWN_SETTLE:
            return
        packed = None if self._row_of is None else self._row_of(t - self.controller.t0 - self._t_start)
        planned = 15 if packed is None else packed[1]  # a hold stands on all four feet
        touch = self._sim.sensordata[self._foot_sensor_adr]
        slipping = self._slip.update(self._model, d, planned, touch, self._commanded_loads)
        if slipping < 0 or t < self._slip_cooldown or self._stance_tilt_cos(planned) < SLIP_MIN_TILT_COS:
            return
        cfg, old = self.config, self._base_mu
        mu = max(cfg.friction_min, old * cfg.friction_decrease)
        if mu >= old:
            return
        self._base_mu = mu
        self.controller.set_friction(mu)  # a steep cycle's cones too: the floor is more slippery than assumed
        self._foothold_limits = foothold_limits_for_friction(mu)
        self._slip_cooldown = t + SLIP_COOLDOWN
        self._slip.slip_time[:] = 0.0
        self._log(
            f"t={t - self.controller.t0:.2f} s: stance foot {C.LEG_NAMES[slipping]} slips "
            f"({self._slip.last_speed[slipping]:.2f} m/s, > {cfg.slip_speed:g} m/s for {SLIP_DURATION * 1e3:.0f} "
            f"ms): assumed friction {old:.3f} -> {mu:.3f}"
        )

    def _commanded_loads(self) -> np.ndarray:
        """(4,) N: the normal forces (world z) the controller commanded at its last step (0 before any)."""
        last = self.controller.last
        return np.zeros(C.N_LEGS) if last is None else last.contact_forces[:, 2]

    def _stance_tilt_cos(self, planned: int) -> float:
        """cos of the steepest terrain tilt under the planned stance feet (1: none)."""
        legs = [leg for leg in range(C.N_LEGS) if planned >> leg & 1]
        if not legs:
            return 1.0
        feet = physics.feet_pos(self._data, self.env.idx)
        return float(np.min(self._terrain.heightfield.normal(feet[legs, 0], feet[legs, 1])[:, 2]))

    @property
    def assumed_friction(self) -> float:
        """-: the friction coefficient the controller's cones assume now (``ExpertConfig.friction``, lowered
        by slips with ``friction_adapt``, or the steep-ground friction in a cycle that needs it; the
        simulator's with ``model="oracle"``)."""
        return float(self.controller.mu)

    def _steep_mu(self) -> float | None:
        """-: the friction a stride refused for steep footholds may be planned again with, or None."""
        cfg = self.config
        if self.nominal is None or cfg.steep_friction <= 0.0:
            return None
        mu = cfg.steep_friction * self._base_mu / cfg.friction  # slips scale it down with the base
        return mu if mu > self._base_mu else None

    def _log(self, message: str) -> None:
        """Append to :attr:`failure_log` (at most ``MAX_FAILURE_LOG`` entries; the rest are counted)."""
        if len(self.failure_log) < MAX_FAILURE_LOG:
            self.failure_log.append(message)
        else:
            self._log_dropped += 1

    @property
    def last_torques(self) -> np.ndarray:
        """(12,) N m: the torques of the last successful physics step (a read-only view)."""
        view = self._tau_ok.view()
        view.setflags(write=False)
        return view

    def planned_now(self, sim_time: float) -> tuple[ReferenceSample, float]:
        """The current plan at simulator time ``sim_time`` (s), without planning anything new.

        :return: the planned whole-robot motion (held at the plan's end once past it) and the phase of the
            current cycle in [0, 1].
        """
        duration = max(self._t_end - self._t_start, 1e-9)
        tc = min(max(sim_time - self.controller.t0 - self._t_start, 0.0), duration)
        return self._current_ref.sample(tc), tc / duration

    # -------------------------------------------------------------- planning
    def _reference(self, t: float) -> ReferenceSample:
        self._advance(t)
        ref = self._current_ref.sample(t - self._t_start)
        return self._push_late_touchdowns(ref, t - self._t_start)

    def _reference_row(self, t: float) -> tuple[np.ndarray, int] | None:
        """The controller's fast form of :meth:`_reference`: the packed plan row and its stance
        bitmask, or None (hold, off the grid, or a late touch-down to push: use :meth:`_reference`)."""
        if t >= self._t_end:
            self._advance(t)
        row_of = self._row_of
        packed = None if row_of is None else row_of(t - self._t_start)
        if packed is None:
            return None
        touch = self._sim.sensordata
        for a in self._stance_sensor_adr[packed[1]]:
            if touch[a] <= 0:
                return None
        return packed

    def _advance(self, t: float) -> None:
        """Plan the next gait cycle once ``t`` (s) reaches the end of the current one."""
        if t >= self._t_end:
            goal = None
            if hasattr(self._current, "cog"):
                tc = self._t_end - self._t_start
                goal = {
                    "pos": self._current.cog.position(np.array([tc]))[0],
                    "vel": self._current.cog.velocity(np.array([tc]))[0],
                    "acc": self._current.cog.acceleration(np.array([tc]))[0],
                }
            self._start_cycle(self._t_end, cog_start=goal)

    def _push_late_touchdowns(self, ref: ReferenceSample, tc: float) -> ReferenceSample:
        """Aim a planned-stance foot that has not touched down ``touchdown_depth`` below its foothold.

        The swing spline ends exactly on the surface; a few millimetres of tracking error leave
        the foot hovering, and the controller then treats it as a swing leg (its stance
        fallback). Pushing the joint target below the surface makes the foot land.
        """
        if not hasattr(self._current, "footholds"):
            return ref
        sd, stance = self._sim.sensordata, ref.stance
        late = [stance[i] and sd[a] <= 0 for i, a in enumerate(self._foot_sensor_adr)]
        if not (late[0] or late[1] or late[2] or late[3]):
            return ref
        return aim_feet_below_footholds(ref, self._current, tc, np.array(late), self.config.touchdown_depth, self.cfg)

    def _measured_footholds(self, mid_swing: bool = False) -> np.ndarray:
        """(4, 3) m, world: the terrain point below each foot site. With ``mid_swing`` (a replan from the
        measured state, which can come in the middle of a swing), a foot in the air whose point below is
        beyond its leg's stance reach (on a downhill slope or past an edge) gets the terrain point nearest to
        its site within :data:`AIRBORNE_FOOTHOLD_RADIUS` instead, where it lands soonest: otherwise the
        cycle would start with that leg stretched straight (a singular stance)."""
        sites = physics.feet_pos(self._data, self.env.idx)
        hf = self._terrain.heightfield
        ground = hf.height(sites[:, 0], sites[:, 1])
        out = np.column_stack([sites[:, :2], ground])
        if not mid_swing or self._sim is None:
            return out
        touch = self._sim.sensordata[self._foot_sensor_adr]
        hips = self._data.qpos[:3] + self._hips_B @ quat_to_matrix(physics.base_quat(self._data)).T
        for leg in np.flatnonzero(touch <= 0):
            if np.linalg.norm(out[leg] - hips[leg]) <= STANCE_REACH * self.cfg.leg_length:
                continue  # within reach: straight below (on stairs down the nearest point is the nosing above)
            xy = sites[leg, :2] + _AIRBORNE_DISC
            z = hf.height(xy[:, 0], xy[:, 1])
            k = int(np.argmin(np.sum((xy - sites[leg, :2]) ** 2, axis=1) + (z - sites[leg, 2]) ** 2))
            out[leg] = (xy[k, 0], xy[k, 1], z[k])
        return out

    def _stride_xy(self, d: mujoco.MjData, turn: float = 0.0) -> tuple[float, float]:
        """(dx, dy) m, world: the body's advance this cycle, which turns the body by ``turn`` (rad).

        Without a command: ``ExpertConfig.stride`` along +x. With one (``env.command``, read at the start of
        every cycle): the commanded (vx, vy) (m/s, yaw-aligned base frame) times the cycle's duration, turned
        into the world frame by the measured heading plus half the cycle's turn (the mid-cycle heading), and
        shortened to the chord of the arc a constant yaw rate would drive: ``sin(turn / 2) / (turn / 2)``.
        """
        command = self.env.command
        if command is None:
            return (self.config.stride, 0.0)
        period = float(sum(self._durations))
        yaw = yaw_of_quat(physics.base_quat(d))
        if turn != 0.0:
            yaw, period = yaw + 0.5 * turn, period * float(np.sin(0.5 * turn) / (0.5 * turn))
        c, s = float(np.cos(yaw)), float(np.sin(yaw))
        vx, vy = float(command[0]), float(command[1])
        return (period * (c * vx - s * vy), period * (s * vx + c * vy))

    def _turn(self) -> float:
        """rad: the body's yaw change over a whole cycle, the commanded yaw rate times the cycle's duration
        (0 without a command), capped at :data:`MAX_TURN`. In heading mode (``env.command_heading``) the turn
        closes the whole heading error from the planned yaw within the cycle, capped the same way."""
        command = self.env.command
        heading = getattr(self.env, "command_heading", None)
        if heading is not None:
            error = wrap_angle(heading - self._yaw)
            return float(np.clip(error, -MAX_TURN, MAX_TURN)) if abs(error) > HEADING_DEADBAND else 0.0
        if command is None or command[2] == 0.0:
            return 0.0
        return float(np.clip(float(command[2]) * sum(self._durations), -MAX_TURN, MAX_TURN))

    def _cycle_durations(self) -> tuple[float, ...]:
        """s: the phases of the next cycle. ``ExpertConfig.durations``, or, when the commanded speed times their
        cycle would stride further than :data:`MAX_CYCLE_STRIDE`, the same gait faster: its phases longer
        than :data:`MIN_PHASE` (all but the short four-leg one in the middle) scaled down together so that
        the stride is ``MAX_CYCLE_STRIDE``, but none below ``MIN_PHASE``."""
        durations = self.config.durations
        command = self.env.command
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

    def _start_cycle(self, t0: float, cog_start: dict | None, measured: bool = False) -> None:
        """Plan the cycle starting at ``t0`` (s) from ``cog_start`` (the previous plan's end; None: the
        measured COG at rest); ``measured``: ``cog_start`` is the measured COG state (pitch measured too)."""
        d, cfgx = self._data, self.config
        feet = self._measured_footholds(mid_swing=measured)
        previous = getattr(self._current, "pitch", None)
        self._durations = self._cycle_durations()
        full_turn = self._turn()
        # A turning body plans in its yawed frame (pitch about the yawed y axis); otherwise exactly as without yaw.
        turning = full_turn != 0.0 or self._yaw != 0.0

        def measured_pitch() -> float:
            q = physics.base_quat(d)
            return yaw_pitch_of_quaternion(q)[1] if turning else pitch_of_quaternion(q)

        def measure_yaw() -> None:
            """A turning body starts from its measured yaw (unwrapped next to the planned one), not the plan's."""
            if turning:
                y = yaw_pitch_of_quaternion(physics.base_quat(d))[0]
                self._yaw += wrap_angle(y - self._yaw)

        pitch_start = previous.end if previous is not None and not measured else measured_pitch()
        if measured:
            measure_yaw()
        elif cog_start is None or np.linalg.norm(cog_start["pos"] - physics.cog(d, self.env.idx)) > 0.05:
            # First cycle, after a hold, or drifted: start from the measured COG (and pitch) at rest.
            cog_start = {"pos": physics.cog(d, self.env.idx).copy(), "vel": np.zeros(3), "acc": np.zeros(3)}
            pitch_start = measured_pitch()
            measure_yaw()
        plan = None
        turn = 0.0
        cycle_mu = self._base_mu
        steep_mu = self._steep_mu()
        for fx, dy in STRIDE_FALLBACKS:
            turn = min(fx, 1.0) * full_turn  # a shorter stride turns less; a longer one no more than commanded
            sx, sy = self._stride_xy(d, turn)
            if turning:  # the sideways shift and the side stepped to are the body's (its mid-cycle heading)
                c, s = float(np.cos(self._yaw + 0.5 * turn)), float(np.sin(self._yaw + 0.5 * turn))
                stride = (fx * sx - s * dy, fx * sy + c * dy)
                left = c * stride[1] - s * stride[0]
            else:
                stride = (fx * sx, fx * sy + dy)
                left = stride[1]
            order = "left_first" if left > SIDE_STEP else "right_first"  # lead with the legs on that side
            scenario = Scenario(
                terrain=self._terrain.heightfield,
                feet_start=feet,
                cog_start=cog_start,
                durations=self._durations,
                epsilon=cfgx.epsilon,
                clearance=cfgx.clearance,
                cog_height=cfgx.cog_height,
                stride=stride,
                robot=self.cfg,
                body_pitch=cfgx.body_pitch,
                pitch_start=pitch_start,
                yaw_start=self._yaw,
                turn=turn,
                swing_order=order,
                foothold_limits=self._foothold_limits,
            )
            plan, too_steep = self._try_plan(scenario, t0, stride)
            if plan is None and too_steep and steep_mu is not None:
                steep = dataclasses.replace(scenario, foothold_limits=foothold_limits_for_friction(steep_mu))
                plan, _ = self._try_plan(steep, t0, stride, f" (assuming friction {steep_mu:.2f})")
                if plan is not None:
                    cycle_mu = steep_mu
                    self._log(f"t={t0:.2f} s, stride {_fmt(stride)} m: planned assuming friction {steep_mu:.2f}")
            if plan is not None:
                break
        if cycle_mu != self.controller.mu:
            self.controller.set_friction(cycle_mu)
        if plan is None:
            qpos = d.qpos.copy()
            hold = _HoldReference(qpos, float(sum(self._durations)))
            self._log(f"t={t0:.2f} s: no feasible plan, standing still for {hold.duration:.2f} s")
            self._current, self._current_ref = hold, hold
            duration = hold.duration
        else:
            self._current, self._current_ref = plan
            duration = self._current.duration
            self._yaw += turn
        self._row_of = getattr(self._current_ref, "row", None)
        self._grid = getattr(self._current_ref, "grid", None)
        self.plans.append((t0, self._current))
        self._t_start, self._t_end = t0, t0 + duration

    def _try_plan(self, scenario: Scenario, t0: float, stride: tuple[float, float], note: str = "") -> tuple[Any, bool]:
        """Plan one gait cycle: ((the plan, its whole-body reference) or None, whether a steeper foothold slope
        limit could give it footholds); a failure, or a reference that cannot be tracked
        (:meth:`planners.reference.Reference.defect`), is logged with the stride (m) and ``note``."""
        tic = time.perf_counter()
        try:
            # Small dense problems: multi-threaded BLAS only adds contention (much slower on
            # a loaded 2-core machine), so the planner runs single-threaded.
            with _blas_controller().limit(limits=1, user_api="blas"):
                plan = plan_gait_cycle(scenario)
        except PlanningError as err:
            self._log(f"t={t0:.2f} s, stride {_fmt(stride)} m{note}: {err}")
            return None, isinstance(err, FootholdError) and err.slope_blocked > 0
        except Exception as err:  # a planner bug or numerical trouble: handled as a failed plan
            self._log(f"t={t0:.2f} s, stride {_fmt(stride)} m{note}: planner failed ({type(err).__name__}: {err})")
            return None, False
        finally:
            self.planner_times_ms.append(1e3 * (time.perf_counter() - tic))
        reference = plan.reference(self.cfg)
        defect = reference.defect()
        if defect is not None:
            self._log(f"t={t0:.2f} s, stride {_fmt(stride)} m{note}: whole-body reference refused ({defect})")
            return None, False
        return (plan, reference), False


def _fmt(stride: tuple[float, float]) -> str:
    """A 2-D stride (m) for the failure log: ``0.330`` along +x, ``(-0.150, 0.080)`` otherwise."""
    return f"{stride[0]:.3f}" if stride[1] == 0.0 else f"({stride[0]:.3f}, {stride[1]:.3f})"


def foothold_limits_for_friction(mu: float) -> FootholdLimits:
    """Foothold limits whose slope limit keeps a foot inside the friction pyramid the controller assumes.

    The cones are 4-sided pyramids of ``mu / sqrt(2)`` per tangent axis: a foot on a plane steeper than
    ``atan(mu / sqrt(2))`` (19.5 deg for mu = 0.5) cannot hold its share of the weight inside them, and on
    a slope where every foot is that steep the torque QP has no solution (it is relaxed, the feet slip).
    Such a foothold is refused (the failure log says ``failed test: slope``) rather than walked on.

    :param mu: friction coefficient of the controller's cones (-).
    """
    default = FootholdLimits()
    return dataclasses.replace(default, max_slope=min(default.max_slope, float(np.arctan(mu / np.sqrt(2.0)))))


def _contact_friction(model: mujoco.MjModel) -> float:
    """Sliding friction of a foot-terrain contact in ``model`` (MuJoCo's default mix: the larger of the two geoms')."""
    foot = float(model.geom_friction[model.geom(C.FOOT_GEOMS[0]).id, 0])
    return max(foot, float(model.geom_friction[model.geom(C.TERRAIN_GEOM).id, 0]))


__all__ = [
    "EXPERT_MODELS",
    "STRIDE_FALLBACKS",
    "ExpertConfig",
    "ExpertPolicy",
    "attach_expert",
    "foothold_limits_for_friction",
]


def attach_expert(env: gym.Env, config: ExpertConfig | None = None) -> ExpertPolicy:
    """Build an :class:`ExpertPolicy` for ``env`` and install it as the env's physics-rate controller.

    Call it before ``env.reset`` (the reset plans the first cycle). This is the one way the expert
    drives an env; ``ExpertPolicy(env, config)`` alone builds it without attaching it.
    """
    expert = ExpertPolicy(env, config)
    expert.env.set_controller(expert)
    return expert
