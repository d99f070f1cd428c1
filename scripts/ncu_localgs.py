"""Runs the Pallas rasterization of guitar 1280x720 a few times, for Nsight Compute:

    ncu -k regex:kernel python scripts/ncu_localgs.py [DATA]     (DATA: default carry/data)
"""
import os
import sys

import jax

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import lgs_jax  # noqa: E402
from benchmarks.common import load_scene  # noqa: E402

g, cam = load_scene("guitar_720p", sys.argv[1] if len(sys.argv) > 1 else "carry/data")
g = jax.device_put(g)
for backend in ("pallas", "pallas_vanilla"):
    f = jax.jit(lambda g, c: lgs_jax.render(g, c, backend=backend, capacity=2**19).image)
    for _ in range(3):
        jax.block_until_ready(f(g, cam))
