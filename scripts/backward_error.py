"""Float32 backward-kernel error against the float64 walk, for one test scene (default: the seed
of a GPU tolerance failure of tests/test_pallas.py::test_backward_kernel_equals_the_tiles_walk).

Prints, per (config, kernel), the max error of the float32 kernel and of the float32 plain-jnp
walk (`tiles._gradients`), both against the float64 walk on the same residual schedule, scaled by
max |gradient|: if the kernel's error is of the walk's size, a kernel-vs-walk disagreement is
float32 rounding, not a bug.  Usage: python scripts/backward_error.py [seed ...]
"""
import dataclasses
import sys

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)
sys.path.insert(0, "tests")
import scenes  # noqa: E402
from lgs_jax.config import RasterConfig  # noqa: E402

seeds = [int(s) for s in sys.argv[1:]] or [5038]
print(f"{'seed':>6} {'config':>12} {'kernel':>7} {'kernel-walk':>12} {'kernel-f64':>11} {'walk-f64':>9}")
for seed in seeds:
    for name, cfg in (("fast", RasterConfig(blend="fast")), ("local_gs", RasterConfig())):
        for kernel in ("mosaic", "triton"):
            c = dataclasses.replace(cfg, kernel=kernel)
            got, walk = scenes.backward_kernel_and_walk(seed, c, np.float32)
            _, ref = scenes.backward_kernel_and_walk(seed, c, np.float64)
            scale = max(np.abs(ref).max(), 1.0)
            e = lambda a, b: np.abs(a.astype(np.float64) - b).max() / scale  # noqa: E731
            print(f"{seed:>6} {name:>12} {kernel:>7} {e(got, walk):12.2e} {e(got, ref):11.2e} "
                  f"{e(walk, ref):9.2e}")
