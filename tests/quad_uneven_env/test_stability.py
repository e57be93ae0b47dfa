"""The stability index against hand-computed cases."""

from __future__ import annotations

import numpy as np
import pytest

from quad_uneven_env.stability import NO_SUPPORT, normalized_stability_index, order_clockwise, stability_index

M, G = 50.0, 9.81
SQUARE = np.array([[1.0, 1.0, 0.0], [-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [-1.0, 1.0, 0.0]])  # scrambled order


def test_square_static_cog_at_centre():
    index, moments = stability_index([0, 0, 0.5], [0, 0, 0], SQUARE, M, G)
    # Each edge is 1 m from the centre: moment m g * 1.
    np.testing.assert_allclose(moments, M * G * 1.0)
    assert index == pytest.approx(M * G)


def test_offset_cog_gives_distance_to_nearest_edge():
    index, moments = stability_index([0.3, -0.2, 0.5], [0, 0, 0], SQUARE, M, G)
    assert sorted(np.round(moments / (M * G), 12)) == pytest.approx(sorted([0.7, 1.3, 0.8, 1.2]))
    assert index == pytest.approx(M * G * 0.7)
    norm_index, _ = normalized_stability_index([0.3, -0.2, 0.5], [0, 0, 0], SQUARE, M, G)
    assert norm_index == pytest.approx(0.7)


def test_cog_outside_an_edge_is_negative():
    index, _ = stability_index([1.25, 0.0, 0.5], [0, 0, 0], SQUARE, M, G)
    assert index == pytest.approx(-0.25 * M * G)


def test_lateral_acceleration_tips_over_an_edge():
    h = 0.5
    # Static margin 1 m to the edge y = -1. Accelerating towards +y with a puts the inertial
    # force m a towards -y at height h: moment about y = -1 is m g * 1 - m a h.
    a = 25.0  # beyond g * distance / height = 19.6 m/s^2
    index, _ = stability_index([0, 0, h], [0, a, 0], SQUARE, M, G)
    assert index == pytest.approx(M * G * 1.0 - M * a * h)
    assert index < 0
    # Small acceleration: still stable, reduced margin.
    index2, _ = stability_index([0, 0, h], [0, 2.0, 0], SQUARE, M, G)
    assert index2 == pytest.approx(M * G - M * 2.0 * h)


def test_vertical_acceleration_scales_the_margin():
    index, _ = stability_index([0, 0, 0.5], [0, 0, 2.0], SQUARE, M, G)
    assert index == pytest.approx(M * (G + 2.0) * 1.0)


def test_feet_at_different_heights():
    # Edge from (1, 1, 0.4) to (1, -1, 0.0): a sloped edge in the plane x = 1. With a static
    # COG at (0, 0, z) the moment about that edge is m g times the horizontal distance of the COG
    # to the edge line's vertical plane, scaled by the horizontal part of kappa.
    feet = np.array([[1.0, 1.0, 0.4], [1.0, -1.0, 0.0], [-1.0, -1.0, 0.0], [-1.0, 1.0, 0.0]])
    index, moments = stability_index([0, 0, 0.5], [0, 0, 0], feet, M, G)
    kappa = np.array([0.0, -2.0, -0.4]) / np.linalg.norm([0.0, -2.0, -0.4])
    r = np.array([0, 0, 0.5]) - feet[0]
    expected = kappa @ np.cross(r, [0, 0, -M * G])
    assert expected == pytest.approx(M * G * 1.0 * 2.0 / np.sqrt(4.16))
    # Both edges meeting at the raised foot are sloped by the same amount.
    assert np.isclose(moments, expected).sum() == 2
    assert index == pytest.approx(min(expected, M * G))
    # A horizontal acceleration along +x now matters through the height difference.
    _, moments_acc = stability_index([0, 0, 0.5], [1.0, 0, 0], feet, M, G)
    assert not np.allclose(moments_acc, moments)


def test_three_feet_triangle():
    feet = np.array([[0.0, 1.0, 0.0], [1.0, -1.0, 0.0], [-1.0, -1.0, 0.0]])
    index, moments = stability_index([0, 0, 0.3], [0, 0, 0], feet, M, G)
    assert moments.shape == (3,)
    # Distances from the origin to the edges: y = -1 -> 1; the slanted edges y = 1 - 2|x| -> 1/sqrt(5).
    assert sorted(moments / (M * G)) == pytest.approx(sorted([1.0, 1 / np.sqrt(5), 1 / np.sqrt(5)]))
    assert index == pytest.approx(M * G / np.sqrt(5))


def test_fewer_than_three_feet_is_not_stable():
    index, moments = stability_index([0, 0, 0.5], [0, 0, 0], SQUARE[:2], M, G)
    assert index == NO_SUPPORT
    assert moments.shape == (2,) and np.all(moments == NO_SUPPORT)


def test_vectorised_over_time_matches_loop(rng):
    T = 17
    cog = rng.normal(scale=0.3, size=(T, 3))
    acc = rng.normal(size=(T, 3))
    index, moments = stability_index(cog, acc, SQUARE, M, G)
    assert index.shape == (T,) and moments.shape == (T, 4)
    for t in range(T):
        i_t, m_t = stability_index(cog[t], acc[t], SQUARE, M, G)
        assert index[t] == pytest.approx(i_t)
        np.testing.assert_allclose(moments[t], m_t)


def test_clockwise_order():
    order = order_clockwise(SQUARE)
    pts = SQUARE[order, :2]
    # Signed area of a clockwise polygon is negative.
    area = 0.5 * np.sum(pts[:, 0] * np.roll(pts[:, 1], -1) - np.roll(pts[:, 0], -1) * pts[:, 1])
    assert area < 0


def test_bad_shapes_raise():
    with pytest.raises(ValueError, match="cog"):
        stability_index([0, 0], [0, 0, 0], SQUARE, M)


def test_coincident_feet_give_the_polygon_of_the_distinct_ones():
    # Two feet report the same contact point: the polygon is the triangle of the three distinct
    # points (1, 1), (1, -1), (-1, -1); with the COG at (0.2, -0.4) its nearest edge is the
    # hypotenuse y = x, at |0.2 - (-0.4)| / sqrt(2) from the COG.
    feet = np.array([[1.0, 1.0, 0.0], [1.0, -1.0, 0.0], [-1.0, -1.0, 0.0], [1.0, 1.0, 0.0]])
    cog = [0.2, -0.4, 0.5]
    expected = M * G * 0.6 / np.sqrt(2.0)
    index, moments = stability_index(cog, [0, 0, 0], feet, M, G)  # compiled single-instant path
    index_t, moments_t = stability_index(np.array([cog, cog]), np.zeros((2, 3)), feet, M, G)  # numpy path
    assert index == pytest.approx(expected)
    np.testing.assert_allclose(index_t, expected)
    assert np.isfinite(moments).all() and moments.min() == pytest.approx(expected)
    np.testing.assert_allclose(np.sort(moments_t[0]), np.sort(moments))


def test_fewer_than_three_distinct_feet_is_no_support():
    feet = np.array([[1.0, 1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, -1.0, 0.0]])
    for cog, acc in (([0, 0, 0.5], [0, 0, 0]), (np.zeros((2, 3)), np.zeros((2, 3)))):
        index, moments = stability_index(cog, acc, feet, M, G)
        assert np.all(index == NO_SUPPORT) and np.all(moments == NO_SUPPORT)


def test_collinear_feet_are_not_stable():
    feet = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 0.0], [-1.0, 0.0, 0.0]])
    index, moments = stability_index([0.0, 0.0, 0.5], [0, 0, 0], feet, M, G)
    assert np.isfinite(moments).all() and index <= 1e-9
