"""How much of a frame's rasterization is one tile's serial walk (GPU experiment):

    python scripts/tile_walks.py [--data DIR] [--scenes guitar_x16_1080p,guitar_x64_1080p,...]

Per scene: the tile lists' lengths (percentiles), the pairs each block walks before all its
pixels stopped (`RasterResult.stop`: the forward's own stop pairs; blocks are half tiles below
`mosaic_whole_tile_from` tiles, whole tiles above), and a schedule model of the forward kernel:
blocks taken longest list first (`pallas._longest_first`) onto R resident blocks (132 SMs x 5,
ncu's occupancy of the Local-GS kernel), each costing its walked pairs. Printed: the model's
makespan over the ideal (all walked pairs / R) and the longest single block over the ideal, a
lower bound of the makespan whatever the order; then, per `--split` length, the bounds of
`split_model` (long lists split across blocks) relative to that makespan, and with `--local` the
same with each segment's first pass run (`split_model_local`); with `--compact` the walks of
half-tile blocks that skip the pairs none of their strips takes (`compact_walks`,
`KernelConfig.mosaic_compact`, the default since Dec 2) against the full walk's blocks'. The
`tiles` backend on a CPU (same stops). Also printed: the pairs some block of their tile walked
(`render`'s `stats.pairs_walked`) and the backward's row buffers (48 bytes per row and block, 44
for an image loss) for them and for every pair.
"""
import argparse
import dataclasses
import heapq
import os
import sys

import jax
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import lgs_jax  # noqa: E402
from benchmarks.common import add_data_argument, load_scene  # noqa: E402
from lgs_jax import binning, pairs  # noqa: E402
from lgs_jax.backends import REGISTRY, pallas  # noqa: E402
from lgs_jax.projection import project  # noqa: E402

RESIDENT = 132 * 5


def _binned(g, cam):
    """(projected, binned at `pair_capacity` of the view's pairs, the Local-GS config walking
    every pair (compaction off: the blocks the model starts from; the stops are the same) and
    returning each pixel's stop pair (`mosaic_block_stops` off), the backend whose stops are the
    walks: the Mosaic GPU kernel on a GPU, `tiles` elsewhere)."""
    w, h = cam.width, cam.height
    p = jax.jit(project)(g, cam)
    cap = lgs_jax.pair_capacity(int(binning.count_pairs(p, w, h)))
    bins = jax.jit(lambda p: binning.bin_gaussians(p, w, h, cap))(p)
    config = lgs_jax.RasterConfig(tuning=lgs_jax.KernelConfig(
        vanilla_from_pairs=None, mosaic_compact=False, mosaic_block_stops=False))  # pixels
    backend = pallas.LOCALGS if jax.default_backend() == "gpu" else REGISTRY["tiles"]
    return p, bins, config, backend


def walks(g, cam, local: list[int] = ()):
    """(list lengths, pairs each block walks, blocks per tile, {L: local walks}): with `local`
    segment lengths L, for each, the pairs each block of a tile whose list is longer than L
    walks in each segment [start + m·L, start + (m + 1)·L) of it when it starts from T = 1 (a
    split forward's first pass: the same stop rule on the segment alone), (n_tiles, blocks,
    segments); tiles within one segment get zeros."""
    w, h = cam.width, cam.height
    p, bins, config, backend = _binned(g, cam)
    gpu = jax.default_backend() == "gpu"
    n_tiles = bins.tile_start.shape[0]
    stops = jax.jit(lambda p, b: backend.rasterize(p, b, w, h, config).stop)
    pixels = pallas.plan(config, False, n_tiles).forward_pixels if gpu else 128

    def block_walks(b):
        walked = np.asarray(stops(p, b)) - np.asarray(b.tile_start)[:, None]
        return walked.reshape(n_tiles, 256 // pixels, pixels).max(-1)

    start, end = np.asarray(bins.tile_start), np.asarray(bins.tile_end)
    segments = {}
    for seg in local:
        split = end - start > seg
        per_segment = []
        for m in range(int(np.max((end - start + seg - 1) // seg))):
            lo = np.where(split, np.minimum(start + m * seg, end), start)
            hi = np.where(split, np.minimum(lo + seg, end), start)
            per_segment.append(block_walks(dataclasses.replace(
                bins, tile_start=jax.numpy.asarray(lo, np.int32),
                tile_end=jax.numpy.asarray(hi, np.int32))))
        segments[seg] = np.stack(per_segment, -1)
    return end - start, block_walks(bins), 256 // pixels, segments


def compact_walks(g, cam):
    """(pairs each block of the full walk's size walks, (n_tiles, blocks); pairs each half-tile
    block walks, and of those the ones whose strip mask has a bit in the block's strips: what a
    block of `KernelConfig.mosaic_compact` walks, (n_tiles, 2) each). The stops are the
    `tiles` backend's (a CPU) or the Local-GS kernel's."""
    w, h = cam.width, cam.height
    p, bins, config, backend = _binned(g, cam)
    stop = np.asarray(jax.jit(lambda p, b: backend.rasterize(p, b, w, h, config).stop)(p, bins))
    tiles_x = (w + 15) // 16
    masks = np.asarray(jax.jit(lambda p, b: pairs.strip_masks(
        pairs.gather(p, b.gauss), b, tiles_x, config))(p, bins))
    start, end = np.asarray(bins.tile_start), np.asarray(bins.tile_end)
    last = np.minimum(stop.reshape(len(start), 2, 128).max(-1), end[:, None])
    walked = np.maximum(last - start[:, None], 0)
    relevant = np.zeros_like(walked)
    for t in np.nonzero(walked.max(1))[0]:
        for b, bits in enumerate((0x0F, 0xF0)):
            relevant[t, b] = np.count_nonzero(masks[start[t]:last[t, b]] & bits)
    pixels = pallas.block_pixels(None, len(start), config)
    full = np.minimum(stop.reshape(len(start), 256 // pixels, pixels).max(-1),
                         end[:, None]) - start[:, None]
    return np.maximum(full, 0), walked, relevant


def schedule(lengths, walked, per_tile):
    order = np.argsort(-lengths, kind="stable")
    heap = [0] * RESIDENT
    for t in order:
        for c in walked[t]:
            heapq.heapreplace(heap, heap[0] + int(c))
    return max(heap)


def makespan(costs) -> int:
    """Longest-first greedy schedule of `costs` onto RESIDENT blocks."""
    heap = [0] * RESIDENT
    for c in sorted(costs, reverse=True):
        heapq.heapreplace(heap, heap[0] + int(c))
    return max(heap)


def split_model(lengths, walked, seg: int) -> tuple[int, int]:
    """(low, high) makespan with lists longer than `seg` split into segments of `seg` pairs,
    two passes (BENCHMARKS.md §7 "Dec 2"): pass 1 walks each segment from T = 1 (whole segments
    before the block's stop; the stop's segment and those after cost between 0 and their
    length: the two bounds), then pass 2 walks each segment up to the stop from its entering T.
    Lists within one segment run pass 2 only, as now."""
    pass1_lo, pass1_hi, pass2 = [], [], []
    for n, ws in zip(lengths, walked):
        for w in ws:
            if n <= seg:
                pass2.append(w)
                continue
            for s0 in range(0, n, seg):
                size = min(seg, n - s0)
                before = s0 + size <= w
                pass1_lo.append(size if before else 0)
                pass1_hi.append(size)
                pass2.append(min(size, max(w - s0, 0)))
    p2 = makespan(pass2)
    return makespan(pass1_lo) + p2, makespan(pass1_hi) + p2


def split_model_local(lengths, walked, local, seg: int) -> int:
    """`split_model`'s makespan with pass 1 costing each segment's own walk from T = 1
    (`walks`' local walks: a block stops where its pixels' product of 1 − α within the segment
    alone falls to the threshold) instead of its bounds."""
    pass1, pass2 = [], []
    for n, ws, loc in zip(lengths, walked, local):
        for w, lw in zip(ws, loc):
            if n <= seg:
                pass2.append(w)
                continue
            for m, s0 in enumerate(range(0, n, seg)):
                pass1.append(lw[m])
                pass2.append(min(seg, n - s0, max(w - s0, 0)))
    return makespan(pass1) + makespan(pass2)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    add_data_argument(ap)
    ap.add_argument("--scenes", default="guitar_x16_1080p,guitar_x64_1080p,guitar_x110_4k")
    ap.add_argument("--split", type=int, nargs="*", default=[1024, 2048, 4096],
                    help="segment lengths to model (split_model)")
    ap.add_argument("--local", action="store_true",
                    help="also run each segment's first pass (one render per segment index; "
                         "slow on a CPU) for split_model_local")
    ap.add_argument("--compact", action="store_true",
                    help="also model `KernelConfig.mosaic_compact` (compact_walks)")
    args = ap.parse_args()
    print(f"device {jax.devices()[0].device_kind}; JAX {jax.__version__}", flush=True)
    for scene in args.scenes.split(","):
        g, cam = load_scene(scene, args.data)
        if args.compact:
            now, half, kept = compact_walks(jax.device_put(g), cam)
            print(f"{scene} compacted: half-tile blocks walk {kept.sum() / 1e6:.2f}M of "
                  f"{half.sum() / 1e6:.2f}M block-pairs, longest {kept.max()} of {half.max()}; "
                  f"makespan {makespan(kept.ravel()) / makespan(now.ravel()):.2f} of the "
                  f"full walk's blocks ({now.shape[1]} per tile)", flush=True)
        lengths, walked, per_tile, local = walks(jax.device_put(g), cam,
                                                 args.split if args.local else ())
        ideal = walked.sum() / RESIDENT
        q = np.percentile(lengths, [50, 90, 99, 100])
        print(f"{scene}: {lengths.sum() / 1e6:.2f}M pairs in {lengths.size} tiles (list "
              f"p50/p90/p99/max {q[0]:.0f}/{q[1]:.0f}/{q[2]:.0f}/{q[3]:.0f}); {per_tile} "
              f"block(s) per tile walk {walked.sum() / 1e6:.2f}M block-pairs "
              f"({walked.sum() / (per_tile * lengths.sum()):.1%} of their lists), longest "
              f"{walked.max()}; longest-first makespan / ideal "
              f"{schedule(lengths, walked, per_tile) / ideal:.2f}, longest block / ideal "
              f"{walked.max() / ideal:.2f}", flush=True)
        union = int(walked.max(1).sum())  # = render's stats.pairs_walked
        print(f"  pairs walked by some block of their tile {union / 1e6:.2f}M "
              f"({union / lengths.sum():.1%}): the backward's rows with a row_capacity, "
              f"{per_tile} x {union * 48 / 2**20:.0f} MiB against {per_tile} x "
              f"{lengths.sum() * 48 / 2**20:.0f} MiB at the pairs", flush=True)
        now = schedule(lengths, walked, per_tile)
        for seg in args.split:
            lo, hi = split_model(lengths, walked, seg)
            exact = (f", {split_model_local(lengths, walked, local[seg], seg) / now:.2f} with "
                     f"the first pass's own walks" if seg in local else "")
            print(f"  lists split every {seg} pairs: makespan {lo / now:.2f}–{hi / now:.2f} "
                  f"of now{exact}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
