"""A scene's scores on a capture's views: `evaluate` renders each view of a split and scores it
against its image as `fit`'s evaluations do (PSNR and SSIM with scikit-image's defaults,
`report.view_metrics`), for scenes from `fit`, from other trainers' INRIA PLY files, or from
anywhere. `python -m lgs_jax eval SCENE.ply --data DIR` runs it.
"""

from __future__ import annotations

import json
import os

import jax.numpy as jnp
import numpy as np

from ..config import RasterConfig
from ..io.datasets import Dataset, as_float, load_dataset
from ..render import default_backend
from ..scene import Gaussians
from . import report
from ..files import written
from .pool import from_gaussians
from .step import render_views

SPLITS = ("test", "train", "all")


def evaluate(gaussians: Gaussians, data, *, split: str = "test", downscale: int = 1,
             backend: str | None = None, config: RasterConfig = RasterConfig(),
             out: str | None = None) -> dict:
    """Render `gaussians` at the views of `split` ("test": the held-out views, "train", "all")
    of `data` (a `Dataset`, or a folder `load_dataset` reads at `downscale`) over its
    background, with `backend` (default: `render.default_backend()`) and `config`
    (its convention and antialiasing should be the scene's training ones). Returns psnr and
    ssim (means over the views), views (name, psnr, ssim per view), split, gaussians, backend.
    With `out`, writes eval_<name>.png (render beside the image) and metrics.json there."""
    if split not in SPLITS:
        raise ValueError(f"split: expected one of {SPLITS}, got {split!r}")
    d = data if isinstance(data, Dataset) else load_dataset(data, downscale=downscale)
    idx = {"test": d.test, "train": d.train, "all": np.arange(len(d.names))}[split]
    if len(idx) == 0:
        raise ValueError(f"split: {d.path} has no {split} views")
    backend = backend or default_backend()
    renders, _ = render_views(from_gaussians(gaussians), [d.cameras[i] for i in idx],
                              jnp.asarray(d.background), backend, 1 << 16, config)
    targets = [as_float(d.images[i]) for i in idx]
    names = [os.path.splitext(os.path.basename(d.names[i]))[0] for i in idx]
    scores = report.view_metrics(renders, targets)
    result = dict(split=split, psnr=float(np.mean([p for p, _ in scores])),
                  ssim=float(np.mean([s for _, s in scores])), gaussians=gaussians.num,
                  backend=backend,
                  views=[dict(name=n, psnr=p, ssim=s) for n, (p, s) in zip(names, scores)])
    if out:
        os.makedirs(out, exist_ok=True)
        report.save_renders(out, renders, targets, names, prefix="eval")
        with written(os.path.join(out, "metrics.json")) as tmp, open(tmp, "w") as f:
            json.dump(result, f, indent=1)
    return result
