"""The Local-GS and vanilla forward kernels and the backward kernel on Pallas Triton: the
interpret-mode (CPU) path of the `pallas` backends, and their kernels on GPUs Mosaic GPU does
not target. Their inputs are built in XLA (`records`: a pair record per pair, in pair order).

Local-GS forward (`localgs_kernel`, Sec. III): one program per 16x2 strip, `num_warps=1`, so a
program is one warp and its 32 lanes are the strip's pixels. It walks its tile's pairs in order,
reading one record per pair (`steps.pair_records`) and evaluating ln α as a 6-term sum in
its local coordinates (Eq. 10). With `warp_cull` a pair whose strip-mask bit is clear does not
blend, and a staged group of pairs with no bit set is skipped by one warp-uniform branch (Sec.
III-C). The strip stops as a unit once every lane is done (`exact`: each pixel's stop test
fired; `fast`: every T below 1e-4, the paper's coherent blending). Pairs are staged
`UNROLL_LOCALGS` at a time: their mask bits are fetched one iteration ahead, the
group's α are computed together (independent work that overlaps), then blended in order, so the
serial chain per pair is the blend alone.

Vanilla forward (`vanilla_kernel`, the original 3DGS rasterizer): one program per 16x16 tile with
8 warps (256 lanes), the difference form, per-pixel termination, and a tile-wide early exit when
every pixel is done.

Backward (`backward_kernel`): one program per tile, 256 lanes (8 warps), walking the tile's pairs
back to front from the last pair any pixel blended (`steps.backward_step`). Per pair, the
per-pixel gradient terms are reduced over the tile in one (256, 16) column reduction and stored with
the tile at the pair's walked row (gaussian_grads.RowLayout; backends.gaussian_grads sums them
per Gaussian there): each pair belongs to one tile, so every row has one writer (no atomics;
rows never written stay zero, through an aliased zero buffer).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
from jax import lax
from jax.experimental import pallas as pl
from jax.experimental.pallas import triton as pl_triton

from ... import pairs
from ...binning import TileBins
from ...config import RasterConfig
from ...layout import STRIP_PIXELS, STRIPS, TILE_PIXELS
from ...projection import Projected
from . import steps as ks

GRAD_COLUMNS = 16  # the backward's reduction width: GRAD_VALUES padded to a power of two
UNROLL_LOCALGS = 2  # pairs the Local-GS forward stages per loop iteration
UNROLL_VANILLA = 8  # pairs the vanilla forward stages per loop iteration


def every_strip(bins: TileBins):
    """Strip–Gaussian pairs without warp culling: every strip of every real pair's tile."""
    return STRIPS * jnp.sum(bins.tile < bins.tile_start.shape[0], dtype=jnp.int32)


def records(p: Projected, bins: TileBins, tiles_x: int, config: RasterConfig):
    """(strip masks, pair records, strip–Gaussian pairs) the Local-GS kernels read, built in
    XLA (`pairs.gather`, `steps.pair_records`); the masks are a (1,) placeholder without warp
    culling, and the strip pairs then count every strip of every pair."""
    pg = pairs.gather(p, bins.gauss)
    if not config.warp_cull:
        return (jnp.zeros((1,), jnp.int32), ks.pair_records(pg, bins, tiles_x, config),
                every_strip(bins))
    masks = pairs.strip_masks(pg, bins, tiles_x, config)
    strip_pairs = jnp.sum(lax.population_count(masks), dtype=jnp.int32)
    return masks, ks.pair_records(pg, bins, tiles_x, config, masks), strip_pairs


def _store(refs, row, outputs):
    """Write (r, g, b, T, D, stop pair) to row `row` of the (programs, lanes) outputs."""
    for ref, x in zip(refs, outputs):
        ref[row, :] = x.astype(ref.dtype)


def localgs_kernel(order_ref, start_ref, end_ref, mask_ref, rec_ref, *out_refs,
                   config: RasterConfig, tiles_x: int, last_pair: int):
    dt = rec_ref.dtype
    pid = pl.program_id(0)
    tile, s = order_ref[pid // STRIPS], pid % STRIPS
    frame = ks.lane_coordinates(tile, s * STRIP_PIXELS + lax.iota(jnp.int32, STRIP_PIXELS),
                                tiles_x, config, dt)
    bit = jnp.left_shift(jnp.int32(1), s)

    def fetch(j):
        jj = jnp.minimum(j, last_pair)
        return jj, ((mask_ref[jj] & bit) != 0) if config.warp_cull else None

    def pair_alpha(fetched):
        rec = [rec_ref[fetched[0], c] for c in range(ks.REC - 1)]
        alpha, hit, _ = ks.record_alpha(rec, frame, config)
        return alpha, hit, rec[7:10], rec[10]

    # With warp culling, the strip's mask bit decides (a warp-uniform branch, Sec. III-C).
    take = (lambda fetched: fetched[1]) if config.warp_cull else None
    _store(out_refs, tile * STRIPS + s,
           ks.staged_loop(start_ref[tile], end_ref[tile], STRIP_PIXELS, dt, fetch, pair_alpha,
                          config, UNROLL_LOCALGS, take))


def vanilla_kernel(order_ref, start_ref, end_ref, gauss_ref, rows_ref, *out_refs,
                   config: RasterConfig, tiles_x: int, last_pair: int):
    dt = rows_ref.dtype
    tile = order_ref[pl.program_id(0)]
    frame = ks.lane_coordinates(tile, lax.iota(jnp.int32, TILE_PIXELS), tiles_x, config, dt)
    fetch, pair_alpha = ks.vanilla_pairs(gauss_ref, rows_ref, tile, tiles_x, frame, config,
                                         last_pair)
    _store(out_refs, tile, ks.staged_loop(start_ref[tile], end_ref[tile], TILE_PIXELS, dt, fetch,
                                          pair_alpha, config, UNROLL_VANILLA))


def _compiler_params(num_warps: int):
    return pl_triton.CompilerParams(num_warps=num_warps, num_stages=1)


def forward(vanilla: bool, config: RasterConfig, interpret: bool, tiles_x: int, order, bins,
            data, dt):
    """Run the vanilla (data = (Gaussian ids, rows)) or Local-GS (data = (masks, records))
    forward kernel over tiles in `order`; outputs (n_tiles, 256) each: r, g, b, T, D and the stop
    pair ((n_strips, 32) in tile-major strip order is exactly (n_tiles, 256))."""
    n_tiles = bins.tile_start.shape[0]
    kernel, programs, lanes, warps = ((vanilla_kernel, n_tiles, TILE_PIXELS, 8) if vanilla else
                                      (localgs_kernel, n_tiles * STRIPS, STRIP_PIXELS, 1))
    kernel = functools.partial(kernel, config=config, tiles_x=tiles_x,
                               last_pair=bins.gauss.shape[0] - 1)
    out = jax.ShapeDtypeStruct((programs, lanes), dt)  # each program writes its own row
    stop = jax.ShapeDtypeStruct((programs, lanes), jnp.int32)
    outs = pl.pallas_call(
        kernel, out_shape=[out] * 5 + [stop], grid=(programs,),
        compiler_params=_compiler_params(warps), interpret=interpret,
        name=kernel.func.__name__,
    )(order, bins.tile_start, bins.tile_end, *data)
    return [x.reshape(n_tiles, TILE_PIXELS) for x in outs]


def _columns(values, lanes: int, dt):
    """Σ over lanes of each of `values` (`steps.term`s), as one (lanes, GRAD_COLUMNS) column
    reduction (one cross-warp reduction per pair instead of one per value)."""
    col = lax.broadcasted_iota(jnp.int32, (lanes, GRAD_COLUMNS), 1)
    m = jnp.zeros((lanes, GRAD_COLUMNS), dt)
    for c, v in enumerate(map(ks.term, values)):
        if v is not None:
            m = jnp.where(col == c, v[:, None], m)
    return jnp.sum(m, axis=0)


def backward_kernel(order_ref, start_ref, end_ref, mask_ref, row_ref, rec_ref, trans_ref,
                    stop_ref, g_r_ref, g_g_ref, g_b_ref, g_t_ref, g_d_ref, _zeros_ref, rows_ref,
                    *, config: RasterConfig, tiles_x: int):
    """One tile's backward walk (`steps.backward_step`): rows_ref[row_ref[j]] = (pair
    j's gradient summed over the tile's pixels, its tile) at the pair's row
    (`gaussian_grads.RowLayout.at`), for every pair some pixel blended (the others keep their
    zero row)."""
    dt = rec_ref.dtype
    tile = order_ref[pl.program_id(0)]
    trans, stop_at = trans_ref[tile, :], stop_ref[tile, :]
    lane = ks.backward_lanes(tile, lax.iota(jnp.int32, TILE_PIXELS), tiles_x, config, dt, trans,
                             stop_at, [ref[tile, :] for ref in (g_r_ref, g_g_ref, g_b_ref,
                                                                g_t_ref, g_d_ref)])
    start = start_ref[tile]
    last = jnp.minimum(end_ref[tile], jnp.max(stop_at))  # pairs at or after it: no pixel blended

    def body(i, carry):
        j = last - 1 - i
        rec = [rec_ref[j, c] for c in range(ks.REC - 1)]
        values, carry = ks.backward_step(j, rec, mask_ref[j] if config.warp_cull else None, lane,
                                         carry, config)
        row = _columns(values, TILE_PIXELS, dt)
        rows_ref[row_ref[j], :] = jnp.where(lax.iota(jnp.int32, GRAD_COLUMNS) == ks.TILE_COLUMN,
                                             tile.astype(dt), row)
        return carry

    zero = jnp.zeros((TILE_PIXELS,), dt)
    lax.fori_loop(0, jnp.maximum(last - start, 0), body, (trans, zero, zero, zero, zero))


def backward_rows(config: RasterConfig, interpret: bool, tiles_x: int, order, bins, layout,
                  masks, records, lane_rows, dt):
    """(1, layout.size, GRAD_COLUMNS) pair rows of the backward kernel
    (`gaussian_grads.RowLayout`; GRAD_VALUES gradient values, then the tile:
    backends.gaussian_grads); `lane_rows` = the per-tile (n_tiles, 256) final T, stop pairs and
    cotangents (r, g, b, T, D). A tile's walk ends at its last stop pair, which is the
    layout's end with walked rows (`gaussian_grads.walked_rows`)."""
    kernel = functools.partial(backward_kernel, config=config, tiles_x=tiles_x)
    zeros = jnp.zeros((layout.size, GRAD_COLUMNS), dt)
    rows = pl.pallas_call(
        kernel, out_shape=jax.ShapeDtypeStruct(zeros.shape, dt),
        grid=(bins.tile_start.shape[0],),
        input_output_aliases={13: 0},  # unvisited and padding pairs keep their zero row
        compiler_params=_compiler_params(8), interpret=interpret,
        name="localgs_backward",
    )(order, bins.tile_start, bins.tile_end, masks, layout.at, records, *lane_rows, zeros)
    return rows[None]
