"""How much a compile of the next pair capacity slows the steps running beside it, and why.

    python scripts/ahead_contention.py [--gaussians 1000000] [--size 1920x1080] [--seconds 4]

`fit` compiles the step for the next pair capacity in a thread (`train.ahead`); on the H200
the steps ran about 6x slower while it did (BENCHMARKS.md §7), which ate most of the gain. Two
causes fit that: Python's lock, held while the step is traced and lowered (Mosaic GPU's layout
inference is Python: `scripts/lower_time.py`), or CPU starvation, XLA's compile using every
core while the training loop dispatches. This times a `pallas` forward + backward step in a
loop (each step waited for, as `fit` waits for its metrics) at one capacity while the gradient
for the next capacity is lowered and compiled

  - `thread`: in a thread of this process (what `fit` does);
  - `process`: in a child process (no shared lock; the same cores);
  - `process-nice`: in a child process at the lowest CPU priority;

and prints steps per second before, while lowering, while compiling and after. The lock shows
as a slowdown while lowering in `thread` only; starvation as a slowdown while compiling in all
three, less with `nice`. Run it again with `XLA_FLAGS=--xla_gpu_force_compilation_parallelism=1`
for one compile thread. Each variant compiles a capacity of its own (no cache hit between them).
On a GPU run it with `XLA_PYTHON_CLIENT_PREALLOCATE=false` (the child process needs memory too):
`bash scripts/scale_gpu_check.sh ahead` does both runs.
"""

import argparse
import os
import subprocess
import sys
import threading
import time

import jax
import jax.numpy as jnp
import numpy as np

import lgs_jax
from lgs_jax.synthetic import random_scene, synthetic_camera

VARIANTS = ("thread", "process", "process-nice")


def _setup(args):
    w, h = (int(x) for x in args.size.split("x"))
    g, cam = random_scene(args.gaussians), synthetic_camera(w, h)
    cap = lgs_jax.pair_capacity(int(lgs_jax.render(g, cam, backend=args.backend)
                                    .stats.pairs_required))
    return g, cam, cap


def _gradient(backend):
    def loss(g, cam, capacity):
        return jnp.sum(lgs_jax.render(g, cam, backend=backend, capacity=capacity).image)
    return jax.jit(jax.value_and_grad(loss), static_argnums=2)


def _compile(grad, g, cam, cap, marks: dict):
    """Lower and compile `grad` at `cap`, noting when each phase ended (`time.time()`, a clock
    the parent and a child process share) in `marks`."""
    lowered = grad.lower(g, cam, cap)
    marks["lowered"] = time.time()
    lowered.compile()
    marks["compiled"] = time.time()


def _child(args, cap):
    """--child: lower and compile at `cap` (after JAX's start and the scene, which are not
    timed), printing when it started and when each phase ended; the parent reads them."""
    if args.nice:
        os.nice(19)
    g, cam, _ = _setup(args)
    marks = {"started": time.time()}
    _compile(_gradient(args.backend), g, cam, cap, marks)
    for name, t in marks.items():
        print(f"{name} {t:.3f}")


def _rate(times, lo, hi) -> float:
    """Steps per second among the steps that ended in [lo, hi)."""
    inside = [t for t in times if lo <= t < hi]
    return len(inside) / (hi - lo) if hi > lo and inside else float("nan")


def run(variant, args, grad, g, cam, cap, cap_next):
    """(steps/s before, while lowering, while compiling, after; lower s, compile s)."""
    step = lambda: jax.block_until_ready(grad(g, cam, cap))
    step()
    times, t0 = [], time.time()
    while time.time() - t0 < args.seconds:
        step()
        times.append(time.time())
    launched = time.time()
    marks = {"started": launched}
    if variant == "thread":
        job = threading.Thread(target=lambda: _compile(grad, g, cam, cap_next, marks))
        job.start()
        alive = job.is_alive
    else:
        child = subprocess.Popen(
            [sys.executable, __file__, "--child", str(cap_next), "--gaussians",
             str(args.gaussians), "--size", args.size, "--backend", args.backend]
            + (["--nice"] if variant == "process-nice" else []),
            stdout=subprocess.PIPE, text=True)
        alive = lambda: child.poll() is None
    while alive():
        step()
        times.append(time.time())
    end = time.time()
    while time.time() - end < args.seconds:
        step()
        times.append(time.time())
    if variant != "thread":
        marks = {name: float(t) for name, t in
                 (line.split() for line in child.stdout.read().splitlines())}
    begun, lowered, compiled = marks["started"], marks["lowered"], marks["compiled"]
    return (_rate(times, t0, launched), _rate(times, begun, lowered),
            _rate(times, lowered, compiled), _rate(times, end, end + args.seconds),
            lowered - begun, compiled - lowered)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--gaussians", type=int, default=1_000_000)
    ap.add_argument("--size", default="1920x1080")
    ap.add_argument("--backend", default="pallas")
    ap.add_argument("--seconds", type=float, default=4.0, help="stepping before and after")
    ap.add_argument("--variants", default=",".join(VARIANTS))
    ap.add_argument("--child", type=int, help=argparse.SUPPRESS)
    ap.add_argument("--nice", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        return _child(args, args.child)
    g, cam, cap = _setup(args)
    grad = _gradient(args.backend)
    print(f"device {jax.devices()[0].device_kind}; JAX {jax.__version__}; "
          f"XLA_FLAGS={os.environ.get('XLA_FLAGS', '')!r}; capacity {cap}", flush=True)
    rows = []
    for i, variant in enumerate(args.variants.split(",")):
        cap_next = lgs_jax.pair_capacity(cap + 1, 1.5 + 0.25 * i)  # a compile of its own
        rows.append((variant, *run(variant, args, grad, g, cam, cap, cap_next)))
        print(f"{variant}: compiled capacity {cap_next}", flush=True)
    print(f"{'variant':>13} {'before':>8} {'lowering':>9} {'compiling':>10} {'after':>8} "
          f"{'lower s':>8} {'compile s':>9}  (steps per second)")
    for v, *r in rows:
        print(f"{v:>13} " + " ".join(f"{x:8.1f}" if np.isfinite(x) else f"{'-':>8}"
                                     for x in r[:4]) + f" {r[4]:8.1f} {r[5]:9.1f}")


if __name__ == "__main__":
    main()
