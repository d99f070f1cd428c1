"""Held-out evaluations during training that cost the run milliseconds (`Evaluations`), and
scikit-image's PSNR and SSIM on the device (`view_scores`).

At an evaluation step the held-out views are rendered from that step's pool and scored on the
device; only the scores (a few floats per view) cross to the host: no image is copied and no
scoring runs in Python, where scikit-image took seconds per evaluation. The loop waits for the
scores before its next step, so the renders' buffers never sit beside a training step's. The
pair buffer of the held-out renders is sized by counting the views' pairs first with the run's
pair headroom, so that it grows, a compile each, about as rarely as the training step's. The
final evaluation (`outputs.finish`) is scikit-image's own (`report.heldout_metrics`), on the
host.

`view_scores` computes scikit-image's defaults, `peak_signal_noise_ratio(data_range=1)` and
`structural_similarity(channel_axis=-1, data_range=1)` (7x7 uniform window, sample covariance
49/48, C1 = 0.01², C2 = 0.03², the mean over the pixels whose window lies inside the image and
over the channels), in float32 where scikit-image computes in float64: the same numbers up to
float32 rounding (tests/train/test_heldout.py compares them).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from ..config import RasterConfig
from ..render import count_pairs, pair_capacity
from .config import Setup
from .pool import Pool, render_gaussians
from .step import COMPILER_OPTIONS

WINDOW = 7  # scikit-image's default SSIM window (uniform)


def _uniform(x):
    """The mean over each WINDOW x WINDOW window of (H, W, C) x that lies inside the image:
    (H − 6, W − 6, C), scikit-image's uniform filter on the pixels its SSIM averages."""
    h, w = x.shape[0] - WINDOW + 1, x.shape[1] - WINDOW + 1
    rows = sum(x[k:k + h] for k in range(WINDOW))
    return sum(rows[:, k:k + w] for k in range(WINDOW)) / WINDOW**2


def view_scores(image, target):
    """(PSNR, SSIM) of an (H, W, C) image against its target, both in [0, 1] (the image
    clipped), as scikit-image's defaults compute them (module docstring)."""
    image = jnp.clip(image, 0.0, 1.0)
    psnr = -10.0 * jnp.log10(jnp.mean((target - image) ** 2))
    cov = WINDOW**2 / (WINDOW**2 - 1)
    ux, uy = _uniform(image), _uniform(target)
    vx = cov * (_uniform(image * image) - ux * ux)
    vy = cov * (_uniform(target * target) - uy * uy)
    vxy = cov * (_uniform(image * target) - ux * uy)
    c1, c2 = 0.01**2, 0.03**2
    s = ((2 * ux * uy + c1) * (2 * vxy + c2)) / ((ux**2 + uy**2 + c1) * (vx + vy + c2))
    return psnr, jnp.mean(s)


@functools.partial(jax.jit, static_argnames=("backend", "capacity", "config"),
                   compiler_options=COMPILER_OPTIONS)
def _scored(pool: Pool, cam, target, background, *, backend: str, capacity: int,
            config: RasterConfig):
    """(PSNR, SSIM, overflow) of one held-out view rendered from `pool`."""
    from ..render import render

    out = render(render_gaussians(pool.params, pool.active), cam, background=background,
                 backend=backend, capacity=capacity, config=config)
    psnr, ssim = view_scores(out.image, target)
    return psnr, ssim, out.stats.overflow


@functools.partial(jax.jit, static_argnames="antialiased")
def _pairs(pool: Pool, cam, antialiased: bool):
    return count_pairs(render_gaussians(pool.params, pool.active), cam, antialiased=antialiased)


class Evaluations:
    """The held-out views of a run, scored on the device (module docstring): `score(pool)` is
    the (PSNR, SSIM) of the pool over the views, averaged. `capacity`: the held-out renders'
    pair buffer, grown here (a checkpoint keeps it)."""

    def __init__(self, cams, targets, background, setup: Setup, capacity: int,
                 headroom: float):
        self.cams, self.targets = list(cams), targets
        self.background = jnp.asarray(background)
        self.setup, self.capacity, self.headroom = setup, capacity, headroom

    def score(self, pool: Pool) -> tuple[float, float]:
        recipe = self.setup.recipe
        # every view's count dispatched before the one read: a single wait on the device
        need = int(max(jax.device_get([_pairs(pool, cam, recipe.antialiased)
                                       for cam in self.cams])))
        if need > self.capacity:
            self.capacity = pair_capacity(need, self.headroom)
        scores = jax.device_get([
            _scored(pool, cam, jnp.asarray(target), self.background,
                    backend=self.setup.backend, capacity=self.capacity, config=recipe.raster)
            for cam, target in zip(self.cams, self.targets)])
        if any(bool(o) for _, _, o in scores):  # counted just before: cannot happen
            raise RuntimeError("a held-out view overflowed its pair buffer")
        return (float(np.mean([p for p, _, _ in scores])),
                float(np.mean([s for _, s, _ in scores])))
