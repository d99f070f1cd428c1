"""Whether a Mosaic GPU kernel can stage its own pair records (issues 17 and 18): each lane of a
warpgroup gathers one pair's Gaussian row by its id, the lane vectors go to shared memory, and
the pair loop reads them back as scalars. That is the paper's staging (V built per tile from
per-Gaussian rows) and would remove the 48-byte per-pair records the Local-GS kernels read today
(1.21 GB at 10M Gaussians at 4K) and the XLA pass that writes them.

    XLA_PYTHON_CLIENT_PREALLOCATE=false python scripts/probe_lane_gather.py [--lower-only]

Pallas Mosaic GPU has no per-lane gather from global memory into a lane vector; inline Mosaic GPU
code (`plgpu.inline_mgpu`) can issue one load per thread at its own address. The probe kernel,
one warpgroup per chunk of 128 ids: `lane_gather` (inline: thread t loads table[ids[t], c] for
every column c, returned as strided (128,) lane vectors), then lane-vector arithmetic in Pallas
(here 2x + 1, where the kernel would build V and the strip mask), a store of each column to
shared memory, and a scalar loop reading smem[c, i] back and writing it out. On a GPU the output
is checked against numpy; `--lower-only` lowers it for the GPU on any machine (the same layout
and lowering errors, not the GPU compiler's LLVM-level ones: run it on a GPU before building on
it).
"""

from __future__ import annotations

import argparse
import functools
import sys

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax
from jax.experimental import pallas as pl
from jax.experimental.mosaic.gpu import fragmented_array as mgpu_fa
from jax.experimental.pallas import mosaic_gpu as plgpu
from jaxlib.mlir import ir
from jaxlib.mlir.dialects import arith, memref, vector

LANES = 128
STRIDED = plgpu.Layout.WG_STRIDED((LANES,), vec_size=1)


def lane_gather(table_ref, ids, columns: int):
    """`columns` (LANES,) float32 lane vectors: lane t holds table_ref[ids[t], c] (inline Mosaic
    GPU code: one load per thread and column at the thread's own row)."""
    @plgpu.inline_mgpu(
        arg_types=(plgpu.RefType(), STRIDED),
        return_type=tuple(plgpu.ShapeDtypeStruct((LANES,), jnp.float32, layout=STRIDED)
                          for _ in range(columns)))
    def gather(_, table, lane_ids):
        index = ir.IndexType.get()
        [reg] = lane_ids.registers.reshape(-1)
        row = arith.index_cast(index, vector.extract(
            reg, dynamic_position=[], static_position=ir.DenseI64ArrayAttr.get([0])))
        out = []
        for c in range(columns):
            x = memref.load(table, [row, arith.constant(index, c)])
            vec = vector.broadcast(ir.VectorType.get((1,), x.type), x)
            out.append(mgpu_fa.FragmentedArray(
                _registers=np.array([vec], dtype=object),
                _layout=mgpu_fa.WGStridedFragLayout((LANES,), 1), _is_signed=None))
        return tuple(out)

    return gather(table_ref, ids)


def probe_kernel(ids_ref, table_ref, out_ref, smem, *, columns: int):
    base = lax.axis_index("chunk") * LANES
    ids = ids_ref[pl.ds(base, LANES)]
    for c, v in enumerate(lane_gather(table_ref, ids, columns)):
        smem[c, :] = 2.0 * v + 1.0  # where the kernel would build V and the strip mask

    def body(i, carry):  # the pair loop: one pair's staged values as scalars
        for c in range(columns):
            out_ref[c, base + i] = smem[c, i]
        return carry

    lax.fori_loop(0, LANES, body, jnp.int32(0))


def run(ids, table):
    columns = table.shape[1]
    kernel = functools.partial(probe_kernel, columns=columns)
    return plgpu.kernel(kernel, out_type=jax.ShapeDtypeStruct((columns, ids.shape[0]),
                                                              jnp.float32),
                        scratch_types=(plgpu.SMEM((columns, LANES), jnp.float32),),
                        grid=(ids.shape[0] // LANES,), grid_names=("chunk",))(ids, table)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--lower-only", action="store_true",
                    help="only lower the probe for the GPU (runs without one)")
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    table = rng.normal(size=(1000, 10)).astype(np.float32)
    ids = rng.integers(0, table.shape[0], size=4 * LANES).astype(np.int32)
    print(f"device {jax.devices()[0].device_kind}; JAX {jax.__version__}", flush=True)
    try:
        if args.lower_only:
            jax.jit(run).trace(ids, table).lower(lowering_platforms=("cuda",))
            print("lane gather + shared-memory staging: lowers for the GPU")
            return 0
        got = np.asarray(jax.jit(run)(ids, table))
        want = (2.0 * table[ids] + 1.0).T
        ok = np.array_equal(got, want)
        print(f"lane gather + shared-memory staging: {'OK' if ok else 'WRONG VALUES'}")
        return 0 if ok else 1
    except Exception as e:  # noqa: BLE001 - report what fails
        print(f"lane gather + shared-memory staging FAILS: {type(e).__name__}: "
              f"{str(e).strip()[:600]}")
        return 1


if __name__ == "__main__":
    sys.exit(main())
