"""Cycle planning: the expert's plan of every gait cycle, from the measured state, with its fallbacks.

At the end of every cycle (and when the recovery asks, mid-cycle) :class:`CyclePlanner` measures the footholds
under the feet, builds the cycle's :class:`planners.Scenario` (stride and turn from :mod:`agents.expert.command`,
foothold limits from :mod:`agents.expert.friction`) and plans it (:func:`planners.plan_gait_cycle`). When a plan
fails (:class:`planners.PlanningError`), or its whole-body reference could not be tracked
(:meth:`planners.reference.Reference.defect`), it retries with the strides of :data:`STRIDE_FALLBACKS`
(shorter, longer, half with a sideways body shift, then in place), a stride refused only for steep footholds
once more with the steep-ground friction; if none is feasible the robot stands still for one cycle
(:class:`HoldReference`, the measured pose) and it replans. Every failure is logged.
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any

import mujoco
import numpy as np

from agents.expert.command import cycle_durations, cycle_stride, cycle_turn, fallback_stride
from agents.expert.config import ExpertConfig
from agents.expert.friction import FrictionAdaptation, foothold_limits_for_friction
from agents.expert.log import FailureLog
from planners import PlanningError, Scenario, plan_gait_cycle
from planners.cycle import STANCE_REACH
from planners.pitch import pitch_of_quaternion, yaw_pitch_of_quaternion
from planners.reference import aim_feet_below_footholds
from planners.robot_geometry import robot_geometry
from planners.types import FootholdError, ReferenceGrid, ReferenceSample
from quad_uneven_env import physics
from quad_uneven_env.spatial import quat_to_matrix, wrap_angle

STRIDE_FALLBACKS: tuple[tuple[float, float], ...] = (
    (1.0, 0.0), (0.75, 0.0), (1.25, 0.0), (0.5, 0.0), (0.5, 0.05), (0.5, -0.05), (0.0, 0.0),
)  # fmt: skip
"""Strides tried in turn when a plan fails, closest to the nominal first: (fraction of the cycle's stride (the
commanded one, else ``ExpertConfig.stride`` along +x), sideways body shift (m, world y)); the first feasible
plan is walked (the shift in the paper robot's lengths: times the robot's leg-length ratio). Shorter and longer
strides move every nominal foothold (onto the next stone, off a reach
limit), a sideways shift moves the body over its support; 0 steps in place. If none is feasible the expert
stands still for one cycle."""

AIRBORNE_FOOTHOLD_RADIUS = 0.1
"""m: a foot in the air at a replan lands at the terrain point nearest to it within this horizontal radius."""


def disc_offsets(radius: float, step: float) -> np.ndarray:
    """(n, 2) m: the points of a square grid of spacing ``step`` (m) within ``radius`` (m) of the origin."""
    k = np.arange(-int(radius / step), int(radius / step) + 1) * step
    grid = np.stack(np.meshgrid(k, k), axis=-1).reshape(-1, 2)
    return grid[np.hypot(grid[:, 0], grid[:, 1]) <= radius + 1e-9]


AIRBORNE_DISC = disc_offsets(AIRBORNE_FOOTHOLD_RADIUS, 0.01)
"""(n, 2) m: horizontal offsets on a 1 cm grid within ``AIRBORNE_FOOTHOLD_RADIUS`` (the origin included)."""


class HoldReference:
    """Hold a fixed whole-robot pose with all four feet in stance (the stand-still fallback).

    :param qpos: the pose (the measured ``qpos``, copied).
    :param duration: s, how long.
    """

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
        """The held pose, at any ``t``."""
        return self.sample_value


class CyclePlanner:
    """The current gait cycle's plan and its whole-body reference, planned again at every cycle's end.

    Times are controller times (s since the controller's reset). The plan holds for [:attr:`t_start`,
    :attr:`t_end`); :meth:`reference` plans the next cycle when asked past it.

    :param env: the unwrapped env (its indices, robot configuration and command).
    :param config: the expert's settings.
    :param friction: the friction assumption (steep ground, foothold limits, the cycle's cones).
    :param log: where failures go.
    """

    def __init__(self, env: Any, config: ExpertConfig, friction: FrictionAdaptation, log: FailureLog) -> None:
        self.env = env
        self.config = config
        self.cfg = robot_geometry(env.robot)
        """the planners' view of the env's robot (:mod:`planners.robot_geometry`)."""
        self.friction = friction
        self.log = log
        self.foot_sensor_adr = np.array([int(a) for a in env.idx.foot_sensor_adr])
        """the feet's contact-sensor addresses in the simulator's ``sensordata``."""
        self._hips_B = self.cfg.shoulders_B
        self.planner_times_ms: list[float] = []
        """wall time of every gait-cycle plan (ms)."""
        self.plans: list[Any] = []
        """(t_start, plan or hold reference) of every cycle of the current episode."""
        self.current: Any = None
        """the current cycle's plan (:class:`planners.GaitCyclePlan`) or :class:`HoldReference`."""
        self.current_ref: Any = None
        """its whole-body reference (``sample(t)``)."""
        self.row_of: Any = None
        """the reference's packed row lookup ``row(t) -> (row, stance mask) or None`` (None: a hold)."""
        self.grid: ReferenceGrid | None = None
        """the current plan's rows (None: a hold)."""
        self.t_start = 0.0
        self.t_end = 0.0
        self.yaw = 0.0
        """rad: the planned base yaw at the end of the current plan (0 until a command turns it)."""
        self.durations: tuple[float, ...] = config.durations
        """s: the phases of the current cycle."""
        self.cycle_config: ExpertConfig | None = None
        """the settings the next cycles are planned with (durations, stride, epsilon, clearance, cog_height), set by
        a controller that adjusts the plan per cycle; None: :attr:`config`."""
        self._data: mujoco.MjData | None = None
        self._sim: mujoco.MjData | None = None
        self._terrain: Any = None

    def reset(self, data: mujoco.MjData, sim: mujoco.MjData, terrain: Any) -> None:
        """Start an episode and plan its first cycle from the measured stand.

        :param data: the data the expert plans with (its own model's, or the simulator's).
        :param sim: the simulator's (contact sensors only).
        """
        self._data, self._sim, self._terrain = data, sim, terrain
        self.planner_times_ms.clear()
        self.plans.clear()
        self.yaw = 0.0
        self.start_cycle(0.0, cog_start=None)

    # ------------------------------------------------------------------ the reference
    def reference(self, t: float) -> ReferenceSample:
        """The reference at controller time ``t`` (s), planning the next cycle first if ``t`` is past this one;
        a late foot pushed below its foothold (:meth:`push_late_touchdowns`). The controller's reference."""
        self.advance(t)
        ref = self.current_ref.sample(t - self.t_start)
        return self.push_late_touchdowns(ref, t - self.t_start)

    def planned_stance(self, t: float) -> int:
        """The planned stance bitmask at controller time ``t`` (s) (15, all four feet, during a hold)."""
        packed = None if self.row_of is None else self.row_of(t - self.t_start)
        return 15 if packed is None else packed[1]

    def planned_now(self, t: float) -> tuple[ReferenceSample, float]:
        """The current plan at controller time ``t`` (s), without planning anything new: the planned whole-robot
        motion (held at the plan's end once past it) and the phase of the current cycle in [0, 1]."""
        duration = max(self.t_end - self.t_start, 1e-9)
        tc = min(max(t - self.t_start, 0.0), duration)
        return self.current_ref.sample(tc), tc / duration

    def advance(self, t: float) -> None:
        """Plan the next gait cycle once ``t`` (s) reaches the end of the current one."""
        if t >= self.t_end:
            goal = None
            if hasattr(self.current, "cog"):
                tc = self.t_end - self.t_start
                goal = {
                    "pos": self.current.cog.position(np.array([tc]))[0],
                    "vel": self.current.cog.velocity(np.array([tc]))[0],
                    "acc": self.current.cog.acceleration(np.array([tc]))[0],
                }
            self.start_cycle(self.t_end, cog_start=goal)

    def push_late_touchdowns(self, ref: ReferenceSample, tc: float) -> ReferenceSample:
        """Aim a planned-stance foot that has not touched down ``touchdown_depth`` below its foothold.

        The swing spline ends exactly on the surface; a few millimetres of tracking error leave
        the foot hovering, and the controller then treats it as a swing leg (its stance
        fallback). Pushing the joint target below the surface makes the foot land.
        """
        if not hasattr(self.current, "footholds"):
            return ref
        sd, stance = self._sim.sensordata, ref.stance  # type: ignore[union-attr]
        late = [stance[i] and sd[a] <= 0 for i, a in enumerate(self.foot_sensor_adr)]
        if not (late[0] or late[1] or late[2] or late[3]):
            return ref
        return aim_feet_below_footholds(ref, self.current, tc, np.array(late), self.config.touchdown_depth, self.cfg)

    # ------------------------------------------------------------------ planning
    def measured_footholds(self, mid_swing: bool = False) -> np.ndarray:
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
        touch = self._sim.sensordata[self.foot_sensor_adr]
        hips = self._data.qpos[:3] + self._hips_B @ quat_to_matrix(physics.base_quat(self._data)).T
        for leg in np.flatnonzero(touch <= 0):
            if np.linalg.norm(out[leg] - hips[leg]) <= STANCE_REACH * self.cfg.leg_length:
                continue  # within reach: straight below (on stairs down the nearest point is the nosing above)
            xy = sites[leg, :2] + AIRBORNE_DISC
            z = hf.height(xy[:, 0], xy[:, 1])
            k = int(np.argmin(np.sum((xy - sites[leg, :2]) ** 2, axis=1) + (z - sites[leg, 2]) ** 2))
            out[leg] = (xy[k, 0], xy[k, 1], z[k])
        return out

    def start_cycle(self, t0: float, cog_start: dict | None, measured: bool = False) -> None:
        """Plan the cycle starting at ``t0`` (s) from ``cog_start`` (the previous plan's end; None: the
        measured COG at rest); ``measured``: ``cog_start`` is the measured COG state (pitch measured too)."""
        d, env = self._data, self.env
        cfgx = self.config if self.cycle_config is None else self.cycle_config
        feet = self.measured_footholds(mid_swing=measured)
        previous = getattr(self.current, "pitch", None)
        self.durations = cycle_durations(cfgx.durations, env.command)
        full_turn = cycle_turn(env.command, getattr(env, "command_heading", None), self.yaw, self.durations)
        # A turning body plans in its yawed frame (pitch about the yawed y axis); otherwise exactly as without yaw.
        turning = full_turn != 0.0 or self.yaw != 0.0

        def measured_pitch() -> float:
            q = physics.base_quat(d)
            return yaw_pitch_of_quaternion(q)[1] if turning else pitch_of_quaternion(q)

        def measure_yaw() -> None:
            """A turning body starts from its measured yaw (unwrapped next to the planned one), not the plan's."""
            if turning:
                y = yaw_pitch_of_quaternion(physics.base_quat(d))[0]
                self.yaw += wrap_angle(y - self.yaw)

        pitch_start = previous.end if previous is not None and not measured else measured_pitch()
        if measured:
            measure_yaw()
        elif cog_start is None or np.linalg.norm(cog_start["pos"] - physics.cog(d, env.idx)) > 0.05 * self.cfg.scale:
            # First cycle, after a hold, or drifted: start from the measured COG (and pitch) at rest.
            cog_start = {"pos": physics.cog(d, env.idx).copy(), "vel": np.zeros(3), "acc": np.zeros(3)}
            pitch_start = measured_pitch()
            measure_yaw()
        plan = None
        turn = 0.0
        friction = self.friction
        cycle_mu = friction.base_mu
        steep_mu = friction.steep_mu()
        for fx, dy in STRIDE_FALLBACKS:
            turn = min(fx, 1.0) * full_turn  # a shorter stride turns less; a longer one no more than commanded
            nominal = cycle_stride(env.command, cfgx.stride, self.durations, physics.base_quat(d), turn)
            stride, order = fallback_stride(nominal, fx, dy * self.cfg.scale, self.yaw + 0.5 * turn, turning)
            scenario = Scenario(
                terrain=self._terrain.heightfield,
                feet_start=feet,
                cog_start=cog_start,
                durations=self.durations,
                epsilon=cfgx.epsilon,
                clearance=cfgx.clearance,
                cog_height=cfgx.cog_height,
                stride=stride,
                robot=self.cfg,
                body_pitch=cfgx.body_pitch,
                pitch_start=pitch_start,
                yaw_start=self.yaw,
                turn=turn,
                swing_order=order,
                foothold_limits=friction.foothold_limits,
            )
            plan, too_steep = self._try_plan(scenario, t0, stride)
            if plan is None and too_steep and steep_mu is not None:
                limits = foothold_limits_for_friction(steep_mu, cfgx.foothold_scale)
                steep = dataclasses.replace(scenario, foothold_limits=limits)
                plan, _ = self._try_plan(steep, t0, stride, f" (assuming friction {steep_mu:.2f})")
                if plan is not None:
                    cycle_mu = steep_mu
                    self.log.add(f"t={t0:.2f} s, stride {_fmt(stride)} m: planned assuming friction {steep_mu:.2f}")
            if plan is not None:
                break
        friction.use_for_cycle(cycle_mu)
        if plan is None:
            qpos = d.qpos.copy()
            hold = HoldReference(qpos, float(sum(self.durations)))
            self.log.add(f"t={t0:.2f} s: no feasible plan, standing still for {hold.duration:.2f} s")
            self.current, self.current_ref = hold, hold
            duration = hold.duration
        else:
            self.current, self.current_ref = plan
            duration = self.current.duration
            self.yaw += turn
        self.row_of = getattr(self.current_ref, "row", None)
        self.grid = getattr(self.current_ref, "grid", None)
        self.plans.append((t0, self.current))
        self.t_start, self.t_end = t0, t0 + duration

    def _try_plan(self, scenario: Scenario, t0: float, stride: tuple[float, float], note: str = "") -> tuple[Any, bool]:
        """Plan one gait cycle: ((the plan, its whole-body reference) or None, whether a steeper foothold slope
        limit could give it footholds); a failure, or a reference that cannot be tracked
        (:meth:`planners.reference.Reference.defect`), is logged with the stride (m) and ``note``."""
        tic = time.perf_counter()
        try:
            plan = plan_gait_cycle(scenario)  # (single-threaded BLAS: planners.blas)
        except PlanningError as err:
            self.log.add(f"t={t0:.2f} s, stride {_fmt(stride)} m{note}: {err}")
            return None, isinstance(err, FootholdError) and err.slope_blocked > 0
        except Exception as err:  # a planner bug or numerical trouble: handled as a failed plan
            self.log.add(f"t={t0:.2f} s, stride {_fmt(stride)} m{note}: planner failed ({type(err).__name__}: {err})")
            return None, False
        finally:
            self.planner_times_ms.append(1e3 * (time.perf_counter() - tic))
        reference = plan.reference(self.cfg)
        defect = reference.defect()
        if defect is not None:
            self.log.add(f"t={t0:.2f} s, stride {_fmt(stride)} m{note}: whole-body reference refused ({defect})")
            return None, False
        return (plan, reference), False


def _fmt(stride: tuple[float, float]) -> str:
    """A 2-D stride (m) for the failure log: ``0.330`` along +x, ``(-0.150, 0.080)`` otherwise."""
    return f"{stride[0]:.3f}" if stride[1] == 0.0 else f"({stride[0]:.3f}, {stride[1]:.3f})"


__all__ = ["AIRBORNE_FOOTHOLD_RADIUS", "STRIDE_FALLBACKS", "CyclePlanner", "HoldReference"]
