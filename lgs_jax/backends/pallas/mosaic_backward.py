"""The backward kernel on Mosaic GPU: each tile's pairs walked back to front, a gradient row per
pair and block (lgs_jax.backends.pallas.steps.backward_step, the recurrence of
lgs_jax.backends.backward). Its plain-jnp counterpart is the `tiles` backend's walk
(`tiles.gradients`: the same rows, summed per Gaussian in another association).

The blocks walk the tile's pairs back to front from the last pair any of their pixels blended,
with pair records built in shared memory per chunk of 128 (lgs_jax.backends.pallas.staging:
chunks aligned to multiples of 128, built downward), and reduce each pair's gradient terms over
their pixels with a transposing butterfly (lgs_jax.backends.pallas.rows; interpret mode sums each
term with `jnp.sum`). A pair none of the block's strips takes (mask bits clear) is skipped by one
uniform branch. Each block writes its own row per pair at the pair's walked row
(gaussian_grads.RowLayout), zero where its pixels had stopped; lgs_jax.backends.pallas.
gaussian_grads adds a tile's blocks and sums each Gaussian's rows: one writer per row, no
atomics, a fixed summation order, deterministic. With `KernelConfig.backward_segment` the blocks
walk segments of at most that many pairs instead of whole lists, each entering from the
checkpoint the Local-GS forward stored there (lgs_jax.backends.pallas.segments).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
from jax import lax
from jax.experimental.pallas import mosaic_gpu as plgpu

from ...config import RasterConfig
from ...layout import TILE_PIXELS
from . import quotients, rows, segments, staging
from . import steps as ks
from .mosaic_forward import block_index, grid, guarded, interpret_params, lanes, strip_bits


def backward_kernel(seg_ref, gauss_ref, row_ref, table_ref, trans_ref, stop_ref, *refs,
                    config: RasterConfig, tiles_x: int, pixels: int, reduction: str,
                    last_pair: int, interpret: bool, from_checkpoints: bool,
                    depth_cotangent: bool = True, rows_per_fold: int | None = None):
    """The backward walk (`steps.backward_step`) for one warpgroup over segment
    seg_ref[s] = (tile, lo, hi, checkpoint) (lgs_jax.backends.pallas.segments: a tile's whole
    list by default): rows_ref[wg, r] = (pair j's gradient summed over this block's pixels, its
    tile) at the pair's row r = row_ref[j] (`gaussian_grads.RowLayout.at`), for the pairs in
    [lo, hi) before the block's last stop pair, and zero rows for the segment's pairs after it:
    every row is written once per block (the tile in every one), as `reduction` says
    (lgs_jax.backends.pallas.rows). (gauss_ref, table_ref): the pairs' Gaussian ids and
    `pairs.gaussian_table`, from which the records and strip masks are built per chunk in
    shared memory (`staging.backward_source`). `refs`: the cotangent rows (r, g, b, T, D;
    without D where not `depth_cotangent`, whose terms are then left out:
    `backward.walk_step`); with `from_checkpoints` (split segments), the buffers of the carries
    a segment that is not its tile's last enters with (`segments.entries`; without D − D_hi
    alike); then rows_ref; then the scratch: the records' (`staging.scratch`), then the
    reduction's (`rows.scratch`; the loop carries which exchange buffer is next). Each pair's
    row is loaded one pair ahead (the skip branch waits on it)."""
    dt = table_ref.dtype
    n_cot = 5 if depth_cotangent else 4
    n_in = n_cot * (2 if from_checkpoints else 1)  # cotangents, entering carries alike
    cot_refs, entry_refs, rows_ref, scratch = (refs[:n_cot], refs[n_cot:n_in], refs[n_in],
                                               refs[n_in + 1:])
    sid, wg = block_index(rows_per_fold), lax.axis_index("wg")
    tile, lo, hi, check = (seg_ref[sid, c] for c in range(segments.COLUMNS))
    k, _, half = lanes(wg, pixels)
    trans, stop_at = trans_ref[tile, half], stop_ref[tile, half]
    cots = [ref[tile, half] for ref in cot_refs] + [None] * (5 - n_cot)
    lane = ks.backward_lanes(tile, k, tiles_x, config, dt, trans, stop_at, cots)
    block_last = jnp.max(stop_at)
    last = jnp.clip(block_last, lo, hi)
    mine = strip_bits(wg, pixels)
    store_row, zero_row = rows.writers(reduction, rows_ref, wg, tile, pixels, *scratch[1:])
    record, mask_of, begin = staging.backward_source(gauss_ref, table_ref, scratch[0], tile,
                                                     tiles_x, config, last_pair, interpret)

    def ahead(j):  # pair j's (strip mask placeholder, row)
        return jnp.int32(0), row_ref[jnp.maximum(j, 0)]

    def skip(j, mask_word, s, carry, parity):  # a zero row, the carry unchanged
        del j, mask_word
        zero_row(s)
        return carry, parity

    def step(j, mask_word, s, carry, parity):
        values, carry = ks.backward_step(j, record(j), mask_word if config.warp_cull else None,
                                         lane, carry, config, quotients.of(interpret, dt))
        return carry, store_row(values, s, parity)

    def body(i, state):
        (mask_word, s), carry, parity = state
        j = last - 1 - i
        begin(i, j)
        if config.warp_cull:
            mask_word = mask_of(j)
        following = ahead(j - 1)
        if config.warp_cull:  # a pair none of this block's strips takes: zero row, same carry
            carry, parity = lax.cond((mask_word & mine) != 0, step, skip, j, mask_word, s, carry,
                                     parity)
        else:
            carry, parity = step(j, mask_word, s, carry, parity)
        return following, carry, parity

    entry = segments.enter(trans, stop_at, hi, entry_refs, check, hi < block_last, half)
    lax.fori_loop(0, last - lo, body, (ahead(last - 1), entry, jnp.int32(0)))

    def after(i, c):  # pairs no pixel of this block reached
        zero_row(row_ref[last + i])
        return c

    lax.fori_loop(0, hi - last, after, jnp.int32(0))


def backward_rows(config: RasterConfig, interpret: bool, pixels: int, tiles_x: int, segs,
                  bins, layout, table, lane_rows, dt, entry=(),
                  reduction: str | None = None):
    """(blocks per tile, layout.size, width) pair rows (`gaussian_grads.RowLayout`) from
    `backward_kernel` on a (segments, blocks per tile) grid: block w's row of each pair with a
    row (gradient over its pixels, then the tile), zero where the block's pixels had stopped;
    rows no pair has are left unwritten (no Gaussian's rows reach them). `segs`: the
    (n, segments.COLUMNS) table (`segments.whole_tiles` or `segments.split`); `entry`: with
    split segments, `segments.entries` (C − C_hi for r, g, b; T_hi; D − D_hi per checkpoint).
    `table`: `pairs.gaussian_table` of the Gaussians. `lane_rows` = the per-tile final T, stop
    pairs and cotangents (r, g, b, T, D; D left out where it is zero, a symbolic zero not
    materialised, and with it the rows' ∂L/∂z column: width = `steps.row_width`, the tile
    last). `reduction`: `rows.resolve`'s (by default "transposed" on the GPU, "terms" in
    interpret mode)."""
    reduction = rows.resolve(reduction, interpret)
    capacity = bins.gauss.shape[0]
    n = TILE_PIXELS // pixels
    launch, names, fold = grid(segs.shape[0], n)
    kernel = functools.partial(backward_kernel, config=config, tiles_x=tiles_x, pixels=pixels,
                               reduction=reduction, last_pair=capacity - 1, interpret=interpret,
                               from_checkpoints=bool(entry), depth_cotangent=len(lane_rows) == 7,
                               rows_per_fold=fold)
    out = jax.ShapeDtypeStruct((n, layout.size, ks.row_width(len(lane_rows) == 7)), dt)
    scratch = staging.scratch(dt) + rows.scratch(reduction, dt)
    return plgpu.kernel(guarded(kernel, segs.shape[0], fold), out_type=out,
                        scratch_types=scratch, grid=launch, grid_names=names,
                        interpret=interpret_params(interpret),
                        kernel_name="localgs_backward_mosaic")(
        segs, bins.gauss, layout.at, table, *lane_rows, *entry)
