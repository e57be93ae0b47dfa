"""The three dynamics backends on every shipped robot, against MuJoCo's own functions on the simulated model.

For the paper's robot and the URDF robots (hip offsets, rotated joint frames, hip links with mass, full
inertia tensors), each backend built from the robot's description and from its MjModel must give MuJoCo's
``mj_fullM``, ``qfrc_bias`` (and at zero velocity the gravity term), the foot sites' ``mj_jacSite`` and
``mj_jacDot @ qvel`` on random states: any base pose and orientation, velocities, joints within their limits.
"""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from quad_uneven_env import constants as C
from quad_uneven_env.robot.description import load_robot
from quad_uneven_env.robot.dynamics import BACKENDS, make_dynamics
from quad_uneven_env.robot.dynamics.chains import LegChains
from quad_uneven_env.robot.dynamics.explicit_backend import ExplicitDynamics
from quad_uneven_env.robot.model import robot_mjcf

ROBOTS = ("paper", "hyq", "anymal_c", "go1", "solo12")
N_STATES = 60
TOL = 1e-8
FIELDS = ("M", "h", "G", "J_feet", "Jdot_qdot_feet")


def simulated_model(name: str) -> mujoco.MjModel:
    """The robot alone as the env simulates it."""
    return mujoco.MjModel.from_xml_string(robot_mjcf(load_robot(name)))


def random_states(model: mujoco.MjModel, rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    """n random states: base anywhere in a 4 m cube, any orientation, joints within their ranges,
    |v| <= 2 m/s, |w|, |qd| <= 5 rad/s."""
    qpos = np.zeros((n, C.NQ))
    qpos[:, :3] = rng.uniform(-2.0, 2.0, (n, 3))
    quat = rng.normal(size=(n, 4))
    qpos[:, 3:7] = quat / np.linalg.norm(quat, axis=1, keepdims=True)
    qpos[:, 7:] = rng.uniform(model.jnt_range[1:, 0], model.jnt_range[1:, 1], (n, C.N_JOINTS))
    qvel = np.concatenate([rng.uniform(-2.0, 2.0, (n, 3)), rng.uniform(-5.0, 5.0, (n, 15))], axis=1)
    return qpos, qvel


def mujoco_reference(model: mujoco.MjModel, qpos: np.ndarray, qvel: np.ndarray) -> dict[str, np.ndarray]:
    """MuJoCo's mj_fullM, qfrc_bias, qfrc_bias at zero velocity, mj_jacSite and mj_jacDot @ qvel of the feet."""
    d = mujoco.MjData(model)
    n = len(qpos)
    out = {f: np.empty((n, *s)) for f, s in zip(FIELDS, ((18, 18), (18,), (18,), (4, 3, 18), (4, 3)), strict=True)}
    jdot = np.empty((3, C.NV))
    for k in range(n):
        d.qpos[:], d.qvel[:] = qpos[k], qvel[k]
        mujoco.mj_forward(model, d)
        mujoco.mj_fullM(model, d, out["M"][k])
        out["h"][k] = d.qfrc_bias
        for i, s in enumerate(C.FOOT_SITES):
            site = model.site(s).id
            mujoco.mj_jacSite(model, d, out["J_feet"][k, i], None, site)
            mujoco.mj_jacDot(model, d, jdot, None, d.site_xpos[site], model.site_bodyid[site])
            out["Jdot_qdot_feet"][k, i] = jdot @ qvel[k]
        d.qvel[:] = 0.0
        mujoco.mj_forward(model, d)
        out["G"][k] = d.qfrc_bias
    return out


@pytest.fixture(scope="module", params=ROBOTS)
def robot(request) -> tuple[str, mujoco.MjModel, np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """(name, simulated model, qpos, qvel, MuJoCo's terms) of one robot."""
    model = simulated_model(request.param)
    qpos, qvel = random_states(model, np.random.default_rng(2025), N_STATES)
    return request.param, model, qpos, qvel, mujoco_reference(model, qpos, qvel)


def _terms(dyn, qpos: np.ndarray, qvel: np.ndarray) -> dict[str, np.ndarray]:
    ts = [dyn.terms(qpos[k], qvel[k]) for k in range(len(qpos))]
    return {f: np.array([getattr(t, f) for t in ts]) for f in FIELDS}


@pytest.mark.parametrize("source", ("description", "model"))
@pytest.mark.parametrize("backend", BACKENDS)
def test_backend_matches_mujoco(robot, backend, source):
    name, model, qpos, qvel, ref = robot
    dyn = make_dynamics(backend, load_robot(name) if source == "description" else model)
    got = _terms(dyn, qpos, qvel)
    errors = {f: float(np.abs(got[f] - ref[f]).max()) for f in FIELDS}
    assert max(errors.values()) < TOL, f"{name} {backend} from its {source}: {errors}"
    # not a vacuous comparison: velocity-dependent forces and the feet's accelerations are large
    scale = load_robot(name).total_mass
    assert np.abs(ref["h"] - ref["G"]).max() > 0.1 * scale
    assert np.abs(ref["Jdot_qdot_feet"]).max() > 1.0


def test_explicit_batch_equals_single_states(robot):
    name, _, qpos, qvel, ref = robot
    dyn = make_dynamics("explicit", load_robot(name))
    batch = dyn.terms(qpos, qvel)
    for f in FIELDS:
        assert np.abs(getattr(batch, f) - ref[f]).max() < TOL
    single = dyn.terms(qpos[3], qvel[3])
    for f in FIELDS:
        np.testing.assert_array_equal(getattr(single, f), getattr(batch, f)[3])


def test_explicit_kernel_equals_numpy_twin(robot):
    name, _, qpos, qvel, _ = robot
    dyn = ExplicitDynamics(load_robot(name))
    fast, ref = dyn.terms(qpos, qvel), dyn.terms_numpy(qpos, qvel)
    for f in FIELDS:
        np.testing.assert_allclose(getattr(fast, f), getattr(ref, f), rtol=0, atol=1e-10, err_msg=f"{name} {f}")


def test_chains_of_the_model_equal_the_description(robot):
    """Read back from the MjModel the env simulates, the chains are the description's (the MJCF loses nothing);
    the paper's robot has a massless hip link: its hip-link mass is zero in both."""
    name, model, _, _, _ = robot
    a, b = LegChains.from_description(load_robot(name)), LegChains.from_mjmodel(model)
    for field in ("joint_pos", "joint_rot", "joint_axis", "link_mass", "link_com", "link_inertia", "foot", "armature"):
        np.testing.assert_allclose(getattr(a, field), getattr(b, field), rtol=0, atol=1e-12, err_msg=field)
    assert a.total_mass == pytest.approx(b.total_mass, rel=1e-12)
    assert (np.all(a.link_mass[:, 0] == 0.0)) == (name == "paper")


def test_model_source_reads_randomized_masses():
    """Backends built from an MjModel read its masses and inertias as they are (the env randomizes them)."""
    model = simulated_model("go1")
    for leg in C.LEG_NAMES:
        b = model.body(C.shank_body(leg)).id
        model.body_mass[b] *= 1.7
        model.body_inertia[b] *= 1.7
        model.body_ipos[b] += [0.01, -0.005, 0.002]
    mujoco.mj_setConst(model, mujoco.MjData(model))
    qpos, qvel = random_states(model, np.random.default_rng(5), 10)
    ref = mujoco_reference(model, qpos, qvel)
    nominal = _terms(make_dynamics("explicit", load_robot("go1")), qpos, qvel)
    assert np.abs(nominal["M"] - ref["M"]).max() > 1e-3  # the draw changed the robot
    for backend in BACKENDS:
        got = _terms(make_dynamics(backend, model), qpos, qvel)
        for f in FIELDS:
            assert np.abs(got[f] - ref[f]).max() < TOL, (backend, f)


def test_other_structures_are_refused():
    with pytest.raises(ValueError, match=r"robot must be a RobotDescription or a mujoco\.MjModel, got str"):
        make_dynamics("explicit", "go1")
    model = simulated_model("go1")
    model.jnt_pos[model.joint("RF_HFE").id] = [0.0, 0.01, 0.0]
    with pytest.raises(ValueError, match="joint RF_HFE must sit at its body's origin"):
        make_dynamics("pinocchio", model)
    xml = robot_mjcf(load_robot("go1")).replace(
        '<site name="LH_foot"', '<body name="extra"><inertial pos="0 0 0" mass="1" diaginertia="1 1 1"/></body>'
        '<site name="LH_foot"',
    )  # fmt: skip
    with pytest.raises(ValueError, match="body 'extra' carries no leg joint"):
        make_dynamics("explicit", mujoco.MjModel.from_xml_string(xml))
    xml = robot_mjcf(load_robot("go1")).replace('name="RH_foot"', 'name="RH_toe"')
    with pytest.raises(ValueError, match="RH_foot"):
        make_dynamics("mujoco", mujoco.MjModel.from_xml_string(xml))


def test_paper_robot_reduces_to_appendix_a():
    """On the paper's robot the chains give Appendix A's closed form: the foot at ``hip + R_x(q1) [u, 0, s]`` with
    ``u = -l1 sin q2 - l2 sin(q2 + q3)``, ``s = -l1 cos q2 - l2 cos(q2 + q3)``, so its leg Jacobian columns are
    ``e_x x R_x [u, 0, s]``, ``R_x [s, 0, -u]`` and ``R_x [-l2 cos(q2 + q3), 0, l2 sin(q2 + q3)]`` (trunk frame)."""
    desc = load_robot("paper")
    l1, l2 = desc.two_link.thigh, desc.two_link.shank
    model = simulated_model("paper")
    qpos, qvel = random_states(model, np.random.default_rng(4), 20)
    t = make_dynamics("explicit", desc).terms(qpos, qvel)
    R = np.array([_quat_matrix(q) for q in qpos[:, 3:7]])
    for i in range(C.N_LEGS):
        q1, q2, q3 = qpos[:, 7 + 3 * i], qpos[:, 8 + 3 * i], qpos[:, 9 + 3 * i]
        c1, s1 = np.cos(q1), np.sin(q1)
        Rx = np.zeros((len(q1), 3, 3))
        Rx[:, 0, 0], Rx[:, 1, 1], Rx[:, 1, 2], Rx[:, 2, 1], Rx[:, 2, 2] = 1.0, c1, -s1, s1, c1
        u = -l1 * np.sin(q2) - l2 * np.sin(q2 + q3)
        s = -l1 * np.cos(q2) - l2 * np.cos(q2 + q3)
        zero = np.zeros_like(u)
        p = (Rx @ np.stack([u, zero, s], -1)[..., None])[..., 0]
        cols = [
            np.cross([1.0, 0.0, 0.0], p),
            (Rx @ np.stack([s, zero, -u], -1)[..., None])[..., 0],
            (Rx @ np.stack([-l2 * np.cos(q2 + q3), zero, l2 * np.sin(q2 + q3)], -1)[..., None])[..., 0],
        ]
        expected = R @ np.stack(cols, -1)  # world frame
        np.testing.assert_allclose(t.J_feet[:, i, :, 6 + 3 * i : 9 + 3 * i], expected, rtol=0, atol=1e-12)


def _quat_matrix(q: np.ndarray) -> np.ndarray:
    R = np.empty(9)
    mujoco.mju_quat2Mat(R, q)
    return R.reshape(3, 3)
