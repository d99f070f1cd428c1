"""`fit` on a real capture made of two image sizes, beside the same capture at one size.

Every other training view of the capture is cropped to a centred window (`--keep` of each side,
the camera cropped with it: the same rays for the pixels kept), the held-out views left whole;
both captures train with the same recipe and seed and are scored on the same held-out views.
A working mixed-size path trains close to the whole capture (a little fewer training pixels);
a view rendered at the wrong size or paired with another's image would not train at all.

    python scripts/fit_mixed_sizes.py --data ../shared/data/skull --downscale 8 --steps 1500
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import tempfile


import lgs_jax
from lgs_jax import train


def mixed(d, keep: float):
    """`d` with every other training view cropped to its centred `keep` x `keep` window."""
    images, cams = list(d.images), list(d.cameras)
    for n, i in enumerate(d.train):
        if n % 2:
            c = cams[i]
            w, h = int(c.width * keep), int(c.height * keep)
            x0, y0 = (c.width - w) // 2, (c.height - h) // 2
            images[i] = images[i][y0:y0 + h, x0:x0 + w]
            cams[i] = c.cropped(x0, y0, w, h)
    return dataclasses.replace(d, images=images, cameras=tuple(cams))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default="../shared/data/skull")
    ap.add_argument("--downscale", type=int, default=8)
    ap.add_argument("--steps", type=int, default=1500)
    ap.add_argument("--batch", type=int, default=1)
    ap.add_argument("--keep", type=float, default=0.75)
    ap.add_argument("--out", default=None, help="run folders go here (default: a temporary one)")
    args = ap.parse_args()
    d = lgs_jax.load_dataset(args.data, downscale=args.downscale)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name, data in (("one size", d), ("two sizes", mixed(d, args.keep))):
            out = os.path.join(args.out or tmp, name.replace(" ", "_"))
            config = train.FitConfig(data=data.path, out=out, steps=args.steps,
                                     recipe=train.Recipe(batch=args.batch), eval_every=10**9,
                                     checkpoint_every=10**9, overwrite=True)
            r = train.fit(config, data, log=lambda m: None)
            rows.append((name, r))
            print(json.dumps(dict(run=name, **r)), flush=True)
    print(f"\n{'capture':10s} {'held-out PSNR':>14s} {'SSIM':>7s} {'Gaussians':>10s} "
          f"{'ms/step':>8s}")
    for name, r in rows:
        print(f"{name:10s} {r['heldout_psnr']:14.2f} {r['heldout_ssim']:7.4f} "
              f"{r['gaussians']:10d} {r['ms_per_step']:8.1f}")


if __name__ == "__main__":
    main()
