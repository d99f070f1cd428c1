"""How much of the Mosaic GPU backward kernel's time its per-pair reductions take (issue 18), and
whether Mosaic GPU can express the reductions a faster kernel would need (GPU only).

    XLA_PYTHON_CLIENT_PREALLOCATE=false python scripts/probe_backward_reductions.py [--data DIR]
        [--scenes guitar_x16_1080p,guitar_x110_4k] [--repeat 10] [--lower-only]

1. Reduction variants. Per pair, `pallas_mosaic.backward_kernel` reduces 11 gradient terms over
   its block's pixels: `terms` reduces each with a warpgroup-wide `jnp.sum` (shuffles within
   each warp, an exchange across the four warps through shared memory with barriers, a store
   from every thread); `transposed` (the default on the GPU) with `mosaic_rows.transposed_row`'s
   transposing butterfly (13 shuffles per thread for the 11 terms, one exchange, one barrier,
   one coalesced store). The `one_sum` variant adds the 11 per-lane terms elementwise and
   reduces that once with `terms` (same loads and arithmetic, wrong rows; only its time
   matters). Records read from global memory (`mosaic_chunk` 0) or staged in shared memory
   (64); the kernel alone (`pallas_mosaic.backward_rows`) on the same real inputs; each
   variant's rows against those of `terms` (a different summation order: rounding only).
2. Layout probes: small kernels that compile and run (or print the error) the pieces a batched
   reduction through Pallas' own layouts would use: a (R, 256) array in a tiled layout whose
   pixel axis is split over warps, lanes and a 2-vector, reduced along the pixels (all R rows
   through one shared-memory exchange), and a within-warp reduction that leaves one partial per
   warp (BENCHMARKS.md §7 has what they showed). `--lower-only` only lowers them for the GPU,
   which needs no GPU and raises the same layout errors (for designing on a CPU).
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import os
import sys

import jax
import jax.numpy as jnp
import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import lgs_jax  # noqa: E402
from benchmarks.common import add_data_argument, load_scene, median_ms  # noqa: E402
from lgs_jax import binning  # noqa: E402
from lgs_jax.backends import (backward_segments, gaussian_grads, kernel_steps,  # noqa: E402
                              pallas, pallas_mosaic)
from lgs_jax.layout import tile_grid  # noqa: E402
from lgs_jax.projection import project  # noqa: E402


def _one_sum_step(original):
    """`kernel_steps.backward_step` whose 11 terms are added per lane into the first (one
    reduction per pair in the kernel); the others are None (written as zero)."""
    def step(*args, **kwargs):
        values, carry = original(*args, **kwargs)
        total = functools.reduce(jnp.add, [v for v in values if v is not None])
        return [total] + [None] * (len(values) - 1), carry

    return step


def reduction_share(g, cam, repeat: int):
    """Backward kernel time (ms) on the same inputs: 11 reductions per pair (`terms`) and the
    transposing butterfly (`transposed`, records staged (chunk 64) or read from global memory
    (chunk 0)), and 1 reduction per pair (a bound); how far each variant's rows are from the
    first's."""
    # XLA's records, whose TMA staging the variants switch (the default builds them in the
    # kernel: KernelConfig.mosaic_pair_source), each pixel's stop pair (mosaic_block_stops off)
    config = lgs_jax.RasterConfig(tuning=lgs_jax.KernelConfig(mosaic_pair_source="records",
                                                              mosaic_block_stops=False))
    w, h = cam.width, cam.height
    tiles_x, tiles_y = tile_grid(w, h)
    cap = int(lgs_jax.render(g, cam, backend="pallas").stats.capacity)
    p = jax.jit(project)(g, cam)
    bins = jax.jit(lambda p: binning.bin_gaussians(p, w, h, cap))(p)
    plan = pallas.plan(config, False, tiles_x * tiles_y)
    state, stop, _, saved = jax.jit(lambda p, b: pallas._forward(p, b, w, h, plan))(p, bins)
    masks, records, order = saved[:3]
    rng = np.random.default_rng(0)
    cot = [jnp.asarray(rng.normal(size=state.trans.shape).astype(np.float32)) for _ in range(5)]
    args = (bins, masks, records, order, (state.trans, stop, *cot))

    def rows_fn(chunk: int, reduction: str):
        cf = dataclasses.replace(config, tuning=dataclasses.replace(config.tuning,
                                                                    mosaic_chunk=chunk))
        def rows(b, m, r, o, lr):
            layout = gaussian_grads.rows_of(b, lr[1])
            return pallas_mosaic.backward_rows(
                cf, False, plan.backward_pixels, tiles_x,
                backward_segments.whole_tiles(o, b, layout.end), b, layout, m, r, lr,
                jnp.float32, reduction=reduction)

        f = jax.jit(rows)
        jax.block_until_ready(f(*args))  # compiled now, with backward_step as it is now
        return f

    fns = {"11 sums, chunk 64": rows_fn(64, "terms"),
           "transposed, chunk 64": rows_fn(64, "transposed"),
           "transposed, chunk 0": rows_fn(0, "transposed")}
    # Rows sit at emission slots; slots from the pair count on are padding, never written.
    real = int(bins.pairs_required)
    base = fns["11 sums, chunk 64"](*args)[:, :real]
    scale = float(jnp.max(jnp.abs(base)))
    same = {}
    for k in list(fns)[1:]:
        rows = fns[k](*args)[:, :real]
        same[k] = ("equal" if bool(jnp.array_equal(base, rows)) else
                   f"max |diff| {float(jnp.max(jnp.abs(rows - base))) / scale:.1e} x max |row|")
    original = kernel_steps.backward_step
    kernel_steps.backward_step = _one_sum_step(original)
    try:
        fns["1 sum, chunk 64"] = rows_fn(64, "terms")
    finally:
        kernel_steps.backward_step = original
    ms = median_ms({k: lambda f=f: jax.block_until_ready(f(*args)) for k, f in fns.items()},
                   repeat)
    return ms, same, int(bins.pairs_required), cap, plan.backward_pixels


# ------------------------------------------------------------------------------ layout probes

def _probe(name: str, fn, args, want, lower_only: bool):
    """Run `fn(*args)` and compare with `want`, or (lower_only) only lower it for the GPU, which
    works without one and raises the same layout errors."""
    try:
        if lower_only:
            jax.jit(fn).trace(*args).lower(lowering_platforms=("cuda",))
            print(f"  {name:<48s} lowers", flush=True)
            return
        got = np.asarray(fn(*args))
        ok = np.allclose(got, want, rtol=1e-5, atol=1e-4)
        print(f"  {name:<48s} {'OK' if ok else 'WRONG VALUES'}", flush=True)
        if not ok:
            print(f"    got {got.ravel()[:8]} want {np.asarray(want).ravel()[:8]}")
    except Exception as e:  # noqa: BLE001 - report and go on
        text = str(e).strip()
        print(f"  {name:<48s} FAILS: {type(e).__name__}: {text[:400]}", flush=True)


def layout_probes(lower_only: bool):
    from jax.experimental import pallas as pl
    from jax.experimental.pallas import mosaic_gpu as plgpu
    from jax.experimental.mosaic.gpu.fragmented_array import Tiling

    def pixel_layout(rows: int):
        """(rows, 256): rows in registers, pixels over 4 warps x 32 lanes x 2-vectors."""
        return plgpu.Layout.TILED(Tiling(((rows, 256), (64,), (2,))),
                                  warp_dims=(-3,), lane_dims=(-2,), vector_dim=-1)

    def warp_layout():
        """(4, 64): warp w holds row w, 2 elements per lane (the strided (256,) order)."""
        return plgpu.Layout.TILED(Tiling(((4, 64), (2,))),
                                  warp_dims=(-3,), lane_dims=(-2,), vector_dim=-1)

    def call(kernel, shape, *args):
        return plgpu.kernel(kernel, out_type=jax.ShapeDtypeStruct(shape, jnp.float32))(*args)

    x = np.random.default_rng(0).normal(size=(16, 256)).astype(np.float32)

    def rows_sum(rows):
        def kernel(x_ref, o_ref):
            v = plgpu.load(x_ref, layout=pixel_layout(rows))
            o_ref[...] = jnp.sum(v * 2.0, axis=1)
        return lambda x: call(kernel, (rows,), x), (jnp.asarray(x[:rows]),), 2 * x[:rows].sum(1)

    def iota_rows_sum():
        def kernel(o_ref):
            i = plgpu.broadcasted_iota(jnp.int32, (16, 256), 1,
                                       layout=pixel_layout(16)).astype(jnp.float32)
            r = plgpu.broadcasted_iota(jnp.int32, (16, 256), 0,
                                       layout=pixel_layout(16)).astype(jnp.float32)
            o_ref[...] = jnp.sum(i * r, axis=1)
        return lambda: call(kernel, (16,)), (), np.arange(16) * np.arange(256).sum()

    def broadcast_row():
        def kernel(x_ref, o_ref):
            row = plgpu.load(x_ref.at[pl.ds(0, 1)], layout=pixel_layout(1))
            basis = plgpu.load(x_ref, layout=pixel_layout(16))
            o_ref[...] = jnp.sum(basis * jnp.broadcast_to(row, (16, 256)), axis=1)
        return lambda x: call(kernel, (16,), x), (jnp.asarray(x),), (x * x[:1]).sum(1)

    def per_warp_sum():
        def kernel(x_ref, o_ref):
            v = plgpu.load(x_ref, layout=warp_layout())
            o_ref[...] = jnp.sum(v, axis=1)
        return (lambda x: call(kernel, (4,), x), (jnp.asarray(x[0].reshape(4, 64)),),
                x[0].reshape(4, 64).sum(1))

    _probe("(16,256) tiled load + sum over pixels", *rows_sum(16), lower_only)
    _probe("(16,256) tiled iota + sum over pixels", *iota_rows_sum(), lower_only)
    _probe("(1,256) row broadcast to (16,256) + sum", *broadcast_row(), lower_only)
    _probe("(4,64) per-warp sum (no cross-warp step)", *per_warp_sum(), lower_only)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    add_data_argument(ap)
    ap.add_argument("--scenes", default="guitar_x16_1080p,guitar_x110_4k")
    ap.add_argument("--repeat", type=int, default=10)
    ap.add_argument("--lower-only", action="store_true",
                    help="only lower the layout probes for the GPU (runs without one)")
    args = ap.parse_args()
    print(f"device {jax.devices()[0].device_kind}; JAX {jax.__version__}", flush=True)
    print("layout probes:", flush=True)
    layout_probes(args.lower_only)
    if args.lower_only:
        return 0
    for scene in args.scenes.split(","):
        g, cam = load_scene(scene, args.data)
        g, cam = jax.device_put(g), jax.device_put(cam)
        ms, same, n_pairs, cap, px = reduction_share(g, cam, args.repeat)
        print(f"{scene}: {g.num} Gaussians, {n_pairs} pairs, capacity {cap}, {px}-pixel blocks; "
              "backward kernel ms (rows against '11 sums, chunk 64'):", flush=True)
        for k, v in ms.items():
            print(f"  {k:<22s} {v:8.3f}  {same.get(k, '')}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
