"""Every GPU kernel of one forward (or forward + backward) of ours and of gsplat 1.5.3, timed by
JAX's profiler (CUPTI), summed per kernel and per call (GPU).

    XLA_PYTHON_CLIENT_PREALLOCATE=false python scripts/kernel_times.py [--data DIR]
        [--scenes guitar_x110_4k] [--rows localgs] [--grad] [--iters 5] [--top 25] [--host N]

Per program (a `benchmarks.scale` row's jitted `render`, or its `value_and_grad` with --grad;
gsplat's `rasterization`, with `backward()` under --grad): its calls are traced alone after a
warm-up, then each kernel's time (CUPTI's device timestamps) is summed over the calls and
divided by them. Kernels are named by their HLO op where XLA reports one (e.g. a sort's CUB
custom call, a fusion), else by the CUDA kernel's name, shortened. Printed per program: the
device-busy time per call (the sum of all kernels and copies) beside the call's wall time and
the device's idle time (no stream busy), then the `--top` kernels by time, then the kernels the
device sat idle longest before (the launch gaps: what the host's dispatch costs).
"""

from __future__ import annotations

import argparse
import collections
import glob
import os
import sys
import tempfile
import time

import jax
import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import lgs_jax  # noqa: E402
from benchmarks.common import add_data_argument, load_scene  # noqa: E402
from benchmarks.scale import ROWS, count_pairs, gsplat_grad_step, gsplat_peer  # noqa: E402


def _name(event) -> str:
    """An event's HLO op where XLA names one, else its (shortened) kernel name."""
    stats = dict(event.stats)
    op = stats.get("hlo_op")
    name = event.name
    if op:
        return f"{op}  [{name[:60]}]" if name != op else op
    return name[:110]


def traced(call, iters: int):
    """(ms per call of each kernel on the device, its launches per call, wall ms per call, idle
    ms before each kernel, inclusive ms per call of each host event) of `call` traced `iters`
    times after one warm-up call."""
    call()
    with tempfile.TemporaryDirectory() as d:
        jax.profiler.start_trace(d)
        t0 = time.perf_counter()
        for _ in range(iters):
            call()
        wall = (time.perf_counter() - t0) * 1e3 / iters
        jax.profiler.stop_trace()
        path = sorted(glob.glob(f"{d}/**/*.xplane.pb", recursive=True))[-1]
        data = jax.profiler.ProfileData.from_file(path)
        per = collections.Counter()
        counts = collections.Counter()
        spans = []
        host = collections.Counter()
        for plane in data.planes:
            if plane.name.startswith("/host:CPU"):
                for line in plane.lines:
                    for e in line.events:
                        host[e.name[:100]] += e.duration_ns / 1e6 / iters
            if not plane.name.startswith("/device:GPU"):
                continue
            for line in plane.lines:
                if not line.name.startswith("Stream"):
                    continue
                for e in line.events:
                    per[_name(e)] += e.duration_ns / 1e6 / iters
                    counts[_name(e)] += 1
                    spans.append((e.start_ns, e.end_ns, _name(e)))
    return per, counts, wall, idle_before(spans, iters), host


def idle_before(spans, iters: int):
    """ms per call the device sat idle (no stream busy) before each kernel, by kernel name: the
    launch gaps. The gap before a call's first kernel is the host's time between calls."""
    gaps = collections.Counter()
    reach = None
    for start, end, name in sorted(spans):
        if reach is not None and start > reach:
            gaps[name] += (start - reach) / 1e6 / iters
        reach = end if reach is None else max(reach, end)
    return gaps


def report(label: str, per, counts, wall: float, gaps, host, iters: int, top: int,
           host_top: int = 0):
    busy = sum(per.values())
    print(f"\n== {label}: device busy {busy:.3f} ms per call, wall {wall:.3f} ms "
          f"({len(per)} kernels), idle {sum(gaps.values()):.3f} ms", flush=True)
    for name, ms in per.most_common(top):
        print(f"  {ms:8.3f} ms  {ms / busy:5.1%}  x{counts[name] / iters:<4.0f} {name}")
    print("  idle before (launch gaps, the first kernel's includes the time between calls):")
    for name, ms in gaps.most_common(top // 2):
        print(f"  {ms:8.3f} ms  before {name}")
    if host_top:
        print("  host events (inclusive, nested ones counted in each):")
        for name, ms in host.most_common(host_top):
            print(f"  {ms:8.3f} ms  {name}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    add_data_argument(ap)
    ap.add_argument("--scenes", default="guitar_x110_4k")
    ap.add_argument("--rows", default="localgs")
    ap.add_argument("--grad", action="store_true")
    ap.add_argument("--iters", type=int, default=5)
    ap.add_argument("--top", type=int, default=25)
    ap.add_argument("--no-gsplat", action="store_true")
    ap.add_argument("--host", type=int, default=0, help="print the N longest host events")
    args = ap.parse_args(argv)
    print(f"device {jax.devices()[0].device_kind}; JAX {jax.__version__}", flush=True)
    for scene in args.scenes.split(","):
        g, cam = load_scene(scene, args.data)
        g, cam = jax.device_put(g), jax.device_put(cam)
        cap = lgs_jax.pair_capacity(count_pairs(g, cam))
        print(f"\n### {scene}: {g.num} Gaussians, {cam.width}x{cam.height}, capacity {cap}")
        weights = jax.random.uniform(jax.random.key(0), (cam.height, cam.width, 3))
        for row in args.rows.split(","):
            backend, config = ROWS[row]
            # the camera and weights are arguments: closed over, XLA would constant-fold them
            render = lambda g, c, b=backend, cf=config: lgs_jax.render(
                g, c, backend=b, config=cf, capacity=cap).image
            if args.grad:
                f = jax.jit(jax.value_and_grad(lambda g, c, w, r=render: (r(g, c) * w).sum()))
                call = lambda f=f: jax.block_until_ready(f(g, cam, weights))
            else:
                f = jax.jit(render)
                call = lambda f=f: jax.block_until_ready(f(g, cam))
            report(f"{scene} {row}", *traced(call, args.iters), args.iters, args.top,
                   args.host)
        if not args.no_gsplat:
            peer = gsplat_peer(g, cam)
            if peer is None:
                continue
            call = (gsplat_grad_step(g, cam, np.asarray(weights)) if args.grad
                    else peer[0]["gsplat:e2e"])
            report(f"{scene} gsplat", *traced(call, args.iters), args.iters, args.top,
                   args.host)
    return 0


if __name__ == "__main__":
    sys.exit(main())
