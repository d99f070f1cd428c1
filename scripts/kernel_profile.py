"""Where the Pallas rasterization stage's time goes (GPU): masks, row packing, the kernel call
alone, and the image assembly, guitar 1280x720 and 3840x2160, median of 30, per UNROLL."""
import functools, statistics, sys, time
import jax, jax.numpy as jnp
from jax import lax
sys.path.insert(0, ".")
import lgs_jax
from lgs_jax import binning
from lgs_jax.backends import pallas, tiles
from lgs_jax.projection import project

C = lgs_jax.RasterConfig

def med(f, *a):
    jax.block_until_ready(f(*a))
    ts = []
    for _ in range(30):
        t0 = time.perf_counter(); jax.block_until_ready(f(*a)); ts.append(time.perf_counter() - t0)
    return 1e3 * statistics.median(ts)

g = jax.device_put(lgs_jax.load_ply("carry/data/guitar/guitar.ply"))
for w, h in [(1280, 720), (3840, 2160)]:
    cam = lgs_jax.load_cameras("carry/data/guitar/orbit_cameras.json", width=w, height=h)[0]
    cap = int(lgs_jax.render(g, cam).stats.capacity)
    p = jax.jit(project)(g, cam)
    bins = jax.jit(lambda p: binning.bin_gaussians(p, w, h, cap))(p)
    tx, ty = binning.tile_grid(w, h)
    masks_f = jax.jit(lambda p, b: tiles.pair_masks(p, b, tx, C()))
    rows_f = jax.jit(pallas.gaussian_rows)
    masks, rows = masks_f(p, bins), rows_f(p)
    print(f"{w}x{h}: masks {med(masks_f, p, bins):.3f} ms, rows {med(rows_f, p):.3f} ms")
    for unroll in (1, 2, 4, 8):
        pallas.UNROLL = {"localgs": unroll, "vanilla": unroll}
        jax.clear_caches()
        for name, cfg in [("localgs", C()), ("fast", C(blend="fast")), ("nocull", C(warp_cull=False))]:
            k = functools.partial(pallas._localgs_kernel, config=cfg, tiles_x=tx, last_pair=cap - 1)
            m = masks if cfg.warp_cull else jnp.zeros((1,), jnp.int32)
            f = jax.jit(lambda s, e, gg, m, r, k=k: pallas._call(k, tx * ty * 8, 32, 1, jnp.float32, (s, e, gg, m, r)))
            print(f"  unroll {unroll} {name:<8s} kernel {med(f, bins.tile_start, bins.tile_end, bins.gauss, m, rows):.3f} ms", flush=True)
        for nw in (4, 8):
            k = functools.partial(pallas._vanilla_kernel, config=C(), tiles_x=tx, last_pair=cap - 1)
            f = jax.jit(lambda s, e, gg, r, k=k, nw=nw: pallas._call(k, tx * ty, 256, nw, jnp.float32, (s, e, gg, r)))
            print(f"  unroll {unroll} vanilla warps {nw} kernel {med(f, bins.tile_start, bins.tile_end, bins.gauss, rows):.3f} ms", flush=True)
