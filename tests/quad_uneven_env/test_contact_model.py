"""The terrain contact model: stiff contacts, few and well-placed contacts, standing unchanged.

The reference for the forces is MuJoCo's own ``mj_contactForce`` over the raw contact list (not
the env's sensor path), and the former (20 ms) model's values are stored below with their tolerances
(docs/results.md section 7).
"""

from __future__ import annotations

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import quad_uneven_env  # noqa: F401  (registers QuadUneven-v0)
from quad_uneven_env import constants as C
from quad_uneven_env.robot.model import PhysicsOptions
from quad_uneven_env.stability import stability_index

# Fixed test state: rough terrain seed 0, no reset noise, joint_pd servos holding the standing
# pose (zero action) for 50 control steps (1 s). Values of the former 20 ms model (elliptic
# cones, contact time constant 0.02 s), from mj_contactForce on that state: force on each foot (N,
# world, leg order LF, RF, LH, RH) and the stability index (N m).
PRE13_FOOT_FORCES = np.array(
    [
        [-20.78, 0.14, 123.43],
        [-21.15, 0.18, 121.72],
        [21.21, -0.17, 121.92],
        [20.82, -0.16, 123.44],
    ]
)
PRE13_INDEX = 90.737
FORCE_TOL = 2.0
"""N per component: 1.6 % of the mean foot load (122.6 N); the models differ by <= 0.4 N."""
INDEX_TOL = 0.5
"""N m: 0.55 % of the index; the models differ by 0.23 N m."""


def _standing_env(**kwargs):
    env = gym.make("QuadUneven-v0", terrain="rough", action_mode="joint_pd", reset_noise_scale=0.0, **kwargs)
    env.reset(seed=0)
    info = {}
    for _ in range(50):
        _, _, terminated, _, info = env.step(np.zeros(12))
        assert not terminated
    return env, info


def _reference_forces(env):
    """Per-foot forces on the robot (4, 3), their force-weighted points (4, 3) and the total force (3,)
    from mj_contactForce over the raw contact list."""
    u = env.unwrapped
    m, d, idx = u.model, u.data, u.idx
    forces, points, weights, total = np.zeros((4, 3)), np.zeros((4, 3)), np.zeros(4), np.zeros(3)
    f6 = np.zeros(6)
    for i in range(d.ncon):
        c = d.contact[i]
        g1, g2 = c.geom
        mujoco.mj_contactForce(m, d, i, f6)
        f_world = c.frame.reshape(3, 3).T @ f6[:3]  # force of geom1 on geom2
        robot = g2 if idx.robot_geoms[g2] else g1
        f_robot = f_world if idx.robot_geoms[g2] else -f_world
        total += f_robot
        leg = idx.foot_of_geom[robot]
        if leg >= 0:
            w = np.linalg.norm(f6[:3])
            forces[leg] += f_robot
            points[leg] += w * c.pos
            weights[leg] += w
    return forces, points / np.maximum(weights, 1e-12)[:, None], total


def test_contact_parameters():
    """Feet and terrain carry the contact time constant, the limbs (trunk, thighs, shanks) the stiffest
    stable one with priority over the terrain; both respect MuJoCo's 2-step stability bound."""
    env = gym.make("QuadUneven-v0")
    m = env.unwrapped.model
    p = PhysicsOptions()
    assert m.opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC
    assert m.opt.impratio == pytest.approx(10.0)
    assert m.opt.jacobian == mujoco.mjtJacobian.mjJAC_SPARSE
    assert m.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_NATIVECCD
    names = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, i) for i in range(m.ngeom)]
    limbs = np.array([n == C.TRUNK_GEOM or n.endswith(("_thigh_geom", "_shank_geom")) for n in names])
    assert limbs.sum() == 9
    np.testing.assert_allclose(
        m.geom_solref[~limbs], np.tile([p.contact_timeconst, p.contact_dampratio], ((~limbs).sum(), 1))
    )
    np.testing.assert_allclose(m.geom_solref[limbs], np.tile([2.0 * m.opt.timestep, p.contact_dampratio], (9, 1)))
    np.testing.assert_array_equal(m.geom_priority, limbs.astype(int))
    # The limbs' own friction is the terrain's: priority changes the stiffness, not the friction.
    np.testing.assert_array_equal(m.geom_friction[limbs], np.tile(m.geom_friction[names.index(C.TERRAIN_GEOM)], (9, 1)))
    assert p.contact_timeconst >= 2.0 * m.opt.timestep
    assert p.contact_timeconst < 0.02  # stiffer than MuJoCo's default
    assert PhysicsOptions(timestep=0.001).limb_timeconst() == pytest.approx(0.002)
    assert PhysicsOptions(limb_contact_timeconst=0.01).limb_timeconst() == pytest.approx(0.01)


def test_standing_forces_and_index_match_reference_and_pre13_model():
    env, info = _standing_env()
    u = env.unwrapped
    forces, points, total = _reference_forces(env)
    # The env's measurement (sensor path) equals MuJoCo's contact forces on the same state.
    np.testing.assert_allclose(info["contact_forces"], forces, atol=1e-6)
    mass = u.idx.total_mass
    cog = u.data.subtree_com[u.idx.trunk_body]
    index, _ = stability_index(cog, total / mass + u.model.opt.gravity, points, mass)
    assert info["stability_index"] == pytest.approx(float(index), abs=1e-6)
    # Static equilibrium: the terrain carries the weight.
    assert total[2] == pytest.approx(mass * -u.model.opt.gravity[2], rel=2e-3)
    # Within the documented tolerance of the former 20 ms model.
    np.testing.assert_allclose(forces, PRE13_FOOT_FORCES, atol=FORCE_TOL)
    assert float(index) == pytest.approx(PRE13_INDEX, abs=INDEX_TOL)


def test_standing_feet_make_few_upright_shallow_contacts():
    """Standing: at most 3 contacts per foot (pre-13: up to 6), normals within 15 deg of the (flat)
    surface normal, penetration < 0.5 mm (pre-13: ~1 mm), no other robot geom touching."""
    env, _ = _standing_env()
    u = env.unwrapped
    d, idx = u.data, u.idx
    geoms = d.contact.geom[: d.ncon]
    for leg, g in enumerate(idx.foot_geoms):
        rows = np.flatnonzero((geoms == g).any(axis=1))
        assert 1 <= len(rows) <= 3, f"foot {leg}: {len(rows)} contacts"
        assert np.all(np.abs(d.contact.frame[rows, 2]) > np.cos(np.radians(15.0)))
        assert np.all(-d.contact.dist[rows] < 5e-4)
    assert np.isin(geoms, [*idx.foot_geoms, idx.terrain_geom]).all()


@pytest.mark.parametrize("seed", [0, 1])
def test_random_torques_contact_count_bounded(seed):
    """Uniform random torques on rough terrain (resets included): the mean contact count stays well
    below the pre-13 model's (88-95 over the same 300 steps; 50-72 now) and below MuJoCo's cap per pair."""
    env = gym.make("QuadUneven-v0", terrain="rough")
    u = env.unwrapped
    env.action_space.seed(seed)
    env.reset(seed=seed)
    counts, per_foot = [], []
    for _ in range(300):
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        geoms = u.data.contact.geom[: u.data.ncon]
        counts.append(u.data.ncon)
        per_foot += [int((geoms == g).any(axis=1).sum()) for g in u.idx.foot_geoms]
        if terminated or truncated:
            env.reset()
    assert np.mean(counts) < 80.0
    assert max(per_foot) < mujoco.mjMAXCONPAIR


def _foot_depths(setup=None, seeds=(0, 1), steps=400) -> np.ndarray:
    """Depth (m) of every foot below the height field's surface after each step of uniform random torques."""
    out = []
    for seed in seeds:
        env = gym.make("QuadUneven-v0", terrain="rough")
        u = env.unwrapped
        if setup is not None:
            setup(u.model)
        sites = [mujoco.mj_name2id(u.model, mujoco.mjtObj.mjOBJ_SITE, C.foot_site(leg)) for leg in C.LEG_NAMES]
        env.action_space.seed(seed)
        env.reset(seed=seed)
        for _ in range(steps):
            _, _, term, trunc, _ = env.step(env.action_space.sample())
            p = u.data.site_xpos[sites]
            out.append(u.terrain.height(p[:, 0], p[:, 1]) - (p[:, 2] - u.robot.foot_radius))
            if term or trunc:
                env.reset()
    return np.concatenate(out)


def _native_ccd_soft_limbs(m: mujoco.MjModel) -> None:
    """The former model: MuJoCo's native convex collider, every contact at 7.5 ms, no limb priority."""
    m.opt.disableflags &= ~int(mujoco.mjtDisableBit.mjDSBL_NATIVECCD)
    m.geom_solref[:, 0] = PhysicsOptions().contact_timeconst
    m.geom_priority[:] = 0


def test_impacting_feet_are_not_buried_in_the_height_field():
    """Under random torques feet hit the ground at several m/s. With libccd and stiff limbs a foot is
    rarely more than 1 cm below the surface; the former model (native CCD) buried feet for about half
    of all foot-steps, held by the prisms' interior side walls."""
    ours = _foot_depths()
    former = _foot_depths(_native_ccd_soft_limbs)
    assert np.mean(ours > 0.01) < 0.06, np.mean(ours > 0.01)
    assert np.mean(former > 0.01) > 0.3, np.mean(former > 0.01)
