"""The Local-GS and vanilla forward kernels and the backward kernel on Mosaic GPU
(`jax.experimental.pallas.mosaic_gpu`), the Pallas GPU backend JAX supports going forward. The
per-pair arithmetic is lgs_jax.backends.kernel_steps, shared with the Triton kernels
(lgs_jax.backends.pallas_triton); lgs_jax.backends.pallas picks between the two.

Mapping. A Mosaic GPU (Pallas) thread is a 128-lane warpgroup, and each block is one
warpgroup on a grid (tiles in longest-list-first order, blocks per tile) of one of two sizes
(`pixels`, resolved by lgs_jax.backends.pallas.block_pixels): 128 pixels (a half tile of four
16x2 strips, one per hardware warp: lane l of block w is tile pixel 128·w + l) or 256 (the whole
tile in one block, each lane holding two adjacent pixels of one row: Mosaic GPU's strided layout
of a (256,) array, so a hardware warp holds two strips). A block walks its tile's pairs and
stops as soon as its pixels are done. (Two warpgroups in one block with independent early exits
crashed on the H100 with CUDA_ERROR_ILLEGAL_INSTRUCTION on real scenes: the loop's cross-warp
reductions synchronise the block; two pixels per lane avoid that and share every record load
and loop step between them.) Whole tiles win where tiles are many and their lists short, half
tiles where lists are long (two blocks stop independently; the backward skips the pairs none of
a block's four strips takes): BENCHMARKS.md §6 has the measurements behind the default.

Culling. The strip-mask bit of a pair is tested per lane (each lane's strip); as a lane
predicate it is uniform within each strip's lanes, so the hardware never diverges inside one,
but Pallas:MGPU has no way to *skip* work per warp inside a warpgroup (`plgpu.warp_map` runs
scalar per-warp code, not array code), so the α of a pair whose bit is clear for some of the
block's strips is still computed there. Branching around a staged group with no bit set in any
of the block's strips measured slower than predicating (BENCHMARKS.md §6), so the kernel stages
`tuning.mosaic_unroll_localgs` pairs per iteration and lets the lane predicates do the culling.
With `tuning.mosaic_compact` (`compacts`; the default) the block culls instead: of each chunk of
128 pairs it builds, it walks only those with a mask bit in its own strips
(lgs_jax.backends.mosaic_staging.compact_loop), the full walk's outputs (bit for bit in float32 on
the H200; float64 within ulps there, another compilation's multiply-add contractions). With
`tuning.mosaic_warp_lists` (`warp_lists`; the default) each warp walks only the pairs of its own
strip: per-lane shared-memory reads, one record per warp, written as inline Mosaic GPU code
(lgs_jax.backends.mosaic_warp_lists), which makes the paper's warp-level skip real inside one
warpgroup program (the loop runs to the busiest warp's count).

Pair records. By default (`tuning.mosaic_pair_source="gaussians"`) the Local-GS forward and
the backward build them inside the kernel, per chunk of 128 pairs, from the pairs' Gaussian ids
and per-Gaussian rows (lgs_jax.backends.mosaic_staging: an inline per-lane gather, the records
and strip masks on lane vectors, shared memory), with no per-pair buffer in global memory. With
"records" they read records XLA built (`kernel_steps.pair_records`), staged in shared memory by
TMA where `tuning.mosaic_chunk` > 0 and they are float32 (lgs_jax.backends.mosaic_tma).

Arithmetic and blending are exactly those of the Triton kernels (the same functions), so the
images are the same to the bit in interpret mode (on the GPU the two compilers' exp and
multiply-add contraction differ by ulps); both record per-pixel stop pairs for the backward.

Backward. The same blocks walk the tile's pairs back to front from the last pair any of their pixels
blended (`kernel_steps.backward_step`), float32 records staged in shared memory as in the forward
(chunks aligned to multiples of the chunk size, copied downward), and reduce each pair's 11 gradient
terms over their pixels with a transposing butterfly (lgs_jax.backends.mosaic_rows, inline Mosaic
GPU code: 13 shuffles per thread where one warp reduction per term takes 55, one exchange across the
warps, one barrier per pair, one coalesced store of the row; interpret mode, which cannot run inline
code, sums each term with `jnp.sum`). A pair none of the block's strips takes (mask bits clear) is
skipped by one uniform branch: unlike the forward's staged groups, a backward step is long enough
for the branch to pay. Each block writes its own row per pair at the pair's walked row
(gaussian_grads.RowLayout) (zero where its pixels had stopped;
lgs_jax.backends.gaussian_grads adds a tile's blocks and sums each Gaussian's rows): one writer per
row, no atomics, a fixed summation order, deterministic. With `tuning.mosaic_backward_segment` the
blocks walk segments of at most that many pairs instead of whole lists, each entering from the
checkpoint the Local-GS forward stored there (lgs_jax.backends.backward_segments): the walk's length
is then a segment, not the longest list's walk.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
from jax import lax
from jax.experimental import pallas as pl
from jax.experimental.pallas import mosaic_gpu as plgpu

from ..config import RasterConfig
from ..layout import STRIP_PIXELS, TILE, TILE_PIXELS
from . import kernel_steps as ks
from . import (backward_segments, mosaic_inline, mosaic_quotients, mosaic_rows, mosaic_staging,
               mosaic_tma, mosaic_warp_lists)


def _ranges(*columns):
    """(n_tiles, len(columns)) per-tile values (e.g. [start, end)) as one fresh buffer: Mosaic
    GPU requires 256-byte aligned operands, and XLA may pass `tile_end` (a slice of the ranges
    scan) at an offset."""
    return jnp.stack(columns, -1)


def _interpret_params(interpret: bool):
    return plgpu.InterpretGPUParams() if interpret else None


def _lanes(wg, pixels: int):
    """Tile pixel indices of block `wg` of `pixels` pixels (a warpgroup array: one or two per
    lane) and their strips (0..7), and the block's slice of a tile row."""
    k = lax.broadcasted_iota(jnp.int32, (pixels,), 0) + wg * pixels
    return k, k // STRIP_PIXELS, pl.ds(wg * pixels, pixels)


def _store(refs, tile, cols, outputs):
    """Write a block's pixels (`cols`, from `_lanes`) of row `tile` of the (n_tiles, 256)
    outputs."""
    for ref, x in zip(refs, outputs):
        ref[tile, cols] = x.astype(ref.dtype)


def _forward_store(image: bool, block_stops: bool, tiles_x: int, wg, pixels: int):
    """The Local-GS forward's store of its (r, g, b, T, D, stop pair) into `forward`'s outputs:
    `_store`'s per-tile planes, except, with `image`, the colour into a (tiles_y·16, tiles_x·16,
    3) image (block `wg` of tile `tile` holds rows wg·pixels/16 .. of the tile, pixel k of the
    block at row k // 16, column k % 16: lgs_jax.layout; each channel one (pixels/16, 16) box,
    stored with a stride of 3, one element per thread: blocks of 128 pixels, as Mosaic GPU
    refuses a stride of 3 with two elements per thread), and with `block_stops` the block's
    latest stop pair alone, at [tile, wg] of a (n_tiles, 256 / pixels) output."""
    rows = pixels // TILE

    def store(refs, tile, cols, outputs):
        color, (trans, depth, stop) = outputs[:3], outputs[3:]
        if image:
            color_ref, refs = refs[0], refs[1:]
            y, x = (tile // tiles_x) * TILE + wg * rows, (tile % tiles_x) * TILE
            for c in range(3):
                color_ref[pl.ds(y, rows), pl.ds(x, TILE), c] = (
                    color[c].astype(color_ref.dtype).reshape(rows, TILE))
        else:
            _store(refs[:3], tile, cols, color)
            refs = refs[3:]
        _store(refs[:2], tile, cols, (trans, depth))
        if block_stops:
            refs[2][tile, wg] = jnp.max(stop)
        else:
            _store(refs[2:], tile, cols, (stop,))

    return store


def _strip_bits(wg, pixels: int):
    """The mask bits of the strips of block `wg` of `pixels` pixels (a uniform branch's test)."""
    per_block = pixels // STRIP_PIXELS
    return jnp.left_shift(jnp.int32((1 << per_block) - 1), wg * per_block)


def compacts(config: RasterConfig) -> bool:
    """Whether the Local-GS forward walks each chunk's pairs of its block only
    (`KernelConfig.mosaic_compact`, `mosaic_staging.compact_loop`): asked for, records built
    from Gaussians, exact blending (a pixel's stop pair), strip masks on (`warp_cull`), and the
    split backward's entries (stored at the forward's chunk starts) at multiples of 128. Both
    α forms (hoisted and difference) compact."""
    t = config.tuning
    segment = t.mosaic_backward_segment
    return (t.mosaic_compact and t.mosaic_pair_source == "gaussians"
            and config.blend == "exact" and config.warp_cull
            and (segment is None or segment % mosaic_staging.LANES == 0))


def warp_lists(config: RasterConfig, pixels: int) -> bool:
    """Whether the compacted forward walks per-warp lists (`KernelConfig.mosaic_warp_lists`,
    lgs_jax.backends.mosaic_warp_lists): asked for, compacting, half-tile blocks (one pixel per
    lane, so a warp is one strip); whole-tile blocks compact per block."""
    return (config.tuning.mosaic_warp_lists and compacts(config)
            and pixels == mosaic_warp_lists.LANES)


def localgs_kernel(order_ref, ranges_ref, mask_ref, rec_ref, *refs,
                   config: RasterConfig, tiles_x: int, last_pair: int, pixels: int,
                   interpret: bool, segment: int | None = None, image: bool = False,
                   block_stops: bool = False):
    """The Local-GS forward for one warpgroup; `refs` = the six outputs (four with `image`:
    the colour image, T, D, the stop pairs; `_forward_store`), then, with a
    `segment`, the five checkpoint outputs (r, g, b, T, D before every pair start + m·segment,
    m >= 1, at row ranges_ref[tile, 2] + m − 1: lgs_jax.backends.backward_segments), then, when
    `mosaic_tma.staged`, the shared-memory record buffers and their barriers. With
    `tuning.mosaic_pair_source` "gaussians", (mask_ref, rec_ref) are (the pairs' Gaussian ids,
    `pairs.gaussian_table`) and the scratch is lgs_jax.backends.mosaic_staging's."""
    n_plain = 4 if image else 6
    n_out = n_plain if segment is None else n_plain + 5
    out_refs, check_refs, scratch = refs[:n_plain], refs[n_plain:n_out], refs[n_out:]
    dt = rec_ref.dtype
    tid, wg = lax.axis_index("tile"), lax.axis_index("wg")
    tile = order_ref[tid]
    start, end = ranges_ref[tile, 0], ranges_ref[tile, 1]
    k, strip, cols = _lanes(wg, pixels)
    frame, pixel = ks.lane_coordinates(tile, k, tiles_x, config, dt)
    bit = jnp.left_shift(jnp.int32(1), strip)
    store = _forward_store(image, block_stops, tiles_x, wg, pixels)

    def evaluate(rec, mask_word):  # mask_word None: a pair known to have this lane's bit
        alpha, hit, _ = ks.record_alpha(rec, frame, pixel, config)
        if config.warp_cull and mask_word is not None:
            hit = hit & ((mask_word & bit) != 0)
        return alpha, hit, rec[7:10], rec[10]

    checkpoint = None
    if segment is not None:
        checkpoint = _checkpoint(check_refs, ranges_ref[tile, 2], start, cols, segment)
    if compacts(config):
        shift = wg * (pixels // STRIP_PIXELS) if warp_lists(config, pixels) else None
        store(out_refs, tile, cols, mosaic_staging.compact_loop(
            mask_ref, rec_ref, scratch, start, end, tile, tiles_x, _strip_bits(wg, pixels),
            evaluate, k.shape[0], dt, config, last_pair, interpret, checkpoint, shift))
        return
    if config.tuning.mosaic_pair_source == "gaussians":
        fetch, pair_alpha, stage = mosaic_staging.forward_source(
            mask_ref, rec_ref, scratch[0], start, end, tile, tiles_x, evaluate, config,
            last_pair, interpret)
    elif scratch:
        fetch, pair_alpha, stage = mosaic_tma.forward_source(rec_ref, *scratch, start, end,
                                                             evaluate, config)
    else:
        def fetch(j):
            jj = jnp.minimum(j, last_pair)
            return jj, mask_ref[jj] if config.warp_cull else None

        def pair_alpha(fetched):
            return evaluate([rec_ref[fetched[0], c] for c in range(ks.REC - 1)], fetched[1])

        stage = None
    store(out_refs, tile, cols,
          ks.staged_loop(start, end, k.shape[0], dt, fetch, pair_alpha, config,
                         config.tuning.mosaic_unroll_localgs, stage=stage,
                         checkpoint=checkpoint, more=mosaic_inline.running(config, interpret)))


def _checkpoint(refs, base, start, cols, segment: int):
    """`staged_loop`'s checkpoint hook: the state (r, g, b, T, D) before pair start + m·segment
    (m >= 1) into row base + m − 1 of `refs` (lgs_jax.backends.backward_segments)."""
    def checkpoint(j, state):
        m = (j - start) // segment

        @pl.when((j > start) & ((j - start) % segment == 0))
        def _():
            _store(refs, base + m - 1, cols, state[:5])

    return checkpoint


def vanilla_kernel(order_ref, ranges_ref, gauss_ref, rows_ref, *out_refs,
                   config: RasterConfig, tiles_x: int, last_pair: int, pixels: int,
                   interpret: bool):
    """The original 3DGS forward for one warpgroup."""
    dt = rows_ref.dtype
    tid, wg = lax.axis_index("tile"), lax.axis_index("wg")
    tile = order_ref[tid]
    k, _, cols = _lanes(wg, pixels)
    _, pixel = ks.lane_coordinates(tile, k, tiles_x, config, dt)
    fetch, pair_alpha = ks.vanilla_pairs(gauss_ref, rows_ref, pixel, config, last_pair)
    _store(out_refs, tile, cols,
           ks.staged_loop(ranges_ref[tile, 0], ranges_ref[tile, 1], k.shape[0], dt, fetch,
                          pair_alpha, config, config.tuning.mosaic_unroll_vanilla,
                          more=mosaic_inline.running(config, interpret)))


def forward(vanilla: bool, config: RasterConfig, interpret: bool, pixels: int, tiles_x: int,
            order, bins, data, dt, segment: int | None = None, image: bool = False,
            block_stops: bool = False):
    """Run the vanilla (data = (Gaussian ids, rows)) or Local-GS (data = (masks, records), or
    (Gaussian ids, `pairs.gaussian_table`) with `tuning.mosaic_pair_source` "gaussians")
    forward kernel on a (n_tiles, 256 / pixels) grid of one-warpgroup blocks; outputs
    (n_tiles, 256) each: r, g, b, T, D and the stop pair, or with `image` (Local-GS, blocks of
    128 pixels) the colour as one (tiles_y·16, tiles_x·16, 3) image and T, D, the stop pair;
    with `block_stops` (Local-GS) the stop pairs as each block's latest, (n_tiles, 256 /
    pixels); then with a `segment` (Local-GS only) the five (n_checkpoints, 256) checkpoint
    buffers of `backward_segments.checkpoints`."""
    if (image and pixels != 128) or (vanilla and (image or block_stops)):
        raise ValueError("image, block_stops: the Local-GS kernel's (image: blocks of 128)")
    n_tiles = bins.tile_start.shape[0]
    common = dict(config=config, tiles_x=tiles_x, last_pair=bins.gauss.shape[0] - 1,
                  pixels=pixels, interpret=interpret)
    kernel = (functools.partial(vanilla_kernel, **common) if vanilla else
              functools.partial(localgs_kernel, **common, segment=segment, image=image,
                                block_stops=block_stops))
    columns = [bins.tile_start, bins.tile_end]
    checks = []
    if segment is not None:
        base, rows = backward_segments.checkpoints(bins, segment)
        columns.append(base)
        checks = [jax.ShapeDtypeStruct((rows, TILE_PIXELS), dt)] * 5
    scratch = ()
    if not vanilla and warp_lists(config, pixels):
        scratch = mosaic_warp_lists.scratch(dt)
    elif not vanilla and compacts(config):
        scratch = mosaic_staging.compact_scratch(dt)
    elif not vanilla and config.tuning.mosaic_pair_source == "gaussians":
        scratch = mosaic_staging.scratch(dt)
    elif not vanilla and mosaic_tma.staged(config, dt):
        scratch = mosaic_tma.scratch(config, dt)
    out = jax.ShapeDtypeStruct((n_tiles, TILE_PIXELS), dt)
    stop = jax.ShapeDtypeStruct((n_tiles, TILE_PIXELS // pixels if block_stops else TILE_PIXELS),
                                jnp.int32)
    planes = [out] * 5
    if image:
        shape = (n_tiles // tiles_x * TILE, tiles_x * TILE, 3)
        planes = [jax.ShapeDtypeStruct(shape, dt), out, out]
    return plgpu.kernel(kernel, out_type=planes + [stop] + checks, scratch_types=scratch,
                        grid=(n_tiles, TILE_PIXELS // pixels), grid_names=("tile", "wg"),
                        interpret=_interpret_params(interpret),
                        kernel_name=kernel.func.__name__)(order, _ranges(*columns), *data)


def backward_kernel(seg_ref, mask_ref, row_ref, rec_ref, trans_ref, stop_ref, *refs,
                    config: RasterConfig, tiles_x: int, pixels: int, reduction: str,
                    last_pair: int, interpret: bool, from_checkpoints: bool,
                    depth_cotangent: bool = True):
    """The backward walk (`kernel_steps.backward_step`) for one warpgroup over segment
    seg_ref[s] = (tile, lo, hi, checkpoint) (lgs_jax.backends.backward_segments: a tile's whole
    list by default): rows_ref[wg, r] = (pair j's gradient summed over this block's pixels, its
    tile) at the pair's row r = row_ref[j] (`gaussian_grads.RowLayout.at`), for the pairs in
    [lo, hi) before the block's last stop pair, and zero rows for the segment's pairs after it:
    every row is written once per block (the tile in every one), as `reduction` says
    (lgs_jax.backends.mosaic_rows). `refs`: the cotangent rows (r, g, b, T, D; without D where
    not `depth_cotangent`, whose terms are then left out: `backward.walk_step`); with
    `from_checkpoints` (split segments), the buffers of the carries a segment that is not its
    tile's last enters with (`backward_segments.entries`; without D − D_hi alike);
    then rows_ref; then the scratch:
    when `mosaic_tma.staged`, the shared-memory record buffers and their barriers
    (`mosaic_tma.backward_source`), then the reduction's (`mosaic_rows.scratch`; the loop carries
    which exchange buffer is next). Each pair's strip mask and row are loaded one pair ahead
    (the skip branch waits on them). With `tuning.mosaic_pair_source` "gaussians", (mask_ref,
    rec_ref) are (the pairs' Gaussian ids, `pairs.gaussian_table`), the records and masks are
    built per chunk in shared memory (`mosaic_staging`, its buffers first in the scratch) and a
    pair's mask is read there once its chunk is built."""
    dt = rec_ref.dtype
    n_cot = 5 if depth_cotangent else 4
    n_in = n_cot * (2 if from_checkpoints else 1)  # cotangents, entering carries alike
    cot_refs, entry_refs, rows_ref, scratch = (refs[:n_cot], refs[n_cot:n_in], refs[n_in],
                                               refs[n_in + 1:])
    sid, wg = lax.axis_index("tile"), lax.axis_index("wg")
    tile, lo, hi, check = (seg_ref[sid, c] for c in range(backward_segments.COLUMNS))
    k, _, half = _lanes(wg, pixels)
    trans, stop_at = trans_ref[tile, half], stop_ref[tile, half]
    cots = [ref[tile, half] for ref in cot_refs] + [None] * (5 - n_cot)
    lane = ks.backward_lanes(tile, k, tiles_x, config, dt, trans, stop_at, cots)
    block_last = jnp.max(stop_at)
    last = jnp.clip(block_last, lo, hi)
    mine = _strip_bits(wg, pixels)
    n = len(scratch) - len(mosaic_rows.scratch(reduction, dt))  # the records' scratch first
    store_row, zero_row = mosaic_rows.writers(reduction, rows_ref, wg, tile, pixels,
                                              *scratch[n:])
    record, mask_of, begin = _backward_records(rec_ref, mask_ref, scratch[:n], tile, tiles_x,
                                               lo, last, config, last_pair, interpret)

    def ahead(j):  # pair j's (strip mask, row)
        jj = jnp.maximum(j, 0)
        ahead_mask = config.warp_cull and mask_of is None
        return mask_ref[jj] if ahead_mask else jnp.int32(0), row_ref[jj]

    def skip(j, mask_word, s, carry, parity):  # a zero row, the carry unchanged
        del j, mask_word
        zero_row(s)
        return carry, parity

    def step(j, mask_word, s, carry, parity):
        values, carry = ks.backward_step(j, record(j), mask_word if config.warp_cull else None,
                                         lane, carry, config, mosaic_quotients.of(interpret, dt))
        return carry, store_row(values, s, parity)

    def body(i, state):
        (mask_word, s), carry, parity = state
        j = last - 1 - i
        if begin is not None:
            begin(i, j)
        if config.warp_cull and mask_of is not None:
            mask_word = mask_of(j)
        following = ahead(j - 1)
        if config.warp_cull:  # a pair none of this block's strips takes: zero row, same carry
            carry, parity = lax.cond((mask_word & mine) != 0, step, skip, j, mask_word, s, carry,
                                     parity)
        else:
            carry, parity = step(j, mask_word, s, carry, parity)
        return following, carry, parity

    entry = backward_segments.enter(trans, stop_at, hi, entry_refs, check, hi < block_last, half)
    lax.fori_loop(0, last - lo, body, (ahead(last - 1), entry, jnp.int32(0)))

    def after(i, c):  # pairs no pixel of this block reached
        zero_row(row_ref[last + i])
        return c

    lax.fori_loop(0, hi - last, after, jnp.int32(0))


def _backward_records(rec_ref, mask_ref, scratch, tile, tiles_x: int, start, last,
                      config: RasterConfig, last_pair: int, interpret: bool):
    """The backward walk's (record(j), mask(j) or None, begin(i, j) or None): records built in
    the kernel from Gaussians (`mosaic_staging.backward_source`; mask_ref holds the pairs'
    Gaussian ids and rec_ref the table), staged by TMA (`mosaic_tma.backward_source`, when
    `scratch` holds its buffers) or read from global memory."""
    if config.tuning.mosaic_pair_source == "gaussians":
        return mosaic_staging.backward_source(mask_ref, rec_ref, scratch[0], tile, tiles_x,
                                              config, last_pair, interpret)
    if scratch:
        record, begin = mosaic_tma.backward_source(rec_ref, *scratch, start, last,
                                               config.tuning.mosaic_chunk)
        return record, None, begin
    return (lambda j: [rec_ref[j, c] for c in range(ks.REC - 1)]), None, None


def backward_rows(config: RasterConfig, interpret: bool, pixels: int, tiles_x: int, segments,
                  bins, layout, masks, records, lane_rows, dt, entry=(),
                  reduction: str | None = None):
    """(blocks per tile, layout.size, width) pair rows (`gaussian_grads.RowLayout`) from
    `backward_kernel` on a (segments, blocks per tile) grid: block w's row of each pair with a
    row (gradient over its pixels, then the tile), zero where the block's pixels had stopped;
    rows no pair has are left unwritten (no Gaussian's rows reach them). `segments`: the
    (n, backward_segments.COLUMNS) table (`backward_segments.whole_tiles` or `split`);
    `entry`: with split segments, `backward_segments.entries` (C − C_hi for r, g, b; T_hi;
    D − D_hi per checkpoint). `lane_rows` = the per-tile final T, stop pairs and cotangents
    (r, g, b, T, D; D left out where it is zero, a symbolic zero not materialised, and with
    it the rows' ∂L/∂z column: width = `kernel_steps.row_width`, the tile last). (masks,
    records): the pairs' (Gaussian ids, `pairs.gaussian_table`) with
    `tuning.mosaic_pair_source` "gaussians". `reduction`: `mosaic_rows.resolve`'s (by default
    "transposed" on the GPU, "terms" in interpret mode)."""
    reduction = mosaic_rows.resolve(reduction, interpret)
    capacity = bins.gauss.shape[0]
    n = TILE_PIXELS // pixels
    kernel = functools.partial(backward_kernel, config=config, tiles_x=tiles_x, pixels=pixels,
                               reduction=reduction, last_pair=capacity - 1, interpret=interpret,
                               from_checkpoints=bool(entry), depth_cotangent=len(lane_rows) == 7)
    out = jax.ShapeDtypeStruct((n, layout.size, ks.row_width(len(lane_rows) == 7)), dt)
    scratch = ()
    if config.tuning.mosaic_pair_source == "gaussians":
        scratch = mosaic_staging.scratch(dt)
    elif mosaic_tma.staged(config, dt):
        scratch = mosaic_tma.scratch(config, dt)
    scratch += mosaic_rows.scratch(reduction, dt)
    return plgpu.kernel(kernel, out_type=out, scratch_types=scratch,
                        grid=(segments.shape[0], n), grid_names=("tile", "wg"),
                        interpret=_interpret_params(interpret),
                        kernel_name="localgs_backward_mosaic")(
        segments, masks, layout.at, records, *lane_rows, *entry)
