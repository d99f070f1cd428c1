"""Image losses and metrics of training.

`ssim(a, b, padding=...)`: SSIM with an 11x11 Gaussian window (σ = 1.5), C1 = 0.01², C2 = 0.03²
(data range 1), local statistics μ = w * x, σ² = w * x² − μ², σ_ab = w * ab − μ_a μ_b, and

    SSIM = (2 μ_a μ_b + C1)(2 σ_ab + C2) / ((μ_a² + μ_b² + C1)(σ_a² + σ_b² + C2)),

averaged over pixels and channels. Two boundary rules:
  "same"   the window is zero-padded and every pixel counts: the SSIM of the 3DGS loss (`ssim`
           in graphdeco's utils/loss_utils.py, fused-ssim's padding="same");
  "valid"  only the pixels whose whole window lies inside the image (5-pixel border dropped):
           fused-ssim's padding="valid" (gsplat's simple_trainer loss) and scikit-image's
           `structural_similarity(gaussian_weights=True, sigma=1.5,
           use_sample_covariance=False, data_range=1)` (tests compare them).
`loss_fn`: (1 − λ)·L1 + λ·(1 − SSIM), λ = 0.2 (3DGS, gsplat's simple_trainer), with the "same"
SSIM by default (3DGS's; gsplat's simple_trainer uses "valid": Recipe.ssim_padding).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

LAMBDA_DSSIM = 0.2
PADDINGS = ("same", "valid")  # `ssim` boundary rules (module docstring)
RADIUS = 5  # an 11-pixel window


def gaussian_window(sigma: float = 1.5, radius: int = RADIUS) -> np.ndarray:
    """The normalised 1D Gaussian window (2·radius + 1 taps)."""
    x = np.arange(-radius, radius + 1, dtype=np.float64)
    w = np.exp(-0.5 * (x / sigma) ** 2)
    return w / w.sum()


def _blur(x, w, mode: str):
    """Separable filter of (C, H, W) images, output of the input's size: padded by jnp.pad's
    `mode` (e.g. "constant": zeros), then y = Σ_k w_k · x[k : k + H] along rows, then along
    columns: shifted slices that XLA fuses into one elementwise pass each, float32 products
    throughout (faster on the CPU than a depthwise convolution)."""
    r = (len(w) - 1) // 2
    h, wd = x.shape[1:]
    x = jnp.pad(x, [(0, 0), (r, r), (r, r)], mode=mode)
    x = sum(float(w[k]) * x[:, k:k + h, :] for k in range(len(w)))
    return sum(float(w[k]) * x[:, :, k:k + wd] for k in range(len(w)))


def ssim(a, b, data_range: float = 1.0, padding: str = "valid"):
    """Mean SSIM of two (H, W, C) images (module docstring: "same" or "valid" padding)."""
    if padding not in PADDINGS:
        raise ValueError(f"padding: expected 'same' or 'valid', got {padding!r}")
    c = a.shape[-1]
    a, b = jnp.moveaxis(a, -1, 0), jnp.moveaxis(b, -1, 0)
    maps = _blur(jnp.concatenate([a, b, a * a, b * b, a * b]), gaussian_window(), "constant")
    mu_a, mu_b, aa, bb, ab = (maps[i * c:(i + 1) * c] for i in range(5))
    c1, c2 = (0.01 * data_range) ** 2, (0.03 * data_range) ** 2
    var_a, var_b, cov = aa - mu_a**2, bb - mu_b**2, ab - mu_a * mu_b
    s = ((2 * mu_a * mu_b + c1) * (2 * cov + c2)
         / ((mu_a**2 + mu_b**2 + c1) * (var_a + var_b + c2)))
    if padding == "valid":  # the padding is never read there
        s = s[:, RADIUS:-RADIUS, RADIUS:-RADIUS]
    return jnp.mean(s)


def loss_fn(image, target, lam: float = LAMBDA_DSSIM, padding: str = "same"):
    """(1 − λ)·L1 + λ·(1 − SSIM) (module docstring)."""
    l1 = jnp.mean(jnp.abs(image - target))
    return (1 - lam) * l1 + lam * (1 - ssim(image, target, padding=padding))


def psnr(mse):
    """PSNR in dB of a mean squared error (data range 1)."""
    return -10.0 * jnp.log10(mse)
