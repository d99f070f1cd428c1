"""`brute` backend: every valid Gaussian for every pixel, in depth order, no tiles.

O(N·H·W): the oracle for small scenes that the tiled backends are tested against.
"""

from __future__ import annotations

import jax.numpy as jnp
from jax import lax

from ..composite import PixelState, blend
from ..config import RasterConfig
from ..projection import Projected, depth_order


def rasterize(p: Projected, width: int, height: int, config: RasterConfig) -> PixelState:
    """Composite all Gaussians over all pixels; returns the (H·W,) row-major pixel state."""
    dt = p.mean2d.dtype
    jj, ii = jnp.meshgrid(jnp.arange(width), jnp.arange(height))
    px = (jj.reshape(-1) + 0.5).astype(dt)
    py = (ii.reshape(-1) + 0.5).astype(dt)
    order = depth_order(p)

    def body(k, state):
        g = order[k]
        return blend(state, p.mean2d[g], p.conic[g], p.opacity[g], p.rgb[g], p.depth[g],
                     p.valid[g], px, py, config)

    return lax.fori_loop(0, order.shape[0], body, PixelState.empty(width * height, dt))
