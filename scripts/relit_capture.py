"""Experiment: a capture whose training photos are relit differently over the image, trained
plain, with colour corrections (`--color-opt`) and with appearance embeddings (`--app-opt`).

    python scripts/relit_capture.py [--data DIR] [--scene skull] [--downscale 16]
        [--steps 1000] [--modes plain,color_opt,app_opt,bilateral_grid] [--out DIR]

Each training photo k is multiplied by a gain that changes linearly across it,
g_k(x, y) = 1 + a_k · (x / W − 1/2) + b_k · (y / H − 1/2), with a_k, b_k uniform in ±0.8 (seed
0), clipped to [0, 1]: light that differs over the scene and from photo to photo, which one
affine colour map per photo cannot undo. Held-out photos are left as they are, so the held-out
score says how well each mode keeps the relighting out of the scene. Prints, per mode, the
training views' PSNR (mean of the last 10% of steps, against the relit photos), the held-out
PSNR and SSIM, and the seconds.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import tempfile
import time

import jax
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import lgs_jax  # noqa: E402
from lgs_jax import train  # noqa: E402
from lgs_jax.train import report  # noqa: E402
from lgs_jax.io.dataset import as_float  # noqa: E402


def relit(d, seed: int = 0):
    """The dataset with its training photos relit (module docstring), as float32 images."""
    rng = np.random.default_rng(seed)
    images = [as_float(im).copy() for im in d.images]
    for k in d.train:
        h, w = images[k].shape[:2]
        a, b = rng.uniform(-0.8, 0.8, 2)
        gain = (1 + a * (np.arange(w)[None, :] / w - 0.5)
                + b * (np.arange(h)[:, None] / h - 0.5))
        images[k] = np.clip(images[k] * gain[..., None], 0, 1).astype(np.float32)
    return dataclasses.replace(d, images=np.stack(images))


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--data", default=os.path.join(os.path.dirname(__file__), "..", "..",
                                                  "shared", "data"))
    p.add_argument("--scene", default="skull")
    p.add_argument("--downscale", type=int, default=16)
    p.add_argument("--steps", type=int, default=1000)
    p.add_argument("--modes", default="plain,color_opt,app_opt")
    p.add_argument("--out", default=None, help="run directories (default: a temporary one)")
    args = p.parse_args(argv)
    d = relit(lgs_jax.load_dataset(os.path.join(args.data, args.scene),
                                   downscale=args.downscale))
    out = args.out or tempfile.mkdtemp()
    print(f"{args.scene} at 1/{args.downscale}, {args.steps} steps, training photos relit "
          f"(seed 0), {jax.devices()[0].device_kind}, JAX {jax.__version__}")
    print("| mode | training PSNR (last 10%) | held-out PSNR | held-out SSIM | Gaussians | s |")
    print("|---|---:|---:|---:|---:|---:|", flush=True)
    for mode in args.modes.split(","):
        flags = {} if mode == "plain" else {mode: True}
        settings = train.Settings(eval_every=args.steps + 1, checkpoint_every=args.steps,
                                  **flags)
        t0 = time.perf_counter()
        r = train.fit(d, args.steps, os.path.join(out, mode), settings=settings,
                      overwrite=True, log=lambda m: None)
        metrics = report.read_metrics(os.path.join(out, mode, "metrics.jsonl"))
        psnrs = [m["psnr"] for m in metrics if "psnr" in m and "loss" in m]
        tail = float(np.mean(psnrs[-max(1, len(psnrs) // 10):]))
        print(f"| {mode} | {tail:.2f} | {r['heldout_psnr']:.2f} | {r['heldout_ssim']:.4f} | "
              f"{r['gaussians']} | {time.perf_counter() - t0:.0f} |", flush=True)

if __name__ == "__main__":
    main()
