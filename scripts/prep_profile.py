"""Time each XLA pre-pass stage on the GPU (guitar, 1280x720 and 3840x2160), median of 30."""
import statistics, sys, time
import jax, jax.numpy as jnp
from jax import lax
sys.path.insert(0, ".")
import lgs_jax
from lgs_jax import binning
from lgs_jax.projection import project, depth_order

def med(f, *a, n=30):
    jax.block_until_ready(f(*a))
    ts = []
    for _ in range(n):
        t = time.perf_counter(); jax.block_until_ready(f(*a)); ts.append(time.perf_counter() - t)
    return 1e3 * statistics.median(ts)

gg = jax.device_put(lgs_jax.load_ply("carry/data/guitar/guitar.ply"))
for w, h in [(1280, 720), (3840, 2160)]:
    cam = lgs_jax.load_cameras("carry/data/guitar/orbit_cameras.json", width=w, height=h)[0]
    cap = int(lgs_jax.render(gg, cam, backend="tiles").stats.capacity)
    p = jax.jit(project)(gg, cam)
    rects = jax.jit(lambda p: binning.tile_rects(p, w, h))(p)
    counts = rects[2] * rects[3]
    order = jax.jit(depth_order)(p)
    ends = jnp.cumsum(counts[order])
    slot = jnp.arange(cap, dtype=jnp.int32)
    tiles = jax.random.randint(jax.random.key(0), (cap,), 0, 3600, jnp.int32)
    gidx = jnp.arange(cap, dtype=jnp.int32)
    sort_bits = lambda p: lax.sort((lax.bitcast_convert_type(jnp.where(p.valid, p.depth, jnp.inf),
                                                             jnp.int32),
                                    jnp.arange(p.depth.shape[0], dtype=jnp.int32)),
                                   num_keys=1, is_stable=True)[1]
    search = lambda method: jax.jit(lambda e, s: jnp.searchsorted(e, s, side="right",
                                                                  method=method))
    ranges = lambda t: tuple(jnp.searchsorted(t, jnp.arange(3600), side=side)
                             for side in ("left", "right"))
    rows = [
        ("project", jax.jit(project), (gg, cam)),
        ("tile_rects", jax.jit(lambda p: binning.tile_rects(p, w, h)), (p,)),
        ("depth_order (f32 key sort)", jax.jit(depth_order), (p,)),
        ("depth sort int-bits key", jax.jit(sort_bits), (p,)),
        ("searchsorted slots, default", search("scan"), (ends, slot)),
        ("searchsorted slots, method=sort", search("sort"), (ends, slot)),
        ("searchsorted slots, scan_unrolled", search("scan_unrolled"), (ends, slot)),
        ("tile sort (2 operands, stable)",
         jax.jit(lambda t, g: lax.sort((t, g), num_keys=1, is_stable=True)), (tiles, gidx)),
        ("tile ranges by searchsorted", jax.jit(ranges), (jnp.sort(tiles),)),
        ("tile ranges (binning.tile_ranges)",
         jax.jit(lambda t: binning.tile_ranges(t, 3600)), (jnp.sort(tiles),)),
        ("bin_gaussians total", jax.jit(lambda p: binning.bin_gaussians(p, w, h, cap)), (p,)),
    ]
    print(f"guitar {w}x{h} cap {cap}")
    for name, f, a in rows:
        try:
            print(f"  {name:<40s} {med(f, *a):8.3f} ms", flush=True)
        except Exception as e:
            print(f"  {name:<40s} FAILED {type(e).__name__}: {str(e)[:100]}")
