"""The work warp culling skips, per tile, on a real scene (the Local-GS paper's Fig. 1 idea).

    python -m paper_figs.culling [--scene SPEC ...] [--data DIR] [--out DIR]

For each scene (benchmarks.common specs: `default@1280x720`, `guitar@1280x720`, ...), on the
CPU: project, bin (lgs_jax.binning.bin_gaussians) and build every pair's 8-bit strip mask
(lgs_jax.pairs.strip_masks, the default `RasterConfig`: hoisted, tile-local). A tile with P
pairs has 8·P strip–Gaussian pairs without warp culling; with it, one per set mask bit. Writes
DIR/culling_<scene>.csv (one row per tile: tile_x, tile_y, pairs, strip_pairs, skipped_share =
1 − strip_pairs / (8·pairs), empty for a tile without pairs) and DIR/culling_<scene>.png, the
float32 render (`tiles` backend) the figure draws the tiles over. paper_figs/make_figs.py draws
the figure from these files.
"""

from __future__ import annotations

import argparse
import csv
import os

import jax
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
SCENES = ("default@1280x720", "guitar@1280x720")


def strip_counts(g, cam):
    """(pairs, strip_pairs), each (tiles_y, tiles_x) int64: per tile, its tile–Gaussian pairs
    and the set bits of their strip masks."""
    import lgs_jax
    from lgs_jax import binning, pairs
    from lgs_jax.layout import STRIPS, tile_grid
    from lgs_jax.projection import project

    tiles_x, tiles_y = tile_grid(cam.width, cam.height)
    cap = lgs_jax.pair_capacity(int(lgs_jax.count_pairs(g, cam)))

    @jax.jit
    def masks(g, cam):
        p = project(g, cam)
        bins = binning.bin_gaussians(p, cam.width, cam.height, cap)
        m = pairs.strip_masks(pairs.gather(p, bins.gauss), bins, tiles_x, lgs_jax.RasterConfig())
        return bins.tile, m

    tile, mask = (np.asarray(x) for x in masks(g, cam))
    real = tile < tiles_x * tiles_y
    bits = sum((mask >> s) & 1 for s in range(STRIPS))
    n_tiles = tiles_x * tiles_y
    count = np.bincount(tile[real], minlength=n_tiles)
    strip = np.bincount(tile[real], weights=bits[real], minlength=n_tiles).astype(np.int64)
    return count.reshape(tiles_y, tiles_x), strip.reshape(tiles_y, tiles_x)


def write(name, g, cam, out):
    """DIR/culling_<name>.csv and .png (module docstring); returns the CSV's path."""
    import matplotlib.pyplot as plt

    import lgs_jax

    count, strip = strip_counts(g, cam)
    path = os.path.join(out, f"culling_{name}.csv")
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["scene", "width", "height", "tile_x", "tile_y", "pairs", "strip_pairs",
                    "skipped_share"])
        for (ty, tx), n in np.ndenumerate(count):
            share = f"{1 - strip[ty, tx] / (8 * n):.6f}" if n else ""
            w.writerow([name, cam.width, cam.height, tx, ty, n, strip[ty, tx], share])
    image = np.clip(np.asarray(lgs_jax.render(g, cam, backend="tiles").image), 0, 1)
    plt.imsave(os.path.join(out, f"culling_{name}.png"), image[::2, ::2])  # half size
    total = count.sum()
    print(f"{name}: {total} pairs, {strip.sum()} strip pairs of {8 * total}: warp culling skips "
          f"{1 - strip.sum() / (8 * total):.1%}; wrote {path}")
    return path


def main(argv=None) -> int:
    from benchmarks.common import add_data_argument, parse_scene

    ap = argparse.ArgumentParser(prog="python -m paper_figs.culling", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", action="append", help=f"scene specs (default: {SCENES})")
    add_data_argument(ap)
    ap.add_argument("--out", default=os.path.join(HERE, "data"))
    args = ap.parse_args(argv)
    os.makedirs(args.out, exist_ok=True)
    for spec in args.scene or SCENES:
        case = parse_scene(spec, args.data)
        write(spec.split("@")[0], case.scene, case.camera, args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
