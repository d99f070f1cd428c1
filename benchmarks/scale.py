"""Speed and memory at scale against gsplat 1.5.3: forward (and with --grad forward+backward) of
0.06M–10M Gaussians at 720p–4K, ours and gsplat's in one process, all rows alternating within
each round.

    XLA_PYTHON_CLIENT_PREALLOCATE=false python -m benchmarks.scale [--data DIR] [--scenes a,b]
        [--rows localgs,localgs:fast,vanilla] [--grad] [--repeat 20] [--csv FILE]

Rows (`ROWS`) name a backend and config; every row's pair buffer is `lgs_jax.pair_capacity` of
the view's pairs, or with the suffix `@pow2` (e.g. `--rows localgs,localgs@pow2`) the power of
two above them, the policy before `pair_capacity`: the same row at both sizes measures what the
pair capacity costs in one run. With --grad, the suffix `@walked` sizes the backward's buffer of
rows for the walked pairs (`render`'s `row_capacity`) from an eager forward's count instead of
the pair capacity. The shared
stages below (`project`, `emit`, `sort`, `pair_prep`) are timed once, at the `pair_capacity`
size.

Scenes (`SCENES`): guitar (91k) and lego_sh3 (60k) as they are, densified copies of guitar
(lgs_jax.synthetic.densified: x16 1.5M, x64 5.8M, x110 10M) and lego_sh3 (x16 1M), and
`synthetic` scenes (lgs_jax.synthetic.random_scene), each through view 0 of its cameras scaled
to the size shown. Every row renders in the "gsplat" convention (gsplat 1.5.3's alpha cap and
stop test), so the images can be compared: PSNR against gsplat's image.

Forward rows: per stage (`project`, `emit` = pair emission, `sort` = tile sort and ranges;
gsplat: projection + SH, `isect_tiles`, `isect_offset_encode`), the rasterization stage alone
(`raster`: from projected and binned inputs, per-pair preparation included; gsplat's
`rasterize_to_pixels`; `pair_prep`, on the rows whose raster builds records in XLA (Triton, or
`localgs:records`): the Local-GS strip masks and pair records alone), and end
to end (`e2e`: one jitted `render` / one `gsplat.rasterization` call, blocked; `e2e_queued`:
the time per call of `QUEUED` calls issued back to back and blocked once, as a training loop
issues its steps: JAX's dispatch returns before the device is done, so the host's share of one
call overlaps the device's work on the one before; gsplat's call waits on its device before
the rasterizer is launched (it reads the pair count), so queueing saves it less). Memory: ours
is XLA's compiled memory analysis of the e2e program (temporaries + outputs, not the
arguments), gsplat's the peak torch allocates during the call above what it held before (its
inputs), in MiB.

--grad rows: the gradient of Σ image·w (w fixed, random) with respect to every Gaussian field,
ours jitted (`value_and_grad`) and gsplat's `rasterization` + `backward()`, with memory as above,
and whether two of our calls give the same bits.

Times are medians over `--repeat` rounds (fewer for scenes of 5M Gaussians or more) after one
warm-up call each; every call ends with `block_until_ready` / `torch.cuda.synchronize`.
"""

from __future__ import annotations

import argparse
import csv
import sys

import jax
import jax.numpy as jnp
import numpy as np

import lgs_jax
from lgs_jax import binning, pairs
from lgs_jax.backends import REGISTRY, pallas
from lgs_jax.backends.pallas import steps as kernel_steps
from lgs_jax.layout import tile_grid
from lgs_jax.projection import project
from lgs_jax.render import next_pow2

from .common import (SCENES, add_data_argument, compiled_mib, load_scene, median_ms,
                     pipeline_stages, psnr, torch_peak_mib)

C = lgs_jax.RasterConfig
QUEUED = 8  # calls issued before one block, for the e2e_queued column
K = lgs_jax.KernelConfig
# row -> (backend, config); "auto" is what users get (Mosaic GPU on a GPU)
ROWS = {
    "auto": ("pallas", C("gsplat")),
    "localgs": ("pallas", C("gsplat")),
    "localgs:fast": ("pallas", C("gsplat", blend="fast")),
    "localgs:triton": ("pallas", C("gsplat", kernel="triton")),
    "vanilla": ("pallas_vanilla", C("gsplat")),
    "vanilla:triton": ("pallas_vanilla", C("gsplat", kernel="triton")),
    # the KernelConfig settings: the pair loop unrolled 4 times instead of 8; block sizes;
    # the backward's walks whole (one block per tile) or in segments of 512 / 2048 pairs
    "localgs:unroll4": ("pallas", C("gsplat", tuning=K(unroll=4))),
    "localgs:px256": ("pallas", C("gsplat", tuning=K(forward_pixels=256, backward_pixels=256))),
    "vanilla:px128": ("pallas_vanilla", C("gsplat", tuning=K(forward_pixels=128))),
    "localgs:bwd128": ("pallas", C("gsplat", tuning=K(backward_pixels=128))),
    "localgs:whole": ("pallas", C("gsplat", tuning=K(backward_segment=None))),
    "localgs:seg512": ("pallas", C("gsplat", tuning=K(backward_segment=512))),
    "localgs:seg2048": ("pallas", C("gsplat", tuning=K(backward_segment=2048))),
}
POW2 = "@pow2"
"""Row-name suffix: the row's pair capacity is the power of two above the pairs."""
WALKED = "@walked"
"""Row-name suffix (--grad): the backward's rows for the walked pairs only, `render`'s
`row_capacity` = `pair_capacity` of an eager forward's walked pairs (as the pair
capacity is sized from a count of the pairs)."""


def _row_key(name: str) -> str:
    """The `ROWS` key of row `name` (its suffix `POW2` or `WALKED` removed)."""
    return name.removesuffix(POW2).removesuffix(WALKED)


def row_setup(name: str, n_pairs: int):
    """(backend, config, pair capacity) of row `name` (a `ROWS` key, optionally + `POW2` or
    `WALKED`) for a view of `n_pairs` tile–Gaussian pairs."""
    backend, config = ROWS[_row_key(name)]
    cap = next_pow2(n_pairs) if name.endswith(POW2) else lgs_jax.pair_capacity(n_pairs)
    return backend, config, cap


def builds_records_in_xla(backend: str, config, n_tiles: int, cap: int) -> bool:
    """Whether the row's raster includes the XLA per-pair preparation `pair_prep` times: a
    Local-GS forward on Triton (the Mosaic GPU kernels build their records themselves)."""
    del cap
    plan = pallas.plan(config, backend == "pallas_vanilla", n_tiles)
    return not plan.vanilla and plan.kernel == "triton"


def count_pairs(g, cam) -> int:
    """Tile–Gaussian pairs of scene `g` through `cam`."""
    p = jax.jit(project)(g, cam)
    return int(jax.jit(binning.count_pairs, static_argnums=(1, 2))(p, cam.width, cam.height))


def ours_forward(g, cam, rows):
    """Timed callables (stages and pair prep at the default capacity, then raster and e2e per
    row at the row's capacity), images, memory, pairs and {row: capacity}."""
    w, h = cam.width, cam.height
    n_pairs = count_pairs(g, cam)
    p, bins, stages = pipeline_stages(g, cam, lgs_jax.pair_capacity(n_pairs))
    bin_at = jax.jit(binning.bin_gaussians, static_argnums=(1, 2, 3))
    tiles_x = tile_grid(w, h)[0]

    def pair_prep(p, b):
        pg = pairs.gather(p, b.gauss)
        masks = pairs.strip_masks(pg, b, tiles_x, C())
        return kernel_steps.pair_records(pg, b, tiles_x, C(), masks)

    prep = jax.jit(pair_prep)
    fns = {f"ours:{k}": lambda f=f: jax.block_until_ready(f()) for k, f in stages.items()}
    images, memory, caps = {}, {}, {}
    for name in rows:
        backend, config, cap = row_setup(name, n_pairs)
        caps[name] = cap
        if builds_records_in_xla(backend, config, bins.tile_start.shape[0], cap):
            fns["ours:pair_prep"] = lambda: jax.block_until_ready(prep(p, bins))
        rasterize = REGISTRY[backend].rasterize
        e2e = jax.jit(lambda g, c, b=backend, cf=config, cap=cap: lgs_jax.render(
            g, c, backend=b, config=cf, capacity=cap).image)
        raster = jax.jit(lambda p, b, r=rasterize, cf=config: r(p, b, w, h, cf).color)
        row_bins = bins if cap == bins.tile.shape[0] else bin_at(p, w, h, cap)
        images[name] = np.asarray(e2e(g, cam))
        memory[name] = compiled_mib(e2e, g, cam)
        fns[f"{name}:raster"] = lambda r=raster, b=row_bins: jax.block_until_ready(r(p, b))
        fns[f"{name}:e2e"] = lambda f=e2e: jax.block_until_ready(f(g, cam))
        fns[f"{name}:e2e_queued"] = lambda f=e2e: jax.block_until_ready(
            [f(g, cam) for _ in range(QUEUED)])
    return fns, images, memory, n_pairs, caps


def gsplat_peer(g, cam):
    """gsplat 1.5.3 on the same scene and camera: (timed callables, image, peak MiB, pairs), or
    None where gsplat does not import."""
    try:
        import torch
        from gsplat import rasterization
        from gsplat.cuda._wrapper import (fully_fused_projection, isect_offset_encode,
                                          isect_tiles, rasterize_to_pixels, spherical_harmonics)
    except Exception as e:  # noqa: BLE001 - any import failure means no peer
        print(f"gsplat unavailable: {e}", file=sys.stderr)
        return None
    dev = torch.device("cuda")
    t = lambda x: torch.from_numpy(np.ascontiguousarray(np.asarray(x, np.float32))).to(dev)
    viewmat = t(cam.viewmat)[None]
    K = t([[cam.fx, 0, cam.cx], [0, cam.fy, cam.cy], [0, 0, 1]])[None]
    deg = int(round(np.sqrt(g.sh.shape[1]))) - 1
    w, h, near, far = cam.width, cam.height, float(cam.near), float(cam.far)
    means, quats, sh = t(g.means), t(g.quats), t(g.sh)
    scales, opac = torch.exp(t(g.log_scales)), torch.sigmoid(t(g.logit_opacities))
    sync = torch.cuda.synchronize

    def render():
        return rasterization(means, quats, scales, opac, sh, viewmat, K, w, h, near_plane=near,
                             far_plane=far, sh_degree=deg, packed=False,
                             rasterize_mode="classic")[0]

    def e2e():
        out = render()
        sync()
        return out

    def e2e_queued():
        out = [render() for _ in range(QUEUED)]
        sync()
        return out

    def proj():
        radii, m2d, depths, conics, _ = fully_fused_projection(
            means, None, quats, scales, viewmat, K, w, h, near_plane=near, far_plane=far,
            opacities=opac)
        dirs = means[None] - torch.linalg.inv(viewmat)[:, None, :3, 3]
        colors = spherical_harmonics(deg, dirs, sh[None].expand(1, -1, -1, -1),
                                     masks=(radii > 0).all(dim=-1))
        out = radii, m2d, depths, conics, torch.clamp_min(colors + 0.5, 0.0)
        sync()
        return out

    radii, m2d, depths, conics, colors = proj()
    tw, th = tile_grid(w, h)
    isect = lambda: (isect_tiles(m2d, radii, depths, 16, tw, th, packed=False), sync())[0]
    _, isect_ids, flatten_ids = isect()
    offsets = lambda: (isect_offset_encode(isect_ids, 1, tw, th).reshape(1, th, tw), sync())[0]
    offs = offsets()
    raster = lambda: (rasterize_to_pixels(m2d, conics, colors, opac[None], w, h, 16, offs,
                                          flatten_ids), sync())
    image = e2e()[0].float().cpu().numpy()
    fns = {"gsplat:project": proj, "gsplat:emit": isect, "gsplat:sort": offsets,
           "gsplat:raster": raster, "gsplat:e2e": e2e, "gsplat:e2e_queued": e2e_queued}
    return fns, image, torch_peak_mib(e2e), int(isect_ids.shape[0])


def forward_rows(scene: str, g, cam, rows, repeat: int, with_gsplat: bool):
    g, cam = jax.device_put(g), jax.device_put(cam)
    fns, images, memory, n_pairs, caps = ours_forward(g, cam, rows)
    peer = gsplat_peer(g, cam) if with_gsplat else None
    if peer:
        fns.update(peer[0])
    ms = {k: t / QUEUED if k.endswith(":e2e_queued") else t  # per call
          for k, t in median_ms(fns, repeat).items()}
    base = dict(scene=scene, gaussians=g.num, width=cam.width, height=cam.height)
    n_tiles = int(np.prod(tile_grid(cam.width, cam.height)))
    out = []
    for name in rows:
        r = dict(base, row=name, pairs=n_pairs, capacity=caps[name], project_ms=ms["ours:project"],
                 emit_ms=ms["ours:emit"], sort_ms=ms["ours:sort"],
                 raster_ms=ms[f"{name}:raster"], e2e_ms=ms[f"{name}:e2e"],
                 e2e_queued_ms=ms[f"{name}:e2e_queued"], memory_mib=memory[name],
                 same_image_as_first_row=bool(np.array_equal(images[name], images[rows[0]])))
        if builds_records_in_xla(*row_setup(name, n_pairs)[:2], n_tiles, caps[name]):
            r["pair_prep_ms"] = ms["ours:pair_prep"]
        if peer:
            r.update(psnr_vs_gsplat=psnr(images[name], peer[1]),
                     e2e_vs_gsplat=r["e2e_ms"] / ms["gsplat:e2e"],
                     e2e_queued_vs_gsplat=r["e2e_queued_ms"] / ms["gsplat:e2e_queued"],
                     memory_vs_gsplat=r["memory_mib"] / peer[2])
        out.append(r)
    if peer:
        out.append(dict(base, row="gsplat", pairs=peer[3], project_ms=ms["gsplat:project"],
                        emit_ms=ms["gsplat:emit"], sort_ms=ms["gsplat:sort"],
                        raster_ms=ms["gsplat:raster"], e2e_ms=ms["gsplat:e2e"],
                        e2e_queued_ms=ms["gsplat:e2e_queued"], memory_mib=peer[2]))
    return out


def same_bits(scene: str, name: str, first, again) -> bool:
    """Whether two calls' gradients have the same bits (NaNs included, which `array_equal`
    calls unequal); where not, which fields differ, in how many elements and by how much, to
    stderr."""
    same = True
    for (path, x), y in zip(jax.tree_util.tree_leaves_with_path(first), jax.tree.leaves(again)):
        x, y = np.atleast_1d(np.asarray(x)), np.atleast_1d(np.asarray(y))
        differ = x.view(np.uint8).reshape(x.shape + (-1,)) != y.view(np.uint8).reshape(
            y.shape + (-1,))
        if differ.any():
            same = False
            nans = [int(np.isnan(v).sum()) if np.issubdtype(v.dtype, np.floating) else 0
                    for v in (x, y)]
            print(f"{scene} {name}: {jax.tree_util.keystr(path)} differs between two calls "
                  f"in {int(differ.any(-1).sum())} of {x.size} elements (largest difference "
                  f"{float(np.nanmax(np.abs(x - y), initial=0)):.3g}, NaNs {nans[0]} / {nans[1]})",
                  file=sys.stderr)
    return same


def grad_rows(scene: str, g, cam, rows, repeat: int, with_gsplat: bool):
    g, cam = jax.device_put(g), jax.device_put(cam)
    w, h = cam.width, cam.height
    n_pairs = count_pairs(g, cam)
    weights = jax.random.normal(jax.random.key(0), (h, w, 3), jnp.float32)
    fns, extra = {}, {}
    for name in rows:
        backend, config, cap = row_setup(name, n_pairs)
        row_cap = walked = None
        if name.endswith(WALKED):
            walked = int(lgs_jax.render(g, cam, backend=backend, config=config,
                                        capacity=cap).stats.backend_stats.pairs_walked)
            row_cap = lgs_jax.pair_capacity(walked)
        # w is an argument: closed over, XLA would constant-fold the image-sized weights into
        # the backward (minutes of compilation at 4K).
        def loss(g, w, b=backend, cf=config, cap=cap, rc=row_cap):
            out = lgs_jax.render(g, cam, backend=b, config=cf, capacity=cap, row_capacity=rc)
            return jnp.sum(out.image * w), out.stats.backend_stats.row_overflow

        f = jax.jit(jax.value_and_grad(loss, has_aux=True))
        (_, overflow), first = f(g, weights)
        same = same_bits(scene, name, first, f(g, weights)[1])
        if bool(overflow):
            print(f"{scene} {name}: row capacity {row_cap} overflowed", file=sys.stderr)
        extra[name] = dict(capacity=cap, row_capacity=row_cap, pairs_walked=walked,
                           memory_mib=compiled_mib(f, g, weights), bitwise_repeatable=same)
        fns[name] = lambda f=f: jax.block_until_ready(f(g, weights))
    if with_gsplat:
        step = gsplat_grad_step(g, cam, weights)
        if step:
            fns["gsplat"] = step
            extra["gsplat"] = dict(memory_mib=torch_peak_mib(step))
    ms = median_ms(fns, repeat)
    out = []
    for name in fns:
        r = dict(scene=scene, gaussians=g.num, width=w, height=h, row=f"grad:{name}",
                 fwd_bwd_ms=ms[name], **extra[name])
        if "gsplat" in fns:
            r.update(fwd_bwd_vs_gsplat=ms[name] / ms["gsplat"],
                     memory_vs_gsplat=r["memory_mib"] / extra["gsplat"]["memory_mib"])
        out.append(r)
    return out


def cuda_f32(x):
    """`x` as a float32 torch tensor on the GPU."""
    import torch

    return torch.from_numpy(np.ascontiguousarray(np.asarray(x, np.float32))).to("cuda")


def gsplat_draw(cam, sh_degree: int):
    """draw(means, quats, log_scales, logit_opacities, sh) -> (1, H, W, 3): gsplat's
    rasterization of view `cam` from our parameter layout (torch tensors on the GPU)."""
    import torch
    from gsplat import rasterization

    viewmat = cuda_f32(cam.viewmat)[None]
    K = cuda_f32([[cam.fx, 0, cam.cx], [0, cam.fy, cam.cy], [0, 0, 1]])[None]

    def draw(means, quats, log_scales, logit_opacities, sh):
        return rasterization(means, quats, torch.exp(log_scales), torch.sigmoid(logit_opacities),
                             sh, viewmat, K, cam.width, cam.height, near_plane=float(cam.near),
                             far_plane=float(cam.far), sh_degree=sh_degree, packed=False,
                             rasterize_mode="classic")[0]

    return draw


def gsplat_grad_step(g, cam, weights):
    """gsplat's rasterization + backward() of Σ image·w w.r.t. all parameters, or None."""
    try:
        import torch
        draw = gsplat_draw(cam, int(round(np.sqrt(g.sh.shape[1]))) - 1)
    except Exception as e:  # noqa: BLE001
        print(f"gsplat unavailable: {e}", file=sys.stderr)
        return None
    params = [cuda_f32(x) for x in (g.means, g.quats, g.log_scales, g.logit_opacities, g.sh)]
    for x in params:
        x.requires_grad_(True)
    tw = cuda_f32(weights)

    def step():
        for x in params:
            x.grad = None
        (draw(*params)[0] * tw).sum().backward()
        torch.cuda.synchronize()

    return step


def _format(r) -> str:
    head = f"{r['scene']:>18s} {r['gaussians'] / 1e6:5.2f}M {r['row']:<16s}"
    if "fwd_bwd_ms" in r:
        vs = (f" | {r['fwd_bwd_vs_gsplat']:5.2f}x time {r['memory_vs_gsplat']:5.2f}x memory of "
              f"gsplat" if "fwd_bwd_vs_gsplat" in r else "")
        same = {True: " bitwise", False: " NOT BITWISE"}.get(r.get("bitwise_repeatable"), "")
        cap = f" cap {r['capacity'] / 1e6:6.2f}M" if "capacity" in r else ""
        if r.get("row_capacity"):  # the buffer, then the walked pairs it was sized for
            cap += f" rows {r['row_capacity'] / 1e6:6.2f}M ({r['pairs_walked'] / 1e6:.2f}M)"
        return (f"{head} fwd+bwd {r['fwd_bwd_ms']:8.2f} ms mem {r['memory_mib']:8.0f} MiB{cap}"
                f"{vs}{same}")
    vs = (f" | {r['e2e_vs_gsplat']:5.2f}x time ({r['e2e_queued_vs_gsplat']:5.2f}x queued) "
          f"{r['memory_vs_gsplat']:5.2f}x memory of gsplat, {r['psnr_vs_gsplat']:5.1f} dB"
          if "e2e_vs_gsplat" in r else "")
    prep = f" (pair prep {r['pair_prep_ms']:6.2f})" if "pair_prep_ms" in r else ""
    cap = f" cap {r['capacity'] / 1e6:6.2f}M" if "capacity" in r else ""
    if r.get("same_image_as_first_row") is False:  # its image differs from the first row's
        cap += " (image != first row's)"
    return (f"{head} e2e {r['e2e_ms']:7.2f} (queued {r['e2e_queued_ms']:7.2f}) raster "
            f"{r['raster_ms']:7.2f}{prep} proj {r['project_ms']:6.2f} emit {r['emit_ms']:6.2f} "
            f"sort {r['sort_ms']:6.2f} ms "
            f"mem {r['memory_mib']:7.0f} MiB pairs {r['pairs'] / 1e6:6.2f}M{cap}{vs}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.scale", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    add_data_argument(ap)
    ap.add_argument("--scenes", default=",".join(SCENES))
    ap.add_argument("--rows", default="localgs,localgs:fast,vanilla")
    ap.add_argument("--grad", action="store_true")
    ap.add_argument("--repeat", type=int, default=20)
    ap.add_argument("--big-repeat", type=int, default=7, help="rounds for >= 5M Gaussians")
    ap.add_argument("--no-gsplat", action="store_true")
    ap.add_argument("--csv")
    args = ap.parse_args(argv)
    rows = args.rows.split(",")
    for name in rows:
        if _row_key(name) not in ROWS:
            ap.error(f"--rows: unknown row {name!r} (known: {', '.join(ROWS)}, each optionally "
                     f"with the suffix {POW2}, or with --grad {WALKED})")
        if name.endswith(WALKED) and not args.grad:
            ap.error(f"--rows: {name!r}: the suffix {WALKED} sizes the backward (--grad)")
    print(f"device {jax.devices()[0].device_kind}; JAX {jax.__version__}", flush=True)
    results = []
    for scene in args.scenes.split(","):
        g, cam = load_scene(scene, args.data)
        repeat = args.big_repeat if g.num >= 5_000_000 else args.repeat
        run = grad_rows if args.grad else forward_rows
        for r in run(scene, g, cam, rows, repeat, not args.no_gsplat):
            print(_format(r), flush=True)
            results.append(r)
    if args.csv:
        with open(args.csv, "w", newline="") as f:
            wr = csv.DictWriter(f, fieldnames=list(dict.fromkeys(k for r in results for k in r)))
            wr.writeheader()
            wr.writerows(results)
    return 0


if __name__ == "__main__":
    sys.exit(main())
