"""GPU smoke test of the Pallas kernels: equivalence on a small scene, then kernel and end-to-end
times on guitar 1280x720 (median of 30)."""
import statistics, sys, time
import jax, jax.numpy as jnp, numpy as np
sys.path.insert(0, ".")
import lgs_jax
from lgs_jax import binning
from lgs_jax.backends import pallas, tiles
from lgs_jax.projection import project
from tests import scenes
C = lgs_jax.RasterConfig
print(jax.devices())
g = scenes.cast(scenes.scene(3), np.float32); cam = scenes.camera()
ref = scenes.render(g, cam, "reference", C())
for backend, cfg in [("pallas", C()), ("pallas", C(hoist=False, warp_cull=False)), ("pallas", C(blend="fast")), ("pallas_vanilla", C())]:
    out = scenes.render(g, cam, backend, cfg)
    d = np.abs(np.asarray(out.image) - np.asarray(ref.image))
    print(backend, cfg.hoist, cfg.warp_cull, cfg.blend, out.stats.kernel, out.stats.interpreted, "maxdiff", d.max(), flush=True)

def med(f, *a, n=30):
    jax.block_until_ready(f(*a))
    ts = []
    for _ in range(n):
        t = time.perf_counter(); jax.block_until_ready(f(*a)); ts.append(time.perf_counter() - t)
    return 1e3 * statistics.median(ts)

gg = lgs_jax.load_ply("carry/data/guitar/guitar.ply")
for w, h in [(1280, 720), (3840, 2160)]:
    cam = lgs_jax.load_cameras("carry/data/guitar/orbit_cameras.json", width=w, height=h)[0]
    first = lgs_jax.render(gg, cam, backend="tiles")
    cap = int(first.stats.capacity)
    prep = jax.jit(lambda g, c: (lambda p: (p, binning.bin_gaussians(p, w, h, cap)))(project(g, c)))
    p, bins = prep(gg, cam)
    rows = []
    rows.append(("prep", med(prep, gg, cam)))
    for name, fn in [("pallas", lambda p, b: pallas.rasterize(p, b, w, h, C())),
                     ("pallas-fast", lambda p, b: pallas.rasterize(p, b, w, h, C(blend="fast"))),
                     ("pallas-nocull", lambda p, b: pallas.rasterize(p, b, w, h, C(warp_cull=False))),
                     ("vanilla", lambda p, b: pallas.rasterize(p, b, w, h, C(), vanilla=True)),
                     ("tiles", lambda p, b: tiles.rasterize(p, b, w, h, C()))]:
        f = jax.jit(fn)
        rows.append((name + " raster", med(f, p, bins)))
    for backend in ["pallas", "pallas_vanilla"]:
        f = jax.jit(lambda g, c, b=backend: lgs_jax.render(g, c, backend=b, capacity=cap).image)
        out = f(gg, cam)
        err = float(jnp.max(jnp.abs(out - first.image)))
        rows.append((backend + f" e2e (max|d| vs tiles {err:.1e})", med(f, gg, cam)))
    print(f"guitar {w}x{h} pairs {int(first.stats.pairs_required)}")
    for r in rows:
        print(f"  {r[0]:<40s} {r[1]:8.3f} ms")
