"""Pair emission: the library's against variants, same process (GPU experiment):

    XLA_PYTHON_CLIENT_PREALLOCATE=false python scripts/probe_emission.py [--data DIR]
        [--scenes guitar_x64_1080p,guitar_x110_4k] [--repeat 10]

The depth order with float keys through JAX's comparator (the code before Dec 2) against the
library's `projection.float_sort_key`; the library's slot segments (a running max) against
running sums only; the library's `binning.emit_pairs` (rectangles gathered per slot by Gaussian)
against rows gathered once in depth order and one row per slot. Each pair must agree exactly.
Also prints whether XLA compiled each depth sort to CUB (a `cub` custom call in the HLO). The
run recorded in BENCHMARKS.md §7 ("Dec 2") labelled the library's forms "old" and the variants
"new" for the segments and the emission (they were the library's then).
"""

from __future__ import annotations

import argparse
import os
import sys

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import lgs_jax  # noqa: E402
from benchmarks.common import add_data_argument, load_scene, median_ms  # noqa: E402
from lgs_jax import binning  # noqa: E402
from lgs_jax.layout import tile_grid  # noqa: E402
from lgs_jax.projection import depth_order, project  # noqa: E402


def old_depth_order(p):
    idx = jnp.arange(p.depth.shape[0], dtype=jnp.int32)
    key = jnp.where(p.valid, p.depth, jnp.inf)
    return lax.sort((key, idx), num_keys=1, is_stable=True)[1]


def cumsum_segment_of_slot(starts, counts, capacity):
    """Running sums only: each non-empty segment stores its index minus the previous non-empty
    segment's at its first slot."""
    n = counts.shape[0]
    idx = jnp.arange(n, dtype=jnp.int32)
    nonempty = (counts > 0) & (starts >= 0) & (starts < capacity)
    rank = jnp.cumsum(nonempty.astype(jnp.int32)) - 1
    by_rank = jnp.zeros((n,), jnp.int32).at[jnp.where(nonempty, rank, n)].set(
        idx, mode="drop", unique_indices=True)
    previous = jnp.where(rank > 0, by_rank[jnp.maximum(rank - 1, 0)], 0)
    marks = jnp.zeros((capacity + 1,), jnp.int32).at[jnp.where(nonempty, starts, capacity)].set(
        idx - previous, mode="drop", unique_indices=True)
    k = jnp.cumsum(marks[:capacity])
    total = starts[-1] + counts[-1]
    return jnp.where(jnp.arange(capacity, dtype=jnp.int32) < total, k, n - 1)


def rows_emit(p, width, height, capacity):
    """`binning.emit_pairs`' tiles and Gaussians with the rectangles gathered once in depth order
    and one 5-column row gathered per slot (the cumsum slot segments)."""
    tiles_x, tiles_y = tile_grid(width, height)
    tx0, ty0, nx, ny, _ = binning.tile_rects(p, width, height)
    counts = nx * ny
    order = depth_order(p)
    rect = jnp.stack([tx0, ty0, jnp.maximum(nx, 1), counts], -1)[order]
    counts_sorted = rect[:, 3]
    starts = jnp.cumsum(counts_sorted) - counts_sorted
    k = cumsum_segment_of_slot(starts, counts_sorted, capacity)
    per_k = jnp.concatenate([jnp.stack([starts, order], -1), rect[:, :3]], -1)[k]
    slot = jnp.arange(capacity, dtype=jnp.int32)
    local = slot - per_k[:, 0]
    tile = (per_k[:, 3] + local // per_k[:, 4]) * tiles_x + per_k[:, 2] + local % per_k[:, 4]
    return jnp.where(slot < binning.total_pairs(counts), tile, tiles_x * tiles_y), per_k[:, 1]


def uses_cub(f, *args) -> bool:
    return "cub" in jax.jit(f).lower(*args).compile().as_text().lower()


def probe(g, cam, repeat):
    w, h = cam.width, cam.height
    cap = int(lgs_jax.render(g, cam, backend="pallas").stats.capacity)
    p = jax.jit(project)(g, cam)
    tx0, ty0, nx, ny, _ = jax.jit(lambda p: binning.tile_rects(p, w, h))(p)
    order = jax.jit(depth_order)(p)
    cs = (nx * ny)[order]
    starts = jnp.cumsum(cs) - cs
    fns = {
        "depth order, float keys (old)": (jax.jit(old_depth_order), (p,)),
        "depth order, uint keys (library)": (jax.jit(depth_order), (p,)),
        "slot segments, cummax (library)": (jax.jit(binning.segment_of_slot, static_argnums=2),
                                            (starts, cs, cap)),
        "slot segments, cumsum (variant)": (jax.jit(cumsum_segment_of_slot, static_argnums=2),
                                            (starts, cs, cap)),
        "emit_pairs (library)": (jax.jit(lambda p: binning.emit_pairs(p, w, h, cap)), (p,)),
        "emit_pairs, rows (variant)": (jax.jit(lambda p: rows_emit(p, w, h, cap)), (p,)),
    }
    outs = {k: f(*a) for k, (f, a) in fns.items()}
    lib_emit = outs["emit_pairs (library)"]
    same = {
        "depth order": np.array_equal(*(outs[k] for k in list(fns)[:2])),
        "slot segments": np.array_equal(*(outs[k] for k in list(fns)[2:4])),
        "emit tile": np.array_equal(outs["emit_pairs, rows (variant)"][0], lib_emit.tile),
        "emit gauss": np.array_equal(outs["emit_pairs, rows (variant)"][1], lib_emit.gauss),
    }
    cub = {"float keys": uses_cub(old_depth_order, p), "uint keys": uses_cub(depth_order, p)}
    ms = median_ms({k: (lambda f=f, a=a: jax.block_until_ready(f(*a)))
                    for k, (f, a) in fns.items()}, repeat)
    return ms, same, cub, cap


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    add_data_argument(ap)
    ap.add_argument("--scenes", default="guitar_x64_1080p,guitar_x110_4k")
    ap.add_argument("--repeat", type=int, default=10)
    args = ap.parse_args()
    print(f"device {jax.devices()[0].device_kind}; JAX {jax.__version__}", flush=True)
    for scene in args.scenes.split(","):
        g, cam = load_scene(scene, args.data)
        ms, same, cub, cap = probe(jax.device_put(g), jax.device_put(cam), args.repeat)
        print(f"{scene}: {g.num} Gaussians, capacity {cap}; equal: {same}; CUB sort: {cub}")
        for k, v in ms.items():
            print(f"  {k:<32s} {v:8.3f} ms", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
