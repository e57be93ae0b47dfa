"""Terrain package: HeightField against MuJoCo's own surface, kinds, specs and validation."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from quad_uneven_env import constants as C
from quad_uneven_env.robot.model import scene_mjcf
from quad_uneven_env.terrain import (
    PAPER_BLOCKS,
    TERRAIN_KINDS,
    HeightField,
    Terrain,
    TerrainSpec,
    parse_terrain_spec,
    preset_names,
)


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
    # The scalar fast path gives the same surface (including clamping outside the grid).
    scalar = [hf.height(float(a), float(b)) for a, b in zip(xe[::10], ye[::10], strict=True)]
    np.testing.assert_allclose(scalar, z_ray[::10], atol=1e-6, rtol=0)
    for a, b in ((x0 - 1.0, y0 - 2.0), (x1 + 0.3, 0.5), (0.1, y1 + 4.0)):
        assert hf.height(a, b) == hf.height(np.array([a]), np.array([b]))[0]
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


@pytest.mark.parametrize("radius", [0.013, 0.05, 0.11])
def test_patch_stats_compiled_matches_numpy_twin(radius):
    rng = np.random.default_rng(3)
    heights = np.cumsum(rng.normal(0.0, 0.01, (35, 50)), axis=1)
    heights[:, 25:] += 0.08  # a step, so the edge statistics are exercised
    hf = HeightField(heights, 0.02, origin=(-0.3, 0.1))
    (x0, x1), (y0, y1) = hf.extent
    # inside, on the border and beyond it (clamped nodes), in a 2-D broadcast shape
    x = rng.uniform(x0 - 0.1, x1 + 0.1, (6, 7))
    y = rng.uniform(y0 - 0.1, y1 + 0.1, (6, 7))
    fast, ref = hf.patch_stats(x, y, radius), hf.patch_stats_numpy(x, y, radius)
    for name, a, b in zip(ref._fields, fast, ref, strict=True):
        assert a.shape == b.shape, name
        np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-12, err_msg=name)


def _max_slope_every_triangle(hf: HeightField, x: float, y: float, radius: float) -> float:
    """The compiled kernel's max slope (rad) before it skipped triangles: every hypot of the disc's triangles."""
    nrow, ncol = hf._h.shape
    cell, (ox, oy) = hf._cell, hf._origin
    k = int(np.ceil(radius / cell))
    p = 2 * k + 2
    c0, r0 = math.floor((x - ox) / cell), math.floor((y - oy) / cell)
    dxs = [(ox + (c0 - k + j) * cell) - x for j in range(p)]
    dys = [(oy + (r0 - k + j) * cell) - y for j in range(p)]
    hp = [[float(hf._flat[min(max(r0 - k + i, 0), nrow - 1) * ncol + min(max(c0 - k + j, 0), ncol - 1)])
           for j in range(p)] for i in range(p)]  # fmt: skip
    mask = [[dxs[j] ** 2 + dys[i] ** 2 <= radius * radius or (k <= i < k + 2 and k <= j < k + 2) for j in range(p)]
            for i in range(p)]  # fmt: skip
    steep = 0.0
    for i in range(p - 1):
        for j in range(p - 1):
            if mask[i][j] or mask[i][j + 1] or mask[i + 1][j] or mask[i + 1][j + 1]:
                h00, h01, h10, h11 = hp[i][j], hp[i][j + 1], hp[i + 1][j], hp[i + 1][j + 1]
                steep = max(steep, math.hypot(h01 - h00, h11 - h01) / cell, math.hypot(h11 - h10, h10 - h00) / cell)
    return math.atan(steep)


@pytest.mark.parametrize("radius", [0.013, 0.05, 0.11])
def test_patch_stats_max_slope_is_the_float_of_every_triangle(radius):
    """The kernel evaluates a triangle's hypot only where it could beat the steepest so far: the same float."""
    rng = np.random.default_rng(5)
    heights = np.cumsum(rng.normal(0.0, 0.01, (35, 50)), axis=1)
    heights[:, 25:] += 0.08
    heights[10:12, 5:8] = 0.02  # equal heights: ties
    hf = HeightField(heights, 0.02, origin=(-0.3, 0.1))
    (x0, x1), (y0, y1) = hf.extent
    x, y = rng.uniform(x0 - 0.1, x1 + 0.1, 60), rng.uniform(y0 - 0.1, y1 + 0.1, 60)
    got = hf.patch_stats(x, y, radius).max_slope
    want = [_max_slope_every_triangle(hf, float(a), float(b), radius) for a, b in zip(x, y, strict=True)]
    assert got.tolist() == want
    flat = HeightField(np.zeros((20, 20)), 0.02)
    assert flat.patch_stats([0.1, 0.2], [0.1, 0.2], radius).max_slope.tolist() == [0.0, 0.0]


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


# --- Terrain in a full MuJoCo scene --------------------------------------------------------------


def _heightmap_array(nrow: int = 61, ncol: int = 121, cell: float = 0.05) -> np.ndarray:
    """A user heightmap: a 0.1 m block and a ramp beyond x = 1 m, flat (0.03 m) around the spawn point."""
    x = -1.5 + cell * np.arange(ncol)
    y = -(nrow - 1) * cell / 2 + cell * np.arange(nrow)
    h = np.full((nrow, ncol), 0.03)
    h += np.where(x > 1.0, 0.2 * (x - 1.0), 0.0)[None, :]
    h[(np.abs(y) < 0.4)[:, None] & ((x > 2.0) & (x < 2.5))[None, :]] += 0.1
    return h


def _spec(kind: str) -> dict | str:
    return {"kind": "heightmap", "heights": _heightmap_array(), "cell_size": 0.05} if kind == "heightmap" else kind


def _scene(terrain: Terrain, paper_robot) -> tuple[mujoco.MjModel, mujoco.MjData]:
    """Full robot scene on ``terrain`` with the current surface uploaded and the robot lifted out of the way."""
    xml = scene_mjcf(paper_robot, terrain.hfield_asset_xml(), terrain.hfield_geom_xml(paper_robot.friction))
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    terrain.upload(model)
    data.qpos[2] = terrain.z_max + 5.0  # rays from z_max + 1 only see the terrain
    mujoco.mj_forward(model, data)
    return model, data


def _edge_points(hf: HeightField, rng: np.random.Generator, n_max: int = 2000) -> tuple[np.ndarray, np.ndarray]:
    """Random points inside cells whose corner heights differ by more than 1 cm (steep block / step edges)."""
    h = hf.heights
    corners = np.stack([h[:-1, :-1], h[:-1, 1:], h[1:, :-1], h[1:, 1:]])
    r, c = np.nonzero(np.ptp(corners, axis=0) > 0.01)
    if r.size == 0:
        return np.empty(0), np.empty(0)
    pick = rng.integers(0, r.size, n_max)
    x = hf.xs[c[pick]] + hf.cell_size * rng.random(n_max)
    y = hf.ys[r[pick]] + hf.cell_size * rng.random(n_max)
    return x, y


@pytest.mark.parametrize("kind", TERRAIN_KINDS)
def test_every_kind_matches_mj_ray(kind, paper_robot, rng):
    terrain = Terrain(_spec(kind))
    terrain.generate(rng)
    model, data = _scene(terrain, paper_robot)
    hf = terrain.heightfield
    (x0, x1), (y0, y1) = hf.extent
    xr, yr = rng.uniform(x0, x1, 2000), rng.uniform(y0, y1, 2000)
    xe, ye = _edge_points(hf, rng)
    if kind in ("stairs", "stepping_stones", "paper", "heightmap"):
        assert xe.size > 0  # the kind has steep edges and they are tested
    x, y = np.concatenate([xr, xe]), np.concatenate([yr, ye])
    z_ray, n_ray = _ray_down(model, data, x, y, terrain.z_max + 1.0)
    assert np.all(np.isfinite(z_ray))
    np.testing.assert_allclose(terrain.height(x, y), z_ray, atol=1e-6, rtol=0)
    np.testing.assert_allclose(hf.normal(x, y), n_ray, atol=1e-6)


def test_hfield_xml_uses_the_shared_names(paper_robot):
    terrain = Terrain("stairs")
    model, _ = _scene(terrain, paper_robot)
    gid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, C.TERRAIN_GEOM)
    hid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_HFIELD, C.TERRAIN_HFIELD)
    assert gid >= 0 and hid >= 0 and model.geom_dataid[gid] == hid
    assert model.geom_type[gid] == mujoco.mjtGeom.mjGEOM_HFIELD
    assert (model.geom_contype[gid], model.geom_conaffinity[gid]) == (C.TERRAIN_CONTYPE, C.TERRAIN_CONAFFINITY)
    assert model.geom_friction[gid][0] == pytest.approx(paper_robot.friction)
    assert model.geom_matid[gid] == mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_MATERIAL, "terrain_mat")
    assert (model.hfield_nrow[hid], model.hfield_ncol[hid]) == terrain.heightfield.shape
    with pytest.raises(ValueError, match="friction"):
        terrain.hfield_geom_xml(0.0)


@pytest.mark.parametrize("kind", ["rough", "stepping_stones", "paper"])
def test_regeneration_is_seeded(kind):
    terrain = Terrain(kind)
    xml = (terrain.hfield_asset_xml(), terrain.hfield_geom_xml(1.0))
    a = terrain.generate(np.random.default_rng(1)).heights.copy()
    b = terrain.generate(np.random.default_rng(2)).heights.copy()
    a2 = terrain.generate(np.random.default_rng(1)).heights.copy()
    np.testing.assert_array_equal(a, a2)
    assert np.max(np.abs(a - b)) > 1e-3
    # Layout and elevation bounds do not depend on the seed: the model never needs recompiling.
    assert (terrain.hfield_asset_xml(), terrain.hfield_geom_xml(1.0)) == xml
    assert Terrain(kind).hfield_asset_xml() == xml[0]


def test_upload_rewrites_the_same_model_without_recompiling(paper_robot, rng):
    terrain = Terrain({"kind": "stepping_stones", "height_jitter": 0.1})
    model, data = _scene(terrain, paper_robot)
    x, y = rng.uniform(0.8, 4.0, 500), rng.uniform(-1.2, 1.2, 500)
    z0 = terrain.z_max + 1.0
    before, _ = _ray_down(model, data, x, y, z0)
    old = terrain.height(x, y)
    terrain.generate(np.random.default_rng(777))
    terrain.upload(model)  # same MjModel object, data only
    mujoco.mj_forward(model, data)
    after, _ = _ray_down(model, data, x, y, z0)
    np.testing.assert_allclose(before, old, atol=1e-6)
    np.testing.assert_allclose(after, terrain.height(x, y), atol=1e-6)
    assert np.max(np.abs(after - before)) > 0.01
    np.testing.assert_array_equal(model.hfield_data.reshape(terrain.heightfield.shape), terrain.hfield_data)
    # MuJoCo does not renormalise data written at run time: halve it and the relief above z_min halves.
    model.hfield_data[:] *= 0.5
    mujoco.mj_forward(model, data)
    halved, _ = _ray_down(model, data, x, y, z0)
    np.testing.assert_allclose(halved - terrain.z_min, 0.5 * (after - terrain.z_min), atol=1e-6)


def test_upload_refuses_a_model_of_another_layout(paper_robot):
    model, _ = _scene(Terrain("flat"), paper_robot)
    with pytest.raises(ValueError, match="another terrain spec"):
        Terrain({"kind": "flat", "length": 6.0}).upload(model)
    with pytest.raises(ValueError, match="hfield"):
        Terrain("flat").upload(mujoco.MjModel.from_xml_string("<mujoco/>"))


def test_robot_stands_on_the_spawn_area(paper_robot):
    """Home pose at spawn_height: feet touch the terrain within a millimetre (contact distance from MuJoCo).

    The pose is lowered by 0.5 mm: libccd (the scene's collider) reports overlaps only, not exact touches.
    """

    terrain = Terrain({"kind": "rough", "amplitude": 0.1})
    model, data = _scene(terrain, paper_robot)
    data.qpos[:] = paper_robot.home_qpos(terrain.spawn_height)
    data.qpos[2] -= 5e-4
    mujoco.mj_forward(model, data)
    gid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, C.TERRAIN_GEOM)
    feet = {mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, g) for g in C.FOOT_GEOMS}
    touching = {int(c.geom[0] + c.geom[1] - gid) for c in data.contact[: data.ncon] if gid in c.geom}
    assert feet <= touching
    assert all(-1e-3 < c.dist < 0.0 for c in data.contact[: data.ncon])


# --- kinds ------------------------------------------------------------------------------------------


@pytest.mark.parametrize("kind", [k for k in TERRAIN_KINDS if k != "paper"])
def test_spawn_area_is_flat(kind, rng):
    terrain = Terrain(_spec(kind))
    terrain.generate(rng)
    r = terrain.spec.params["spawn_radius"] * np.sqrt(rng.random(3000))
    phi = rng.uniform(0, 2 * np.pi, 3000)
    x, y = terrain.spawn_xy[0] + r * np.cos(phi), terrain.spawn_xy[1] + r * np.sin(phi)
    np.testing.assert_allclose(terrain.height(x, y), terrain.spawn_height, atol=1e-9)
    np.testing.assert_allclose(terrain.heightfield.normal(x, y)[..., 2], 1.0, atol=1e-12)


@pytest.mark.parametrize("amplitude, wavelength", [(0.04, 0.6), (0.15, 0.3), (0.3, 1.5)])
def test_rough_peak_to_peak_and_wavelength(amplitude, wavelength):
    terrain = Terrain(
        {"kind": "rough", "amplitude": amplitude, "wavelength": wavelength, "length": 16, "width": 8, "x_start": -8}
    )
    for seed in (0, 1):
        h = terrain.generate(np.random.default_rng(seed)).heights
        assert np.ptp(h) == pytest.approx(amplitude, abs=1e-6)
        # Power-weighted mean spatial frequency ~ 1 / wavelength.
        power = np.abs(np.fft.rfft2(h - h.mean())) ** 2
        fy = np.fft.fftfreq(h.shape[0], terrain.grid.cell_size)[:, None]
        fx = np.fft.rfftfreq(h.shape[1], terrain.grid.cell_size)[None, :]
        f_mean = np.sum(np.hypot(fx, fy) * power) / np.sum(power)
        assert 1.0 / f_mean == pytest.approx(wavelength, rel=0.15)
    assert np.all(Terrain({"kind": "rough", "amplitude": 0.0}).heightfield.heights == 0.0)


@pytest.mark.parametrize("angle_deg", [5.0, 10.0, 30.0])
def test_slope_angle_measured_from_heights(angle_deg):
    terrain = Terrain({"kind": "slope", "angle_deg": angle_deg, "ramp_length": 1.2, "plateau_length": 0.8})
    hf = terrain.heightfield
    x0 = 0.6 + 0.02  # spawn_radius + cell_size
    top = 1.2 * np.tan(np.deg2rad(angle_deg))
    # Angle from node heights of the middle of each ramp (finite differences of the grid itself).
    for a, b, sign in ((x0 + 0.2, x0 + 1.0, 1.0), (x0 + 2.2, x0 + 3.0, -1.0)):
        cols = (hf.xs > a) & (hf.xs < b)
        slope = np.diff(hf.heights[:, cols], axis=1) / hf.cell_size
        np.testing.assert_allclose(np.degrees(np.arctan(sign * slope)), angle_deg, atol=1e-4)
    assert hf.heights.max() == pytest.approx(top, abs=1e-6)
    assert terrain.height(x0 + 1.6, 0.3) == pytest.approx(top, abs=1e-6)  # plateau
    assert terrain.height(x0 + 3.5, -0.3) == pytest.approx(0.0, abs=1e-9)  # flat after


@pytest.mark.parametrize(
    "direction, levels",
    [("up", [0, 1, 2, 3, 4, 4]), ("down", [0, -1, -2, -3, -4, -4]), ("pyramid", [0, 1, 2, 3, 4, 3, 2, 1, 0, 0])],
)
def test_stairs_risers(direction, levels):
    riser, tread = 0.07, 0.4
    terrain = Terrain({"kind": "stairs", "riser": riser, "tread": tread, "n_steps": 4, "direction": direction})
    x0 = 0.6 + 0.02
    centres = np.array([0.3] + [x0 + (k + 0.5) * tread for k in range(len(levels) - 1)])
    z = terrain.height(centres, 0.5)
    np.testing.assert_allclose(z, riser * np.array(levels), atol=1e-6)
    np.testing.assert_allclose(np.abs(np.diff(z))[np.diff(levels) != 0], riser, atol=1e-6)
    # Each riser is a one-cell-wide wall just before its step's edge: the treads are flat up to it.
    tread_pts = x0 + tread * np.arange(len(levels) - 1)[:, None] + np.linspace(0.001, tread - 0.021, 20)
    hz = terrain.height(tread_pts, -0.2)
    np.testing.assert_allclose(hz - hz[:, :1], 0.0, atol=1e-6)


def test_stepping_stones_have_holes_between_them(rng):
    p = {"kind": "stepping_stones", "stone_size": 0.3, "gap": 0.1, "height_jitter": 0.06, "hole_depth": 0.25}
    terrain = Terrain(p)
    terrain.generate(rng)
    hf = terrain.heightfield
    x_first = 0.6 + 0.02 + 0.1  # feature start + gap
    pitch = 0.4
    stone_cx = x_first + 0.15 + pitch * np.arange(8)
    gap_cx = x_first - 0.05 + pitch * np.arange(8)
    for y in (0.2, -0.2, 0.6):  # stone rows are centred on y = +-pitch/2, +-3 pitch/2
        tops = terrain.height(stone_cx, y)
        assert np.all(np.abs(tops) <= 0.03 + 1e-6)
        np.testing.assert_allclose(terrain.height(gap_cx, y), -0.25, atol=1e-6)
    np.testing.assert_allclose(terrain.height(stone_cx, 0.0), -0.25, atol=1e-6)  # a pit runs along y = 0
    # Stone tops are flat and vary from stone to stone.
    s = hf.patch_stats(stone_cx, 0.2, 0.1)
    np.testing.assert_allclose(s.roughness, 0.0, atol=1e-6)
    assert np.ptp(terrain.height(stone_cx, 0.2)) > 0.005
    # The foothold helper sees the holes.
    assert not np.any(hf.is_safe_foothold(gap_cx, 0.2, 0.05))
    assert np.all(hf.is_safe_foothold(stone_cx, 0.2, 0.05))


def test_paper_blocks_and_field(rng, paper_robot):
    terrain = Terrain("paper")
    terrain.generate(rng)
    half = 0.08 - 0.02  # block_size / 2 minus a cell: surely on the flat top
    for key in ("start", "target"):
        b = PAPER_BLOCKS[key]
        assert b.shape == (4, 3) and not b.flags.writeable
        for dx, dy in ((0, 0), (half, half), (-half, half), (half, -half), (-half, -half)):
            np.testing.assert_allclose(terrain.height(b[:, 0] + dx, b[:, 1] + dy), b[:, 2], atol=1e-6)
    assert terrain.height(0.0, 0.0) == pytest.approx(0.12, abs=1e-6)  # raised ground between the blocks
    assert terrain.spawn_height == pytest.approx(PAPER_BLOCKS["start"][:, 2].max())
    x = np.linspace(0.7, 5.8, 400)
    field = terrain.height(x, 0.2)
    assert np.all((field >= 0.12 - 1e-6) & (field <= 0.18 + 1e-6)) and np.ptp(field) > 0.02
    # The paper's COG heights are reachable: hip-to-foot-site distance below the stretched leg (0.42 m).
    for key, cog in (("start", (0.01, 0.0, 0.544)), ("target", (0.21, 0.0, 0.5743))):
        hips = np.array(cog) + np.array([[0.25, 0.185, 0], [0.25, -0.185, 0], [-0.25, 0.185, 0], [-0.25, -0.185, 0]])
        feet = PAPER_BLOCKS[key] + [0.0, 0.0, paper_robot.foot_radius]
        reach = np.linalg.norm(hips - feet, axis=1)
        assert np.all(reach < 0.95 * paper_robot.leg_length) and np.all(reach > 0.6 * paper_robot.leg_length)


def test_heightmap_from_npy_round_trips(tmp_path):
    h = _heightmap_array()
    path = tmp_path / "map.npy"
    np.save(path, h)
    terrain = Terrain({"kind": "heightmap", "params": {"heights": str(path), "cell_size": 0.05}})
    np.testing.assert_allclose(terrain.heightfield.heights, h, atol=1e-6 * np.ptp(h), rtol=0)
    assert terrain.heightfield.shape == h.shape
    np.testing.assert_allclose(terrain.heightfield.extent, ((-1.5, 4.5), (-1.5, 1.5)))
    assert terrain.spawn_height == pytest.approx(0.03)
    assert terrain.spec == TerrainSpec("heightmap", {"heights": h, "cell_size": 0.05})
    moved = Terrain({"kind": "heightmap", "heights": path, "cell_size": 0.05, "origin": (-1.4, -1.6)})
    assert moved.heightfield.origin.tolist() == [-1.4, -1.6]
    assert moved.height(1.15, 0.0) == pytest.approx(0.03 + 0.2 * 0.05, abs=1e-6)  # the ramp moved by +0.1 m


# --- specs and validation ------------------------------------------------------------------------


def test_parse_forms():
    default = parse_terrain_spec(None)
    assert default.kind == "rough" and default.params["amplitude"] == 0.04
    assert parse_terrain_spec("rough") == default == parse_terrain_spec({"kind": "rough", "params": {}})
    a = parse_terrain_spec({"kind": "rough", "amplitude": 0.05})
    b = parse_terrain_spec({"kind": "rough", "params": {"amplitude": 0.05}})
    assert a == b and a != default and a.params["wavelength"] == 0.6
    assert parse_terrain_spec(a) is a
    assert set(TERRAIN_KINDS) == {"flat", "rough", "slope", "stairs", "stepping_stones", "paper", "heightmap"}
    with pytest.raises(TypeError):
        a.params["amplitude"] = 0.1  # read-only


def test_presets_load():
    names = preset_names()
    assert names
    for name in names:
        spec = parse_terrain_spec(name)
        assert Terrain(spec).spec == spec


@pytest.mark.parametrize(
    "spec, field",
    [
        ("lava", "kind"),
        ({"amplitude": 0.1}, "kind"),
        ({"kind": "rough", "amplitud": 0.1}, "amplitud"),
        ({"kind": "rough", "amplitude": 0.5}, "amplitude"),
        ({"kind": "rough", "amplitude": -0.1}, "amplitude"),
        ({"kind": "rough", "amplitude": "big"}, "amplitude"),
        ({"kind": "rough", "amplitude": float("nan")}, "amplitude"),
        ({"kind": "rough", "amplitude": True}, "amplitude"),
        ({"kind": "rough", "wavelength": 0.03}, "wavelength"),
        ({"kind": "rough", "params": [1, 2]}, "params"),
        ({"kind": "rough", "amplitude": 0.1, "params": {"amplitude": 0.1}}, "amplitude"),
        ({"kind": "flat", "length": 0.0}, "length"),
        ({"kind": "flat", "width": -3.0}, "width"),
        ({"kind": "flat", "cell_size": 0.0}, "cell_size"),
        ({"kind": "flat", "cell_size": 0.005, "length": 100.0, "width": 50.0}, "cap is 4000000"),
        ({"kind": "flat", "x_start": 0.5}, "spawn_radius"),
        ({"kind": "slope", "angle_deg": 0.0}, "angle_deg"),
        ({"kind": "slope", "angle_deg": 31.0}, "angle_deg"),
        ({"kind": "stairs", "riser": 0.3}, "riser"),
        ({"kind": "stairs", "tread": 0.1}, "tread"),
        ({"kind": "stairs", "n_steps": 2.5}, "n_steps"),
        ({"kind": "stairs", "direction": "sideways"}, "direction"),
        ({"kind": "stepping_stones", "gap": 0.01}, "gap"),
        ({"kind": "stepping_stones", "hole_depth": 0.0}, "hole_depth"),
        ({"kind": "paper", "block_size": 0.5}, "block_size"),
        ({"kind": "paper", "base_height": 0.16}, r"base_height must be <= 0.15 \* scale"),
        ({"kind": "paper", "scale": 0.1}, "scale"),
        ({"kind": "heightmap"}, "heights"),
        ({"kind": "heightmap", "heights": np.zeros(10)}, "heights"),
        ({"kind": "heightmap", "heights": np.full((80, 80), np.inf)}, "heights"),
        ({"kind": "heightmap", "heights": "missing.npy"}, "heights"),
        ({"kind": "heightmap", "heights": np.zeros((80, 80)), "length": 3.0}, "length"),
        ({"kind": "heightmap", "heights": np.zeros((80, 80)), "origin": (0.0, 0.0)}, "origin"),
        ({"kind": "heightmap", "heights": np.zeros((3000, 3000)), "cell_size": 0.01}, "cap is 4000000"),
        (42, "terrain spec"),
    ],
)
def test_validation_errors_name_the_field(spec, field):
    with pytest.raises(ValueError, match=field):
        Terrain(spec)


def test_heightmap_spawn_area_must_be_flat():
    h = _heightmap_array()
    h[30, 30] += 0.002  # node (x, y) = (0, 0): inside the spawn area
    with pytest.raises(ValueError, match=r"heights.*flat within 1 mm"):
        Terrain({"kind": "heightmap", "heights": h, "cell_size": 0.05})
    h[30, 30] -= 0.0015  # 0.5 mm: accepted
    assert Terrain({"kind": "heightmap", "heights": h, "cell_size": 0.05}).spawn_height == pytest.approx(0.03, abs=1e-4)


def test_generate_needs_a_generator():
    with pytest.raises(ValueError, match="rng"):
        Terrain("flat").generate(42)  # type: ignore[arg-type]


def test_docs_parameter_tables_are_in_sync():
    from pathlib import Path

    from quad_uneven_env.terrain.docs import parameter_tables

    root = Path(__file__).resolve().parents[2]
    doc = (root / "docs" / "terrain.md").read_text()
    assert parameter_tables().strip() in doc
    for kind in TERRAIN_KINDS:
        assert f"### `{kind}`" in doc
    assert "(docs/terrain.md)" in (root / "README.md").read_text()


def test_compiled_height_and_normal_points_equal_numpy():
    from quad_uneven_env.terrain import Terrain, parse_terrain_spec

    rng = np.random.default_rng(3)
    hf = Terrain(parse_terrain_spec("stepping_stones")).generate(rng)
    (x0, x1), (y0, y1) = hf.extent
    x = rng.uniform(x0 - 0.5, x1 + 0.5, 5000)  # includes points outside the grid (clamped)
    y = rng.uniform(y0 - 0.5, y1 + 0.5, 5000)
    np.testing.assert_allclose(hf.height_points(x, y), hf.height_numpy(x, y), rtol=0, atol=1e-12)
    xb, yb = x[:12].reshape(3, 4, 1), y[:5]  # broadcast shapes go through the same kernel
    np.testing.assert_allclose(hf.height(xb, yb), hf.height_numpy(xb, yb), rtol=0, atol=1e-12)
    assert hf.height(xb, yb).shape == (3, 4, 5) and np.ndim(hf.height(np.float64(0.3), 0.2)) == 0
    normals = hf.normal_points(np.column_stack([x, y, np.zeros_like(x)]))
    np.testing.assert_allclose(normals, hf.normal(x, y), rtol=0, atol=1e-12)
    assert (normals[:, 2] < 0.999).mean() > 0.05  # the stones' edges: tilted triangles were sampled


def _npy_header_only(path, shape, dtype="<f8", version=(1, 0)):
    """A .npy file whose header claims ``shape`` but which holds no data at all."""
    from numpy.lib import format as fmt

    header = {"descr": dtype, "fortran_order": False, "shape": shape}
    with open(path, "wb") as f:
        (fmt.write_array_header_1_0 if version == (1, 0) else fmt.write_array_header_2_0)(f, header)


@pytest.mark.parametrize(
    "shape, dtype, version, message",
    [
        ((100_000, 100_000), "<f8", (1, 0), "heights has 100000 x 100000 nodes in its header; the cap is"),
        ((100_000, 100_000), "<f8", (2, 0), "heights has 100000 x 100000 nodes in its header"),
        ((10, 10, 10), "<f8", (1, 0), "must be a 2-D array"),
        ((10, 10), "|O", (1, 0), "holds object values, not numbers"),
        ((10, 10), "<U3", (1, 0), "not numbers"),
    ],
)
def test_heightmap_npy_is_refused_from_its_header_before_loading(tmp_path, monkeypatch, shape, dtype, version, message):
    path = tmp_path / "huge.npy"
    _npy_header_only(path, shape, dtype, version)
    monkeypatch.setattr(np, "load", lambda *a, **k: pytest.fail("np.load ran before the header was checked"))
    with pytest.raises(ValueError, match=r"heights") as err:
        parse_terrain_spec({"kind": "heightmap", "heights": str(path)})
    assert message in str(err.value)


@pytest.mark.parametrize("content", [b"", b"not a numpy file at all", b"\x93NUMPY\x01\x00\xff\xff{"])
def test_heightmap_npy_garbage_is_a_clean_error(tmp_path, content):
    path = tmp_path / "bad.npy"
    path.write_bytes(content)
    with pytest.raises(ValueError, match=r"cannot read .* as a \.npy array"):
        parse_terrain_spec({"kind": "heightmap", "heights": str(path)})


def test_heightmap_npy_truncated_after_a_valid_header(tmp_path):
    path = tmp_path / "short.npy"
    _npy_header_only(path, (50, 60))  # a sane header, no data
    with pytest.raises(ValueError, match=r"cannot read .* as a \.npy array"):
        parse_terrain_spec({"kind": "heightmap", "heights": str(path)})


def test_rough_cached_filter_gives_the_uncached_surface_bit_for_bit():
    """The rough kind caches its spectral filter and fade-in per grid: the surface equals the direct
    spectral synthesis (written out here) exactly, on a first and on a repeated draw."""
    from quad_uneven_env.terrain.grid import SPAWN_XY, spawn_blend_radius
    from quad_uneven_env.terrain.kinds.rough import BANDWIDTH, KIND, blend_width

    terrain = Terrain({"kind": "rough", "amplitude": 0.06, "wavelength": 0.45})
    p, grid = terrain.spec.params, terrain.grid

    def direct(seed: int) -> np.ndarray:
        noise = np.random.default_rng(seed).standard_normal((grid.nrow, grid.ncol))
        fy = np.fft.fftfreq(grid.nrow, d=grid.cell_size)[:, None]
        fx = np.fft.rfftfreq(grid.ncol, d=grid.cell_size)[None, :]
        f0 = 1.0 / p["wavelength"]
        f = np.hypot(fx, fy)
        f[0, 0] = 1.0
        ring = np.exp(-0.5 * ((f - f0) / (BANDWIDTH * f0)) ** 2) / np.sqrt(f / f0)
        ring[0, 0] = 0.0
        field = np.fft.irfft2(np.fft.rfft2(noise) * ring, s=noise.shape)
        x, y = grid.mesh()
        t = np.clip((np.hypot(x - SPAWN_XY[0], y - SPAWN_XY[1]) - spawn_blend_radius(p)) / blend_width(p), 0.0, 1.0)
        h = t * t * (3.0 - 2.0 * t) * field
        return h * (p["amplitude"] / float(np.ptp(h)))

    for seed in (3, 3, 11):
        np.testing.assert_array_equal(KIND.generate(p, grid, np.random.default_rng(seed)), direct(seed))


# ---------------------------------------------------------------------------------- features beyond the grid
@pytest.mark.parametrize(
    ("spec", "end", "fields"),
    [
        # the grid ends at x_start + length = -1.5 + 8 = 6.5 m; features start at x0 = 0.6 + 0.02 = 0.62 m
        ({"kind": "slope", "ramp_length": 3.0}, 0.62 + 2 * 3.0 + 1.0, ("ramp_length", "plateau_length", "length")),
        ({"kind": "slope", "plateau_length": 6.0}, 0.62 + 2 * 1.5 + 6.0, ("ramp_length", "plateau_length")),
        ({"kind": "slope", "length": 4.0}, 0.62 + 2 * 1.5 + 1.0, ("length to at least 6.12 m",)),
        ({"kind": "stairs", "direction": "pyramid", "n_steps": 11}, 0.62 + 21 * 0.3, ("n_steps", "tread", "length")),
        ({"kind": "stairs", "direction": "up", "n_steps": 30}, 0.62 + 29 * 0.3, ("n_steps",)),
        ({"kind": "stairs", "direction": "down", "tread": 1.0, "n_steps": 7}, 0.62 + 6 * 1.0, ("tread",)),
    ],
    ids=["long ramps", "long plateau", "short grid", "pyramid", "up", "down"],
)
def test_a_feature_that_ends_beyond_the_grid_is_refused(spec, end, fields):
    """Cut off without a word, a ramp down or a flight of steps would never come back down (or reach its top)."""
    with pytest.raises(ValueError, match="beyond the grid") as err:
        Terrain(spec)
    message = str(err.value)
    assert f"x = {end:g} m" in message and "grid's end x = " in message
    assert [f for f in fields if f not in message] == [], message


@pytest.mark.parametrize(
    "spec",
    [
        {"kind": "slope", "ramp_length": 2.9, "plateau_length": 0.02},  # ends at 6.44 m, on the grid (6.5 m)
        {"kind": "stairs", "direction": "pyramid", "n_steps": 11, "length": 8.0 + 0.6},  # last edge 6.92 m
        {"kind": "stairs", "direction": "up", "n_steps": 20, "tread": 0.3},  # last edge 6.32 m
    ],
    ids=["slope", "pyramid", "up"],
)
def test_a_feature_that_ends_on_the_grid_is_whole(spec):
    """The last node of the grid sees the feature's end: the slope back at 0, the flight at its last level."""
    hf = Terrain(spec).heightfield
    last = hf.heights[:, -1]
    if spec["kind"] == "slope":
        assert np.all(last == 0.0)
    else:
        top = 0.0 if spec["direction"] == "pyramid" else spec["n_steps"] * 0.08
        np.testing.assert_allclose(last, top, atol=1e-12)


def test_a_huge_broadcast_heightmap_is_refused_before_it_is_copied():
    """A 10^6 x 10^6 view costs no memory; its float64 copy would be 8 TB: the cap is checked on the shape first."""
    huge = np.broadcast_to(np.float64(0.0), (10**6, 10**6))
    with pytest.raises(ValueError, match=r"heights has 1000000 x 1000000 nodes; the cap is 4000000"):
        parse_terrain_spec({"kind": "heightmap", "heights": huge})
    with pytest.raises(ValueError, match="cap is 4000000"):
        Terrain({"kind": "heightmap", "heights": np.broadcast_to(np.float32(0.0), (3001, 3001)), "cell_size": 0.01})
