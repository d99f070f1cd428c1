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

On a GPU `ssim` runs two fused Pallas Triton kernels (`ssim_kernel`: the five blurred maps,
the SSIM map and its per-pixel partial derivatives in one, their blur into the gradients in
the other, as fused-ssim does) on images of more than SMALL_IMAGE pixels; on smaller ones,
where the kernels' row sweeps leave the GPU idle, and on other platforms it is XLA's
(`xla_ssim`), with its gradient written
out (a custom VJP, the kernels' equations): with A = 2 μ_a μ_b + C1, B = 2 σ_ab + C2,
C = μ_a² + μ_b² + C1, D = σ_a² + σ_b² + C2 and g the mean's weight of each pixel (1/N inside
the counted pixels, 0 outside),

    ∂SSIM/∂a = w * [g·s·(2μ_b/A − 2μ_b/B − 2μ_a/C + 2μ_a/D)] + 2a·(w * [−g·s/D]) + b·(w * [2g·s/B])

(and the same with a and b swapped), where w * is the zero-padded window itself: the adjoint of
a zero-padded correlation with a symmetric window is that correlation. Three blurred maps per
image in one forward-style pass, where differentiating the blur's shifted slices gives XLA a
pad and an add per tap. `ssim_reference` is the same SSIM differentiated by JAX (tests compare
the two).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from . import ssim_kernel

LAMBDA_DSSIM = 0.2
PADDINGS = ("same", "valid")  # `ssim` boundary rules (module docstring)
RADIUS = 5  # an 11-pixel window
SMALL_IMAGE = 200 * 200  # pixels: at or below, XLA's SSIM is the faster on a GPU (H100: one
# 200x200 view 0.23 ms against the kernels' 0.31; 533x951, 0.63 against 0.33 for two views;
# benchmarks/ssim_sizes.py, scripts/profile_train_step.py)


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


def _check(padding: str, shape) -> None:
    if padding not in PADDINGS:
        raise ValueError(f"padding: expected 'same' or 'valid', got {padding!r}")
    if padding == "valid" and min(shape[:2]) <= 2 * RADIUS:
        raise ValueError(f"padding: 'valid' counts no pixel of a {shape[0]}x{shape[1]} image "
                         f"(its {RADIUS}-pixel border is left out)")


def _terms(a, b, data_range: float):
    """(s, (μ_a, μ_b, A, B, C, D)) of (C, H, W) images (module docstring), every pixel."""
    c = a.shape[0]
    maps = _blur(jnp.concatenate([a, b, a * a, b * b, a * b]), gaussian_window(), "constant")
    mu_a, mu_b, aa, bb, ab = (maps[i * c:(i + 1) * c] for i in range(5))
    c1, c2 = (0.01 * data_range) ** 2, (0.03 * data_range) ** 2
    big_a, big_b = 2 * mu_a * mu_b + c1, 2 * (ab - mu_a * mu_b) + c2
    big_c, big_d = mu_a**2 + mu_b**2 + c1, (aa - mu_a**2) + (bb - mu_b**2) + c2
    return big_a * big_b / (big_c * big_d), (mu_a, mu_b, big_a, big_b, big_c, big_d)


def _mean(s, padding: str):
    if padding == "valid":  # the padding is never read there
        s = s[:, RADIUS:-RADIUS, RADIUS:-RADIUS]
    return jnp.mean(s)


def ssim_reference(a, b, data_range: float = 1.0, padding: str = "valid"):
    """`ssim` differentiated by JAX through the blur (module docstring)."""
    _check(padding, a.shape)
    a, b = jnp.moveaxis(a, -1, 0), jnp.moveaxis(b, -1, 0)
    return _mean(_terms(a, b, data_range)[0], padding)


def ssim(a, b, data_range: float = 1.0, padding: str = "valid"):
    """Mean SSIM of two (H, W, C) images (module docstring: "same" or "valid" padding), with
    its gradient written out: the fused kernels when JAX's default backend is a GPU and the
    images have more than SMALL_IMAGE pixels, else `xla_ssim`."""
    if jax.default_backend() != "gpu" or a.shape[-3] * a.shape[-2] <= SMALL_IMAGE:
        return xla_ssim(a, b, data_range, padding)
    _check(padding, a.shape)
    return ssim_kernel.ssim(a, b, tuple(gaussian_window()), float(data_range), padding,
                            interpret=False)


def xla_ssim(a, b, data_range: float = 1.0, padding: str = "valid"):
    """`ssim` in XLA on any platform (module docstring), its gradient written out."""
    _check(padding, a.shape)
    return _ssim(a, b, float(data_range), padding)


@functools.partial(jax.custom_vjp, nondiff_argnums=(2, 3))
def _ssim(a, b, data_range: float, padding: str):
    return _ssim_fwd(a, b, data_range, padding)[0]  # the residuals are dead code here


def _ssim_fwd(a, b, data_range: float, padding: str):
    ac, bc = jnp.moveaxis(a, -1, 0), jnp.moveaxis(b, -1, 0)
    s, terms = _terms(ac, bc, data_range)
    return _mean(s, padding), (ac, bc, s, terms)


def _ssim_bwd(data_range: float, padding: str, res, ct):
    ac, bc, s, (mu_a, mu_b, big_a, big_b, big_c, big_d) = res
    c, h, w = s.shape
    if padding == "valid":
        inside = jnp.zeros((h, w), s.dtype).at[RADIUS:-RADIUS, RADIUS:-RADIUS].set(1)
        g = ct * inside / (c * (h - 2 * RADIUS) * (w - 2 * RADIUS))
    else:
        g = ct / (c * h * w)
    gs = g * s
    d_var, d_cov = -gs / big_d, 2 * gs / big_b
    common = 1 / big_a - 1 / big_b
    d_mu_a = 2 * gs * (mu_b * common - mu_a / big_c + mu_a / big_d)
    d_mu_b = 2 * gs * (mu_a * common - mu_b / big_c + mu_b / big_d)
    blurred = _blur(jnp.concatenate([d_mu_a, d_mu_b, d_var, d_cov]), gaussian_window(),
                    "constant")
    bm_a, bm_b, bv, bc_ = (blurred[i * c:(i + 1) * c] for i in range(4))
    da = bm_a + 2 * ac * bv + bc * bc_
    db = bm_b + 2 * bc * bv + ac * bc_
    return jnp.moveaxis(da, 0, -1), jnp.moveaxis(db, 0, -1)


_ssim.defvjp(_ssim_fwd, _ssim_bwd)


def loss_fn(image, target, lam: float = LAMBDA_DSSIM, padding: str = "same"):
    """(1 − λ)·L1 + λ·(1 − SSIM) (module docstring)."""
    l1 = jnp.mean(jnp.abs(image - target))
    return (1 - lam) * l1 + lam * (1 - ssim(image, target, padding=padding))


def psnr(mse):
    """PSNR in dB of a mean squared error (data range 1)."""
    return -10.0 * jnp.log10(mse)
