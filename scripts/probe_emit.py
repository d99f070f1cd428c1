"""Probe: the emission with its slots filled by the Pallas Triton kernel
(`KernelConfig.emit_kernel`, lgs_jax.backends.pallas_emit) against XLA's
(`binning.expand_slots`) on `benchmarks.scale` scenes: whether every array agrees, and the
median time of each emission (alternating rounds).

    python scripts/probe_emit.py --data carry/data --scenes guitar_x64_1080p,guitar_x110_4k
"""

from __future__ import annotations

import argparse
import functools
import sys

import jax
import numpy as np

sys.path.insert(0, ".")
import lgs_jax  # noqa: E402
from benchmarks.common import load_scene, median_ms  # noqa: E402
from benchmarks.scale import count_pairs  # noqa: E402
from lgs_jax import binning  # noqa: E402
from lgs_jax.backends import pallas_emit  # noqa: E402
from lgs_jax.projection import project  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", default="carry/data")
    ap.add_argument("--scenes", default="guitar_x64_1080p,guitar_x110_4k")
    ap.add_argument("--repeat", type=int, default=10)
    args = ap.parse_args()
    kernel = functools.partial(pallas_emit.expand, interpret=jax.default_backend() != "gpu")
    for scene in args.scenes.split(","):
        g, cam = load_scene(scene, args.data)
        cap = lgs_jax.pair_capacity(count_pairs(g, cam))
        p = jax.jit(project)(g, cam)
        fns = {name: jax.jit(lambda p, e=e: binning.emit_pairs(p, cam.width, cam.height, cap, e))
               for name, e in (("xla", binning.expand_slots), ("kernel", kernel))}
        out = {name: f(p) for name, f in fns.items()}
        same = all(np.array_equal(a, b) for a, b in zip(jax.tree.leaves(out["xla"]),
                                                        jax.tree.leaves(out["kernel"])))
        times = median_ms({name: (lambda f=f: jax.block_until_ready(f(p)))
                           for name, f in fns.items()}, args.repeat)
        print(f"{scene}: {g.num} Gaussians, {int(out['xla'].total)} pairs, capacity {cap}: "
              f"arrays equal {same}; emission ms xla {times['xla']:.3f}, kernel "
              f"{times['kernel']:.3f}", flush=True)


if __name__ == "__main__":
    main()
