"""Experiment (GPU): two XLA passes over the Gaussians that the kernel profile found slow at 10M
(BENCHMARKS.md §7 "Dec 2, late evening"), each against a candidate, in one process. Each is timed
alone (median of alternating rounds) and by its kernels' device time (`kernel_times.traced`),
and its results are compared with the current pass's.

1. The projection's vjp (`jax.vjp(project)` with fixed random cotangents). As it is now, XLA
   splits it into two fusions with 32 arrays of N floats between them. The cotangents reach
   the (N, 3), (N, 4) and (N, K, 3) fields through the transposes of column slices, pads added
   per element of the stacked field. Candidate `columns`: the columns' cotangents are put behind
   an optimization barrier and stacked (`columns_barrier`). The vjp's outputs are then all (N,)
   columns, which one multi-output fusion can write.
2. The Gaussian table (`pairs.gaussian_table`, a concatenate along the minor axis: 0.69 ms for
   (10M, 14)). Candidate `stack_T`: the 14 columns stacked along the major axis behind a
   barrier, then transposed (XLA's tiled transpose).
3. The pair emission and tile sort (`binning.bin_gaussians`). Its slot fill's two per-slot
   fusions each recompute `binning.expand_slots`' running maximum and row gathers. Candidate
   `barrier`: each slot's (Gaussian, local index, rectangle) materialised once behind a barrier
   (`expand_slots_materialised`; the same integers).

    XLA_PYTHON_CLIENT_PREALLOCATE=false python scripts/probe_projection_passes.py \
        [--data DIR] [--scenes guitar_x110_4k,lego_x16_1080p] [--repeat 10]
"""

from __future__ import annotations

import argparse
import os
import sys

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import lgs_jax  # noqa: E402
from benchmarks.common import add_data_argument, load_scene, median_ms  # noqa: E402
from lgs_jax import binning, pairs  # noqa: E402
from lgs_jax.binning import padded_ellipse, segment_of_slot  # noqa: E402
from lgs_jax.projection import gaussian_columns, project, project_columns  # noqa: E402
from lgs_jax.scene import Gaussians  # noqa: E402
from scripts.kernel_times import traced  # noqa: E402


@jax.custom_vjp
def columns_barrier(g: Gaussians):
    """`gaussian_columns(g)`, whose vjp materialises the columns' cotangents, then stacks them."""
    return gaussian_columns(g)


def _columns_fwd(g):
    return gaussian_columns(g), None


def _columns_bwd(_, cts):
    mean, quat, log_scale, logit, sh = lax.optimization_barrier(cts)
    return (Gaussians(means=jnp.stack(mean, -1), quats=jnp.stack(quat, -1),
                      log_scales=jnp.stack(log_scale, -1), logit_opacities=logit,
                      sh=jnp.stack([jnp.stack(row, -1) for row in sh], 1)),)


columns_barrier.defvjp(_columns_fwd, _columns_bwd)


def project_via_columns(g, cam):
    return lax.optimization_barrier(project_columns(*columns_barrier(g), cam))


def table_stack_t(p):
    e = padded_ellipse(p)
    cols = [p.mean2d[:, 0], p.mean2d[:, 1], p.conic[:, 0], p.conic[:, 1], p.conic[:, 2],
            p.opacity, p.rgb[:, 0], p.rgb[:, 1], p.rgb[:, 2], p.depth, e.tau, e.tau_pad,
            e.det_lo, e.unbounded.astype(p.mean2d.dtype)]
    return lax.optimization_barrier(lax.optimization_barrier(jnp.stack(cols, 0)).T)


def expand_slots_materialised(plan: binning.SlotPlan):
    """`binning.expand_slots` with each slot's (Gaussian, local index, rectangle) behind a
    barrier."""
    k = segment_of_slot(plan.start, plan.kept, plan.capacity)
    per_k = jnp.stack([plan.start, plan.order], -1)[k]
    g = per_k[:, 1]
    slot = jnp.arange(plan.capacity, dtype=jnp.int32)
    g, local, rect = lax.optimization_barrier((g, slot - per_k[:, 0], plan.rect[g]))
    tile = (rect[:, 1] + local // rect[:, 2]) * plan.tiles_x + rect[:, 0] + local % rect[:, 2]
    return jnp.where(slot < plan.total, tile, plan.n_tiles), g


def bin_with_materialised_slots(p, width: int, height: int, capacity: int):
    """`binning.bin_gaussians` through `expand_slots_materialised` (patched while it traces)."""
    saved = binning.expand_slots
    binning.expand_slots = expand_slots_materialised
    try:
        return binning.bin_gaussians(p, width, height, capacity)
    finally:
        binning.expand_slots = saved


def _diff(a, b) -> str:
    a, b = (np.asarray(x) for x in jax.tree.leaves(a)), (np.asarray(x) for x in jax.tree.leaves(b))
    worst = 0.0
    for x, y in zip(a, b):
        scale = np.max(np.abs(x)) + 1e-30
        worst = max(worst, float(np.max(np.abs(x.astype(np.float64) - y)) / scale))
    return "same bits" if worst == 0 else f"max diff {worst:.2e} of each field's largest"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    add_data_argument(ap)
    ap.add_argument("--scenes", default="guitar_x110_4k,lego_x16_1080p")
    ap.add_argument("--repeat", type=int, default=10)
    args = ap.parse_args(argv)
    print(f"device {jax.devices()[0].device_kind}; JAX {jax.__version__}", flush=True)
    for scene in args.scenes.split(","):
        g, cam = load_scene(scene, args.data)
        g, cam = jax.device_put(g), jax.device_put(cam)
        p = jax.jit(project)(g, cam)
        key = jax.random.key(1)
        cot = jax.tree.map(lambda x: jax.random.normal(key, x.shape, x.dtype)
                           if x.dtype == g.dtype else np.zeros(x.shape, jax.dtypes.float0), p)

        def vjp_of(f):
            return jax.jit(lambda g, c, ct: jax.vjp(lambda g: f(g, c), g)[1](ct)[0])

        cap = lgs_jax.pair_capacity(int(jax.jit(binning.count_pairs, static_argnums=(1, 2))(
            p, cam.width, cam.height)))
        size = (cam.width, cam.height, cap)
        fns = {"vjp:xla": vjp_of(project), "vjp:columns": vjp_of(project_via_columns),
               "table:concat": jax.jit(pairs.gaussian_table), "table:stack_T":
               jax.jit(table_stack_t),
               "emit:xla": jax.jit(binning.bin_gaussians, static_argnums=(1, 2, 3)),
               "emit:barrier": jax.jit(bin_with_materialised_slots, static_argnums=(1, 2, 3))}
        calls = {"vjp:xla": lambda: fns["vjp:xla"](g, cam, cot),
                 "vjp:columns": lambda: fns["vjp:columns"](g, cam, cot),
                 "table:concat": lambda: fns["table:concat"](p),
                 "table:stack_T": lambda: fns["table:stack_T"](p),
                 "emit:xla": lambda: fns["emit:xla"](p, *size),
                 "emit:barrier": lambda: fns["emit:barrier"](p, *size)}
        outs = {k: jax.block_until_ready(c()) for k, c in calls.items()}
        ms = median_ms({k: (lambda c=c: jax.block_until_ready(c())) for k, c in calls.items()},
                       args.repeat)
        print(f"\n### {scene}: {g.num} Gaussians, SH bases {g.sh.shape[1]}")
        for k, c in calls.items():
            per, _, wall = traced(lambda c=c: jax.block_until_ready(c()), 3)
            base = k.split(":")[0] + ":" + {"vjp": "xla", "table": "concat", "emit": "xla"}[
                k.split(":")[0]]
            print(f"{k:14s} {ms[k]:7.3f} ms (median), device busy {sum(per.values()):.3f} ms in "
                  f"{len(per)} kernels; {_diff(outs[base], outs[k])}", flush=True)
            for name, t in per.most_common(4):
                print(f"      {t:7.3f} ms  {name}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
