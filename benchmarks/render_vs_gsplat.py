"""GPU benchmark of the Pallas kernels against gsplat 1.5.3, same process, scenes and cameras.

    XLA_PYTHON_CLIENT_PREALLOCATE=false python -m benchmarks.render_vs_gsplat --preset issue5 \\
        [--scene SPEC ...] [--data DIR] [--repeat 30] [--csv FILE] [--grad]

Scene SPECs: benchmarks.common. Rows (`common.PALLAS_ROWS`, `--rows`) per scene and camera:
`pallas` (Local-GS, exact and fast blending), `pallas_vanilla`, `tiles` (XLA; fewer rounds: it
is slow on GPUs) and `gsplat` (`rasterization(..., packed=False, rasterize_mode="classic")`,
when gsplat imports; `--antialiased`: both in antialiased mode). Per row: the rasterization stage
(`raster_ms`: our kernel call with its mask and row packing, from projected and binned inputs;
gsplat's `rasterize_to_pixels` from its own intersections), the end-to-end forward
(`e2e_ms`: one jitted `render` from device-resident parameters / one `rasterization` call), the
shared stages (`project_ms`, `emit_ms` = pair emission, `sort_ms` = tile sort and ranges;
gsplat: projection + SH, intersection, offsets), tile–Gaussian pairs, peak memory (ours: XLA's
compiled buffer sizes for the e2e program; gsplat: torch's peak allocation in the call), and
the error against gsplat's image (max abs, PSNR) and, where it fits (`--f64-max-pixels`), against
the float64 reference. `--grad` times forward + backward instead (the differentiable backend
against gsplat's `rasterization` + `backward()`). Times are medians of `--repeat` calls after
warm-up, each ended by `block_until_ready` / `torch.cuda.synchronize`; rows alternate within
each round (`common.median_ms`).
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import sys
import types

import jax
import jax.numpy as jnp
import numpy as np

from lgs_jax import render
from lgs_jax.backends import REGISTRY, pallas
from lgs_jax.config import RasterConfig

from .common import (GRAD_ROWS, PALLAS_ROWS, add_data_argument, median_ms, parse_scene,
                     pipeline_stages, psnr, torch_peak_mib)

C = RasterConfig


def _row(backend, config):
    """(backend, config, rasterize stage from projected and binned inputs) of a forward row."""
    rasterize = REGISTRY[backend].rasterize
    return backend, config, lambda p, b, w, h: rasterize(p, b, w, h, config)


OURS = {name: _row(*row) for name, row in PALLAS_ROWS.items()}
PRESETS = {"issue5": ["guitar@1280x720", "guitar@3840x2160", "lego_sh3@800x800",
                      "lego_sh3@3200x3200", "synthetic:1000000@1280x720",
                      "synthetic:3000000@1280x720"]}


def _median_ms(fns, repeat, sync):
    """common.median_ms of callables whose results `sync` blocks on."""
    return median_ms({name: lambda f=f: sync(f()) for name, f in fns.items()}, repeat)


def _ours(case, repeat, slow_repeat, f64_max_pixels, names=tuple(OURS), antialiased=False):
    g = jax.device_put(case.scene)
    cam = jax.device_put(case.camera)
    w, h = cam.width, cam.height
    first = render(g, cam, backend="pallas")
    cap = int(first.stats.capacity)
    p, bins, stage_fns = pipeline_stages(g, cam, cap)
    stages = _median_ms(stage_fns, repeat, jax.block_until_ready)
    images, memory, fns, slow_fns = {}, {}, {}, {}
    for name in names:
        backend, config, stage = OURS[name]
        config = dataclasses.replace(config, antialiased=antialiased)
        f = jax.jit(lambda g, c, b=backend, cf=config: render(g, c, backend=b, config=cf,
                                                               capacity=cap).image)
        r = jax.jit(lambda p, b, st=stage: st(p, b, w, h).color)
        try:
            images[name] = np.asarray(f(g, cam))
            jax.block_until_ready(r(p, bins))
        except Exception as e:  # noqa: BLE001 - report the row that does not compile, go on
            print(f"{case.name} {name}: failed: {type(e).__name__}: {str(e)[:300]}",
                  file=sys.stderr, flush=True)
            continue
        mem = f.lower(g, cam).compile().memory_analysis()
        memory[name] = None if mem is None else (mem.temp_size_in_bytes + mem.argument_size_in_bytes
                                                 + mem.output_size_in_bytes)
        target = slow_fns if name == "tiles" else fns
        target[f"e2e:{name}"] = lambda f=f: f(g, cam)
        target[f"raster:{name}"] = lambda r=r: r(p, bins)
    times = _median_ms(fns, repeat, jax.block_until_ready)  # all rows alternate in each round
    times.update(_median_ms(slow_fns, slow_repeat, jax.block_until_ready))
    truth = None
    if w * h <= f64_max_pixels:
        g64 = jax.tree.map(lambda x: jnp.asarray(x, jnp.float64), g)
        truth = np.asarray(render(g64, cam, backend="reference", capacity=cap,
                                  config=C(antialiased=antialiased)).image)
    rows = []
    for name in images:
        row = dict(scene=case.name, width=w, height=h, gaussians=case.scene.num, row=name,
                   raster_ms=times[f"raster:{name}"], e2e_ms=times[f"e2e:{name}"],
                   project_ms=stages["project"], emit_ms=stages["emit"], sort_ms=stages["sort"],
                   pairs=int(first.stats.pairs_required), peak_mb=memory[name] / 2**20
                   if memory[name] else "")
        if truth is not None:
            err = np.abs(images[name].astype(np.float64) - truth)
            row.update(max_err_f64=float(err.max()), psnr_f64=psnr(images[name], truth))
        rows.append(row)
    return rows, images


def _gsplat_peer(case, antialiased=False):
    """gsplat's view of a case: to_torch(x) (a float32 CUDA tensor), the camera as gsplat takes
    it (viewmat (1, 4, 4), K (1, 3, 3), near, far) and the SH degree, and render(means, quats,
    scales, opacities, sh): `gsplat.rasterization`'s image (1, H, W, 3) through that camera
    (packed=False, classic or antialiased)."""
    import gsplat
    import torch

    dev = torch.device("cuda")
    cam = case.camera
    to_torch = lambda x: torch.from_numpy(np.ascontiguousarray(np.asarray(x, np.float32))).to(dev)
    viewmat = to_torch(cam.viewmat)[None]
    K = to_torch([[cam.fx, 0, cam.cx], [0, cam.fy, cam.cy], [0, 0, 1]])[None]
    deg = int(round(np.sqrt(case.scene.sh.shape[1]))) - 1
    near, far = float(cam.near), float(cam.far)
    mode = "antialiased" if antialiased else "classic"

    def render(means, quats, scales, opacities, sh):
        return gsplat.rasterization(means, quats, scales, opacities, sh, viewmat, K, cam.width,
                                    cam.height, near_plane=near, far_plane=far, sh_degree=deg,
                                    packed=False, rasterize_mode=mode)[0]

    return types.SimpleNamespace(to_torch=to_torch, viewmat=viewmat, K=K, near=near, far=far,
                                 deg=deg, render=render)


def _gsplat(case, repeat, antialiased=False):
    """gsplat 1.5.3's forward on the same scene and camera: (row, image) or None (its stages'
    timings are the classic mode's)."""
    try:
        import torch
        from gsplat.cuda._wrapper import (fully_fused_projection, isect_offset_encode,
                                          isect_tiles, rasterize_to_pixels, spherical_harmonics)
    except Exception as e:  # noqa: BLE001 - any import failure means no peer
        print(f"gsplat unavailable: {e}", file=sys.stderr)
        return None
    g, cam = case.scene, case.camera
    peer = _gsplat_peer(case, antialiased)
    t, viewmat, K, deg = peer.to_torch, peer.viewmat, peer.K, peer.deg
    near, far = peer.near, peer.far
    means, quats = t(g.means), t(g.quats)
    scales, opac = torch.exp(t(g.log_scales)), torch.sigmoid(t(g.logit_opacities))
    sh = t(g.sh)
    w, h = cam.width, cam.height
    sync = lambda _: torch.cuda.synchronize()

    def full():
        return peer.render(means, quats, scales, opac, sh)

    def proj():
        radii, m2d, depths, conics, _ = fully_fused_projection(
            means, None, quats, scales, viewmat, K, w, h, near_plane=near, far_plane=far,
            opacities=opac)  # as rasterization() calls it
        dirs = means[None] - torch.linalg.inv(viewmat)[:, None, :3, 3]
        colors = spherical_harmonics(deg, dirs, sh[None].expand(1, -1, -1, -1),
                                     masks=(radii > 0).all(dim=-1))
        colors = torch.clamp_min(colors + 0.5, 0.0)
        return radii, m2d, depths, conics, colors

    radii, m2d, depths, conics, colors = proj()
    tw, th = -(-w // 16), -(-h // 16)

    def isect():
        return isect_tiles(m2d, radii, depths, 16, tw, th, packed=False)

    _, isect_ids, flatten_ids = isect()

    def offsets():
        return isect_offset_encode(isect_ids, 1, tw, th).reshape(1, th, tw)

    offs = offsets()
    op = opac[None]

    def raster():
        return rasterize_to_pixels(m2d, conics, colors, op, w, h, 16, offs, flatten_ids)

    image = full()
    peak = torch_peak_mib(full)
    times = _median_ms({"e2e": full, "project": proj, "isect": isect, "offsets": offsets,
                        "raster": raster}, repeat, sync)
    row = dict(scene=case.name, width=w, height=h, gaussians=g.num, row="gsplat",
               raster_ms=times["raster"], e2e_ms=times["e2e"], project_ms=times["project"],
               emit_ms=times["isect"], sort_ms=times["offsets"], pairs=int(isect_ids.shape[0]),
               peak_mb=peak)
    return row, image[0].float().cpu().numpy()


def _grad_rows(case, repeat, slow_repeat, names=tuple(GRAD_ROWS)):
    """Forward + backward of sum(image · W) w.r.t. all parameters: each differentiable backend
    (jitted value_and_grad; `tiles` and `reference` for `slow_repeat` rounds) and gsplat
    (rasterization + backward()), alternating within each round; plus our forward alone, and
    whether two gradient calls give the same bits."""
    g = jax.device_put(case.scene)
    cam = jax.device_put(case.camera)
    w, h = cam.width, cam.height
    cap = int(render(g, cam).stats.capacity)
    weights = jax.random.normal(jax.random.key(0), (h, w, 3), jnp.float32)
    fns, fwd, rows = {}, {}, {}
    for name in names:
        backend, config = GRAD_ROWS[name]
        image = lambda g, b=backend, c=config: render(g, cam, backend=b, config=c,
                                                      capacity=cap).image
        # w is an argument: closed over, XLA would constant-fold the image-sized weights.
        f = jax.jit(jax.value_and_grad(lambda g, w, image=image: jnp.sum(image(g) * w)))
        fwd_f = jax.jit(image)
        mem = f.lower(g, weights).compile().memory_analysis()
        first, again = f(g, weights)[1], f(g, weights)[1]
        same = all(bool(jnp.array_equal(x, y)) for x, y in zip(jax.tree.leaves(first),
                                                                 jax.tree.leaves(again)))
        fns[name] = lambda f=f: jax.block_until_ready(f(g, weights))
        fwd[name] = lambda f=fwd_f: jax.block_until_ready(f(g))
        rows[name] = dict(scene=case.name, width=w, height=h, row=f"grad:{name}",
                          peak_mb=(mem.temp_size_in_bytes + mem.argument_size_in_bytes
                                   + mem.output_size_in_bytes) / 2**20 if mem else "",
                          bitwise_repeatable=same)
    try:
        import torch

        peer = _gsplat_peer(case)
    except Exception as e:  # noqa: BLE001 - any import failure means no peer
        print(f"gsplat unavailable: {e}", file=sys.stderr)
        peer = None
    if peer is not None:
        t = peer.to_torch
        params = [t(case.scene.means), t(case.scene.quats), t(case.scene.log_scales),
                  t(case.scene.logit_opacities), t(case.scene.sh)]
        for x in params:
            x.requires_grad_(True)
        tw = t(np.asarray(weights))

        def gsplat_fwd():
            img = peer.render(params[0], params[1], torch.exp(params[2]),
                              torch.sigmoid(params[3]), params[4])
            torch.cuda.synchronize()
            return img

        def gsplat_step():
            (gsplat_fwd()[0] * tw).sum().backward()
            torch.cuda.synchronize()

        gsplat_step()
        fns["gsplat"], fwd["gsplat"] = gsplat_step, gsplat_fwd
        rows["gsplat"] = dict(scene=case.name, width=w, height=h, row="grad:gsplat",
                              peak_mb=torch_peak_mib(gsplat_step))
    slow = {"tiles", "reference"}
    for part, key in ((fns, "fwd_bwd_ms"), (fwd, "fwd_ms")):
        times = _median_ms({k: v for k, v in part.items() if k not in slow}, repeat, lambda _: 0)
        times.update(_median_ms({k: v for k, v in part.items() if k in slow}, slow_repeat,
                                lambda _: 0))
        for name, ms in times.items():
            rows[name][key] = ms
    for r in rows.values():
        r["bwd_ms"] = r["fwd_bwd_ms"] - r["fwd_ms"]
        if peer is not None:
            r["fwd_bwd_vs_gsplat"] = r["fwd_bwd_ms"] / rows["gsplat"]["fwd_bwd_ms"]
    return list(rows.values())


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.render_vs_gsplat", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", action="append", default=[],
                    help="scene SPEC (benchmarks.common; repeatable)")
    ap.add_argument("--preset", choices=sorted(PRESETS))
    add_data_argument(ap)
    ap.add_argument("--repeat", type=int, default=30)
    ap.add_argument("--slow-repeat", type=int, default=3, help="rounds for the tiles row")
    ap.add_argument("--f64-max-pixels", type=int, default=1280 * 720)
    ap.add_argument("--no-gsplat", action="store_true")
    ap.add_argument("--grad", action="store_true",
                    help="forward+backward rows instead (differentiable backend vs gsplat)")
    ap.add_argument("--rows", default=",".join(OURS),
                    help=f"comma-separated forward rows, of {','.join(OURS)}")
    ap.add_argument("--grad-rows", default=",".join(GRAD_ROWS),
                    help=f"comma-separated rows for --grad, of {','.join(GRAD_ROWS)}")
    ap.add_argument("--antialiased", action="store_true",
                    help="forward rows in antialiased mode, ours and gsplat's (images, e2e)")
    ap.add_argument("--csv")
    args = ap.parse_args(argv)
    jax.config.update("jax_enable_x64", True)  # the float64 reference; renders stay float32
    specs = args.scene + (PRESETS[args.preset] if args.preset else [])
    dev = jax.devices()[0]
    print(f"device {dev.device_kind}; JAX {jax.__version__}; Pallas kernels interpreted: "
          f"{pallas.interpreted(C())}", flush=True)
    rows = []
    for spec in specs:
        case = parse_scene(spec, args.data)
        if args.grad:
            grad = _grad_rows(case, args.repeat, args.slow_repeat, args.grad_rows.split(","))
            for r in grad:
                print(_format_grad(r), flush=True)
            rows += grad
            continue
        ours, images = _ours(case, args.repeat, args.slow_repeat, args.f64_max_pixels,
                             args.rows.split(","), args.antialiased)
        peer = None if args.no_gsplat else _gsplat(case, args.repeat, args.antialiased)
        if peer:
            row, image = peer
            for r in ours:
                err = np.abs(images[r["row"]].astype(np.float64) - image)
                r.update(max_err_gsplat=float(err.max()), psnr_gsplat=psnr(images[r["row"]], image),
                         e2e_vs_gsplat=r["e2e_ms"] / row["e2e_ms"])
            ours.append(row)
        vanilla = next((r for r in ours if r["row"] == "pallas_vanilla"), ours[0])
        for r in ours:
            r["raster_speedup_vs_vanilla"] = vanilla["raster_ms"] / r["raster_ms"]
        rows += ours
        for r in ours:
            print(_format(r), flush=True)
    if args.csv:
        with open(args.csv, "w", newline="") as f:
            wr = csv.DictWriter(f, fieldnames=sorted({k for r in rows for k in r}))
            wr.writeheader()
            wr.writerows(rows)
    return 0


def _format_grad(r):
    ratio = f" | vs gsplat {r['fwd_bwd_vs_gsplat']:7.2f}" if "fwd_bwd_vs_gsplat" in r else ""
    same = {True: " bitwise repeatable", False: " NOT bitwise repeatable", None: ""}[
        r.get("bitwise_repeatable")]
    return (f"{r['scene']:>16s} {r['width']}x{r['height']} {r['row']:<20s} fwd+bwd "
            f"{r['fwd_bwd_ms']:9.3f} ms (fwd {r['fwd_ms']:8.3f} bwd {r['bwd_ms']:8.3f}) peak "
            f"{r['peak_mb']:8.1f} MB{ratio}{same}")


def _format(r):
    extra = (f" | vs gsplat {r['psnr_gsplat']:6.1f} dB e2e ratio {r['e2e_vs_gsplat']:5.2f}"
             if "psnr_gsplat" in r else "")
    return (f"{r['scene']:>16s} {r['width']}x{r['height']} {r['row']:<15s} raster "
            f"{r['raster_ms']:8.3f} e2e {r['e2e_ms']:8.3f} ms (proj {r['project_ms']:.3f} emit "
            f"{r['emit_ms']:.3f} sort {r['sort_ms']:.3f}) pairs {r['pairs']:>9d} "
            f"x{r['raster_speedup_vs_vanilla']:.2f} vs vanilla{extra}")


if __name__ == "__main__":
    sys.exit(main())
