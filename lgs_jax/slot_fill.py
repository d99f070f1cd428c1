"""The pair emission's slot fill (`binning.expand_slots`) as a Pallas Triton kernel, for GPUs.

`binning.expand_slots` finds each slot's Gaussian from the slots' side: a store per Gaussian,
a running maximum over the capacity, then per slot a row gather of (start, Gaussian) and one of
the Gaussian's tile rectangle, and the tile's arithmetic. At 25M slots (10M Gaussians, 4K) on
an H200 those XLA passes took about 1 ms of a 5.7 ms forward (BENCHMARKS.md §7 "Dec 2, late
evening"). Here the fill goes from the Gaussians' side, as gsplat's `isect_tiles` does: lane k
of a program takes depth rank k, reads its run (start, kept) and its Gaussian's rectangle
once, and writes its slots start + i, i < kept, walking the rectangle row by row:

    tile(start + i) = (ty0 + i // nx) · tiles_x + tx0 + i % nx,  gauss(start + i) = order[k].

The runs tile [0, min(total, capacity)) without overlap (`binning.SlotPlan`), so every slot has
one writer (deterministic, no atomics); slots from `total` on keep the padding the outputs start
with (tile n_tiles, Gaussian order[-1]). The integers equal `expand_slots`' (a test compares
them in interpret mode). A warp's lanes hold consecutive ranks, whose runs are consecutive, so
its stores land close together; a program loops to its longest run (an unbounded Gaussian's is
the whole image: its program takes that long, as a thread of gsplat's does).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
from jax import lax
from jax.experimental import pallas as pl
from jax.experimental.pallas import triton as plt

LANES = 64  # depth ranks per program (two warps: a program loops to its longest run)


def _kernel(order_ref, start_ref, kept_ref, rect_ref, _tile_in, _gauss_in, tile_ref, gauss_ref,
            *, n: int, lanes: int, tiles_x: int, capacity: int):
    k = pl.program_id(0) * lanes + lax.iota(jnp.int32, lanes)
    kk = jnp.minimum(k, n - 1)
    count = jnp.where(k < n, kept_ref[kk], 0)
    start = jnp.where(count > 0, start_ref[kk], 0)
    g = order_ref[kk]
    tx0, ty0, nx = rect_ref[g, 0], rect_ref[g, 1], rect_ref[g, 2]

    def body(i, carry):
        row_tile, col = carry  # (ty0 + i // nx) · tiles_x + tx0, and i % nx
        live = i < count
        slot = jnp.where(live, start + i, capacity)  # lanes done: the spare slot, masked
        plt.store(tile_ref.at[slot], row_tile + col, mask=live)
        plt.store(gauss_ref.at[slot], g, mask=live)
        wrap = col + 1 == nx
        return jnp.where(wrap, row_tile + tiles_x, row_tile), jnp.where(wrap, 0, col + 1)

    lax.fori_loop(0, jnp.max(count), body, (ty0 * tiles_x + tx0, jnp.zeros_like(tx0)))


def fill(order, start, kept, rect, n_tiles: int, tiles_x: int, capacity: int,
         interpret: bool = False, lanes: int = LANES):
    """(tile, gauss) of every slot, as `binning.expand_slots` (its `SlotPlan` fields: order,
    start, kept per depth rank, rect (N, 3) per Gaussian). `interpret`: Pallas' interpreter
    (tests); `lanes`: a multiple of 32."""
    if lanes % 32:
        raise ValueError(f"lanes: expected a multiple of 32, got {lanes}")
    n, n_tiles, tiles_x, capacity = order.shape[0], int(n_tiles), int(tiles_x), int(capacity)
    # One spare slot past the capacity: the masked stores' index (Pallas' interpreter writes
    # masked lanes' old values back, so they must not share a live lane's slot).
    padding = (jnp.full((capacity + 1,), n_tiles, jnp.int32),
               jnp.broadcast_to(order[-1], (capacity + 1,)).astype(jnp.int32))
    out = jax.ShapeDtypeStruct((capacity + 1,), jnp.int32)
    tile, gauss = pl.pallas_call(
        functools.partial(_kernel, n=n, lanes=lanes, tiles_x=tiles_x, capacity=capacity),
        out_shape=(out, out), grid=(pl.cdiv(n, lanes),), interpret=interpret,
        input_output_aliases={4: 0, 5: 1},
        compiler_params=plt.CompilerParams(num_warps=lanes // 32, num_stages=1),
        name="slot_fill",
    )(order, start, kept, rect, *padding)
    return tile[:capacity], gauss[:capacity]  # the slices fuse into the tile sort's key and
    # the sorted Gaussians' gather
