"""Image comparison with the contract's notion of "equal up to float rounding"."""

from __future__ import annotations

import numpy as np


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


def psnr(a, b, peak=1.0):
    mse = np.mean((np.asarray(a, np.float64) - np.asarray(b, np.float64)) ** 2)
    return np.inf if mse == 0 else 10 * np.log10(peak**2 / mse)
