"""Joint references for the controller (paper §5 -> §2.3): beta_ref(t) and its exact derivatives.

From a :class:`~planners.cycle.GaitCyclePlan`: the base is placed so the whole-robot COG (legs
included) follows the planned COG path, with the plan's base orientation: identity (the paper)
or the plan's pitch and yaw profile (:class:`planners.pitch.BodyPitch`); swing-leg joints follow the
swing paths by closed-form IK; stance-leg joints hold the feet on their footholds (IK against
the planned base), so the controller can use them as a fallback. Velocities and accelerations
come from the analytic leg Jacobians and their time derivatives (:mod:`planners.wholebody`),
not from finite differences.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from planners.gait import phase_index
from planners.pitch import LEVEL
from planners.robot_geometry import RobotGeometry, robot_geometry
from planners.terrain_query import foot_site_on
from planners.types import ReferenceGrid, ReferenceSample
from planners.wholebody import WholeBody
from quad_uneven_env.constants import LEG_NAMES
from quad_uneven_env.robot.description import RobotDescription
from quad_uneven_env.spatial import quat_to_matrix

_IDENTITY = np.array([1.0, 0.0, 0.0, 0.0])
MAX_JOINT_SPEED = 50.0
"""rad/s: a reference joint speed above this is a singular leg, not a motion (planned gait cycles stay below
~12 rad/s, also on the randomized suites; a leg planned at full stretch gives 1e17 and more)."""
_STANCE_OF_MASK = [tuple(bool(m >> i & 1) for i in range(4)) for m in range(16)]
"""stance tuple (LF, RF, LH, RH) of each 4-bit mask."""


class Reference:
    """Whole-robot reference of a planned gait cycle; ``sample(t)`` for the controller.

    :param plan: the gait-cycle plan.
    :param cfg: the robot (a ``RobotDescription`` or :class:`~planners.robot_geometry.RobotGeometry`;
        default: the paper's Table 1); must be the robot the plan was made for.
    :param grid_dt: spacing (s) of the exact samples precomputed (vectorised) at construction;
        ``sample(t)`` at a grid time (the controller's 2 ms ticks from the cycle start) is a
        lookup, other times are computed exactly on the spot (Newton warm-started from the grid).
    """

    def __init__(self, plan, cfg: RobotDescription | RobotGeometry | None = None, grid_dt: float = 0.002) -> None:
        self.plan = plan
        self.geometry = robot_geometry(cfg)
        """the planners' view of the robot."""
        self.cfg = self.geometry.description
        """the robot's description."""
        self.wb = WholeBody(self.geometry)
        r = self.geometry.foot_radius
        self.sites_start = foot_site_on(plan.terrain, plan.feet_start, r)
        self.sites_target = foot_site_on(plan.terrain, plan.footholds, r)
        self.t_end = plan.duration
        self.pitch = getattr(plan, "pitch", None) or LEVEL
        self._swing_end = np.array([plan.swing[leg].t_end if leg in plan.swing else -np.inf for leg in LEG_NAMES])
        self._stance = np.array([p.stance for p in plan.phases])
        self._grid_dt = float(grid_dt)
        self._grid_t = np.arange(0.0, self.t_end + 0.5 * grid_dt, grid_dt)
        self._grid = self.evaluate(self._grid_t, newton_steps=3)  # converged to ~1e-14 (tests)
        self._grid_p = self._grid[0]
        self._grid_mask = (self._grid[6].astype(np.int64) << np.arange(4)).sum(axis=1).tolist()
        # Shared tuples: thousands of new ones per plan would wake Python's cyclic GC.
        self._grid_stance = [_STANCE_OF_MASK[m] for m in self._grid_mask]
        # One packed row per grid time, so that a sample is one copy plus views of it.
        p, pd, pdd, q, qd, qdd, _ = self._grid
        quat, w, dw = self._orientation(self._grid_t)
        self._packed = np.concatenate([p, quat, pd, w, pdd, dw, q, qd, qdd], axis=1)
        # Row views made when asked for: the lane looks rows up in compiled code, the Python path a few times a cycle.
        self._rows = PackedRows(self._packed)
        self._grid_t_list = self._grid_t.tolist()
        self.grid = ReferenceGrid(
            self._grid_t, self._grid_dt, self.t_end, self._packed, np.array(self._grid_mask, dtype=np.int64), self._rows
        )
        """the rows :meth:`row` returns, for the controller's compiled lookup (:class:`ReferenceGrid`)."""

    def row(self, t: float) -> tuple[np.ndarray, int] | None:
        """The packed reference at grid time ``t`` (s from the cycle start, clipped to the cycle), or None off the grid.

        Returns a view (55,) into the grid (not to be written) laid out as
        :data:`planners.types.PACKED_FIELDS` and the
        planned stance as a bitmask (bit i: leg i of LF, RF, LH, RH), for the controller's compiled
        path; :meth:`sample` is the same data as a :class:`ReferenceSample`.
        """
        tc = min(max(t, 0.0), self.t_end)
        k = round(tc / self._grid_dt)
        if k < len(self._rows) and abs(self._grid_t_list[k] - tc) < 1e-9:
            return self._rows[k], self._grid_mask[k]
        return None

    def defect(self, max_joint_speed: float = MAX_JOINT_SPEED) -> str | None:
        """Why this reference cannot be tracked, or None if it can: a non-finite value or a joint speed above
        ``max_joint_speed`` (rad/s) on its grid.

        Both come from a leg the plan holds at or beyond full stretch (a measured start whose feet are
        farther from the hips than the leg reaches): its IK is clipped to the stretched knee, where the leg
        Jacobian is singular and the joint velocities and accelerations are not defined.
        """
        p, pd, pdd, q, qd, qdd, _ = self._grid
        for name, a in (("base", np.hstack([p, pd, pdd])), ("joint", np.hstack([q, qd, qdd]))):
            if not np.isfinite(a).all():
                k = int(np.flatnonzero(~np.isfinite(a).all(axis=1))[0])
                return f"non-finite {name} reference at t={self._grid_t[k]:.3f} s"
        speed = np.abs(qd)
        k, j = np.unravel_index(int(np.argmax(speed)), speed.shape)
        if speed[k, j] > max_joint_speed:
            knee = abs(q[k, 3 * (j // 3) + 2])
            return (
                f"singular leg {LEG_NAMES[j // 3]}: joint speed {speed[k, j]:.3g} rad/s > {max_joint_speed:g} at "
                f"t={self._grid_t[k]:.3f} s (knee {knee:.3f} rad from stretched)"
            )
        return None

    def joint_range_excess(self) -> tuple[float, int, float]:
        """How far the joint references go beyond the robot's joint ranges (:attr:`RobotGeometry.joint_ranges`).

        The planners bound each leg's reach (hip-to-foot distance), not its joint angles: a narrow joint range
        (HyQ's HFE: 70 deg forward of the standing thigh at most) can be planned past, and the simulated joint then
        stops at its limit while its reference goes on (docs/robots.md, "What fails").

        :return: ``(excess, joint, t)``: the largest excess (rad; <= 0: every reference within its range), the joint
            (index in ``JOINT_NAMES``) and the grid time (s from the cycle start) where it occurs.
        """
        lo, hi = self.geometry.joint_ranges.T  # type: ignore[union-attr]
        q = self._grid[3]
        over = np.maximum(q - hi, lo - q)
        k, j = np.unravel_index(int(np.argmax(over)), over.shape)
        return float(over[k, j]), int(j), float(self._grid_t[k])

    def feet(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Planned foot-site positions, velocities, accelerations (T, 4, 3) (m, m/s, m/s^2) at times ``t`` (s)."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        moved = t[:, None] >= self._swing_end[None, :]
        x = np.where(moved[..., None], self.sites_target, self.sites_start)
        xd = np.zeros_like(x)
        xdd = np.zeros_like(x)
        for i, leg in enumerate(LEG_NAMES):
            sw = self.plan.swing.get(leg)
            if sw is None:
                continue
            sel = (t > sw.t_start) & (t < sw.t_end)
            if np.any(sel):
                ts = t[sel]
                x[sel, i], xd[sel, i], xdd[sel, i] = sw.spline.evaluate(ts)  # position, velocity, acceleration
        return x, xd, xdd

    def evaluate(self, t: np.ndarray, newton_steps: int = 4, p_guess: np.ndarray | None = None):
        """Vectorised reference at times ``t`` (T,) (s), clipped to the cycle.

        :return: ``(p, p_d, p_dd, q, qd, qdd, stance)``: base position/velocity/acceleration (T, 3)
            in m, m/s, m/s^2 (world); joints (T, 12) in rad, rad/s, rad/s^2 (JOINT_NAMES order);
            stance flags (T, 4).
        """
        t = np.clip(np.atleast_1d(np.asarray(t, dtype=float)), 0.0, self.t_end)
        cog = self.plan.cog
        c, cd, cdd = cog.position(t), cog.velocity(t), cog.acceleration(t)
        x, xd, xdd = self.feet(t)
        n, compiled = len(t), p_guess is None
        if not self.pitch.level:  # solve in the frame rotating with the base (planners.wholebody)
            w, a = self.pitch.omega(t)
            p, pd, pdd, q, qd, qdd = self.wb.place_base_rotated(
                c, cd, cdd, x, xd, xdd, self.pitch.rotation(t), w, a, p_guess, newton_steps, compiled
            )
        elif compiled:
            p, pd, pdd, q, qd, qdd = self.wb.place_base_compiled(c, cd, cdd, x, xd, xdd, newton_steps)
        else:
            p, pd, pdd, q, qd, qdd = self.wb.place_base(c, cd, cdd, x, xd, xdd, p_guess, newton_steps)
        if not compiled:
            q, qd, qdd = q.reshape(n, 12), qd.reshape(n, 12), qdd.reshape(n, 12)
        stance = self._stance[phase_index(self.plan.phases, t)]
        return p, pd, pdd, q, qd, qdd, stance

    def _orientation(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Base quaternion (T, 4), angular velocity (T, 3) (rad/s) and acceleration (T, 3) (rad/s^2), base frame."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        if self.pitch.level:
            return np.tile(_IDENTITY, (len(t), 1)), np.zeros((len(t), 3)), np.zeros((len(t), 3))
        w, dw = self.pitch.omega_base(t)
        return self.pitch.quaternion(t), w, dw

    def sample(self, t: float) -> ReferenceSample:
        """The planned whole-robot state at time ``t`` (s from the cycle start; clipped to the cycle)."""
        tc = min(max(float(t), 0.0), self.t_end)
        k = round(tc / self._grid_dt)
        if k < len(self._grid_t) and abs(self._grid_t[k] - tc) < 1e-9:
            row = self._packed[k].copy()
            return ReferenceSample(
                float(t), row[0:3], row[3:7], row[7:10], row[10:13], row[13:16], row[16:19],
                row[19:31], row[31:43], row[43:55], self._grid_stance[k],
            )  # fmt: skip
        else:
            guess = np.array([np.interp(tc, self._grid_t, self._grid_p[:, j]) for j in range(3)])[None]
            p, pd, pdd, q, qd, qdd, stance = (a[0] for a in self.evaluate(np.array([tc]), 2, guess))
            stance = tuple(bool(s) for s in stance)
            quat, w, dw = (a[0] for a in self._orientation(tc))
        return ReferenceSample(
            t=float(t),
            p_base_W=p.copy(),
            quat_WB=quat,
            v_base_W=pd.copy(),
            omega_base_B=w,
            a_base_W=pdd.copy(),
            domega_base_B=dw,
            q_joints=q.copy(),
            qd_joints=qd.copy(),
            qdd_joints=qdd.copy(),
            stance=stance,  # type: ignore[arg-type]
        )


class PackedRows(Sequence):
    """The rows of a (T, 55) packed grid as a sequence of (55,) views (made at each lookup; not to be written)."""

    def __init__(self, packed: np.ndarray) -> None:
        self._packed = packed

    def __len__(self) -> int:
        """Number of grid rows."""
        return self._packed.shape[0]

    def __getitem__(self, k: int) -> np.ndarray:  # type: ignore[override]
        """Row ``k`` (55,), a view."""
        return self._packed[k]


def aim_feet_below_footholds(
    sample: ReferenceSample,
    plan,
    t: float,
    legs: np.ndarray,
    depth: float,
    cfg: RobotDescription | RobotGeometry,
) -> ReferenceSample:
    """``sample`` with the joints of ``legs`` (4 bools) aimed ``depth`` (m) below their current footholds.

    For a planned-stance foot that has not touched down: the swing spline ends exactly on the
    surface, and a few millimetres of tracking error would leave the foot hovering. The joint
    targets come from the closed-form leg IK against the sample's base pose; their velocity and
    acceleration references are zero.

    :param t: plan time (s) of ``sample``: a leg whose swing has ended aims at its target foothold,
        otherwise at its start foothold.
    """
    q, qd, qdd = sample.q_joints.copy(), sample.qd_joints.copy(), sample.qdd_joints.copy()
    R = quat_to_matrix(sample.quat_WB)
    geom = robot_geometry(cfg)
    for i in np.flatnonzero(legs):
        leg = LEG_NAMES[i]
        sw = plan.swing.get(leg)
        foothold = plan.footholds[i] if sw is not None and t >= sw.t_end - 1e-9 else plan.feet_start[i]
        target_W = foothold + np.array([0.0, 0.0, geom.foot_radius - depth])
        hip_W = sample.p_base_W + R @ geom.hips_B[i]
        q[3 * i : 3 * i + 3] = geom.leg_ik(i, R.T @ (target_W - hip_W))
        qd[3 * i : 3 * i + 3] = 0.0
        qdd[3 * i : 3 * i + 3] = 0.0
    return dataclasses.replace(sample, q_joints=q, qd_joints=qd, qdd_joints=qdd)
