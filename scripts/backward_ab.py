"""Rasterization forward+backward (projection and binning done once, outside the timing) of the
Pallas kernels, Triton vs Mosaic GPU at each block size (mosaic.BLOCK_PIXELS: pixels per
warpgroup block of the forward and of the backward kernel), alternating in one process on the GPU:

    PYTHONPATH=$PWD python3 scripts/backward_ab.py   # scenes in carry/data

Prints the median of 30 rounds per row and each row's largest gradient difference from the
Triton row, relative to each gradient leaf's largest magnitude.
"""
import dataclasses
import statistics
import time

import jax
import jax.numpy as jnp

from lgs_jax import bench, binning, render
from lgs_jax.backends import mosaic, pallas
from lgs_jax.config import RasterConfig as C
from lgs_jax.projection import project

D = "carry/data"
SCENES = [f"guitar={D}/guitar/guitar.ply:{D}/guitar/orbit_cameras.json@1280x720",
          f"lego_sh3={D}/lego_sh3/lego_sh3.ply:{D}/lego_sh3/lego_cameras.json@800x800",
          f"guitar4k={D}/guitar/guitar.ply:{D}/guitar/orbit_cameras.json@3840x2160",
          "synthetic:1000000@1280x720"]
# row -> (vanilla, kernel, mosaic.BLOCK_PIXELS for the forward and the backward)
ROWS = {"localgs-triton": (False, "triton", None),
        "localgs-mosaic f128 b128": (False, "mosaic", (128, 128)),
        "localgs-mosaic f256 b128": (False, "mosaic", (256, 128)),
        "localgs-mosaic f256 b256": (False, "mosaic", (256, 256)),
        "vanilla-triton": (True, "triton", None),
        "vanilla-mosaic f256 b128": (True, "mosaic", (256, 128)),
        "vanilla-mosaic f256 b256": (True, "mosaic", (256, 256))}


def main():
    for spec in SCENES:
        case = bench.parse_scene(spec)
        g, cam = jax.device_put(case.scene), jax.device_put(case.camera)
        cap = int(render(g, cam).stats.capacity)
        p = jax.jit(project)(g, cam)
        bins = jax.jit(lambda p: binning.bin_gaussians(p, cam.width, cam.height, cap))(p)
        weights = jax.random.normal(jax.random.key(0), (cam.height * cam.width, 3))
        x = (p.mean2d, p.conic, p.opacity, p.rgb, p.depth)
        fns, grads = {}, {}
        default = dict(mosaic.BLOCK_PIXELS)
        for name, (vanilla, kernel, pixels) in ROWS.items():
            def loss(x, vanilla=vanilla, config=C(kernel=kernel)):
                q = dataclasses.replace(p, mean2d=x[0], conic=x[1], opacity=x[2], rgb=x[3],
                                        depth=x[4])
                color = pallas.rasterize(q, bins, cam.width, cam.height, config, vanilla)[0].color
                return jnp.sum(color.reshape(-1, 3) * weights)
            if pixels:
                mosaic.BLOCK_PIXELS.update(forward=pixels[0], backward=pixels[1])
            jax.clear_caches()  # compile this row with these block sizes (traces are cached)
            f = jax.jit(jax.value_and_grad(loss)).lower(x).compile()
            mosaic.BLOCK_PIXELS.update(default)
            grads[name] = jax.block_until_ready(f(x))[1]
            fns[name] = f
        times = {k: [] for k in fns}
        for _ in range(30):
            for k, f in fns.items():
                t0 = time.perf_counter()
                jax.block_until_ready(f(x))
                times[k].append(time.perf_counter() - t0)
        for k in fns:
            ref = grads[k.split("-")[0] + "-triton"]
            diff = max(float(jnp.max(jnp.abs(a - b)) / (jnp.max(jnp.abs(b)) + 1e-30))
                       for a, b in zip(grads[k], ref))
            print(f"{case.name:18s} {k:26s} fwd+bwd {1e3 * statistics.median(times[k]):7.3f} ms"
                  f"   grad vs Triton {diff:.1e}", flush=True)


if __name__ == "__main__":
    main()
