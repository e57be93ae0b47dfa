"""Diagnostic: the static joint torque of a three-legged stance against the leg extension, per robot.

For each robot and leg extension e (the feet e leg lengths below the shoulders, 1 a straight leg), the robot is
posed in MuJoCo with its feet under their standing points, one foot moved half a stride forward (the expert's
stride for the robot, where a stance leg's hip works hardest), and that foot carries a third of the robot's weight
vertically (the three-legged support of the crawl). The joint torques are J^T f (MuJoCo's foot-site Jacobian),
printed over the motor limits (ab/ad, hip, knee), beside the COG height of the pose (MuJoCo's whole-body COM above
the feet's lowest point) and the expert's walking COG height.

Usage: ``python benchmarks/stance_torque.py [--robots paper,hyq,anymal_c] [--extensions 0.67,0.7,0.76,0.8,0.85]``.
docs/robustness.md#where-the-falls-start quotes its lines.
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import mujoco
import numpy as np

import quad_uneven_env  # noqa: F401  (registers QuadUneven-v0)
from agents.expert import ExpertConfig
from planners.robot_geometry import robot_geometry


def stance_torque_fractions(name: str, extension: float) -> tuple[np.ndarray, float]:
    """-, (3,): |ab/ad, hip, knee torque| / limit of the front-left leg holding a third of the weight at
    ``extension`` (-), its foot half a stride ahead of its standing point; and m, the COG height of the pose."""
    env = gym.make("QuadUneven-v0", robot=name, terrain="flat")
    env.reset(seed=0)
    u = env.unwrapped
    geom = robot_geometry(u.robot)
    feet = geom.feet_B.copy()
    feet[:, 2] = geom.shoulders_B[:, 2] - extension * geom.leg_length
    feet[0, 0] += ExpertConfig.for_robot(u.robot).stride / 2
    u.data.qpos[:7] = (0, 0, 0, 1, 0, 0, 0)
    u.data.qpos[7:] = geom.ik(feet - geom.hips_B).reshape(-1)
    mujoco.mj_kinematics(u.model, u.data)
    mujoco.mj_comPos(u.model, u.data)
    jac = np.zeros((3, u.model.nv))
    mujoco.mj_jacSite(u.model, u.data, jac, None, u.idx.foot_sites[0])
    force = np.array([0.0, 0.0, u.robot.total_mass * 9.81 / 3.0])
    torque = jac[:, 6:9].T @ force
    feet_bottom = u.data.site_xpos[u.idx.foot_sites, 2].min() - u.robot.foot_radius
    cog_height = float(u.data.subtree_com[u.idx.trunk_body, 2] - feet_bottom)
    env.close()
    return np.abs(torque) / u.idx.torque_limit[:3], cog_height


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", default="paper,hyq,anymal_c", help="comma-separated robot names")
    parser.add_argument("--extensions", default="0.67,0.7,0.76,0.8,0.85", help="comma-separated leg extensions (-)")
    args = parser.parse_args()
    extensions = [float(e) for e in args.extensions.split(",")]
    for name in args.robots.split(","):
        from quad_uneven_env.robot.description import load_robot

        desc = load_robot(name)
        print(f"{name}: walking COG height {ExpertConfig.for_robot(desc).cog_height:.3f} m")
        for e in extensions:
            f, cog_height = stance_torque_fractions(name, e)
            print(
                f"  extension {e:.2f} (COG {cog_height:.3f} m): "
                f"torque / limit ab/ad {f[0]:.2f}, hip {f[1]:.2f}, knee {f[2]:.2f}"
            )


if __name__ == "__main__":
    main()
