"""Bytes Gaussian parallelism (lgs_jax.parallel) exchanges per training step and view, and what
NVLink makes of them: counted on the CPU, no GPU needed.

    python -m benchmarks.exchange_bytes [--gaussians 10000000] [--sample 1000000]
        [--devices 2 4 8] [--link-gbs 450]

The scene is `lgs_jax.synthetic.random_scene` of `--gaussians` Gaussians through
`synthetic_camera` at 1080p and 4K, estimated from a sample: `random_scene(sample)` with its
log-scales shifted by ln(gaussians / sample)/3, which is exactly how `random_scene(gaussians)`
draws its sizes, and every count scaled by gaussians / sample.

Per device count D, with the Gaussians in D contiguous blocks of a scene in random order (each
block sends every band about 1/D of that band's records):
  records: Σ over bands of the Gaussians whose tile rectangle reaches the band (a Gaussian
    across k bands counts k times); off-device: the (D − 1)/D of them that leave their device;
  MB fwd / bwd: off-device records x 40 bytes (mean2d, conic, depth, opacity, RGB as float32),
    the forward's records and the backward's cotangents (the same width);
  buffer MB: what the all-to-all of the fixed-size buffers moves per device and direction,
    (D − 1)·capacity·40 bytes, capacity = `render.pair_capacity` of the largest
    (source, destination) count;
  ms @ link: 2 x buffer / link bandwidth (forward and backward, all devices sending at once,
    each at `--link-gbs` GB/s per direction: H100 NVLink 4 is 900 GB/s bidirectional, 450 each
    way; an ideal all-to-all, no latency or protocol overhead);
  pairs x: Σ over devices of the tile pairs each renders (every received Gaussian's whole
    rectangle) over the one-device pairs: the rasterization work duplicated at band edges.
The data-parallel alternative all-reduces every parameter's gradient each step: for SH degree 3
(59 floats a Gaussian) a ring all-reduce moves 2·(D − 1)/D·N·59·4 bytes per device.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np

from lgs_jax import binning, synthetic
from lgs_jax.parallel import exchange
from lgs_jax.projection import project
from lgs_jax.render import pair_capacity

RESOLUTIONS = (("1080p", 1920, 1080), ("4K", 3840, 2160))
RECORD_BYTES = exchange.record_width(3) * 4


def sample_scene(gaussians: int, sample: int, seed: int = 0):
    """`sample` Gaussians drawn as `random_scene(gaussians)` draws its Gaussians."""
    g = synthetic.random_scene(sample, seed)
    shift = np.float32(np.log(gaussians / sample) / 3)
    return dataclasses.replace(g, log_scales=g.log_scales - shift)


@functools.partial(jax.jit, static_argnames=("devices",))
def band_counts(g, cam, devices: tuple):
    """Per device count: (records per band (D,), pairs per band (D,)); and the one-device
    pairs and the Gaussians in view."""
    p = project(g, cam)
    _, _, nx, ny, _ = binning.tile_rects(p, cam.width, cam.height)
    pairs = (nx * ny).astype(jnp.float32)
    out = {}
    for d in devices:
        masks = exchange.band_masks(p, cam.width, cam.height, d)
        out[d] = (jnp.sum(masks, axis=1, dtype=jnp.int32),
                  jnp.sum(jnp.where(masks, pairs[None], 0), axis=1))
    return out, jnp.sum(pairs), jnp.sum(nx * ny > 0, dtype=jnp.int32)


def rows(gaussians: int, sample: int, devices: tuple, link_gbs: float):
    g = sample_scene(gaussians, sample)
    scale = gaussians / sample
    for name, w, h in RESOLUTIONS:
        per_d, pairs_one, visible = band_counts(g, synthetic.synthetic_camera(w, h), devices)
        for d in devices:
            records, pairs = (np.asarray(x, np.float64) * scale for x in per_d[d])
            off = records.sum() * (d - 1) / d
            capacity = pair_capacity(int(np.ceil(records.max() / d)))
            buffer = (d - 1) * capacity * RECORD_BYTES
            allreduce = 2 * (d - 1) / d * gaussians * 59 * 4
            yield dict(res=name, devices=d, visible=float(visible) * scale,
                       records=records.sum(), off=off, fwd_mb=off * RECORD_BYTES / 1e6,
                       buffer_mb=buffer / 1e6, ms=2 * buffer / (link_gbs * 1e9) * 1e3,
                       pairs_x=pairs.sum() / (float(pairs_one) * scale),
                       allreduce_ms=allreduce / (link_gbs * 1e9) * 1e3)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--gaussians", type=int, default=10_000_000)
    ap.add_argument("--sample", type=int, default=1_000_000)
    ap.add_argument("--devices", type=int, nargs="+", default=[2, 4, 8])
    ap.add_argument("--link-gbs", type=float, default=450.0,
                    help="GB/s per device and direction (H100 NVLink 4: 450)")
    args = ap.parse_args(argv)
    print(f"{args.gaussians / 1e6:g}M Gaussians (random_scene, estimated from "
          f"{args.sample / 1e6:g}M), records of {RECORD_BYTES} B, link {args.link_gbs:g} GB/s "
          "per direction\n")
    print("| view | D | in view (M) | records (M) | off-device (M) | MB fwd = MB bwd (all "
          "devices) | buffer MB per device and direction | ms @ link (fwd + bwd) | pairs x "
          "| data-parallel all-reduce ms (SH 3) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for r in rows(args.gaussians, args.sample, tuple(args.devices), args.link_gbs):
        print(f"| {r['res']} | {r['devices']} | {r['visible'] / 1e6:.2f} | "
              f"{r['records'] / 1e6:.2f} | {r['off'] / 1e6:.2f} | {r['fwd_mb']:.0f} | "
              f"{r['buffer_mb']:.0f} | {r['ms']:.2f} | {r['pairs_x']:.3f} | "
              f"{r['allreduce_ms']:.1f} |")


if __name__ == "__main__":
    main()
