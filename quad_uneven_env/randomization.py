"""Domain randomization and disturbances of the simulated world, drawn per episode from ``env.np_random``.

Three pieces:

- :class:`RandomizationConfig` (+ :class:`ObservationNoise`): frozen, validated configs, one range per
  factor (``None``: the factor is off and the world stays nominal); presets in ``configs/randomization/``
  (:func:`load_randomization`). Every range is drawn **uniformly** on ``[low, high]`` (see each field).
- :class:`ModelRandomizer`: at every reset it restores the model's nominal values exactly, draws the
  episode's factors (:class:`EpisodeDraw`) and writes them into the ``MjModel``, then recomputes what
  MuJoCo derives from masses (``mj_setConst`` on scratch data: subtree masses, inverse weights,
  ``body_sameframe``, ...). The nominal values of every array it writes, or that ``mj_setConst``
  recomputes (found at construction by diffing a perturbed copy), are kept and copied back bit for bit.
- :class:`PushSchedule`: external pushes on the trunk (``xfrc_applied`` at its centre of mass), as
  segments of constant force over the physics steps of a control step.

Actuation latency and pushes are applied by the env's physics loop (:class:`quad_uneven_env.stepper.PhysicsStepper`),
the draw and the observation noise by :class:`quad_uneven_env.world.SimulatedWorld`; this module gives their
per-episode values.
The drawn values are reported as a flat dict of floats (:meth:`EpisodeDraw.as_info`) with the same
keys for every config (nominal values for the factors that are off), so vector envs can stack them.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import os
from collections.abc import Mapping
from typing import Any

import mujoco
import numpy as np

from quad_uneven_env import constants as C
from quad_uneven_env.config import read_yaml, resolve_config_path
from quad_uneven_env.fields import check_fields, excerpt, from_mapping, param, params_of
from quad_uneven_env.physics import RobotIndex
from quad_uneven_env.robot.description import RobotDescription

ROBOT_BODIES: tuple[str, ...] = (
    C.TRUNK_BODY,
    *(b for leg in C.LEG_NAMES for b in (C.thigh_body(leg), C.shank_body(leg))),
)
"""Bodies whose mass ``link_mass_scale`` scales, in this order (trunk, then thigh and shank per leg)."""


RANDOMIZATION_SCALES: tuple[str, ...] = ("none", "robot")
"""Allowed ``scale`` of a :class:`RandomizationConfig`."""


def _range(unit: str, doc: str, **bounds: Any) -> Any:
    return param(None, unit, doc, kind="range", **bounds)


@dataclasses.dataclass(frozen=True)
class ObservationNoise:
    """Additive observation noise, uniform on ``[-scale, scale]`` per element, drawn every step.

    One scale per observation field (the field's unit; 0: no noise). The noisy observation is clipped
    to the observation Box, so it never leaves the space. Noise is on the returned observation only:
    the env's own measurement (reward, termination, ``info``) stays exact.
    """

    base_height: float = param(0.0, "m", lo=0.0, hi=1.0)
    """m, in [0, 1]."""
    projected_gravity: float = param(0.0, "-", lo=0.0, hi=1.0)
    """-, in [0, 1] (unit vector components)."""
    base_lin_vel: float = param(0.0, "m/s", lo=0.0, hi=10.0)
    """m/s, in [0, 10]."""
    base_ang_vel: float = param(0.0, "rad/s", lo=0.0, hi=20.0)
    """rad/s, in [0, 20]."""
    joint_pos: float = param(0.0, "rad", lo=0.0, hi=1.0)
    """rad, in [0, 1]."""
    joint_vel: float = param(0.0, "rad/s", lo=0.0, hi=40.0)
    """rad/s, in [0, 40]."""
    foot_contact: float = param(0.0, "-", lo=0.0, hi=1.0)
    """-, in [0, 1]."""
    stability_index: float = param(0.0, "m", lo=0.0, hi=1.0)
    """m, in [0, 1] (normalised index)."""
    edge_moments: float = param(0.0, "m", lo=0.0, hi=1.0)
    """m, in [0, 1] (normalised moments)."""
    gait_clock: float = param(0.0, "-", lo=0.0, hi=1.0)
    """-, in [0, 1]."""
    height_scan: float = param(0.0, "m", lo=0.0, hi=1.0)
    """m, in [0, 1]."""
    prev_action: float = param(0.0, "-", lo=0.0, hi=1.0)
    """-, in [0, 1]."""
    course_heading: float = param(0.0, "-", lo=0.0, hi=1.0)
    """-, in [0, 1] (sin and cos of the yaw; only with the env's ``course_frame``)."""
    course_lateral: float = param(0.0, "m", lo=0.0, hi=1.0)
    """m, in [0, 1] (only with the env's ``course_frame``)."""

    def __post_init__(self) -> None:
        check_fields(self)

    def any(self) -> bool:
        """Some field has noise."""
        return any(getattr(self, p.name) > 0.0 for p in params_of(ObservationNoise))


@dataclasses.dataclass(frozen=True)
class RandomizationConfig:
    """What is randomized per episode, and how. Every range is ``[low, high]``, drawn uniformly; None: off.

    Per-joint and per-link factors draw one independent value per joint (``JOINT_NAMES`` order) or
    per body (:data:`ROBOT_BODIES`).
    """

    scale: str = param(
        "none",
        "-",
        "how the ranges read: `none` as written; `robot` written for the paper's robot (50 kg, 0.42 m legs) and "
        "scaled to the env's robot by dynamic similarity (docs/randomization.md)",
        kind="choice",
        choices=RANDOMIZATION_SCALES,
    )
    """``"none"``: the ranges are in SI units as written. ``"robot"``: written for the paper's robot and scaled to the
    env's robot (:meth:`for_robot`); the shipped presets say ``robot``."""
    friction: tuple[float, float] | None = _range(
        "-",
        "foot-terrain sliding friction (terrain and every robot geom); U(low, high) per episode",
        lo=0.0,
        hi=5.0,
        lo_open=True,
    )
    """-, in (0, 5]: sliding friction of the terrain and of every robot geom (MuJoCo takes the larger of a pair)."""
    payload_mass: tuple[float, float] | None = _range(
        "kg", "point mass added to the trunk; U per episode", lo=0.0, hi=1000.0
    )
    """kg, in [0, 1000]: a point mass added to the trunk (the paper's robot weighs 50 kg)."""
    payload_com_x: tuple[float, float] | None = _range(
        "m", "payload position along trunk x from its nominal COM; U per episode", lo=-1.0, hi=1.0
    )
    """m, in [-1, 1]: payload position along trunk x, relative to the trunk's nominal COM."""
    payload_com_y: tuple[float, float] | None = _range(
        "m", "payload position along trunk y; U per episode", lo=-1.0, hi=1.0
    )
    """m, in [-1, 1]: along trunk y."""
    payload_com_z: tuple[float, float] | None = _range(
        "m", "payload position along trunk z; U per episode", lo=-1.0, hi=1.0
    )
    """m, in [-1, 1]: along trunk z."""
    link_mass_scale: tuple[float, float] | None = _range(
        "-",
        "mass and inertia factor, COM kept; U per body (trunk, thighs, shanks) per episode",
        lo=0.0,
        hi=10.0,
        lo_open=True,
    )
    """-, in (0, 10]: per body of :data:`ROBOT_BODIES`, mass and inertia x factor (COM kept)."""
    motor_strength: tuple[float, float] | None = _range(
        "-",
        "applied / commanded torque, saturated at the nominal limit; U per joint per episode",
        lo=0.0,
        hi=10.0,
        lo_open=True,
    )
    """-, in (0, 10]: per joint, applied torque = factor x commanded torque, still saturated at the nominal limit
    (``joint_pd``: the servo's kp and kd scale alike)."""
    joint_damping: tuple[float, float] | None = _range(
        "N m s/rad", "viscous joint damping (replaces the nominal); U per joint per episode", lo=0.0, hi=100.0
    )
    """N m s/rad, in [0, 100]: per joint, replaces the robot config's damping."""
    joint_frictionloss: tuple[float, float] | None = _range(
        "N m", "dry joint friction (MuJoCo frictionloss); U per joint per episode", lo=0.0, hi=100.0
    )
    """N m, in [0, 100]: per joint, MuJoCo's dry friction (``dof_frictionloss``)."""
    latency: tuple[float, float] | None = _range(
        "s",
        "command applied k physics steps late, k uniform over round(low/dt)..round(high/dt) per episode; "
        "high <= control period",
        lo=0.0,
        hi=1.0,
    )
    """s, in [0, 1] and at most the env's control period: torques act k physics steps late, k uniform over the
    integers round(low / timestep) ... round(high / timestep)."""
    push_impulse: tuple[float, float] | None = _range(
        "N s", "impulse of a horizontal push on the trunk COM; U per push, direction U[0, 360) deg", lo=0.0, hi=1000.0
    )
    """N s, in [0, 1000]: impulse of each push on the trunk, horizontal, direction uniform in [0, 360) deg."""
    push_interval: tuple[float, float] | None = _range(
        "s", "reset to first push and between push starts; U per push", lo=0.0, hi=1e6, lo_open=True
    )
    """s, in (0, 1e6]: from the reset to the first push, and between push starts (required with ``push_impulse``)."""
    push_duration: tuple[float, float] | None = _range(
        "s",
        "constant-force duration (whole physics steps), <= push_interval low; U per push",
        lo=0.0,
        hi=10.0,
        lo_open=True,
    )
    """s, in (0, 10], at most ``push_interval`` low: constant force = impulse / duration (rounded to physics steps)."""
    observation_noise: ObservationNoise | None = None
    """per-field uniform observation noise (a mapping of field -> scale), or None."""

    def __post_init__(self) -> None:
        check_fields(self, "randomization")
        noise = self.observation_noise
        if noise is not None and not isinstance(noise, ObservationNoise):
            object.__setattr__(
                self, "observation_noise", from_mapping(ObservationNoise, noise, "randomization.observation_noise")
            )
        for axis in "xyz":
            if getattr(self, f"payload_com_{axis}") is not None and self.payload_mass is None:
                raise ValueError(f"randomization.payload_com_{axis} needs payload_mass (the payload it places)")
        push = (self.push_impulse, self.push_interval, self.push_duration)
        if any(v is not None for v in push) and any(v is None for v in push):
            missing = [
                n for n, v in zip(("push_impulse", "push_interval", "push_duration"), push, strict=True) if v is None
            ]
            raise ValueError(
                f"randomization.{missing[0]} is required when any of push_impulse, push_interval, push_duration is set"
            )
        if self.push_duration is not None and self.push_duration[1] > self.push_interval[0]:
            raise ValueError(
                f"randomization.push_duration high must be <= push_interval low = {self.push_interval[0]} s "
                f"(pushes must not overlap), got {list(self.push_duration)}"
            )

    def for_robot(self, mass_ratio: float, length_ratio: float) -> RandomizationConfig:
        """The config in SI units for a robot ``mass_ratio`` (-) times the paper robot's mass and ``length_ratio`` (-)
        times its leg length: itself when ``scale`` is ``"none"``.

        Dynamic similarity (the Froude number kept, gravity unchanged): with m = ``mass_ratio`` and s =
        ``length_ratio``, lengths x s, masses x m, times x sqrt(s), speeds x sqrt(s), angular speeds / sqrt(s),
        torques x m s, impulses x m sqrt(s), viscous damping x m s^1.5. Ratios, friction and latency (the robot's
        computer, not its body) stay as written.

        :raises ValueError: if a scaled range leaves its allowed interval (naming ``randomization.<field>``).
        """
        if self.scale == "none":
            return self
        m, s = float(mass_ratio), float(length_ratio)
        t = math.sqrt(s)
        factors = {
            "payload_mass": m, "payload_com_x": s, "payload_com_y": s, "payload_com_z": s,
            "joint_damping": m * s * t, "joint_frictionloss": m * s,
            "push_impulse": m * t, "push_interval": t, "push_duration": t,
        }  # fmt: skip
        changes: dict[str, Any] = {"scale": "none"}
        for name, k in factors.items():
            r = getattr(self, name)
            if r is not None:
                changes[name] = (r[0] * k, r[1] * k)
        noise = self.observation_noise
        if noise is not None:
            noise_factors = {
                "base_height": s, "base_lin_vel": t, "base_ang_vel": 1.0 / t, "joint_vel": 1.0 / t,
                "stability_index": s, "edge_moments": s, "height_scan": s, "course_lateral": s,
            }  # fmt: skip
            changes["observation_noise"] = dataclasses.replace(
                noise, **{n: getattr(noise, n) * k for n, k in noise_factors.items()}
            )
        return dataclasses.replace(self, **changes)

    @property
    def pushes(self) -> bool:
        """Pushes are on."""
        return self.push_impulse is not None


def load_randomization(
    spec: str | os.PathLike[str] | Mapping[str, Any] | RandomizationConfig | None, where: str = "randomization"
) -> RandomizationConfig | None:
    """The config of ``spec``: None (nominal world), a preset name (``configs/randomization/NAME.yaml``), a YAML
    path, a mapping of fields, or a config.

    :raises ValueError: on an unknown preset or file, an unknown factor or a bad range, naming ``where.field``.
    """
    if spec is None or isinstance(spec, RandomizationConfig):
        return spec
    if isinstance(spec, str | os.PathLike):
        try:
            raw = read_yaml(resolve_config_path(spec, "randomization"))
        except ValueError as err:
            raise ValueError(f"{where}: {err}") from None
    elif isinstance(spec, Mapping):
        raw = spec
    else:
        raise ValueError(f"{where} must be None, a preset name, a YAML path or a mapping, got {excerpt(spec)}")
    return from_mapping(RandomizationConfig, raw, where)


def randomization_for_robot(cfg: RandomizationConfig | None, robot: RobotDescription) -> RandomizationConfig | None:
    """``cfg`` in SI units for ``robot``: :meth:`RandomizationConfig.for_robot` with its mass and leg length over the
    paper robot's (:attr:`RobotDescription.mass_ratio`, :attr:`RobotDescription.length_ratio`); the paper's robot
    (both ratios 1) takes the ranges as written."""
    if cfg is None:
        return None
    return cfg.for_robot(robot.mass_ratio, robot.length_ratio)


def config_table() -> str:
    """Markdown table of the factors (field, allowed, unit, meaning): the reference of docs/randomization.md."""
    rows = ["| factor | allowed | unit | meaning and distribution (U: uniform on [low, high]) |", "|---|---|---|---|"]
    for p in params_of(RandomizationConfig):
        rows.append(f"| `{p.name}` | {p.allowed()} | {p.unit} | {p.doc} |")
    rows.append(
        "| `observation_noise` | null or a mapping observation field -> scale >= 0 | the field's | added noise "
        "U(-scale, scale) per element per step, then clipped to the Box |"
    )
    return "\n".join(rows)


# ------------------------------------------------------------------------------------------ the draw
@dataclasses.dataclass(frozen=True, eq=False)
class EpisodeDraw:
    """One episode's drawn world (SI units); nominal values where a factor is off."""

    friction: float
    """-, foot-terrain sliding friction."""
    payload_mass: float
    """kg, point mass added to the trunk."""
    payload_com: np.ndarray
    """(3,) m, payload position in the trunk frame relative to the trunk's nominal COM."""
    link_mass_scale: np.ndarray
    """(9,) -, mass factor per body of :data:`ROBOT_BODIES`."""
    motor_strength: np.ndarray
    """(12,) -, torque gain per joint."""
    joint_damping: np.ndarray
    """(12,) N m s/rad."""
    joint_frictionloss: np.ndarray
    """(12,) N m."""
    latency_steps: int
    """physics steps between a torque command and its application."""
    physics_dt: float
    """s, the physics timestep (latency = latency_steps x physics_dt)."""
    total_mass: float = math.nan
    """kg, simulated whole-robot mass after the draw (set by :meth:`ModelRandomizer.apply`)."""

    def as_info(self) -> dict[str, float]:
        """Flat dict of floats, the same keys for every config (``info["randomization"]``)."""
        out = {
            "friction": float(self.friction),
            "payload_mass": float(self.payload_mass),
            "payload_com_x": float(self.payload_com[0]),
            "payload_com_y": float(self.payload_com[1]),
            "payload_com_z": float(self.payload_com[2]),
            "total_mass": float(self.total_mass),
            "latency": float(self.latency_steps * self.physics_dt),
            "latency_steps": float(self.latency_steps),
        }
        out.update({f"link_mass_scale_{b}": float(v) for b, v in zip(ROBOT_BODIES, self.link_mass_scale, strict=True)})
        for name in ("motor_strength", "joint_damping", "joint_frictionloss"):
            values = getattr(self, name)
            out.update({f"{name}_{j}": float(v) for j, v in zip(C.JOINT_NAMES, values, strict=True)})
        return out


def factor_values(info: Mapping[str, float]) -> dict[str, float]:
    """One number per factor from an ``info["randomization"]`` dict (the report's grouping keys).

    ``total_mass`` stands for payload and link masses together, ``motor_strength_min`` is the weakest
    joint's gain, ``joint_damping_mean`` and ``joint_frictionloss_mean`` the means over the joints.
    """

    def joints(prefix: str) -> np.ndarray:
        return np.array([info[f"{prefix}_{j}"] for j in C.JOINT_NAMES])

    return {
        "friction": float(info["friction"]),
        "payload_mass": float(info["payload_mass"]),
        "total_mass": float(info["total_mass"]),
        "motor_strength_min": float(joints("motor_strength").min()),
        "joint_damping_mean": float(joints("joint_damping").mean()),
        "joint_frictionloss_mean": float(joints("joint_frictionloss").mean()),
        "latency": float(info["latency"]),
    }


def _uniform(rng: np.random.Generator, r: tuple[float, float], size: int | None = None) -> Any:
    return rng.uniform(r[0], r[1], size)


def draw_episode(
    cfg: RandomizationConfig | None,
    rng: np.random.Generator | None,
    nominal_friction: float,
    nominal_damping: np.ndarray,
    nominal_frictionloss: np.ndarray,
    physics_dt: float,
) -> EpisodeDraw:
    """Draw one episode's world from ``rng``, the factors in field order; a factor that is off draws nothing.

    ``cfg=None`` gives the nominal world (``rng`` unused, may be None).

    :param nominal_friction: -, the model's foot-terrain friction. :param nominal_damping: (12,) N m s/rad.
    :param nominal_frictionloss: (12,) N m. :param physics_dt: s.
    """
    c = cfg or RandomizationConfig()
    nj, nb = C.N_JOINTS, len(ROBOT_BODIES)
    friction = float(_uniform(rng, c.friction)) if c.friction else float(nominal_friction)
    payload = float(_uniform(rng, c.payload_mass)) if c.payload_mass else 0.0
    com = np.array([float(_uniform(rng, r)) if r else 0.0 for r in (c.payload_com_x, c.payload_com_y, c.payload_com_z)])
    scale = _uniform(rng, c.link_mass_scale, nb) if c.link_mass_scale else np.ones(nb)
    strength = _uniform(rng, c.motor_strength, nj) if c.motor_strength else np.ones(nj)
    damping = _uniform(rng, c.joint_damping, nj) if c.joint_damping else np.array(nominal_damping, dtype=float)
    floss = (
        _uniform(rng, c.joint_frictionloss, nj) if c.joint_frictionloss else np.array(nominal_frictionloss, dtype=float)
    )
    k = 0
    if c.latency:
        k_lo, k_hi = round(c.latency[0] / physics_dt), round(c.latency[1] / physics_dt)
        k = int(rng.integers(k_lo, k_hi + 1))
    return EpisodeDraw(friction, payload, com, scale, strength, damping, floss, k, float(physics_dt))


# ------------------------------------------------------------------------------------------ the model
_WRITTEN = (
    "geom_friction",
    "body_mass",
    "body_inertia",
    "body_ipos",
    "body_iquat",
    "actuator_gainprm",
    "actuator_biasprm",
    "actuator_forcelimited",
    "actuator_forcerange",
    "dof_damping",
    "dof_frictionloss",
)
"""MjModel arrays :meth:`ModelRandomizer.apply` writes."""


def _model_arrays(model: mujoco.MjModel) -> dict[str, np.ndarray]:
    return {n: v for n in dir(model) if not n.startswith("_") and isinstance(v := getattr(model, n, None), np.ndarray)}


def _setconst_outputs(model: mujoco.MjModel, bodies: np.ndarray) -> tuple[str, ...]:
    """Names of the MjModel arrays that ``mj_setConst`` recomputes after a mass, inertia and COM change."""
    probe = copy.deepcopy(model)
    probe.body_mass[bodies] *= 1.37
    probe.body_inertia[bodies] *= 1.37
    probe.body_ipos[bodies] += 0.0123
    mujoco.mj_setConst(probe, mujoco.MjData(probe))
    before, after = _model_arrays(model), _model_arrays(probe)
    return tuple(n for n in before if not np.array_equal(before[n], after[n]))


class ModelRandomizer:
    """Writes an :class:`EpisodeDraw` into a model and restores the nominal model bit for bit.

    :param model: the env's compiled model (modified in place).
    :param idx: its resolved robot ids.
    :param servo: the actuators are ``joint_pd`` servos (motor strength scales kp and kd too).
    """

    def __init__(self, model: mujoco.MjModel, idx: RobotIndex, servo: bool) -> None:
        self.model = model
        self.idx = idx
        self.servo = servo
        self.bodies = np.array([model.body(b).id for b in ROBOT_BODIES])
        self.dofs = np.array([model.jnt_dofadr[model.joint(j).id] for j in C.JOINT_NAMES])
        self.actuators = np.array([model.actuator(a).id for a in C.ACTUATOR_NAMES])
        self.friction_geoms = np.flatnonzero(idx.robot_geoms | (np.arange(model.ngeom) == idx.terrain_geom))
        names = dict.fromkeys(_WRITTEN + _setconst_outputs(model, self.bodies))
        self._nominal = {n: getattr(model, n).copy() for n in names}
        self._scratch = mujoco.MjData(model)
        self.dirty = False
        """the model holds a draw (restore before the next one)."""

    @property
    def restored_fields(self) -> tuple[str, ...]:
        """Names of the MjModel arrays kept and restored: those written plus those ``mj_setConst`` recomputes."""
        return tuple(self._nominal)

    @property
    def nominal_friction(self) -> float:
        """-, the nominal foot-terrain sliding friction (the larger of terrain and foot)."""
        f = self._nominal["geom_friction"]
        return float(max(f[self.idx.terrain_geom, 0], f[self.idx.foot_geoms, 0].max()))

    @property
    def nominal_damping(self) -> np.ndarray:
        """(12,) N m s/rad."""
        return self._nominal["dof_damping"][self.dofs]

    @property
    def nominal_frictionloss(self) -> np.ndarray:
        """(12,) N m."""
        return self._nominal["dof_frictionloss"][self.dofs]

    def restore(self) -> None:
        """Copy every nominal array back (exact: the stored copies, not a recomputation)."""
        if not self.dirty:
            return
        for name, value in self._nominal.items():
            getattr(self.model, name)[...] = value
        self.dirty = False

    def apply(self, cfg: RandomizationConfig, draw: EpisodeDraw) -> EpisodeDraw:
        """Restore, then write the factors of ``cfg`` from ``draw`` into the model; ``draw`` with its total mass.

        A factor that is off leaves its arrays nominal.
        """
        self.restore()
        m, nom = self.model, self._nominal
        self.dirty = True
        if cfg.friction:
            m.geom_friction[self.friction_geoms, 0] = draw.friction
        masses = cfg.link_mass_scale is not None or cfg.payload_mass is not None
        if cfg.link_mass_scale:
            m.body_mass[self.bodies] = nom["body_mass"][self.bodies] * draw.link_mass_scale
            m.body_inertia[self.bodies] = nom["body_inertia"][self.bodies] * draw.link_mass_scale[:, None]
        if cfg.payload_mass and draw.payload_mass > 0.0:
            self._add_payload(draw.payload_mass, draw.payload_com)
        if cfg.motor_strength:
            a, s = self.actuators, draw.motor_strength
            m.actuator_gainprm[a, 0] = nom["actuator_gainprm"][a, 0] * s
            if self.servo:
                m.actuator_biasprm[a, 1:3] = nom["actuator_biasprm"][a, 1:3] * s[:, None]
            else:  # saturate the applied torque at the nominal motor limit
                m.actuator_forcelimited[a] = 1
                m.actuator_forcerange[a] = m.actuator_ctrlrange[a]
        if cfg.joint_damping:
            m.dof_damping[self.dofs] = draw.joint_damping
        if cfg.joint_frictionloss:
            m.dof_frictionloss[self.dofs] = draw.joint_frictionloss
        if masses:
            mujoco.mj_setConst(m, self._scratch)
        return dataclasses.replace(draw, total_mass=float(m.body_subtreemass[self.idx.trunk_body]))

    def _add_payload(self, mass: float, offset_B: np.ndarray) -> None:
        """Add a point mass at the trunk's nominal COM + ``offset_B`` (trunk frame): new mass, COM and inertia."""
        m, b = self.model, self.idx.trunk_body
        m_t, c_t = float(m.body_mass[b]), m.body_ipos[b].copy()
        R = np.empty(9)
        mujoco.mju_quat2Mat(R, m.body_iquat[b])
        R = R.reshape(3, 3)
        I_t = R @ np.diag(m.body_inertia[b]) @ R.T  # about the trunk COM, trunk frame
        p = self._nominal["body_ipos"][b] + offset_B
        total = m_t + mass
        c = (m_t * c_t + mass * p) / total

        def shift(r: np.ndarray) -> np.ndarray:  # parallel-axis term of a unit point mass at r
            return float(r @ r) * np.eye(3) - np.outer(r, r)

        inertia = I_t + m_t * shift(c_t - c) + mass * shift(p - c)
        eigval, eigvec, quat = np.empty(3), np.empty(9), np.empty(4)
        mujoco.mju_eig3(eigval, eigvec, quat, inertia.ravel())
        m.body_mass[b] = total
        m.body_ipos[b] = c
        m.body_inertia[b] = eigval
        m.body_iquat[b] = quat


# ------------------------------------------------------------------------------------------ pushes
@dataclasses.dataclass(frozen=True)
class Push:
    """One push on the trunk."""

    start: float
    """s after the reset."""
    impulse: float
    """N s, magnitude (force x duration)."""
    direction_deg: float
    """deg, horizontal direction of the force from world +x towards +y."""
    duration: float
    """s, a whole number of physics steps."""
    force: tuple[float, float, float]
    """N, world frame: the constant force."""


class PushSchedule:
    """The pushes of one episode, in physics steps since the reset; draws each push when it starts.

    :param cfg: the config (pushes off: no segment ever has a force).
    :param physics_dt: s.
    """

    def __init__(self, cfg: RandomizationConfig | None, physics_dt: float) -> None:
        self.on = cfg is not None and cfg.pushes
        self.cfg = cfg
        self.dt = float(physics_dt)
        self.pushes: list[Push] = []
        """the pushes started so far this episode."""
        self._next = self._start = self._end = 0
        self._force = np.zeros(3)

    def reset(self, rng: np.random.Generator | None) -> None:
        """Forget the pushes; draw the first start time (``rng`` unused, may be None, when pushes are off)."""
        self.pushes = []
        self._start = self._end = 0
        self._next = self._steps(_uniform(rng, self.cfg.push_interval)) if self.on else 1 << 62

    def _steps(self, seconds: float) -> int:
        return max(1, round(seconds / self.dt))

    def _begin(self, rng: np.random.Generator, step: int) -> None:
        c = self.cfg
        impulse = float(_uniform(rng, c.push_impulse))
        angle = float(rng.uniform(0.0, 2.0 * math.pi))
        n = self._steps(_uniform(rng, c.push_duration))
        force = impulse / (n * self.dt)
        self._force = np.array([force * math.cos(angle), force * math.sin(angle), 0.0])
        self._start, self._end = step, step + n
        self._next = step + max(n, self._steps(_uniform(rng, c.push_interval)))
        self.pushes.append(Push(step * self.dt, impulse, math.degrees(angle), n * self.dt, tuple(self._force.tolist())))

    def segments(self, rng: np.random.Generator, step: int, n: int) -> list[tuple[int, np.ndarray | None]]:
        """Physics steps ``step ... step + n - 1`` as ``(length, force or None)`` runs of constant force (N, world)."""
        out: list[tuple[int, np.ndarray | None]] = []
        s, stop = step, step + n
        while s < stop:
            if s >= self._next:
                self._begin(rng, s)
            if self._start <= s < self._end:
                e = min(self._end, stop)
                out.append((e - s, self._force))
            else:
                e = min(self._next, stop)
                out.append((e - s, None))
            s = e
        return out
