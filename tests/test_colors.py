"""`render(..., colors=(N, C))`: per-Gaussian values composited in place of the SH colour
(features of any width), against the float64 oracle, autodiff through `brute`, and bad input.

C = 7 takes three passes of three channels (the last padded), C = 1 one padded pass, C = 3 the
SH colour's single pass: each backend is checked at one of them (each C is a compile)."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, strategies as st

import lgs_jax
from lgs_jax.projection import project
from tests import oracle, scenes
from tests.compare import F64_ATOL, assert_close_to_scale, assert_render_close


def _colors(seed: int, channels: int, n: int = scenes.N):
    """Values of both signs and beyond [0, 1] (features are not colours), and a NaN and an
    inf row (invalid Gaussians: they must not reach the image)."""
    f = np.random.default_rng(seed).normal(0.0, 2.0, size=(n, channels))
    f[3, -1], f[7, 0] = np.nan, np.inf
    return f


def _render(g, cam, backend, f, background=None, capacity=scenes.CAPACITY):
    return lgs_jax.render(g, cam, backend=backend, capacity=capacity, colors=f,
                          background=background)


@pytest.mark.parametrize("backend,channels", [("reference", 7), ("brute", 1), ("tiles", 7),
                                              ("pallas", 4)])
@given(seed=st.integers(0, 2**32 - 1))
def test_colors_equal_the_float64_oracle(backend, channels, seed):
    """Every adversarial kind; the image (H, W, C) over a background of C channels, alpha and
    depth as the SH render's; the NaN and inf rows counted invalid."""
    g = scenes.scene(seed)
    cam = scenes.camera(dtype=np.float64)
    f = _colors(seed, channels)
    bg = np.linspace(-1.0, 1.0, channels)
    out = _render(g, cam, backend, f, bg)
    img, alpha, depth = oracle.composite(g, cam, bg, colors=f)
    assert out.image.shape == (scenes.H, scenes.W, channels)
    assert_render_close(out.image, img, atol=F64_ATOL, what="image")
    assert_render_close(out.alpha, alpha, atol=F64_ATOL, what="alpha")
    assert_render_close(out.depth, depth, atol=1e-8, what="depth")
    geometry = np.asarray(project(g, cam).invalid)  # the scenes' SH are finite
    assert int(out.stats.n_invalid) == np.sum(geometry | ~np.all(np.isfinite(f), axis=1))


def test_three_colors_are_the_sh_colours_pass():
    """Three channels equal to the projected SH colour render the SH image (to the float64
    rounding of another compiled program), and a Gaussian's NaN SH coefficient no longer
    matters once colours are given."""
    g = scenes.scene(8, kinds=("normal", "opaque", "layers", "needle"))
    cam = scenes.camera(dtype=np.float64)
    nan_sh = g.sh.copy()
    nan_sh[0, 0, 0] = np.nan

    @jax.jit
    def both(g, nan_sh):  # one program: compiled together, a third less than apart
        want = lgs_jax.render(g, cam, backend="tiles", capacity=scenes.CAPACITY)
        rgb = project(g, cam).rgb
        return want, _render(dataclasses.replace(g, sh=nan_sh), cam, "tiles", rgb)

    want, got = both(g, nan_sh)
    np.testing.assert_allclose(got.image, want.image, rtol=0, atol=1e-14)
    np.testing.assert_array_equal(got.alpha, want.alpha)


# Slow: `reference` (its own backward: tests/backends/test_gradients.py checks it against
# autodiff through `brute` in the default set); the passes' gradient (render._channel_passes,
# backend-independent) is `tiles`' in the default set.
@pytest.mark.parametrize("backend", [pytest.param("reference", marks=pytest.mark.slow), "tiles"])
def test_color_gradients_equal_autodiff_through_brute(backend):
    """∂L/∂colors and ∂L/∂(every Gaussian field) through two passes (C = 4), float64."""
    g = scenes.scene(21)
    cam = scenes.camera(dtype=np.float64)
    f = _colors(21, 4)
    weights = jnp.asarray(np.random.default_rng(1).normal(size=(scenes.H, scenes.W, 4)))

    def loss(g, f, backend):
        out = _render(g, cam, backend, f)
        return jnp.sum(out.image * weights) + 0.1 * jnp.sum(out.depth)

    # Jitted: one program per backend (eager, the forward and the backward of render's own jit
    # compile apart, two per backend).
    grad = jax.jit(jax.grad(loss, argnums=(0, 1)), static_argnums=2)
    (gg, gf), (bg, bf) = (grad(g, f, b) for b in (backend, "brute"))
    assert np.all(np.isfinite(np.asarray(gf))) and np.all(np.asarray(gf)[[3, 7]] == 0)
    assert np.any(np.asarray(gf) != 0)
    assert_close_to_scale(gf, bf, 1e-8, "colors")
    for name in ("means", "quats", "log_scales", "logit_opacities"):
        assert_close_to_scale(getattr(gg, name), getattr(bg, name), 1e-8, name)
    assert np.all(np.asarray(gg.sh) == 0)  # unread


def test_colors_under_jit_and_vmap():
    g = scenes.cast(scenes.scene(4, kinds=("normal", "layers")), np.float32)
    f = _colors(4, 2).astype(np.float32)
    f[[3, 7]] = 0.5
    cams = [scenes.camera(yaw=y) for y in (-0.2, 0.25)]
    many = jax.jit(jax.vmap(lambda c: _render(g, c, "reference", f).image))(
        lgs_jax.stack_cameras(cams))
    assert many.shape == (2, scenes.H, scenes.W, 2) and many.dtype == np.float32
    for i, c in enumerate(cams):  # an ulp of the batched projection, times values up to ~6
        np.testing.assert_allclose(many[i], _render(g, c, "reference", f).image, atol=1e-5)


@pytest.mark.parametrize("colors,background,match", [
    (np.zeros((scenes.N - 1, 3)), None, r"colors: expected shape \(32, C\)"),
    (np.zeros((scenes.N,)), None, r"colors: expected shape \(32, C\)"),
    (np.zeros((scenes.N, 0)), None, r"colors: expected shape \(32, C\)"),
    (np.zeros((scenes.N, 2), complex), None, "colors: expected real numbers"),
    (np.zeros((scenes.N, 5)), np.zeros(3), r"background: expected shape \(5,\)"),
])
def test_bad_colors_are_refused_by_name(colors, background, match):
    g = scenes.scene(0)
    with pytest.raises(ValueError, match=match):
        _render(g, scenes.camera(dtype=np.float64), "reference", colors, background)


def test_an_empty_scene_shows_the_background_of_c_channels():
    g = scenes.scene(0)
    empty = jax.tree.map(lambda x: x[:0], g)
    out = _render(empty, scenes.camera(dtype=np.float64), "reference", np.zeros((0, 5)),
                  np.arange(5.0))
    np.testing.assert_array_equal(out.image, np.broadcast_to(np.arange(5.0),
                                                             (scenes.H, scenes.W, 5)))
