"""Gaussians whose 1/255 ellipse holds a pixel, for the exponent-level studies (numerics.study,
numerics.centre): pixel uniform over a `resolution`-wide 16:9 image, centre `offset_px` away in a
random direction, 2D covariance with condition number `anisotropy` and smallest eigenvalue >= the
0.3 px² dilation, scaled so the pixel sits at a random level 0 < q <= τ of the ellipse."""

from __future__ import annotations

import numpy as np

from . import forms

RESOLUTIONS = (1024, 2048, 4096, 8192, 16384)
LN255 = np.log(255.0)
OFFSETS = (0, 4, 16, 64, 256, 1024, 4096)
ANISOTROPY = (1.0, 1e2, 1e4, 1e6)
OPACITIES = (1.5 / 255, 0.05, 0.5, 1.0)  # numerics.study's opacity sweep (4096 px wide)


def sample(rng, n, resolution, offset, kappa, opacity=None):
    """Float64 Gaussians (mean, pixel, cov, log_o) with the pixel inside the 1/255 ellipse
    (opacity uniform in [2/255, 1] unless given)."""
    height = resolution * 9 // 16
    pixel = np.floor(rng.uniform([0, 0], [resolution, height], (n, 2))) + 0.5
    phi = rng.uniform(0, 2 * np.pi, n)
    d = (offset + rng.uniform(0, 1, n))[:, None] * np.stack([np.cos(phi), np.sin(phi)], -1)
    theta = rng.uniform(0, np.pi, n)
    c, s = np.cos(theta), np.sin(theta)
    lam = np.stack([np.full(n, kappa), np.ones(n)], -1)  # shape, scaled below
    log_o = np.log(rng.uniform(2 / 255, 1.0, n) if opacity is None else np.full(n, opacity))
    tau = 2 * (LN255 + log_o)
    level = tau * rng.uniform(0.01, 1.0, n)  # target q at the pixel
    # q(d) for eigenvalues lam·scale: scale = q(d; lam) / level.
    t1, t2 = c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]
    scale = (t1 * t1 / lam[:, 0] + t2 * t2 / lam[:, 1]) / level
    lam = lam * scale[:, None]
    lam = np.maximum(lam, 0.3 + 1e-3 * rng.uniform(0, 1, (n, 2)))  # the dilation floor
    return pixel + d, pixel, forms.covariance(lam[:, 0], lam[:, 1], theta), log_o
