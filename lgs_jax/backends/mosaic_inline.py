"""Helpers of the inline Mosaic GPU code (`plgpu.inline_mgpu`) the Mosaic GPU kernels write
where Pallas has no expression (per-lane loads and stores, ballots, shuffles): a warpgroup's
thread ids, the elements of a vector register, and lane vectors built from one scalar per
thread."""

from __future__ import annotations

import numpy as np
from jax.experimental.mosaic.gpu import fragmented_array as mgpu_fa
from jax.experimental.mosaic.gpu import utils as mgpu_utils
from jax.experimental.pallas import mosaic_gpu as plgpu
from jaxlib.mlir import ir
from jaxlib.mlir.dialects import arith, vector

LANES = 128  # threads of a warpgroup (a block): one staged pair each
WARP = 32
STRIDED = plgpu.Layout.WG_STRIDED((LANES,), vec_size=1)  # one element of a (LANES,) per thread


def threads(i32):
    """(thread of the warpgroup, its lane in the warp, its warp) as `i32` values."""
    tid = arith.remui(mgpu_utils.thread_idx(), mgpu_utils.c(LANES, i32))
    return (tid, arith.remui(tid, mgpu_utils.c(WARP, i32)),
            arith.divui(tid, mgpu_utils.c(WARP, i32)))


def element(vec, i: int):
    """Element i of a vector register (inline Mosaic GPU code's lane values)."""
    return vector.extract(vec, dynamic_position=[], static_position=ir.DenseI64ArrayAttr.get([i]))


def lane_vector(x, signed: bool | None = None):
    """A (LANES,) `STRIDED` lane vector holding scalar x at each thread (`signed`: an integer's
    signedness, None for a float)."""
    return mgpu_fa.FragmentedArray(
        _registers=np.array([vector.broadcast(ir.VectorType.get((1,), x.type), x)], dtype=object),
        _layout=mgpu_fa.WGStridedFragLayout((LANES,), 1), _is_signed=signed)
