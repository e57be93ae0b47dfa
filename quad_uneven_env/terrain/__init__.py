"""Terrain: kinds -> height grids, MuJoCo height fields, and the pure-numpy :class:`HeightField`.

Parameters of every kind: docs/terrain.md. Typical use::

    terrain = Terrain({"kind": "stairs", "riser": 0.1})
    xml = scene_mjcf(cfg, terrain.hfield_asset_xml(), terrain.hfield_geom_xml(cfg.friction))
    model = mujoco.MjModel.from_xml_string(xml)
    terrain.generate(rng)   # at every reset
    terrain.upload(model)   # rewrites model.hfield_data, no recompilation
"""

from typing import TYPE_CHECKING

from quad_uneven_env.terrain.grid import SPAWN_XY, Grid
from quad_uneven_env.terrain.heightfield import MAX_CELLS, HeightField, PatchStats
from quad_uneven_env.terrain.kinds.paper import PAPER_BLOCKS
from quad_uneven_env.terrain.spec import TERRAIN_KINDS, TerrainSpec, parse_terrain_spec, preset_names

if TYPE_CHECKING:  # for type checkers and IDEs; at run time ``__getattr__`` imports it on first use
    from quad_uneven_env.terrain.terrain import Terrain


def __getattr__(name: str):
    """:class:`Terrain` on first use: it needs MuJoCo, while the height field and its kernels (what the planners
    use) do not."""
    if name == "Terrain":
        from quad_uneven_env.terrain.terrain import Terrain

        return Terrain
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    "MAX_CELLS",
    "PAPER_BLOCKS",
    "SPAWN_XY",
    "TERRAIN_KINDS",
    "Grid",
    "HeightField",
    "PatchStats",
    "Terrain",
    "TerrainSpec",
    "parse_terrain_spec",
    "preset_names",
]
