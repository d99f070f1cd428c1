"""XLA-built pair records (`tuning.mosaic_pair_source="records"`, `kernel_steps.pair_records`)
staged in shared memory by TMA for the Mosaic GPU Local-GS forward and backward kernels
(lgs_jax.backends.pallas_mosaic), where `tuning.mosaic_chunk` > 0 and the records are float32
(TMA has no 64-bit float type).

The forward stages the tile's records `mosaic_chunk` per TMA copy, double-buffered (chunk c + 1
in flight while chunk c is blended; a copy is issued only where the list reaches it, and the
block waits for the one in flight before it exits), the strip mask read from the record's last
column; the backward copies chunks aligned to multiples of the chunk downward. Bit for bit the
outputs of the kernels reading records from global memory.
"""

from __future__ import annotations

import jax.numpy as jnp
from jax.experimental import pallas as pl
from jax.experimental.pallas import mosaic_gpu as plgpu

from ..config import RasterConfig
from . import kernel_steps as ks


def staged(config: RasterConfig, dt) -> bool:
    """Whether the kernels stage XLA's records of dtype `dt` in shared memory by TMA: records
    built in XLA (`tuning.mosaic_pair_source`), a chunk set, and float32 records (TMA has no
    64-bit float type: Mosaic GPU raises "unsupported TMA dtype f64" when compiling for the
    GPU; interpret mode has no TMA and would not notice)."""
    t = config.tuning
    from_xla = t.mosaic_pair_source == "records"
    return from_xla and t.mosaic_chunk > 0 and jnp.dtype(dt) == jnp.float32


def scratch(config: RasterConfig, dt) -> tuple:
    """Shared memory: two chunks of records (2, mosaic_chunk, REC) and their copies' barriers."""
    return (plgpu.SMEM((2, config.tuning.mosaic_chunk, ks.REC), dt),
            plgpu.Barrier(num_barriers=2))


def forward_source(rec_ref, smem, barriers, start, end, evaluate, config: RasterConfig):
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


def backward_source(rec_ref, smem, barriers, start, last, chunk: int):
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
