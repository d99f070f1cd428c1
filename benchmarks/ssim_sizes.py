"""The training loss's SSIM and its gradient by image size: the fused kernels with their row
block (`ssim_kernel.block_rows`), the same kernels in 32-row blocks, and XLA's (`losses.xla_ssim`).

Each row: a batch of views (the fast recipe's two by default) of one size, value and both
images' gradients under jit and vmap, the median of --repeat rounds (`common.median_ms`, the
three in turn). Sizes: the fast recipe's coarse levels of lego_train (50, 100, 200 pixels
square), skull's and fox's full images. On a CPU the kernels run in interpret mode: only a
GPU's times mean anything.

    python -m benchmarks.ssim_sizes [--sizes 200x200 533x951] [--views 2] [--repeat 50]
"""

from __future__ import annotations

import argparse
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if __package__ in (None, ""):  # run as a file: make `benchmarks` importable
    sys.path.insert(0, ROOT)

SIZES = ("50x50", "100x100", "200x200", "533x951", "708x1063")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", nargs="+", default=list(SIZES), help="HxW")
    ap.add_argument("--views", type=int, default=2)
    ap.add_argument("--repeat", type=int, default=50)
    args = ap.parse_args(argv)

    import jax
    import jax.numpy as jnp
    import numpy as np

    from benchmarks.common import device_line, median_ms
    from lgs_jax.train import losses, ssim_kernel

    print(device_line(), flush=True)
    interpret = jax.default_backend() != "gpu"
    window = tuple(losses.gaussian_window())

    def kernel(rows):
        return lambda a, b: ssim_kernel.ssim(a, b, window, 1.0, "same", interpret, rows)

    print(f"{'size':>9} {'rows':>4} {'fused ms':>9} {'fused, 32 rows':>14} {'XLA ms':>7}")
    for size in args.sizes:
        h, w = (int(x) for x in size.split("x"))
        rng = np.random.default_rng(0)
        a = jnp.asarray(rng.uniform(0, 1, (args.views, h, w, 3)), jnp.float32)
        b = jnp.asarray(np.clip(np.asarray(a) + rng.normal(0, 0.1, a.shape), 0, 1), jnp.float32)
        fns = {}
        for name, f in (("fused", kernel(None)), ("fused32", kernel(32)),
                        ("xla", lambda x, y: losses.xla_ssim(x, y, 1.0, "same"))):
            g = jax.jit(jax.vmap(jax.value_and_grad(f, (0, 1))))
            fns[name] = lambda g=g: jax.block_until_ready(g(a, b))
        ms = median_ms(fns, args.repeat)
        print(f"{size:>9} {ssim_kernel.block_rows(h, 3 * w):>4} {ms['fused']:9.3f} "
              f"{ms['fused32']:14.3f} {ms['xla']:7.3f}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
