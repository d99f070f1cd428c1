"""`reference` backend: 16x16 tiles, each walking its sorted pair list pixel by pixel.

Same per-pixel semantics as `brute` (lgs_jax.composite), none of the paper's optimisations:
tiles are vmapped, each runs a while loop over its (depth, index)-ordered pairs and stops when
its list ends or every pixel of the tile is done.

Differentiable: `rasterize` is a `jax.custom_vjp` (reverse-mode cannot go through the while
loop) whose backward, lgs_jax.backends.backward, walks each tile back to front from the final
transmittance; the forward records where each pixel stopped for it.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax import lax

from ..binning import TileBins
from ..composite import PixelState, blend
from ..config import RasterConfig
from ..layout import TILE_PIXELS, tile_pixels
from ..projection import Projected
from . import backward
from .custom_vjp import differentiable
from .interface import Backend, BackendInputs, RasterResult


def composite_tiles(fields, bins: TileBins, pixels, config: RasterConfig):
    """Per tile (n_tiles, 256): the composited state and each pixel's stop position (the list
    index of the Gaussian whose stop test fired, or the tile's end).
    fields = (mean2d, mean2d_lo, conic, opacity, rgb, depth)."""
    mean2d, mean2d_lo, conic, opacity, rgb, depth = fields
    dt = mean2d.dtype

    def one_tile(px, py, start, end):
        def cond(carry):
            k, state, _ = carry
            return (k < end) & ~jnp.all(state.done)

        def body(carry):
            k, state, stop_at = carry
            g = bins.gauss[k]
            new = blend(state, mean2d[g], mean2d_lo[g], conic[g], opacity[g], rgb[g], depth[g],
                        True, px, py, config)
            return k + 1, new, jnp.where(new.done & ~state.done, k, stop_at)

        init = (start, PixelState.empty(TILE_PIXELS, dt), jnp.full((TILE_PIXELS,), end))
        _, state, stop_at = lax.while_loop(cond, body, init)
        return state, stop_at

    return jax.vmap(one_tile)(*pixels, bins.tile_start, bins.tile_end)


def _fields(p: Projected):
    return p.mean2d, p.mean2d_lo, p.conic, p.opacity, p.rgb, p.depth


def _forward(p: Projected, bins: TileBins, extra, width: int, height: int,
             config: RasterConfig):
    del extra
    state, stop_at = composite_tiles(_fields(p), bins, tile_pixels(width, height, p.mean2d.dtype),
                                     config)
    return state, stop_at, None, None


def _gradients(p: Projected, bins: TileBins, extra, width: int, height: int,
               config: RasterConfig, trans, stop_at, saved, cotangents):
    del extra, saved
    g_color, g_trans, g_depth = cotangents
    rows = backward.pair_rows(_fields(p), bins, tile_pixels(width, height, p.mean2d.dtype),
                              config, trans, stop_at, g_color, g_trans,
                              backward.depth_cotangent(g_depth, trans))
    return backward.per_gaussian_sum(rows, bins, p.mean2d.shape[0])


_composite = differentiable(_forward, _gradients)


def rasterize(p: Projected, bins: TileBins, width: int, height: int, config: RasterConfig,
              inputs: BackendInputs = BackendInputs()) -> RasterResult:
    """Composite every tile (differentiable)."""
    del inputs
    color, trans, depth, stop, _ = _composite(p, bins, None, width, height, config)
    return RasterResult(color=color, trans=trans, depth=depth, stop=stop)


BACKEND = Backend("reference", rasterize)
