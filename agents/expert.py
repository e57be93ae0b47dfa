"""The scripted expert: the paper's planner and inverse-dynamics controller in the loop.

:class:`ExpertPolicy` replans every gait cycle from the measured state (receding horizon:
footholds, COG path, swing paths) heading +x, with the body pitched along the slope of the
footholds (``ExpertConfig.body_pitch``; the paper keeps it level), and runs the computed-torque
controller (:class:`agents.control.controller.ComputedTorqueController`) at physics rate through the env's
control hook. It has **privileged access**: the terrain's height field
(``env.unwrapped.terrain``) and the full MuJoCo state (COG, foot positions), as a scripted
expert in simulation may.

It follows SB3's ``predict`` protocol so the evaluation code runs it like a learned agent;
``predict`` returns the zero action because the work is done in the physics-rate hook (the
residual RL agent adds its action on top of it).

When a plan fails (:class:`planners.PlanningError`) the expert degrades: it retries with half
the stride, then steps in place, then stands still for one cycle (holding the measured pose)
and replans; every failure is recorded in :attr:`ExpertPolicy.failure_log`. It never raises
out of a rollout.
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np
from threadpoolctl import ThreadpoolController

from agents.control.controller import ComputedTorqueController, Gains
from agents.control.inverse_dynamics import DISTRIBUTIONS
from planners import PlanningError, Scenario, plan_gait_cycle
from planners.gait import validate_durations
from planners.pitch import pitch_of_quaternion
from planners.reference import aim_feet_below_footholds
from planners.scenario import BODY_PITCH_MODES
from planners.types import ReferenceSample
from quad_uneven_env import physics
from quad_uneven_env.fields import check_fields, param
from quad_uneven_env.robot.dynamics import BACKENDS


@dataclasses.dataclass(frozen=True)
class ExpertConfig:
    """Gait and control settings of the expert (SI units)."""

    durations: tuple[float, ...] = (0.5, 0.5, 0.5, 0.1, 0.5, 0.5, 0.5)
    """s: the 7 phases of the walk cycle (paper order; the paper uses 1, 1, 1, 0.1, 1, 1, 1)."""
    stride: float = param(0.33, "m", lo=0.0, hi=1.0, lo_open=True)
    """m, in (0, 1]: body advance per cycle along +x (0.33 m / 3.1 s = 0.106 m/s nominal)."""
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

    def __post_init__(self) -> None:
        check_fields(self)
        validate_durations(self.durations)
        if not isinstance(self.gains, Gains):
            raise ValueError(f"ExpertConfig.gains must be a Gains, got {self.gains!r}")


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
        self.controller = ComputedTorqueController(
            reference=self._reference,
            reference_row=self._reference_row,
            backend=self.config.backend,
            distribution=self.config.distribution,
            gains=self.config.gains,
        )
        self.planner_times_ms: list[float] = []
        """wall time of every gait-cycle plan (ms)."""
        self.failure_log: list[str] = []
        """why plans failed and what the expert did instead."""
        self.plans: list[Any] = []
        """(t_start, plan or hold reference) of every cycle of the current episode."""
        self._current: Any = None
        self._row_of: Any = None
        self._t_start = 0.0
        self._t_end = 0.0
        self._data: mujoco.MjData | None = None
        self._terrain: Any = None
        self._zero = np.zeros(env.action_space.shape, dtype=env.action_space.dtype)

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
        self._data = data
        self._terrain = terrain
        self.planner_times_ms.clear()
        self.failure_log.clear()
        self.plans.clear()
        self.controller.reset(model, data, terrain)
        self._start_cycle(0.0, cog_start=None)

    def __call__(self, model: mujoco.MjModel, data: mujoco.MjData, action: np.ndarray) -> np.ndarray:
        """Joint torques (N m) of the computed-torque controller at the current state."""
        return self.controller(model, data, action)

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
        planned = packed[1]
        touch = self._data.sensordata[self._foot_sensor_adr].tolist()
        for i in range(4):
            if planned >> i & 1 and touch[i] <= 0:
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
        sd, stance = self._data.sensordata, ref.stance
        late = [stance[i] and sd[a] <= 0 for i, a in enumerate(self._foot_sensor_adr)]
        if not (late[0] or late[1] or late[2] or late[3]):
            return ref
        return aim_feet_below_footholds(ref, self._current, tc, np.array(late), self.config.touchdown_depth, self.cfg)

    def _measured_footholds(self) -> np.ndarray:
        """(4, 3) points on the terrain below the foot sites (m, world)."""
        sites = physics.feet_pos(self._data, self.env.idx)
        ground = self._terrain.heightfield.height(sites[:, 0], sites[:, 1])
        return np.column_stack([sites[:, :2], ground])

    def _start_cycle(self, t0: float, cog_start: dict | None) -> None:
        d, cfgx = self._data, self.config
        feet = self._measured_footholds()
        previous = getattr(self._current, "pitch", None)
        pitch_start = previous.end if previous is not None else pitch_of_quaternion(physics.base_quat(d))
        if cog_start is None or np.linalg.norm(cog_start["pos"] - physics.cog(d, self.env.idx)) > 0.05:
            # First cycle, after a hold, or drifted: start from the measured COG (and pitch) at rest.
            cog_start = {"pos": physics.cog(d, self.env.idx).copy(), "vel": np.zeros(3), "acc": np.zeros(3)}
            pitch_start = pitch_of_quaternion(physics.base_quat(d))
        plan = None
        for stride in (cfgx.stride, 0.5 * cfgx.stride, 0.0):
            scenario = Scenario(
                terrain=self._terrain.heightfield,
                feet_start=feet,
                cog_start=cog_start,
                durations=cfgx.durations,
                epsilon=cfgx.epsilon,
                clearance=cfgx.clearance,
                cog_height=cfgx.cog_height,
                stride=(stride, 0.0),
                robot=self.cfg,
                body_pitch=cfgx.body_pitch,
                pitch_start=pitch_start,
            )
            tic = time.perf_counter()
            try:
                # Small dense problems: multi-threaded BLAS only adds contention (much slower on
                # a loaded 2-core machine), so the planner runs single-threaded.
                with _blas_controller().limit(limits=1, user_api="blas"):
                    plan = plan_gait_cycle(scenario)
            except PlanningError as err:
                self.failure_log.append(f"t={t0:.2f} s, stride {stride:.3f} m: {err}")
                continue
            finally:
                self.planner_times_ms.append(1e3 * (time.perf_counter() - tic))
            break
        if plan is None:
            qpos = d.qpos.copy()
            hold = _HoldReference(qpos, float(sum(cfgx.durations)))
            self.failure_log.append(f"t={t0:.2f} s: no feasible plan, standing still for {hold.duration:.2f} s")
            self._current, self._current_ref = hold, hold
            duration = hold.duration
        else:
            self._current, self._current_ref = plan, plan.reference(self.cfg)
            duration = plan.duration
        self._row_of = getattr(self._current_ref, "row", None)
        self.plans.append((t0, self._current))
        self._t_start, self._t_end = t0, t0 + duration


__all__ = ["ExpertConfig", "ExpertPolicy"]


def attach_expert(env: gym.Env, config: ExpertConfig | None = None) -> ExpertPolicy:
    """Build an :class:`ExpertPolicy` for ``env`` and install it as the env's physics-rate controller.

    Call it before ``env.reset`` (the reset plans the first cycle). This is the one way the expert
    drives an env; ``ExpertPolicy(env, config)`` alone builds it without attaching it.
    """
    expert = ExpertPolicy(env, config)
    expert.env.set_controller(expert)
    return expert
