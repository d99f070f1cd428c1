"""Synthetic scenes for scale tests: N random Gaussians filling a camera's view."""

from __future__ import annotations

import numpy as np

from .scene import Camera, Gaussians


def random_scene(n: int, seed: int = 0, sh_bases: int = 1) -> Gaussians:
    """N Gaussians in the box [-1, 1]² x [2, 6] (in front of `synthetic_camera`), sizes log-uniform
    from ~1/500 to ~1/20 of the view, random rotations, opacities and colours (float32).

    Sizes shrink with N^(1/3) so that coverage per pixel stays similar as N grows."""
    rng = np.random.default_rng(seed)
    means = np.stack([rng.uniform(-1, 1, n), rng.uniform(-0.6, 0.6, n), rng.uniform(2, 6, n)], -1)
    shrink = np.log(max(n, 1) / 1e4) / 3
    log_scales = rng.uniform(np.log(0.004), np.log(0.04), (n, 3)) - shrink
    quats = rng.normal(size=(n, 4))
    logit = rng.normal(0.0, 2.0, n)
    sh = np.zeros((n, sh_bases, 3))
    sh[:, 0] = rng.uniform(-1.5, 1.5, (n, 3))
    if sh_bases > 1:
        sh[:, 1:] = rng.normal(0, 0.1, (n, sh_bases - 1, 3))
    f32 = lambda x: np.asarray(x, np.float32)
    return Gaussians(f32(means), f32(quats), f32(log_scales), f32(logit), f32(sh))


def synthetic_camera(width: int = 1280, height: int = 720) -> Camera:
    """Camera at the origin looking down +z, 60° horizontal field of view."""
    f = 0.5 * width / np.tan(np.radians(30))
    return Camera(viewmat=np.eye(4, dtype=np.float32), fx=np.float32(f), fy=np.float32(f),
                  cx=np.float32(width / 2), cy=np.float32(height / 2), width=width, height=height)


def densified(g: Gaussians, k: int, seed: int = 0) -> Gaussians:
    """A denser scene of similar look: every Gaussian replaced by k copies whose means are
    jittered by N(0, 1)·max(exp(log_scales)) (per Gaussian, per axis), log_scales lowered by
    ln(k)/3, opacity, rotation and SH unchanged. Copy j of Gaussian i is row i·k + j."""
    rng = np.random.default_rng(seed)
    rep = lambda x: np.repeat(np.asarray(x), k, axis=0)
    log_scales = np.asarray(g.log_scales, np.float64)
    sigma = np.exp(np.max(np.where(np.isfinite(log_scales), log_scales, -np.inf), axis=1))
    sigma = np.where(np.isfinite(sigma), sigma, 0.0)
    jitter = rng.standard_normal((g.num * k, 3)) * np.repeat(sigma, k)[:, None]
    means = np.asarray(g.means, np.float64).repeat(k, 0) + jitter
    dt = np.asarray(g.means).dtype
    return Gaussians(means.astype(dt), rep(g.quats), (rep(log_scales) - np.log(k) / 3).astype(dt),
                     rep(g.logit_opacities), rep(g.sh))
