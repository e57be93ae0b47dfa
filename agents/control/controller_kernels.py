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
(:class:`StepArguments`, :class:`GridArguments`): numba unboxes two arguments instead of ~50. :func:`control_step`
(its body) and :func:`grid_control_step` compile on their first call, the others at import, all with the on-disk
cache of :mod:`quad_uneven_env.jit`.
"""

from __future__ import annotations

import numba as nb
from numba.core import types
from numba.experimental import structref

from agents.control import inverse_dynamics_kernels as K
from agents.control import qp_kernels as QK
from planners.reference_kernels import grid_index
from quad_uneven_env.jit import njit
from quad_uneven_env.robot.dynamics import mujoco_kernels as DK
from quad_uneven_env.terrain.heightfield_kernels import normals_into

INSIDE_CONES = 1 << 16
"""bit of :func:`control_step`'s result: the pinv forces lie in every stance friction pyramid."""
QP_DONE, QP_RELAXED = 1 << 17, 1 << 18
"""bits of :func:`control_step`'s result: the "qp" distribution was applied (the workspace's tau and F are
its solution), and it was the relaxed problem's (``InverseDynamics._relax``)."""

STANCE_BOTH, STANCE_PLANNED, STANCE_MEASURED = 0, 1, 2
"""``stance_mode`` codes of :func:`control_step` (``ComputedTorqueController.stance_mode``)."""


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


@njit(nogil=True)
def control_step(
    row, planned, stance_mode, contact_geom, foot_of_geom, terrain_geom, measured,
    qpos, qvel, gains, bdd,
    M_csr, rowadr, rownnz, colind, xpos, xmat, xanchor, xaxis, site_xpos, subtree_com, idx, par,
    M, J, Jdd, G, h, inv_sigma, damping, tau, F, qacc, r, Jinv, S,
    hf_flat, nrow, ncol, ox, oy, inv_cell, foot_sites, site_pos, normals,
    mu, cone_lower, cones, compiled_qp,
):  # fmt: skip  # pragma: no cover - compiled
    """Stance, PD command, dynamics terms, pinv inverse dynamics and foot normals at one physics step.

    Inputs as the kernels it calls: ``row`` a packed reference (55,), ``planned`` its stance
    bitmask, ``stance_mode`` a ``STANCE_*`` code; ``measured`` the bitmask of feet in contact, or -1
    to read it from the contact list ``contact_geom``; MuJoCo arrays after ``mj_step1``; ``tau, F,
    qacc, r, Jinv, S`` the inverse-dynamics outputs; ``normals`` (4, 3) is written when
    ``hf_flat`` is not empty (else it must hold the normals to use, e.g. +z). With ``mu > 0`` ("qp")
    the pinv forces are also checked against the stance legs' friction pyramids (written into
    ``cones``, (4, 5, 3)) with the lower bounds ``cone_lower`` (5,), as
    :func:`agents.control.inverse_dynamics_kernels.qp_fill` does: inside, they are the "qp" optimum;
    outside, with ``compiled_qp``, :func:`agents.control.qp_kernels.distribute_qp` replaces ``tau`` and ``F``
    by the QP's. Returns
    ``stance_mask | status << 4 | n_beta << 8`` with ``status`` the bits of
    :func:`agents.control.inverse_dynamics_kernels.id_pinv`, or-ed with ``INSIDE_CONES``, or ``QP_DONE``
    (and ``QP_RELAXED``); "qp" with neither bit: the QP is left to the caller (DAQP). A negative
    value when an input has the wrong size (the caller then takes the general path, which names it).
    """
    meas = K.foot_contact_mask(contact_geom, foot_of_geom, terrain_geom) if measured < 0 else measured
    mask = select_stance_mask(planned, meas, stance_mode)
    n_beta = K.beta_command(
        qpos, qvel, row[0:3], row[3:7], row[7:10], row[10:13], row[13:16], row[16:19],
        row[19:31], row[31:43], row[43:55], gains, mask, bdd,
    )  # fmt: skip
    if n_beta < 0 or row.shape[0] != 55:
        return -1
    DK.mujoco_terms(qvel, M_csr, rowadr, rownnz, colind, xpos, xmat, xanchor, xaxis, site_xpos, subtree_com, idx, par,
                    M, J, Jdd, G)  # fmt: skip
    status = K.id_pinv(M, h, J, Jdd, mask, bdd[:n_beta], inv_sigma, damping, tau, F, qacc, r, Jinv, S)
    if status < 0:
        return -1
    if hf_flat.shape[0] > 0:
        for i in range(foot_sites.shape[0]):
            for k in range(3):
                site_pos[i, k] = site_xpos[foot_sites[i], k]
        normals_into(hf_flat, nrow, ncol, ox, oy, inv_cell, site_pos, normals)
    code = mask | status << 4 | n_beta << 8
    if mu > 0.0 and status > 0 and mask != 0:
        K.stance_pyramids_into(normals, mask, mu, cones)
        inside = True
        k = 0
        for leg in range(4):
            if not (mask >> leg) & 1:
                continue
            for a in range(5):
                s = cones[k, a, 0] * F[leg, 0] + cones[k, a, 1] * F[leg, 1] + cones[k, a, 2] * F[leg, 2]
                if s < cone_lower[a]:
                    inside = False
            k += 1
        if inside:
            return code | INSIDE_CONES
        if not compiled_qp:
            return code
        qp = QK.distribute_qp(normals, mu, J, mask, r, cone_lower, tau, F, cones)
        if qp == QK.QP_OPTIMAL:
            return code | QP_DONE
        if qp == QK.QP_RELAXED:
            return code | QP_DONE | QP_RELAXED
    return code


STEP_FIELDS: tuple[str, ...] = (
    "foot_of_geom", "terrain_geom",
    "qpos", "qvel", "gains", "bdd",
    "M_csr", "rowadr", "rownnz", "colind", "xpos", "xmat", "xanchor", "xaxis", "site_xpos", "subtree_com", "idx", "par",
    "M", "J", "Jdd", "G", "h", "inv_sigma", "damping", "tau", "F", "qacc", "r", "Jinv", "S",
    "hf_flat", "nrow", "ncol", "ox", "oy", "inv_cell", "foot_sites", "site_pos", "normals",
    "mu", "cone_lower", "cones", "compiled_qp", "torque_limit", "tau_out",
)  # fmt: skip
"""The fields of :class:`StepArguments`: :func:`control_step`'s arguments that outlive a step (in its order),
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


GRID_PLANNED_SHIFT, GRID_ROW_SHIFT = 20, 24
"""bit offsets in :func:`grid_control_step`'s result of the planned stance bitmask and of the grid row's index."""

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


OFF_PLAN = -2
""":func:`grid_control_step`'s result when the base is off its plan (the caller's readable path replans)."""


@njit(nogil=True)
def grid_control_step(  # pragma: no cover - compiled
    t, position_tol2, velocity_tol2, stance_mode, contact_geom, measured, a, g, limit, out
):
    """The control step at the row of ``g``'s grid at plan time ``t`` (s), with the step's arguments in ``a`` (a
    :class:`StepArguments`); the torques, clipped to the motor limits (``a.torque_limit``), in ``g.tau_ok`` and,
    clipped to ``±limit`` (N m), in ``out``.

    The row is the one :meth:`planners.reference.Reference.row` returns (:func:`grid_index`). With
    ``position_tol2 >= 0`` the disturbance check comes first (``ExpertConfig.recovery``): if the base's horizontal
    position (m) or velocity (m/s) is farther than the tolerances' square roots from the row's, nothing is written
    and :data:`OFF_PLAN` is returned. The step is taken only if every planned stance foot's touch sensor reads > 0
    (else the caller pushes the late foot down on the readable path). ``measured`` as in :func:`control_step`.

    Returns -1 where the caller must take its readable path, writing nothing but the inverse-dynamics buffers: no
    grid row, a planned foot not touching, a step :func:`control_step` did not solve, a "qp" step whose QP it left
    to DAQP (``g.qp``, stance feet, neither ``INSIDE_CONES`` nor ``QP_DONE``), or non-finite torques. Otherwise
    :func:`control_step`'s code or-ed with ``planned << GRID_PLANNED_SHIFT | row << GRID_ROW_SHIFT``.
    """
    k = grid_index(t, g.grid_t, g.grid_dt, g.t_end)
    if k < 0:
        return -1
    row = g.rows[k]
    if position_tol2 >= 0.0:
        qpos, qvel = a.qpos, a.qvel
        dv = (qvel[0] - row[7]) ** 2 + (qvel[1] - row[8]) ** 2
        dp = (qpos[0] - row[0]) ** 2 + (qpos[1] - row[1]) ** 2
        if not (dv <= velocity_tol2 and dp <= position_tol2):
            return OFF_PLAN
    planned = g.masks[k]
    for leg in range(4):
        if (planned >> leg) & 1 and g.touch[g.touch_adr[leg]] <= 0:
            return -1
    code = control_step(
        row, planned, stance_mode, contact_geom, a.foot_of_geom, a.terrain_geom, measured,
        a.qpos, a.qvel, a.gains, a.bdd,
        a.M_csr, a.rowadr, a.rownnz, a.colind, a.xpos, a.xmat, a.xanchor, a.xaxis, a.site_xpos, a.subtree_com,
        a.idx, a.par, a.M, a.J, a.Jdd, a.G, a.h, a.inv_sigma, a.damping, a.tau, a.F, a.qacc, a.r, a.Jinv, a.S,
        a.hf_flat, a.nrow, a.ncol, a.ox, a.oy, a.inv_cell, a.foot_sites, a.site_pos, a.normals,
        a.mu, a.cone_lower, a.cones, a.compiled_qp,
    )  # fmt: skip
    if code < 0 or not (code >> 4) & K.DONE:
        return -1
    if g.qp and code & 15 and not code & (INSIDE_CONES | QP_DONE):
        return -1
    K.clip_into(a.tau, a.torque_limit, a.tau_out)
    if not K.copy_if_finite(a.tau_out, g.tau_ok):
        return -1
    K.clip_into(g.tau_ok, limit, out)
    return code | planned << GRID_PLANNED_SHIFT | k << GRID_ROW_SHIFT
