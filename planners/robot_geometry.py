"""The robot as the planners see it: :class:`RobotGeometry`, one view of any robot description.

Every robot-specific number the planners use comes from here: the legs' hips, where their feet stand, how far
they reach, the foot and shank radii, the whole-body mass, the leg inverse kinematics and the knee. One builder,
:meth:`RobotGeometry.from_description`, reads them from the robot's description, in one of two leg models:

- two-link legs (the paper's Table-1 robot, the description's
  :class:`~quad_uneven_env.robot.quadruped.TwoLinkLegs`): hips at the trunk corners, a leg of ``thigh`` and
  ``shank`` hanging from each (:mod:`quad_uneven_env.robot.kinematics`), exactly the numbers the planners were
  written with, planned as the paper plans them (reach only);
- any other description (a URDF robot): the HAA-HFE-KFE chain of each leg with its offsets
  (:mod:`quad_uneven_env.robot.leg_chain`), its swing knots also tested against its joint ranges.

Three points per leg, all in the trunk frame (m), coincide for the paper's robot and differ for a robot with
hip offsets:

- ``hips_B``: the HAA origin, where the leg's chain starts (the whole-body COM placement, the leg IK);
- ``shoulders_B``: the centre of the leg's reach: the HAA origin moved by the HFE origin's offsets along the HAA
  axis and normal to both axes (not the lateral one, along the HFE axis). The reach (``leg_length``) combines the
  stretched thigh and shank with that lateral offset ``lat``: a foot at planar distance ``d`` from the HFE axis
  lies ``sqrt(d^2 + lat^2)`` from the shoulder at any HAA angle, exactly where the HFE origin has no offset
  normal to both axes (Go1, Solo12, ANYmal C; HyQ's 8 cm below its HAA axis makes it approximate);
- ``feet_B``: the foot point in the standing pose (the nominal foothold lies under it).

:func:`robot_geometry` builds (and caches) the view of a ``RobotDescription`` or returns a ``RobotGeometry`` as
it is.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from quad_uneven_env import constants as C
from quad_uneven_env.constants import LEG_NAMES
from quad_uneven_env.fields import excerpt
from quad_uneven_env.robot.description import RobotDescription, TwoLinkLegs, load_robot
from quad_uneven_env.robot.kinematics import leg_fk_hip, leg_ik_hip
from quad_uneven_env.robot.leg_chain import chain_constants, feet_positions_B, knee_position_B, leg_ik_B

PAPER_MIN_REACH = 0.12
"""m: the paper robot's hip-to-foot-site distance below which a swing knot is too close to the hip (knee fully
bent: ~0.114 m)."""


@dataclasses.dataclass(frozen=True)
class LegChainModel:
    """The legs of a description as ``p(q) = h + B R_x(q1) [c0 + R_y(q2) a + R_y(q2 + sigma q3) b]``.

    ``B`` (4, 3, 3) has the columns (HAA axis, HFE axis, their cross product) in the trunk frame; ``R_x``,
    ``R_y`` turn about the first and second of them; ``a`` and ``b`` are the thigh and the shank at zero
    angles (HFE to knee, knee to foot), ``c0`` the HFE origin from the HAA origin, all in ``B``'s coordinates.
    The same form with the mass-weighted link COMs (``com_c0``, ``com_a``, ``com_b``, kg m) gives each leg's
    first mass moment about its HAA origin.
    """

    basis: np.ndarray
    """(4, 3, 3) B per leg."""
    sigma: np.ndarray
    """(4,) +1 where the KFE axis is the HFE axis, -1 where it is opposite."""
    foot_c0: np.ndarray
    """(4, 3) m."""
    foot_a: np.ndarray
    """(4, 3) m."""
    foot_b: np.ndarray
    """(4, 3) m."""
    com_c0: np.ndarray
    """(4, 3) kg m."""
    com_a: np.ndarray
    """(4, 3) kg m."""
    com_b: np.ndarray
    """(4, 3) kg m."""
    leg_mass: np.ndarray
    """(4,) kg, the three links of each leg."""
    trunk_moment: np.ndarray
    """(3,) kg m, the trunk's mass times its COM (trunk frame)."""

    @classmethod
    def from_description(cls, desc: RobotDescription) -> LegChainModel:
        """The constants of every leg of ``desc`` (trunk-frame placements at zero angles)."""
        rows: dict[str, list[Any]] = {k: [] for k in ("B", "s", "fc", "fa", "fb", "mc", "ma", "mb", "m")}
        for leg in desc.legs:
            R1 = leg.haa.rot
            a1 = R1 @ leg.haa.axis
            R2 = R1 @ leg.hfe.rot
            a2 = R2 @ leg.hfe.axis
            R3 = R2 @ leg.kfe.rot
            B = np.column_stack([a1, a2, np.cross(a1, a2)])
            o2 = R1 @ leg.hfe.pos  # HFE origin - HAA origin
            u1 = R2 @ leg.kfe.pos  # knee - HFE origin
            u2 = R3 @ leg.foot  # foot - knee
            mh, mt, ms = (j.link.mass for j in leg.joints)
            ch, ct, cs = R1 @ leg.haa.link.com, R2 @ leg.hfe.link.com, R3 @ leg.kfe.link.com
            rows["B"].append(B)
            rows["s"].append(float(np.sign((R3 @ leg.kfe.axis) @ a2)))
            for key, v in (("fc", o2), ("fa", u1), ("fb", u2)):
                rows[key].append(B.T @ v)
            for key, v in (("mc", mh * ch + (mt + ms) * o2), ("ma", mt * ct + ms * u1), ("mb", ms * cs)):
                rows[key].append(B.T @ v)
            rows["m"].append(mh + mt + ms)
        a = {k: np.array(v, dtype=float) for k, v in rows.items()}
        trunk = desc.trunk.mass * np.asarray(desc.trunk.com, dtype=float)
        return cls(a["B"], a["s"], a["fc"], a["fa"], a["fb"], a["mc"], a["ma"], a["mb"], a["m"], trunk)

    def point(self, q: np.ndarray, which: str, qd: np.ndarray | None = None):
        """The foot point (``which="foot"``, m) or the leg's mass moment (``"com"``, kg m) from the HAA origin.

        :param q: (..., 4, 3) leg angles (rad); :param qd: optional (..., 4, 3) joint velocities (rad/s).
        :return: ``(p, J)``, p (..., 4, 3) in the trunk frame and J = dp/dq (..., 4, 3, 3); with ``qd`` also
            ``Jd_qd = (dJ/dt) qd`` (..., 4, 3), the velocity-product acceleration (as
            :func:`planners.wholebody.leg_point`).
        """
        if which == "foot":
            c0, a, b = self.foot_c0, self.foot_a, self.foot_b
        else:
            c0, a, b = self.com_c0, self.com_a, self.com_b
        q = np.asarray(q, dtype=float)
        s1, c1 = np.sin(q[..., 0]), np.cos(q[..., 0])
        t2, t23 = q[..., 1], q[..., 1] + self.sigma * q[..., 2]
        va, vb = _rot_y(t2, a), _rot_y(t23, b)
        v = c0 + va + vb
        p = _rot_x(s1, c1, v)
        zero = np.zeros_like(s1)
        col1 = np.stack([zero, -p[..., 2], p[..., 1]], axis=-1)  # e1 x p
        col2 = _rot_x(s1, c1, _e2_cross(va + vb))
        col3 = self.sigma[:, None] * _rot_x(s1, c1, _e2_cross(vb))
        J = np.stack([col1, col2, col3], axis=-1)
        B = self.basis
        p_B = (B @ p[..., None])[..., 0]
        J_B = B @ J
        if qd is None:
            return p_B, J_B
        qd = np.asarray(qd, dtype=float)
        d1, d2 = qd[..., 0], qd[..., 1]
        d23 = d2 + self.sigma * qd[..., 2]
        w = _rot_x(s1, c1, _e2_cross(d2[..., None] * va + d23[..., None] * vb))
        w1 = d1[..., None]
        # omega1 x (omega1 x p) + 2 omega1 x w + R_x (d2^2 e2 x (e2 x va) + d23^2 e2 x (e2 x vb)), omega1 = d1 e1
        cent = -(w1**2) * np.stack([zero, p[..., 1], p[..., 2]], axis=-1)
        cor = 2.0 * w1 * np.stack([zero, -w[..., 2], w[..., 1]], axis=-1)
        rel = _rot_x(s1, c1, -(d2[..., None] ** 2) * _xz(va) - (d23[..., None] ** 2) * _xz(vb))
        jd = cent + cor + rel
        return p_B, J_B, (B @ jd[..., None])[..., 0]


def _rot_x(s: np.ndarray, c: np.ndarray, v: np.ndarray) -> np.ndarray:
    """R_x v for (...) sin/cos and (..., 3) v."""
    return np.stack([v[..., 0], c * v[..., 1] - s * v[..., 2], s * v[..., 1] + c * v[..., 2]], axis=-1)


def _rot_y(t: np.ndarray, v: np.ndarray) -> np.ndarray:
    """R_y(t) v for (...) angles and (..., 3) v."""
    s, c = np.sin(t), np.cos(t)
    y = np.broadcast_to(v[..., 1], s.shape)
    return np.stack([c * v[..., 0] + s * v[..., 2], y, -s * v[..., 0] + c * v[..., 2]], axis=-1)


def _e2_cross(v: np.ndarray) -> np.ndarray:
    """e2 x v."""
    return np.stack([v[..., 2], np.zeros_like(v[..., 0]), -v[..., 0]], axis=-1)


def _xz(v: np.ndarray) -> np.ndarray:
    """-(e2 x (e2 x v)): the part of v normal to e2."""
    return np.stack([v[..., 0], np.zeros_like(v[..., 0]), v[..., 2]], axis=-1)


@dataclasses.dataclass(frozen=True, eq=False)
class RobotGeometry:
    """What the planners know of a robot (SI units, trunk frame, legs LF, RF, LH, RH); see the module docstring."""

    name: str
    """the robot's name."""
    mass: float
    """kg, the whole robot."""
    hips_B: np.ndarray
    """(4, 3) m, HAA origins."""
    shoulders_B: np.ndarray
    """(4, 3) m, centres of the legs' reach."""
    feet_B: np.ndarray
    """(4, 3) m, foot points in the standing pose."""
    leg_length: float
    """m, the longest leg's stretched reach from its shoulder (the paper's robot: thigh + shank)."""
    shank_length: float
    """m, knee to foot point."""
    foot_radius: float
    """m, foot sphere."""
    link_radius: float
    """m, thigh capsule (the shank's: :data:`planners.footholds.SHANK_RADIUS_SCALE` of it)."""
    min_reach: float
    """m, shoulder-to-foot-site distance below which a swing knot is too close to the hip."""
    scale: float
    """-, the description's leg length over the paper robot's
    (:attr:`~quad_uneven_env.robot.quadruped.RobotDescription.length_ratio`: 1 for the paper's robot)."""
    description: RobotDescription
    """the robot's description."""
    joint_ranges: np.ndarray
    """(12, 2) rad, each joint's [low, high] in ``JOINT_NAMES`` order."""
    two_link: TwoLinkLegs | None = None
    """the legs in the paper's closed form (the Table-1 robot), else None."""
    chain: LegChainModel | None = None
    """the legs' chain constants (any other robot), else None."""

    @property
    def tests_joint_ranges(self) -> bool:
        """The swing knots are tested against the joint ranges (the chain model; two-link legs are planned as the
        paper plans them, by reach alone)."""
        return self.two_link is None

    @classmethod
    def from_description(cls, desc: RobotDescription) -> RobotGeometry:
        """The planners' view of ``desc`` (two-link legs: hips, shoulders and standing feet at the trunk corners)."""
        if desc.two_link is not None:
            hips = desc.hip_positions_B
            return cls(
                name=desc.name, mass=desc.total_mass, hips_B=hips, shoulders_B=hips, feet_B=hips,
                leg_length=desc.two_link.thigh + desc.two_link.shank, shank_length=desc.two_link.shank,
                foot_radius=desc.foot_radius, link_radius=desc.link_radius,
                min_reach=PAPER_MIN_REACH * desc.length_ratio, scale=desc.length_ratio, description=desc,
                joint_ranges=desc.joint_ranges, two_link=desc.two_link,
            )  # fmt: skip
        chains = chain_constants(desc)
        # The HFE origin's offset along the HAA axis and normal to both axes moves the centre; the lateral offset
        # (along the HFE axis) is a radius: a foot whose planar distance from the HFE axis is d lies
        # sqrt(d^2 + lat^2) from the centre, whatever the HAA angle (exact without a normal offset).
        shoulders = np.array([c.h + c.alpha[0] * c.a1 + c.alpha[2] * c.n for c in chains])
        l1 = np.array([abs(c.U1) for c in chains])
        l2 = np.array([abs(c.U2) for c in chains])
        lat = np.array([c.lat for c in chains])
        leg_length = float(np.max(np.hypot(l1 + l2, lat)))
        # the fully bent knee: the smaller of the two KFE limits' distances, with the paper's margin
        bent = []
        for i, c in enumerate(chains):
            lo, hi = desc.joint_ranges[3 * i + 2]
            q3 = float(np.clip(lo if c.branch * c.sigma > 0 else hi, -np.pi, np.pi))
            bent.append(float(np.hypot(abs(c.U1 + c.U2 * np.exp(-1j * c.sigma * q3)), c.lat)))
        scale = desc.length_ratio
        return cls(
            name=desc.name, mass=desc.total_mass, hips_B=desc.hip_positions_B, shoulders_B=shoulders,
            feet_B=feet_positions_B(desc, desc.standing_joints), leg_length=leg_length,
            shank_length=float(np.max(l2)), foot_radius=desc.foot_radius, link_radius=desc.link_radius,
            min_reach=max(PAPER_MIN_REACH * scale, float(np.max(bent)) + 0.006 * scale), scale=scale,
            description=desc, chain=LegChainModel.from_description(desc), joint_ranges=desc.joint_ranges,
        )  # fmt: skip

    # ------------------------------------------------------------------ kinematics
    def ik(self, e: np.ndarray) -> np.ndarray:
        """Leg angles (..., 4, 3) (rad) placing the foot points at ``e`` (..., 4, 3) from the hips (trunk axes, m)."""
        e = np.asarray(e, dtype=float)
        if self.two_link is not None:
            return leg_ik_hip(e, self.two_link.thigh, self.two_link.shank, self.two_link.knee_signs)
        return np.stack([leg_ik_B(self.description, i, self.hips_B[i] + e[..., i, :]) for i in range(C.N_LEGS)], -2)

    def leg_ik(self, i: int, e: np.ndarray) -> np.ndarray:
        """Angles (..., 3) (rad) of leg ``i`` placing its foot point at ``e`` (..., 3) from its hip (trunk axes, m)."""
        if self.two_link is not None:
            return leg_ik_hip(e, self.two_link.thigh, self.two_link.shank, C.KNEE_SIGN[LEG_NAMES[i]])
        return leg_ik_B(self.description, i, self.hips_B[i] + np.asarray(e, dtype=float))

    def knee(self, i: int, q: np.ndarray) -> np.ndarray:
        """Knee (..., 3) of leg ``i`` from its hip (trunk axes, m) for its angles ``q`` (..., 3)."""
        if self.two_link is not None:
            return leg_fk_hip(q, self.two_link.thigh, 0.0)
        return knee_position_B(self.description.legs[i], q) - self.hips_B[i]

    def standing_legs(self, height: float) -> np.ndarray:
        """Leg angles (4, 3) (rad) with the feet under their standing points, ``height`` (m) below the shoulders
        (two-link legs: :meth:`~quad_uneven_env.robot.quadruped.TwoLinkLegs.standing_joints`)."""
        if self.two_link is not None:
            return self.two_link.standing_joints(height).reshape(4, 3)
        feet = self.feet_B.copy()
        feet[:, 2] = self.shoulders_B[:, 2] - height
        return self.ik(feet - self.hips_B)


def robot_geometry(robot: RobotDescription | RobotGeometry | None = None) -> RobotGeometry:
    """The planners' view of ``robot`` (None: the paper's robot), built once per description."""
    if isinstance(robot, RobotGeometry):
        return robot
    if robot is None:
        robot = load_robot("paper")
    if not isinstance(robot, RobotDescription):
        raise ValueError(f"robot must be a RobotDescription or a RobotGeometry, got {excerpt(robot)}")
    hit = _CACHE.get(id(robot))
    if hit is None or hit[0] is not robot:
        if len(_CACHE) >= 64:
            _CACHE.clear()
        hit = _CACHE[id(robot)] = (robot, RobotGeometry.from_description(robot))
    return hit[1]


_CACHE: dict[int, tuple[RobotDescription, RobotGeometry]] = {}
"""the geometry of each description seen (keyed by identity; descriptions are immutable)."""


__all__ = ["LegChainModel", "RobotGeometry", "robot_geometry"]
