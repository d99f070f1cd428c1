"""The pair records of the Mosaic GPU kernels (the Local-GS forward and the backward) built
inside them (the paper's staging, Sec. III-B: V hoisted per tile into shared memory from
per-Gaussian data), instead of read from records XLA wrote for every pair
(`tuning.mosaic_pair_source = "gaussians"`, the default).

Per chunk of LANES = 128 pairs of a tile's list, lane t of the block's warpgroup
  1. loads pair (base + t)'s Gaussian id and that Gaussian's `pairs.gaussian_table` row
     (`gather`: inline Mosaic GPU code, one load per thread at its own address, which Pallas
     cannot express; in interpret mode, which cannot run inline code, array gathers give the
     same lane vectors),
  2. computes the pair record on the lane vectors, the strip mask included, with the functions
     the XLA path uses (`pairs.record_columns`, `pairs.strip_mask_columns`; the tile is the
     block's, a scalar), and
  3. stores it to shared memory as row t of one of two (LANES, REC) buffers (chunk c in
     c % 2; `_store_rows`), followed by one warpgroup barrier,
and the pair loop reads the records there as scalars, as it reads TMA-staged records (the
forward's chunks start at the tile's first pair, `forward_source`; the backward walks down
through chunks aligned to multiples of LANES, `backward_source`). Two
buffers and one barrier per chunk suffice: a buffer is written again two chunks later, after
every thread passed the barrier of the chunk in between, which follows its reads.

A record per row keeps its columns adjacent, so the compiler loads a record with three 128-bit
loads (float32) where column-major buffers took twelve scalar loads, and stores it with three:
for the H200 (`scripts/kernel_sass.py`, BENCHMARKS.md §7, Dec 3, seventh session) the
forward's pair loop 54 -> 46.5 SASS instructions per pair, the backward's 230 -> 223, and the
backward's staging 26 -> 2 barriers per chunk (Pallas fenced each column's store with two).

No per-pair buffer in global memory and no per-pair XLA pass (the records, and the Gaussian rows
gathered per pair to build them, are 48 + 40 bytes per pair: 1.2 + 1.0 GB at 10M Gaussians at
4K). Records past the list's end (the last chunk's tail) are computed from clamped ids and never
read. Same arithmetic as the XLA records (the same functions); bit for bit in interpret mode.
Float32 and float64 (no TMA involved).
"""

from __future__ import annotations

import jax.numpy as jnp
from jax import lax
from jax.experimental import pallas as pl
from jax.experimental.mosaic.gpu import fragmented_array as mgpu_fa
from jax.experimental.mosaic.gpu import utils as mgpu_utils
from jax.experimental.pallas import mosaic_gpu as plgpu
from jaxlib.mlir import ir
from jaxlib.mlir.dialects import arith, memref, nvvm, scf, vector
from jaxlib.mlir.dialects import math as math_dialect

from .. import pairs
from ..config import RasterConfig
from . import kernel_steps as ks
from . import mosaic_inline, mosaic_warp_lists
from .mosaic_inline import LANES, STRIDED, element, lane_vector, threads


def scratch(dt) -> tuple:
    """Shared memory: the two record buffers (2, LANES, REC)."""
    return (plgpu.SMEM((2, LANES, ks.REC), dt),)


def gather(gauss_ref, table_ref, base, last_pair: int, interpret: bool):
    """`pairs.TABLE_COLUMNS` (LANES,) lane vectors: lane t holds column c of the table row of
    Gaussian gauss_ref[min(base + t, last_pair)]. On the GPU inline Mosaic GPU code (two
    dependent loads per thread: the id, then the row); in interpret mode, which runs neither
    inline code nor per-lane loads from refs, whole-ref loads and array gathers (the same
    values)."""
    columns = pairs.TABLE_COLUMNS
    if interpret:
        pair = jnp.minimum(base + jnp.arange(LANES, dtype=jnp.int32), last_pair)
        rows = table_ref[...][gauss_ref[...][pair]]
        return [rows[:, c] for c in range(columns)]
    dt = table_ref.dtype

    @plgpu.inline_mgpu(
        arg_types=(plgpu.RefType(), plgpu.RefType(), plgpu.Layout.WG_SPLAT(())),
        return_type=tuple(plgpu.ShapeDtypeStruct((LANES,), dt, layout=STRIDED)
                          for _ in range(columns)))
    def load(_, ids, table, first):
        index, i32 = ir.IndexType.get(), ir.IntegerType.get_signless(32)
        tid, _, _ = threads(i32)
        pair = arith.minsi(arith.addi(first.registers.item(), tid),
                           mgpu_utils.c(last_pair, i32))
        row = arith.index_cast(index, memref.load(ids, [arith.index_cast(index, pair)]))
        return tuple(lane_vector(memref.load(table, [row, arith.constant(index, c)]))
                     for c in range(columns))

    return list(load(gauss_ref, table_ref, base))


def stage(buffer, gauss_ref, table_ref, base, tile, tiles_x: int, config: RasterConfig,
          last_pair: int, interpret: bool):
    """Build the records of pairs [base, base + LANES) (`tile`'s, where the caller reads them)
    into `buffer` (LANES, REC) of shared memory, then a warpgroup barrier (module docstring)."""
    tx, ty = tile % tiles_x, tile // tiles_x
    cols = gather(gauss_ref, table_ref, base, last_pair, interpret)
    mask = pairs.strip_mask_columns(cols, tx, ty, config) if config.warp_cull else None
    records = _records(cols, tx, ty, config, mask, interpret)
    if interpret:
        for c, v in enumerate(records):
            buffer[:, c] = v
    else:
        _store_rows(buffer, *records)


def _records(cols, tx, ty, config: RasterConfig, mask, interpret: bool):
    """`pairs.record_columns`, on the GPU in float32 with the strip mask's int32 bits as its
    last column (stored and loaded, never computed on), which the pair loop takes back by
    reinterpreting them (`_mask`) where the mask as a float took a conversion and its two
    clamps per pair (3 of the forward's 46.5 SASS instructions per pair for the H200)."""
    columns = pairs.record_columns(cols, tx, ty, config, mask)
    if not interpret and mask is not None and columns[-1].dtype == jnp.float32:
        columns[-1] = lax.bitcast_convert_type(mask, jnp.float32)
    return columns


def _mask(value, interpret: bool):
    """The strip mask (int32) of a staged record's last column (`_records`)."""
    if interpret or value.dtype != jnp.float32:
        return value.astype(jnp.int32)
    splat = plgpu.Layout.WG_SPLAT(())

    @plgpu.inline_mgpu(arg_types=(splat,),
                       return_type=plgpu.ShapeDtypeStruct((), jnp.int32, layout=splat))
    def bits(_, v):  # a scalar bitcast, which Pallas' Mosaic GPU lowering does not take
        i32 = ir.IntegerType.get_signless(32)
        return mgpu_fa.FragmentedArray.splat(arith.bitcast(i32, v.registers.item()), (),
                                             is_signed=True)

    return bits(value)


def _store_rows(buffer, *columns):
    """buffer[t, c] = columns[c] at lane t (a record per row: the pair loop's scalar reads of
    one record are then adjacent), one store per column from each thread (a strided store
    Pallas' shared-memory lowering rejects), then a warpgroup barrier."""
    @plgpu.inline_mgpu(arg_types=(plgpu.RefType(),) + (STRIDED,) * len(columns))
    def store(_, buf, *arrays):
        i32, index = ir.IntegerType.get_signless(32), ir.IndexType.get()
        tid, _, _ = threads(i32)
        for col, a in enumerate(arrays):
            memref.store(element(a.registers.flat[0], 0), buf,
                         [arith.index_cast(index, tid),
                          arith.index_cast(index, mgpu_utils.c(col, i32))])
        mgpu_utils.warpgroup_barrier()

    store(buffer, *columns)


def _read(smem, k, columns=range(ks.REC)):
    """Columns `columns` of the record at position k of a walk's chunks (chunk k // LANES, in
    buffer (k // LANES) % 2, lane k % LANES), as scalars."""
    return [smem[(k // LANES) % 2, k % LANES, c] for c in columns]


def forward_source(gauss_ref, table_ref, smem, start, end, tile, tiles_x: int, evaluate,
                   config: RasterConfig, last_pair: int, interpret: bool):
    """`kernel_steps.staged_loop`'s (fetch, pair_alpha, stage) for the pairs [start, end) of
    `tile`, walked forward: chunk c = pairs [start + c·LANES, start + (c + 1)·LANES) built into
    smem[c % 2] at its first group (LANES is a multiple of the loop's group);
    `evaluate(rec, mask_word)` as the other sources of the Local-GS kernel."""
    del end

    def begin(j):
        i = j - start

        @pl.when(i % LANES == 0)
        def _():
            stage(smem.at[(i // LANES) % 2], gauss_ref, table_ref, j, tile, tiles_x, config,
                  last_pair, interpret)

    def pair_alpha(j):
        rec = _read(smem, j - start)
        return evaluate(rec, _mask(rec[ks.REC - 1], interpret))

    return (lambda j: j), pair_alpha, (begin, lambda j: None)


def backward_source(gauss_ref, table_ref, smem, tile, tiles_x: int, config: RasterConfig,
                    last_pair: int, interpret: bool):
    """(record(j), mask(j), begin(i, j)) of the backward walk (step i at pair j, downward):
    chunks aligned to multiples of LANES (chunk q = pairs [q·LANES, (q + 1)·LANES)) built into
    smem[q % 2] at the walk's first pair and wherever it enters a chunk; record(j) the REC
    values of pair j, mask(j) its strip mask (int32)."""
    def begin(i, j):
        q = j // LANES

        @pl.when((i == 0) | (j % LANES == LANES - 1))
        def _():
            stage(smem.at[q % 2], gauss_ref, table_ref, q * LANES, tile, tiles_x, config,
                  last_pair, interpret)

    def mask(j):
        return _mask(_read(smem, j, [ks.REC - 1])[0], interpret)

    return (lambda j: _read(smem, j)), mask, begin


COUNT = 4  # `compact_scratch`'s sync buffer: the warps' kept counts at 0..3, the chunk's here


def compact_scratch(dt) -> tuple:
    """Shared memory of the compacted forward (`compact_loop`): one chunk's records (LANES,
    REC), their pair indices (LANES,) and the warps' and the chunk's kept counts (8,)."""
    return (plgpu.SMEM((LANES, ks.REC), dt), plgpu.SMEM((LANES,), jnp.int32),
            plgpu.SMEM((8,), jnp.int32))


def _partition(records, keep, base, buf, index_ref, sync_ref, interpret: bool):
    """Store chunk `base`'s records (lane t: pair base + t) in `buf` as a stable partition, the
    kept lanes first (`keep`, int32 0/1), their pair indices in `index_ref`, and the number kept
    at sync_ref[COUNT]; every thread may read them when this returns. On the GPU (inline Mosaic
    GPU code): per warp a ballot of `keep` and population counts give each lane its rank among
    the warp's kept lanes and the warp's count; the counts go through `sync_ref` (one barrier),
    so lane t's position is its kept rank in the warpgroup, or for a lane not kept, the count
    kept plus its rank among those not kept; then one store per column and a second barrier.
    Every position holds a record of this chunk (finite, where a stale one could be NaN)."""
    if interpret:
        order = jnp.argsort(keep == 0, stable=True)
        for c, v in enumerate(records):
            buf[:, c] = v[order]
        index_ref[...] = (base + jnp.arange(LANES, dtype=jnp.int32))[order]
        sync_ref[COUNT] = jnp.sum(keep, dtype=jnp.int32)
        return

    @plgpu.inline_mgpu(
        arg_types=(plgpu.RefType(), plgpu.RefType(), plgpu.RefType(), plgpu.Layout.WG_SPLAT(()))
        + (STRIDED,) * (len(records) + 1))
    def store(_, buf, index_ref, sync_ref, first, *arrays):
        i32, index = ir.IntegerType.get_signless(32), ir.IndexType.get()
        c = lambda v: mgpu_utils.c(v, i32)
        at = lambda v: arith.index_cast(index, v)
        value = lambda a: element(a.registers.flat[0], 0)
        tid, lane, warp = threads(i32)
        kept = arith.cmpi(arith.CmpIPredicate.ne, value(arrays[-1]), c(0))
        ballot = nvvm.vote_sync(c(0xFFFFFFFF), kept, "ballot", results=[i32])
        below = nvvm.read_ptx_sreg_lanemask_lt(results=[i32])  # lanes under this one
        rank = math_dialect.ctpop(arith.andi(ballot, below))
        with ir.InsertionPoint(scf.IfOp(arith.cmpi(arith.CmpIPredicate.eq, lane, c(0)))
                               .then_block):
            memref.store(math_dialect.ctpop(ballot), sync_ref, [at(warp)])
            scf.yield_([])
        mgpu_utils.warpgroup_barrier()
        counts = vector.load(ir.VectorType.get((4,), i32), sync_ref, [at(c(0))])
        counts = [element(counts, w) for w in range(4)]
        before, total = rank, c(0)
        for w, n in enumerate(counts):
            before = arith.addi(before, arith.select(
                arith.cmpi(arith.CmpIPredicate.ugt, warp, c(w)), n, c(0)))
            total = arith.addi(total, n)
        pos = arith.select(kept, before, arith.subi(arith.addi(total, tid), before))
        for col, a in enumerate(arrays[:-1]):
            memref.store(value(a), buf, [at(pos), at(c(col))])
        memref.store(arith.addi(first.registers.item(), tid), index_ref, [at(pos)])
        with ir.InsertionPoint(scf.IfOp(arith.cmpi(arith.CmpIPredicate.eq, tid, c(0)))
                               .then_block):
            memref.store(total, sync_ref, [at(c(COUNT))])
            scf.yield_([])
        mgpu_utils.warpgroup_barrier()

    store(buf, index_ref, sync_ref, base, *records, keep)


def compact_loop(gauss_ref, table_ref, scratch, start, end, tile, tiles_x: int, block_bits,
                 evaluate, lanes: int, dt, config: RasterConfig, last_pair: int,
                 interpret: bool, checkpoint=None, warp_shift=None):
    """The compacted Local-GS forward walk (`KernelConfig.mosaic_compact`) of pairs [start,
    end): per chunk of LANES pairs, the records built as `stage` builds them, those whose strip
    mask has a bit of `block_bits` (the block's strips) packed first (`_partition`), and only
    those blended, `unroll` per iteration (`kernel_steps.blend`, with each pair's own index for
    the stop pair), while some lane still blends. A dropped pair has no bit in the block's
    strips, so no pixel of the block passes its α test (the masks are conservative): the state
    is the same as after walking every pair, and the outputs are `kernel_steps.staged_loop`'s
    (the same bits in interpret mode and, on the H200, in float32; float64 within ulps there:
    the two loops compile to other multiply-add contractions). With `warp_shift` (the block's
    first strip; `KernelConfig.mosaic_warp_lists`, half-tile blocks, `scratch` =
    `mosaic_warp_lists.scratch`) each warp walks its own strip's list instead
    (lgs_jax.backends.mosaic_warp_lists), the same outputs. `checkpoint(j, state)` runs at
    each chunk's start j with the state before pair j (chunks start at multiples of LANES, as
    the split backward's entries do). Returns (r, g, b, T, D, stop pair) per lane."""
    buf, index_ref, sync_ref = scratch
    unroll = config.tuning.mosaic_unroll_localgs
    tx, ty = tile % tiles_x, tile // tiles_x
    offsets = lax.broadcasted_iota(jnp.int32, (LANES,), 0)
    more = mosaic_inline.running(config, interpret)

    def stage_chunk(c):
        base = start + c * LANES
        cols = gather(gauss_ref, table_ref, base, last_pair, interpret)
        mask = pairs.strip_mask_columns(cols, tx, ty, config)
        live = base + offsets < end
        records = _records(cols, tx, ty, config, mask, interpret)
        if warp_shift is None:
            keep = (((mask & block_bits) != 0) & live).astype(jnp.int32)
            _partition(records, keep, base, buf, index_ref, sync_ref, interpret)
        else:
            bits = jnp.where(live, (mask >> warp_shift) & ((1 << mosaic_warp_lists.WARPS) - 1),
                             0)
            mosaic_warp_lists.partition(records, bits, buf, index_ref, sync_ref, interpret)

    def group(c, v):  # (n, left, [(record, strip mask, pair index)] of positions v .. v + unroll)
        if warp_shift is not None:
            read = mosaic_warp_lists.reads(buf, index_ref, v, unroll, interpret)
            base = start + c * LANES
            # no strip-mask test (a listed pair has the warp's bit: `evaluate` takes None) and
            # no count test (positions past a list's end hold its never-blended sentinel)
            return (sync_ref[mosaic_warp_lists.BUSIEST], None,
                    [(rec, None, base + row) for rec, row in read])
        n = sync_ref[COUNT]
        # v is a multiple of unroll below n <= LANES, which unroll divides (`KernelConfig`
        # checks it): the group's records are rows [v, v + unroll), no clamp, at offsets from
        # one address
        rows, indices = buf.at[pl.ds(v, unroll)], index_ref.at[pl.ds(v, unroll)]
        read = []
        for u in range(unroll):
            rec = [rows[u, col] for col in range(ks.REC)]
            read.append((rec, _mask(rec[ks.REC - 1], interpret), indices[u]))
        return n, n - v, read

    def cond(carry):
        c, _, st = carry
        return (start + c * LANES < end) & more(st)

    def body(carry):
        c, v, st = carry
        first = v == 0
        if checkpoint is not None:
            checkpoint(jnp.where(first, start + c * LANES, start), st)
        pl.when(first)(lambda: stage_chunk(c))
        n, left, read = group(c, v)  # pair v + u is one to blend iff u < left (one compare)
        evaluated = [evaluate(rec, mask) for rec, mask, _ in read]
        for u, ((alpha, hit, rgb, z), (_, _, pair)) in enumerate(zip(evaluated, read)):
            st = ks.blend(st, alpha, hit if left is None else hit & (left > u), rgb, z, pair,
                          config)
        wrap = v + unroll >= n
        return jnp.where(wrap, c + 1, c), jnp.where(wrap, 0, v + unroll), st

    if warp_shift is not None:
        mosaic_warp_lists.clear(buf, interpret)
    _, _, st = lax.while_loop(cond, body, (jnp.int32(0), jnp.int32(0),
                                           ks.empty_state(lanes, dt)))
    walked = start + (end - start + unroll - 1) // unroll * unroll  # staged_loop's last j
    return st[:5] + (jnp.minimum(st[5], walked),)
