"""Where the time of one `pallas` render and its gradient goes, stage by stage (GPU).

    XLA_PYTHON_CLIENT_PREALLOCATE=false python scripts/profile_stages.py [--data DIR]
        [--scenes guitar_x16_1080p,guitar_x110_4k] [--repeat 10]

Each stage is its own jitted function of the previous stages' (precomputed) outputs, timed
alone (median of `--repeat` calls, all stages alternating): projection, the pieces of binning
(tile rectangles, depth order, slot segments, the full emission, the tile sort), the per-pair
preparation (row gather, strip masks, records), the forward kernel from prepared inputs, and
the backward's pieces (backward kernel rows, the per-Gaussian chain and sum kernel with 32
(the default), 64 and 128 Gaussians per program, the vjp of projection; and, for comparison in
the same run, the XLA chain and per-Gaussian sum the `tiles` backend takes). Stage times do not
add up to the end-to-end time exactly (fusion across stage boundaries, launch gaps), which is
printed last for comparison.
"""

from __future__ import annotations

import argparse
import os
import sys

import jax
import jax.numpy as jnp
import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import lgs_jax  # noqa: E402
from benchmarks.common import add_data_argument, load_scene, median_ms  # noqa: E402
from lgs_jax import binning, pairs  # noqa: E402
from lgs_jax.backends import backward, pallas  # noqa: E402
from lgs_jax.backends.pallas import (gaussian_grads, mosaic_backward,  # noqa: E402
                                     segments, table)
from lgs_jax.backends.pallas import steps as kernel_steps  # noqa: E402
from lgs_jax.layout import tile_grid, tiled_image_to_tiles  # noqa: E402
from lgs_jax.projection import depth_order, project  # noqa: E402


def _time(fns: dict, repeat: int) -> dict:
    """benchmarks.common.median_ms of callables returning JAX arrays."""
    return median_ms({k: lambda f=f: jax.block_until_ready(f()) for k, f in fns.items()}, repeat)


def profile(g, cam, repeat: int):
    C = lgs_jax.RasterConfig()
    w, h = cam.width, cam.height
    tiles_x, tiles_y = tile_grid(w, h)
    cap = int(lgs_jax.render(g, cam, backend="pallas").stats.capacity)
    j = jax.jit
    p = j(project)(g, cam)
    rects = j(lambda p: binning.tile_rects(p, w, h))(p)
    order = j(depth_order)(p)
    counts = rects[2] * rects[3]
    cs = counts[order]
    starts = jnp.cumsum(cs) - cs
    e = j(lambda p: binning.emit_pairs(p, w, h, cap))(p)
    bins = j(lambda p: binning.bin_gaussians(p, w, h, cap))(p)
    pg = j(pairs.gather)(p, bins.gauss)
    masks = j(lambda pg, b: pairs.strip_masks(pg, b, tiles_x, C))(pg, bins)
    records = j(lambda pg, b, m: kernel_steps.pair_records(pg, b, tiles_x, C, m))(pg, bins, masks)
    plan = pallas.plan(C, False, tiles_x * tiles_y)
    gtable = j(lambda p: table.gaussian_table(p, plan.interpret))(p)
    fwd = j(lambda p, b, t: pallas.forward(p, b, t, w, h, plan))
    state, stop, _, saved = fwd(p, bins, gtable)
    rng = np.random.default_rng(0)
    cot = tuple(jnp.asarray(rng.normal(size=x.shape).astype(np.float32))
                for x in (state.color, state.trans, state.depth))
    grads = j(lambda p, b, t, s, sv, c: pallas.gradients(p, b, None, w, h, plan, t, s, sv, c))

    def rows_of(b, t, sv, c):  # the whole walks (segments: none)
        stop_at = sv[4]
        color = tiled_image_to_tiles(c[0]) if plan.image else c[0]
        lane_rows = (t, stop_at, color[..., 0], color[..., 1], color[..., 2], c[1], c[2])
        layout = gaussian_grads.rows_of(b, stop_at, None)
        segs = segments.whole_tiles(sv[2], b, layout.end)
        return mosaic_backward.backward_rows(C, plan.interpret, plan.backward_pixels, tiles_x,
                                             segs, b, layout, sv[1], lane_rows, jnp.float32)

    kernel_rows = j(rows_of)
    emission_rows = kernel_rows(bins, state.trans, saved, cot)
    rows11 = jnp.asarray(rng.normal(size=(cap, 11)).astype(np.float32))
    rows10 = jnp.asarray(rng.normal(size=(cap, 10)).astype(np.float32))
    _, proj_vjp = jax.vjp(lambda g: project(g, cam), g)
    stage = {
        "project": (j(project), (g, cam)),
        "tile_rects": (j(lambda p: binning.tile_rects(p, w, h)), (p,)),
        "depth_order": (j(depth_order), (p,)),
        "segment_of_slot": (j(binning.segment_of_slot, static_argnums=2), (starts, cs, cap)),
        "emit_pairs (all)": (j(lambda p: binning.emit_pairs(p, w, h, cap)), (p,)),
        "sort_pairs": (j(lambda t, i: binning.sort_pairs(t, i, tiles_x * tiles_y)),
                       (e.tile, e.gauss)),
        "pairs.gather": (j(pairs.gather), (p, bins.gauss)),
        "strip_masks": (j(lambda pg, b: pairs.strip_masks(pg, b, tiles_x, C)), (pg, bins)),
        "pair_records": (j(lambda pg, b, m: kernel_steps.pair_records(pg, b, tiles_x, C, m)),
                         (pg, bins, masks)),
        "Gaussian table": (j(lambda p: table.gaussian_table(p, plan.interpret)), (p,)),
        "forward (kernel)": (fwd, (p, bins, gtable)),
        "backward (kernel + chain + sum)": (grads, (p, bins, state.trans, stop, saved, cot)),
        "backward kernel (rows)": (kernel_rows, (bins, state.trans, saved, cot)),
        **{f"gaussian_grads (chain + sum), {n} lanes": (
            j(lambda r, b, s, p, n=n: gaussian_grads.sums(
                r, gaussian_grads.rows_of(b, s, None), p, tiles_x, C, False, lanes=n)),
            (emission_rows, bins, saved[4], p)) for n in (32, 64, 128)},
        "XLA: chain_hoisted_rows": (j(lambda p, b, r: pairs.chain_hoisted_rows(
            pairs.gather(p, b.gauss), b, r, tiles_x, C)), (p, bins, rows11)),
        "XLA: per_gaussian_sum": (j(backward.per_gaussian_sum, static_argnums=2),
                                  (rows10, bins, g.num)),
        "XLA: segment_sums (ids in order)": (j(backward.segment_sums, static_argnums=2),
                                             (jnp.sort(bins.gauss), rows10, g.num)),
        "projection vjp": (j(proj_vjp), (jax.tree.map(jnp.ones_like, p),)),
        "e2e render": (j(lambda g: lgs_jax.render(g, cam, backend="pallas",
                                                  capacity=cap).image), (g,)),
        "e2e value_and_grad": (j(jax.value_and_grad(lambda g: jnp.sum(lgs_jax.render(
            g, cam, backend="pallas", capacity=cap).image))), (g,)),
    }
    fns = {k: (lambda f=f, a=a: f(*a)) for k, (f, a) in stage.items()}
    del records
    return _time(fns, repeat), int(bins.pairs_required), cap


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    add_data_argument(ap)
    ap.add_argument("--scenes", default="guitar_x16_1080p,guitar_x110_4k")
    ap.add_argument("--repeat", type=int, default=10)
    args = ap.parse_args()
    print(f"device {jax.devices()[0].device_kind}; JAX {jax.__version__}", flush=True)
    for scene in args.scenes.split(","):
        g, cam = load_scene(scene, args.data)
        g, cam = jax.device_put(g), jax.device_put(cam)
        ms, n_pairs, cap = profile(g, cam, args.repeat)
        print(f"{scene}: {g.num} Gaussians, {n_pairs} pairs, capacity {cap}", flush=True)
        for k, v in ms.items():
            print(f"  {k:<34s} {v:8.3f} ms", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
