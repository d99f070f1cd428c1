"""How much the Local-GS warp culling can skip per scene, on a CPU:

    python scripts/strip_occupancy.py [--data DIR] [--scenes synthetic4M_1080p,...]

Per scene (`benchmarks.common.SCENES`): every tile–Gaussian pair the binning emits, and its
8-bit strip mask (`pairs.strip_mask_columns`, the default `RasterConfig`: the masks the Local-GS
kernels cull with). A strip-warp blends a pair only where its bit is set, so the share of set
bits bounds the blending work the culling leaves: the Local-GS kernel's lead over the vanilla
kernel (which blends every pair in all eight strips) from culling alone is at most
8 / (mean set bits), less where staging, list walking and the per-pair setup do not shrink.
Printed per scene: Gaussians, pairs, pairs per valid Gaussian, mean set bits of 8, the share
of pairs with 0, 1, ..., 8 bits, and the share of pairs a half-tile block could skip (no bit in
its four strips). All emitted pairs count, walked or
not (early termination is not modelled: it needs the forward, too slow at 10M on a CPU).

With --chunks, the blend iterations of a forward compacted per block (per chunk of 128 pairs of
a tile's sorted list, a block of four warps packs the pairs with a bit in any of its strips and
every warp steps through all of them, `KernelConfig.unroll` = 8 per iteration: the walk the
per-warp lists replaced, docs/design-notes.md) against per-warp lists (the Mosaic GPU forward,
lgs_jax.backends.pallas.warp_lists: each warp only the pairs of its own strip; the block still
loops to its busiest warp's count, as a warpgroup program must): the blend iterations summed
over every chunk and block, and their ratio, the blending the per-warp lists save.
"""

from __future__ import annotations

import argparse
import functools
import os
import sys

import jax
import jax.numpy as jnp
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import lgs_jax  # noqa: E402
from benchmarks.common import add_data_argument, load_scene  # noqa: E402
from lgs_jax import binning, pairs  # noqa: E402
from lgs_jax.backends import pallas  # noqa: E402
from lgs_jax.backends.pallas.inline import LANES  # noqa: E402
from lgs_jax.layout import tile_grid  # noqa: E402
from lgs_jax.projection import project  # noqa: E402

SCENES = ("guitar_x16_1080p,lego_x16_1080p,guitar_x64_1080p,guitar_x110_4k,synthetic4M_1080p,"
          "synthetic10M_4k")


def _scene(name: str, data: str):
    """(g, cam, projected, pair capacity, tiles_x, tiles_y) of scene `name`."""
    g, cam = load_scene(name, data)
    p = jax.jit(project)(g, cam)
    cap = lgs_jax.pair_capacity(int(binning.count_pairs(p, cam.width, cam.height)))
    return (g, cam, p, cap) + tile_grid(cam.width, cam.height)


def _masks(p, tile, gauss, tiles_x: int):
    """The strip masks of pairs (tile, gauss), as the default `RasterConfig`'s kernels cull."""
    cols = [c[gauss] for c in pairs.table_columns(p)]
    return pairs.strip_mask_columns(cols, tile % tiles_x, tile // tiles_x, lgs_jax.RasterConfig())


def occupancy(name: str, data: str) -> dict:
    """The strip-mask statistics of scene `name` (module docstring)."""
    g, cam, p, cap, tiles_x, tiles_y = _scene(name, data)

    @jax.jit
    def bits(p):
        e = binning.emit_pairs(p, cam.width, cam.height, cap)
        mask = _masks(p, e.tile, e.gauss, tiles_x)
        real = e.tile < tiles_x * tiles_y  # not padding
        count = sum((mask >> i) & 1 for i in range(8))
        halves = (mask & 0xF != 0).astype(jnp.int32) + (mask >> 4 != 0).astype(jnp.int32)
        hist = jnp.stack([jnp.sum(real & (count == k)) for k in range(9)])
        return hist, jnp.sum(jnp.where(real, halves, 0)), jnp.sum(p.valid)

    hist, halves, valid = (np.asarray(x) for x in bits(p))
    n = int(hist.sum())
    return dict(scene=name, gaussians=g.means.shape[0], valid=int(valid), pairs=n,
                mean_bits=float((hist * np.arange(9)).sum() / n), share=hist / n,
                compact_skip=1 - float(halves) / (2 * n))


def chunk_walks(name: str, data: str) -> dict:
    """Blend iterations of the compacted forward and of per-warp lists (module docstring)."""
    _, cam, p, cap, tiles_x, tiles_y = _scene(name, data)
    gpu = lgs_jax.RasterConfig(kernel="mosaic", tuning=lgs_jax.KernelConfig(interpret=False))
    tuning = gpu.tuning
    whole = pallas.plan(gpu, False, tiles_x * tiles_y).forward_pixels == 256
    unroll, lanes = tuning.unroll, LANES
    # (blocks of a tile, warps of a block, strips of a warp) as bit groups of the 8-bit mask
    blocks = [[0b11 << 2 * w for w in range(4)]] if whole else \
        [[1 << 4 * b + w for w in range(4)] for b in range(2)]

    @jax.jit
    def iterations(p):
        bins = binning.bin_gaussians(p, cam.width, cam.height, cap)
        count = bins.tile_end - bins.tile_start
        chunks = (count + lanes - 1) // lanes
        offset = jnp.cumsum(chunks) - chunks
        real = bins.tile < tiles_x * tiles_y
        t = jnp.where(real, bins.tile, 0)
        seg = jnp.where(real, offset[t] + (jnp.arange(cap) - bins.tile_start[t]) // lanes,
                        jnp.sum(chunks))
        mask = _masks(p, t, bins.gauss, tiles_x)
        n_seg = cap // lanes + tiles_x * tiles_y  # chunks: at most one partial per tile
        per_chunk = lambda x: jax.ops.segment_sum(x.astype(jnp.int32), seg, n_seg + 1)[:-1]
        steps = lambda n: (n + unroll - 1) // unroll
        now = per_warp = 0
        for warps in blocks:
            kept = per_chunk(real & ((mask & sum(warps)) != 0))
            busiest = functools.reduce(jnp.maximum, [per_chunk(real & ((mask & w) != 0))
                                                     for w in warps])
            now, per_warp = now + jnp.sum(steps(kept)), per_warp + jnp.sum(steps(busiest))
        return now, per_warp

    now, per_warp = (int(x) for x in iterations(p))
    return dict(scene=name, blocks="whole" if whole else "half", now=now, per_warp=per_warp)


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    add_data_argument(ap)
    ap.add_argument("--scenes", default=SCENES)
    ap.add_argument("--chunks", action="store_true", help="the blend iterations (docstring)")
    args = ap.parse_args()
    if args.chunks:
        print(f"{'scene':>20} {'blocks':>6} {'iterations':>11} {'per-warp lists':>14} {'ratio':>6}")
        for name in args.scenes.split(","):
            r = chunk_walks(name, args.data)
            print(f"{name:>20} {r['blocks']:>6} {r['now']:11d} {r['per_warp']:14d} "
                  f"{r['now'] / r['per_warp']:6.2f}", flush=True)
        return
    print(f"{'scene':>20} {'Gaussians':>10} {'pairs':>10} {'pairs/G':>7} {'bits':>5} "
          f"{'8/bits':>6} {'compact skip':>12}  share of pairs with 0..8 bits")
    for name in args.scenes.split(","):
        r = occupancy(name, args.data)
        shares = " ".join(f"{s:.2f}" for s in r["share"])
        print(f"{name:>20} {r['gaussians'] / 1e6:9.2f}M {r['pairs'] / 1e6:9.2f}M "
              f"{r['pairs'] / r['valid']:7.2f} {r['mean_bits']:5.2f} {8 / r['mean_bits']:6.2f} "
              f"{r['compact_skip']:12.2f}  {shares}", flush=True)


if __name__ == "__main__":
    main()
