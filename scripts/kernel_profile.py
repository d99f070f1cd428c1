"""Where the Pallas rasterization stage's time goes (GPU): masks, pair records, Gaussian rows
and each kernel call alone, guitar 1280x720 and 3840x2160, median of 30, per UNROLL."""
import functools, statistics, sys, time
import jax, jax.numpy as jnp
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
    b = jax.jit(lambda p: binning.bin_gaussians(p, w, h, cap))(p)
    tx, ty = binning.tile_grid(w, h)
    order = jnp.argsort(b.tile_start - b.tile_end, stable=True).astype(jnp.int32)
    masks_f = jax.jit(lambda p, b: tiles.pair_masks(p, b, tx, C()))
    rec_f = jax.jit(lambda p, b: pallas.pair_records(p, b, tx, C()))
    rows_f = jax.jit(pallas.gaussian_rows)
    masks, rec, rows = masks_f(p, b), rec_f(p, b), rows_f(p)
    print(f"{w}x{h}: masks {med(masks_f, p, b):.3f} ms, records {med(rec_f, p, b):.3f} ms, "
          f"rows {med(rows_f, p):.3f} ms")
    for unroll in (2, 4, 8):
        pallas.UNROLL = {"localgs": unroll, "vanilla": unroll}
        jax.clear_caches()
        for name, cfg in [("localgs", C()), ("fast", C(blend="fast")),
                          ("nocull", C(warp_cull=False))]:
            k = functools.partial(pallas._localgs_kernel, config=cfg, tiles_x=tx, last_pair=cap - 1)
            m = masks if cfg.warp_cull else jnp.zeros((1,), jnp.int32)
            f = jax.jit(lambda *a, k=k: pallas._call(k, tx * ty * 8, 32, 1, jnp.float32, a))
            t = med(f, order, b.tile_start, b.tile_end, m, rec)
            print(f"  unroll {unroll} {name:<8s} kernel {t:.3f} ms", flush=True)
        k = functools.partial(pallas._vanilla_kernel, config=C(), tiles_x=tx, last_pair=cap - 1)
        f = jax.jit(lambda *a, k=k: pallas._call(k, tx * ty, 256, 8, jnp.float32, a))
        t = med(f, order, b.tile_start, b.tile_end, b.gauss, rows)
        print(f"  unroll {unroll} vanilla  kernel {t:.3f} ms", flush=True)
