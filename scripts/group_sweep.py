"""Sweep the tiles backend's strip-group size on the current device (same run, same scenes).

    python scripts/group_sweep.py GROUP [GROUP ...]
"""
import statistics
import sys
import time

import jax

import lgs_jax
from lgs_jax.backends import tiles
from lgs_jax.synthetic import random_scene, synthetic_camera

D = "carry/data/"
cases = {
    "guitar": (lgs_jax.load_ply(D + "guitar/guitar.ply"),
               lgs_jax.load_cameras(D + "guitar/orbit_cameras.json", width=1280, height=720)[0]),
    "lego800": (lgs_jax.load_ply(D + "lego_sh3/lego_sh3.ply"),
                lgs_jax.load_cameras(D + "lego_sh3/lego_cameras.json")[0]),
    "syn1M": (random_scene(1_000_000), synthetic_camera(1280, 720)),
}


def med(f, *a, n=15):
    jax.block_until_ready(f(*a))
    ts = []
    for _ in range(n):
        t = time.perf_counter()
        jax.block_until_ready(f(*a))
        ts.append(time.perf_counter() - t)
    return 1e3 * statistics.median(ts)


for name, (g, cam) in cases.items():
    cap = int(lgs_jax.render(g, cam).stats.capacity)
    ref = med(jax.jit(lambda g, c: lgs_jax.render(g, c, capacity=cap).image), g, cam)
    row = [f"{name:8s} reference {ref:7.1f} ms"]
    for group in map(int, sys.argv[1:]):
        tiles.GROUP = group
        f = jax.jit(lambda g, c: lgs_jax.render(g, c, backend="tiles", capacity=cap).image)
        row.append(f"G{group}: {med(f, g, cam):7.1f}")
    print(" | ".join(row), flush=True)
