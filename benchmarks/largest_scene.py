"""The largest scene one GPU trains: a capture's start densified to n Gaussians, 100 training
steps at the capture's full size, n doubled until a size fails.

    python -m benchmarks.largest_scene [--data DIR] [--sizes 16 32 64 128] [--steps 100]
        [--headroom 1.5] [--out CSV]

Sizes are in millions of Gaussians. Each runs in a process of its own (a failed allocation
leaves nothing behind for the next): the capture's SfM start with MCMC's initial opacity and
scales (`train.init.start_gaussians`), each point copied k times on the device (means jittered
by N(0, 1)·its largest scale, log-scales lowered by ln(k)/3, higher SH bands small and random:
`lgs_jax.synthetic.densified`'s rule, as scripts/profile_train_step.py densifies), the pool
exactly n slots (MCMC's cap; no refinement inside the steps), the pair capacity
`pair_capacity` of the largest pair count over the training views times --headroom, then
`train.step.train_step` on one streamed training view a step (`feed.TrainViews`, as `fit`
feeds), its metrics read back every step as `fit` reads them. A size trains when every step's
loss is finite and no buffer overflowed. The sizes stop at the first that fails (out of memory,
a non-finite loss, an overflow, a pair count past the buffers' int32 indices), its error the
row's status.

Row: Gaussians, status, median ms per step (the steps after the first), the largest pairs
of a view and the capacity, memory by part (MiB): parameters, optimizer state, MCMC's state,
XLA's temporaries of the compiled step (the pair and row buffers, the per-pair records, the
loss's images) and the device's peak bytes in use over the process (`memory_stats`).
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if __package__ in (None, ""):
    sys.path.insert(0, ROOT)

FIELDS = ("gaussians", "status", "ms_per_step", "loss_first", "loss_last", "max_pairs",
          "capacity", "params_mib", "optimizer_mib", "strategy_mib", "xla_temp_mib",
          "peak_mib", "device")


def parse(argv=None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default=os.path.join(
        os.environ.get("LGS_JAX_DATA", os.path.join(ROOT, "..", "shared", "data")), "skull"))
    ap.add_argument("--sizes", type=float, nargs="+", default=[16, 32, 64, 128],
                    help="millions of Gaussians, tried in order until one fails")
    ap.add_argument("--steps", type=int, default=100)
    ap.add_argument("--headroom", type=float, default=1.5)
    ap.add_argument("--timeout", type=float, default=600, help="seconds per size")
    ap.add_argument("--out", help="CSV of the rows")
    ap.add_argument("--worker", type=int, help=argparse.SUPPRESS)
    return ap.parse_args(argv)


def start(rd, setup, n: int, seed: int = 0):
    """n Gaussians on the device: the capture's start, each point copied (module docstring),
    in one program (its intermediates in XLA's temporary buffer, not left as separate
    allocations between the steps that build the pool)."""
    import functools

    import jax
    import jax.numpy as jnp

    from lgs_jax.scene import Gaussians
    from lgs_jax.train import FitConfig, init

    cfg = FitConfig(data="", out="", strategy=setup.strategy, max_gaussians=10**9, seed=seed)
    g0 = jax.tree.map(jnp.asarray, init.start_gaussians(rd, cfg, log=lambda s: 0))

    @functools.partial(jax.jit, static_argnums=0)
    def copies(n, g0, key):
        k = -(-n // g0.num)
        idx = jnp.arange(n) % g0.num
        k_means, k_sh = jax.random.split(key)
        ls = g0.log_scales[idx]
        means = g0.means[idx] + jax.random.normal(k_means, (n, 3)) * jnp.exp(
            ls.max(axis=1, keepdims=True))
        sh = g0.sh[idx]
        sh = sh.at[:, 1:].set(0.05 * jax.random.normal(k_sh, sh[:, 1:].shape))
        return Gaussians(means=means, quats=g0.quats[idx], log_scales=ls - jnp.log(k) / 3,
                         logit_opacities=g0.logit_opacities[idx], sh=sh)
    return copies(n, g0, jax.random.key(seed))


def worker(args) -> dict:
    """One size's row (module docstring)."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    from benchmarks.common import device_line
    from lgs_jax.render import pair_capacity
    from lgs_jax.train import MCMCStrategy, Recipe, Setup
    from lgs_jax.train import step as st
    from lgs_jax.train.feed import TrainViews, prepare
    from lgs_jax.train.state import pairs, templates

    n = args.worker
    row = dict(gaussians=n, device=device_line())
    mib = lambda tree: sum(x.nbytes for x in jax.tree.leaves(tree)) / 2**20
    rd = prepare(args.data, 1, dtype="auto")
    backend = "pallas" if jax.default_backend() == "gpu" else "tiles"
    setup = Setup(Recipe(), MCMCStrategy(cap_max=n), 7000, rd.scene_scale, backend)
    g = start(rd, setup, n)
    pool, opt_state, sstate, _ = templates(setup, n, rd, 0, g)
    del g
    row.update(params_mib=mib(pool.params), optimizer_mib=mib(opt_state),
               strategy_mib=mib(sstate))
    cams = rd.train_cams
    per_view = [pairs(pool, jax.tree.map(lambda x: x[i], cams))
                for i in range(len(rd.train_names))]
    row["max_pairs"] = max(per_view)
    capacity = row["capacity"] = pair_capacity(row["max_pairs"], args.headroom)
    views = TrainViews(rd.train_images, 1, 0, stream=True)
    bg, key = jnp.asarray(rd.background), jax.random.key(0)
    targets, idx = views.args(0)
    compiled = st.train_step.lower(pool, opt_state, sstate, None, cams, targets, idx, bg,
                                   jnp.int32(0), key, setup=setup, capacity=capacity).compile()
    m = compiled.memory_analysis()
    row["xla_temp_mib"] = m.temp_size_in_bytes / 2**20 if m is not None else None
    times, losses = [], []
    for s in range(args.steps):
        t = time.perf_counter()
        targets, idx = views.args(s)
        views.prefetch(s + 1)
        pool, opt_state, sstate, _, metrics = compiled(pool, opt_state, sstate, None, cams,
                                                       targets, idx, bg, jnp.int32(s), key)
        metrics = jax.device_get(metrics)
        times.append(time.perf_counter() - t)
        losses.append(float(metrics["loss"]))
        if not (metrics["ok"] and metrics["fits"]):
            row["status"] = (f"step {s}: loss {losses[-1]}, ok {bool(metrics['ok'])}, "
                             f"fits {bool(metrics['fits'])}")
            break
    views.close()
    row.update(ms_per_step=1e3 * float(np.median(times[1:] or times)), loss_first=losses[0],
               loss_last=losses[-1])
    row.setdefault("status", f"trains ({len(losses)} steps)")
    stats = jax.devices()[0].memory_stats() or {}
    row["peak_mib"] = stats.get("peak_bytes_in_use", 0) / 2**20 or None
    return row


def run_size(args, n: int) -> dict:
    """The worker for n Gaussians in a process of its own; its row, or its failure."""
    cmd = [sys.executable, "-m", "benchmarks.largest_scene", "--worker", str(n), "--data",
           args.data, "--steps", str(args.steps), "--headroom", str(args.headroom)]
    env = dict(os.environ, XLA_PYTHON_CLIENT_PREALLOCATE="false")
    try:
        p = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, env=env,
                           timeout=args.timeout)
    except subprocess.TimeoutExpired:
        return dict(gaussians=n, status=f"timed out after {args.timeout:.0f} s")
    for line in p.stdout.splitlines()[::-1]:
        if line.startswith("ROW "):
            return json.loads(line[4:])
    last = [ln for ln in p.stderr.splitlines() if ln.strip()][-3:]
    return dict(gaussians=n, status=f"exit {p.returncode}: " + " | ".join(last)[-300:])


def main(argv=None) -> int:
    args = parse(argv)
    if args.worker is not None:
        print("ROW " + json.dumps(worker(args)), flush=True)
        return 0
    rows = []
    for millions in args.sizes:
        n = int(round(millions * 1e6))
        t = time.time()
        row = run_size(args, n)
        rows.append(row)
        print(f"{n / 1e6:7.1f}M  {time.time() - t:5.0f} s  " + "  ".join(
            f"{k}={row.get(k)}" for k in FIELDS[1:] if k != "device"), flush=True)
        if not str(row.get("status", "")).startswith("trains"):
            break
    if rows and rows[0].get("device"):
        print(rows[0]["device"])
    if args.out:
        with open(args.out, "w", newline="") as f:
            w = csv.DictWriter(f, FIELDS, extrasaction="ignore")
            w.writeheader()
            w.writerows(rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
