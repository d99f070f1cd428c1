"""Comparisons and tolerances the tests share: the contract's notion of "equal up to float
rounding" for images, gradients and the `fast` blending bound.

The contract's constants, written out (ALPHA_CAP, STOP_INCLUSIVE), so that the oracle and the
bounds do not take them from the config under test.

Tolerances (use these names, not new literals, so that one reason has one number):
  F64_ATOL         two backends' float64 images, alpha and depth: same contract, different order
                   of float64 operations.
  F32_ATOL         two float32 renders outside threshold flips: the hoisted and difference forms
                   round differently; on the adversarial needles of tests/scenes.py (2D condition
                   numbers to ~1e7) they differ by up to ~1e-4, and each stays as close to the
                   float64 truth as the other (numerics/ studies why).
  F32_FLIP_SHARE   share of pixels a float32 comparison lets differ by a threshold flip (a 1/255
                   or stop decision rounding the other way), each by at most one Gaussian's
                   contribution (`assert_float32_close`).
  GRAD_F64_REL     float64 gradients of two backward implementations, relative to the gradient's
                   largest magnitude (`assert_close_to_scale`).
  COMPOSITE_ULPS   two renders' images from the same kernel values whose colour reached
                   `render`'s composite in different layouts (`assert_composites_equal`).
"""

from __future__ import annotations

import numpy as np

from benchmarks.common import psnr  # noqa: F401 - one PSNR for tests and benchmarks

ALPHA_CAP = {"3dgs": 0.99, "gsplat": 0.999}  # docs/conventions.md: the cap on α per convention
STOP_INCLUSIVE = {"3dgs": False, "gsplat": True}  # whether T·(1 − α) == 1e-4 already stops
F64_ATOL = 1e-9
F32_ATOL = 1e-4
F32_FLIP_SHARE = 0.01
GRAD_F64_REL = 1e-9
COMPOSITE_ULPS = 1


def assert_render_close(got, want, atol, max_flip_share=0.0, flip_atol=np.inf, what="image"):
    """Every pixel within `atol`, except at most `max_flip_share` of pixels (threshold flips of
    the 1/255 or stop tests), which must stay within `flip_atol` (one Gaussian's contribution)."""
    got, want = np.asarray(got, np.float64), np.asarray(want, np.float64)
    assert got.shape == want.shape, (got.shape, want.shape)
    assert np.all(np.isfinite(got)), f"{what}: non-finite values"
    diff = np.abs(got - want)
    if diff.ndim == 3:
        diff = diff.max(-1)
    bad = diff > atol
    share = bad.mean()
    assert share <= max_flip_share, (
        f"{what}: {bad.sum()} pixels ({share:.2%}) differ by > {atol} (max {diff.max():.3g}); "
        f"allowed share {max_flip_share:.2%}")
    assert diff.max() <= flip_atol, f"{what}: max difference {diff.max():.3g} > {flip_atol}"


def assert_composites_equal(got, want):
    """Two renders' images whose kernels produced the same colour, T and depth bits, but the
    colour in different layouts (the Local-GS Mosaic GPU forward's (H, W, 3) image,
    `pallas.Plan.image`, against per-tile planes): equal to COMPOSITE_ULPS units
    in the last place. `render` composites C + T·background in XLA after the kernel, and XLA's
    CPU compiler contracts that multiply-add into a fused one in some iterations of its
    vectorised loop and not in others; the layouts split the pixels into those iterations
    differently. Seen with AVX-512 (an AMD EPYC, Dec 4): 231 of 2880 values, blue channel
    only, 1 ulp apart, the alpha and depth equal; with XLA's CPU ISA capped at AVX2
    (`--xla_cpu_max_isa=AVX2`) the images are equal. A dropped or extra pair moves the alpha,
    which the tests still compare bit for bit."""
    got, want = np.asarray(got), np.asarray(want)
    assert got.dtype == want.dtype, (got.dtype, want.dtype)
    np.testing.assert_array_max_ulp(got, want, maxulp=COMPOSITE_ULPS)


def assert_float32_close(got, want, atol=F32_ATOL, max_flip_share=F32_FLIP_SHARE):
    """Two float32 renders (RenderOutput): image and alpha within `atol` outside threshold flips
    on at most `max_flip_share` of pixels (a flip moves a pixel by at most one Gaussian: 2 in
    colour, 1 in alpha)."""
    assert_render_close(got.image, want.image, atol=atol, max_flip_share=max_flip_share,
                        flip_atol=2.0)
    assert_render_close(got.alpha, want.alpha, atol=atol, max_flip_share=max_flip_share,
                        flip_atol=1.0, what="alpha")


def assert_close_to_scale(got, want, rel, err_msg=""):
    """|got − want| <= rel·max(max |want|, 1) everywhere (gradients: relative to their scale)."""
    want = np.asarray(want)
    np.testing.assert_allclose(got, want, rtol=0, atol=rel * max(np.abs(want).max(), 1.0),
                               err_msg=err_msg)


def fast_blending_bound(alpha_cap: float) -> float:
    """How far `fast` blending may move alpha from the exact image, per pixel: 1e-4/(1 − cap)
    (derived in lgs_jax.backends.tiles); the colour bound is this times max|rgb − background|."""
    return 1e-4 / (1 - alpha_cap)


def assert_within_fast_bound(fast, exact, rgb, background, alpha_cap: float):
    """`fast` (RenderOutput) within the bound of `exact` for Gaussians of colour `rgb` (N, 3)."""
    bound = fast_blending_bound(alpha_cap)
    rgb = np.asarray(rgb)
    colour_range = np.abs(rgb[:, None, :] - np.asarray(background)).max() if len(rgb) else 0.0
    assert_render_close(fast.image, exact.image, atol=bound * colour_range + 1e-9)
    assert_render_close(fast.alpha, exact.alpha, atol=bound + 1e-9, what="alpha")
