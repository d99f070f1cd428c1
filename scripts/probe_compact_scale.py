"""Probe: are the compacted forward's gradients repeatable at scale, and which block sizes matter?

On guitar x110 at 4K (`benchmarks.scale`'s scene) the gradient with `mosaic_compact` (half-tile
forward blocks, whole-tile backward blocks there) was reported "NOT BITWISE" (jnp.array_equal,
which also fails on NaN), with half-tile backward blocks it was repeatable. Per configuration:
three gradients of sum(image · w), whether their bytes agree, NaN counts, the largest difference
between runs, and the largest difference from the default configuration's gradient (relative to
its largest magnitude).

    python scripts/probe_compact_scale.py --data carry/data --scene guitar_x110_4k
"""

from __future__ import annotations

import argparse
import sys

import jax
import jax.numpy as jnp
import numpy as np

sys.path.insert(0, ".")
import lgs_jax  # noqa: E402
from benchmarks.common import load_scene  # noqa: E402
from benchmarks.scale import count_pairs  # noqa: E402

K, C = lgs_jax.KernelConfig, lgs_jax.RasterConfig
CONFIGS = {
    "default": K(vanilla_from_pairs=None),
    "compact fwd128 bwd256": K(mosaic_compact=True, vanilla_from_pairs=None,
                               mosaic_backward_pixels=256),
    "compact fwd128 bwd128": K(mosaic_compact=True, vanilla_from_pairs=None,
                               mosaic_backward_pixels=128),
    "full fwd128 bwd256": K(mosaic_forward_pixels=128, mosaic_backward_pixels=256,
                            vanilla_from_pairs=None),
    "full fwd128 bwd128": K(mosaic_forward_pixels=128, mosaic_backward_pixels=128,
                            vanilla_from_pairs=None),
}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", default="carry/data")
    ap.add_argument("--scene", default="guitar_x110_4k")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--configs", default=",".join(CONFIGS))
    args = ap.parse_args()
    g, cam = load_scene(args.scene, args.data)
    cap = lgs_jax.pair_capacity(count_pairs(g, cam))
    w = jax.random.normal(jax.random.key(0), (cam.height, cam.width, 3), jnp.float32)
    base = None
    for name in args.configs.split(","):
        config = C("gsplat", tuning=CONFIGS[name])

        def loss(g, w, config=config):
            return jnp.sum(lgs_jax.render(g, cam, backend="pallas", config=config,
                                          capacity=cap).image * w)

        f = jax.jit(jax.grad(loss))
        runs = [[np.asarray(x) for x in jax.tree.leaves(f(g, w))] for _ in range(args.repeats)]
        same = all(a.tobytes() == b.tobytes() for r in runs[1:] for a, b in zip(runs[0], r))
        nans = sum(int(np.isnan(a).sum()) for a in runs[0])
        spread = max(float(np.nanmax(np.abs(a - b))) for r in runs[1:]
                     for a, b in zip(runs[0], r))
        if base is None:
            base = runs[0]
        rel = max(float(np.nanmax(np.abs(a - b)) / max(np.nanmax(np.abs(b)), 1e-30))
                  for a, b in zip(runs[0], base))
        print(f"{args.scene} {name:24s} bytes repeatable {same}, NaN {nans}, spread {spread:.3g},"
              f" max rel. diff from default {rel:.3g}", flush=True)


if __name__ == "__main__":
    main()
