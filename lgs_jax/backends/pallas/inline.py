"""Helpers of the inline Mosaic GPU code (`plgpu.inline_mgpu`) the Mosaic GPU kernels write
where Pallas has no expression (per-lane loads and stores, ballots, shuffles): a warpgroup's
thread ids, the elements of a vector register, lane vectors built from one scalar per thread,
and the blend loops' condition as one barrier reduction."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jax.experimental.mosaic.gpu import fragmented_array as mgpu_fa
from jax.experimental.mosaic.gpu import utils as mgpu_utils
from jax.experimental.pallas import mosaic_gpu as plgpu
from jaxlib.mlir import ir
from jaxlib.mlir.dialects import arith, vector

from ...config import RasterConfig
from . import steps as ks

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


def any_equal(x, value: int):
    """Whether some element of the warpgroup's int32 vector `x` (n / LANES consecutive elements
    per thread) equals `value`, as an int32 0/1 the whole warpgroup holds: each
    thread ors its own elements' tests, then one `bar.red.or.pred` over the warpgroup's named
    barrier (the one Mosaic GPU's `warpgroup_barrier` uses) reduces the 128 threads'
    predicates. jnp.any(x == value)'s value (`steps.running`'s test) without the
    butterfly of shuffles, the shared-memory exchange and the two barriers its lowering
    takes."""
    n = x.shape[0]  # thread t holds elements [t·v, (t + 1)·v): the layout iota's lanes take
    layout = plgpu.Layout.WG_STRIDED((n,), vec_size=max(1, n // LANES))

    @plgpu.inline_mgpu(arg_types=(layout,),
                       return_type=plgpu.ShapeDtypeStruct((), jnp.int32,
                                                          layout=plgpu.Layout.WG_SPLAT(())))
    def reduce(_, x):
        i1, i32 = ir.IntegerType.get_signless(1), ir.IntegerType.get_signless(32)
        target = mgpu_utils.c(value, i32)
        mine = None
        for reg in x.registers.flat:
            for i in range(ir.VectorType(reg.type).shape[0]):
                z = arith.cmpi(arith.CmpIPredicate.eq, element(reg, i), target)
                mine = z if mine is None else arith.ori(mine, z)
        some = mgpu_utils.inline_ptx(f"bar.red.or.pred $0, $1, {LANES}, $2;",
                                     mgpu_utils.warpgroup_barrier_idx(sync=False), mine,
                                     result_types=i1, has_side_effects=True)
        return mgpu_fa.FragmentedArray.splat(arith.extui(i32, some), (), is_signed=True)

    return reduce(plgpu.layout_cast(x, layout))


def running(config: RasterConfig, interpret: bool):
    """The blend loops' condition (`steps.running`: some pixel of the warpgroup not done)
    as a function of the blend state: on the GPU in exact blending `any_equal` on the stop
    pairs (one `bar.red` per iteration), the same value; else `steps.running` (interpret mode
    runs no inline code)."""
    if interpret or config.blend != "exact":
        return lambda st: ks.running(st, config)
    return lambda st: any_equal(st[5], ks.NOT_STOPPED) != 0
