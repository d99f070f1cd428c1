"""Mosaic GPU forward kernels (lgs_jax.backends.mosaic) per block size (pixels per warpgroup
block: 128 = half a tile, 256 = the whole tile, two pixels per lane), CHUNK (Local-GS records
staged in shared memory by TMA; 0: read from global memory) and UNROLL, against the Triton
Local-GS kernel: kernel calls alone from the same binned inputs, all variants alternating in
each of 30 rounds (median ms), H100. Each variant's outputs are compared with the first
variant's of its kernel. (Earlier runs swept UNROLL and GROUP_SKIP alone:
bench_results/mosaic_profile_h100.log.)

    XLA_PYTHON_CLIENT_PREALLOCATE=false python scripts/mosaic_profile.py [DATA]
"""
import functools
import statistics
import sys
import time

import jax
import jax.numpy as jnp

import lgs_jax
from lgs_jax import binning
from lgs_jax.backends import mosaic, pallas, tiles
from lgs_jax.bench import parse_scene
from lgs_jax.projection import project

C = lgs_jax.RasterConfig
data = sys.argv[1] if len(sys.argv) > 1 else "carry/data"
specs = [f"guitar={data}/guitar/guitar.ply:{data}/guitar/orbit_cameras.json@1280x720",
         f"guitar4k={data}/guitar/guitar.ply:{data}/guitar/orbit_cameras.json@3840x2160",
         f"lego={data}/lego_sh3/lego_sh3.ply:{data}/lego_sh3/lego_cameras.json@800x800",
         f"lego3200={data}/lego_sh3/lego_sh3.ply:{data}/lego_sh3/lego_cameras.json@3200x3200",
         "synthetic:1000000@1280x720"]
# (kernel, pixels per block, CHUNK, UNROLL)
VARIANTS = [("localgs", 128, 0, 8), ("localgs", 128, 64, 8), ("localgs", 256, 0, 8),
            ("localgs", 256, 64, 8), ("localgs", 256, 64, 4), ("vanilla", 128, 0, 8),
            ("vanilla", 256, 0, 8)]
defaults = mosaic.CHUNK, dict(mosaic.UNROLL)
print(f"device {jax.devices()[0].device_kind}; JAX {jax.__version__}")
for spec in specs:
    case = parse_scene(spec)
    g, cam = jax.device_put(case.scene), jax.device_put(case.camera)
    w, h = cam.width, cam.height
    cap = int(lgs_jax.render(g, cam).stats.capacity)
    p = jax.jit(project)(g, cam)
    b = jax.jit(lambda p: binning.bin_gaussians(p, w, h, cap))(p)
    tx, ty = binning.tile_grid(w, h)
    order = jnp.argsort(b.tile_start - b.tile_end, stable=True).astype(jnp.int32)
    masks = jax.jit(lambda p, b: tiles.pair_masks(p, b, tx, C()))(p, b)
    rec = jax.jit(lambda p, b, m: pallas.pair_records(p, b, tx, C(), m))(p, b, masks)
    ranges = jax.jit(mosaic.ranges)(b)
    fns = {}
    kw = dict(config=C(), tiles_x=tx, last_pair=cap - 1)
    k = functools.partial(pallas._localgs_kernel, **kw)
    fns["triton localgs"] = (jax.jit(lambda *a, k=k: pallas._call(
        k, tx * ty * 8, 32, 1, jnp.float32, a)), (order, b.tile_start, b.tile_end, masks, rec))
    gauss_rows = jax.jit(pallas.gaussian_rows)(p)
    for kind, px, chunk, unroll in VARIANTS:
        mosaic.CHUNK, mosaic.UNROLL[kind] = chunk, unroll
        if kind == "localgs":
            k = functools.partial(mosaic.localgs_kernel, **kw, pixels=px)
            a, scratch = (order, ranges, masks, rec), mosaic.localgs_scratch(jnp.float32)
        else:
            k = functools.partial(mosaic.vanilla_kernel, **kw, pixels=px)
            a, scratch = (order, ranges, b.gauss, gauss_rows), ()
        f = jax.jit(lambda *a, k=k, px=px, s=scratch: mosaic.call(k, tx * ty, px, jnp.float32, a,
                                                                  False, s))
        fns[f"{kind} px={px} chunk={chunk} unroll={unroll}"] = (f.lower(*a).compile(), a)
    mosaic.CHUNK, mosaic.UNROLL = defaults
    refs = {}
    for name, (f, a) in fns.items():
        if name.startswith("triton"):
            continue
        out = jax.block_until_ready(f(*a))
        ref = refs.setdefault(name.split()[0], out)
        diff = max(float(jnp.max(jnp.abs(x - y))) for x, y in zip(out[:5], ref[:5]))
        print(f"{case.name:>9s} {name:<36s} max |diff| vs first: {diff:.1e}", flush=True)
    times = {name: [] for name in fns}
    for name, (f, a) in fns.items():
        jax.block_until_ready(f(*a))
    for _ in range(30):
        for name, (f, a) in fns.items():
            t0 = time.perf_counter()
            jax.block_until_ready(f(*a))
            times[name].append(1e3 * (time.perf_counter() - t0))
    for name, t in times.items():
        print(f"{case.name:>9s} {name:<36s} {statistics.median(t):7.3f} ms", flush=True)
