"""The paper's §6 scenario run in the simulator: ``quad-uneven paper --out DIR``.

One gait cycle of the paper (Table-1 robot, footholds given as by the paper's "expert user",
phases 1, 1, 1, 0.1, 1, 1, 1 s, COG (0.01, 0, 0.544) -> (0.21, 0, 0.5743) m) is planned on the
``paper`` terrain of ``QuadUneven-v0`` and tracked by the computed-torque controller
(:class:`agents.control.controller.ComputedTorqueController`) at physics rate. The robot starts exactly in
the plan's initial state (base pose and joints of ``reference.sample(0)``, zero velocity), holds
it for a short ``settle`` time (so the contact forces build up before the cycle starts), walks
the cycle, then holds the final pose for ``hold`` s. Every physics step is recorded
(:class:`PaperRun`); :mod:`agents.paper.metrics` turns the record into ``paper.json``,
:mod:`agents.paper.figures` and :mod:`agents.paper.animation` into Figs 4-9.

Public API: :class:`PaperRunConfig`, :class:`PaperRun`, :func:`plan_paper_cycle`,
:func:`run_paper_sim`, :func:`write_paper_outputs`, :func:`add_paper_parser`.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from agents.control.controller import ComputedTorqueController, Gains
from planners import paper_scenario, plan_gait_cycle
from planners.cycle import GaitCyclePlan
from planners.reference import Reference, aim_feet_below_footholds
from planners.types import ReferenceSample
from quad_uneven_env import constants as C
from quad_uneven_env import physics
from quad_uneven_env.fields import check_fields, param

DISTRIBUTIONS = ("qp", "pinv")
"""Torque distributions offered on the command line ("qp": friction-cone aware; "pinv": the paper's)."""


@dataclasses.dataclass(frozen=True)
class PaperRunConfig:
    """Settings of the simulated §6 run (SI units)."""

    distribution: str = param("qp", kind="choice", choices=DISTRIBUTIONS)
    """inverse-dynamics torque distribution: "qp" (friction cones) or "pinv" (the paper's pseudo-inverse)."""
    epsilon: float = param(10.0, "N m", lo=0.0, hi=1000.0)
    """N m: stability margin of the planned COG path. The paper's Table 1 has 0.1 N m; with it the COG ends
    the short four-leg support on the LF-RH diagonal and the simulated robot rocks on that edge (see
    docs/paper.md): 10 N m (2 cm of static margin at 50 kg) is the default, ``--epsilon 0.1`` the paper's."""
    duration: float | None = param(None, "s", lo=0.0, hi=100.0, lo_open=True, none_ok=True)
    """s of the cycle to run (None: the whole 6.1 s cycle); a shorter run stops early (tests)."""
    hold: float = param(0.5, "s", lo=0.0, hi=100.0)
    """s: holding the final planned pose after the cycle (only when the whole cycle is run)."""
    settle: float = param(0.1, "s", lo=0.0, hi=100.0)
    """s: holding the initial planned pose before the cycle starts (not recorded)."""
    touchdown_depth: float = param(0.015, "m", lo=0.0, hi=0.1)
    """m: a planned-stance foot without contact is aimed this far below its foothold (0: off)."""
    seed: int = param(0, kind="int", lo=0)
    """seed of the env reset (the paper terrain's field beyond x = 0.6 m only)."""

    def __post_init__(self) -> None:
        check_fields(self, where="")


@dataclasses.dataclass
class PaperRun:
    """The record of one simulated run, one row per physics step (times from the cycle start)."""

    plan: GaitCyclePlan
    """the planned cycle."""
    config: PaperRunConfig
    """the settings of the run."""
    dt: float
    """s: physics timestep."""
    mass: float
    """kg: total robot mass."""
    torque_limit: np.ndarray
    """(12,) N m."""
    start_site_error: np.ndarray
    """(4, 3) m: foot sites at the start minus their planned places (block top + foot radius)."""
    settle_cog_drift: float
    """m: how far the COG moved during the settle hold."""
    fall_reason: str | None
    """the env's termination reason, None when the run ended standing."""
    arrays: dict[str, np.ndarray]
    """per step k, state at ``time[k]``: ``time`` (N,) s; ``cog``, ``cog_vel``, ``cog_acc`` (N, 3)
    measured (m, m/s, m/s^2, world); ``cog_plan``, ``cog_vel_plan``, ``cog_acc_plan`` (N, 3); ``qpos``
    (N, 19); ``tau`` (N, 12) N m applied (actuator_force); ``forces`` (N, 4, 3) N on each foot
    (world); ``normal_force`` (N, 4) N, the vertical component (the normal on the flat block tops the
    feet stand on; a height-field normal is ill-defined at the block edges); ``contact`` (N, 4) bool;
    ``feet`` (N, 4, 3), ``hips`` (N, 4, 3), ``knees`` (N, 4, 3) m (world); ``index`` (N,) measured
    stability index N m (-inf: < 3 feet in contact); ``index_plan`` (N,) N m; ``stance`` (N, 4) bool planned."""

    @property
    def time(self) -> np.ndarray:
        """(N,) s from the cycle start."""
        return self.arrays["time"]


class PaperReference:
    """``reference(t)`` for the controller: the plan shifted by ``settle`` s, late touch-downs pushed down.

    ``t`` (s) is the controller clock; the plan time is ``t - settle`` clipped to the cycle, so the
    robot holds the plan's initial state during the settle and its final state after the cycle.
    A planned-stance foot whose contact sensor reads no contact is aimed ``touchdown_depth`` below
    its foothold (joint targets by IK against the planned base), so a few millimetres of tracking
    error at the end of a swing do not leave it hovering.
    """

    def __init__(self, reference: Reference, settle: float, touchdown_depth: float, data: mujoco.MjData, idx) -> None:
        self.reference = reference
        self.plan = reference.plan
        self.settle = float(settle)
        self.depth = float(touchdown_depth)
        self._data = data
        self._sensor = np.asarray(idx.foot_sensor_adr)
        self._cfg = reference.cfg

    def __call__(self, t: float) -> ReferenceSample:
        """The reference sample at controller time ``t`` (s)."""
        tp = float(t) - self.settle
        ref = self.reference.sample(tp)
        if self.depth <= 0.0:
            return ref
        late = np.asarray(ref.stance) & ~(self._data.sensordata[self._sensor] > 0)
        if not late.any():
            return ref
        return aim_feet_below_footholds(ref, self.plan, tp, late, self.depth, self._cfg)


def plan_paper_cycle(terrain, robot, epsilon: float = 0.1) -> GaitCyclePlan:
    """Plan the paper's §6 cycle on ``terrain`` (a height map, e.g. the env's) for ``robot`` (a description) with
    margin ``epsilon`` (N m)."""
    scenario = dataclasses.replace(paper_scenario(), terrain=terrain, robot=robot, epsilon=float(epsilon))
    return plan_gait_cycle(scenario)


def _make_env(seed: int):
    import gymnasium as gym

    import quad_uneven_env  # noqa: F401  (registers QuadUneven-v0)

    env = gym.make("QuadUneven-v0", terrain="paper", frame_skip=1, reset_noise_scale=0.0)
    env.reset(seed=seed)
    return env


def run_paper_sim(config: PaperRunConfig | None = None, progress: bool = True) -> PaperRun:
    """Plan the §6 cycle and simulate it with the computed-torque controller; record every physics step.

    :param config: run settings (default :class:`PaperRunConfig`).
    :param progress: show a tqdm progress bar over the physics steps.
    """
    from tqdm import tqdm

    cfg = config or PaperRunConfig()
    env = _make_env(cfg.seed)
    u = env.unwrapped
    m, d, idx = u.model, u.data, u.idx
    plan = plan_paper_cycle(u.terrain.heightfield, u.robot, cfg.epsilon)
    reference = plan.reference(u.robot)
    s0 = reference.sample(0.0)
    mujoco.mj_resetData(m, d)
    d.qpos[:] = s0.qpos
    d.qvel[:] = 0.0
    mujoco.mj_forward(m, d)
    start_err = physics.feet_pos(d, idx) - reference.sites_start
    cog_start = physics.cog(d, idx).copy()
    hook = PaperReference(reference, cfg.settle, cfg.touchdown_depth, d, idx)
    controller = ComputedTorqueController(hook, distribution=cfg.distribution, gains=Gains())
    controller.reset(m, d, u.terrain)
    u.set_controller(controller)
    dt = u.physics_dt
    zero = np.zeros(C.N_JOINTS)
    n_settle = round(cfg.settle / dt)
    for _ in range(n_settle):
        _, _, term, _, info = u.step(zero)
        if term:
            break
    settle_drift = float(np.linalg.norm(physics.cog(d, idx) - cog_start))
    run_time = plan.duration + cfg.hold if cfg.duration is None else min(cfg.duration, plan.duration + cfg.hold)
    n = round(run_time / dt)
    rec = _Recorder(n, m, idx)
    fall = None
    for k in tqdm(range(n), desc="paper run", unit="step", disable=not progress, mininterval=0.5):
        qpos = d.qpos.copy()
        _, _, term, _, info = u.step(zero)
        rec.add(k, k * dt, qpos, info, d)
        if term:
            fall = info["termination_reason"]
            break
    env.close()
    arrays = rec.finish(plan)
    return PaperRun(plan, cfg, dt, idx.total_mass, idx.torque_limit.copy(), start_err, settle_drift, fall, arrays)


class _Recorder:
    """Preallocated per-step arrays of a run."""

    def __init__(self, n: int, model: mujoco.MjModel, idx) -> None:
        self.n = 0
        z = np.zeros
        self.a = {
            "time": z(n), "cog": z((n, 3)), "cog_vel": z((n, 3)), "cog_acc": z((n, 3)), "qpos": z((n, C.NQ)),
            "tau": z((n, C.N_JOINTS)), "forces": z((n, 4, 3)), "normal_force": z((n, 4)),
            "contact": z((n, 4), dtype=bool), "feet": z((n, 4, 3)), "hips": z((n, 4, 3)), "knees": z((n, 4, 3)),
            "index": z(n),
        }  # fmt: skip
        self._hips = np.array([model.site(s).id for s in C.HIP_SITES])
        self._knees = np.array([model.body(C.shank_body(leg)).id for leg in C.LEG_NAMES])

    def add(self, k: int, t: float, qpos: np.ndarray, info: dict[str, Any], d: mujoco.MjData) -> None:
        a = self.a
        a["time"][k] = t
        a["qpos"][k] = qpos
        for key in ("cog", "cog_vel", "cog_acc"):
            a[key][k] = info[key]
        f = info["contact_forces"]
        a["forces"][k] = f
        feet = info["feet_pos"]
        a["feet"][k] = feet
        a["normal_force"][k] = f[:, 2]
        a["contact"][k] = info["foot_contact"]
        a["index"][k] = info["stability_index"]
        a["tau"][k] = d.actuator_force
        a["hips"][k] = d.site_xpos[self._hips]
        a["knees"][k] = d.xpos[self._knees]
        self.n = k + 1

    def finish(self, plan: GaitCyclePlan) -> dict[str, np.ndarray]:
        out = {k: v[: self.n] for k, v in self.a.items()}
        tp = np.clip(out["time"], 0.0, plan.duration)
        out["cog_plan"] = plan.cog.position(tp)
        out["cog_vel_plan"] = plan.cog.velocity(tp)
        out["cog_acc_plan"] = plan.cog.acceleration(tp)
        out["index_plan"] = plan.stability(tp)
        from planners.gait import phase_index

        stance = np.array([p.stance for p in plan.phases])
        out["stance"] = stance[phase_index(plan.phases, tp)]
        return out


def write_paper_outputs(run: PaperRun, out: Path, fps: float = 20.0) -> dict:
    """Write Figs 4-9 and ``paper.json`` for ``run`` into ``out``; return the paper.json content."""
    import matplotlib

    matplotlib.use("Agg")
    from agents.paper.animation import write_stick_animation
    from agents.paper.figures import FIGURES
    from agents.paper.metrics import summarize

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    files = []
    for name, draw in FIGURES.items():
        draw(run, out / name)
        files.append(name)
    files.append(write_stick_animation(run, out / "fig9_stick.gif", fps=fps).name)
    info = summarize(run)
    info["figures"] = files
    (out / "paper.json").write_text(json.dumps(info, indent=2))
    return info
