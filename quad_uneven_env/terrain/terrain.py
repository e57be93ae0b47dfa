"""A terrain spec as a MuJoCo height field: XML, per-episode generation, upload into a compiled model.

MuJoCo stores a height field as float32 data normalised to [0, 1]; the surface height of node
``(r, c)`` is ``geom_pos.z + data[r, c] * size[2]``. Here ``geom_pos.z = z_min`` and
``size[2] = z_max - z_min`` are fixed by the spec's parameters, so a reset only rewrites
``model.hfield_data`` (MuJoCo does not renormalise data written at run time) and the model is
never recompiled. :attr:`Terrain.heightfield` holds exactly the surface MuJoCo sees (the heights
are rounded through the same float32 data).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from typing import Any

import mujoco
import numpy as np
from numpy.typing import ArrayLike

from quad_uneven_env import constants as C
from quad_uneven_env.fields import excerpt
from quad_uneven_env.terrain.grid import SPAWN_XY, Grid
from quad_uneven_env.terrain.heightfield import HeightField
from quad_uneven_env.terrain.kinds import KINDS
from quad_uneven_env.terrain.spec import TerrainSpec, parse_terrain_spec

BASE_DEPTH = 0.2
"""m: thickness of MuJoCo's solid height-field box below z_min (hfield size[3])."""

MATERIAL = "terrain_mat"
"""Material of the terrain geom (defined by ``scene_mjcf``)."""


def _num(v: float) -> str:
    return repr(float(v))  # round-trips exactly, so MuJoCo parses the same doubles


class Terrain:
    """A terrain built from a spec: height-field XML for the scene, seeded surfaces, upload into a model.

    The grid shape, cell size, origin and elevation bounds ``(z_min, z_max)`` depend on the spec's
    parameters only; :meth:`generate` draws a new surface from an rng within those bounds. On
    construction a first surface is generated from ``np.random.default_rng(0)`` so the terrain is
    usable at once; call :meth:`generate` with the episode's generator at every reset.

    :param spec: anything :func:`parse_terrain_spec` accepts (None: default ``"rough"``).
    :raises ValueError: on an invalid spec (naming the field).
    """

    def __init__(self, spec: str | os.PathLike[str] | Mapping[str, Any] | TerrainSpec | None = None) -> None:
        self.spec: TerrainSpec = parse_terrain_spec(spec)
        self._kind = KINDS[self.spec.kind]
        self.grid: Grid = self._kind.grid(self.spec.params)
        """node layout (fixed by the spec)."""
        z_min, z_max = self._kind.z_bounds(self.spec.params)
        self.z_min: float = float(z_min)
        """m: lowest possible surface height (world z of the hfield geom)."""
        self.z_max: float = float(z_max)
        """m: highest possible surface height."""
        self._data = np.zeros((self.grid.nrow, self.grid.ncol), dtype=np.float32)
        self.heightfield: HeightField = HeightField(
            np.full(self._data.shape, self.z_min), self.grid.cell_size, self.grid.origin
        )
        """the current surface (m); replaced by :meth:`generate`."""
        self.generate(np.random.default_rng(0))

    # --- layout ------------------------------------------------------------------------------
    @property
    def kind(self) -> str:
        """Terrain kind name."""
        return self.spec.kind

    @property
    def z_range(self) -> float:
        """m: z_max - z_min (MuJoCo's hfield size[2])."""
        return self.z_max - self.z_min

    @property
    def spawn_xy(self) -> tuple[float, float]:
        """World (x, y) (m) above which the trunk starts; the robot walks along +x."""
        return SPAWN_XY

    @property
    def spawn_height(self) -> float:
        """Terrain height (m) of the spawn area (``paper``: the highest start-block top, see docs/terrain.md).

        Rounded as MuJoCo stores heights (float32 data), so it equals :meth:`height` there exactly.
        """
        return float(self._quantise(np.array(self._kind.spawn_height(self.spec.params)))[1])

    @property
    def hfield_data(self) -> np.ndarray:
        """(nrow, ncol) float32 normalised data in [0, 1] as written into ``model.hfield_data`` (read-only view)."""
        view = self._data.view()
        view.setflags(write=False)
        return view

    # --- MJCF ---------------------------------------------------------------------------------
    def hfield_asset_xml(self) -> str:
        """The ``<hfield>`` asset element: nrow, ncol and size = (half length, half width, z range, base depth) (m).

        It carries no elevation data (MuJoCo starts with zeros): call :meth:`upload` after compiling.
        """
        lx, ly = self.grid.size
        size = " ".join(_num(v) for v in (lx / 2.0, ly / 2.0, self.z_range, BASE_DEPTH))
        return f'<hfield name="{C.TERRAIN_HFIELD}" nrow="{self.grid.nrow}" ncol="{self.grid.ncol}" size="{size}"/>'

    def hfield_geom_xml(self, friction: float) -> str:
        """The terrain ``<geom type="hfield">`` element placed so that node [0, 0] is at ``grid.origin``.

        :param friction: sliding friction coefficient (-), > 0; torsional 0.005 and rolling 1e-4 as the robot's.
        """
        if (
            isinstance(friction, bool)
            or not isinstance(friction, (int, float, np.floating))
            or not (np.isfinite(friction) and friction > 0)
        ):
            raise ValueError(f"friction must be a finite number > 0, got {excerpt(friction)}")
        cx, cy = self.grid.center
        pos = " ".join(_num(v) for v in (cx, cy, self.z_min))
        return (
            f'<geom name="{C.TERRAIN_GEOM}" type="hfield" hfield="{C.TERRAIN_HFIELD}" pos="{pos}" '
            f'material="{MATERIAL}" contype="{C.TERRAIN_CONTYPE}" conaffinity="{C.TERRAIN_CONAFFINITY}" '
            f'friction="{float(friction):.6g} 0.005 0.0001"/>'
        )

    # --- surfaces -----------------------------------------------------------------------------
    def generate(self, rng: np.random.Generator) -> HeightField:
        """Draw a new surface from ``rng`` (deterministic per generator state); store it as :attr:`heightfield`.

        :param rng: the episode's generator (never the global numpy RNG).
        :return: the new :class:`HeightField` (heights in m, rounded as MuJoCo stores them).
        """
        if not isinstance(rng, np.random.Generator):
            raise ValueError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
        h = np.asarray(self._kind.generate(self.spec.params, self.grid, rng), dtype=np.float64)
        if h.shape != self._data.shape:
            raise RuntimeError(f"terrain kind {self.kind!r} produced shape {h.shape}, expected {self._data.shape}")
        tol = 1e-9 * max(1.0, self.z_range)
        if h.min() < self.z_min - tol or h.max() > self.z_max + tol:
            raise RuntimeError(
                f"terrain kind {self.kind!r} left its bounds [{self.z_min}, {self.z_max}] m: [{h.min()}, {h.max()}]"
            )
        self._data, heights = self._quantise(h)
        self.heightfield = HeightField(heights, self.grid.cell_size, self.grid.origin)
        return self.heightfield

    def _quantise(self, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(float32 normalised data, heights (m) MuJoCo reconstructs from it) of heights ``h`` (m)."""
        data = np.clip((h - self.z_min) / self.z_range, 0.0, 1.0).astype(np.float32)
        return data, self.z_min + data.astype(np.float64) * self.z_range

    def upload(self, model: mujoco.MjModel, context: mujoco.MjrContext | None = None) -> None:
        """Write the current surface into ``model.hfield_data`` (no recompilation; call before ``mj_forward``).

        :param model: a model compiled from this terrain's :meth:`hfield_asset_xml` and :meth:`hfield_geom_xml`.
        :param context: a rendering context to refresh too (``mjr_uploadHField``), if one exists.
        :raises ValueError: if the model's terrain hfield or geom does not match this terrain's layout.
        """
        hid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_HFIELD, C.TERRAIN_HFIELD)
        if hid < 0:
            raise ValueError(f"model has no hfield named {C.TERRAIN_HFIELD!r}; build it with hfield_asset_xml()")
        nrow, ncol = int(model.hfield_nrow[hid]), int(model.hfield_ncol[hid])
        lx, ly = self.grid.size
        expected = np.array([lx / 2.0, ly / 2.0, self.z_range, BASE_DEPTH])
        if (nrow, ncol) != self._data.shape or not np.allclose(model.hfield_size[hid], expected, rtol=0, atol=1e-12):
            raise ValueError(
                f"model hfield {C.TERRAIN_HFIELD!r} is {nrow} x {ncol} with size {model.hfield_size[hid].tolist()}, "
                f"this terrain needs {self._data.shape} with size {expected.tolist()}: the model was built from "
                "another terrain spec"
            )
        gid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, C.TERRAIN_GEOM)
        if gid >= 0:
            pos = np.array([*self.grid.center, self.z_min])
            if not np.allclose(model.geom_pos[gid], pos, rtol=0, atol=1e-12):
                raise ValueError(
                    f"geom {C.TERRAIN_GEOM!r} is at {model.geom_pos[gid].tolist()}, this terrain needs {pos.tolist()}"
                )
        adr = int(model.hfield_adr[hid])
        model.hfield_data[adr : adr + nrow * ncol] = self._data.ravel()
        if context is not None:
            mujoco.mjr_uploadHField(model, context, hid)

    def height(self, x: ArrayLike, y: ArrayLike) -> np.ndarray:
        """Surface height (m) at world (x, y) (m), broadcast: ``self.heightfield.height``."""
        return self.heightfield.height(x, y)

    def __repr__(self) -> str:
        return (
            f"Terrain(kind={self.kind!r}, grid={self.grid.nrow}x{self.grid.ncol} @ {self.grid.cell_size:g} m, "
            f"z=[{self.z_min:g}, {self.z_max:g}] m)"
        )
