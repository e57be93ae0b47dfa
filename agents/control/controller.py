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

*The compiled step.* For a reference planned on a grid (the expert), :meth:`ComputedTorqueController.grid_step_into`
does the same step in one compiled call (:func:`agents.control.controller_kernels.grid_control_step`) and gives the
same torques (tested against ``__call__``); it declines, changing nothing the call would not redo, where the
readable path must run.

Public API: :class:`Gains`, :class:`ComputedTorqueController`, and re-exports of
:class:`InverseDynamics`, :class:`IDResult`, :func:`eliminate_constraints`,
:func:`verify_inverse_dynamics`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any, NamedTuple

import mujoco
import numpy as np
from numba.core.errors import NumbaError

from agents.control import controller_kernels
from agents.control import inverse_dynamics_kernels as IK
from agents.control.elimination import DAMPING, SINGULAR_SIGMA, ProjectedDynamics, eliminate_constraints, stance_layout
from agents.control.inverse_dynamics import (
    DISTRIBUTIONS,
    QP_SOLVERS,
    IDResult,
    InverseDynamics,
    WorkspaceResult,
    friction_pyramid,
)
from agents.control.verify import IDCheck, verify_inverse_dynamics
from planners.types import PACKED_FIELDS, ReferenceGrid, ReferenceSample
from quad_uneven_env import constants as C
from quad_uneven_env.compiled_call import entry_point
from quad_uneven_env.fields import check_fields, excerpt, param
from quad_uneven_env.robot.dynamics import make_dynamics
from quad_uneven_env.robot.dynamics import mujoco_kernels as DK
from quad_uneven_env.robot.dynamics.base import DynamicsTerms

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
"""height-field kernel arguments that tell ``control_step`` to skip the normals."""


def contact_pairs(data: mujoco.MjData) -> np.ndarray:
    """(ncon, 2) int32: the geom pairs of ``data``'s contacts, C-contiguous whatever ``ncon``.

    MuJoCo's own view (``data.contact.geom``) is strided for two contacts or more and contiguous for none or
    one, which numba types as two array layouts: every compiled control kernel would compile twice, the second
    time in the middle of a rollout (the first airborne step), for seconds.
    """
    return np.ascontiguousarray(data.contact.geom)


class PackedReference(NamedTuple):
    """A reference sample as the compiled step received it: a packed row (:data:`PACKED_FIELDS`) and a stance mask."""

    t: float
    """s since the controller's reset."""
    row: np.ndarray
    """(55,) packed :class:`ReferenceSample` arrays."""
    planned: int
    """planned stance bitmask (bit i: leg i)."""

    def unpack(self) -> ReferenceSample:
        """The :class:`ReferenceSample` (copies)."""
        parts, k = [], 0
        for _, n in PACKED_FIELDS:
            parts.append(self.row[k : k + n].copy())
            k += n
        stance = tuple(bool(self.planned >> i & 1) for i in range(C.N_LEGS))
        return ReferenceSample(self.t, *parts, stance)  # type: ignore[arg-type]


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
    mask = IK.foot_contact_mask(data.contact.geom, lut, int(terrain_geom)) if data.ncon else 0
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
    :param mu: friction coefficient of the "qp" cones (-); None: the model's foot friction.
    :param qp_solver: "qp" solver, ``"compiled"`` or ``"daqp"`` (:class:`InverseDynamics`).
    """

    def __init__(
        self,
        reference: Callable[[float], ReferenceSample],
        backend: str = "mujoco",
        distribution: str = "pinv",
        gains: Gains | None = None,
        stance_mode: str = "both",
        min_normal_force: float = 5.0,
        mu: float | None = None,
        qp_solver: str = "compiled",
    ) -> None:
        if distribution not in DISTRIBUTIONS:
            raise ValueError(f"distribution must be one of {list(DISTRIBUTIONS)}, got {excerpt(distribution)}")
        if stance_mode not in STANCE_MODES:
            raise ValueError(f"stance_mode must be one of {list(STANCE_MODES)}, got {excerpt(stance_mode)}")
        self.reference = reference
        self.backend = backend
        self.distribution = distribution
        self.gains = gains or Gains()
        self.stance_mode = stance_mode
        self.min_normal_force = float(min_normal_force)
        if mu is not None and not mu > 0:
            raise ValueError(f"mu must be > 0 (friction coefficient of the cones), got {excerpt(mu)}")
        self.mu = mu
        if qp_solver not in QP_SOLVERS:
            raise ValueError(f"qp_solver must be one of {list(QP_SOLVERS)}, got {excerpt(qp_solver)}")
        self.qp_solver = qp_solver
        self.t0 = 0.0
        self.terrain: Any = None
        self._model: mujoco.MjModel | None = None
        self._last: IDResult | WorkspaceResult | None = None
        self._last_reference: ReferenceSample | PackedReference | None = None
        self._bdd = np.empty(C.NV)
        self._stance_memo: dict = {}
        self._layouts = [stance_layout(tuple(bool(m >> i & 1) for i in range(C.N_LEGS))) for m in range(16)]
        self._step_cache: tuple | None = None  # (data, height field, gains, their StepArguments or None: refused)
        self._grid_cache: tuple | None = None  # (grid, touch, tau_ok, their GridArguments) of grid_step_into
        self._grid_step: tuple | None = None  # (code, t, grid, workspace version) of the last grid step, unread
        self._grid_calls: dict[tuple[int, int], tuple] = {}
        """per (id(limit), id(out)) of :meth:`grid_step_into`: grid_control_step's compiled entry point, then the
        objects that fix its argument types (StepArguments, GridArguments, limit, out, the stance mode) and its
        code (see :mod:`quad_uneven_env.compiled_call`)."""

    def __getstate__(self) -> dict[str, Any]:
        """``copy.deepcopy`` and pickle: everything but the compiled step's records and entry points (numba objects,
        which neither copy nor pickle); the copy rebuilds them at its first compiled step."""
        if self._grid_step is not None:
            self._settle_grid_step()
        state = dict(self.__dict__)
        state["_step_cache"] = state["_grid_cache"] = None
        state["_grid_calls"] = {}
        return state

    @property
    def last(self) -> IDResult | None:
        """The inverse-dynamics result of the last call (diagnostics; read it before the next call)."""
        if self._grid_step is not None:
            self._settle_grid_step()
        last = self._last
        if isinstance(last, WorkspaceResult):  # the compiled step (pinv, or its QP): built on demand
            distribution = "qp" if self.distribution == "qp" and last.layout.n_stance else "pinv"
            last = self._last = last.build(self.id, distribution)
        return last

    @property
    def last_reference(self) -> ReferenceSample | None:
        """The reference sample of the last call (diagnostics)."""
        if self._grid_step is not None:
            self._settle_grid_step()
        last = self._last_reference
        if isinstance(last, PackedReference):  # the compiled step: unpacked on demand
            last = self._last_reference = last.unpack()
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
        self.id = InverseDynamics(
            self.dynamics,
            self.distribution,
            mu=self.mu,
            min_normal_force=self.min_normal_force,
            qp_solver=self.qp_solver,
        )
        act = [model.actuator(a).id for a in C.ACTUATOR_NAMES]
        if [int(model.actuator_trnid[a, 0]) for a in act] != [model.joint(j).id for j in C.JOINT_NAMES]:
            raise ValueError("actuators must drive the joints in JOINT_NAMES order")
        self.torque_limit = model.actuator_ctrlrange[act, 1].copy()
        self.foot_of_geom = foot_lookup(model).astype(np.int64)
        self.terrain_geom = model.geom(C.TERRAIN_GEOM).id
        self._foot_sites = np.array([model.site(s).id for s in C.FOOT_SITES])
        self._normal_buf = np.empty((C.N_LEGS, 3))
        # buffers of the mujoco-backend terms on the readable path: M, J_feet, Jdot qdot, G
        self._terms_buf = (
            np.empty((C.NV, C.NV)),
            np.empty((C.N_LEGS, 3, C.NV)),
            np.empty((C.N_LEGS, 3)),
            np.empty(C.NV),
        )
        self._stance_memo.clear()
        self._grid_cache = self._grid_step = self._step_cache = None
        self._grid_calls.clear()
        # outputs of the compiled step: M, J_feet, Jdot qdot, G; beta_ddot; foot sites; normals; clipped torques
        self._step_terms = (
            np.empty((C.NV, C.NV)), np.empty((C.N_LEGS, 3, C.NV)), np.empty((C.N_LEGS, 3)), np.empty(C.NV),
        )  # fmt: skip
        self._step_bdd = np.empty(C.NV)
        self._step_sites = np.empty((C.N_LEGS, 3))
        self._step_normals = np.empty((C.N_LEGS, 3))
        self._step_tau = np.empty(C.N_JOINTS)

    def reset(self, model: mujoco.MjModel, data: mujoco.MjData, terrain: Any = None) -> None:
        """Bind to ``model``, restart the reference clock at ``data.time``, keep ``terrain`` for normals."""
        self._bind(model)
        self.t0 = float(data.time)
        self.terrain = terrain
        self._last = self._grid_step = None

    def set_friction(self, mu: float) -> None:
        """Change the friction coefficient of the "qp" cones (-, > 0) from the next step on, until the next
        :meth:`reset` rebuilds them from :attr:`mu` (which this sets too)."""
        self.mu = float(mu)
        self.id.set_mu(mu)
        self._step_cache = None  # the compiled step's arguments hold the cones' friction

    # ------------------------------------------------------------------ control law
    def __call__(
        self,
        model: mujoco.MjModel,
        data: mujoco.MjData,
        action: np.ndarray | None = None,
        contacts: int | None = None,
    ) -> np.ndarray:
        """Joint torques (12, N m, clipped to the motor limits) at ``data``'s state (after mj_step1).

        :param contacts: bitmask of the feet measured in contact (bit i: leg i); None: from ``data.contact``.
        """
        if model is not self._model:
            self._bind(model)
        self._grid_step = None
        t = float(data.time) - self.t0
        ref = self.reference(t)
        if contacts is not None:
            meas = contacts
        else:
            meas = self.foot_contact_bits(data)
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
        IK.clip_into(result.tau, self.torque_limit, tau)
        return tau

    def foot_contact_bits(self, data: mujoco.MjData) -> int:
        """Bitmask of the feet touching the terrain in ``data.contact`` (bit i: leg i; after ``mj_step1``)."""
        return IK.foot_contact_mask(contact_pairs(data), self.foot_of_geom, self.terrain_geom) if data.ncon else 0

    def grid_step_into(
        self,
        model: mujoco.MjModel,
        data: mujoco.MjData,
        grid: ReferenceGrid,
        t_start: float,
        t_stop: float,
        touch: np.ndarray,
        touch_adr: np.ndarray,
        tau_ok: np.ndarray,
        limit: np.ndarray,
        out: np.ndarray,
        contacts: int = -1,
    ) -> bool:
        """The call ``self(model, data, None, contacts)`` for a reference planned on ``grid``, in one compiled call
        (:func:`~agents.control.controller_kernels.grid_control_step`): its torques (clipped to the motor limits,
        finite) into ``tau_ok`` and, clipped to ``±limit`` (N m), into ``out``. True when it took the step; False
        where the call must run instead (nothing but the inverse-dynamics buffers changed).

        It takes the step where the reference at controller time ``t`` is ``grid``'s row at ``t - t_start`` (s),
        every planned stance foot touches (``touch[touch_adr[leg]] > 0``, the simulator's touch sensors), and the
        step needs nothing the kernel leaves to Python (1-2 stance feet, a failed Cholesky, a QP the compiled solver
        gives up on). :attr:`last` and :attr:`last_reference` are then those of the call it replaces.

        :param grid: the plan's rows, valid for controller times ``t`` (s) in [``t_start``, ``t_stop``).
        :param contacts: bitmask of the feet measured in contact (bit i: leg i); -1: from ``data.contact``.
        """
        t = data.time - self.t0
        args = None if t >= t_stop else self._grid_arguments(model, data, grid, touch, touch_adr, tau_ok)
        if args is None:
            return False
        self.id.workspace_version += 1  # the compiled call rewrites the inverse-dynamics buffers
        a, g = args
        key = (id(limit), id(out))
        call = self._grid_calls.get(key)
        try:
            if (
                call is not None and call[1] is a and call[2] is g and call[3] is limit and call[4] is out
                and call[5] is self.stance_mode
            ):  # fmt: skip
                code = call[0](t - t_start, call[6], contact_pairs(data), contacts, a, g, limit, out)
            else:
                values = (
                    t - t_start, STANCE_MODES.index(self.stance_mode), contact_pairs(data), int(contacts), a, g, limit,
                    out,
                )  # fmt: skip
                code = controller_kernels.grid_control_step(*values)
                entry = entry_point(controller_kernels.grid_control_step, values)
                if len(self._grid_calls) >= 4:  # a caller handing new buffers every step: keep the cache small
                    self._grid_calls.clear()
                if entry is not None:
                    self._grid_calls[key] = (entry, a, g, limit, out, self.stance_mode, values[1])
        except (TypeError, NumbaError):  # arrays the kernel does not take (numba dispatch): the readable path,
            # for these inputs from now on: a failed compilation is not retried every step
            self._step_cache = (data, getattr(self.terrain, "heightfield", None), self._gains, None)
            return False
        if code < 0:
            return False
        self._grid_step = (code, t, grid, self.id.workspace_version)
        return True

    def _grid_arguments(
        self,
        model: mujoco.MjModel,
        data: mujoco.MjData,
        grid: ReferenceGrid,
        touch: np.ndarray,
        touch_adr: np.ndarray,
        tau_ok: np.ndarray,
    ) -> tuple[controller_kernels.StepArguments, controller_kernels.GridArguments] | None:
        """The compiled step's two argument records (built when an input changes), or None where the readable
        path must run (not the "mujoco" backend, another model, arguments the kernel refused)."""
        if self.backend != "mujoco" or model is not self._model:
            return None
        packed = self._step_arguments(data)
        if packed is None:
            return None
        c = self._grid_cache
        if c is None or c[0] is not grid or c[1] is not touch or c[2] is not tau_ok:
            qp = self.distribution == "qp"
            g = controller_kernels.GridArguments(
                grid.t, grid.dt, grid.t_end, grid.packed, grid.masks, touch, touch_adr, tau_ok, qp
            )
            c = self._grid_cache = (grid, touch, tau_ok, g)
        return packed, c[3]

    def _step_arguments(self, data: mujoco.MjData) -> controller_kernels.StepArguments | None:
        """The arguments of ``control_step`` that outlive a step (views and buffers) in one record (None: refused
        by the kernel), rebuilt when an input object changes (the data, the terrain's height field, the gains) and
        after :meth:`set_friction`."""
        hf = getattr(self.terrain, "heightfield", None)
        c = self._step_cache
        if c is not None and c[0] is data and c[1] is hf and c[2] is self._gains:
            return c[3]
        ident = self.id
        qp = ident.distribution == "qp"
        normals = self._step_normals if qp and hasattr(hf, "kernel_args") else None
        hf_args = _NO_TERRAIN if normals is None else hf.kernel_args
        fields = (
            self.foot_of_geom, self.terrain_geom,
            data.qpos, data.qvel, self._gains, self._step_bdd, *self.dynamics.data_views(data)[1:],
            *self._step_terms, data.qfrc_bias, 1.0 / SINGULAR_SIGMA, DAMPING, *ident.workspace,
            *hf_args, self._foot_sites, self._step_sites, ident.up_normals if normals is None else normals,
            ident.mu if qp else 0.0, ident.cone_lower, ident.cone_buffer, ident.qp_solver == "compiled",
            self.torque_limit, self._step_tau,
        )  # fmt: skip
        packed = controller_kernels.StepArguments(*fields)
        self._step_cache = (data, hf, self._gains, packed)
        return packed

    def _settle_grid_step(self) -> None:
        """Turn the last grid step's code into :attr:`last`'s and :attr:`last_reference`'s records."""
        code, t, grid, version = self._grid_step
        self._grid_step = None
        fields = controller_kernels.decode_grid_code(code)
        self._last = WorkspaceResult(fields.status, self._layouts[fields.stance], version, fields.relaxed)
        self._last_reference = PackedReference(t, grid.rows[fields.row], fields.planned)

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
            n = IK.beta_command(qpos, qvel, *args, self._gains, mask, self._bdd)
        except TypeError:  # lists, other dtypes, read-only arrays: convert once
            args = [np.ascontiguousarray(a, dtype=float).reshape(-1) for a in args]
            n = IK.beta_command(qpos, qvel, *args, self._gains, mask, self._bdd)
        if n < 0:
            what = _CMD_INPUTS[-n - 1]
            got = np.shape(qpos if what == "qpos" else qvel if what == "qvel" else getattr(ref, what))
            what = what if what in ("qpos", "qvel") else f"reference field {what}"
            raise ValueError(f"{what} must have {_CMD_SIZES[-n - 1]} entries, got shape {got}")
        return n

    def _normals(self, data: mujoco.MjData, stance: tuple[bool, ...]) -> np.ndarray | None:
        """(4, 3) terrain normals under the feet (world); only stance rows are used by the QP.

        The normal of the surface triangle under each foot site (compiled query): it is
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
