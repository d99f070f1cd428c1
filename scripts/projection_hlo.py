"""The kernels XLA compiles the projection into on this device (fusions, sorts, gathers, custom
calls of the entry computation, one line each): how many passes `lgs_jax.projection.project`
makes over the Gaussians and which inputs each reads (BENCHMARKS.md §7, Dec 1).

    python scripts/projection_hlo.py [--data DIR] [--scene guitar_x16_1080p] [--vjp]

--vjp lists the kernels of the projection's backward instead (its vjp applied to cotangents of
every floating output, as the rasterizer's backward does).
"""

from __future__ import annotations

import argparse
import os
import re
import sys

import jax
import jax.numpy as jnp
import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from benchmarks.common import add_data_argument, load_scene  # noqa: E402
from lgs_jax.projection import project  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    add_data_argument(ap)
    ap.add_argument("--scene", default="guitar_x16_1080p")
    ap.add_argument("--vjp", action="store_true", help="the backward's kernels")
    args = ap.parse_args()
    g, cam = load_scene(args.scene, args.data)
    g, cam = jax.device_put(g), jax.device_put(cam)
    if args.vjp:
        def backward(g, cam, cotangents):
            return jax.vjp(lambda g: project(g, cam), g)[1](cotangents)

        p = jax.eval_shape(project, g, cam)
        cot = jax.tree.map(lambda x: jnp.ones(x.shape, x.dtype)
                           if jnp.issubdtype(x.dtype, jnp.floating) else None, p)
        cot = jax.tree.map(lambda x, c: c if c is not None else
                           np.zeros(x.shape, jax.dtypes.float0), p, cot)
        compiled = jax.jit(backward).lower(g, cam, cot).compile()
    else:
        compiled = jax.jit(project).lower(g, cam).compile()
    text = compiled.as_text()
    kernels = 0
    for line in text[text.index("ENTRY"):].splitlines():
        if re.search(r"= .*(fusion|custom-call|sort|scatter|gather|reduce)\(", line):
            print(line.strip()[:260])
            kernels += 1
    print(f"{kernels} kernels")
    return 0


if __name__ == "__main__":
    sys.exit(main())
