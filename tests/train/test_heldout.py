"""lgs_jax.train.heldout: scikit-image's PSNR and SSIM on the device, and held-out evaluations
scored on the device; the MCMC pool sized to the most Gaussians its run can reach."""

import jax
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import lgs_jax
from lgs_jax import train
from lgs_jax.train import heldout
from lgs_jax.train.config import Setup
from lgs_jax.train.pool import from_gaussians
from lgs_jax.train.report import view_metrics
from tests import scenes


@settings(max_examples=5, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), noise=st.floats(0.0, 0.5))
def test_view_scores_are_scikit_images(seed, noise):
    """`view_scores` is scikit-image's PSNR and default SSIM (7x7 uniform window, sample
    covariance, channels averaged), up to float32 rounding; the image clipped to [0, 1]."""
    rng = np.random.default_rng(seed)
    target = rng.uniform(0, 1, (24, 40, 3)).astype(np.float32)
    image = np.clip(target + rng.normal(0, noise, target.shape), -0.2, 1.2).astype(np.float32)
    psnr, ssim = (float(x) for x in heldout.view_scores(image, target))
    [(want_psnr, want_ssim)] = view_metrics([np.clip(image, 0, 1)], [target])
    if np.isfinite(want_psnr):
        np.testing.assert_allclose(psnr, want_psnr, rtol=1e-5)
    np.testing.assert_allclose(ssim, want_ssim, rtol=0, atol=2e-5)


def test_evaluations_score_the_pool_they_are_given():
    """Each evaluation scores the pool it is given (the pool changed between the two), as
    rendering and scoring one view at a time does (to float32 rounding: another compilation);
    the pair buffer grows from one pair to the views' need."""
    g = scenes.cast(scenes.scene(4), np.float32)
    cams = [scenes.camera(yaw=y) for y in (0.0, 0.3)]
    background = np.asarray(scenes.BACKGROUND, np.float32)
    setup = Setup(backend="tiles")
    pools = [from_gaussians(g, 64), from_gaussians(scenes.cast(scenes.scene(5), np.float32), 64)]
    shown = [train.render_gaussians(pool.params, pool.active) for pool in pools]
    # one program for both pools (a capacity of their own each: two) and jitted scores (eager,
    # each of their operations compiles on its own)
    render = lambda g, c: lgs_jax.render(g, c, background=background, capacity=1024).image
    view_scores = jax.jit(heldout.view_scores)
    noise = np.random.default_rng(0).normal(0, 0.05, (len(cams), cams[0].height,
                                                     cams[0].width, 3)).astype(np.float32)
    # the first pool's renders, noisy (its scores finite too)
    targets = [np.clip(np.asarray(render(shown[0], c)) + n, 0, 1) for c, n in zip(cams, noise)]
    evaluations = heldout.Evaluations(cams, targets, background, setup, capacity=1, headroom=2)
    got = [evaluations.score(pool) for pool in pools]
    assert evaluations.capacity > 1
    for (psnr, ssim), g in zip(got, shown):
        scores = [view_scores(render(g, c), t) for c, t in zip(cams, targets)]
        np.testing.assert_allclose(psnr, np.mean([float(p) for p, _ in scores]), rtol=1e-6)
        np.testing.assert_allclose(ssim, np.mean([float(s) for _, s in scores]), rtol=1e-5)


@pytest.mark.parametrize("n,steps,cap,want", [
    (1000, 500, 10**6, 1000),  # no refinement before step 500
    (1000, 602, 10**6, 1050),  # one, after step 600
    (11582, 7000, 500_000, 262_774),
    (11582, 30_000, 500_000, 500_000),  # the cap
    (10, 2000, 10**6, 10),  # n // 20 = 0: MCMC adds nothing to 19 or fewer
])
def test_mcmc_pool_holds_every_gaussian_the_run_can_reach(n, steps, cap, want):
    assert train.MCMCStrategy(cap_max=cap).max_count(n, steps, cap) == want
    assert train.DefaultStrategy().max_count(n, steps, cap) is None
    assert train.Strategy().max_count(n, steps, cap) == n
