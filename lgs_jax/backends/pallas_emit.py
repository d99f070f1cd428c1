"""The pair emission's slot filling as a Pallas Triton kernel (`KernelConfig.emit_kernel`): the
same (tile, Gaussian) arrays as lgs_jax.binning.expand_slots.

`expand_slots` works per slot over the whole pair capacity: it finds each slot's Gaussian (a
scatter of markers and a running maximum, `binning.segment_of_slot`), then gathers that
Gaussian's start and rectangle for every slot. Here a program takes LANES consecutive
Gaussians of the depth order, whose slots are one contiguous range [s0, s1) (their ranges tile
it in order), loads their starts, kept counts and rectangles once, and walks the range LANES
slots at a time: slot s belongs to the j-th of them, j = #{Gaussians whose range ends at or
before s} (the ends are non-decreasing, empty ranges included), and loads that Gaussian's
start and rectangle (rows this program has just read: cached); the stores are coalesced. Per
program about (s1 − s0) / LANES steps of LANES² comparisons.

The buffers start as padding (tile n_tiles, Gaussian order[-1], as `expand_slots` gives slots
past the total) and every slot below the total has exactly one writer, so the result is
`expand_slots`' bit for bit, deterministic, with no atomics. Lanes past their program's range
are masked off and point at a spare slot past the capacity (interpret mode emulates a masked
store by storing the old value back, so a masked lane must not share a live lane's slot); the
spare is sliced off (a copy of the capacity in XLA).

History: a first version gave each lane one Gaussian and looped to the program's longest
count, storing one slot per lane and step (gsplat's `isect_tiles` pattern). On the H200 it
gave XLA's arrays but took 1.81 against 1.49 ms at 5.8M Gaussians (1080p) and 3.01 against
2.46 ms at 10M (4K) for the whole emission (BENCHMARKS.md §7): scattered stores, and each
program waiting on its longest Gaussian.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
from jax import lax
from jax.experimental import pallas as pl
from jax.experimental.pallas import triton as plt

from ..binning import SlotPlan, expand_slots
from ..config import RasterConfig
from .pallas import interpreted

LANES = 32  # Gaussians per program and slots per step (one warp)


def _kernel(start_ref, kept_ref, rect_ref, tile_in, gauss_in, tile_ref, gauss_ref, *, n: int,
            tiles_x: int):
    """Program p: Gaussians k = p·LANES + l of the depth order (rect_ref row k: tx0, ty0, nx,
    Gaussian index) store their kept pairs (`SlotPlan`), LANES slots per step."""
    del tile_in, gauss_in  # aliased to the outputs: the padding already there
    spare = tile_ref.shape[0] - 1
    lane = lax.iota(jnp.int32, LANES)
    k0 = pl.program_id(0) * LANES
    k = k0 + lane
    ki = jnp.minimum(k, n - 1)
    start = start_ref[ki]
    kept = jnp.where(k < n, kept_ref[ki], 0)
    end = jnp.where(k < n, start + kept, jnp.iinfo(jnp.int32).max)  # past n: never before s
    s0 = jnp.min(jnp.where(kept > 0, start, jnp.iinfo(jnp.int32).max))
    s1 = jnp.max(jnp.where(kept > 0, start + kept, 0))
    steps = jnp.where(s1 > s0, (s1 - s0 + LANES - 1) // LANES, 0)

    def body(c, carry):
        slot = s0 + c * LANES + lane
        live = slot < s1
        owner = jnp.sum(end[None, :] <= slot[:, None], axis=1, dtype=jnp.int32)
        ko = jnp.minimum(k0 + owner, n - 1)  # the owner's row (cached: this program's rows)
        first = start_ref[ko]
        tx0, ty0, nx, g = (rect_ref[ko, c] for c in range(4))
        local = slot - first
        row = local // jnp.maximum(nx, 1)
        tile = (ty0 + row) * tiles_x + tx0 + (local - row * nx)
        at = jnp.where(live, slot, spare)
        plt.store(tile_ref.at[at], tile, mask=live)
        plt.store(gauss_ref.at[at], g, mask=live)
        return carry

    lax.fori_loop(0, steps, body, 0)


def expand(plan: SlotPlan, interpret: bool):
    """`binning.expand_slots`' (tile, gauss) by the kernel (module docstring)."""
    n = plan.order.shape[0]
    rect = jnp.concatenate([plan.rect[plan.order], plan.order[:, None]], -1)  # per depth rank
    size = plan.capacity + 1  # the last slot: a spare no lane stores to (kernel)
    tile = jnp.full((size,), plan.n_tiles, jnp.int32)
    gauss = jnp.full((size,), plan.order[-1], jnp.int32)
    kernel = functools.partial(_kernel, n=n, tiles_x=plan.tiles_x)
    tile, gauss = pl.pallas_call(
        kernel, out_shape=(jax.ShapeDtypeStruct((size,), jnp.int32),) * 2,
        grid=(pl.cdiv(n, LANES),), input_output_aliases={3: 0, 4: 1}, interpret=interpret,
        compiler_params=plt.CompilerParams(num_warps=1, num_stages=1), name="emit_pairs",
    )(plan.start, plan.kept, rect, tile, gauss)
    return tile[:-1], gauss[:-1]


def slot_expander(config: RasterConfig):
    """The `expand` of `binning.emit_pairs` that `config` asks for (`KernelConfig.emit_kernel`:
    this kernel, in interpret mode as `pallas.interpreted` says; else XLA's)."""
    if not config.tuning.emit_kernel:
        return expand_slots
    return functools.partial(expand, interpret=interpreted(config))
