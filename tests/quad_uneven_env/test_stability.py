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


# ---------------------------------------------------------------------------- degenerate support polygons
def both_paths(cog, acc, feet):
    """(index, moments) of the compiled single-instant path and of the numpy (vectorised) path."""
    one = stability_index(cog, acc, feet, M, G)
    many = stability_index(np.asarray(cog, float)[None], np.asarray(acc, float)[None], feet, M, G)
    return one, (many[0][0], many[1][0])


def assert_paths_agree(cog, acc, feet):
    (i1, m1), (i2, m2) = both_paths(cog, acc, feet)
    np.testing.assert_allclose(i1, i2, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(m1, m2, rtol=1e-12, atol=1e-9)
    return float(i1), m1


def test_coincident_feet_merge_into_the_polygon_of_the_distinct_points():
    # Two of four feet on the same point: the triangle of the three distinct points.
    feet = np.array([[0.0, 1.0, 0.0], [1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [-1.0, -1.0, 0.0]])
    index, moments = assert_paths_agree([0, 0, 0.3], [0, 0, 0], feet)
    triangle, _ = stability_index([0, 0, 0.3], [0, 0, 0], feet[[0, 1, 3]], M, G)
    assert index == pytest.approx(float(triangle)) == pytest.approx(M * G / np.sqrt(5))
    # The zero-length edge bounds nothing and reports the index; the other three are the triangle's.
    assert moments.shape == (4,)
    expected = sorted([1.0, 1 / np.sqrt(5), 1 / np.sqrt(5), 1 / np.sqrt(5)])
    assert sorted(moments / (M * G)) == pytest.approx(expected)


def test_a_shrinking_corner_edge_tends_to_the_merged_value():
    # The square with one corner split into two points eps apart: the index tends to the square's.
    merged, _ = stability_index([0.3, -0.2, 0.5], [0, 0, 0], SQUARE, M, G)
    for eps in (1e-3, 1e-6, 1e-8):
        feet = np.vstack([SQUARE, SQUARE[0] + [eps, 0.0, 0.0]])
        index, _ = assert_paths_agree([0.3, -0.2, 0.5], [0, 0, 0], feet)
        assert index == pytest.approx(float(merged), abs=M * G * 2 * eps)


@pytest.mark.parametrize(
    "feet",
    [
        np.zeros((3, 3)),  # all on one point
        np.zeros((4, 3)),
        np.array([[0.0, 1.0, 0.0], [0.0, 1.0, 0.0], [1.0, -1.0, 0.0]]),  # three feet, two distinct points
        np.array([[0.0, 1.0, 0.0], [0.0, 1.0, 0.0], [1.0, -1.0, 0.0], [1.0, -1.0, 0.0]]),  # two pairs
        np.array([[0.0, 1.0, 0.0], [0.0, 1.0, 0.0], [0.0, 1.0, 5e-10]]),  # within MIN_EDGE_LENGTH
    ],
)
def test_fewer_than_three_distinct_points_is_no_support(feet):
    index, moments = assert_paths_agree([0, 0, 0.5], [0.3, -0.2, 1.0], feet)
    assert index == NO_SUPPORT and moments.shape == (len(feet),) and np.all(moments == NO_SUPPORT)


@pytest.mark.parametrize("n", [3, 4])
def test_collinear_feet_give_minus_the_moment_about_the_line(n):
    # Feet on the x axis; a static COG 0.3 m beside it tips over the line with moment m g 0.3:
    # the edges run along the line both ways, +-0.3 m g, and the index is -0.3 m g.
    feet = np.zeros((n, 3))
    feet[:, 0] = np.linspace(-1.0, 1.0, n)[np.r_[1:n, 0]]  # scrambled order
    index, moments = assert_paths_agree([0.2, 0.3, 0.5], [0, 0, 0], feet)
    assert index == pytest.approx(-0.3 * M * G)
    np.testing.assert_allclose(np.sort(np.abs(moments)), 0.3 * M * G)
    assert (moments > 0).any() and (moments < 0).any()
    # A COG on the line: zero margin; and the limit of an ever thinner triangle.
    assert assert_paths_agree([0.2, 0.0, 0.5], [0, 0, 0], feet)[0] == pytest.approx(0.0, abs=1e-9)
    thin = np.array([[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1e-7, 0.0]])
    assert stability_index([0.2, 0.3, 0.5], [0, 0, 0], thin, M, G)[0] == pytest.approx(-0.3 * M * G, rel=1e-5)


def test_degenerate_polygons_never_raise_and_both_paths_agree(rng):
    """Random feet with duplicated, near-duplicated and collinear (in xy, at any height) points."""
    for trial in range(400):
        n = int(rng.integers(3, 5))
        feet = rng.uniform(-0.5, 0.5, (n, 3))
        kind = trial % 4
        if kind == 0:  # exact duplicates
            feet[1:] = feet[rng.integers(0, n, n - 1)]
        elif kind == 1:  # near duplicates
            feet[1] = feet[0] + rng.normal(scale=1e-10, size=3)
        elif kind == 2:  # collinear in xy, heights free
            t = rng.uniform(-1, 1, n)
            feet[:, :2] = feet[0, :2] + np.outer(t, rng.normal(size=2))
        else:  # collinear in 3-D, with a duplicate
            feet = feet[0] + np.outer(rng.uniform(-1, 1, n), rng.normal(size=3))
            feet[-1] = feet[0]
        cog, acc = rng.normal(scale=0.3, size=3), rng.normal(size=3)
        index, moments = assert_paths_agree(cog, acc, feet)
        assert not np.isnan(index) and not np.isnan(moments).any()
        if index == NO_SUPPORT:
            assert np.all(moments == NO_SUPPORT)
        else:
            assert np.isfinite(index) and np.isfinite(moments).all() and moments.min() == index
