"""Per-warp pair lists of the compacted Local-GS forward (`mosaic_forward.compact_loop`): the
paper's warp-level culling (Sec. III-C) at the granularity of a hardware warp, inside one
Mosaic GPU warpgroup program.

A half-tile block is four hardware warps, warp w the 32 pixels of the block's strip w (lane l
of the block is tile pixel 128·wg + l, lgs_jax.backends.pallas.mosaic_forward). Of each staged
chunk of LANES = 128 pairs (lane t: pair base + t, its record built as `staging.stage` builds
it), `partition` stores every record at row t of a shared-memory buffer and, per warp w, the
rows of the pairs whose strip mask has warp w's bit, in pair order, as list w; `reads` then
gives lane l, at list position v, the record of row lists[l // 32][v]: one record per warp,
each warp stepping through its own list. The warpgroup's loop still runs to the busiest warp's
count (one control flow per warpgroup), so per chunk it takes max_w n_w / unroll iterations
(scripts/strip_occupancy.py --chunks counts them over whole scenes).

Same outputs as the full walk: a pair outside warp w's list has its bit clear, so no pixel of
strip w passes its α test for it (the masks are conservative), and each list keeps pair order,
so every pixel blends the same pairs in the same order; a lane's stop pair is the pair's own
index (base + row). Positions past a warp's count hold the sentinel row SENTINEL (`partition`
fills them each chunk): a record whose α is 0 at every pixel (ln o = −∞ in the hoisted form,
o = 0 in the difference form; the rest 0), so it never passes the α test and the walk needs
no per-pair test of a warp's count.

On the GPU inline Mosaic GPU code (per-lane shared-memory addresses, ballots, population
counts, which Pallas cannot express); in interpret mode, which cannot run inline code, whole-ref
loads, sorts and array gathers give the same lists and lane vectors.
"""

from __future__ import annotations

import jax.numpy as jnp
from jax import lax
from jax.experimental import pallas as pl
from jax.experimental.mosaic.gpu import utils as mgpu_utils
from jax.experimental.pallas import mosaic_gpu as plgpu
from jaxlib.mlir import ir
from jaxlib.mlir.dialects import arith, memref, nvvm, scf, vector
from jaxlib.mlir.dialects import math as math_dialect

from . import steps as ks
from .inline import LANES, STRIDED, WARP, element, lane_vector, threads

WARPS = LANES // WARP
TOTALS = WARPS * WARPS  # sync_ref: counts[source warp, target warp] at 0..15, then n_w
BUSIEST = TOTALS + WARPS  # ... then max_w n_w
SENTINEL = LANES  # the record buffer's last row: α = 0 everywhere (module docstring)
LN_OPACITY = 6  # the record column SENTINEL holds −∞ in (ln o; unused by the difference form)


def scratch(dt) -> tuple:
    """Shared memory: one chunk's records (LANES, REC) and the SENTINEL row, the warps' lists
    (WARPS, LANES) of rows, and the counts (BUSIEST + 1, padded to 24)."""
    return (plgpu.SMEM((LANES + 1, ks.REC), dt), plgpu.SMEM((WARPS, LANES), jnp.int32),
            plgpu.SMEM((24,), jnp.int32))


def sentinel_value(col: int) -> float:
    """Column `col` of the SENTINEL record."""
    return -float("inf") if col == LN_OPACITY else 0.0


def clear(buf, interpret: bool):
    """Write the SENTINEL row (before the first `partition`, whose first barrier orders these
    stores before any read)."""
    if interpret:
        for col in range(ks.REC):
            buf[SENTINEL, col] = jnp.asarray(sentinel_value(col), buf.dtype)
        return

    @plgpu.inline_mgpu(arg_types=(plgpu.RefType(),))
    def store(_, buf):
        i32, index = ir.IntegerType.get_signless(32), ir.IndexType.get()
        ft = ir.MemRefType(buf.type).element_type
        tid, _, _ = threads(i32)
        for col in range(ks.REC):
            mine = arith.cmpi(arith.CmpIPredicate.eq, tid, mgpu_utils.c(col, i32))
            with ir.InsertionPoint(scf.IfOp(mine).then_block):
                memref.store(arith.constant(ft, sentinel_value(col)), buf,
                             [arith.constant(index, SENTINEL), arith.constant(index, col)])
                scf.yield_([])

    store(buf)


def partition(records, bits, buf, lists_ref, sync_ref, interpret: bool):
    """Row t of `buf` = lane t's record (`records`: REC lane vectors); list w of `lists_ref` =
    the rows t with bit w of `bits` (int32 lane vector, the warps' bits of lane t's strip mask,
    0 past the tile's list) in increasing order, then SENTINEL to the end; sync_ref[TOTALS + w]
    = its length n_w and sync_ref[BUSIEST] = max_w n_w. Every thread may read them when this
    returns. On the GPU:
    per source warp and target warp a ballot and population counts (lane t's rank among its
    warp's lanes with the bit, the warp's count), the counts through `sync_ref` (one barrier),
    then lane t's position in list w is its rank plus the counts of the warps below it, and
    thread t writes SENTINEL at position t of each list shorter than t + 1; the stores, then a
    second barrier. The loop reads the buffers between this second barrier and
    the next chunk's first, and the next chunk writes them (counts aside) only after its first
    barrier, so no warp overwrites a record, list entry or total another still reads."""
    if interpret:
        for c, v in enumerate(records):
            buf[pl.ds(0, LANES), c] = v
        keep = [(bits >> w) & 1 for w in range(WARPS)]
        totals = [jnp.sum(k, dtype=jnp.int32) for k in keep]
        position = lax.broadcasted_iota(jnp.int32, (LANES,), 0)
        lists_ref[...] = jnp.stack([
            jnp.where(position < n, jnp.argsort(k == 0, stable=True).astype(jnp.int32),
                      SENTINEL) for k, n in zip(keep, totals)])
        for w, n in enumerate(totals):
            sync_ref[TOTALS + w] = n
        sync_ref[BUSIEST] = jnp.max(jnp.stack(totals))
        return

    @plgpu.inline_mgpu(arg_types=(plgpu.RefType(),) * 3 + (STRIDED,) * (len(records) + 1))
    def store(_, buf, lists_ref, sync_ref, *arrays):
        i32, index = ir.IntegerType.get_signless(32), ir.IndexType.get()
        c = lambda v: mgpu_utils.c(v, i32)
        at = lambda v: arith.index_cast(index, v)
        value = lambda a: element(a.registers.flat[0], 0)
        eq = lambda a, b: arith.cmpi(arith.CmpIPredicate.eq, a, b)
        tid, lane, warp = threads(i32)
        bits = value(arrays[-1])
        below = nvvm.read_ptx_sreg_lanemask_lt(results=[i32])
        kept, ranks = [], []
        for w in range(WARPS):
            k = arith.cmpi(arith.CmpIPredicate.ne, arith.andi(bits, c(1 << w)), c(0))
            ballot = nvvm.vote_sync(c(0xFFFFFFFF), k, "ballot", results=[i32])
            kept.append(k)
            ranks.append(math_dialect.ctpop(arith.andi(ballot, below)))
            with ir.InsertionPoint(scf.IfOp(eq(lane, c(0))).then_block):
                memref.store(math_dialect.ctpop(ballot), sync_ref,
                             [at(arith.addi(arith.muli(warp, c(WARPS)), c(w)))])
                scf.yield_([])
        mgpu_utils.warpgroup_barrier()
        for col, a in enumerate(arrays[:-1]):
            memref.store(value(a), buf, [at(tid), at(c(col))])
        counts = [vector.load(ir.VectorType.get((WARPS,), i32), sync_ref, [at(c(WARPS * s))])
                  for s in range(WARPS)]  # counts[s]: source warp s's count per target warp
        totals = []
        for w in range(WARPS):
            pos, total = ranks[w], c(0)
            for s in range(WARPS):
                n = element(counts[s], w)
                pos = arith.addi(pos, arith.select(
                    arith.cmpi(arith.CmpIPredicate.ugt, warp, c(s)), n, c(0)))
                total = arith.addi(total, n)
            totals.append(total)
            with ir.InsertionPoint(scf.IfOp(kept[w]).then_block):
                memref.store(tid, lists_ref, [at(c(w)), at(pos)])
                scf.yield_([])
            past = arith.cmpi(arith.CmpIPredicate.sge, tid, total)  # past list w's end
            with ir.InsertionPoint(scf.IfOp(past).then_block):
                memref.store(c(SENTINEL), lists_ref, [at(c(w)), at(tid)])
                scf.yield_([])
        with ir.InsertionPoint(scf.IfOp(eq(tid, c(0))).then_block):
            busiest = c(0)
            for w, total in enumerate(totals):
                memref.store(total, sync_ref, [at(c(TOTALS + w))])
                busiest = arith.maxsi(busiest, total)
            memref.store(busiest, sync_ref, [at(c(BUSIEST))])
            scf.yield_([])
        mgpu_utils.warpgroup_barrier()

    store(buf, lists_ref, sync_ref, *records, bits)


def reads(buf, lists_ref, v, unroll: int, interpret: bool):
    """[(record, row) for positions v .. v + unroll − 1]: lane l's warp w = l // 32 reads
    position v + u of its list and the record at that row of `buf` (its first REC − 1 lane
    vectors: the strip mask is not read, every listed pair has warp w's bit; past the list's
    end the SENTINEL row, never blended). v + unroll <= LANES (the caller's)."""
    dt = buf.dtype
    if interpret:
        warp = lax.broadcasted_iota(jnp.int32, (LANES,), 0) // WARP
        lists, records = lists_ref[...], buf[...]
        out = []
        for u in range(unroll):
            row = lists[warp, v + u]
            out.append(([records[row, col] for col in range(ks.REC - 1)], row))
        return out
    i32_type = plgpu.ShapeDtypeStruct((LANES,), jnp.int32, layout=STRIDED)
    per_pair = (plgpu.ShapeDtypeStruct((LANES,), dt, layout=STRIDED),) * (ks.REC - 1) + (
        i32_type,)

    @plgpu.inline_mgpu(arg_types=(plgpu.RefType(),) * 2 + (plgpu.Layout.WG_SPLAT(()),),
                       return_type=per_pair * unroll)
    def load(_, buf, lists_ref, first):
        i32, index = ir.IntegerType.get_signless(32), ir.IndexType.get()
        c = lambda x: mgpu_utils.c(x, i32)
        at = lambda x: arith.index_cast(index, x)
        _, _, warp = threads(i32)
        v = first.registers.item()
        out = []
        for u in range(unroll):
            # the offset added as an index, which the compiler folds into the load's address
            row = memref.load(lists_ref, [at(warp), arith.addi(at(v), arith.constant(index, u))])
            rec = [memref.load(buf, [at(row), at(c(col))]) for col in range(ks.REC - 1)]
            out.append([lane_vector(x) for x in rec] + [lane_vector(row, True)])
        return tuple(x for per_pair in out for x in per_pair)

    flat = load(buf, lists_ref, v)
    n = ks.REC
    return [(list(flat[n * u:n * u + ks.REC - 1]), flat[n * u + ks.REC - 1])
            for u in range(unroll)]
