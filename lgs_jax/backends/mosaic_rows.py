"""How the Mosaic GPU backward kernel (lgs_jax.backends.pallas_mosaic) writes a pair's row: its
gradient terms summed over the block's pixels, then the pair's tile, at the pair's row
(`gaussian_grads.RowLayout`, which reads the rows there).

Two reductions (`REDUCTIONS`, `writers`):
  "transposed" (the GPU default): `transposed_row`, a transposing butterfly in inline Mosaic GPU
    code (13 shuffles per thread for 11 terms, one exchange across the warps through shared
    memory, one barrier, one coalesced store of the row by the first warp), and `zero_row`,
    one coalesced store; `plgpu.inline_mgpu` code does not run in interpret mode;
  "terms" (interpret mode): one warpgroup `jnp.sum` per term, each stored from every thread.
The two agree to float rounding (a different summation order); each is deterministic (a fixed
order, no atomics). BENCHMARKS.md §7 has the measurements.
"""

from __future__ import annotations

import functools

import jax.numpy as jnp
import numpy as np
from jax.experimental.mosaic.gpu import utils as mgpu_utils
from jax.experimental.pallas import mosaic_gpu as plgpu
from jaxlib.mlir import ir
from jaxlib.mlir.dialects import arith, memref, scf, vector

from . import kernel_steps as ks

REDUCTIONS = ("terms", "transposed")


def resolve(reduction: str | None, interpret: bool) -> str:
    """The reduction to run: `reduction`, or by default "terms" in interpret mode (which cannot
    run inline Mosaic GPU code) and "transposed" on the GPU."""
    if reduction is None:
        return "terms" if interpret else "transposed"
    if reduction not in REDUCTIONS:
        raise ValueError(f"reduction: expected one of {REDUCTIONS}, got {reduction!r}")
    return reduction


def scratch(reduction: str, dt) -> tuple:
    """The shared memory `reduction` needs: two exchange buffers for "transposed" (used in turn,
    so one barrier per pair suffices: `transposed_row`), none for "terms"."""
    return (plgpu.SMEM((2, EXCHANGE), dt),) if reduction == "transposed" else ()


def writers(reduction: str, rows_ref, wg, tile, pixels: int, exchange=None):
    """(store, zero) for block `wg`'s rows rows_ref[wg] (capacity, ROW_WIDTH) of tile `tile`
    (a row's ref is taken as rows_ref.at[wg, s], one subview, as the GPU runs tested it):
    store(values, s, parity) reduces a pair's GRAD_VALUES per-pixel terms (None: zero) and
    writes them and the tile at slot s, returning the next exchange buffer's index; zero(s)
    writes a zero row with the tile (a tile's other block may have a row there)."""
    dt = rows_ref.dtype
    tile_value = tile.astype(dt)
    if reduction == "transposed":
        def store(values, s, parity):
            transposed_row(values, pixels, exchange.at[parity], rows_ref.at[wg, s], tile_value)
            return 1 - parity

        def zero(s):
            zero_row(rows_ref.at[wg, s], tile_value)

        return store, zero
    zero_scalar = jnp.zeros((), dt)

    def store(values, s, parity):
        for c, v in enumerate(values):
            rows_ref[wg, s, c] = zero_scalar if v is None else jnp.sum(v)
        rows_ref[wg, s, ks.TILE_COLUMN] = tile_value
        return parity

    def zero(s):
        for c in range(ks.GRAD_VALUES):
            rows_ref[wg, s, c] = zero_scalar
        rows_ref[wg, s, ks.TILE_COLUMN] = tile_value

    return store, zero


EXCHANGE = 16 * 4  # `transposed_row`'s shared-memory exchange: 16 slots x 4 warps


def butterfly_plan(rows: int):
    """The transposing butterfly of `transposed_row` for `rows` <= 16 values per lane: the
    halving sizes h of its steps (lane distance 16, 8, ...; a step on m values keeps
    h = ceil(m / 2), a lane with the distance's bit set keeping values h..m − 1) and, per lane
    pair (2s, 2s + 1) after the last step, the row s holds (−1: none). Each lane's value
    at the end is its row's sum over the warp's 32 lanes."""
    if not 1 <= rows <= 16:
        raise ValueError(f"rows: must be in [1, 16], got {rows}")
    lanes = np.arange(32)
    table = [np.full(32, r) for r in range(rows)]
    halves = []
    for d in (16, 8, 4, 2, 1):
        m = len(table)
        if m == 1:
            halves.append(0)
            continue
        h = (m + 1) // 2
        halves.append(h)
        table = [np.where(lanes & d, table[k + h] if k + h < m else -1, table[k])
                 for k in range(h)]
    final = table[0]
    assert np.array_equal(final[0::2], final[1::2])
    return tuple(halves), tuple(int(r) for r in final[0::2])


def transposed_row(terms, pixels: int, exchange, row, tile):
    """Store one pair's row: row[c] = Σ over the block's pixels of terms[c] (c < len(terms)),
    then row[len(terms)] = tile, from the block-wide (pixels,) lane vectors `terms` (Mosaic GPU
    strided layout: each thread holds pixels/128 of them; None: a term that is zero, which
    stays a constant inside: a zero array passed in fails the GPU compiler's LLVM translation
    with an unrealized layout cast).

    A transposing reduction (`plgpu.inline_mgpu`; GPU only): each thread adds its own pixels,
    then five butterfly steps over the warp's lanes (distance 16, 8, 4, 2, 1) halve the values
    each lane still holds, exchanging only the half its partner keeps (for 11 terms 6 + 3 + 2 +
    1 + 1 = 13 shuffles per thread, where reducing each term over the lanes takes 11 x 5 = 55),
    leaving every lane pair the warp's sum of one term (`butterfly_plan`). Each warp writes its
    16 sums to `exchange` (a (EXCHANGE,) view of shared memory: slot s of warp w at 4s + w),
    one barrier, and lanes 0..len(terms) of the first warp add the four warps' sums
    ((w0 + w1) + (w2 + w3)) and store the row with one coalesced store (the tile from lane
    len(terms)). The caller alternates two `exchange` buffers between consecutive reductions,
    so one barrier per pair suffices: a warp writes a buffer again only after the barrier of
    the reduction in between, which the first warp passes after reading it. Fixed order,
    no atomics: deterministic."""
    rows, vec = len(terms), pixels // 128
    halves, slot_rows = butterfly_plan(rows)
    present = [c for c, v in enumerate(terms) if v is not None]

    @plgpu.inline_mgpu(
        arg_types=(plgpu.RefType(), plgpu.RefType(), plgpu.Layout.WG_SPLAT(()))
        + (plgpu.Layout.WG_STRIDED((pixels,), vec_size=vec),) * len(present))
    def reduce(_, exchange_ref, row_ref, tile_value, *arrays):
        el = ir.VectorType(arrays[0].registers.flat[0].type).element_type
        tid = arith.remui(mgpu_utils.thread_idx(), _i32(128))
        zero = arith.constant(el, 0.0)
        vals = [zero] * rows
        for col, a in zip(present, arrays):
            [reg] = a.registers.reshape(-1)  # this thread's pixels of the term
            vals[col] = functools.reduce(arith.addf, [_element(reg, e) for e in range(vec)])
        value = _butterfly(vals, halves, arith.remui(tid, _i32(32)), zero)
        _exchange_and_store(value, exchange_ref, row_ref, tid, slot_rows, rows,
                            tile_value.registers.item())

    reduce(exchange, row, tile, *[terms[c] for c in present])


def _i32(v: int):
    return mgpu_utils.c(v, ir.IntegerType.get_signless(32))


def _element(vec, i: int):
    return vector.extract(vec, dynamic_position=[], static_position=ir.DenseI64ArrayAttr.get([i]))


def _shuffle(v, d: int):
    """v of lane l ^ d (a butterfly shuffle), through a 1-vector: utils.shfl_bfly cannot
    bitcast a 64-bit scalar."""
    return _element(mgpu_utils.shfl_bfly(vector.broadcast(ir.VectorType.get((1,), v.type), v),
                                         d), 0)


def _butterfly(vals, halves, lane, zero):
    """`butterfly_plan`'s steps on this lane's values `vals` (one per term): the lane's one
    value at the end, the warp's sum of the term the plan assigns to its lane pair."""
    for d, h in zip((16, 8, 4, 2, 1), halves):
        if h == 0:
            vals = [arith.addf(vals[0], _shuffle(vals[0], d))]
            continue
        upper = arith.cmpi(arith.CmpIPredicate.ne, arith.andi(lane, _i32(d)), _i32(0))
        merged = []
        for k in range(h):
            lo = vals[k]
            hi = vals[k + h] if k + h < len(vals) else zero
            send = arith.select(upper, lo, hi)
            keep = arith.select(upper, hi, lo)
            merged.append(arith.addf(keep, _shuffle(send, d)))
        vals = merged
    return vals[0]


def _exchange_and_store(value, exchange_ref, row_ref, tid, slot_rows, rows: int, tile):
    """Each lane's warp sum `value` to exchange_ref[4·slot + warp] (slot = lane // 2), one
    barrier, then thread t <= rows of the first warp stores row_ref[t]: the four warps' sums of
    term t, (w0 + w1) + (w2 + w3), or, for t = rows, the tile."""
    index = ir.IndexType.get()
    lane, warp = arith.remui(tid, _i32(32)), arith.divui(tid, _i32(32))
    at = arith.addi(arith.muli(arith.shrui(lane, _i32(1)), _i32(4)), warp)
    memref.store(value, exchange_ref, [arith.index_cast(index, at)])
    mgpu_utils.warpgroup_barrier()
    with ir.InsertionPoint(scf.IfOp(arith.cmpi(arith.CmpIPredicate.ule, tid, _i32(rows)))
                           .then_block):
        slot = _i32(0)
        for s, r in enumerate(slot_rows):
            if r >= 0:
                slot = arith.select(arith.cmpi(arith.CmpIPredicate.eq, tid, _i32(r)), _i32(s),
                                    slot)
        four = vector.load(ir.VectorType.get((4,), value.type), exchange_ref,
                           [arith.index_cast(index, arith.muli(slot, _i32(4)))])
        p = [_element(four, w) for w in range(4)]
        total = arith.addf(arith.addf(p[0], p[1]), arith.addf(p[2], p[3]))
        memref.store(arith.select(arith.cmpi(arith.CmpIPredicate.eq, tid, _i32(rows)), tile,
                                  total),
                     row_ref, [arith.index_cast(index, tid)])
        scf.yield_([])


@plgpu.inline_mgpu(arg_types=(plgpu.RefType(), plgpu.Layout.WG_SPLAT(())))
def zero_row(_, row_ref, tile_value):
    """row_ref[:] = (0, ..., 0, tile): one coalesced store by the first warp's lanes (where a
    store from Pallas would have every thread write every column)."""
    i32, index = ir.IntegerType.get_signless(32), ir.IndexType.get()
    width = ir.MemRefType(row_ref.type).shape[0]
    tid = arith.remui(mgpu_utils.thread_idx(), mgpu_utils.c(128, i32))
    last = mgpu_utils.c(width - 1, i32)
    value = tile_value.registers.item()
    with ir.InsertionPoint(scf.IfOp(arith.cmpi(arith.CmpIPredicate.ule, tid, last)).then_block):
        zero = arith.constant(value.type, 0.0)
        memref.store(arith.select(arith.cmpi(arith.CmpIPredicate.eq, tid, last), value, zero),
                     row_ref, [arith.index_cast(index, tid)])
        scf.yield_([])
