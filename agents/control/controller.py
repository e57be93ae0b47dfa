"""Computed-torque control on the constraint-eliminated dynamics (paper §2), usable as the env hook.

``ComputedTorqueController(reference, ...)`` is called by the environment at physics rate as
``tau = controller(model, data, action)`` right after ``mj_step1``. Each call:

1. samples the plan, ``reference(t) -> planners.types.ReferenceSample`` with ``t = data.time - t0``;
2. picks the stance set (see *Stance fallback*);
3. forms ``beta_ddot_cmd = beta_ddot_ref + K_d (beta_dot_ref - beta_dot) + K_p (beta_ref - beta)``
   with beta = [base position (world), base orientation, swing-leg joints]; the orientation
   error is the rotation vector ``log(R^T R_ref)`` in the base frame (on SO(3), not a
   difference of Euler angles); the reference angular velocity and acceleration are mapped
   into the current base frame with ``R^T R_ref``;
4. solves the inverse dynamics (:class:`agents.control.inverse_dynamics.InverseDynamics`) and clips the
   torques to the model's motor limits (actuator ctrlrange).

*Stance fallback.* The stance set used is the planned set restricted to the feet that
measurably touch the terrain (MuJoCo contact between the foot geom and the terrain geom),
so a late touch-down keeps the leg on its joint reference (treated as swing) and an early
one is not loaded. If that leaves fewer stance feet than ``min(3, planned)``, the plan is
used unchanged: losing control of the base (fewer than three feet cannot hold it) is worse
than commanding a force on a foot a few millimetres from the ground. ``stance_mode``
``"planned"`` or ``"measured"`` uses one source only.

Public API: :class:`Gains`, :class:`ComputedTorqueController`, and re-exports of
:class:`InverseDynamics`, :class:`IDResult`, :func:`eliminate_constraints`,
:func:`verify_inverse_dynamics`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import mujoco
import numpy as np

from agents.control import controller_kernels as FK
from agents.control import inverse_dynamics_kernels as K
from agents.control.elimination import DAMPING, SINGULAR_SIGMA, ProjectedDynamics, eliminate_constraints, stance_layout
from agents.control.inverse_dynamics import DISTRIBUTIONS, IDResult, InverseDynamics, friction_pyramid
from agents.control.verify import IDCheck, verify_inverse_dynamics
from planners.types import PACKED_FIELDS, ReferenceSample
from quad_uneven_env import constants as C
from quad_uneven_env.fields import check_fields, param
from quad_uneven_env.robot.dynamics import mujoco_kernels as DK
from quad_uneven_env.robot.dynamics.base import DynamicsTerms, make_dynamics

__all__ = [
    "ComputedTorqueController",
    "Gains",
    "IDCheck",
    "IDResult",
    "InverseDynamics",
    "ProjectedDynamics",
    "eliminate_constraints",
    "friction_pyramid",
    "verify_inverse_dynamics",
]

STANCE_MODES: tuple[str, ...] = ("both", "planned", "measured")
"""Allowed values of ``ComputedTorqueController(stance_mode=...)``; the index is the kernels' code."""

_NO_TERRAIN = (np.empty(0), 0, 0, 0.0, 0.0, 0.0)
"""height-field kernel arguments that tell ``controller_kernels.control_step`` to skip the normals."""


@dataclasses.dataclass(frozen=True)
class Gains:
    """PD gains of the computed-torque law (per unit mass/inertia: they act on accelerations)."""

    kp_pos: float = param(400.0, "1/s^2", lo=0.0)
    """1/s^2, base position."""
    kd_pos: float = param(40.0, "1/s", lo=0.0)
    """1/s, base linear velocity."""
    kp_rot: float = param(400.0, "1/s^2", lo=0.0)
    """1/s^2, base orientation (rotation vector)."""
    kd_rot: float = param(40.0, "1/s", lo=0.0)
    """1/s, base angular velocity."""
    kp_joint: float = param(900.0, "1/s^2", lo=0.0)
    """1/s^2, swing-leg joints."""
    kd_joint: float = param(60.0, "1/s", lo=0.0)
    """1/s, swing-leg joint velocities."""

    def __post_init__(self) -> None:
        check_fields(self)


def foot_lookup(model: mujoco.MjModel) -> np.ndarray:
    """(ngeom,) leg index of each foot geom, ``N_LEGS`` for every other geom (a dummy slot)."""
    lut = np.full(model.ngeom, C.N_LEGS, dtype=int)
    lut[[model.geom(g).id for g in C.FOOT_GEOMS]] = np.arange(C.N_LEGS)
    return lut


def measured_foot_contacts(data: mujoco.MjData, foot_of_geom: np.ndarray, terrain_geom: int) -> np.ndarray:
    """(4,) bool: foot ``i`` has a contact with the terrain geom in ``data.contact``.

    :param foot_of_geom: from :func:`foot_lookup`.
    """
    lut = np.asarray(foot_of_geom, dtype=np.int64)
    mask = K.foot_contact_mask(data.contact.geom, lut, int(terrain_geom)) if data.ncon else 0
    return np.array([bool(mask >> i & 1) for i in range(C.N_LEGS)])


_CMD_INPUTS: tuple[str, ...] = (
    "p_base_W", "quat_WB", "v_base_W", "omega_base_B", "a_base_W", "domega_base_B",
    "q_joints", "qd_joints", "qdd_joints", "qpos", "qvel",
)  # fmt: skip
"""ReferenceSample fields the PD command reads, then the state, in the order of ``control_kernels.beta_command``."""
_CMD_SIZES = (3, 4, 3, 3, 3, 3, 12, 12, 12, C.NQ, C.NV)


class ComputedTorqueController:
    """Computed-torque controller on the constraint-eliminated dynamics; an env physics-rate hook.

    :param reference: ``reference(t) -> ReferenceSample`` with t (s) since the controller's reset.
    :param backend: dynamics backend (``"mujoco"`` uses what ``mj_step1`` computed: fastest).
    :param distribution: ``"pinv"`` (paper) or ``"qp"`` (friction-cone aware).
    :param gains: PD gains; default :class:`Gains`.
    :param stance_mode: ``"both"`` (plan and measured contacts, see module doc), ``"planned"``, ``"measured"``.
    :param min_normal_force: N, minimum normal force per stance foot in "qp".
    :param reference_row: optional fast form of ``reference``: ``reference_row(t) -> (row, planned)``
        with ``row`` the same sample packed as :data:`planners.types.PACKED_FIELDS` (55,) and
        ``planned`` its stance bitmask, or None where only ``reference`` applies. With the
        "mujoco" backend the controller then runs one compiled call per step
        (:mod:`agents.control.controller_kernels`) and gives the same torques.
    """

    def __init__(
        self,
        reference: Callable[[float], ReferenceSample],
        backend: str = "mujoco",
        distribution: str = "pinv",
        gains: Gains | None = None,
        stance_mode: str = "both",
        min_normal_force: float = 5.0,
        reference_row: Callable[[float], tuple[np.ndarray, int] | None] | None = None,
    ) -> None:
        if distribution not in DISTRIBUTIONS:
            raise ValueError(f"distribution must be one of {list(DISTRIBUTIONS)}, got {distribution!r}")
        if stance_mode not in STANCE_MODES:
            raise ValueError(f"stance_mode must be one of {list(STANCE_MODES)}, got {stance_mode!r}")
        self.reference = reference
        self.reference_row = reference_row
        self.backend = backend
        self.distribution = distribution
        self.gains = gains or Gains()
        self.stance_mode = stance_mode
        self.min_normal_force = float(min_normal_force)
        self.t0 = 0.0
        self.terrain: Any = None
        self._model: mujoco.MjModel | None = None
        self._last: IDResult | tuple[int, Any] | None = None
        self._last_reference: ReferenceSample | tuple[float, np.ndarray, int] | None = None
        self._bdd = np.empty(C.NV)
        self._stance_memo: dict = {}

    @property
    def last(self) -> IDResult | None:
        """The inverse-dynamics result of the last call (diagnostics)."""
        last = self._last
        if isinstance(last, tuple):  # fast path, pinv forces inside the cones: built on demand
            status, lay, version = last
            if version != self.id.ws_version:
                raise RuntimeError(
                    "controller.last: the inverse-dynamics buffers were reused since; read it right after the call"
                )
            ws = self.id._ws
            last = self._last = IDResult(
                ws[0].copy(), ws[1].copy(), ws[2].copy(), lay.stance,
                "qp" if self.distribution == "qp" and lay.n_stance else "pinv",
                exact=bool(status & K.EXACT), damped=bool(status & K.DAMPED),
            )  # fmt: skip
        return last

    @property
    def last_reference(self) -> ReferenceSample | None:
        """The reference sample of the last call (diagnostics)."""
        last = self._last_reference
        if isinstance(last, tuple):  # fast path: unpack the row on demand
            t, row, planned = last
            parts, k = [], 0
            for _, n in PACKED_FIELDS:
                parts.append(row[k : k + n].copy())
                k += n
            stance = tuple(bool(planned >> i & 1) for i in range(C.N_LEGS))
            last = self._last_reference = ReferenceSample(t, *parts, stance)  # type: ignore[arg-type]
        return last

    @property
    def gains(self) -> Gains:
        """PD gains of the control law."""
        return self._gains_obj

    @gains.setter
    def gains(self, gains: Gains) -> None:
        self._gains_obj = gains
        g = gains
        self._gains = np.array([g.kp_pos, g.kd_pos, g.kp_rot, g.kd_rot, g.kp_joint, g.kd_joint], dtype=float)

    # ------------------------------------------------------------------ setup
    def _bind(self, model: mujoco.MjModel) -> None:
        self._model = model
        self.dynamics = make_dynamics(self.backend, model)
        self.id = InverseDynamics(self.dynamics, self.distribution, min_normal_force=self.min_normal_force)
        act = [model.actuator(a).id for a in C.ACTUATOR_NAMES]
        if [int(model.actuator_trnid[a, 0]) for a in act] != [model.joint(j).id for j in C.JOINT_NAMES]:
            raise ValueError("actuators must drive the joints in JOINT_NAMES order")
        self.torque_limit = model.actuator_ctrlrange[act, 1].copy()
        self.foot_of_geom = foot_lookup(model).astype(np.int64)
        self.terrain_geom = model.geom(C.TERRAIN_GEOM).id
        self._foot_sites = np.array([model.site(s).id for s in C.FOOT_SITES])
        self._normal_buf = np.empty((C.N_LEGS, 3))
        # buffers of the compiled mujoco-backend path: M, J_feet, Jdot qdot, G
        self._terms_buf = (
            np.empty((C.NV, C.NV)),
            np.empty((C.N_LEGS, 3, C.NV)),
            np.empty((C.N_LEGS, 3)),
            np.empty(C.NV),
        )
        self._stance_memo.clear()
        self._site_buf = np.empty((C.N_LEGS, 3))
        self._fast_cache: tuple | None = None
        self._layouts = [stance_layout(tuple(bool(m >> i & 1) for i in range(C.N_LEGS))) for m in range(16)]

    def reset(self, model: mujoco.MjModel, data: mujoco.MjData, terrain: Any = None) -> None:
        """Bind to ``model``, restart the reference clock at ``data.time``, keep ``terrain`` for normals."""
        self._bind(model)
        self.t0 = float(data.time)
        self.terrain = terrain
        self._last = None

    # ------------------------------------------------------------------ control law
    def __call__(self, model: mujoco.MjModel, data: mujoco.MjData, action: np.ndarray | None = None) -> np.ndarray:
        """Joint torques (12, N m, clipped to the motor limits) at ``data``'s state (after mj_step1)."""
        if model is not self._model:
            self._bind(model)
        t = float(data.time) - self.t0
        if self.reference_row is not None and self.backend == "mujoco":
            packed = self.reference_row(t)
            if packed is not None:
                tau = self._fast_step(data, t, *packed)
                if tau is not None:
                    return tau
        ref = self.reference(t)
        meas = K.foot_contact_mask(data.contact.geom, self.foot_of_geom, self.terrain_geom) if data.ncon else 0
        try:
            stance = self._stance_memo[(ref.stance, meas, self.stance_mode)]
        except (KeyError, TypeError):
            stance = self.select_stance(ref.stance, np.array([bool(meas >> i & 1) for i in range(C.N_LEGS)]))
            if isinstance(ref.stance, tuple):
                self._stance_memo[(ref.stance, meas, self.stance_mode)] = stance
        lay = stance_layout(stance)
        qpos, qvel = data.qpos, data.qvel
        beta_ddot = self._bdd[: self._beta_command(qpos, qvel, ref, lay.mask)]
        normals = self._normals(data, stance) if self.distribution == "qp" else None
        if self.backend == "mujoco":
            M, J, Jdd, G = self._terms_buf
            DK.mujoco_terms(*self.dynamics.data_views(data), M, J, Jdd, G)
            h = data.qfrc_bias
            result = self.id.solve_compiled(M, h, J, Jdd, lay, beta_ddot, normals)
            if result is None:
                terms = DynamicsTerms(M.copy(), h.copy(), G.copy(), J.copy(), Jdd.copy())
                result = self.id.solve_terms(terms, beta_ddot.copy(), stance, normals)
        else:
            terms = self.dynamics.terms(qpos, qvel)
            result = self.id.solve_terms(terms, beta_ddot.copy(), stance, normals)
        self._last, self._last_reference = result, ref
        tau = np.empty(C.N_JOINTS)
        K.clip_into(result.tau, self.torque_limit, tau)
        return tau

    def _fast_step(self, data: mujoco.MjData, t: float, row: np.ndarray, planned: int) -> np.ndarray | None:
        """:meth:`__call__` from a packed reference row by one compiled call (:mod:`agents.control.controller_kernels`);
        None where the general path is needed (1-2 stance feet, a failed Cholesky, a malformed row)."""
        tail, normals = self._fast_arguments(data)
        self.id.ws_version += 1  # control_step rewrites the inverse-dynamics buffers
        try:
            code = FK.control_step(
                row, planned, STANCE_MODES.index(self.stance_mode),
                data.contact.geom, self.foot_of_geom, self.terrain_geom, *tail,
            )  # fmt: skip
        except TypeError:  # arrays the kernel does not take (numba dispatch): the general path
            return None
        if code < 0 or not (code >> 4) & K.DONE:
            return None
        lay = self._layouts[code & 15]
        status, ws = code >> 4, self.id._ws
        self._last_reference = (t, row, planned)
        tau = np.empty(C.N_JOINTS)
        if self.distribution == "qp" and lay.n_stance and not code & FK.INSIDE_CONES:
            result = IDResult(
                ws[0].copy(), ws[1].copy(), ws[2].copy(), lay.stance, "pinv",
                exact=bool(status & K.EXACT), damped=bool(status & K.DAMPED),
            )  # fmt: skip
            self.id._distribute_qp(lay, self._terms_buf[1], ws[3], result, normals)
            self._last = result
            K.clip_into(result.tau, self.torque_limit, tau)
        else:  # the pinv torques (for "qp": its optimum, as control_step checked the cones)
            self._last = (status, lay, self.id.ws_version)  # the IDResult is built from the buffers if asked for
            K.clip_into(ws[0], self.torque_limit, tau)
        return tau

    def _fast_arguments(self, data: mujoco.MjData) -> tuple[tuple, np.ndarray | None]:
        """The arguments of ``control_step`` after the contacts (views and buffers that outlive a step),
        and the normals buffer (None without "qp" or a height field); rebuilt when an input object changes."""
        hf = getattr(self.terrain, "heightfield", None)
        c = self._fast_cache
        if c is not None and c[0] is data and c[1] is hf and c[2] is self._gains and c[3] == self.distribution:
            return c[4], c[5]
        normals = self._normal_buf if self.distribution == "qp" and hasattr(hf, "kernel_args") else None
        hf_args = _NO_TERRAIN if normals is None else hf.kernel_args
        tail = (
            data.qpos, data.qvel, self._gains, self._bdd, *self.dynamics.data_views(data)[1:],
            *self._terms_buf, data.qfrc_bias, 1.0 / SINGULAR_SIGMA, DAMPING, *self.id._ws,
            *hf_args, self._foot_sites, self._site_buf, self._normal_buf,
            self.id.mu if normals is not None else 0.0, self.id._cone_lower, self.id._cone_buf,
        )  # fmt: skip
        self._fast_cache = (data, hf, self._gains, self.distribution, tail, normals)
        return tail, normals

    def select_stance(self, planned, measured: np.ndarray) -> tuple[bool, bool, bool, bool]:
        """Stance set from the plan and the measured contacts (rule in the module docstring)."""
        if self.stance_mode == "planned":
            return tuple(bool(s) for s in planned)  # type: ignore[return-value]
        if self.stance_mode == "measured":
            return tuple(bool(s) for s in measured)  # type: ignore[return-value]
        chosen = tuple(bool(p) and bool(m) for p, m in zip(planned, measured, strict=True))
        n_planned = sum(bool(p) for p in planned)
        if sum(chosen) < min(3, n_planned):
            return tuple(bool(p) for p in planned)  # type: ignore[return-value]
        return chosen  # type: ignore[return-value]

    def beta_ddot_command(
        self, qpos: np.ndarray, qvel: np.ndarray, ref: ReferenceSample, stance: tuple[bool, bool, bool, bool]
    ) -> np.ndarray:
        """beta_ddot_cmd (n_beta,): reference acceleration plus PD on position, SO(3) orientation and swing joints."""
        n = self._beta_command(
            np.asarray(qpos, dtype=float), np.asarray(qvel, dtype=float), ref, stance_layout(stance).mask
        )
        return self._bdd[:n].copy()

    def _beta_command(self, qpos: np.ndarray, qvel: np.ndarray, ref: ReferenceSample, mask: int) -> int:
        """Write beta_ddot_cmd into ``self._bdd`` (compiled kernel); returns n_beta."""
        args = [getattr(ref, f) for f in _CMD_INPUTS[:9]]
        try:
            n = K.beta_command(qpos, qvel, *args, self._gains, mask, self._bdd)
        except TypeError:  # lists, other dtypes, read-only arrays: convert once
            args = [np.ascontiguousarray(a, dtype=float).reshape(-1) for a in args]
            n = K.beta_command(qpos, qvel, *args, self._gains, mask, self._bdd)
        if n < 0:
            what = _CMD_INPUTS[-n - 1]
            got = np.shape(qpos if what == "qpos" else qvel if what == "qvel" else getattr(ref, what))
            what = what if what in ("qpos", "qvel") else f"reference field {what}"
            raise ValueError(f"{what} must have {_CMD_SIZES[-n - 1]} entries, got shape {got}")
        return n

    def _normals(self, data: mujoco.MjData, stance: tuple[bool, ...]) -> np.ndarray | None:
        """(4, 3) terrain normals under the feet (world); only stance rows are used by the QP.

        The normal of the surface triangle under each foot site (compiled query, ~1 us): it is
        constant while a foot stays on its triangle, so the QP's friction cones stay cached.
        """
        hf = getattr(self.terrain, "heightfield", None)
        if hf is None or not hasattr(hf, "normal_points"):
            return None
        return hf.normal_points(data.site_xpos[self._foot_sites], self._normal_buf)


def verify(
    model: mujoco.MjModel, qpos: np.ndarray, qvel: np.ndarray, beta_ddot: np.ndarray, result: IDResult
) -> IDCheck:
    """Alias of :func:`agents.control.verify.verify_inverse_dynamics` (MuJoCo's M, h, J at the same state)."""
    return verify_inverse_dynamics(model, qpos, qvel, beta_ddot, result)
