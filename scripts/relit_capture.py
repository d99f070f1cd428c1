"""Experiment: a capture whose training photos are relit differently over the image, trained
plain, with colour corrections (`--color-opt`) and with appearance embeddings (`--app-opt`).

    python scripts/relit_capture.py [--data DIR] [--scene skull] [--downscale 16]
        [--steps 1000] [--modes plain,color_opt,app_opt,bilateral_grid] [--out DIR]
    python scripts/relit_capture.py --scene lego_train --truth lego_sh3/lego_sh3.ply ...

Each training photo k is multiplied by a gain that changes linearly across it, g_k(x, y) = 1 + a_k ·
(x / W − 1/2) + b_k · (y / H − 1/2), with a_k, b_k uniform in ±0.8 (seed 0), clipped to [0, 1]:
light that differs over the scene and from photo to photo, which one affine colour map per photo
cannot undo. Held-out photos are left as they are, so the held-out score says how well each mode
keeps the relighting out of the scene. With --truth the photos are renders of that scene relit in
scene space instead (`relit_in_scene`: half of the scene lit brighter or darker in each training
view, what appearance embeddings are for). Prints, per mode, the training views' PSNR (mean of the
last 10% of steps, against the relit photos), the held-out PSNR and SSIM, and the seconds.
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
from lgs_jax.io.datasets import as_float  # noqa: E402
from lgs_jax.sh import C0  # noqa: E402


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


def relit_in_scene(d, truth, seed: int = 0, keep: int = 10):
    """`d` with its photos replaced by renders of the scene `truth` at its cameras: in each
    training view k the Gaussians with x above the median x have their colours times a gain
    g_k uniform in [0.4, 1.6] (as SH: sh · g, band 0 plus (g − 1) · ½ / C0, so max(SH·Y + ½, 0)
    is scaled exactly), the others as they are; held-out views show the scene as it is. The
    start points: every `keep`-th Gaussian's mean and band-0 colour."""
    rng = np.random.default_rng(seed)
    sh = np.asarray(truth.sh, np.float32)
    side = np.asarray(truth.means)[:, 0] > np.median(np.asarray(truth.means)[:, 0])
    images = []
    for k, cam in enumerate(d.cameras):
        g = 1.0 if k in set(d.test.tolist()) else rng.uniform(0.4, 1.6)
        lit = np.where(side[:, None, None], sh * g, sh)
        lit[:, 0] += np.where(side[:, None], (g - 1) * 0.5 / C0, 0.0)
        scene = dataclasses.replace(truth, sh=lit)
        image = lgs_jax.render(scene, cam, background=d.background).image
        images.append(np.clip(np.asarray(image), 0, 1))
    points = np.asarray(truth.means)[::keep]
    colors = np.clip(sh[::keep, 0] * C0 + 0.5, 0, 1)
    return dataclasses.replace(d, images=np.stack(images).astype(np.float32),
                               points=points.astype(np.float32), colors=colors)


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--data", default=os.path.join(os.path.dirname(__file__), "..", "..",
                                                  "shared", "data"))
    p.add_argument("--scene", default="skull")
    p.add_argument("--downscale", type=int, default=16)
    p.add_argument("--steps", type=int, default=1000)
    p.add_argument("--modes", default="plain,color_opt,app_opt")
    p.add_argument("--out", default=None, help="run directories (default: a temporary one)")
    p.add_argument("--truth", default=None,
                   help="a scene (PLY) at the capture's cameras: relight it in scene space "
                        "(`relit_in_scene`) instead of relighting the photos over the image")
    args = p.parse_args(argv)
    d = lgs_jax.load_dataset(os.path.join(args.data, args.scene), downscale=args.downscale)
    d = relit(d) if args.truth is None else relit_in_scene(
        d, lgs_jax.load_ply(os.path.join(args.data, args.truth)))
    out = args.out or tempfile.mkdtemp()
    how = "over the image" if args.truth is None else f"in scene space ({args.truth})"
    print(f"{args.scene} at 1/{args.downscale}, {args.steps} steps, training photos relit "
          f"{how} (seed 0), {jax.devices()[0].device_kind}, JAX {jax.__version__}")
    print("| mode | training PSNR (last 10%) | held-out PSNR | held-out SSIM | Gaussians | s |")
    print("|---|---:|---:|---:|---:|---:|", flush=True)
    for mode in args.modes.split(","):
        flags = {} if mode == "plain" else {mode: True}
        config = train.FitConfig(data=d.path, out=os.path.join(out, mode), steps=args.steps,
                                 recipe=train.Recipe(**flags), eval_every=args.steps + 1,
                                 checkpoint_every=max(args.steps, 1), overwrite=True)
        t0 = time.perf_counter()
        r = train.fit(config, d, log=lambda m: None)
        metrics = report.read_metrics(os.path.join(out, mode, "metrics.jsonl"))
        psnrs = [m["psnr"] for m in metrics if "psnr" in m and "loss" in m]
        tail = float(np.mean(psnrs[-max(1, len(psnrs) // 10):]))
        print(f"| {mode} | {tail:.2f} | {r['heldout_psnr']:.2f} | {r['heldout_ssim']:.4f} | "
              f"{r['gaussians']} | {time.perf_counter() - t0:.0f} |", flush=True)

if __name__ == "__main__":
    main()
