"""Property test: the env's compiled measurement equals the numpy references at every step of hostile rollouts.

Random and bang-bang torques over the whole motor range, at ``frame_skip`` 1, 2 and 10, make feet
touch, slide, separate and carry no force while still in contact (MuJoCo's netforce sensor then
reports the point (0, 0, 0)), put the robot on its back and pile feet together. At every step the
env's contacts, COG, stability index and edge moments are compared with
``physics.measure_contacts_reference`` (the raw contact list; ``measure_contacts``, the numpy reading of
the same sensors, too) and the numpy (vectorised) path of
``stability.stability_index``. The fast suite runs a few thousand steps; ``-m slow`` the rest
(more than 20,000 in all).
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import quad_uneven_env  # noqa: F401
from quad_uneven_env.physics import MIN_FOOT_FORCE, measure_contacts, measure_contacts_reference
from quad_uneven_env.stability import NO_SUPPORT, stability_index

# Relaxed limits keep an episode going while the robot thrashes on the ground (more contact states).
THRASH = {"trunk_contact": False, "min_base_height": 0.0, "max_tilt_deg": 180.0, "max_base_height": 10.0}


def numpy_index(cog, cog_acc, feet, mass, g):
    """The numpy path of the stability index (the compiled one serves the single-instant call)."""
    index, moments = stability_index(cog[None], cog_acc[None], feet, mass, g)
    return float(index[0]), moments[0]


def check_step(u, stats) -> None:
    """The measurement the env just made (its buffers) against the references, on the same MuJoCo data."""
    meas, d, m = u._meas, u.data, u.model
    mass, g = u.idx.total_mass, -m.opt.gravity[2]
    ref = measure_contacts_reference(m, d, u.idx, u.robot.foot_radius)
    np.testing.assert_array_equal(meas.foot_contact, ref.foot_contact)
    np.testing.assert_allclose(meas.foot_forces, ref.foot_forces, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(meas.foot_points, ref.foot_points, rtol=0, atol=1e-9)
    np.testing.assert_allclose(meas.total_force, ref.total_force, rtol=1e-9, atol=1e-9)
    assert meas.trunk_contact == ref.trunk_contact and meas.other_contact == ref.other_contact
    sensors = measure_contacts(m, d, u.idx, u.robot.foot_radius)  # the numpy twin from the same sensors
    np.testing.assert_array_equal(sensors.foot_contact, ref.foot_contact)
    np.testing.assert_allclose(sensors.foot_points, ref.foot_points, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(meas.cog, d.subtree_com[u.idx.trunk_body])
    np.testing.assert_allclose(meas.cog_acc, ref.total_force / mass + m.opt.gravity, rtol=1e-12, atol=1e-9)
    index, moments = numpy_index(meas.cog, meas.cog_acc, ref.foot_points[ref.foot_contact], mass, g)
    assert np.isfinite(meas.index) or meas.index == index == NO_SUPPORT, (meas.index, index)
    np.testing.assert_allclose(meas.index, index, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(meas.moments, moments, rtol=1e-9, atol=1e-9)
    assert np.isfinite(meas.obs).all()
    # What the rollout exercised.
    unloaded = meas.foot_contact & (np.linalg.norm(meas.foot_forces, axis=1) < MIN_FOOT_FORCE)
    stats["unloaded_feet"] += int(unloaded.sum())
    stats["steps"] += 1
    stats["no_support"] += int(meas.index == NO_SUPPORT)


def rollout(frame_skip: int, seed: int, n_steps: int, torques: str, termination=None) -> dict[str, int]:
    """Drive one env for ``n_steps`` control steps (resetting after every episode end), checking every step."""
    env = gym.make("QuadUneven-v0", frame_skip=frame_skip, termination=termination, max_episode_steps=400)
    u = env.unwrapped
    rng = np.random.default_rng(1000 + seed)
    stats = {"steps": 0, "unloaded_feet": 0, "no_support": 0, "diverged": 0, "episodes": 1}
    env.reset(seed=seed)
    for _ in range(n_steps):
        action = rng.choice([-1.0, 1.0], 12) if torques == "bang_bang" else rng.uniform(-1.0, 1.0, 12)
        _, _, terminated, truncated, info = env.step(action)
        if info["diverged"]:
            stats["diverged"] += 1  # the buffers hold the last good measurement: nothing new to check
        else:
            check_step(u, stats)
        if terminated or truncated:
            env.reset()
            stats["episodes"] += 1
    env.close()
    return stats


def test_the_reported_zero_force_state_is_measured_like_the_reference():
    """frame_skip 1, seed 1, two bang-bang steps of default_rng(1001): two feet in contact without force."""
    env = gym.make("QuadUneven-v0", frame_skip=1)
    u = env.unwrapped
    env.reset(seed=1)
    rng = np.random.default_rng(1001)
    stats = {"steps": 0, "unloaded_feet": 0, "no_support": 0}
    for _ in range(2):
        _, _, _, _, info = env.step(rng.choice([-1.0, 1.0], 12))
        check_step(u, stats)
    assert stats["unloaded_feet"] >= 1
    assert np.isfinite(info["stability_index"])


FAST = [  # (frame_skip, seed, steps, torques, termination): 2,600 steps
    (1, 1, 800, "bang_bang", None),
    (1, 2, 500, "uniform", THRASH),
    (2, 3, 500, "bang_bang", THRASH),
    (2, 4, 400, "uniform", None),
    (10, 5, 200, "bang_bang", None),
    (10, 6, 200, "uniform", None),
]
SLOW = [  # 19,000 more steps (a robot thrashing on the ground makes MuJoCo's steps slow)
    (1, 11, 1500, "bang_bang", None),
    (1, 12, 1500, "uniform", THRASH),
    (1, 13, 1500, "bang_bang", THRASH),
    (1, 14, 2000, "bang_bang", THRASH),
    (2, 21, 1500, "bang_bang", THRASH),
    (2, 22, 1500, "uniform", None),
    (2, 23, 1500, "uniform", THRASH),
    (2, 24, 2000, "bang_bang", THRASH),
    (10, 31, 2000, "bang_bang", THRASH),
    (10, 32, 2000, "uniform", THRASH),
    (10, 33, 2000, "bang_bang", None),
]


@pytest.mark.parametrize(
    "frame_skip, seed, steps, torques, termination", [*FAST, *(pytest.param(*c, marks=pytest.mark.slow) for c in SLOW)]
)
def test_measurement_equals_references_under_hostile_torques(frame_skip, seed, steps, torques, termination):
    stats = rollout(frame_skip, seed, steps, torques, termination)
    assert stats["steps"] + stats["diverged"] == steps
    assert stats["diverged"] == 0  # none so far: every step was checked


def test_the_property_test_covers_twenty_thousand_steps_and_every_frame_skip():
    assert sum(c[2] for c in FAST + SLOW) >= 20_000
    assert {c[0] for c in FAST} == {c[0] for c in SLOW} == {1, 2, 10}
    assert {c[3] for c in FAST + SLOW} == {"bang_bang", "uniform"}
