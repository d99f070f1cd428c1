"""`brute` backend: every valid Gaussian for every pixel, in depth order, no tiles.

O(N·H·W): the oracle for small scenes that the tiled backends are tested against. Plain JAX
autodiff differentiates it (a fori_loop of fixed length).
"""

from __future__ import annotations

import jax.numpy as jnp
from jax import lax

from ..composite import PixelState, blend
from ..config import RasterConfig
from ..layout import image_to_tiles
from ..projection import Projected, depth_order
from .interface import Backend, BackendInputs, RasterResult


def composite_pixels(p: Projected, width: int, height: int, config: RasterConfig) -> PixelState:
    """Composite all Gaussians over all pixels; returns the (H·W,) row-major pixel state."""
    dt = p.mean2d.dtype
    jj, ii = jnp.meshgrid(jnp.arange(width), jnp.arange(height))
    px = (jj.reshape(-1) + 0.5).astype(dt)
    py = (ii.reshape(-1) + 0.5).astype(dt)
    order = depth_order(p)

    def body(k, state):
        g = order[k]
        return blend(state, p.mean2d[g], p.mean2d_lo[g], p.conic[g], p.opacity[g], p.rgb[g],
                     p.depth[g], p.valid[g], px, py, config)

    return lax.fori_loop(0, order.shape[0], body, PixelState.empty(width * height, dt))


def rasterize(p: Projected, bins, width: int, height: int, config: RasterConfig,
              inputs: BackendInputs = BackendInputs()) -> RasterResult:
    """`composite_pixels` in the per-tile layout every backend returns (`bins` and `inputs`
    are unused)."""
    del bins, inputs
    state = composite_pixels(p, width, height, config)
    tiles = lambda x: image_to_tiles(x, width, height)
    return RasterResult(color=tiles(state.color), trans=tiles(state.trans),
                        depth=tiles(state.depth))


BACKEND = Backend("brute", rasterize, binned=False)
