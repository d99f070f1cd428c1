"""`reference` backend: 16x16 tiles, each walking its sorted pair list pixel by pixel.

Same per-pixel semantics as `brute` (lgs_jax.composite), none of the paper's optimisations:
tiles are vmapped, each runs a while loop over its (depth, index)-ordered pairs and stops when
its list ends or every pixel of the tile is done.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax import lax

from ..binning import TILE, TileBins, tile_grid
from ..composite import PixelState, blend
from ..config import RasterConfig
from ..projection import Projected


def tiles_to_image(x, width: int, height: int):
    """(tiles_y·tiles_x, 256, ...) per-tile pixel arrays -> (H·W, ...) row-major pixels."""
    tiles_x, tiles_y = tile_grid(width, height)
    rest = x.shape[2:]
    x = x.reshape((tiles_y, tiles_x, TILE, TILE) + rest)
    x = jnp.moveaxis(x, 2, 1).reshape((tiles_y * TILE, tiles_x * TILE) + rest)
    return x[:height, :width].reshape((height * width,) + rest)


def rasterize(p: Projected, bins: TileBins, width: int, height: int,
              config: RasterConfig) -> PixelState:
    dt = p.mean2d.dtype
    tiles_x, tiles_y = tile_grid(width, height)
    local_j, local_i = jnp.meshgrid(jnp.arange(TILE), jnp.arange(TILE))
    local_j, local_i = local_j.reshape(-1), local_i.reshape(-1)

    def one_tile(tile_id, start, end):
        px = ((tile_id % tiles_x) * TILE + local_j + 0.5).astype(dt)
        py = ((tile_id // tiles_x) * TILE + local_i + 0.5).astype(dt)

        def cond(carry):
            k, state = carry
            return (k < end) & ~jnp.all(state.done)

        def body(carry):
            k, state = carry
            g = bins.gauss[k]
            return k + 1, blend(state, p.mean2d[g], p.conic[g], p.opacity[g], p.rgb[g],
                                p.depth[g], True, px, py, config)

        _, state = lax.while_loop(cond, body, (start, PixelState.empty(TILE * TILE, dt)))
        return state

    tile_ids = jnp.arange(tiles_x * tiles_y, dtype=jnp.int32)
    states = jax.vmap(one_tile)(tile_ids, bins.tile_start, bins.tile_end)
    return jax.tree.map(lambda x: tiles_to_image(x, width, height), states)
