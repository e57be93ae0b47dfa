"""The controller's per-step work in one compiled call: MuJoCo backend, packed reference rows.

:class:`FastControlStep` does what the readable path of
:class:`~agents.control.controller.ComputedTorqueController` does at one physics step (measured
contacts and stance set, PD command, dynamics terms, pinv inverse dynamics, terrain normals) in one
call of :func:`~agents.control.controller_kernels.control_step`, the friction-cone QP included, and
gives the same torques (tested in ``tests/agents/test_control_fast.py``). A QP the compiled solver
gives up on is the readable path's :meth:`InverseDynamics.distribute_qp` (DAQP). Every case the kernel
does not handle (1-2 stance feet, a failed Cholesky, arrays of other types) returns None: the caller
then takes the readable path.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import mujoco
import numpy as np
from numba.core.errors import NumbaError

from agents.control import controller_kernels as FK
from agents.control import inverse_dynamics_kernels as K
from agents.control.elimination import DAMPING, SINGULAR_SIGMA, stance_layout
from agents.control.inverse_dynamics import IDResult, InverseDynamics, WorkspaceResult
from planners.types import PACKED_FIELDS, ReferenceSample
from quad_uneven_env import constants as C

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
    """A reference sample as the fast path received it: a packed row (:data:`PACKED_FIELDS`) and a stance mask."""

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


class FastControlStep:
    """One compiled call per physics step for a controller bound to one model.

    :param dynamics: the controller's "mujoco" backend (its ``data_views``).
    :param inverse_dynamics: the controller's solver: the kernel writes its :attr:`~InverseDynamics.workspace`.
    :param foot_of_geom: (ngeom,) leg of each foot geom, ``N_LEGS`` elsewhere.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        dynamics: Any,
        inverse_dynamics: InverseDynamics,
        foot_of_geom: np.ndarray,
        terrain_geom: int,
        torque_limit: np.ndarray,
    ) -> None:
        self.dynamics = dynamics
        self.id = inverse_dynamics
        self.foot_of_geom = foot_of_geom
        self.terrain_geom = terrain_geom
        self.torque_limit = torque_limit
        self.foot_sites = np.array([model.site(s).id for s in C.FOOT_SITES])
        self.layouts = [stance_layout(tuple(bool(m >> i & 1) for i in range(C.N_LEGS))) for m in range(16)]
        # outputs of the kernel: M, J_feet, Jdot qdot, G; beta_ddot; foot sites; normals
        self._terms = (np.empty((C.NV, C.NV)), np.empty((C.N_LEGS, 3, C.NV)), np.empty((C.N_LEGS, 3)), np.empty(C.NV))
        self._bdd = np.empty(C.NV)
        self._sites = np.empty((C.N_LEGS, 3))
        self._normals = np.empty((C.N_LEGS, 3))
        self._tau = np.empty(C.N_JOINTS)  # the clipped torques
        self._cache: tuple | None = None

    def step(
        self,
        data: mujoco.MjData,
        terrain: Any,
        gains: np.ndarray,
        stance_mode: int,
        row: np.ndarray,
        planned: int,
        measured: int = -1,
    ) -> tuple[np.ndarray, IDResult | WorkspaceResult] | None:
        """Torques (12, N m, clipped) and the solution at ``data`` (after ``mj_step1``), or None (readable path).

        :param gains: (6,) kp/kd of position, rotation and joints (``ComputedTorqueController``'s array).
        :param stance_mode: index into ``STANCE_MODES`` (``controller_kernels.STANCE_*``).
        :param row: (55,) packed reference; ``planned`` its stance bitmask.
        :param measured: bitmask of the feet in contact (bit i: leg i), or -1: from ``data.contact``.
        """
        self.id.workspace_version += 1  # control_step rewrites the inverse-dynamics buffers
        try:
            packed, normals = self.arguments(data, terrain, gains)
            if packed is None:
                return None
            code = FK.packed_control_step(row, planned, stance_mode, contact_pairs(data), measured, packed)
        except (TypeError, NumbaError):  # arrays the kernel does not take (numba dispatch): the readable path,
            # for these inputs from now on: a failed compilation is not retried every step
            self._cache = (data, getattr(terrain, "heightfield", None), gains, None, None)
            return None
        if code < 0 or not (code >> 4) & K.DONE:
            return None
        lay = self.layouts[code & 15]
        status = code >> 4 & 15
        if self.id.distribution == "qp" and lay.n_stance and not code & (FK.INSIDE_CONES | FK.QP_DONE):
            result = self.id.result_from_workspace(status, lay)  # "daqp", or the compiled QP failed
            self.id.distribute_qp(lay, self._terms[1], self.id.workspace.r, result, normals)
            tau = np.empty(C.N_JOINTS)
            K.clip_into(result.tau, self.torque_limit, tau)
            return tau, result
        # the pinv torques, or the QP's (control_step wrote them, and their clipped copy); copied out only if asked
        return self._tau.copy(), WorkspaceResult(status, lay, self.id.workspace_version, bool(code & FK.QP_RELAXED))

    def forget_arguments(self) -> None:
        """Rebuild the kernel's arguments at the next step (after the solver's ``mu`` or ``qp_solver`` changed)."""
        self._cache = None

    def arguments(
        self, data: mujoco.MjData, terrain: Any, gains: np.ndarray
    ) -> tuple[FK.StepArguments | None, np.ndarray | None]:
        """The arguments of ``control_step`` that outlive a step (views and buffers), packed (None: refused by
        the kernel), and the normals buffer (None without "qp" or a height field); rebuilt when an input object
        changes."""
        hf = getattr(terrain, "heightfield", None)
        c = self._cache
        if c is not None and c[0] is data and c[1] is hf and c[2] is gains:
            return c[3], c[4]
        qp = self.id.distribution == "qp"
        normals = self._normals if qp and hasattr(hf, "kernel_args") else None
        hf_args = _NO_TERRAIN if normals is None else hf.kernel_args
        tail = (
            self.foot_of_geom, self.terrain_geom,
            data.qpos, data.qvel, gains, self._bdd, *self.dynamics.data_views(data)[1:],
            *self._terms, data.qfrc_bias, 1.0 / SINGULAR_SIGMA, DAMPING, *self.id.workspace,
            *hf_args, self.foot_sites, self._sites, self.id.up_normals if normals is None else normals,
            self.id.mu if qp else 0.0, self.id.cone_lower, self.id.cone_buffer, self.id.qp_solver == "compiled",
            self.torque_limit, self._tau,
        )  # fmt: skip
        packed = FK.StepArguments(*tail)
        self._cache = (data, hf, gains, packed, normals)
        return packed, normals
