"""`reference` (tiled) equals `brute` (no tiles) and the numpy float64 oracle.

float64: equal to ~1e-10, no threshold flips. float32: the tiled and brute backends evaluate the
same arithmetic per pixel, so they agree to rounding, with at most 1% of pixels allowed a
threshold flip; against the float64 oracle, float32 is held to 2e-4 outside flips on scenes
without needles (needles are the numerics study's subject: their float32 conic is inexact).
"""

import numpy as np
import pytest
from hypothesis import given, strategies as st

import lgs_jax
from tests import oracle, scenes
from tests.compare import ALPHA_CAP, F64_ATOL, STOP_INCLUSIVE, assert_render_close

CONVENTIONS = [lgs_jax.RasterConfig("3dgs"), lgs_jax.RasterConfig("gsplat")]
BG = np.array(scenes.BACKGROUND)  # what scenes.render composites over


@pytest.mark.parametrize("config", CONVENTIONS, ids=lambda c: c.convention)
@given(seed=st.integers(0, 2**32 - 1))
def test_reference_equals_brute_float64(config, seed):
    g = scenes.scene(seed)
    cam = scenes.camera(dtype=np.float64)
    ref, bru = scenes.render(g, cam, "reference", config), scenes.render(g, cam, "brute", config)
    for field in ("image", "alpha", "depth"):
        assert_render_close(getattr(ref, field), getattr(bru, field), atol=1e-10, what=field)
    assert ref.image.dtype == np.float64


@given(seed=st.integers(0, 2**32 - 1), antialiased=st.booleans())
def test_reference_equals_oracle_float64(seed, antialiased):
    g = scenes.scene(seed)
    cam = scenes.camera(dtype=np.float64)
    config = lgs_jax.RasterConfig(CONVENTIONS[seed % 2].convention, antialiased=antialiased)
    ref = scenes.render(g, cam, "reference", config)
    img, alpha, depth = oracle.composite(g, cam, BG, cap=ALPHA_CAP[config.convention],
                                         inclusive=STOP_INCLUSIVE[config.convention],
                                         antialiased=antialiased)
    assert_render_close(ref.image, img, atol=F64_ATOL, what="image")
    assert_render_close(ref.alpha, alpha, atol=F64_ATOL, what="alpha")
    assert_render_close(ref.depth, depth, atol=1e-8, what="depth")


@given(seed=st.integers(0, 2**32 - 1))
def test_reference_equals_brute_float32(seed):
    g = scenes.cast(scenes.scene(seed), np.float32)
    cam = scenes.camera()
    ref, bru = scenes.render(g, cam, "reference", CONVENTIONS[0]), scenes.render(g, cam, "brute", CONVENTIONS[0])
    assert ref.image.dtype == np.float32  # x64 is on in tests: float32 in, float32 out
    assert_render_close(ref.image, bru.image, atol=1e-5, max_flip_share=0.01, flip_atol=2.0)
    assert_render_close(ref.alpha, bru.alpha, atol=1e-5, max_flip_share=0.01, flip_atol=1.0)


@given(seed=st.integers(0, 2**32 - 1))
def test_reference_float32_accuracy_vs_float64_oracle(seed):
    kinds = ("normal", "tiny", "behind", "faint", "opaque", "layers", "invalid", "huge_far")
    g64 = scenes.scene(seed, kinds=kinds)
    ref = scenes.render(scenes.cast(g64, np.float32), scenes.camera(), "reference", CONVENTIONS[0])
    img, alpha, _ = oracle.composite(g64, scenes.camera(dtype=np.float64), BG)
    assert_render_close(ref.image, img, atol=2e-4, max_flip_share=0.02, flip_atol=2.0)
    assert_render_close(ref.alpha, alpha, atol=2e-4, max_flip_share=0.02, flip_atol=1.0)


def test_depth_and_alpha_definitions():
    """depth = Σ z·α·T with colour's weights: a single opaque-ish Gaussian gives depth = z·alpha."""
    g = scenes.scene(11, kinds=("normal",), n=scenes.N)
    g = lgs_jax.Gaussians(g.means[:1], g.quats[:1], g.log_scales[:1], g.logit_opacities[:1],
                          g.sh[:1])
    out = scenes.render(g, scenes.camera(dtype=np.float64), "reference", CONVENTIONS[0], bg=(0, 0, 0))
    np.testing.assert_allclose(np.asarray(out.depth), np.asarray(out.alpha) * g.means[0, 2],
                               rtol=1e-12, atol=1e-15)
