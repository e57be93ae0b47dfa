"""Diagnostic: how much friction the expert's stance forces ask of the floor, and what they cost in torque.

One expert walk (every factor nominal but the floor's friction) on flat ground, rough 5 cm or 8 cm stairs (lengths
times the robot's leg length over 0.42 m), for ``--seconds`` or 2 m (times that ratio). Every control step it reads
the contact forces MuJoCo applied to each foot and the stance forces the controller's QP commanded, and prints:
the commanded tangential / normal ratio of the loaded stance feet (world frame: on tilted ground the cone is about
the terrain normal; median, 95th percentile, max), the measured
one (95th percentile), how many loaded stance-foot steps slid (contact point faster than 0.05 m/s), the first
slide (time, foot, gait phase), the peak joint torque over the motor limit per joint type, and the distance.

Usage: ``python benchmarks/friction_demand.py --floor 0.35 [--cone 0.5] [--terrain flat|rough|up|down]
[--robot anymal_c] [--seconds 20] [--seed 0]`` (``--cone``: ``ExpertConfig.friction``, the robot's default if
left out). docs/robustness.md#friction quotes its lines.
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import mujoco
import numpy as np

import quad_uneven_env  # noqa: F401  (registers QuadUneven-v0)
from agents.expert import ExpertConfig, attach_expert
from planners.gait import SWING_ORDER
from planners.robot_geometry import robot_geometry
from quad_uneven_env import constants as C

LOADED = 0.04
"""a stance foot counts when its measured normal force exceeds this fraction of the robot's weight (20 N on 50 kg)."""
SLIDE_SPEED = 0.05
"""m/s: a loaded foot whose site moves faster than this slides (the expert's slip threshold)."""


def terrain_spec(kind: str, s: float) -> dict:
    """The terrain ``kind`` (flat, rough, up, down) at length scale ``s``."""
    if kind == "flat":
        return {"kind": "flat"}
    if kind == "rough":
        return {"kind": "rough", "amplitude": 0.05 * s, "wavelength": 0.6 * s}
    return {"kind": "stairs", "direction": kind, "riser": 0.08 * s, "tread": 0.3 * s, "n_steps": 5}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--floor", type=float, required=True, help="the floor's friction coefficient (-)")
    ap.add_argument("--cone", type=float, default=None, help="ExpertConfig.friction (default: the robot's)")
    ap.add_argument("--terrain", choices=("flat", "rough", "up", "down"), default="flat")
    ap.add_argument("--robot", default="paper")
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args()
    probe = gym.make("QuadUneven-v0", robot=a.robot)
    s = robot_geometry(probe.unwrapped.robot).scale
    probe.close()
    env = gym.make(
        "QuadUneven-v0", robot=a.robot, terrain=terrain_spec(a.terrain, s),
        randomization={"friction": [a.floor, a.floor]}, max_episode_steps=10**7,
    )  # fmt: skip
    u = env.unwrapped
    config = ExpertConfig.for_robot(u.robot, {} if a.cone is None else {"friction": a.cone})
    expert = attach_expert(env, config)
    m, d = u.model, u.data
    feet = [m.geom(g).id for g in C.FOOT_GEOMS]
    sites = [m.site(n).id for n in C.FOOT_SITES]
    limit = np.asarray(u.idx.torque_limit, dtype=float)
    loaded = LOADED * u.total_mass * 9.81  # N
    f6, v6 = np.zeros(6), np.zeros(6)
    commanded, measured, peak = [], [], np.zeros(C.N_JOINTS)
    slid = loaded_steps = 0
    first: str | None = None
    env.reset(seed=a.seed)
    goal = 2.0 * s
    info: dict = {"distance": 0.0}
    fell = False
    for _ in range(round(a.seconds / u.dt)):
        _, _, terminated, _, info = env.step(expert.predict(None)[0])
        fn, ft = np.zeros(C.N_LEGS), np.zeros(C.N_LEGS)
        for i in range(d.ncon):
            c = d.contact[i]
            for leg, g in enumerate(feet):
                if g in (c.geom1, c.geom2):
                    mujoco.mj_contactForce(m, d, i, f6)
                    fn[leg] += f6[0]
                    ft[leg] += np.hypot(f6[1], f6[2])
        last = expert.controller.last
        if last is not None:
            f = np.asarray(last.contact_forces)
            for leg in np.flatnonzero(fn > loaded):
                loaded_steps += 1
                measured.append(ft[leg] / fn[leg])
                if f[leg, 2] > loaded:
                    commanded.append(np.hypot(f[leg, 0], f[leg, 1]) / f[leg, 2])
                mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_SITE, sites[leg], v6, 0)
                if np.hypot(v6[3], v6[4]) > SLIDE_SPEED:
                    slid += 1
                    if first is None:
                        phase = _phase(expert, d.time)
                        first = f"t={d.time:.2f} s, {C.LEG_NAMES[leg]}, {phase}, commanded ratio {commanded[-1]:.2f}"
        peak = np.maximum(peak, np.abs(d.actuator_force) / limit)
        if terminated:
            fell = True
            break
        if info["distance"] >= goal:
            break
    cr, mr = np.asarray(commanded), np.asarray(measured)
    print(
        f"{a.robot} {a.terrain} floor {a.floor:g} cones {config.friction:g}: commanded ratio p50/p95/max "
        f"{np.percentile(cr, 50):.2f}/{np.percentile(cr, 95):.2f}/{cr.max():.2f}, "
        f"measured p95 {np.percentile(mr, 95):.2f}; "
        f"slid {slid} of {loaded_steps} loaded foot-steps (first: {first or '-'}); peak torque / limit "
        f"(ab/ad, hip, knee) {np.round(peak.reshape(4, 3).max(axis=0), 2).tolist()}; "
        f"{'fell' if fell else 'walked'} {info['distance']:.2f} m in {d.time:.1f} s"
    )
    env.close()


def _phase(expert, time: float) -> str:
    """The gait phase at simulator ``time`` (s) of the current plan: its index and swing leg."""
    _, fraction = expert.planned_now(time)
    ends = np.cumsum(expert.config.durations)
    k = min(int(np.searchsorted(ends, fraction * ends[-1], side="right")), len(ends) - 1)
    return f"phase {k} ({SWING_ORDER[k] or 'four-leg support'}{' swing' if SWING_ORDER[k] else ''})"


if __name__ == "__main__":
    main()
