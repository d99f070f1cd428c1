"""Runs the Pallas rasterization of one scene once per backend, for Nsight Compute:

    ncu -k regex:'localgs|vanilla' [--set full] python scripts/ncu_localgs.py [DATA]
        [--scene guitar_720p] [--backends pallas,pallas_vanilla] [--kernel auto] [--grad]
        [--gsplat]

DATA: default carry/data; scenes are `benchmarks.common.SCENES` names. Each backend's render is
compiled and run once, so each kernel is launched (and profiled) once. With --grad, the gradient
of Σ image·w (w fixed, random; `benchmarks.scale`'s --grad program) instead of the render; with
--gsplat, then gsplat 1.5.3's forward (+ backward with --grad) once, e.g. both backward kernels:
`ncu -k regex:'localgs_backward|3dgs_bwd' ... --grad --gsplat --backends pallas`.
"""
import argparse
import os
import sys

import jax

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import lgs_jax  # noqa: E402
from benchmarks.common import load_scene  # noqa: E402
from lgs_jax import binning  # noqa: E402
from lgs_jax.projection import project  # noqa: E402

ap = argparse.ArgumentParser(description=__doc__)
ap.add_argument("data", nargs="?", default="carry/data")
ap.add_argument("--scene", default="guitar_720p")
ap.add_argument("--backends", default="pallas,pallas_vanilla")
ap.add_argument("--kernel", default="auto", help="RasterConfig.kernel (\"mosaic\": Local-GS even "
                "where \"auto\" routes a large pair buffer to the vanilla kernel)")
ap.add_argument("--grad", action="store_true")
ap.add_argument("--gsplat", action="store_true")
args = ap.parse_args()
g, cam = load_scene(args.scene, args.data)
g = jax.device_put(g)
p = jax.jit(project)(g, cam)
cap = lgs_jax.pair_capacity(int(binning.count_pairs(p, cam.width, cam.height)))
w = jax.random.normal(jax.random.key(0), (cam.height, cam.width, 3), jax.numpy.float32)
for backend in args.backends.split(","):
    image = lambda g, c, b=backend: lgs_jax.render(
        g, c, backend=b, config=lgs_jax.RasterConfig(kernel=args.kernel), capacity=cap).image
    if args.grad:
        f = jax.jit(jax.grad(lambda g, c, w, image=image: jax.numpy.sum(image(g, c) * w)))
        jax.block_until_ready(f(g, cam, w))
    else:
        jax.block_until_ready(jax.jit(image)(g, cam))
if args.gsplat:
    from benchmarks.scale import gsplat_grad_step, gsplat_peer  # noqa: E402
    if args.grad:
        gsplat_grad_step(g, cam, w)()
    else:
        gsplat_peer(g, cam)
