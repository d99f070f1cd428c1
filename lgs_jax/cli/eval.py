"""`python -m lgs_jax eval`: a scene's PSNR and SSIM on a capture's views (lgs_jax.train.evaluate),
for a `fit` run's scene.ply or another trainer's INRIA PLY file."""

from __future__ import annotations

import json
import os

from .args import (check_dataset, check_input, check_out_dir, int_at_least, load_scene,
                   raster_config)
from ..config import CONVENTIONS


def parser(sub, common) -> None:
    """The `eval` subcommand's options."""
    from ..render import BACKENDS

    e = sub.add_parser(
        "eval", parents=[common], help="score a scene on a capture's views (PSNR, SSIM)",
        description="Render the scene at the views of a capture (load_dataset: COLMAP, "
                    "transforms.json, NeRF-synthetic; --split test: every 8th image, as fit "
                    "holds out) and score each against its image as fit's evaluations do "
                    "(scikit-image's PSNR and SSIM). Prints each view and the means; --out "
                    "writes eval_<name>.png (render beside the image) and metrics.json.")
    e.add_argument("scene", help="INRIA PLY file (e.g. a fit run's scene.ply)")
    e.add_argument("--data", required=True, help="dataset folder (or transforms json)")
    e.add_argument("--downscale", type=int_at_least(1), default=1,
                   help="integer image downscale at load, as the scene was trained (default: 1)")
    e.add_argument("--split", choices=["test", "train", "all"], default="test",
                   help="the views to score (default: test, the held-out ones)")
    e.add_argument("--backend", default=None, choices=BACKENDS,
                   help="rasterizer (default: pallas on a GPU, tiles elsewhere)")
    e.add_argument("--convention", choices=CONVENTIONS, default="3dgs",
                   help="compositing rule the scene was trained with (default: 3dgs)")
    e.add_argument("--antialiased", action="store_true",
                   help="the scene was trained antialiased (fit --antialiased)")
    e.add_argument("--out", help="folder for the renders and metrics.json")
    e.set_defaults(func=run)


def run(args) -> int:
    """`eval`: check the paths, load, render, score, print."""
    from lgs_jax import train

    check_input(args.scene, "scene")
    check_dataset(args.data)
    if args.out:
        check_out_dir(args.out)
    result = train.evaluate(load_scene(args.scene), args.data, split=args.split,
                            downscale=args.downscale, backend=args.backend,
                            config=raster_config(args), out=args.out)
    for v in result["views"]:
        print(f"{v['name']:>24s}  PSNR {v['psnr']:6.2f} dB  SSIM {v['ssim']:.4f}")
    print(f"{args.split} views: {len(result['views'])}; mean PSNR {result['psnr']:.2f} dB, "
          f"SSIM {result['ssim']:.4f} ({result['gaussians']} Gaussians, backend "
          f"{result['backend']})")
    if args.out:
        print(f"wrote {os.path.join(args.out, 'metrics.json')}")
    else:
        print(json.dumps({k: result[k] for k in ("psnr", "ssim")}))
    return 0
