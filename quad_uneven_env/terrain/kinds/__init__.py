"""Registry of terrain kinds (one module each)."""

from __future__ import annotations

from quad_uneven_env.terrain.kinds import flat, heightmap, paper, rough, slope, stairs, stepping_stones
from quad_uneven_env.terrain.kinds.base import TerrainKind
from quad_uneven_env.terrain.kinds.paper import PAPER_BLOCKS

KINDS: dict[str, TerrainKind] = {
    k.KIND.name: k.KIND for k in (flat, rough, slope, stairs, stepping_stones, paper, heightmap)
}
"""Kind name -> TerrainKind, in documentation order."""

__all__ = ["KINDS", "PAPER_BLOCKS", "TerrainKind"]
