"""The pair emission's slot filling as a Pallas Triton kernel (`KernelConfig.emit_kernel`): the
same (tile, Gaussian) arrays as lgs_jax.binning.expand_slots, written Gaussian by Gaussian.

`expand_slots` works per slot: it finds each slot's Gaussian (a scatter of markers and a running
maximum over the whole pair capacity, `binning.segment_of_slot`), then gathers that Gaussian's
start and rectangle for every slot: three passes over the capacity and two per-slot gathers.
Here one lane owns one Gaussian of the depth order, as gsplat's `isect_tiles` and the original
rasterizer's `duplicateWithKeys` do: it loads its start, kept count and rectangle once and
stores its pairs to slots [start, start + kept), row by row of its rectangle, one slot per loop
step; a program of LANES lanes loops to its longest count. The buffers start as padding (tile
n_tiles, Gaussian order[-1], as `expand_slots` gives slots past the total), and every slot
below the total has exactly one writer (the ranges tile [0, total) in depth order), so the
result is `expand_slots`' bit for bit, deterministic, with no atomics. A lane with nothing
left to store is masked off and points at a spare slot past the capacity (interpret mode
emulates a masked store by storing the old value, so no two lanes may share a slot); the
spare is sliced off (a copy of the capacity in XLA).
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

LANES = 32  # Gaussians per program (one warp): it loops to its lanes' longest count


def _kernel(start_ref, kept_ref, rect_ref, tile_in, gauss_in, tile_ref, gauss_ref, *, n: int,
            tiles_x: int):
    """Lane l: Gaussian k = program·LANES + l of the depth order (rect_ref row k: tx0, ty0, nx,
    Gaussian index) stores its kept pairs (`SlotPlan`)."""
    del tile_in, gauss_in  # aliased to the outputs: the padding already there
    spare = tile_ref.shape[0] - 1  # the lanes not storing point here (masked off)
    k = pl.program_id(0) * LANES + lax.iota(jnp.int32, LANES)
    ki = jnp.minimum(k, n - 1)
    start = start_ref[ki]
    kept = jnp.where(k < n, kept_ref[ki], 0)
    tx0, ty0, nx, g = (rect_ref[ki, c] for c in range(4))

    def body(i, carry):
        live = i < kept
        slot = jnp.where(live, start + i, spare)
        row = i // nx
        tile = (ty0 + row) * tiles_x + tx0 + (i - row * nx)
        plt.store(tile_ref.at[slot], tile, mask=live)
        plt.store(gauss_ref.at[slot], g, mask=live)
        return carry

    lax.fori_loop(0, jnp.max(kept), body, 0)


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
