"""The Local-GS and vanilla forward kernels on Mosaic GPU (`jax.experimental.pallas.mosaic_gpu`),
the Pallas GPU backend JAX supports going forward. The per-pair arithmetic is
lgs_jax.backends.pallas.steps, shared with the Triton kernels (lgs_jax.backends.pallas.triton);
`reference` is what a forward computes, in plain jnp (the `tiles` backend's walk).

Mapping. A Mosaic GPU (Pallas) thread is a 128-lane warpgroup, and each block is one warpgroup
on a grid (tiles in longest-list-first order, blocks per tile) of one of two sizes (`pixels`,
lgs_jax.backends.pallas.plan): 128 pixels (a half tile of four 16x2 strips, one per hardware
warp: lane l of block w is tile pixel 128·w + l) or 256 (the whole tile in one block, each lane
holding two adjacent pixels of one row: Mosaic GPU's strided layout of a (256,) array). A block
walks its tile's pairs and stops as soon as its pixels are done. (Two warpgroups in one block
with independent early exits crash: the loop's cross-warp reductions synchronise the block; two
pixels per lane avoid that and share every record load and loop step between them.)

Pair records are built inside the kernel, per chunk of 128 pairs, from the pairs' Gaussian ids
and the per-Gaussian table (lgs_jax.backends.pallas.staging); the vanilla kernel reads each
pair's Gaussian row by id, as the original rasterizer does.

Culling. With exact blending and warp culling (`compacts`, the default) the Local-GS forward runs
half-tile blocks in which each hardware warp walks only the pairs of its own strip
(`compact_loop`, lgs_jax.backends.pallas.warp_lists): the paper's warp-level skip inside one
warpgroup program. Otherwise (fast blending, or warp culling off) a block walks every pair of
its tile and the strip-mask bit is a per-lane predicate, uniform within each strip's lanes
(`steps.staged_loop`). Both walks give the same outputs: a pair a warp skips has its strip's bit
clear, so no pixel of the strip passes its α test (the masks are conservative).

Outputs per tile (n_tiles, 256): r, g, b, T, D and each pixel's stop pair, the backward's
residuals. A render no gradient follows (`block_stops`) keeps only each block's latest stop
pair; the half-tile Local-GS forward writes its colour as one (H, W, 3) image (`image`) rather
than three planes, so the planes and the image are never live together.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
from jax import lax
from jax.experimental import pallas as pl
from jax.experimental.pallas import mosaic_gpu as plgpu

from ... import pairs
from ...config import RasterConfig
from ...layout import STRIP_PIXELS, TILE, TILE_PIXELS
from . import inline, segments, staging, warp_lists
from . import steps as ks
from .inline import LANES

UNROLL_VANILLA = 8  # pairs the vanilla kernel stages per loop iteration
MAX_GRID_YZ = 65535  # CUDA's limit on a launch's gridDim.y and gridDim.z (x: 2^31 − 1)


def grid(blocks: int, per_block: int):
    """(grid, names, rows) of a launch of `blocks` × `per_block` warpgroups: Mosaic GPU maps a
    Pallas grid (a, b) to CUDA's (x, y) = (b, a), so the long axis `blocks` (tiles, or the
    split backward's segments) lands on y, limited to MAX_GRID_YZ. Up to that limit the grid is
    (blocks, per_block) named ("tile", "wg"); beyond it `blocks` is folded as (hi, rows) onto z
    and y (block i = hi·rows + lo, launched in the same order), blocks past the last doing
    nothing (`block_index`). Every dimension then stays within CUDA's limits for any int32
    count of blocks."""
    if blocks <= MAX_GRID_YZ:
        return (blocks, per_block), ("tile", "wg"), None
    rows = MAX_GRID_YZ
    hi = -(-blocks // rows)
    if hi > MAX_GRID_YZ:
        raise ValueError(f"{blocks} blocks exceed CUDA's grid ({MAX_GRID_YZ}^2 on y and z)")
    return (hi, rows, per_block), ("hi", "tile", "wg"), rows


def block_index(rows: int | None):
    """This warpgroup's block along `grid`'s long axis (its folded row index, where `rows`)."""
    if rows is None:
        return lax.axis_index("tile")
    return lax.axis_index("hi") * rows + lax.axis_index("tile")


def guarded(kernel, blocks: int, rows: int | None):
    """`kernel` run only for block indices below `blocks` (a folded grid's tail does nothing);
    `kernel` itself where the grid is not folded."""
    if rows is None:
        return kernel

    def run(*refs, **kwargs):
        @pl.when(block_index(rows) < blocks)
        def _():
            kernel(*refs, **kwargs)

    return functools.wraps(kernel)(run)


def ranges(*columns):
    """(n_tiles, len(columns)) per-tile values (e.g. [start, end)) as one fresh buffer: Mosaic
    GPU requires 256-byte aligned operands, and XLA may pass `tile_end` (a slice of the ranges
    scan) at an offset."""
    return jnp.stack(columns, -1)


def interpret_params(interpret: bool):
    """`plgpu.kernel`'s `interpret` argument."""
    return plgpu.InterpretGPUParams() if interpret else None


def lanes(wg, pixels: int):
    """Tile pixel indices of block `wg` of `pixels` pixels (a warpgroup array: one or two per
    lane) and their strips (0..7), and the block's slice of a tile row."""
    k = lax.broadcasted_iota(jnp.int32, (pixels,), 0) + wg * pixels
    return k, k // STRIP_PIXELS, pl.ds(wg * pixels, pixels)


def store(refs, tile, cols, outputs):
    """Write a block's pixels (`cols`, from `lanes`) of row `tile` of the (n_tiles, 256)
    outputs."""
    for ref, x in zip(refs, outputs):
        ref[tile, cols] = x.astype(ref.dtype)


def strip_bits(wg, pixels: int):
    """The mask bits of the strips of block `wg` of `pixels` pixels."""
    per_block = pixels // STRIP_PIXELS
    return jnp.left_shift(jnp.int32((1 << per_block) - 1), wg * per_block)


def compacts(config: RasterConfig) -> bool:
    """Whether the Local-GS forward walks per-warp lists (`compact_loop`): exact blending (a
    pixel's stop pair), strip masks on (`warp_cull`), and the split backward's entries (stored
    at the forward's chunk starts) at multiples of 128. Both α forms (hoisted and difference)
    compact. Such a forward runs half-tile blocks (one warp per strip)."""
    segment = config.tuning.backward_segment
    return (config.blend == "exact" and config.warp_cull
            and (segment is None or segment % LANES == 0))


def _forward_store(image: bool, block_stops: bool, tiles_x: int, wg, pixels: int):
    """The Local-GS forward's store of its (r, g, b, T, D, stop pair) into `forward`'s outputs:
    `store`'s per-tile planes, except, with `image`, the colour into a (tiles_y·16, tiles_x·16,
    3) image (block `wg` of tile `tile` holds rows wg·pixels/16 .. of the tile, pixel k of the
    block at row k // 16, column k % 16: lgs_jax.layout; each channel one (pixels/16, 16) box,
    stored with a stride of 3, one element per thread: blocks of 128 pixels, as Mosaic GPU
    refuses a stride of 3 with two elements per thread), and with `block_stops` the block's
    latest stop pair alone, at [tile, wg] of a (n_tiles, 256 / pixels) output."""
    rows = pixels // TILE

    def write(refs, tile, cols, outputs):
        color, (trans, depth, stop) = outputs[:3], outputs[3:]
        if image:
            color_ref, refs = refs[0], refs[1:]
            y, x = (tile // tiles_x) * TILE + wg * rows, (tile % tiles_x) * TILE
            for c in range(3):
                color_ref[pl.ds(y, rows), pl.ds(x, TILE), c] = (
                    color[c].astype(color_ref.dtype).reshape(rows, TILE))
        else:
            store(refs[:3], tile, cols, color)
            refs = refs[3:]
        store(refs[:2], tile, cols, (trans, depth))
        if block_stops:
            refs[2][tile, wg] = jnp.max(stop)
        else:
            store(refs[2:], tile, cols, (stop,))

    return write


def compact_loop(gauss_ref, table_ref, scratch, start, end, tile, tiles_x: int, warp_shift,
                 evaluate, lanes_: int, dt, config: RasterConfig, last_pair: int,
                 interpret: bool, checkpoint=None):
    """The compacted Local-GS forward walk of pairs [start, end) in a half-tile block whose
    first strip is `warp_shift`: per chunk of LANES pairs, the records built as
    `staging.stage` builds them, and each warp's list of the pairs with its strip's bit
    (`warp_lists.partition`), walked `unroll` per iteration (`steps.blend`, with each pair's
    own index for the stop pair) while some lane still blends. The outputs are
    `steps.staged_loop`'s over every pair (module docstring): the same bits in interpret mode
    and in float32 on the GPU; float64 within ulps there (the two loops compile to other
    multiply-add contractions). `checkpoint(j, state)` runs at each chunk's start j with the
    state before pair j (chunks start at multiples of LANES, as the split backward's entries
    do). Returns (r, g, b, T, D, stop pair) per lane."""
    buf, index_ref, sync_ref = scratch
    unroll = config.tuning.unroll
    tx, ty = tile % tiles_x, tile // tiles_x
    offsets = lax.broadcasted_iota(jnp.int32, (LANES,), 0)
    more = inline.running(config, interpret)

    def stage_chunk(c):
        base = start + c * LANES
        cols = staging.gather(gauss_ref, table_ref, base, last_pair, interpret)
        mask = pairs.strip_mask_columns(cols, tx, ty, config)
        live = base + offsets < end
        records = staging.lane_records(cols, tx, ty, config, mask, interpret)
        bits = jnp.where(live, (mask >> warp_shift) & ((1 << warp_lists.WARPS) - 1), 0)
        warp_lists.partition(records, bits, buf, index_ref, sync_ref, interpret)

    def cond(carry):
        c, _, st = carry
        return (start + c * LANES < end) & more(st)

    def body(carry):
        c, v, st = carry
        first = v == 0
        if checkpoint is not None:
            checkpoint(jnp.where(first, start + c * LANES, start), st)
        pl.when(first)(lambda: stage_chunk(c))
        # no strip-mask test (a listed pair has the warp's bit: `evaluate` takes None) and no
        # count test (positions past a list's end hold its never-blended sentinel); the
        # group's α first (independent work that overlaps), then the blends in order
        read = warp_lists.reads(buf, index_ref, v, unroll, interpret)
        base = start + c * LANES
        busiest = sync_ref[warp_lists.BUSIEST]
        evaluated = [evaluate(rec, None) for rec, _ in read]
        for (alpha, hit, rgb, z), (_, row) in zip(evaluated, read):
            st = ks.blend(st, alpha, hit, rgb, z, base + row, config)
        wrap = v + unroll >= busiest
        return jnp.where(wrap, c + 1, c), jnp.where(wrap, 0, v + unroll), st

    warp_lists.clear(buf, interpret)
    _, _, st = lax.while_loop(cond, body, (jnp.int32(0), jnp.int32(0),
                                           ks.empty_state(lanes_, dt)))
    walked = start + (end - start + unroll - 1) // unroll * unroll  # staged_loop's last j
    return st[:5] + (jnp.minimum(st[5], walked),)


def localgs_kernel(order_ref, ranges_ref, gauss_ref, table_ref, *refs,
                   config: RasterConfig, tiles_x: int, last_pair: int, pixels: int,
                   interpret: bool, rows: int | None = None, segment: int | None = None,
                   image: bool = False, block_stops: bool = False):
    """The Local-GS forward for one warpgroup; `refs` = the six outputs (four with `image`:
    the colour image, T, D, the stop pairs; `_forward_store`), then, with a `segment`, the five
    checkpoint outputs (r, g, b, T, D before every pair start + m·segment, m >= 1, at row
    ranges_ref[tile, 2] + m − 1: lgs_jax.backends.pallas.segments), then the scratch
    (`warp_lists.scratch` where it `compacts`, else `staging.scratch`). (gauss_ref, table_ref):
    the pairs' Gaussian ids and `pairs.gaussian_table`."""
    n_plain = 4 if image else 6
    n_out = n_plain if segment is None else n_plain + 5
    out_refs, check_refs, scratch = refs[:n_plain], refs[n_plain:n_out], refs[n_out:]
    dt = table_ref.dtype
    tid, wg = block_index(rows), lax.axis_index("wg")
    tile = order_ref[tid]
    start, end = ranges_ref[tile, 0], ranges_ref[tile, 1]
    k, strip, cols = lanes(wg, pixels)
    frame = ks.lane_coordinates(tile, k, tiles_x, config, dt)
    bit = jnp.left_shift(jnp.int32(1), strip)
    write = _forward_store(image, block_stops, tiles_x, wg, pixels)

    def evaluate(rec, mask_word):  # mask_word None: a pair known to have this lane's bit
        alpha, hit, _ = ks.record_alpha(rec, frame, config)
        if config.warp_cull and mask_word is not None:
            hit = hit & ((mask_word & bit) != 0)
        return alpha, hit, rec[7:10], rec[10]

    checkpoint = None
    if segment is not None:
        checkpoint = _checkpoint(check_refs, ranges_ref[tile, 2], start, cols, segment)
    if compacts(config):
        write(out_refs, tile, cols, compact_loop(
            gauss_ref, table_ref, scratch, start, end, tile, tiles_x,
            wg * (pixels // STRIP_PIXELS), evaluate, k.shape[0], dt, config, last_pair,
            interpret, checkpoint))
        return
    fetch, pair_alpha, stage = staging.forward_source(
        gauss_ref, table_ref, scratch[0], start, end, tile, tiles_x, evaluate, config,
        last_pair, interpret)
    write(out_refs, tile, cols,
          ks.staged_loop(start, end, k.shape[0], dt, fetch, pair_alpha, config,
                         config.tuning.unroll, stage=stage, checkpoint=checkpoint,
                         more=inline.running(config, interpret)))


def _checkpoint(refs, base, start, cols, segment: int):
    """`staged_loop`'s checkpoint hook: the state (r, g, b, T, D) before pair start + m·segment
    (m >= 1) into row base + m − 1 of `refs` (lgs_jax.backends.pallas.segments)."""
    def checkpoint(j, state):
        m = (j - start) // segment

        @pl.when((j > start) & ((j - start) % segment == 0))
        def _():
            store(refs, base + m - 1, cols, state[:5])

    return checkpoint


def vanilla_kernel(order_ref, ranges_ref, gauss_ref, rows_ref, *out_refs,
                   config: RasterConfig, tiles_x: int, last_pair: int, pixels: int,
                   interpret: bool, rows: int | None = None):
    """The original 3DGS forward for one warpgroup (difference form, Gaussian rows by id)."""
    dt = rows_ref.dtype
    tid, wg = block_index(rows), lax.axis_index("wg")
    tile = order_ref[tid]
    k, _, cols = lanes(wg, pixels)
    frame = ks.lane_coordinates(tile, k, tiles_x, config, dt)
    fetch, pair_alpha = ks.vanilla_pairs(gauss_ref, rows_ref, tile, tiles_x, frame, config,
                                         last_pair)
    store(out_refs, tile, cols,
          ks.staged_loop(ranges_ref[tile, 0], ranges_ref[tile, 1], k.shape[0], dt, fetch,
                         pair_alpha, config, UNROLL_VANILLA,
                         more=inline.running(config, interpret)))


def forward(vanilla: bool, config: RasterConfig, interpret: bool, pixels: int, tiles_x: int,
            order, bins, data, dt, segment: int | None = None, image: bool = False,
            block_stops: bool = False):
    """Run the vanilla (data = (Gaussian ids, `steps.gaussian_rows`)) or Local-GS (data =
    (Gaussian ids, `pairs.gaussian_table`)) forward kernel on a (n_tiles, 256 / pixels) grid of
    one-warpgroup blocks; outputs (n_tiles, 256) each: r, g, b, T, D and the stop pair, or with
    `image` (Local-GS, blocks of 128 pixels) the colour as one (tiles_y·16, tiles_x·16, 3)
    image and T, D, the stop pair; with `block_stops` (Local-GS) the stop pairs as each block's
    latest, (n_tiles, 256 / pixels); then with a `segment` (Local-GS only) the five
    (n_checkpoints, 256) checkpoint buffers of `segments.checkpoints`."""
    if (image and pixels != 128) or (vanilla and (image or block_stops)):
        raise ValueError("image, block_stops: the Local-GS kernel's (image: blocks of 128)")
    if not vanilla and compacts(config) and pixels != LANES:
        raise ValueError(f"pixels: the compacted Local-GS forward runs blocks of {LANES}")
    n_tiles = bins.tile_start.shape[0]
    launch, names, fold = grid(n_tiles, TILE_PIXELS // pixels)
    common = dict(config=config, tiles_x=tiles_x, last_pair=bins.gauss.shape[0] - 1,
                  pixels=pixels, interpret=interpret, rows=fold)
    kernel = (functools.partial(vanilla_kernel, **common) if vanilla else
              functools.partial(localgs_kernel, **common, segment=segment, image=image,
                                block_stops=block_stops))
    columns = [bins.tile_start, bins.tile_end]
    checks = []
    if segment is not None:
        base, rows = segments.checkpoints(bins, segment)
        columns.append(base)
        checks = [jax.ShapeDtypeStruct((rows, TILE_PIXELS), dt)] * 5
    scratch = ()
    if not vanilla:
        scratch = warp_lists.scratch(dt) if compacts(config) else staging.scratch(dt)
    out = jax.ShapeDtypeStruct((n_tiles, TILE_PIXELS), dt)
    stop = jax.ShapeDtypeStruct((n_tiles, TILE_PIXELS // pixels if block_stops else TILE_PIXELS),
                                jnp.int32)
    planes = [out] * 5
    if image:
        shape = (n_tiles // tiles_x * TILE, tiles_x * TILE, 3)
        planes = [jax.ShapeDtypeStruct(shape, dt), out, out]
    name = kernel.func.__name__
    return plgpu.kernel(guarded(kernel, n_tiles, fold), out_type=planes + [stop] + checks,
                        scratch_types=scratch, grid=launch, grid_names=names,
                        interpret=interpret_params(interpret),
                        kernel_name=name)(order, ranges(*columns), *data)
