"""Seconds to trace and lower the `pallas` gradient for the GPU (Python work, under the
interpreter's lock), per pair capacity, on any machine (nothing is compiled or run):

    python scripts/lower_time.py [--gaussians 262774] [--size 1063x708] [--profile] CAP...

Each pair capacity is a new program for `fit` (a recompile at every growth, BENCHMARKS.md §7),
and its lowering is the part of a compile that holds Python's lock (what slows the training
loop while `train.ahead` compiles the next capacity in a thread). --profile: cProfile of the last
capacity's lowering, top 25 by cumulative time.
"""

import argparse
import cProfile
import pstats
import time

import jax
import jax.numpy as jnp
from jax._src.pallas.triton import gpu_info

import lgs_jax
from lgs_jax.synthetic import random_scene, synthetic_camera


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("capacities", nargs="+", type=int)
    ap.add_argument("--gaussians", type=int, default=262_774)  # skull at 7k steps
    ap.add_argument("--size", default="1063x708")
    ap.add_argument("--profile", action="store_true")
    args = ap.parse_args(argv)
    # the Triton kernel asks for the GPU's properties while lowering: an H100's, on any machine
    gpu_info.get_gpu_info = lambda: gpu_info.get_gpu_info_from_version(gpu_info.GpuVersion.H100)
    w, h = (int(x) for x in args.size.split("x"))
    g, cam = random_scene(args.gaussians, sh_bases=16), synthetic_camera(w, h)
    config = lgs_jax.RasterConfig(tuning=lgs_jax.KernelConfig(interpret=False))
    for cap in args.capacities:
        def loss(g, c, cap=cap):
            out = lgs_jax.render(g, c, backend="pallas", config=config, capacity=cap)
            return jnp.sum(out.image)
        traced_at = time.perf_counter()
        traced = jax.jit(jax.value_and_grad(loss)).trace(g, cam)
        lowered_at = time.perf_counter()
        profile = cProfile.Profile() if args.profile and cap == args.capacities[-1] else None
        if profile:
            profile.enable()
        traced.lower(lowering_platforms=("cuda",))
        if profile:
            profile.disable()
        done = time.perf_counter()
        print(f"capacity {cap}: trace {lowered_at - traced_at:.2f} s, "
              f"lower {done - lowered_at:.2f} s", flush=True)
        if profile:
            pstats.Stats(profile).sort_stats("cumulative").print_stats(25)


if __name__ == "__main__":
    main()
