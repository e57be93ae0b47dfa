"""``rough``: smooth random ground (band-limited noise) with an exact peak-to-peak amplitude."""

from __future__ import annotations

import functools

import numpy as np

from quad_uneven_env.terrain.grid import SPAWN_XY, Grid, spawn_blend_radius, with_positive_range
from quad_uneven_env.terrain.kinds.base import Params, TerrainKind
from quad_uneven_env.terrain.params import Param

BANDWIDTH = 0.5
"""Relative width (standard deviation / centre) of the radial power spectrum around 1 / wavelength."""


def _check(p: Params, where: str) -> None:
    if p["wavelength"] < 2.0 * p["cell_size"]:
        raise ValueError(
            f"{where}.wavelength must be in [2 * cell_size, 5] = [{2 * p['cell_size']:g}, 5] m, got {p['wavelength']:g}"
        )


def blend_width(p: Params) -> float:
    """Width (m) of the ring outside the flat spawn disc over which the relief fades in."""
    return max(0.5 * p["wavelength"], 2.0 * p["cell_size"])


@functools.lru_cache(maxsize=8)
def _spectral_filter(grid: Grid, wavelength: float) -> np.ndarray:
    """(nrow, ncol // 2 + 1) real gain on ``rfft2`` of the noise: a band around 1 / wavelength (1/m).

    Amplitude ring / sqrt(f): the power per frequency band (ring area ~ f) then peaks at f0 itself.
    Depends on the grid and the wavelength only, so one array serves every episode (read-only).
    """
    fy = np.fft.fftfreq(grid.nrow, d=grid.cell_size)[:, None]
    fx = np.fft.rfftfreq(grid.ncol, d=grid.cell_size)[None, :]
    f0 = 1.0 / wavelength
    f = np.hypot(fx, fy)
    f[0, 0] = 1.0
    ring = np.exp(-0.5 * ((f - f0) / (BANDWIDTH * f0)) ** 2) / np.sqrt(f / f0)
    ring[0, 0] = 0.0
    ring.flags.writeable = False
    return ring


@functools.lru_cache(maxsize=8)
def _fade_in(grid: Grid, flat_radius: float, width: float) -> np.ndarray:
    """(nrow, ncol) smoothstep weight in [0, 1]: 0 within ``flat_radius`` (m) of the spawn, 1 beyond ``+ width``."""
    x, y = grid.mesh()
    t = np.clip((np.hypot(x - SPAWN_XY[0], y - SPAWN_XY[1]) - flat_radius) / width, 0.0, 1.0)
    w = t * t * (3.0 - 2.0 * t)
    w.flags.writeable = False
    return w


def _generate(p: Params, grid: Grid, rng: np.random.Generator) -> np.ndarray:
    amplitude = p["amplitude"]
    noise = rng.standard_normal((grid.nrow, grid.ncol))
    if amplitude == 0.0:
        return np.zeros_like(noise)
    # Spectral synthesis: white noise filtered to a band of spatial frequencies around f0 = 1 / wavelength.
    ring = _spectral_filter(grid, float(p["wavelength"]))
    field = np.fft.irfft2(np.fft.rfft2(noise) * ring, s=noise.shape)
    # Fade in from 0 outside the spawn disc (smoothstep), so every triangle touching the disc is flat.
    h = _fade_in(grid, float(spawn_blend_radius(p)), float(blend_width(p))) * field
    ptp = float(np.ptp(h))
    return h * (amplitude / ptp) if ptp > 0.0 else np.zeros_like(h)


def _bounds(p: Params) -> tuple[float, float]:
    # 0 (the spawn area) lies within [min, max] and max - min = amplitude.
    return with_positive_range(-p["amplitude"], p["amplitude"])


KIND = TerrainKind(
    name="rough",
    doc=(
        "Smooth random ground: white noise filtered so that its radially summed power spectrum is a Gaussian "
        "around the spatial frequency 1 / wavelength (standard deviation 0.5 / wavelength), faded in by a "
        "smoothstep over max(wavelength / 2, 2 cell_size) outside the spawn disc, "
        "then scaled so that the peak-to-peak height of the whole grid is exactly `amplitude`. "
        "The spawn area stays at height 0. The default kind."
    ),
    params=(
        Param("amplitude", 0.04, "m", "peak-to-peak height of the whole grid", lo=0.0, hi=0.3),
        Param("wavelength", 0.6, "m", "dominant horizontal scale (>= 2 cell_size)", lo=0.0, hi=5.0, lo_open=True),
    ),
    generate=_generate,
    z_bounds=_bounds,
    check=_check,
)
