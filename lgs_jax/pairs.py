"""Per-pair preparation: what each (tile, Gaussian) pair carries into the Local-GS rasterizers.

For pair k of Gaussian g in tile t (lgs_jax.binning's sorted pairs):
  - `gather`: the Gaussian's fields for every pair, read as one packed row per pair (a row of a
    per-Gaussian table materialised once: one gather of contiguous values instead of one
    scattered read per field, which dominates at millions of pairs);
  - `strip_masks`: the 8-bit strip mask (Sec. III-C, lgs_jax.warp_masks), made conservative for
    the forms that will be evaluated (the pair records' forms take the offset Δ = μ − T from the
    tile's origin, rounded at |Δ|, and round differently from the contract's difference form:
    the hoisted form's error bound, lgs_jax.hoist.error_bound, widens the threshold);
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

from . import hoist, twofloat
from .binning import TileBins, ellipse_bound
from .config import RasterConfig
from .layout import TILE, tile_origin_axis
from .projection import Projected
from .warp_masks import FULL_MASK, strip_mask


@jax.tree_util.register_dataclass
@dataclasses.dataclass
class PairGaussians:
    """The projection's fields of each pair's Gaussian, (capacity, ...)."""

    mean2d: Any
    mean2d_lo: Any
    conic: Any
    opacity: Any
    rgb: Any
    depth: Any


# `gaussian_table`: μx, μy, a, b, c, o, r, g, b, z, then the centre's low parts (mean2d_lo x,
# y; after the ten, so that the first six stay what lgs_jax.backends.pallas.gaussian_grads
# reads). The strip masks' padded ellipse (τ, τ_pad, det_lo and whether it is bounded) is
# computed from a, b, c and o where a mask is made (`strip_mask_columns`), not stored: the table
# lives through the whole gradient, and its three columns more took 12 bytes per Gaussian.
TABLE_COLUMNS = 12


def table_columns(p: Projected) -> list:
    """The TABLE_COLUMNS (N,) columns `gaussian_table` packs, in its column order: mean2d's
    x, y, conic's a, b, c, opacity, rgb, depth and mean2d_lo's x, y. The vector fields'
    columns are slices of `project`'s stacks, which XLA reads from its stored columns."""
    return ([p.mean2d[:, i] for i in range(2)] + [p.conic[:, i] for i in range(3)]
            + [p.opacity] + [p.rgb[:, i] for i in range(3)] + [p.depth]
            + [p.mean2d_lo[:, i] for i in range(2)])


def gaussian_table(p: Projected):
    """(N, TABLE_COLUMNS) per-Gaussian rows of every field a pair needs (`table_columns`),
    materialised once: fused into the per-pair consumers, XLA would recompute the rows (and
    read every field separately) for every pair. On GPUs the kernels take the same values from
    lgs_jax.backends.pallas.table, which writes them faster."""
    return lax.optimization_barrier(jnp.stack(table_columns(p), -1))


def gather(p: Projected, gauss) -> PairGaussians:
    """Every pair's Gaussian fields, through one packed `gaussian_table` row per pair."""
    rows = gaussian_table(p)[gauss]
    return PairGaussians(mean2d=rows[:, 0:2], mean2d_lo=rows[:, 10:12], conic=rows[:, 2:5],
                         opacity=rows[:, 5], rgb=rows[:, 6:9], depth=rows[:, 9])


def columns(pg: PairGaussians) -> list:
    """The `gaussian_table` columns of `pg` (what `record_columns` takes)."""
    return [pg.mean2d[:, 0], pg.mean2d[:, 1], pg.conic[:, 0], pg.conic[:, 1], pg.conic[:, 2],
            pg.opacity, pg.rgb[:, 0], pg.rgb[:, 1], pg.rgb[:, 2], pg.depth, pg.mean2d_lo[:, 0],
            pg.mean2d_lo[:, 1]]


def origin_offsets(mean2d, mean2d_lo, tx, ty, config: RasterConfig):
    """Δ = μ − T, (Δx, Δy), of centres μ = mean2d + mean2d_lo (pairs (x, y) of columns) from
    the origin T of tiles (tx, ty)'s hoisting frame (lgs_jax.layout.tile_origin_axis):
    (mean2d − T) + mean2d_lo (lgs_jax.twofloat.offset), which rounds once, at |Δ|."""
    dt = mean2d[0].dtype
    return (twofloat.offset(mean2d[0], mean2d_lo[0], tile_origin_axis(tx, config, dt)),
            twofloat.offset(mean2d[1], mean2d_lo[1], tile_origin_axis(ty, config, dt)))


def table_offsets(cols, tx, ty, config: RasterConfig):
    """`origin_offsets` of Gaussians `cols` (`gaussian_table` columns)."""
    return origin_offsets(cols[0:2], cols[10:12], tx, ty, config)


def strip_mask_columns(cols, tx, ty, config: RasterConfig):
    """Strip masks (int32) of Gaussians `cols` (`gaussian_table` columns) in tiles (tx, ty),
    FULL_MASK for those the binning could not bound. Written on columns, so that the XLA path
    (`strip_masks`) and the Mosaic GPU kernels' in-kernel staging (lane vectors, a scalar tile;
    lgs_jax.backends.pallas.staging) compute the same bits.

    The threshold is the difference form's (`binning.ellipse_bound`), widened by the hoisted
    form's error bound (`hoist.error_bound_terms` at Δ = `table_offsets`) for either form:
    the pair records (`record_columns`) take both from Δ, whose rounding at |Δ| the bound
    covers (it bounds a change of d by u·(|Δ| + reach) per axis, and more)."""
    mx, my, a, b, c, o = cols[:6]
    dt = mx.dtype
    u = jnp.finfo(dt).eps / 2
    # The ellipse of `binning` (every pair's Gaussian is valid), widened by 8u: in the Mosaic
    # GPU kernels its division is PTX div.full (<= 2 ulp), not the correctly rounded one the
    # bound was derived for.
    e = ellipse_bound(a, b, c, o)
    tau_min, tau, det_lo = e.tau, e.tau_pad * (1 + 8 * u), e.det_lo
    ox, oy = tile_origin_axis(tx, config, dt), tile_origin_axis(ty, config, dt)
    cx, cy = (tx * TILE).astype(dt), (ty * TILE).astype(dt)
    reach_x = jnp.maximum(jnp.abs(cx + 0.5 - ox), jnp.abs(cx + TILE - 0.5 - ox))
    reach_y = jnp.maximum(jnp.abs(cy + 0.5 - oy), jnp.abs(cy + TILE - 0.5 - oy))
    err = hoist.error_bound_terms(a, b, c, *table_offsets(cols, tx, ty, config), jnp.log(o),
                                  reach_x, reach_y, 16 * u)
    tau = jnp.maximum(tau, tau_min * (1 + 4 * u) + 128 * u + 2 * err)
    mask = strip_mask(mx, my, a, b, c, tau, det_lo, tx, ty)
    return jnp.where(e.unbounded, FULL_MASK, mask)


def strip_masks(pg: PairGaussians, bins: TileBins, tiles_x: int, config: RasterConfig):
    """Strip masks of every pair (`strip_mask_columns`; 0 for padding pairs)."""
    t = bins.tile
    mask = strip_mask_columns(columns(pg), t % tiles_x, t // tiles_x, config)
    return jnp.where(t < bins.tile_start.shape[0], mask, 0)


def strip_pair_count(p: Projected, bins: TileBins, tiles_x: int, config: RasterConfig):
    """Strip–Gaussian pairs the strip masks keep (int32): Σ over the pairs of their masks' set
    bits, 8 per pair without warp culling; strip_pairs / (8·pairs) is the share of the
    blending work warp culling leaves. Counted here in XLA (a gather of each pair's Gaussian
    fields): the Mosaic GPU kernels build their masks themselves and report −1, so a study that
    wants the count on that path calls this beside the render."""
    real = jnp.sum(bins.tile < bins.tile_start.shape[0], dtype=jnp.int32)
    if not config.warp_cull:
        return 8 * real
    masks = strip_masks(gather(p, bins.gauss), bins, tiles_x, config)
    return jnp.sum(lax.population_count(masks), dtype=jnp.int32)


def record_columns(cols, tx, ty, config: RasterConfig, mask=None):
    """The 12 columns of the Local-GS kernels' pair record of Gaussians `cols` in tiles (tx, ty)
    (lgs_jax.backends.pallas.steps), from Δ = μ − T relative to the tile's origin
    (`table_offsets`): hoisted, V (Eq. 8) and ln o; the difference form, Δ (the kernels take
    d = Δ − x' in the hoisting frame), the conic, o and 0; then rgb, z and the strip mask as a
    float (`mask`: int32, None for 0). On columns, as `strip_mask_columns`. The zeros (the
    difference form's o · 0, no mask's z · 0) are products of the lanes' own data: a constant
    (`zeros_like`) reaches the Mosaic GPU kernels' lane-strided shared-memory stores as a
    splat they cannot take, and the kernel fails to build for the H200 (LLVM translation: an
    unrealized_conversion_cast; on the GPU the test hung instead of raising)."""
    a, b, c, o, red, green, blue, z = cols[2:10]
    dx, dy = table_offsets(cols, tx, ty, config)
    if config.hoist:
        log_o = jnp.log(o)
        head = list(hoist.hoist_terms(a, b, c, dx, dy, log_o)) + [log_o]
    else:
        head = [dx, dy, a, b, c, o, o * 0]
    bits = z * 0 if mask is None else mask.astype(z.dtype)
    return head + [red, green, blue, z, bits]


def hoisted_vectors(pg: PairGaussians, bins: TileBins, tiles_x: int, config: RasterConfig):
    """What each pair stages (capacity, 7): the hoisted V (Eq. 8) relative to its tile's origin,
    then ln o (the clamp of ln α): `record_columns`' first seven."""
    t = bins.tile
    return jnp.stack(record_columns(columns(pg), t % tiles_x, t // tiles_x, config)[:7], -1)


def chain_hoisted_rows(pg: PairGaussians, bins: TileBins, rows, tiles_x: int,
                       config: RasterConfig):
    """Pair rows (∂L/∂V, ∂L/∂ln o from the clamp, ∂L/∂rgb, ∂L/∂z: capacity x 11) chained to
    the pair's Gaussian through Eq. 8 (`hoist.hoist_terms_vjp`, the vjp of `hoist.hoist`):
    (capacity, 10) rows of ∂L/∂(mean2d, conic, opacity, rgb, depth)."""
    t = bins.tile
    dx, dy = table_offsets(columns(pg), t % tiles_x, t // tiles_x, config)
    q = pg.conic
    d_a, d_b, d_c, d_dx, d_dy, d_log_o = hoist.hoist_terms_vjp(
        [rows[:, i] for i in range(6)], q[:, 0], q[:, 1], q[:, 2], dx, dy)
    o = pg.opacity
    d_o = jnp.where(o > 0, (d_log_o + rows[:, 6]) / jnp.where(o > 0, o, 1), 0)
    return jnp.concatenate([jnp.stack([d_dx, d_dy, d_a, d_b, d_c, d_o], -1), rows[:, 7:]], -1)
