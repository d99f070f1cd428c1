"""The Local-GS and vanilla forward kernels and the backward kernel on Mosaic GPU
(`jax.experimental.pallas.mosaic_gpu`), the Pallas GPU backend JAX supports going forward;
`lgs_jax.backends.pallas` holds the Triton versions and the shared per-pair arithmetic
(`_record_alpha`, `_blend`, `_staged_loop`, `_backward_step`), and picks between the two
implementations (`pallas.auto`).

Mapping. A Mosaic GPU (Pallas) thread is a 128-lane warpgroup, and each block is one
warpgroup on a grid (tiles in longest-list-first order, blocks per tile) of one of two sizes
(`block_pixels`): 128 pixels (a half tile of four 16x2 strips, one per hardware warp: lane l of
block w is tile pixel 128·w + l) or 256 (the whole tile in one block, each lane holding two
adjacent pixels of one row: Mosaic GPU's strided layout of a (256,) array, so a hardware warp
holds two strips). A block walks its tile's pairs and stops as soon as its pixels are done.
(Two warpgroups in one block with independent early exits crashed on the H100 with
CUDA_ERROR_ILLEGAL_INSTRUCTION on real scenes: the loop's cross-warp reductions synchronise the
block; two pixels per lane avoid that and share every record load and loop step between them.)
Whole tiles win where tiles are many and their lists short, half tiles where lists are long
(two blocks stop independently; the backward skips the pairs none of a block's four strips
takes). H100, 256 vs 128 (BENCHMARKS.md §6): the forward kernel alone 0.68 vs 0.82 ms at guitar
3840x2160 (32,400 tiles), 1.12 vs 1.36 at lego 3200x3200 (40,000), but 0.61 vs 0.55 at guitar
1280x720 (3,600) and 0.41 vs 0.39 at lego 800x800 (2,500); rasterization forward+backward
3.62 vs 4.28 ms at guitar 4K but 4.67 vs 3.70 at guitar 720p. Hence the default: whole tiles
from WHOLE_TILE_BLOCKS_FROM = 8192 tiles on (between the measured sizes; 1920x1080 has 8,160).
The rule misses one measured case: 1M small synthetic Gaussians at 1280x720, where 256 is
faster though tiles are few (0.79 vs 0.94 ms forward, 7.25 vs 9.27 ms forward+backward).

Culling. The strip-mask bit of a pair is tested per lane (each lane's strip); as a lane
predicate it is uniform within each strip's lanes, so the hardware never diverges inside one,
but Pallas:MGPU has no way to *skip* work per warp inside a warpgroup (`plgpu.warp_map` runs
scalar per-warp code, not array code), so the α of a pair whose bit is clear for some of the
block's strips is still computed there. Branching around a staged group with no bit set in any
of the block's strips (GROUP_SKIP) measured slower than predicating (H100: 1.10 vs 0.83 ms on
guitar 720p at UNROLL 8, 128-pixel blocks), so the kernel stages 8 pairs per iteration and lets
the lane predicates do the culling.

Staging (CHUNK > 0; float32 only: TMA has no 64-bit float type). The Local-GS kernel stages the
tile's pair records in shared memory: CHUNK records per TMA copy, double-buffered (chunk c + 1
in flight while chunk c is blended; a copy is issued only where the list reaches it, and the
block waits for the one in flight before it exits), the strip mask read from the record's last
column. H100, kernel only: 1.2–1.8x faster than the Triton kernel at 720p/800 with 128-pixel
blocks, and bit for bit the unstaged kernel's output on five real and synthetic scenes
(BENCHMARKS.md §6).

Arithmetic and blending are exactly those of the Triton kernels (the same functions), so the
images are the same to the bit in interpret mode (on the GPU the two compilers' exp and
multiply-add contraction differ by ulps); both record per-pixel stop pairs for the backward.

Backward. The same blocks walk the tile's pairs back to front from the last pair any of their
pixels blended (`pallas._backward_step`), and reduce each pair's 11 gradient terms over their
pixels (11 warpgroup reductions: Mosaic GPU reduces a warpgroup array to a scalar, but has no
multi-column cross-warp reduction like the Triton kernel's (256, 16) one). A pair none of the
block's strips takes (mask bits clear) is skipped by one uniform branch: unlike the forward's
staged groups, a backward step is long enough for the branch to pay (H100, BENCHMARKS.md §6:
3.84 vs 5.01 ms rasterization fwd+bwd on guitar 720p). Each block writes its own row per pair
(`backward_rows` masks the pairs it did not visit and adds a tile's blocks): one writer per
row, no atomics, deterministic.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax import lax

from ..binning import TILE
from ..config import RasterConfig

# Pixels per one-warpgroup block (a Mosaic GPU thread is a 128-lane warpgroup) of the forward
# and backward kernels: 128 = a half tile, one pixel per lane, two blocks per tile; 256 = the
# whole tile, two pixels per lane; None = by the image's tile count (`block_pixels`).
BLOCK_PIXELS = {"forward": None, "backward": None}
WHOLE_TILE_BLOCKS_FROM = 8192  # tiles (module docstring)
UNROLL = {"localgs": 8, "vanilla": 8}  # pairs staged per iteration (scripts/mosaic_profile.py)
CHUNK = 64  # Local-GS: records per TMA copy into shared memory (0: none; module docstring)
GROUP_SKIP = False  # Local-GS: branch around a staged group none of the warpgroup's strips takes


def _interpret_params():
    from jax.experimental.pallas import mosaic_gpu as plgpu

    return plgpu.InterpretGPUParams()


def ranges(bins):
    """(n_tiles, 2) [start, end) per tile as one fresh buffer: Mosaic GPU requires 256-byte
    aligned operands, and XLA may pass `tile_end` (a slice of the ranges scan) at an offset."""
    return jnp.stack([bins.tile_start, bins.tile_end], -1)


def call(kernel, n_tiles: int, pixels: int, dt, args, interpret: bool, scratch=()):
    """Run the forward `kernel(*refs)` on a (n_tiles, 256 / pixels) grid of one-warpgroup
    blocks (axes "tile" and "wg"); outputs (n_tiles, 256): r, g, b, T, D and the stop pair; then
    `scratch` refs."""
    from jax.experimental.pallas import mosaic_gpu as plgpu

    out = jax.ShapeDtypeStruct((n_tiles, TILE * TILE), dt)
    stop = jax.ShapeDtypeStruct((n_tiles, TILE * TILE), jnp.int32)

    return plgpu.kernel(kernel, out_type=[out] * 5 + [stop], scratch_types=scratch,
                        grid=(n_tiles, TILE * TILE // pixels), grid_names=("tile", "wg"),
                        interpret=_interpret_params() if interpret else None,
                        kernel_name=kernel.func.__name__)(*args)


def staged(dt) -> bool:
    """Whether the Local-GS kernel stages records in shared memory for records of dtype `dt`:
    CHUNK > 0 and float32 (TMA has no 64-bit float type: Mosaic GPU raises "unsupported TMA
    dtype f64" when compiling for the GPU; interpret mode has no TMA and would not notice)."""
    return CHUNK > 0 and jnp.dtype(dt) == jnp.float32


def localgs_scratch(dt):
    """The Local-GS kernel's SMEM scratch: with staging two CHUNK-record buffers and a barrier
    each, otherwise none (the kernel stages exactly when it is given this scratch)."""
    from jax.experimental.pallas import mosaic_gpu as plgpu

    from .pallas import REC

    if not staged(dt):
        return ()
    return (plgpu.SMEM((2, CHUNK, REC), dt), plgpu.Barrier(num_barriers=2))


def block_pixels(kernel: str, n_tiles: int) -> int:
    """Pixels per block of the "forward" or "backward" kernels for an image of `n_tiles` tiles:
    BLOCK_PIXELS[kernel] if set, else whole tiles (256) from WHOLE_TILE_BLOCKS_FROM tiles on
    (short lists: one block's per-tile work and record loads serve twice the pixels) and half
    tiles (128) below (long lists: two blocks stop independently and, in the backward, skip the
    pairs none of their four strips takes)."""
    fixed = BLOCK_PIXELS[kernel]
    if fixed is not None:
        return fixed
    return 256 if n_tiles >= WHOLE_TILE_BLOCKS_FROM else 128


def lanes(wg, pixels: int):
    """Tile pixel indices of block `wg` of `pixels` pixels (a warpgroup array: one or two per
    lane) and their strips (0..7), and the block's slice of a tile row."""
    from jax.experimental import pallas as pl

    k = lax.broadcasted_iota(jnp.int32, (pixels,), 0) + wg * pixels
    return k, k // (2 * TILE), pl.ds(wg * pixels, pixels)


def store(refs, tile, cols, outputs):
    """Write a block's pixels (`cols`, from `lanes`) of row `tile` of the (n_tiles, 256)
    outputs."""
    for ref, x in zip(refs, outputs):
        ref[tile, cols] = x.astype(ref.dtype)


def strip_bits(wg, pixels: int):
    """The mask bits of the strips of block `wg` of `pixels` pixels (a uniform branch's test)."""
    per_block = pixels // (2 * TILE)
    return jnp.left_shift(jnp.int32((1 << per_block) - 1), wg * per_block)


def localgs_kernel(order_ref, ranges_ref, mask_ref, rec_ref, *refs,
                   config: RasterConfig, tiles_x: int, last_pair: int, pixels: int):
    """The Local-GS forward (lgs_jax.backends.pallas, module docstring) for one warpgroup;
    `refs` = the six outputs, then `localgs_scratch` (records staged in shared memory) if any."""
    from .pallas import REC, _frame, _record_alpha, _staged_loop

    out_refs, scratch = refs[:6], refs[6:]
    dt = rec_ref.dtype
    tid, wg = lax.axis_index("tile"), lax.axis_index("wg")
    tile = order_ref[tid]
    start, end = ranges_ref[tile, 0], ranges_ref[tile, 1]
    k, strip, cols = lanes(wg, pixels)
    frame, pixel = _frame(tile, k, tiles_x, config, dt)
    bit = jnp.left_shift(jnp.int32(1), strip)

    def evaluate(rec, mask_word):
        alpha, hit, _ = _record_alpha(rec, frame, pixel, config)
        if config.warp_cull:
            hit = hit & ((mask_word & bit) != 0)
        return alpha, hit, rec[7:10], rec[10]

    if scratch:
        fetch, pair_alpha, stage = _smem_records(rec_ref, *scratch, start, end, evaluate)
        take = None
    else:
        def fetch(j):
            jj = jnp.minimum(j, last_pair)
            return jj, mask_ref[jj] if config.warp_cull else None

        def pair_alpha(fetched):
            return evaluate([rec_ref[fetched[0], c] for c in range(REC - 1)], fetched[1])

        mine = strip_bits(wg, pixels)
        take = ((lambda fetched: (fetched[1] & mine) != 0) if config.warp_cull and GROUP_SKIP
                else None)
        stage = None
    store(out_refs, tile, cols, _staged_loop(start, end, k.shape[0], dt, fetch, pair_alpha,
                                             config, UNROLL["localgs"], take, stage))


def _smem_records(rec_ref, smem, barriers, start, end, evaluate):
    """`_staged_loop`'s (fetch, pair_alpha, stage) for records [start, end) staged in shared
    memory: CHUNK records at a time by TMA, double-buffered (chunk c + 1 is in flight while
    chunk c is blended), the strip mask read from the record's last column."""
    from jax.experimental import pallas as pl
    from jax.experimental.pallas import mosaic_gpu as plgpu

    from .pallas import REC

    unroll = UNROLL["localgs"]
    assert CHUNK % unroll == 0, "a staged group of pairs must lie within one chunk"

    def copy(c):  # chunk c of the tile's records into slot c % 2, if the list reaches it
        @pl.when(start + c * CHUNK < end)
        def _():
            plgpu.copy_gmem_to_smem(rec_ref.at[pl.ds(start + c * CHUNK, CHUNK)], smem.at[c % 2],
                                    barriers.at[c % 2])

    def begin(j):  # at a chunk's first group: wait for it, start the next one's copy
        c = (j - start) // CHUNK

        @pl.when((j - start) % CHUNK == 0)
        def _():
            plgpu.barrier_wait(barriers.at[c % 2])
            copy(c + 1)

    def finish(j):  # wait for the copy still in flight (if any) before the block exits
        c = (j - start - unroll) // CHUNK + 1  # the last chunk copy() was called for

        @pl.when(start + c * CHUNK < end)
        def _():
            plgpu.barrier_wait(barriers.at[c % 2])

    def pair_alpha(j):
        i = j - start
        rec = [smem[(i // CHUNK) % 2, i % CHUNK, c] for c in range(REC)]
        return evaluate(rec, rec[REC - 1].astype(jnp.int32))

    copy(0)
    return (lambda j: j), pair_alpha, (begin, finish)


def vanilla_kernel(order_ref, ranges_ref, gauss_ref, rows_ref, *out_refs,
                   config: RasterConfig, tiles_x: int, last_pair: int, pixels: int):
    """The original 3DGS forward (lgs_jax.backends.pallas, module docstring), one warpgroup."""
    from .pallas import _frame, _staged_loop, vanilla_pairs

    dt = rows_ref.dtype
    tid, wg = lax.axis_index("tile"), lax.axis_index("wg")
    tile = order_ref[tid]
    k, _, cols = lanes(wg, pixels)
    _, pixel = _frame(tile, k, tiles_x, config, dt)
    fetch, pair_alpha = vanilla_pairs(gauss_ref, rows_ref, pixel, config, last_pair)
    store(out_refs, tile, cols, _staged_loop(ranges_ref[tile, 0], ranges_ref[tile, 1],
                                             k.shape[0], dt, fetch, pair_alpha, config,
                                             UNROLL["vanilla"]))


def backward_kernel(order_ref, ranges_ref, mask_ref, rec_ref, trans_ref, stop_ref, g_r_ref,
                    g_g_ref, g_b_ref, g_t_ref, g_d_ref, rows_ref, *, config: RasterConfig,
                    tiles_x: int, pixels: int):
    """The backward walk (`pallas._backward_step`) for one warpgroup: rows_ref[wg, j] = pair
    j's gradient summed over this block's pixels, for the pairs before the block's last stop
    pair (the others are left unwritten; `backward_rows` masks them)."""
    from .pallas import GRAD_VALUES, REC, _backward_step, backward_lanes

    dt = rec_ref.dtype
    tid, wg = lax.axis_index("tile"), lax.axis_index("wg")
    tile = order_ref[tid]
    k, _, half = lanes(wg, pixels)
    trans, stop_at = trans_ref[tile, half], stop_ref[tile, half]
    lane = backward_lanes(tile, k, tiles_x, config, dt, trans, stop_at,
                          [ref[tile, half] for ref in (g_r_ref, g_g_ref, g_b_ref, g_t_ref,
                                                       g_d_ref)])
    start = ranges_ref[tile, 0]
    last = jnp.minimum(ranges_ref[tile, 1], jnp.max(stop_at))
    mine = strip_bits(wg, pixels)

    zero_row = [jnp.zeros((), dt)] * GRAD_VALUES

    def step(j, carry):
        rec = [rec_ref[j, c] for c in range(REC - 1)]
        values, carry = _backward_step(j, rec, mask_ref[j] if config.warp_cull else None, lane,
                                       carry, config)
        return [zero_row[0] if v is None else jnp.sum(v) for v in values], carry

    def body(i, carry):
        j = last - 1 - i
        if config.warp_cull:  # a pair none of this block's strips takes: zero row, same carry
            sums, carry = lax.cond((mask_ref[j] & mine) != 0, step,
                                   lambda j, carry: (zero_row, carry), j, carry)
        else:
            sums, carry = step(j, carry)
        for c, s in enumerate(sums):
            rows_ref[wg, j, c] = s
        return carry

    zero = jnp.zeros(k.shape, dt)
    lax.fori_loop(0, jnp.maximum(last - start, 0), body, (trans, zero, zero, zero, zero))


def backward_rows(kernel, bins, stop_at, pixels: int, dt, args, interpret: bool):
    """(capacity, GRAD_VALUES) pair rows from `backward_kernel` on a (n_tiles, blocks per
    tile) grid: each block's rows, zero where that block did not visit the pair (pairs at or
    after its last stop pair, padding pairs), summed over a tile's blocks in a fixed order."""
    from jax.experimental.pallas import mosaic_gpu as plgpu

    from .pallas import GRAD_VALUES

    capacity, n_tiles = bins.gauss.shape[0], stop_at.shape[0]
    n = TILE * TILE // pixels
    out = jax.ShapeDtypeStruct((n, capacity, GRAD_VALUES), dt)
    rows = plgpu.kernel(kernel, out_type=out, grid=(n_tiles, n),
                        grid_names=("tile", "wg"),
                        interpret=_interpret_params() if interpret else None,
                        kernel_name="localgs_backward_mosaic")(*args)
    last = jnp.minimum(bins.tile_end[:, None],
                       jnp.max(stop_at.reshape(n_tiles, n, pixels), -1))
    tile = jnp.minimum(bins.tile, n_tiles - 1)
    j = jnp.arange(capacity)
    visited = (bins.tile[None] < n_tiles) & (j[None] < last[tile].T)  # (blocks, capacity)
    return jnp.sum(jnp.where(visited[..., None], rows, 0), axis=0)
