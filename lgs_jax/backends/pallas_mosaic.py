"""The Local-GS and vanilla forward kernels and the backward kernel on Mosaic GPU
(`jax.experimental.pallas.mosaic_gpu`), the Pallas GPU backend JAX supports going forward. The
per-pair arithmetic is lgs_jax.backends.kernel_steps, shared with the Triton kernels
(lgs_jax.backends.pallas_triton); lgs_jax.backends.pallas picks between the two.

Mapping. A Mosaic GPU (Pallas) thread is a 128-lane warpgroup, and each block is one
warpgroup on a grid (tiles in longest-list-first order, blocks per tile) of one of two sizes
(`pixels`, resolved by lgs_jax.backends.pallas.block_pixels): 128 pixels (a half tile of four
16x2 strips, one per hardware warp: lane l of block w is tile pixel 128·w + l) or 256 (the whole
tile in one block, each lane holding two adjacent pixels of one row: Mosaic GPU's strided layout
of a (256,) array, so a hardware warp holds two strips). A block walks its tile's pairs and
stops as soon as its pixels are done. (Two warpgroups in one block with independent early exits
crashed on the H100 with CUDA_ERROR_ILLEGAL_INSTRUCTION on real scenes: the loop's cross-warp
reductions synchronise the block; two pixels per lane avoid that and share every record load
and loop step between them.) Whole tiles win where tiles are many and their lists short, half
tiles where lists are long (two blocks stop independently; the backward skips the pairs none of
a block's four strips takes): BENCHMARKS.md §6 has the measurements behind the default.

Culling. The strip-mask bit of a pair is tested per lane (each lane's strip); as a lane
predicate it is uniform within each strip's lanes, so the hardware never diverges inside one,
but Pallas:MGPU has no way to *skip* work per warp inside a warpgroup (`plgpu.warp_map` runs
scalar per-warp code, not array code), so the α of a pair whose bit is clear for some of the
block's strips is still computed there. Branching around a staged group with no bit set in any
of the block's strips measured slower than predicating (BENCHMARKS.md §6), so the kernel stages
`tuning.mosaic_unroll_localgs` pairs per iteration and lets the lane predicates do the culling.

Staging (`tuning.mosaic_chunk` > 0; float32 only: TMA has no 64-bit float type). The Local-GS
kernel stages the tile's pair records in shared memory: chunk records per TMA copy,
double-buffered (chunk c + 1 in flight while chunk c is blended; a copy is issued only where the
list reaches it, and the block waits for the one in flight before it exits), the strip mask read
from the record's last column. Bit for bit the unstaged kernel's output.

Arithmetic and blending are exactly those of the Triton kernels (the same functions), so the
images are the same to the bit in interpret mode (on the GPU the two compilers' exp and
multiply-add contraction differ by ulps); both record per-pixel stop pairs for the backward.

Backward. The same blocks walk the tile's pairs back to front from the last pair any of their
pixels blended (`kernel_steps.backward_step`), float32 records staged in shared memory as in the
forward (chunks aligned to multiples of the chunk size, copied downward), and reduce each pair's
11 gradient terms over their pixels with a transposing butterfly (`_transposed_row`, through
`plgpu.inline_mgpu`): each shuffle step exchanges only the half of the terms a lane's partner
keeps, 13 shuffles per thread for the 11 terms where one warp reduction per term takes 55; one
exchange across the warps through shared memory, one barrier per pair, and the first warp
stores the row with one coalesced store. Interpret mode, which cannot run inline Mosaic GPU
code, reduces each term with `jnp.sum` (`reduction="terms"`). A pair none of the block's strips
takes (mask bits clear) is skipped by one uniform branch: unlike the forward's staged groups, a
backward step is long enough for the branch to pay. Each block writes its own row per pair at
the pair's emission slot (zero where its pixels had stopped; lgs_jax.backends.gaussian_grads
adds a tile's blocks and sums each Gaussian's rows): one writer per row, no atomics, a fixed
summation order, deterministic.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax
from jax.experimental import pallas as pl
from jax.experimental.mosaic.gpu import utils as mgpu_utils
from jax.experimental.pallas import mosaic_gpu as plgpu
from jaxlib.mlir import ir
from jaxlib.mlir.dialects import arith, memref, scf, vector

from ..config import RasterConfig
from ..layout import STRIP_PIXELS, TILE_PIXELS
from . import kernel_steps as ks


def _ranges(bins):
    """(n_tiles, 2) [start, end) per tile as one fresh buffer: Mosaic GPU requires 256-byte
    aligned operands, and XLA may pass `tile_end` (a slice of the ranges scan) at an offset."""
    return jnp.stack([bins.tile_start, bins.tile_end], -1)


def _interpret_params(interpret: bool):
    return plgpu.InterpretGPUParams() if interpret else None


def _lanes(wg, pixels: int):
    """Tile pixel indices of block `wg` of `pixels` pixels (a warpgroup array: one or two per
    lane) and their strips (0..7), and the block's slice of a tile row."""
    k = lax.broadcasted_iota(jnp.int32, (pixels,), 0) + wg * pixels
    return k, k // STRIP_PIXELS, pl.ds(wg * pixels, pixels)


def _store(refs, tile, cols, outputs):
    """Write a block's pixels (`cols`, from `_lanes`) of row `tile` of the (n_tiles, 256)
    outputs."""
    for ref, x in zip(refs, outputs):
        ref[tile, cols] = x.astype(ref.dtype)


def _strip_bits(wg, pixels: int):
    """The mask bits of the strips of block `wg` of `pixels` pixels (a uniform branch's test)."""
    per_block = pixels // STRIP_PIXELS
    return jnp.left_shift(jnp.int32((1 << per_block) - 1), wg * per_block)


def staged(config: RasterConfig, dt) -> bool:
    """Whether the Local-GS kernel stages records of dtype `dt` in shared memory: a chunk is set
    and the records are float32 (TMA has no 64-bit float type: Mosaic GPU raises "unsupported
    TMA dtype f64" when compiling for the GPU; interpret mode has no TMA and would not
    notice)."""
    return config.tuning.mosaic_chunk > 0 and jnp.dtype(dt) == jnp.float32


def localgs_kernel(order_ref, ranges_ref, mask_ref, rec_ref, *refs,
                   config: RasterConfig, tiles_x: int, last_pair: int, pixels: int):
    """The Local-GS forward for one warpgroup; `refs` = the six outputs, then, when `staged`,
    the shared-memory record buffers and their barriers."""
    out_refs, scratch = refs[:6], refs[6:]
    dt = rec_ref.dtype
    tid, wg = lax.axis_index("tile"), lax.axis_index("wg")
    tile = order_ref[tid]
    start, end = ranges_ref[tile, 0], ranges_ref[tile, 1]
    k, strip, cols = _lanes(wg, pixels)
    frame, pixel = ks.lane_coordinates(tile, k, tiles_x, config, dt)
    bit = jnp.left_shift(jnp.int32(1), strip)

    def evaluate(rec, mask_word):
        alpha, hit, _ = ks.record_alpha(rec, frame, pixel, config)
        if config.warp_cull:
            hit = hit & ((mask_word & bit) != 0)
        return alpha, hit, rec[7:10], rec[10]

    if scratch:
        fetch, pair_alpha, stage = _smem_records(rec_ref, *scratch, start, end, evaluate, config)
    else:
        def fetch(j):
            jj = jnp.minimum(j, last_pair)
            return jj, mask_ref[jj] if config.warp_cull else None

        def pair_alpha(fetched):
            return evaluate([rec_ref[fetched[0], c] for c in range(ks.REC - 1)], fetched[1])

        stage = None
    _store(out_refs, tile, cols,
           ks.staged_loop(start, end, k.shape[0], dt, fetch, pair_alpha, config,
                          config.tuning.mosaic_unroll_localgs, stage=stage))


def _smem_records(rec_ref, smem, barriers, start, end, evaluate, config: RasterConfig):
    """`staged_loop`'s (fetch, pair_alpha, stage) for records [start, end) staged in shared
    memory: `tuning.mosaic_chunk` records at a time by TMA, double-buffered (chunk c + 1 is in
    flight while chunk c is blended), the strip mask read from the record's last column."""
    unroll, chunk = config.tuning.mosaic_unroll_localgs, config.tuning.mosaic_chunk

    def copy(c):  # chunk c of the tile's records into slot c % 2, if the list reaches it
        @pl.when(start + c * chunk < end)
        def _():
            plgpu.copy_gmem_to_smem(rec_ref.at[pl.ds(start + c * chunk, chunk)], smem.at[c % 2],
                                    barriers.at[c % 2])

    def begin(j):  # at a chunk's first group: wait for it, start the next one's copy
        c = (j - start) // chunk

        @pl.when((j - start) % chunk == 0)
        def _():
            plgpu.barrier_wait(barriers.at[c % 2])
            copy(c + 1)

    def finish(j):  # wait for the copy still in flight (if any) before the block exits
        c = (j - start - unroll) // chunk + 1  # the last chunk copy() was called for

        @pl.when(start + c * chunk < end)
        def _():
            plgpu.barrier_wait(barriers.at[c % 2])

    def pair_alpha(j):
        i = j - start
        rec = [smem[(i // chunk) % 2, i % chunk, c] for c in range(ks.REC)]
        return evaluate(rec, rec[ks.REC - 1].astype(jnp.int32))

    copy(0)
    return (lambda j: j), pair_alpha, (begin, finish)


def vanilla_kernel(order_ref, ranges_ref, gauss_ref, rows_ref, *out_refs,
                   config: RasterConfig, tiles_x: int, last_pair: int, pixels: int):
    """The original 3DGS forward for one warpgroup."""
    dt = rows_ref.dtype
    tid, wg = lax.axis_index("tile"), lax.axis_index("wg")
    tile = order_ref[tid]
    k, _, cols = _lanes(wg, pixels)
    _, pixel = ks.lane_coordinates(tile, k, tiles_x, config, dt)
    fetch, pair_alpha = ks.vanilla_pairs(gauss_ref, rows_ref, pixel, config, last_pair)
    _store(out_refs, tile, cols,
           ks.staged_loop(ranges_ref[tile, 0], ranges_ref[tile, 1], k.shape[0], dt, fetch,
                          pair_alpha, config, config.tuning.mosaic_unroll_vanilla))


def forward(vanilla: bool, config: RasterConfig, interpret: bool, pixels: int, tiles_x: int,
            order, bins, data, dt):
    """Run the vanilla (data = (Gaussian ids, rows)) or Local-GS (data = (masks, records))
    forward kernel on a (n_tiles, 256 / pixels) grid of one-warpgroup blocks; outputs
    (n_tiles, 256) each: r, g, b, T, D and the stop pair."""
    n_tiles = bins.tile_start.shape[0]
    kernel = functools.partial(vanilla_kernel if vanilla else localgs_kernel, config=config,
                               tiles_x=tiles_x, last_pair=bins.gauss.shape[0] - 1,
                               pixels=pixels)
    scratch = ()
    if not vanilla and staged(config, dt):
        chunk = config.tuning.mosaic_chunk
        scratch = (plgpu.SMEM((2, chunk, ks.REC), dt), plgpu.Barrier(num_barriers=2))
    out = jax.ShapeDtypeStruct((n_tiles, TILE_PIXELS), dt)
    stop = jax.ShapeDtypeStruct((n_tiles, TILE_PIXELS), jnp.int32)
    return plgpu.kernel(kernel, out_type=[out] * 5 + [stop], scratch_types=scratch,
                        grid=(n_tiles, TILE_PIXELS // pixels), grid_names=("tile", "wg"),
                        interpret=_interpret_params(interpret),
                        kernel_name=kernel.func.__name__)(order, _ranges(bins), *data)


def backward_kernel(order_ref, ranges_ref, mask_ref, slot_ref, rec_ref, trans_ref, stop_ref,
                    g_r_ref, g_g_ref, g_b_ref, g_t_ref, g_d_ref, rows_ref, *scratch,
                    config: RasterConfig, tiles_x: int, pixels: int, reduction: str):
    """The backward walk (`kernel_steps.backward_step`) for one warpgroup: rows_ref[wg, s] =
    (pair j's gradient summed over this block's pixels, its tile) at the pair's emission slot
    s = slot_ref[j] (backends.gaussian_grads reads them there), for the pairs before the
    block's last stop pair, and zero rows for the tile's pairs after it: every real pair's row
    is written once per block (the tile in every one). `scratch`: when `staged`, the
    shared-memory record buffers and their barriers (`_smem_records_backward`), then, for the
    "transposed" `reduction`, the two (64,) exchange buffers of `_transposed_row`, used in turn
    (the loop carries which). Each pair's strip mask and slot are loaded one pair ahead (the
    skip branch waits on them). `reduction`: "transposed" (`_transposed_row`, `_zero_row`; GPU
    only) or "terms" (one warpgroup `jnp.sum` and one scalar store per term, any mode)."""
    dt = rec_ref.dtype
    tid, wg = lax.axis_index("tile"), lax.axis_index("wg")
    tile = order_ref[tid]
    k, _, half = _lanes(wg, pixels)
    trans, stop_at = trans_ref[tile, half], stop_ref[tile, half]
    lane = ks.backward_lanes(tile, k, tiles_x, config, dt, trans, stop_at,
                             [ref[tile, half] for ref in (g_r_ref, g_g_ref, g_b_ref, g_t_ref,
                                                          g_d_ref)])
    start, end = ranges_ref[tile, 0], ranges_ref[tile, 1]
    last = jnp.maximum(jnp.minimum(end, jnp.max(stop_at)), start)
    mine = _strip_bits(wg, pixels)
    zero_scalar = jnp.zeros((), dt)
    if reduction == "transposed":
        scratch, exchange = scratch[:-1], scratch[-1]
    if scratch:
        record, begin = _smem_records_backward(rec_ref, *scratch, start, last,
                                               config.tuning.mosaic_chunk)
    else:
        def record(j):
            return [rec_ref[j, c] for c in range(ks.REC - 1)]

        begin = None

    def ahead(j):  # pair j's (strip mask, emission slot)
        jj = jnp.maximum(j, 0)
        return mask_ref[jj] if config.warp_cull else jnp.int32(0), slot_ref[jj]

    def zero_row(s):  # the tile too: a tile's other block may have a row there
        if reduction == "transposed":
            _zero_row(rows_ref.at[wg, s], tile.astype(dt))
            return
        for c in range(ks.GRAD_VALUES):
            rows_ref[wg, s, c] = zero_scalar
        rows_ref[wg, s, ks.TILE_COLUMN] = tile.astype(dt)

    def skip(j, mask_word, s, carry, parity):  # a zero row, the carry unchanged
        del j, mask_word
        zero_row(s)
        return carry, parity

    def step(j, mask_word, s, carry, parity):
        values, carry = ks.backward_step(j, record(j), mask_word if config.warp_cull else None,
                                         lane, carry, config)
        if reduction == "transposed":
            _transposed_row(values, pixels, exchange.at[parity], rows_ref.at[wg, s],
                            tile.astype(dt))
            return carry, 1 - parity
        for c, v in enumerate(values):
            rows_ref[wg, s, c] = zero_scalar if v is None else jnp.sum(v)
        rows_ref[wg, s, ks.TILE_COLUMN] = tile.astype(dt)
        return carry, parity

    def body(i, state):
        (mask_word, s), carry, parity = state
        j = last - 1 - i
        if begin is not None:
            begin(i, j)
        following = ahead(j - 1)
        if config.warp_cull:  # a pair none of this block's strips takes: zero row, same carry
            carry, parity = lax.cond((mask_word & mine) != 0, step, skip, j, mask_word, s, carry,
                                     parity)
        else:
            carry, parity = step(j, mask_word, s, carry, parity)
        return following, carry, parity

    zero = jnp.zeros(k.shape, dt)
    lax.fori_loop(0, last - start, body,
                  (ahead(last - 1), (trans, zero, zero, zero, zero), jnp.int32(0)))

    def after(i, c):  # pairs no pixel of this block reached
        zero_row(slot_ref[last + i])
        return c

    lax.fori_loop(0, end - last, after, jnp.int32(0))


EXCHANGE = 16 * 4  # `_transposed_row`'s shared-memory exchange: 16 slots x 4 warps


def butterfly_plan(rows: int):
    """The transposing butterfly of `_transposed_row` for `rows` <= 16 values per lane: the
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


def _transposed_row(terms, pixels: int, exchange, row, tile):
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
    slot_of = {r: s for s, r in enumerate(slot_rows) if r >= 0}
    present = [c for c, v in enumerate(terms) if v is not None]

    @plgpu.inline_mgpu(
        arg_types=(plgpu.RefType(), plgpu.RefType(), plgpu.Layout.WG_SPLAT(()))
        + (plgpu.Layout.WG_STRIDED((pixels,), vec_size=vec),) * len(present))
    def reduce(_, exchange_ref, row_ref, tile_value, *arrays):
        i32 = ir.IntegerType.get_signless(32)
        el = ir.VectorType(arrays[0].registers.flat[0].type).element_type
        index = ir.IndexType.get()
        c = lambda v: mgpu_utils.c(v, i32)
        tid = arith.remui(mgpu_utils.thread_idx(), c(128))
        lane, warp = arith.remui(tid, c(32)), arith.divui(tid, c(32))
        zero = arith.constant(el, 0.0)
        vals = [zero] * rows
        for col, a in zip(present, arrays):
            [reg] = a.registers.reshape(-1)
            parts = [vector.extract(reg, dynamic_position=[],
                                    static_position=ir.DenseI64ArrayAttr.get([e]))
                     for e in range(vec)]
            v = parts[0]
            for x in parts[1:]:
                v = arith.addf(v, x)
            vals[col] = v
        one = ir.VectorType.get((1,), el)

        def shuffle(v, d):  # as a 1-vector: utils.shfl_bfly cannot bitcast a 64-bit scalar
            v = mgpu_utils.shfl_bfly(vector.broadcast(one, v), d)
            return vector.extract(v, dynamic_position=[],
                                  static_position=ir.DenseI64ArrayAttr.get([0]))

        for d, h in zip((16, 8, 4, 2, 1), halves):
            if h == 0:
                vals = [arith.addf(vals[0], shuffle(vals[0], d))]
                continue
            upper = arith.cmpi(arith.CmpIPredicate.ne, arith.andi(lane, c(d)), c(0))
            merged = []
            for k in range(h):
                lo = vals[k]
                hi = vals[k + h] if k + h < len(vals) else zero
                send = arith.select(upper, lo, hi)
                keep = arith.select(upper, hi, lo)
                merged.append(arith.addf(keep, shuffle(send, d)))
            vals = merged
        slot = arith.shrui(lane, c(1))
        at = arith.addi(arith.muli(slot, c(4)), warp)
        memref.store(vals[0], exchange_ref, [arith.index_cast(index, at)])
        mgpu_utils.warpgroup_barrier()
        with ir.InsertionPoint(scf.IfOp(arith.cmpi(arith.CmpIPredicate.ule, tid, c(rows)))
                               .then_block):
            slot_t = c(0)
            for r, s in slot_of.items():
                slot_t = arith.select(arith.cmpi(arith.CmpIPredicate.eq, tid, c(r)), c(s),
                                      slot_t)
            four = vector.load(ir.VectorType.get((4,), el), exchange_ref,
                               [arith.index_cast(index, arith.muli(slot_t, c(4)))])
            p = [vector.extract(four, dynamic_position=[],
                                static_position=ir.DenseI64ArrayAttr.get([w])) for w in range(4)]
            total = arith.addf(arith.addf(p[0], p[1]), arith.addf(p[2], p[3]))
            value = arith.select(arith.cmpi(arith.CmpIPredicate.eq, tid, c(rows)),
                                 tile_value.registers.item(), total)
            memref.store(value, row_ref, [arith.index_cast(index, tid)])
            scf.yield_([])

    reduce(exchange, row, tile, *[terms[c] for c in present])


@plgpu.inline_mgpu(arg_types=(plgpu.RefType(), plgpu.Layout.WG_SPLAT(())))
def _zero_row(_, row_ref, tile_value):
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


def _smem_records_backward(rec_ref, smem, barriers, start, last, chunk: int):
    """(record(j), begin(i, j)) of the backward walk over pairs last − 1 down to start with
    their records staged in shared memory: chunks of `chunk` records aligned to multiples of
    `chunk` (chunk q holds pairs [q·chunk, (q + 1)·chunk)), copied by TMA into slot q % 2,
    double-buffered: `begin`, at the first pair of each chunk the walk enters, waits for that
    chunk and starts the copy of the one below it if the walk reaches it (every copy started is
    waited for). Records are read only inside a step that reduces over the warpgroup (whose
    barrier every warp passes after its reads), so no warp still reads a slot when the next
    copy into it starts."""
    def copy(q):
        plgpu.copy_gmem_to_smem(rec_ref.at[pl.ds(q * chunk, chunk)], smem.at[q % 2],
                                barriers.at[q % 2])

    @pl.when(last > start)
    def _():
        copy((last - 1) // chunk)

    def begin(i, j):
        q = j // chunk

        @pl.when((i == 0) | (j % chunk == chunk - 1))
        def _():
            plgpu.barrier_wait(barriers.at[q % 2])

            @pl.when(q * chunk > start)
            def _():
                copy(q - 1)

    def record(j):
        return [smem[(j // chunk) % 2, j % chunk, c] for c in range(ks.REC - 1)]

    return record, begin


def backward_rows(config: RasterConfig, interpret: bool, pixels: int, tiles_x: int, order, bins,
                  masks, records, lane_rows, dt, reduction: str | None = None):
    """(blocks per tile, capacity, ROW_WIDTH) pair rows in emission order from
    `backward_kernel` on a (n_tiles, blocks per tile) grid: block w's row of each real pair
    (gradient over its pixels, then the tile), zero where the block's pixels had stopped;
    padding slots are left unwritten (no Gaussian's slots reach them). `lane_rows` = the
    per-tile final T, stop pairs and cotangents (r, g, b, T, D). `reduction`: "transposed"
    (the default on the GPU) or "terms" (the default in interpret mode, which cannot run the
    former's inline Mosaic GPU code); the rows agree to float rounding (a different summation
    order)."""
    if reduction not in (None, "terms", "transposed"):
        raise ValueError(f"reduction: expected 'terms' or 'transposed', got {reduction!r}")
    capacity, n_tiles = bins.gauss.shape[0], bins.tile_start.shape[0]
    n = TILE_PIXELS // pixels
    if reduction is None:
        reduction = "terms" if interpret else "transposed"
    kernel = functools.partial(backward_kernel, config=config, tiles_x=tiles_x, pixels=pixels,
                               reduction=reduction)
    out = jax.ShapeDtypeStruct((n, capacity, ks.ROW_WIDTH), dt)
    scratch = ()
    if staged(config, dt):
        scratch = (plgpu.SMEM((2, config.tuning.mosaic_chunk, ks.REC), dt),
                   plgpu.Barrier(num_barriers=2))
    if reduction == "transposed":
        scratch += (plgpu.SMEM((2, EXCHANGE), dt),)
    return plgpu.kernel(kernel, out_type=out, scratch_types=scratch, grid=(n_tiles, n),
                        grid_names=("tile", "wg"),
                        interpret=_interpret_params(interpret),
                        kernel_name="localgs_backward_mosaic")(
        order, _ranges(bins), masks, bins.slot, records, *lane_rows)
