"""How much the Local-GS warp culling can skip per scene (issue 17), on a CPU:

    python scripts/strip_occupancy.py [--data DIR] [--scenes synthetic4M_1080p,...]

Per scene (`benchmarks.common.SCENES`): every tile–Gaussian pair the binning emits, and its
8-bit strip mask (`pairs.strip_mask_columns`, the default `RasterConfig`: the masks the Local-GS
kernels cull with). A strip-warp blends a pair only where its bit is set, so the share of set
bits bounds the blending work the culling leaves: the Local-GS kernel's lead over the vanilla
kernel (which blends every pair in all eight strips) from culling alone is at most
8 / (mean set bits), less where staging, list walking and the per-pair setup do not shrink.
Printed per scene: Gaussians, pairs, pairs per valid Gaussian, mean set bits of 8, the share
of pairs with 1, 2, ..., 8 bits, and the share of pairs a half-tile block's compact walk skips
(no bit in its four strips: `KernelConfig.mosaic_compact`). All emitted pairs count, walked or
not (early termination is not modelled: it needs the forward, too slow at 10M on a CPU).
"""

from __future__ import annotations

import argparse
import os
import sys

import jax
import jax.numpy as jnp
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import lgs_jax  # noqa: E402
from benchmarks.common import add_data_argument, load_scene  # noqa: E402
from lgs_jax import binning, pairs  # noqa: E402
from lgs_jax.layout import tile_grid  # noqa: E402
from lgs_jax.projection import project  # noqa: E402

SCENES = ("guitar_x16_1080p,lego_x16_1080p,guitar_x64_1080p,guitar_x110_4k,synthetic4M_1080p,"
          "synthetic10M_4k")


def occupancy(name: str, data: str) -> dict:
    """The strip-mask statistics of scene `name` (module docstring)."""
    g, cam = load_scene(name, data)
    p = jax.jit(project)(g, cam)
    cap = lgs_jax.pair_capacity(int(binning.count_pairs(p, cam.width, cam.height)))
    tiles_x, tiles_y = tile_grid(cam.width, cam.height)

    @jax.jit
    def bits(p):
        e = binning.emit_pairs(p, cam.width, cam.height, cap)
        cols = pairs.table_columns(p)
        mask = pairs.strip_mask_columns([c[e.gauss] for c in cols], e.tile % tiles_x,
                                        e.tile // tiles_x, lgs_jax.RasterConfig())
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


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    add_data_argument(ap)
    ap.add_argument("--scenes", default=SCENES)
    args = ap.parse_args()
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
