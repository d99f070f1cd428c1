"""The Local-GS and vanilla forward kernels on Mosaic GPU (`jax.experimental.pallas.mosaic_gpu`),
the Pallas GPU backend JAX supports going forward; `lgs_jax.backends.pallas` holds the Triton
versions, the shared per-pair arithmetic (`_record_alpha`, `_blend`, `_staged_loop`) and the
backward kernel, and picks between the two implementations (`pallas.IMPL`).

Mapping. A Mosaic GPU (Pallas) thread is a 128-lane warpgroup; a 16x16 tile is two of them,
each owning 8 rows, i.e. four 16x2 strips, one per hardware warp (lane l of half w is tile pixel
128·w + l; a warp's 32 lanes are one strip). Each half tile is its own one-warpgroup block
(grid (tiles in longest-list-first order, 2)): it walks the tile's pairs and stops as soon as
its 128 pixels are done. (Two warpgroups in one block with independent early exits crashed on
the H100 with CUDA_ERROR_ILLEGAL_INSTRUCTION on real scenes: the loop's cross-warp reductions
synchronise the block, so both warpgroups must run the same number of iterations.)

Culling. The strip-mask bit of a pair is tested per lane (each lane's strip); as a lane
predicate it is uniform within each warp, so the hardware never diverges inside a warp, but
Pallas:MGPU has no way to *skip* work
per warp inside a warpgroup (`plgpu.warp_map` runs scalar per-warp code, not array code), so
the α of a pair whose bit is clear for some of the warpgroup's strips is still computed there.
Branching around a staged group with no bit set in any of the warpgroup's strips (GROUP_SKIP)
measured slower than predicating (H100: 1.10 vs 0.83 ms on guitar 720p at UNROLL 8), so the
kernel stages 8 pairs per iteration and lets the lane predicates do the culling.

Arithmetic and blending are exactly those of the Triton kernels (the same functions), so the
images are the same to the bit in interpret mode (on the GPU the two compilers' exp and
multiply-add contraction differ by ulps); the per-pixel stop pairs feed the same backward
kernel (`kernel="auto"` differentiates through the Triton forward, see `pallas`).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax import lax

from ..binning import TILE
from ..config import RasterConfig
from ..warp_masks import STRIPS

WG_LANES = 128  # a Mosaic GPU (Pallas) thread: one warpgroup
WARPGROUPS = TILE * TILE // WG_LANES
UNROLL = {"localgs": 8, "vanilla": 8}  # pairs staged per iteration (scripts/mosaic_profile.py)
GROUP_SKIP = False  # Local-GS: branch around a staged group none of the warpgroup's strips takes


def _interpret_params():
    from jax.experimental.pallas import mosaic_gpu as plgpu

    return plgpu.InterpretGPUParams()


def ranges(bins):
    """(n_tiles, 2) [start, end) per tile as one fresh buffer: Mosaic GPU requires 256-byte
    aligned operands, and XLA may pass `tile_end` (a slice of the ranges scan) at an offset."""
    return jnp.stack([bins.tile_start, bins.tile_end], -1)


def call(kernel, n_tiles: int, dt, args, interpret: bool):
    """Run `kernel(*refs)` on a (n_tiles, WARPGROUPS) grid of one-warpgroup blocks (axes "tile"
    and "wg"); outputs (n_tiles, 256): r, g, b, T, D and the stop pair."""
    from jax.experimental.pallas import mosaic_gpu as plgpu

    out = jax.ShapeDtypeStruct((n_tiles, TILE * TILE), dt)
    stop = jax.ShapeDtypeStruct((n_tiles, TILE * TILE), jnp.int32)

    return plgpu.kernel(kernel, out_type=[out] * 5 + [stop], grid=(n_tiles, WARPGROUPS),
                        grid_names=("tile", "wg"),
                        interpret=_interpret_params() if interpret else None,
                        kernel_name=kernel.func.__name__)(*args)


def lanes(wg):
    """Tile pixel index of each lane of warpgroup `wg` and its strip (0..7)."""
    k = lax.broadcasted_iota(jnp.int32, (WG_LANES,), 0) + wg * WG_LANES
    return k, k // (2 * TILE)


def store(refs, tile, wg, outputs):
    """Write this warpgroup's half of row `tile` of the (n_tiles, 256) outputs."""
    from jax.experimental import pallas as pl

    for ref, x in zip(refs, outputs):
        ref[tile, pl.ds(wg * WG_LANES, WG_LANES)] = x.astype(ref.dtype)


def strip_bits(wg):
    """The mask bits of warpgroup `wg`'s four strips (for the group-skip branch)."""
    per_wg = STRIPS // WARPGROUPS
    return jnp.left_shift(jnp.int32((1 << per_wg) - 1), wg * per_wg)


def localgs_kernel(order_ref, ranges_ref, mask_ref, rec_ref, *out_refs,
                   config: RasterConfig, tiles_x: int, last_pair: int):
    """The Local-GS forward (lgs_jax.backends.pallas, module docstring) for one warpgroup."""
    from .pallas import REC, _frame, _record_alpha, _staged_loop

    dt = rec_ref.dtype
    tid, wg = lax.axis_index("tile"), lax.axis_index("wg")
    tile = order_ref[tid]
    k, strip = lanes(wg)
    frame, pixel = _frame(tile, k, tiles_x, config, dt)
    bit = jnp.left_shift(jnp.int32(1), strip)
    mine = strip_bits(wg)

    def fetch(j):
        jj = jnp.minimum(j, last_pair)
        return jj, mask_ref[jj] if config.warp_cull else None

    def pair_alpha(fetched):
        rec = [rec_ref[fetched[0], c] for c in range(REC - 1)]
        alpha, hit, _ = _record_alpha(rec, frame, pixel, config)
        if config.warp_cull:
            hit = hit & ((fetched[1] & bit) != 0)
        return alpha, hit, rec[7:10], rec[10]

    take = ((lambda fetched: (fetched[1] & mine) != 0) if config.warp_cull and GROUP_SKIP
            else None)
    store(out_refs, tile, wg,
          _staged_loop(ranges_ref[tile, 0], ranges_ref[tile, 1], WG_LANES, dt, fetch, pair_alpha,
                       config, UNROLL["localgs"], take))


def vanilla_kernel(order_ref, ranges_ref, gauss_ref, rows_ref, *out_refs,
                   config: RasterConfig, tiles_x: int, last_pair: int):
    """The original 3DGS forward (lgs_jax.backends.pallas, module docstring), one warpgroup."""
    from .pallas import _frame, _staged_loop, vanilla_pairs

    dt = rows_ref.dtype
    tid, wg = lax.axis_index("tile"), lax.axis_index("wg")
    tile = order_ref[tid]
    k, _ = lanes(wg)
    _, pixel = _frame(tile, k, tiles_x, config, dt)
    fetch, pair_alpha = vanilla_pairs(gauss_ref, rows_ref, pixel, config, last_pair)
    store(out_refs, tile, wg, _staged_loop(ranges_ref[tile, 0], ranges_ref[tile, 1], WG_LANES, dt,
                                           fetch, pair_alpha, config, UNROLL["vanilla"]))
