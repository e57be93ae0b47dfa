"""The controller's per-step work on the MuJoCo backend in one compiled call (the expert's hot path).

:func:`grid_control_step` does in one numba call what
:meth:`agents.control.controller.ComputedTorqueController.__call__` (the readable reference) does in a dozen Python
calls, for a reference planned on a grid (:class:`planners.types.ReferenceGrid`): the row lookup at the plan time,
the check that every planned stance foot touches, the measured foot contacts and the stance set, the PD command
from the packed row (:data:`planners.types.PACKED_FIELDS`), the dynamics terms from ``mj_step1``'s results, the
pinv inverse dynamics, the terrain normals under the feet, the "qp" distribution when the pinv forces leave a
friction cone, the motor limits and a finite check. It calls the same kernels as the readable path
(:mod:`agents.control.inverse_dynamics_kernels`, :mod:`agents.control.qp_kernels`,
:mod:`quad_uneven_env.robot.dynamics.mujoco_kernels`, the height field's normal kernel), so the two give the same
torques (tested); every rare case (1-2 stance feet, a failed Cholesky, a QP the compiled solver gives up on, a late
touch-down) declines to the readable path. The arguments that outlive a step travel in two records
(:class:`StepArguments`, :class:`GridArguments`): numba unboxes two arguments instead of ~50. The result is one
int (:func:`control_step`'s code, :func:`grid_control_step`'s grid code) whose fields are named by the ``*_SHIFT``
and flag constants below and read back by :func:`decode_grid_code`. :func:`control_step` (its body) and
:func:`grid_control_step` compile on their first call, the others at import, all with the on-disk cache of
:mod:`quad_uneven_env.jit`.
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
from numba.core import types
from numba.experimental import structref

from agents.control import inverse_dynamics_kernels as IK
from agents.control import qp_kernels as QK
from planners.reference_kernels import grid_index
from quad_uneven_env.jit import njit
from quad_uneven_env.robot.dynamics import mujoco_kernels as DK
from quad_uneven_env.terrain.heightfield_kernels import normals_into

FIELD_MASK = 15
"""a 4-bit field of a result code (a stance bitmask, bit i: leg i; or ``id_pinv``'s status bits)."""
STATUS_SHIFT, N_BETA_SHIFT = 4, 8
"""bit offsets in :func:`control_step`'s code of the ``id_pinv`` status bits and of ``n_beta`` (the stance bitmask
is at bit 0)."""
INSIDE_CONES = 1 << 16
"""flag of :func:`control_step`'s code: the pinv forces lie in every stance friction pyramid."""
QP_DONE, QP_RELAXED = 1 << 17, 1 << 18
"""flags of :func:`control_step`'s code: the "qp" distribution was applied (the workspace's tau and F are
its solution), and it was the relaxed problem's (``InverseDynamics._relax``)."""
GRID_PLANNED_SHIFT, GRID_ROW_SHIFT = 20, 24
"""bit offsets in :func:`grid_control_step`'s code of the planned stance bitmask and of the grid row's index."""

STANCE_BOTH, STANCE_PLANNED, STANCE_MEASURED = 0, 1, 2
"""``stance_mode`` codes of :func:`control_step` (``ComputedTorqueController.stance_mode``)."""


class GridCode(NamedTuple):
    """The fields of :func:`grid_control_step`'s code."""

    stance: int
    """the stance bitmask solved for (bit i: leg i)."""
    status: int
    """:func:`~agents.control.inverse_dynamics_kernels.id_pinv`'s status bits."""
    relaxed: bool
    """the "qp" solution is the relaxed problem's (:data:`QP_RELAXED`)."""
    planned: int
    """the grid row's planned stance bitmask."""
    row: int
    """the grid row's index."""


def decode_grid_code(code: int) -> GridCode:
    """The fields of a code :func:`grid_control_step` returned (>= 0)."""
    return GridCode(
        code & FIELD_MASK,
        code >> STATUS_SHIFT & FIELD_MASK,
        bool(code & QP_RELAXED),
        code >> GRID_PLANNED_SHIFT & FIELD_MASK,
        code >> GRID_ROW_SHIFT,
    )


@njit(nb.int64(nb.int64), nogil=True)
def _popcount4(mask):  # pragma: no cover - compiled
    return (mask & 1) + (mask >> 1 & 1) + (mask >> 2 & 1) + (mask >> 3 & 1)


@njit(nb.int64(nb.int64, nb.int64, nb.int64), nogil=True)
def select_stance_mask(planned, measured, mode):  # pragma: no cover - compiled
    """Stance bitmask from the planned and measured ones (``ComputedTorqueController.select_stance``)."""
    if mode == STANCE_PLANNED:
        return planned
    if mode == STANCE_MEASURED:
        return measured
    chosen = planned & measured
    if _popcount4(chosen) < min(3, _popcount4(planned)):
        return planned
    return chosen


STEP_FIELDS: tuple[str, ...] = (
    "foot_of_geom", "terrain_geom",
    "qpos", "qvel", "gains", "bdd",
    "M_csr", "rowadr", "rownnz", "colind", "xpos", "xmat", "xanchor", "xaxis", "site_xpos", "subtree_com", "idx", "par",
    "M", "J", "Jdd", "G", "h", "inv_sigma", "damping", "tau", "F", "qacc", "r", "Jinv", "S",
    "hf_flat", "nrow", "ncol", "ox", "oy", "inv_cell", "foot_sites", "site_pos", "normals",
    "mu", "cone_lower", "cones", "compiled_qp", "torque_limit", "tau_out",
)  # fmt: skip
"""The fields of :class:`StepArguments`, the inputs and buffers of :func:`control_step` that outlive a step: the
foot lookup (``foot_lookup``) and the terrain geom; MuJoCo's arrays after ``mj_step1`` (``qpos, qvel``, the
sparse mass matrix and the frames :func:`~quad_uneven_env.robot.dynamics.mujoco_kernels.mujoco_terms` reads), the
PD gains and the command buffer ``bdd``; the dynamics terms ``M, J, Jdd, G, h``; the pinv settings and its outputs
``tau, F, qacc, r, Jinv, S``; the height field (``hf_flat`` empty: no normals), the foot sites and the normals
buffer (4, 3) (written when ``hf_flat`` is not empty, else the normals to use, e.g. +z); the "qp" friction ``mu``
(0: "pinv"), the cone rows' lower bounds (5,) and buffer (4, 5, 3), whether the QP is solved in compiled code;
then the motor limits and the buffer of the clipped torques (:func:`grid_control_step`)."""


@structref.register
class _StepArgumentsType(types.StructRef):
    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


class StepArguments(structref.StructRefProxy):
    """:data:`STEP_FIELDS` in one compiled record: one argument to unbox per call instead of ~45
    (numba's per-call dispatch and unboxing of every array argument costs ~70 ns each)."""

    def __new__(cls, *args):
        return _new_step_arguments(*args)


structref.define_proxy(StepArguments, _StepArgumentsType, list(STEP_FIELDS))


@njit()
def _new_step_arguments(*args):  # pragma: no cover - compiled
    """The record's constructor, compiled with the on-disk cache (numba's own proxy constructor is not cached)."""
    return StepArguments(*args)


@njit(nogil=True)
def control_step(row, planned, stance_mode, contact_geom, measured, a):  # pragma: no cover - compiled
    """Stance, PD command, dynamics terms, pinv inverse dynamics and foot normals at one physics step.

    ``row`` is a packed reference (55,), ``planned`` its stance bitmask, ``stance_mode`` a ``STANCE_*`` code;
    ``measured`` the bitmask of feet in contact, or -1 to read it from the contact list ``contact_geom``; ``a`` the
    step's inputs and buffers (:class:`StepArguments`). With ``a.mu > 0`` ("qp") the pinv forces are also checked
    against the stance legs' friction pyramids (written into ``a.cones``) with the lower bounds ``a.cone_lower``,
    as :func:`agents.control.inverse_dynamics_kernels.qp_fill` does: inside, they are the "qp" optimum; outside,
    with ``a.compiled_qp``, :func:`agents.control.qp_kernels.distribute_qp` replaces ``a.tau`` and ``a.F`` by the
    QP's. Returns the code ``stance_mask | status << STATUS_SHIFT | n_beta << N_BETA_SHIFT`` with ``status`` the
    bits of :func:`agents.control.inverse_dynamics_kernels.id_pinv`, or-ed with :data:`INSIDE_CONES`, or
    :data:`QP_DONE` (and :data:`QP_RELAXED`); "qp" with neither flag: the QP is left to the caller (DAQP). A
    negative value when an input has the wrong size (the caller then takes the general path, which names it).
    """
    meas = IK.foot_contact_mask(contact_geom, a.foot_of_geom, a.terrain_geom) if measured < 0 else measured
    mask = select_stance_mask(planned, meas, stance_mode)
    bdd = a.bdd
    n_beta = IK.beta_command(
        a.qpos, a.qvel, row[0:3], row[3:7], row[7:10], row[10:13], row[13:16], row[16:19],
        row[19:31], row[31:43], row[43:55], a.gains, mask, bdd,
    )  # fmt: skip
    if n_beta < 0 or row.shape[0] != 55:
        return -1
    M, J, Jdd, F, normals, cones = a.M, a.J, a.Jdd, a.F, a.normals, a.cones
    DK.mujoco_terms(
        a.qvel, a.M_csr, a.rowadr, a.rownnz, a.colind, a.xpos, a.xmat, a.xanchor, a.xaxis, a.site_xpos,
        a.subtree_com, a.idx, a.par, M, J, Jdd, a.G,
    )  # fmt: skip
    status = IK.id_pinv(M, a.h, J, Jdd, mask, bdd[:n_beta], a.inv_sigma, a.damping, a.tau, F, a.qacc, a.r, a.Jinv, a.S)
    if status < 0:
        return -1
    if a.hf_flat.shape[0] > 0:
        site_pos, foot_sites, site_xpos = a.site_pos, a.foot_sites, a.site_xpos
        for i in range(foot_sites.shape[0]):
            for k in range(3):
                site_pos[i, k] = site_xpos[foot_sites[i], k]
        normals_into(a.hf_flat, a.nrow, a.ncol, a.ox, a.oy, a.inv_cell, site_pos, normals)
    code = mask | status << STATUS_SHIFT | n_beta << N_BETA_SHIFT
    mu = a.mu
    if mu > 0.0 and status > 0 and mask != 0:
        IK.stance_pyramids_into(normals, mask, mu, cones)
        cone_lower = a.cone_lower
        inside = True
        k = 0
        for leg in range(4):
            if not (mask >> leg) & 1:
                continue
            for c in range(5):
                s = cones[k, c, 0] * F[leg, 0] + cones[k, c, 1] * F[leg, 1] + cones[k, c, 2] * F[leg, 2]
                if s < cone_lower[c]:
                    inside = False
            k += 1
        if inside:
            return code | INSIDE_CONES
        if not a.compiled_qp:
            return code
        qp = QK.distribute_qp(normals, mu, J, mask, a.r, cone_lower, a.tau, F, cones)
        if qp == QK.QP_OPTIMAL:
            return code | QP_DONE
        if qp == QK.QP_RELAXED:
            return code | QP_DONE | QP_RELAXED
    return code


GRID_FIELDS: tuple[str, ...] = ("grid_t", "grid_dt", "t_end", "rows", "masks", "touch", "touch_adr", "tau_ok", "qp")
"""The fields of :class:`GridArguments`: a plan's :class:`planners.types.ReferenceGrid` (``t, dt, t_end, packed,
masks``), the simulator's touch sensors (``sensordata``) and the four feet's addresses in it, the buffer of the
last finite torques, and whether the distribution is "qp"."""


@structref.register
class _GridArgumentsType(types.StructRef):
    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


class GridArguments(structref.StructRefProxy):
    """:data:`GRID_FIELDS` in one compiled record (one per plan and simulator data)."""

    def __new__(cls, *args):
        return _new_grid_arguments(*args)


structref.define_proxy(GridArguments, _GridArgumentsType, list(GRID_FIELDS))


@njit()
def _new_grid_arguments(*args):  # pragma: no cover - compiled
    """The record's constructor, compiled with the on-disk cache (numba's own proxy constructor is not cached)."""
    return GridArguments(*args)


@njit(nogil=True)
def grid_control_step(t, stance_mode, contact_geom, measured, a, g, limit, out):  # pragma: no cover - compiled
    """The control step at the row of ``g``'s grid at plan time ``t`` (s), with the step's arguments in ``a`` (a
    :class:`StepArguments`); the torques, clipped to the motor limits (``a.torque_limit``), in ``g.tau_ok`` and,
    clipped to ``±limit`` (N m), in ``out``.

    The row is the one :meth:`planners.reference.Reference.row` returns (:func:`grid_index`). The step is taken
    only if every planned stance foot's touch sensor reads > 0 (else the caller pushes the late foot down on the
    readable path). ``measured`` as in :func:`control_step`.

    Returns -1 where the caller must take its readable path, writing nothing but the inverse-dynamics buffers: no
    grid row, a planned foot not touching, a step :func:`control_step` did not solve, a "qp" step whose QP it left
    to DAQP (``g.qp``, stance feet, neither :data:`INSIDE_CONES` nor :data:`QP_DONE`), or non-finite torques.
    Otherwise :func:`control_step`'s code or-ed with ``planned << GRID_PLANNED_SHIFT | row << GRID_ROW_SHIFT``
    (:func:`decode_grid_code`).
    """
    k = grid_index(t, g.grid_t, g.grid_dt, g.t_end)
    if k < 0:
        return -1
    planned = g.masks[k]
    for leg in range(4):
        if (planned >> leg) & 1 and g.touch[g.touch_adr[leg]] <= 0:
            return -1
    code = control_step(g.rows[k], planned, stance_mode, contact_geom, measured, a)
    if code < 0 or not (code >> STATUS_SHIFT) & IK.DONE:
        return -1
    if g.qp and code & FIELD_MASK and not code & (INSIDE_CONES | QP_DONE):
        return -1
    IK.clip_into(a.tau, a.torque_limit, a.tau_out)
    if not IK.copy_if_finite(a.tau_out, g.tau_ok):
        return -1
    IK.clip_into(g.tau_ok, limit, out)
    return code | planned << GRID_PLANNED_SHIFT | k << GRID_ROW_SHIFT
