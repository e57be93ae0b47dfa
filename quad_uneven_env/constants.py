"""Names and orders shared by every module: leg order, joint order, MJCF names.

Every per-leg array in the project is in ``LEG_NAMES`` order (LF, RF, LH, RH) and every
per-joint array in ``JOINT_NAMES`` order (legs in leg order, HAA, HFE, KFE per leg).

Canonical coordinates are MuJoCo's:
``qpos = [p_base_W (3), quat_WB (w, x, y, z) (4), q_joints (12)]`` and
``qvel = [v_base_W (3), omega_base_B (3), qd_joints (12)]``.
"""

from __future__ import annotations

LEG_NAMES: tuple[str, ...] = ("LF", "RF", "LH", "RH")
"""Leg order of every per-leg array: left front, right front, left hind, right hind."""

JOINT_KINDS: tuple[str, ...] = ("HAA", "HFE", "KFE")
"""Joints of a leg, proximal to distal: hip roll (about body x), hip pitch (y), knee pitch (y)."""

N_LEGS = 4
N_LEG_JOINTS = 3
N_JOINTS = N_LEGS * N_LEG_JOINTS  # 12 actuated joints
NQ = 7 + N_JOINTS  # 19
NV = 6 + N_JOINTS  # 18

# Sign of each leg's position relative to the body centre: (x, y) multipliers of the
# half length / half width of the body.
LEG_SIGN_X: dict[str, float] = {"LF": 1.0, "RF": 1.0, "LH": -1.0, "RH": -1.0}
LEG_SIGN_Y: dict[str, float] = {"LF": 1.0, "RF": -1.0, "LH": 1.0, "RH": -1.0}
# X configuration: front knees bend backwards (KFE < 0), hind knees forwards (KFE > 0).
KNEE_SIGN: dict[str, float] = {"LF": -1.0, "RF": -1.0, "LH": 1.0, "RH": 1.0}

# --- MJCF names ---------------------------------------------------------------------
TRUNK_BODY = "trunk"
TRUNK_GEOM = "trunk_geom"
ROOT_JOINT = "root"
TERRAIN_HFIELD = "terrain"
TERRAIN_GEOM = "terrain_geom"
TRACK_CAMERA = "track"


def thigh_body(leg: str) -> str:
    """MJCF body carrying HAA and HFE of ``leg`` (the thigh link)."""
    return f"{leg}_thigh"


def shank_body(leg: str) -> str:
    """MJCF body carrying KFE of ``leg`` (the shank link)."""
    return f"{leg}_shank"


def joint_name(leg: str, kind: str) -> str:
    """MJCF joint name, e.g. ``joint_name("LF", "KFE") == "LF_KFE"``."""
    return f"{leg}_{kind}"


def foot_site(leg: str) -> str:
    """MJCF site at the foot point of ``leg``, e.g. ``"LF_foot"``."""
    return f"{leg}_foot"


def foot_geom(leg: str) -> str:
    """MJCF collision sphere of the foot of ``leg``."""
    return f"{leg}_foot_geom"


def hip_site(leg: str) -> str:
    """MJCF site at the hip (HAA/HFE axes intersection) of ``leg``."""
    return f"{leg}_hip"


JOINT_NAMES: tuple[str, ...] = tuple(joint_name(leg, k) for leg in LEG_NAMES for k in JOINT_KINDS)
FOOT_SITES: tuple[str, ...] = tuple(foot_site(leg) for leg in LEG_NAMES)
FOOT_GEOMS: tuple[str, ...] = tuple(foot_geom(leg) for leg in LEG_NAMES)
HIP_SITES: tuple[str, ...] = tuple(hip_site(leg) for leg in LEG_NAMES)
ACTUATOR_NAMES: tuple[str, ...] = tuple(f"{j}_motor" for j in JOINT_NAMES)


# Contact sensors (MuJoCo computes them in C every physics step).
def foot_contact_sensor(leg: str) -> str:
    """Net-force contact sensor between the foot of ``leg`` and the terrain."""
    return f"{leg}_foot_contact"


ROBOT_CONTACT_SENSOR = "robot_terrain_contact"
TRUNK_CONTACT_SENSOR = "trunk_terrain_contact"

# Collision groups: robot geoms collide with the terrain only, never with each other.
ROBOT_CONTYPE, ROBOT_CONAFFINITY = 2, 1
TERRAIN_CONTYPE, TERRAIN_CONAFFINITY = 1, 2
