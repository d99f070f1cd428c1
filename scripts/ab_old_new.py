"""Old against new code, same process, alternating rounds: the Pallas kernels' time before and
after a restructuring (issue 14's "each kernel's time ratio within 0.95–1.05").

    cp -r $(git worktree of the old commit)/lgs_jax carry/lgs_jax_old   # the old package, renamed
    XLA_PYTHON_CLIENT_PREALLOCATE=false python scripts/ab_old_new.py [--data DIR] [--repeat 30]

Per scene, each row runs the rasterization stage alone (`rasterize` from projected and binned
inputs, each package's own projection and binning) forward, or forward + backward (the
gradient of Σ colour·w with respect to the projected Gaussians), with the old and the new
package; all rows of a scene alternate within each round (benchmarks.common.median_ms). Prints new/old
median time ratios.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys

import jax
import jax.numpy as jnp
import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path[:0] = [ROOT, os.path.join(ROOT, "carry")]
from benchmarks.common import median_ms  # noqa: E402
ROWS = {  # name -> (backend, RasterConfig kwargs, differentiate)
    "localgs fwd": ("pallas", {}, False),
    "localgs-triton fwd": ("pallas", dict(kernel="triton"), False),
    "vanilla fwd": ("pallas_vanilla", {}, False),
    "vanilla-triton fwd": ("pallas_vanilla", dict(kernel="triton"), False),
    "localgs fwd+bwd": ("pallas", {}, True),
    "localgs-triton fwd+bwd": ("pallas", dict(kernel="triton"), True),
}


def _stage(pkg, backend: str, kwargs: dict, grad: bool, g, cam, weights):
    """A jitted function of the projected Gaussians: the rasterization stage of `pkg`, both
    packages at the current package's pair capacity (`lgs_jax.pair_capacity`), so the rows
    differ only in the code compared."""
    cap = int(importlib.import_module("lgs_jax").render(g, cam).stats.capacity)
    binning = importlib.import_module(f"{pkg}.binning")
    projection = importlib.import_module(f"{pkg}.projection")
    config = importlib.import_module(f"{pkg}.config").RasterConfig(**kwargs)
    lib = importlib.import_module(pkg)
    g = lib.Gaussians(g.means, g.quats, g.log_scales, g.logit_opacities, g.sh)  # pkg's classes
    cam = lib.Camera(viewmat=cam.viewmat, fx=cam.fx, fy=cam.fy, cx=cam.cx, cy=cam.cy,
                     width=cam.width, height=cam.height, near=cam.near, far=cam.far)
    w, h = cam.width, cam.height
    p = jax.jit(projection.project)(g, cam)
    bins = jax.jit(lambda p: binning.bin_gaussians(p, w, h, cap))(p)
    if pkg.endswith("_old"):
        pallas = importlib.import_module(f"{pkg}.backends.pallas")
        color = lambda q: pallas.rasterize(q, bins, w, h, config,
                                           vanilla=backend == "pallas_vanilla")[0].color
    else:
        registry = importlib.import_module(f"{pkg}.backends").REGISTRY
        tiles_to_image = importlib.import_module(f"{pkg}.layout").tiles_to_image
        color = lambda q: tiles_to_image(registry[backend].rasterize(q, bins, w, h, config).color,
                                         w, h)
    x = (p.mean2d, p.conic, p.opacity, p.rgb, p.depth)

    def loss(x):
        q = type(p)(mean2d=x[0], cov2d=p.cov2d, conic=x[1], opacity=x[2], rgb=x[3], depth=x[4],
                    valid=p.valid, invalid=p.invalid)
        return jnp.sum(color(q) * weights)

    f = jax.jit(jax.value_and_grad(loss) if grad else loss).lower(x).compile()
    return lambda: jax.block_until_ready(f(x)), f(x)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", default=os.path.join(ROOT, "carry", "data"))
    ap.add_argument("--repeat", type=int, default=30)
    args = ap.parse_args()
    import lgs_jax
    from lgs_jax.synthetic import random_scene, synthetic_camera

    d = args.data
    guitar = lgs_jax.load_ply(f"{d}/guitar/guitar.ply")
    cams = lambda path, w, h: lgs_jax.load_cameras(path, width=w, height=h)[0]
    scenes = {"guitar 1280x720": (guitar, cams(f"{d}/guitar/orbit_cameras.json", 1280, 720)),
              "synthetic 1M 1280x720": (random_scene(1_000_000), synthetic_camera(1280, 720))}
    print(f"device {jax.devices()[0].device_kind}; JAX {jax.__version__}", flush=True)
    for scene, (g, cam) in scenes.items():
        g, cam = jax.device_put(g), jax.device_put(cam)
        weights = jax.random.normal(jax.random.key(0), (cam.height * cam.width, 3))
        fns, outs = {}, {}
        for row, (backend, kwargs, grad) in ROWS.items():
            for pkg in ("lgs_jax_old", "lgs_jax"):
                fns[row, pkg], outs[row, pkg] = _stage(pkg, backend, kwargs, grad, g, cam,
                                                       weights)
        times = median_ms(fns, args.repeat, warmup=False)  # _stage ran each once
        for row in ROWS:
            old, new = (times[row, p] for p in ("lgs_jax_old", "lgs_jax"))
            same = all(np.array_equal(np.asarray(a), np.asarray(b)) for a, b in zip(
                jax.tree.leaves(outs[row, "lgs_jax_old"]), jax.tree.leaves(outs[row, "lgs_jax"])))
            print(f"{scene:>22s} {row:<24s} old {old:8.3f} ms new {new:8.3f} ms "
                  f"ratio {new / old:5.3f} {'bit-identical' if same else 'DIFFERENT'}",
                  flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
