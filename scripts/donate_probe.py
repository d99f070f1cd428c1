"""Experiment (issue 17): is the host time of a blocked forward XLA re-recording its command
buffers because the output moved?

    python scripts/donate_probe.py [--data DIR] [--scenes NAME ...] [--repeat N]

Per scene (benchmarks.common.SCENES), the jitted `render(...).image` timed blocked three ways,
in alternating rounds: `plain` (a new output buffer every call, the previous one still alive:
its address alternates), `donated` (the previous call's image donated as an argument the
program does not read, so XLA writes the new image into the same buffer: every address the
program touches is the same call after call, if the temporaries' allocation lands where it
did), and `queued` (8 calls, one block, per call). Also the time until each call returns
(the host's part). If `donated` is as fast as `queued` the host share is the re-recording.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time

import jax
import jax.numpy as jnp

import lgs_jax

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from benchmarks.common import add_data_argument, device_line, load_scene  # noqa: E402
from benchmarks.scale import count_pairs  # noqa: E402


def probe(name: str, data: str, repeat: int):
    g, cam = load_scene(name, data)
    g, cam = jax.device_put(g), jax.device_put(cam)
    cap = lgs_jax.pair_capacity(count_pairs(g, cam))
    image = lambda g, c: lgs_jax.render(g, c, capacity=cap).image
    plain = jax.jit(image)
    donated = jax.jit(lambda g, c, previous: image(g, c), donate_argnums=2)
    state = {"out": plain(g, cam), "prev": jax.block_until_ready(donated(g, cam, plain(g, cam)))}

    def run_plain():
        t0 = time.perf_counter()
        state["out"] = plain(g, cam)
        t1 = time.perf_counter()
        jax.block_until_ready(state["out"])
        return t1 - t0

    def run_donated():
        t0 = time.perf_counter()
        state["prev"] = donated(g, cam, state["prev"])
        t1 = time.perf_counter()
        jax.block_until_ready(state["prev"])
        return t1 - t0

    def run_queued():
        t0 = time.perf_counter()
        outs = [plain(g, cam) for _ in range(8)]
        t1 = time.perf_counter()
        jax.block_until_ready(outs)
        return (t1 - t0) / 8

    fns = {"plain": run_plain, "donated": run_donated, "queued": run_queued}
    for f in fns.values():
        f()
    wall = {k: [] for k in fns}
    host = {k: [] for k in fns}
    for _ in range(repeat):
        for k, f in fns.items():
            t0 = time.perf_counter()
            host[k].append(f())
            wall[k].append((time.perf_counter() - t0) / (8 if k == "queued" else 1))
    ms = lambda xs: 1e3 * statistics.median(xs)
    same = bool(jnp.array_equal(state["out"], state["prev"]))
    for k in fns:
        print(f"{name:<20} {k:<8} wall {ms(wall[k]):7.3f} ms  returns after {ms(host[k]):7.3f}"
              f" ms  same image {same}", flush=True)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", nargs="+", default=["synthetic4M_1080p", "guitar_x110_4k"])
    ap.add_argument("--repeat", type=int, default=30)
    add_data_argument(ap)
    args = ap.parse_args(argv)
    print(device_line())
    for name in args.scenes:
        probe(name, args.data, args.repeat)


if __name__ == "__main__":
    main()
