"""Where a training step's time goes: the pieces of `train.step.train_step`
timed one by one on a real capture, beside gsplat's forward+backward of the same Gaussians.

    python scripts/profile_train_step.py [--data carry/data/skull] [--gaussians 262144]
        [--pool 500000] [--ply RUN/scene.ply] [--headroom 1.5] [--downscale 1] [--repeat 20]
        [--no-gsplat]

The pool: the capture's start (SfM points, MCMC's initial opacity and scales) densified to
--gaussians active rows (each point copied k times, means jittered by N(0, 1)·its largest
scale, log-scales lowered by ln(k)/3, as benchmarks.scale densifies) in --pool slots, SH
degree 3 with small random higher bands; or, with --ply, a trained scene (e.g. the scene.ply
of a `fit` run, whose Gaussians crowd where the object is) in --pool slots (at least its
size). The per-tile load of the first training view is printed too: pairs in the busiest
tile and in the busiest 10% of tiles, against the mean (one program per tile runs its pairs
one after another, so the busiest tiles bound a kernel's time when there are few tiles). The
pair capacity is `lgs_jax.pair_capacity(pairs, --headroom)` of the view's pairs (default 1.5;
`fit` starts and grows at `train.FitConfig.pair_headroom`, 3; 1: the tightest size, to see
what the stages sized by the capacity cost; below 1 is refused). Rows (median ms of --repeat
alternating rounds, one training view):
  render        forward image only
  render+bwd    grad of Σ image·w w.r.t. the Gaussian parameters
  loss+bwd      the training loss (L1 + SSIM + MCMC regulariser) and its gradients
  ssim+bwd      the loss's image part alone (gradient w.r.t. the image of one render: the
                render not included), as training computes it (on a GPU the fused kernels
                for images over `losses.SMALL_IMAGE` pixels, XLA's at or below)
  ssim+bwd xla  the same through the XLA SSIM (`losses.xla_ssim`)
  adam          the optimizer update of the whole pool
  noise         MCMC's per-step noise on the means
  train_step    `train_step` whole (device time: blocked, no host read)
  train_loop    `train_step` + the host read of its metrics, as `fit` runs it
  refine        MCMC's refinement (every 100 steps in a run), its report read back
  gsplat        gsplat's rasterization + backward of Σ image·w (same Gaussians, same view)
  gsplat render     gsplat's rasterization alone (no gradient)
  gsplat ssim+bwd   the loss's image part in torch as benchmarks/train_vs_gsplat's gsplat
                    trainer computes it (conv2d SSIM + L1) and its backward
  gsplat adam       torch's fused Adam over the same parameters, one optimizer per group
Then the step's memory by part (MiB): the pool's parameters, the optimizer state, the strategy
state, the view's target, and XLA's buffers of the compiled `train_step` (arguments, outputs,
temporaries: the pair and row buffers, the render's per-pair records, the gradients, the
loss's images; and how much of the outputs XLA writes in place of the donated state). With a
backend that stores backward rows (Pallas), the temporaries are split by compiling the step
twice more (half the rows; twice the pairs): bytes per pair slot, bytes per backward row, and
the rest (the gradients, the loss's images: what does not scale with the buffers).
"""

from __future__ import annotations

import argparse
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from lgs_jax.io.datasets import as_float  # noqa: E402


def densified_pool(rd, setup, n: int, size: int, seed: int = 0):
    """(pool, opt_state, strategy_state) with n active Gaussians in `size` slots."""
    import jax.numpy as jnp

    from lgs_jax.scene import Gaussians
    from lgs_jax.train import FitConfig, init
    from lgs_jax.train.state import templates

    start = FitConfig(data="", out="", strategy=setup.strategy, max_gaussians=10**9, seed=seed,
                      init_points=100_000)
    g0 = init.start_gaussians(rd, start, log=lambda s: 0)
    rng = np.random.default_rng(seed)
    k = max(1, -(-n // g0.num))
    idx = np.arange(n) % g0.num
    ls = np.asarray(g0.log_scales)[idx]
    jitter = rng.standard_normal((n, 3)) * np.exp(ls.max(axis=1, keepdims=True))
    sh = np.asarray(g0.sh)[idx].copy()
    sh[:, 1:] = 0.05 * rng.standard_normal(sh[:, 1:].shape)
    g = Gaussians(means=jnp.asarray(np.asarray(g0.means)[idx] + jitter, jnp.float32),
                  quats=jnp.asarray(np.asarray(g0.quats)[idx]),
                  log_scales=jnp.asarray(ls - np.log(k) / 3, jnp.float32),
                  logit_opacities=jnp.asarray(np.asarray(g0.logit_opacities)[idx]),
                  sh=jnp.asarray(sh, jnp.float32))
    return g, templates(setup, size, rd, seed, g)[:3]


def trained_pool(setup, path: str, size: int, rd):
    """(Gaussians, (pool, opt_state, strategy_state)): a saved scene in max(size, its count)
    slots, SH bands padded with zeros (or cut) to the setup's degree."""
    import jax.numpy as jnp

    from lgs_jax.io.ply import load_ply
    from lgs_jax.scene import Gaussians
    from lgs_jax.train.state import templates

    g = load_ply(path)
    bases = (setup.recipe.sh_degree + 1) ** 2
    sh = jnp.zeros((g.num, bases, 3), jnp.float32).at[:, :min(bases, g.sh.shape[1])].set(
        g.sh[:, :bases])
    g = Gaussians(g.means, g.quats, g.log_scales, g.logit_opacities, sh)
    return g, templates(setup, max(size, g.num), rd, 0, g)[:3]


def tile_load(pool, cam, capacity: int) -> str:
    """The per-tile pair counts of one view, summarised (module docstring)."""
    import jax

    from lgs_jax import binning
    from lgs_jax.projection import project
    from lgs_jax.train.pool import render_gaussians

    p = project(render_gaussians(pool.params, pool.active), cam)
    bins = jax.jit(binning.bin_gaussians, static_argnums=(1, 2, 3))(
        p, cam.width, cam.height, capacity)
    per_tile = np.sort(np.asarray(bins.tile_end - bins.tile_start))[::-1]
    top = per_tile[:max(1, len(per_tile) // 10)]
    return (f"{len(per_tile)} tiles: pairs per tile mean {per_tile.mean():.0f}, busiest "
            f"{per_tile[0]} ({per_tile[0] / max(per_tile.mean(), 1):.1f}x the mean), busiest "
            f"10% hold {top.sum() / max(per_tile.sum(), 1):.0%} of the pairs")


def rows(rd, setup, g, pool, opt_state, sstate, capacity: int, with_gsplat: bool):
    """{row name: zero-argument blocking callable} (module docstring)."""
    import functools

    import jax
    import jax.numpy as jnp

    from lgs_jax import render
    from lgs_jax.train import losses, ops, step as st
    from lgs_jax.train.optim import optimizer
    from lgs_jax.train.pool import render_gaussians

    cam = jax.tree.map(lambda x: x[0], rd.train_cams)
    target = jnp.asarray(as_float(rd.train_images[0]))
    bg = jnp.asarray(rd.background)
    w = jax.random.uniform(jax.random.key(1), (cam.height, cam.width, 3))
    draw = lambda p: render(render_gaussians(p, pool.active), cam, background=bg,
                            backend=setup.backend, capacity=capacity).image
    fwd = jax.jit(draw)
    bwd = jax.jit(jax.grad(lambda p: jnp.sum(draw(p) * w)))
    lossg = jax.jit(lambda p: st.loss_and_grads(setup, capacity, None, st.Pool(p, pool.active),
                                                  jax.tree.map(lambda x: x[None], cam),
                                                  target[None], bg, jnp.int32(6000),
                                                  jnp.array([0])))
    ssimg = jax.jit(jax.grad(lambda im: losses.loss_fn(im, target, 0.2, "same")))
    xla_loss = lambda im: 0.8 * jnp.mean(jnp.abs(im - target)) + 0.2 * (
        1 - losses.xla_ssim(im, target, padding="same"))
    xla_ssimg = jax.jit(jax.grad(xla_loss))
    image = fwd(pool.params)
    opt = optimizer(setup.recipe, setup.steps, setup.scene_scale)
    adam = jax.jit(lambda g_, s_, p_: opt.update(g_, s_, p_))
    noise = jax.jit(lambda p_, k_: ops.inject_noise(p_, k_, 1e-4 * 5e5))
    grads = jax.tree.map(jnp.ones_like, pool.params)
    idx = jnp.array([0])
    key = jax.random.key(0)
    step_fn = functools.partial(st.train_step, setup=setup, capacity=capacity)
    targets = jnp.asarray(rd.train_images[:1])  # view 0's as fit passes it (as stored)
    own = list(jax.tree.map(jnp.copy, (pool, opt_state, sstate)))  # the step donates its state

    def call():
        out = step_fn(*own, None, rd.train_cams, targets, idx, bg, jnp.int32(6000), key)
        own[:] = out[:3]
        return out
    fns = {
        "render": lambda: jax.block_until_ready(fwd(pool.params)),
        "render+bwd": lambda: jax.block_until_ready(bwd(pool.params)),
        "loss+bwd": lambda: jax.block_until_ready(lossg(pool.params)),
        "ssim+bwd": lambda: jax.block_until_ready(ssimg(image)),
        "ssim+bwd xla": lambda: jax.block_until_ready(xla_ssimg(image)),
        "adam": lambda: jax.block_until_ready(adam(grads, opt_state, pool.params)),
        "noise": lambda: jax.block_until_ready(noise(pool, key)),
        "train_step": lambda: jax.block_until_ready(call()),
        "train_loop": lambda: st.read_metrics(call()[4]),
        "refine": lambda: st.refine(setup.strategy, sstate, pool, opt_state, 6100, key,
                                    pool.size),
    }
    if with_gsplat:
        from benchmarks.scale import gsplat_grad_step

        gs = gsplat_grad_step(g, cam, w)
        if gs is not None:
            fns["gsplat"] = gs
            fns.update(gsplat_stages(g, cam, np.asarray(rd.train_images[0])))
    return fns


def gsplat_stages(g, cam, target) -> dict:
    """{row: blocking callable} of gsplat's forward, the torch loss's backward and torch Adam
    (module docstring)."""
    import torch

    from benchmarks.scale import cuda_f32, gsplat_draw
    from benchmarks.train_vs_gsplat import torch_ssim

    draw = gsplat_draw(cam, int(round(np.sqrt(g.sh.shape[1]))) - 1)
    params = [cuda_f32(x) for x in (g.means, g.quats, g.log_scales, g.logit_opacities,
                                    g.sh[:, :1], g.sh[:, 1:])]
    ref = cuda_f32(as_float(target))

    def render():
        with torch.no_grad():
            draw(*params[:4], torch.cat(params[4:], 1))
        torch.cuda.synchronize()

    image = torch.rand_like(ref, requires_grad=True)

    def ssim_bwd():
        image.grad = None
        loss = torch.lerp((image - ref).abs().mean(), 1 - torch_ssim(image, ref), 0.2)
        loss.backward()
        torch.cuda.synchronize()

    leaves = [torch.nn.Parameter(p.clone()) for p in params]
    opts = [torch.optim.Adam([p], lr=1e-3, eps=1e-15, fused=True) for p in leaves]
    for p in leaves:
        p.grad = torch.ones_like(p)

    def adam():
        for o in opts:
            o.step()
        torch.cuda.synchronize()

    return {"gsplat render": render, "gsplat ssim+bwd": ssim_bwd, "gsplat adam": adam}


def memory_parts(setup, pool, opt_state, sstate, rd, capacity: int) -> dict:
    """{part: MiB} of one training step (module docstring)."""
    import jax
    import jax.numpy as jnp

    from lgs_jax.backends import REGISTRY
    from lgs_jax.train import step as st

    mib = lambda tree: sum(x.nbytes for x in jax.tree.leaves(tree)) / 2**20
    targets = jnp.asarray(rd.train_images[:1])  # as fit passes it (as stored)
    args = (pool, opt_state, sstate, None, rd.train_cams, targets, jnp.array([0]),
            jnp.asarray(rd.background), jnp.int32(6000), jax.random.key(0))
    analysis = lambda capacity, rows: st.train_step.lower(
        *args, setup=setup, capacity=capacity, rows=rows).compile().memory_analysis()
    m = analysis(capacity, None)
    parts = {"pool parameters": mib(pool.params), "optimizer state": mib(opt_state),
             "strategy state": mib(sstate), "one target image": mib(targets),
             "all training images (as fit holds them)": nbytes_mib(rd.train_images)}
    if m is None:
        return parts
    parts.update({"XLA arguments": m.argument_size_in_bytes / 2**20,
                  "XLA outputs": m.output_size_in_bytes / 2**20,
                  "XLA outputs in their donated arguments' place": m.alias_size_in_bytes / 2**20,
                  "XLA temporaries (a row per pair slot)": m.temp_size_in_bytes / 2**20})
    if REGISTRY[setup.backend].row_capacity:  # the temporaries split by differences
        half = capacity // 2
        fewer, more = analysis(capacity, half), analysis(2 * capacity, half)
        per_row = (m.temp_size_in_bytes - fewer.temp_size_in_bytes) / (capacity - half)
        per_slot = (more.temp_size_in_bytes - fewer.temp_size_in_bytes) / capacity
        parts.update({
            "  of which the pair slots (bytes a slot)": per_slot,
            "  of which the backward rows (bytes a row)": per_row,
            "  of which the rest": (m.temp_size_in_bytes - capacity * (per_slot + per_row))
            / 2**20})
    return parts


def nbytes_mib(images) -> float:
    from lgs_jax.train.feed import nbytes

    return nbytes(images) / 2**20


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default=os.path.join(
        os.environ.get("LGS_JAX_DATA", "../shared/data"), "skull"))
    ap.add_argument("--gaussians", type=int, default=262_144)
    ap.add_argument("--pool", type=int, default=500_000)
    ap.add_argument("--ply", help="a trained scene instead of the densified start")
    ap.add_argument("--headroom", type=float, default=1.5)
    ap.add_argument("--downscale", type=int, default=1)
    ap.add_argument("--repeat", type=int, default=20)
    ap.add_argument("--backend", default=None)
    ap.add_argument("--no-gsplat", action="store_true")
    ap.add_argument("--float-images", action="store_true",
                    help="hold the images as float32 (default: as fit does, 8-bit where the "
                         "files are)")
    args = ap.parse_args(argv)
    if args.headroom < 1:
        ap.error(f"--headroom: must be at least 1 (fewer slots than pairs drop pairs), got "
                 f"{args.headroom}")

    import jax

    from benchmarks.common import device_line, median_ms
    from lgs_jax.render import pair_capacity
    from lgs_jax.train import MCMCStrategy, Recipe, Setup
    from lgs_jax.train.feed import prepare
    from lgs_jax.train.state import pairs as pool_pairs

    rd = prepare(args.data, args.downscale, dtype=np.float32 if args.float_images else "auto")
    backend = args.backend or ("pallas" if jax.default_backend() == "gpu" else "tiles")
    setup = Setup(Recipe(), MCMCStrategy(cap_max=args.pool), 7000, rd.scene_scale, backend)
    if args.ply:
        g, (pool, opt_state, sstate) = trained_pool(setup, args.ply, args.pool, rd)
    else:
        g, (pool, opt_state, sstate) = densified_pool(rd, setup, args.gaussians, args.pool)
    cam = jax.tree.map(lambda x: x[0], rd.train_cams)
    pairs = pool_pairs(pool, cam)
    capacity = pair_capacity(pairs, args.headroom)
    fns = rows(rd, setup, g, pool, opt_state, sstate, capacity, not args.no_gsplat)
    ms = median_ms(fns, args.repeat)
    print(device_line())
    print(f"{g.num} Gaussians in {pool.size} slots, {cam.width}x{cam.height}, "
          f"{pairs} pairs, capacity {capacity}, backend {backend}")
    print(tile_load(pool, cam, capacity))
    for name, t in ms.items():
        print(f"  {name:<16s} {t:8.2f} ms")
    print("memory by part:")
    for name, size in memory_parts(setup, pool, opt_state, sstate, rd, capacity).items():
        print(f"  {name:<45s} {size:9.1f} " + ("B" if "bytes" in name else "MiB"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
