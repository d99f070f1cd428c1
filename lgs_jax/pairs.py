"""Per-pair preparation: what each (tile, Gaussian) pair carries into the Local-GS rasterizers.

For pair k of Gaussian g in tile t (lgs_jax.binning's sorted pairs):
  - `gather`: the Gaussian's fields for every pair, read as one packed row per pair (a row of a
    per-Gaussian table materialised once: one gather of contiguous values instead of one
    scattered read per field, which dominates at millions of pairs);
  - `strip_masks`: the 8-bit strip mask (Sec. III-C, lgs_jax.warp_masks), made conservative for
    the form that will be evaluated (the hoisted forms round differently from the difference
    form: their error bound, lgs_jax.hoist.error_bound, widens the threshold);
  - `hoisted_vectors`: V (Eq. 8) relative to the tile's origin (lgs_jax.layout.tile_origin),
    then ln o, the clamp of ln α (lgs_jax.alpha);
  - `chain_hoisted_rows`: the backward's way back, ∂L/∂V of each pair through Eq. 8 to the
    Gaussian's mean2d, conic and opacity (the vjp of `hoist.hoist`).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp
from jax import lax

from . import hoist
from .binning import TileBins, padded_ellipse
from .config import RasterConfig
from .layout import TILE, tile_origin
from .projection import Projected
from .warp_masks import FULL_MASK, strip_mask


@jax.tree_util.register_dataclass
@dataclasses.dataclass
class PairGaussians:
    """The fields of each pair's Gaussian, (capacity, ...): projection outputs and the padded
    ellipse of lgs_jax.binning (tau, tau_pad, det_lo, unbounded)."""

    mean2d: Any
    conic: Any
    opacity: Any
    rgb: Any
    depth: Any
    tau: Any
    tau_pad: Any
    det_lo: Any
    unbounded: Any


def gather(p: Projected, gauss) -> PairGaussians:
    """Every pair's Gaussian fields, through one packed per-Gaussian row per pair."""
    e = padded_ellipse(p)
    cols = [p.mean2d, p.conic, p.opacity[:, None], p.rgb, p.depth[:, None], e.tau[:, None],
            e.tau_pad[:, None], e.det_lo[:, None], e.unbounded[:, None].astype(p.mean2d.dtype)]
    # Materialised once per Gaussian: fused into the per-pair consumers, XLA would recompute
    # the rows (and read every field separately) for every pair.
    table = lax.optimization_barrier(jnp.concatenate(cols, -1))
    rows = table[gauss]
    return PairGaussians(mean2d=rows[:, 0:2], conic=rows[:, 2:5], opacity=rows[:, 5],
                         rgb=rows[:, 6:9], depth=rows[:, 9], tau=rows[:, 10],
                         tau_pad=rows[:, 11], det_lo=rows[:, 12], unbounded=rows[:, 13] > 0.5)


def _pair_origins(bins: TileBins, tiles_x: int, config: RasterConfig, dtype):
    t = bins.tile
    return tile_origin(t % tiles_x, t // tiles_x, config, dtype)


def strip_masks(pg: PairGaussians, bins: TileBins, tiles_x: int, config: RasterConfig):
    """Strip masks of every pair (FULL_MASK for Gaussians the binning could not bound; 0 for
    padding pairs)."""
    dt = pg.mean2d.dtype
    u = jnp.finfo(dt).eps / 2
    t = bins.tile
    tx, ty = t % tiles_x, t // tiles_x
    tau = pg.tau_pad
    if config.hoist:
        origin = tile_origin(tx, ty, config, dt)
        corner = jnp.stack([tx * TILE, ty * TILE], -1).astype(dt)
        reach = jnp.maximum(jnp.abs(corner + 0.5 - origin), jnp.abs(corner + TILE - 0.5 - origin))
        err = hoist.error_bound(pg.mean2d, pg.conic, jnp.log(pg.opacity), origin, reach[:, 0],
                                reach[:, 1], 16 * u)
        tau = jnp.maximum(tau, pg.tau * (1 + 4 * u) + 128 * u + 2 * err)
    mask = strip_mask(pg.mean2d, pg.conic, tau, pg.det_lo, tx, ty)
    mask = jnp.where(pg.unbounded, FULL_MASK, mask)
    return jnp.where(t < bins.tile_start.shape[0], mask, 0)


def hoisted_vectors(pg: PairGaussians, bins: TileBins, tiles_x: int, config: RasterConfig):
    """What each pair stages (capacity, 7): the hoisted V (Eq. 8) relative to its tile's origin,
    then ln o (the clamp of ln α)."""
    origin = _pair_origins(bins, tiles_x, config, pg.mean2d.dtype)
    log_o = jnp.log(pg.opacity)
    return jnp.concatenate([hoist.hoist(pg.mean2d, pg.conic, log_o, origin), log_o[:, None]], -1)


def chain_hoisted_rows(pg: PairGaussians, bins: TileBins, rows, tiles_x: int,
                       config: RasterConfig):
    """Pair rows (∂L/∂V, ∂L/∂ln o from the clamp, ∂L/∂rgb, ∂L/∂z: capacity x 11) chained to
    the pair's Gaussian through Eq. 8 (`hoist.hoist_terms_vjp`, the vjp of `hoist.hoist`):
    (capacity, 10) rows of ∂L/∂(mean2d, conic, opacity, rgb, depth)."""
    origin = _pair_origins(bins, tiles_x, config, pg.mean2d.dtype)
    dx, dy = pg.mean2d[:, 0] - origin[:, 0], pg.mean2d[:, 1] - origin[:, 1]
    q = pg.conic
    d_a, d_b, d_c, d_dx, d_dy, d_log_o = hoist.hoist_terms_vjp(
        [rows[:, i] for i in range(6)], q[:, 0], q[:, 1], q[:, 2], dx, dy)
    o = pg.opacity
    d_o = jnp.where(o > 0, (d_log_o + rows[:, 6]) / jnp.where(o > 0, o, 1), 0)
    return jnp.concatenate([jnp.stack([d_dx, d_dy, d_a, d_b, d_c, d_o], -1), rows[:, 7:]], -1)
