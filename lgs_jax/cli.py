"""Command line: `python -m lgs_jax render ...`, `python -m lgs_jax info SCENE.ply` and
`python -m lgs_jax fit --data DIR --steps N --out DIR` (lgs_jax.train)."""

from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np

DEFAULT_BACKEND = "tiles"  # the fastest exact backend available (exact blending by default)


def _render(args) -> int:
    import jax

    import lgs_jax

    scene = lgs_jax.load_ply(args.scene) if args.scene else lgs_jax.default_scene()
    if args.cameras:
        cams = lgs_jax.load_cameras(args.cameras, width=args.width, height=args.height)
        if not 0 <= args.view < len(cams):
            raise SystemExit(f"--view: {args.view} out of range, {args.cameras} has {len(cams)}")
        cam = cams[args.view]
    elif args.scene:
        raise SystemExit("--cameras: needed to render a scene file (the default scene has its own)")
    else:
        cam = lgs_jax.default_camera(args.view, args.width, args.height)
    bg = np.asarray(args.background, np.float32)
    config = lgs_jax.RasterConfig(convention=args.convention)
    t0 = time.perf_counter()
    out = lgs_jax.render(scene, cam, background=bg, backend=args.backend, config=config)
    jax.block_until_ready(out)
    t1 = time.perf_counter()
    out = lgs_jax.render(scene, cam, background=bg, backend=args.backend, config=config,
                         capacity=int(out.stats.capacity) or None)
    jax.block_until_ready(out)
    t2 = time.perf_counter()
    s = out.stats
    print(f"scene: {scene.num} Gaussians (SH degree {scene.sh_degree}); image {cam.width}x"
          f"{cam.height}; backend {s.backend}; device {jax.devices()[0].platform}")
    print(f"first call (compile + run): {t1 - t0:.3f} s; second call: {1e3 * (t2 - t1):.1f} ms")
    print(f"valid {int(s.n_valid)}, invalid {int(s.n_invalid)}, below 1/255 "
          f"{int(s.n_transparent)}, unbounded {int(s.n_unbounded)}; tile-Gaussian pairs "
          f"{int(s.pairs_required)} (capacity {int(s.capacity)})")
    import matplotlib.image

    matplotlib.image.imsave(args.out, np.clip(np.asarray(out.image), 0.0, 1.0))
    print(f"wrote {args.out}")
    return 0


def _info(args) -> int:
    import lgs_jax

    g = lgs_jax.load_ply(args.scene)
    print(f"{args.scene}: {g.num} Gaussians, SH degree {g.sh_degree}, dtype {g.means.dtype}")
    m = np.asarray(g.means)
    fin = np.all(np.isfinite(m), -1)
    if fin.any():
        print(f"bounds: min {m[fin].min(0)}, max {m[fin].max(0)}")
    for name in ("means", "quats", "log_scales", "logit_opacities", "sh"):
        v = np.asarray(getattr(g, name))
        print(f"{name:16s} nan {int(np.isnan(v).sum()):8d}  +inf {int((v == np.inf).sum()):8d}  "
              f"-inf {int((v == -np.inf).sum()):8d}")
    o = 1 / (1 + np.exp(-np.asarray(g.logit_opacities, np.float64)))
    print(f"opacity below 1/255: {int((o < 1 / 255).sum())}; exactly 1: {int((o == 1).sum())}")
    return 0


def _fit(args) -> int:
    import dataclasses

    from . import train

    settings = dataclasses.replace(train.Settings(), batch=args.batch,
                                   eval_every=args.eval_every)
    crop = tuple(args.crop) if args.crop else None
    result = train.fit(args.data, args.steps, args.out, n_gaussians=args.gaussians,
                       resume=args.resume, settings=settings, seed=args.seed, crop=crop,
                       backend=args.backend)
    print(json.dumps(result, indent=1))
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m lgs_jax", description=__doc__)
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("render", help="render a scene (the bundled default scene if none given)")
    r.add_argument("scene", nargs="?", help="INRIA PLY file")
    r.add_argument("--cameras", help="cameras.json or transforms.json")
    r.add_argument("--view", type=int, default=0)
    r.add_argument("--width", type=int)
    r.add_argument("--height", type=int)
    r.add_argument("--backend", default=DEFAULT_BACKEND)
    r.add_argument("--convention", default="3dgs", choices=["3dgs", "gsplat"])
    r.add_argument("--background", type=float, nargs=3, default=[0.0, 0.0, 0.0])
    r.add_argument("--out", default="out.png")
    r.set_defaults(func=_render)
    i = sub.add_parser("info", help="print counts, SH degree, bounds and non-finite values")
    i.add_argument("scene")
    i.set_defaults(func=_info)
    f = sub.add_parser("fit", help="train Gaussians on a NeRF-synthetic folder (ids 0,10,..,90 "
                                   "held out); writes scene.ply, metrics.jsonl, held-out renders")
    f.add_argument("--data", required=True, help="folder with transforms_train.json")
    f.add_argument("--steps", type=int, required=True)
    f.add_argument("--out", required=True)
    f.add_argument("--gaussians", type=int, default=20000)
    f.add_argument("--batch", type=int, default=1, help="views per step")
    f.add_argument("--eval-every", type=int, default=500)
    f.add_argument("--crop", type=int, nargs=4, metavar=("X0", "Y0", "W", "H"))
    f.add_argument("--seed", type=int, default=0)
    f.add_argument("--backend", default=None,
                   choices=["reference", "tiles", "pallas", "pallas_vanilla"],
                   help="differentiable backend (default: pallas on GPUs, tiles elsewhere)")
    f.add_argument("--resume", action="store_true", help="continue from OUT's checkpoint")
    f.set_defaults(func=_fit)
    args = ap.parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
