"""Terrain package: HeightField against MuJoCo's own surface, kinds, specs and validation."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from quad_uneven_env.terrain import HeightField


def _ray_down(
    model: mujoco.MjModel, data: mujoco.MjData, x: np.ndarray, y: np.ndarray, z0: float = 5.0
) -> tuple[np.ndarray, np.ndarray]:
    """World z and surface normal where a ray cast straight down from (x, y, z0) first hits a geom (NaN if none)."""
    z, normals = np.full(len(x), np.nan), np.full((len(x), 3), np.nan)
    geomid = np.zeros(1, np.int32)
    down = np.array([0.0, 0.0, -1.0])
    for i, (xi, yi) in enumerate(zip(x, y, strict=True)):
        dist = mujoco.mj_ray(model, data, np.array([xi, yi, z0]), down, None, 1, -1, geomid, normals[i])
        if dist >= 0:
            z[i] = z0 - dist
    return z, normals


def _raw_hfield_model(hf: HeightField, base: float = 0.1) -> mujoco.MjModel:
    """A bare MuJoCo model holding ``hf`` as its only geom (independent of the Terrain class)."""
    nrow, ncol = hf.shape
    (x0, x1), (y0, y1) = hf.extent
    zmin, zr = float(hf.heights.min()), float(np.ptp(hf.heights)) or 1.0
    xml = f"""<mujoco><asset><hfield name="h" nrow="{nrow}" ncol="{ncol}"
      size="{(x1 - x0) / 2!r} {(y1 - y0) / 2!r} {zr!r} {base}"/></asset><worldbody>
      <geom type="hfield" hfield="h" pos="{(x0 + x1) / 2!r} {(y0 + y1) / 2!r} {zmin!r}"/></worldbody></mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    model.hfield_data[:] = ((hf.heights - zmin) / zr).ravel()
    return model


def test_heightfield_matches_mujoco_triangulation(rng):
    # Random heights with steep block edges: blocks of 0.2 m on a rough base.
    nrow, ncol, cell = 23, 31, 0.05
    h = 0.02 * rng.standard_normal((nrow, ncol))
    h[5:12, 8:15] += 0.2
    h[14:20, 20:27] -= 0.15
    # Quantise to what MuJoCo stores (float32 of the normalised data) so both see the same nodes.
    zmin, zr = h.min(), np.ptp(h)
    h = zmin + ((h - zmin) / zr).astype(np.float32).astype(np.float64) * zr
    hf = HeightField(h, cell, origin=(-0.7, 0.3))
    model = _raw_hfield_model(hf)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    (x0, x1), (y0, y1) = hf.extent
    x = rng.uniform(x0, x1, 3000)
    y = rng.uniform(y0, y1, 3000)
    # Points right at the block edges (within one cell of the steep triangles).
    xe = np.concatenate([x, rng.uniform(hf.xs[7], hf.xs[9], 500), rng.uniform(hf.xs[14], hf.xs[16], 500)])
    ye = np.concatenate([y, rng.uniform(hf.ys[5], hf.ys[12], 1000)])
    z_ray, n_ray = _ray_down(model, data, xe, ye)
    assert np.all(np.isfinite(z_ray))
    np.testing.assert_allclose(hf.height(xe, ye), z_ray, atol=1e-6, rtol=0)
    np.testing.assert_allclose(hf.normal(xe, ye), n_ray, atol=1e-5)
    # The other diagonal (the mirrored grid's triangulation) disagrees: the test can fail.
    other = HeightField(h[:, ::-1], cell, origin=(-0.7, 0.3)).height(x0 + x1 - xe, ye)
    assert np.max(np.abs(other - z_ray)) > 1e-2


def test_heightfield_normal_matches_mujoco_contact_normal(rng):
    nrow, ncol, cell = 9, 11, 0.1
    h = 0.05 * rng.standard_normal((nrow, ncol))
    hf = HeightField(h, cell, origin=(0.0, 0.0))
    (x0, x1), (y0, y1) = hf.extent
    x, y = rng.uniform(x0 + 0.1, x1 - 0.1, 200), rng.uniform(y0 + 0.1, y1 - 0.1, 200)
    n = hf.normal(x, y)
    np.testing.assert_allclose(np.linalg.norm(n, axis=-1), 1.0)
    # Finite differences of height() inside each triangle give the same gradient.
    eps = 1e-7
    gx = (hf.height(x + eps, y) - hf.height(x - eps, y)) / (2 * eps)
    gy = (hf.height(x, y + eps) - hf.height(x, y - eps)) / (2 * eps)
    ref = np.stack([-gx, -gy, np.ones_like(gx)], -1)
    ref /= np.linalg.norm(ref, axis=-1, keepdims=True)
    np.testing.assert_allclose(n, ref, atol=1e-5)


def test_heightfield_clamps_outside_and_broadcasts():
    h = np.arange(12.0).reshape(3, 4)  # rows along y, columns along x
    hf = HeightField(h, 0.5, origin=(1.0, -1.0))
    assert hf.extent == ((1.0, 2.5), (-1.0, 0.0))
    assert hf.height(1.0, -1.0) == 0.0
    assert hf.height(1.5, -1.0) == 1.0  # one column along +x
    assert hf.height(1.0, -0.5) == 4.0  # one row along +y
    assert hf.height(-10.0, -10.0) == 0.0
    assert hf.height(10.0, 10.0) == 11.0
    assert hf.height(np.array([[1.0], [2.5]]), np.array([-1.0, 0.0])).shape == (2, 2)


def test_patch_stats_on_a_plane_and_a_step():
    cell = 0.02
    xs = np.arange(60) * cell
    plane = np.tile(np.tan(np.deg2rad(20.0)) * xs, (40, 1))
    hf = HeightField(plane, cell)
    s = hf.patch_stats([0.5, 0.6], [0.4, 0.3], 0.1)
    np.testing.assert_allclose(s.plane_slope, np.deg2rad(20.0), atol=1e-9)
    np.testing.assert_allclose(s.max_slope, np.deg2rad(20.0), atol=1e-9)
    np.testing.assert_allclose(s.roughness, 0.0, atol=1e-12)
    step = np.zeros((40, 60))
    step[:, 30:] = 0.1  # a 10 cm step at x = 0.6
    hf = HeightField(step, cell)
    s = hf.patch_stats([0.3, 0.59, 0.9], [0.4, 0.4, 0.4], 0.05)
    np.testing.assert_allclose(s.height_max - s.height_min, [0.0, 0.1, 0.0])
    assert s.max_slope[1] == pytest.approx(np.arctan(0.1 / cell))
    assert s.roughness[1] > 0.02 and s.roughness[0] == 0.0
    np.testing.assert_array_equal(hf.is_safe_foothold([0.3, 0.59, 0.9], [0.4, 0.4, 0.4], 0.05), [True, False, True])
    slope_max, rough = hf.max_slope_and_roughness(0.59, 0.4, 0.05)
    assert slope_max == pytest.approx(s.max_slope[1]) and rough == pytest.approx(s.roughness[1])


@pytest.mark.parametrize(
    "heights, cell, field",
    [
        (np.zeros(5), 0.1, "heights"),
        (np.zeros((1, 5)), 0.1, "heights"),
        (np.full((3, 3), np.nan), 0.1, "heights"),
        (np.zeros((3, 3)), 0.0, "cell_size"),
        (np.zeros((3, 3)), -1.0, "cell_size"),
    ],
)
def test_heightfield_rejects_bad_input(heights, cell, field):
    with pytest.raises(ValueError, match=field):
        HeightField(heights, cell)
