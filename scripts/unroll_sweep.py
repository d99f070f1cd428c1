"""Rasterization-stage time of the Pallas kernels against pairs staged per loop iteration
(pallas.UNROLL), guitar at 1280x720 and 3840x2160, median of 30 (GPU)."""
import statistics, sys, time
import jax
sys.path.insert(0, ".")
import lgs_jax
from lgs_jax import binning
from lgs_jax.backends import pallas
from lgs_jax.projection import project

C = lgs_jax.RasterConfig
g = jax.device_put(lgs_jax.load_ply("carry/data/guitar/guitar.ply"))
for w, h in [(1280, 720), (3840, 2160)]:
    cam = lgs_jax.load_cameras("carry/data/guitar/orbit_cameras.json", width=w, height=h)[0]
    cap = int(lgs_jax.render(g, cam).stats.capacity)
    p = jax.jit(project)(g, cam)
    bins = jax.jit(lambda p: binning.bin_gaussians(p, w, h, cap))(p)
    for unroll in (1, 2, 4, 8):
        pallas.UNROLL = {"localgs": unroll, "vanilla": unroll}
        jax.clear_caches()
        for name, cfg, vanilla in [("localgs", C(), False), ("fast", C(blend="fast"), False),
                                   ("vanilla", C(), True)]:
            f = jax.jit(lambda p, b: pallas.rasterize(p, b, w, h, cfg, vanilla=vanilla)[0].color)
            jax.block_until_ready(f(p, bins))
            ts = []
            for _ in range(30):
                t0 = time.perf_counter()
                jax.block_until_ready(f(p, bins))
                ts.append(time.perf_counter() - t0)
            print(f"{w}x{h} unroll {unroll} {name:<8s} {1e3 * statistics.median(ts):7.3f} ms",
                  flush=True)
