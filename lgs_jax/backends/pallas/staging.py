"""The pair records of the Mosaic GPU kernels (the Local-GS forward and the backward) built
inside them (the paper's staging, Sec. III-B: V hoisted per tile into shared memory from
per-Gaussian data), with no per-pair record buffer in global memory and no per-pair XLA pass.

Per chunk of LANES = 128 pairs of a tile's list, lane t of the block's warpgroup
  1. loads pair (base + t)'s Gaussian id and that Gaussian's `pairs.gaussian_table` row
     (`gather`: inline Mosaic GPU code, one load per thread at its own address, which Pallas
     cannot express; in interpret mode, which cannot run inline code, array gathers give the
     same lane vectors),
  2. computes the pair record on the lane vectors, the strip mask included, with the functions
     the XLA records of the Triton kernels use (`pairs.record_columns`,
     `pairs.strip_mask_columns`; the tile is the block's, a scalar), and
  3. stores it to shared memory as row t of one of two (LANES, REC) buffers (chunk c in
     c % 2; `_store_rows`), followed by one warpgroup barrier,
and the pair loop reads the records there as scalars (the forward's chunks start at the tile's
first pair, `forward_source`; the backward walks down through chunks aligned to multiples of
LANES, `backward_source`). Two buffers and one barrier per chunk suffice: a buffer is written
again two chunks later, after every thread passed the barrier of the chunk in between, which
follows its reads.

A record per row keeps its columns adjacent, so the compiler loads and stores a record with
three 128-bit accesses (float32) rather than twelve scalar ones.

Records past the list's end (the last chunk's tail) are computed from clamped ids and never
read. Same arithmetic as the XLA records (`reference`: the same functions); bit for bit in
interpret mode. Float32 and float64.
"""

from __future__ import annotations

import jax.numpy as jnp
from jax import lax
from jax.experimental import pallas as pl
from jax.experimental.mosaic.gpu import fragmented_array as mgpu_fa
from jax.experimental.mosaic.gpu import utils as mgpu_utils
from jax.experimental.pallas import mosaic_gpu as plgpu
from jaxlib.mlir import ir
from jaxlib.mlir.dialects import arith, memref

from ... import pairs
from ...config import RasterConfig
from . import steps as ks
from .inline import LANES, STRIDED, element, lane_vector, threads


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
    records = lane_records(cols, tx, ty, config, mask, interpret)
    if interpret:
        for c, v in enumerate(records):
            buffer[:, c] = v
    else:
        _store_rows(buffer, *records)


def lane_records(cols, tx, ty, config: RasterConfig, mask, interpret: bool):
    """`pairs.record_columns`, on the GPU in float32 with the strip mask's int32 bits as its
    last column (stored and loaded, never computed on), which the pair loop takes back by
    reinterpreting them (`mask_of`) where the mask as a float would take a conversion and two
    clamps per pair."""
    columns = pairs.record_columns(cols, tx, ty, config, mask)
    if not interpret and mask is not None and columns[-1].dtype == jnp.float32:
        columns[-1] = lax.bitcast_convert_type(mask, jnp.float32)
    return columns


def mask_of(value, interpret: bool):
    """The strip mask (int32) of a staged record's last column (`lane_records`)."""
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
    """`steps.staged_loop`'s (fetch, pair_alpha, stage) for the pairs [start, end) of
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
        return evaluate(rec, mask_of(rec[ks.REC - 1], interpret))

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
        return mask_of(_read(smem, j, [ks.REC - 1])[0], interpret)

    return (lambda j: _read(smem, j)), mask, begin


def reference(gauss, table, base, tile, tiles_x: int, config: RasterConfig, last_pair: int):
    """The records `stage` builds for pairs [base, base + LANES) of `tile` from the pairs'
    Gaussian ids `gauss` and the table, in jnp: (LANES, REC), the strip mask as a number in
    the last column (0 without warp culling)."""
    pair = jnp.minimum(base + jnp.arange(LANES, dtype=jnp.int32), last_pair)
    rows = table[gauss[pair]]
    cols = [rows[:, c] for c in range(pairs.TABLE_COLUMNS)]
    tx, ty = tile % tiles_x, tile // tiles_x
    mask = pairs.strip_mask_columns(cols, tx, ty, config) if config.warp_cull else None
    return jnp.stack(pairs.record_columns(cols, tx, ty, config, mask), -1)
