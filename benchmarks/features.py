"""What rendering per-Gaussian features of C channels costs against the SH colour's render.

    python -m benchmarks.features [--scene SPEC ...] [--channels 1,3,8,16,32] [--backend B]
        [--repeat N] [--data DIR] [--no-grad]

For each scene (SPECs: benchmarks.common) and C, `render(..., colors=F)` with F of shape (N, C)
is timed forward (the image) and forward + backward (the gradient of a weighted sum of the
image w.r.t. every Gaussian field and F), every row in turn within each round
(`common.median_ms`); the `sh` row is the plain render (SH colour, three channels). C channels
take ceil(C/3) passes of the rasterizer over the same pairs (`render`'s docstring), so the
time should grow with the passes, not with the projection or the binning.
"""

from __future__ import annotations

import argparse
import math

import jax
import jax.numpy as jnp
import numpy as np

import lgs_jax

from .common import add_data_argument, device_line, median_ms, parse_scene


def _rows(g, cam, channels, backend: str, cap: int, grad: bool):
    """{row name: blocking callable} of the SH render and one features render per C."""
    rng = np.random.default_rng(0)
    rows = {}
    for c in [None] + list(channels):
        f = None if c is None else jnp.asarray(rng.uniform(0, 1, (g.num, c)), g.dtype)
        w = jnp.asarray(rng.normal(size=(cam.height, cam.width, 3 if c is None else c)),
                        g.dtype)
        image = lambda g, f, w: lgs_jax.render(g, cam, backend=backend, capacity=cap,
                                               colors=f).image
        loss = lambda g, f, w: jnp.sum(image(g, f, w) * w)
        fn = jax.jit(jax.grad(loss, argnums=(0, 1)) if grad else image)
        rows["sh" if c is None else f"C={c}"] = (
            lambda fn=fn, f=f, w=w: jax.block_until_ready(fn(g, f, w)))
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", action="append", help="scene spec (repeatable)")
    ap.add_argument("--channels", default="1,3,8,16,32")
    ap.add_argument("--backend", default=None, help="default: lgs_jax.default_backend()")
    ap.add_argument("--repeat", type=int, default=10)
    ap.add_argument("--no-grad", action="store_true", help="time the forward only")
    add_data_argument(ap)
    args = ap.parse_args(argv)
    channels = [int(c) for c in args.channels.split(",")]
    backend = args.backend or lgs_jax.default_backend()
    print(device_line(), f"backend {backend}")
    print(f"{'scene':<24} {'row':>6} {'passes':>6} {'fwd ms':>8} "
          f"{'' if args.no_grad else 'fwd+bwd ms':>10} {'/ sh':>6}")
    for spec in args.scene or ["guitar@1280x720"]:
        case = parse_scene(spec, args.data)
        g, cam = jax.device_put(case.scene), jax.device_put(case.camera)  # no host copies
        cap = int(lgs_jax.render(g, cam, backend=backend).stats.capacity)
        fwd = median_ms(_rows(g, cam, channels, backend, cap, False), args.repeat)
        both = ({} if args.no_grad else
                median_ms(_rows(g, cam, channels, backend, cap, True), args.repeat))
        key = "fwd+bwd" if both else "fwd"
        base = (both or fwd)["sh"]
        for name, ms in fwd.items():
            passes = 1 if name == "sh" else math.ceil(int(name[2:]) / 3)
            ms2 = f"{both[name]:10.2f}" if both else ""
            print(f"{case.name:<24} {name:>6} {passes:>6} {ms:8.2f} {ms2:>10} "
                  f"{(both or fwd)[name] / base:6.2f}", flush=True)
        print(f"({key} / sh's)")


if __name__ == "__main__":
    main()
