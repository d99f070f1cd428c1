"""The child process of tests/parallel/test_gaussian_parallel.py: JAX on 4 simulated CPU devices
(`--xla_force_host_platform_device_count`, set before JAX starts). Renders and gradients, one
device and sharded, saved to an .npz the parent checks (`python -m tests.parallel.sharded_child
OUT.npz PART`, PART one of `PARTS`).

Few compiles (each costs seconds on a CPU): every scene has the same shapes, each program is
run on several scenes."""

import dataclasses
import functools
import os
import sys

os.environ["XLA_FLAGS"] = "--xla_force_host_platform_device_count=4"
os.environ.setdefault("JAX_PLATFORMS", "cpu")

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

jax.config.update("jax_enable_x64", True)
if os.environ.get("LGS_JAX_CACHE"):
    from lgs_jax.cli import cache_into  # the parent's lock (its test workers share the folder)

    cache_into(os.environ["LGS_JAX_CACHE"], least_seconds=0.5)

import lgs_jax  # noqa: E402
from lgs_jax import parallel  # noqa: E402
from lgs_jax.binning import tile_rects  # noqa: E402
from lgs_jax.config import RasterConfig  # noqa: E402
from lgs_jax.projection import project  # noqa: E402
from lgs_jax.render import composite_projected  # noqa: E402
from tests import scenes  # noqa: E402

W, H = 40, 72  # 3 x 5 tiles: on 4 devices bands of 2, 2, 1 and 0 tile rows
N = 37  # not a multiple of 4: the last block holds 6 Gaussians and 3 padding rows
CAPACITY = 512  # pairs per device
EXCHANGE = 32  # records per source and destination (the most a source sends: 23)
CONFIG = RasterConfig()
PROJECTED = ("mean2d", "conic", "depth", "opacity", "rgb")


def scene(dtype, concentrated=False):
    """The adversarial test scene (tests/scenes.py); `concentrated`: every centre moved into
    the image's top tile row (band 0 of 4 receives nearly everything)."""
    g = scenes.scene(3, n=N, dtype=dtype)
    if not concentrated:
        return g
    means = np.array(g.means)
    means[:, 1] = (np.abs(means[:, 1]) % 0.2 - 0.9) * means[:, 2]  # pixel rows 3.6 to 11
    return dataclasses.replace(g, means=means.astype(dtype))


def weights(dtype):
    """A linear loss's per-pixel weights on image, alpha and depth (all outputs reach it)."""
    rng = np.random.default_rng(0)
    return tuple(rng.normal(size=s).astype(dtype) for s in ((H, W, 3), (H, W), (H, W)))


def loss(out, w, mask=None):
    m = np.ones((H, W), w[1].dtype) if mask is None else mask
    return (jnp.sum(out.image * w[0] * m[..., None]) + jnp.sum(out.alpha * w[1] * m)
            + jnp.sum(out.depth * w[2] * m))


def outputs(out):
    """What the parent compares: the images, the visibility mask and the Gaussian counts."""
    st = out.stats
    counts = jnp.stack([st.n_valid, st.n_invalid, st.n_transparent, st.n_unbounded], -1)
    return dict(image=out.image, alpha=out.alpha, depth=out.depth, visible=out.visible,
                counts=counts.astype(jnp.int32))


@jax.jit
def one_device_grads(g, cam, bg, w):
    """(render outputs, gradients w.r.t. the Gaussians' fields and the background)."""
    def f(g, bg):
        out = lgs_jax.render(g, cam, background=bg, backend="tiles", capacity=CAPACITY)
        return loss(out, w), outputs(out)
    (_, out), grads = jax.value_and_grad(f, argnums=(0, 1), has_aux=True)(g, bg)
    return out, grads


@functools.partial(jax.jit, static_argnames=("mesh", "capacity", "exchange_capacity"))
def sharded_grads(gs, cam, bg, w, *, mesh, capacity, exchange_capacity):
    """(render outputs, stats, gradients) of `render_sharded` of the padded rows `gs`."""
    def f(gs, bg):
        out = parallel.render_sharded(parallel.GaussianShards(gs, N), cam, mesh, background=bg,
                                      backend="tiles", capacity=capacity,
                                      exchange_capacity=exchange_capacity)
        return loss(out, w), (outputs(out), out.stats)
    (_, (out, stats)), grads = jax.value_and_grad(f, argnums=(0, 1), has_aux=True)(gs, bg)
    return out, stats, grads


def save_grads(res: dict, key: str, out, grads):
    for k in out:
        res[f"{key}/out/{k}"] = np.asarray(out[k])
    for k in scenes.FIELDS:
        res[f"{key}/grad/{k}"] = np.asarray(getattr(grads[0], k))[:N]
    res[f"{key}/grad/background"] = np.asarray(grads[1])


def save_render_grads(res: dict, tag: str, dtype, devices: int, exchange: int = EXCHANGE,
                      names=("uniform",)):
    """Render and gradients of the scenes `names`, on one device and split over `devices`
    (twice: the same bits?)."""
    cam = scenes.camera(W, H, dtype=dtype)
    bg, w = np.asarray(scenes.BACKGROUND, dtype), weights(dtype)
    mesh = parallel.gaussian_mesh(devices)
    for name in names:
        g = scene(dtype, concentrated=name == "concentrated")
        save_grads(res, f"{tag}/{name}/one", *one_device_grads(g, cam, bg, w))
        gs = parallel.shard_gaussians(g, mesh).gaussians
        for i in range(2):
            out, stats, grads = sharded_grads(gs, cam, bg, w, mesh=mesh, capacity=CAPACITY,
                                              exchange_capacity=exchange)
            save_grads(res, f"{tag}/{name}/{i}", out, grads)
            res[f"{tag}/{name}/{i}/overflow"] = np.asarray([stats.overflow,
                                                            stats.exchange_overflow])
            res[f"{tag}/{name}/{i}/exchange_counts"] = np.asarray(stats.exchange_counts)


def tile_masks():
    """(1 + tiles, H, W): the whole image, then each tile's pixels alone."""
    masks = [np.ones((H, W))]
    for ty in range(-(-H // 16)):
        for tx in range(-(-W // 16)):
            m = np.zeros((H, W))
            m[ty * 16:(ty + 1) * 16, tx * 16:(tx + 1) * 16] = 1
            masks.append(m)
    return np.stack(masks)


def save_projected_bound(res: dict, tag: str, dtype, devices: int):
    """Gradients w.r.t. the projected fields: one device (whole image, and per tile: each
    Gaussian's row of that tile) and split over `devices` (`composite_sharded`), with each
    Gaussian's tile count."""
    g, cam = scene(dtype), scenes.camera(W, H, dtype=dtype)
    bg, w = np.asarray(scenes.BACKGROUND, dtype), weights(dtype)
    mesh = parallel.gaussian_mesh(devices)
    shards = parallel.shard_gaussians(g, mesh)
    p = jax.jit(project)(shards.gaussians, cam)
    fields = lambda p: {k: getattr(p, k) for k in PROJECTED}

    def one(p, mask):
        def f(fl):
            out = composite_projected(dataclasses.replace(p, **fl), W, H, bg, "tiles", CONFIG,
                                      CAPACITY)
            return loss(out, w, mask), outputs(out)
        return jax.grad(f, has_aux=True)(fields(p))

    per_mask, outs = jax.jit(lambda p, m: jax.lax.map(lambda mk: one(p, mk), m))(
        p, tile_masks().astype(dtype))

    def sharded(p):
        def f(fl):
            out = parallel.composite_sharded(dataclasses.replace(p, **fl), bg, width=W,
                                             height=H, mesh=mesh, backend="tiles",
                                             config=CONFIG, capacity=CAPACITY,
                                             exchange_capacity=EXCHANGE)
            return loss(out, w), outputs(out)
        return jax.grad(f, has_aux=True)(fields(p))

    grads, out = jax.jit(sharded)(jax.device_put(p, parallel.gaussian_sharding(mesh)))
    _, _, nx, ny, _ = tile_rects(p, W, H)
    res[f"{tag}/tiles"] = np.asarray(nx * ny)
    for k in PROJECTED:
        res[f"{tag}/one/{k}"] = np.asarray(per_mask[k][0])
        res[f"{tag}/rows/{k}"] = np.asarray(per_mask[k][1:])
        res[f"{tag}/sharded/{k}"] = np.asarray(grads[k])
    for k in out:
        res[f"{tag}/one/out/{k}"] = np.asarray(outs[k][0])
        res[f"{tag}/sharded/out/{k}"] = np.asarray(out[k])


def save_views_mesh(res: dict):
    """A 2 x 2 mesh ("views" x "gaussians"): a batch of 2 views of the float64 scene, from an
    exchange capacity of 2, which overflows (reported), then `render_sharded_growing` grows it;
    one camera (the first view), rendered on both rows of the mesh; and the one-device render
    of each view alone (`one_device_grads`' forward: float64, as `save_render_grads` compiled
    it, rather than a program of its own; float32 on a 2 x 2 mesh: the training run resumed
    on one, test_gaussian_parallel_training.py)."""
    dtype = np.float64
    g, bg = scene(dtype), np.asarray(scenes.BACKGROUND, dtype)
    views = [scenes.camera(W, H, dtype=dtype, yaw=y) for y in (0.0, 0.15)]
    cams = lgs_jax.stack_cameras(views)
    mesh = parallel.gaussian_mesh(2, views=2)
    shards = parallel.shard_gaussians(g, mesh)
    calls = []

    @functools.partial(jax.jit, static_argnames=("capacity", "exchange_capacity"))
    def sharded(gs, c, bg, *, capacity, exchange_capacity):
        out = parallel.render_sharded(parallel.GaussianShards(gs, N), c, mesh, background=bg,
                                      backend="tiles", capacity=capacity,
                                      exchange_capacity=exchange_capacity)
        return outputs(out), out.stats

    def fn(*args, capacity, exchange_capacity):
        out, stats = sharded(*args, capacity=capacity, exchange_capacity=exchange_capacity)
        calls.append((capacity, exchange_capacity, bool(np.any(stats.exchange_overflow)),
                      int(np.max(stats.exchange_required)), bool(np.any(stats.overflow)),
                      int(np.max(stats.pairs_required))))
        return out, stats

    (out, _), *settled = parallel.render_sharded_growing(fn, shards.gaussians, cams, bg,
                                                         capacity=16, exchange_capacity=2)
    res["growth/calls"] = np.asarray(calls, np.int64)
    res["growth/settled"] = np.asarray(settled)
    alone = [one_device_grads(g, c, bg, weights(dtype))[0] for c in views]
    single, _ = sharded(shards.gaussians, views[0], bg, capacity=settled[0],
                        exchange_capacity=settled[1])
    for k in out:
        res[f"views/sharded/{k}"] = np.asarray(out[k])
        res[f"views/one/{k}"] = np.stack([np.asarray(a[k]) for a in alone])
        res[f"single/sharded/{k}"] = np.asarray(single[k])
        res[f"single/one/{k}"] = np.asarray(alone[0][k])


def save_eager(res: dict, devices: int = 4):
    """Eager calls (float32): buffers sized by counting first, and an exchange buffer too small
    refused with the count it needs."""
    dtype = np.float32
    g, cam = scene(dtype), scenes.camera(W, H, dtype=dtype)
    bg = np.asarray(scenes.BACKGROUND, dtype)
    mesh = parallel.gaussian_mesh(devices)
    shards = parallel.shard_gaussians(g, mesh)
    out = parallel.render_sharded(shards, cam, mesh, background=bg, backend="tiles")
    one = jax.jit(lambda g, c, bg: outputs(lgs_jax.render(g, c, background=bg, backend="tiles",
                                                          capacity=CAPACITY)))
    for k, v in outputs(out).items():
        res[f"eager/sharded/{k}"] = np.asarray(v)
    for k, v in one(g, cam, bg).items():
        res[f"eager/one/{k}"] = np.asarray(v)
    res["eager/capacities"] = np.asarray([out.stats.capacity, out.stats.exchange_capacity])
    try:
        parallel.render_sharded(shards, cam, mesh, background=bg, backend="tiles",
                                capacity=CAPACITY, exchange_capacity=2)
        res["eager/refused"] = np.asarray([0, 0])
    except parallel.ExchangeCapacityError as e:
        res["eager/refused"] = np.asarray([e.required, e.capacity])


PARTS = {
    "render": lambda res: (save_render_grads(res, "f64d4", np.float64, 4, EXCHANGE,
                                             ("uniform", "concentrated")),
                           save_views_mesh(res)),
    "bound": lambda res: save_projected_bound(res, "bound32d2", np.float32, 2),
    "slow": lambda res: (save_render_grads(res, "f32d1", np.float32, 1),
                         save_render_grads(res, "f32d4", np.float32, 4),
                         save_projected_bound(res, "bound64d4", np.float64, 4),
                         save_eager(res)),
}


def main(path: str, part: str):
    res = {}
    PARTS[part](res)
    np.savez(path, **res)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
