"""The env's physics loop: one control step as ``frame_skip`` MuJoCo steps, undone whole if it fails.

:class:`PhysicsStepper` runs the substeps under the action's command (:class:`~quad_uneven_env.actuation.ActionMap`)
or under a physics-rate controller (:class:`PhysicsController`, one entry point per physics step: its optional
fast lane ``torques_into``, else its call), with the randomized world's actuation latency (a ring of commands) and
pushes on the trunk (:class:`~quad_uneven_env.randomization.PushSchedule`). A step that fails (a controller error
or a malformed return, MuJoCo's bad-qpos/qvel/qacc warnings or its errors) is rolled back: the simulation state,
time included, and the latency buffers are those of the start of the control step again, and the failure is
returned as a reason string, never raised.
"""

from __future__ import annotations

from typing import Any, Protocol

import mujoco
import numpy as np

from quad_uneven_env import constants as C
from quad_uneven_env.actuation import ActionMap
from quad_uneven_env.fields import excerpt
from quad_uneven_env.measurement_kernels import clip_finite_into
from quad_uneven_env.physics import BAD_WARNINGS, RobotIndex, instability_warnings
from quad_uneven_env.randomization import Push, PushSchedule, RandomizationConfig

_STATE = mujoco.mjtState.mjSTATE_INTEGRATION
"""What a failed control step restores: time, qpos, qvel, act, warm start, ctrl, applied forces, ..."""


class PhysicsController(Protocol):
    """A controller run at physics rate inside :meth:`QuadUnevenEnv.step <quad_uneven_env.env.QuadUnevenEnv.step>`.

    Called after ``mujoco.mj_step1`` (so ``data`` holds kinematics, the mass matrix,
    ``qfrc_bias`` and contacts of the current state) and before ``mujoco.mj_step2``; returns
    the 12 joint torques (N m, ``JOINT_NAMES`` order), which the env clips to the motor limits.
    An exception it raises, or a return that is not 12 finite numbers, ends the episode as diverged
    (the control step is undone). It needs ``action_mode="torque"``. An optional
    ``reset(model, data, terrain)`` method is called at the end of every reset.

    An optional fast lane ``torques_into(model, data, action, out, limit) -> bool``, tried first at every physics
    step: True when it wrote exactly the torques the call would return, clipped to ``±limit`` (N m), into
    ``out``; False (nothing written) to have the env make the call. It saves the call's Python where a
    controller can do the whole step in compiled code; an exception it raises counts as False.
    """

    def __call__(self, model: mujoco.MjModel, data: mujoco.MjData, action: np.ndarray) -> np.ndarray: ...


def check_controller(controller: Any, action_mode: str) -> None:
    """:raises ValueError: unless ``controller`` is None or a :class:`PhysicsController` for ``action_mode``."""
    if controller is None:
        return
    if not callable(controller):
        raise ValueError(
            f"controller must be None or a callable (model, data, action) -> 12 torques (N m), "
            f"got {excerpt(controller)} of type {type(controller).__name__}"
        )
    for hook in ("reset", "torques_into"):
        if hasattr(controller, hook) and not callable(getattr(controller, hook)):
            raise ValueError(
                f"controller.{hook} must be a method (see PhysicsController), got "
                f"{excerpt(getattr(controller, hook))} of type {type(getattr(controller, hook)).__name__}"
            )
    if action_mode != "torque":
        raise ValueError(
            f"controller must be None with action_mode={excerpt(action_mode)}: a physics-rate controller "
            "returns torques, which would drive the position servos as targets; use action_mode='torque'"
        )


class PhysicsStepper:
    """Advances ``model``/``data`` by one control step of ``frame_skip`` physics steps (see the module docstring).

    :param model: the env's compiled model. :param data: its data.
    :param idx: the model's resolved robot ids (trunk body, torque limits).
    :param frame_skip: physics steps per control step.
    :param actions: the action-to-command map (used without a controller).
    :param randomization: the env's randomization (its pushes), or None.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        data: mujoco.MjData,
        idx: RobotIndex,
        frame_skip: int,
        actions: ActionMap,
        randomization: RandomizationConfig | None,
    ) -> None:
        self.model, self.data, self.idx = model, data, idx
        self.frame_skip = frame_skip
        self.actions = actions
        self.controller: PhysicsController | None = None
        """the physics-rate controller (None: the action's command is applied)."""
        self.push_schedule = PushSchedule(randomization, float(model.opt.timestep))
        self.push_force = np.zeros(3)
        """(3,) N, world: the mean push on the trunk over the last control step."""
        self._saved_state = np.empty(mujoco.mj_stateSize(model, _STATE))
        self._cmd = np.zeros(C.N_JOINTS)
        self._ctrl_prev = np.zeros(C.N_JOINTS)
        self._ctrl_ring = np.zeros((1, C.N_JOINTS))
        self._latency = 0
        self._physics_step = 0
        self._rng: np.random.Generator | None = None
        self._warnings_at_reset = 0
        self._bind_data_views()

    def _bind_data_views(self) -> None:
        """Views of ``data``'s warning counters, read every physics step (MuJoCo never reallocates them)."""
        self._warning_counts = self.data.warning.number  # live view of MuJoCo's warning counters
        # the same counters as Python ints at a fraction of numpy's indexing cost (read every physics step)
        self._warning_view = memoryview(self._warning_counts)

    def __getstate__(self) -> dict[str, Any]:
        """Pickle and ``copy.deepcopy``: everything but the views of ``data`` (rebound to the copy's own)."""
        return {k: v for k, v in self.__dict__.items() if k not in ("_warning_counts", "_warning_view")}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._bind_data_views()

    @property
    def pushes(self) -> list[Push]:
        """The pushes started so far this episode."""
        return self.push_schedule.pushes

    def reset(self, latency_steps: int, rng: np.random.Generator | None) -> None:
        """Start an episode from the state in ``data`` (after ``mj_forward``).

        :param latency_steps: physics steps between a command and its application (the episode's draw).
        :param rng: the world's generator, drawing the pushes (None without randomization).
        """
        k = self._latency = latency_steps
        self._ctrl_ring = np.repeat(self.data.ctrl[None, :], k + 1, axis=0)
        self._ctrl_prev[:] = self.data.ctrl
        self._physics_step = 0
        self.push_force[:] = 0.0
        self._rng = rng
        self.push_schedule.reset(rng)
        self._warnings_at_reset = instability_warnings(self._warning_counts)

    def step(self, a: np.ndarray) -> str | None:
        """``frame_skip`` physics steps under the clipped action ``a`` (read-only, (12,)); the failure reason, or
        None. A failed step is undone (the state is that of the start of the step again)."""
        mujoco.mj_getState(self.model, self.data, self._saved_state, _STATE)
        delayed = (self._ctrl_ring.copy(), self._ctrl_prev.copy()) if self._latency else None
        try:
            reason = self._advance(a)
        except Exception as err:  # MuJoCo's own errors (mujoco.FatalError), raised from inside its step
            reason = f"diverged: MuJoCo failed ({type(err).__name__}: {err})"
        except BaseException:  # Ctrl-C and the like still propagate, from a whole-step state
            self._roll_back(delayed)
            raise
        # MuJoCo's own checks (mj_checkPos/Vel/Acc) flag NaN, Inf and huge values in qpos, qvel
        # and qacc; with auto-reset disabled the bad state stays for us to see.
        if reason is None and instability_warnings(self._warning_counts) > self._warnings_at_reset:
            reason = "diverged: MuJoCo reported a bad (NaN, Inf or huge) qpos/qvel/qacc"
        if reason is not None:
            self._roll_back(delayed)  # a failed control step is undone: the state is the last good one again
        else:
            self._physics_step += self.frame_skip
        return reason

    def _roll_back(self, delayed: tuple[np.ndarray, np.ndarray] | None) -> None:
        """Put the simulation back to the state saved at the start of the control step (and recompute its
        derived quantities: positions, contacts, sensors); ``delayed``: the latency buffers saved with it.

        The push schedule's draw of the failed step is not undone (the episode ends there)."""
        mujoco.mj_setState(self.model, self.data, self._saved_state, _STATE)
        if delayed is not None:
            self._ctrl_ring[:], self._ctrl_prev[:] = delayed
        try:
            mujoco.mj_forward(self.model, self.data)
        except Exception:  # the episode is over: a state MuJoCo cannot evaluate stays as restored
            pass

    def _advance(self, a: np.ndarray) -> str | None:
        """The control step's physics steps; the failure reason, or None.

        With a controller the loop stops at the first failure (the caller undoes the step). Pushes and latency go
        through :meth:`_step_controller` / :meth:`_step_open_loop`; the nominal open-loop step is one ``mj_step``
        call.
        """
        segments = self._push_segments()
        if self.controller is not None:
            return self._step_controller(a, segments)
        if segments is None and self._latency == 0:
            self.actions.ctrl_into(a, self.data.ctrl)
            mujoco.mj_step(self.model, self.data, self.frame_skip)
        else:
            self._step_open_loop(a, segments)
        return None

    def _step_controller(self, a: np.ndarray, segments: list | None) -> str | None:
        """``frame_skip`` physics steps under the physics-rate controller; the failure reason, or None.

        With latency k > 0 the torque the controller returns at physics step n is applied at step n + k
        (a ring of k + 1 commands); pushes set the trunk's ``xfrc_applied`` per step.
        """
        m, d = self.model, self.data
        ctrl = d.ctrl
        k, ring, n = self._latency, self._ctrl_ring, self._physics_step
        forces = None if segments is None else [f for length, f in segments for _ in range(length)]
        lane, limit = getattr(self.controller, "torques_into", None), self.idx.torque_limit
        counts, at_reset = self._warning_view, self._warnings_at_reset
        w0, w1, w2 = BAD_WARNINGS
        step1, step2 = mujoco.mj_step1, mujoco.mj_step2
        for j in range(self.frame_skip):
            if forces is not None and (j == 0 or forces[j] is not forces[j - 1]):
                self._set_push(forces[j])
            step1(m, d)
            if counts[w0] + counts[w1] + counts[w2] > at_reset:  # instability_warnings(data)
                return None  # reported by the caller; the controller must not see a garbage state
            out = ctrl if k == 0 else ring[(n + j) % (k + 1)]
            try:
                fast = lane is not None and lane(m, d, a, out, limit)
            except Exception:  # the lane declines; the call below decides
                fast = False
            if type(fast) is not bool:
                if not isinstance(fast, np.bool_):
                    return f"diverged: controller's torques_into returned {_describe(fast)}, not True or False"
                fast = bool(fast)
            if fast:
                if not clip_finite_into(out, limit, out):  # the lane's torques pass the call's checks too
                    bad = np.flatnonzero(~np.isfinite(out)).tolist()
                    return f"diverged: controller's torques_into wrote non-finite torques (NaN/Inf at indices {bad})"
            else:
                reason = self._controller_torques_into(a, out)
                if reason is not None:
                    return reason
            if k:
                ctrl[:] = ring[(n + j + 1) % (k + 1)]  # the command of k steps ago
            step2(m, d)  # a bad qacc here is caught by the next check (or the caller's)
        return None

    def _controller_torques_into(self, a: np.ndarray, out: np.ndarray) -> str | None:
        """Call the controller on the current (``mj_step1``) state and write its torques, clipped to the motor
        limits, into ``out``; the failure reason, or None.

        A failure is any exception the controller raises and any return that is not 12 finite numbers
        (a string, a mapping, None, a wrong shape, NaN/Inf).
        """
        try:
            raw = self.controller(self.model, self.data, a)
        except Exception as err:  # any controller error ends the episode; it never escapes step()
            return f"diverged: controller raised {type(err).__name__}: {err}"
        tau = raw if type(raw) is np.ndarray and raw.dtype == np.float64 else _as_float_array(raw)
        if tau is None or tau.shape != (C.N_JOINTS,):
            return f"diverged: controller returned {_describe(raw)}, not {C.N_JOINTS} finite torques (N m)"
        if not clip_finite_into(tau, self.idx.torque_limit, out):
            bad = np.flatnonzero(~np.isfinite(tau)).tolist()
            return f"diverged: controller returned non-finite torques (NaN/Inf at indices {bad})"
        return None

    def _step_open_loop(self, a: np.ndarray, segments: list | None) -> None:
        """``frame_skip`` physics steps under action ``a`` with latency and/or pushes, as runs of ``mj_step``.

        The command is constant over the control step, so latency k means: the previous command for the
        first k physics steps, then this one; pushes split the runs where their force starts or stops.
        """
        m, d, cmd = self.model, self.data, self._cmd
        self.actions.ctrl_into(a, cmd)
        k = self._latency
        runs = [(self.frame_skip, None)] if segments is None else segments
        j = 0
        for length, force in runs:
            self._set_push(force)
            for start, stop in ((j, min(j + length, k)), (max(j, k), j + length)):
                if stop > start:
                    d.ctrl[:] = self._ctrl_prev if start < k else cmd
                    mujoco.mj_step(m, d, stop - start)
            j += length
        self._ctrl_prev[:] = cmd

    def _push_segments(self) -> list | None:
        """This control step's push runs (see :meth:`PushSchedule.segments`), with their mean force in
        :attr:`push_force`; None without pushes."""
        if not self.push_schedule.on:
            return None
        segments = self.push_schedule.segments(self._rng, self._physics_step, self.frame_skip)
        mean = self.push_force
        mean[:] = 0.0
        for length, force in segments:
            if force is not None:
                mean += force * (length / self.frame_skip)
        return segments

    def _set_push(self, force: np.ndarray | None) -> None:
        """Push force (N, world) on the trunk's centre of mass, zero for None."""
        f = self.data.xfrc_applied[self.idx.trunk_body, :3]
        if force is None:
            f[:] = 0.0
        else:
            f[:] = force


def _as_float_array(raw: Any) -> np.ndarray | None:
    """``raw`` as a float64 array if it holds plain numbers (not bools, strings or objects), else None."""
    try:
        arr = np.asarray(raw)
    except Exception:  # ragged sequences, objects whose __array__ fails
        return None
    if arr.dtype.kind not in "iuf":
        return None
    return arr.astype(np.float64)


def _describe(raw: Any) -> str:
    """A short description of a malformed controller return, for the failure reason."""
    if isinstance(raw, np.ndarray):
        return f"an array of shape {raw.shape} and dtype {raw.dtype}"
    return f"{excerpt(raw)} of type {type(raw).__name__}"
