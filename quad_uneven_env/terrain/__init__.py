"""Terrain: kinds -> height grids, MuJoCo height fields, and the pure-numpy :class:`HeightField`."""

from quad_uneven_env.terrain.heightfield import MAX_CELLS, HeightField, PatchStats

__all__ = ["MAX_CELLS", "HeightField", "PatchStats"]
