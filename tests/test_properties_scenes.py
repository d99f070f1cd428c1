"""Property tests that search scenes: hypothesis draws the Gaussians themselves, so that a failure
shrinks to the feature that causes it (one needle, one far centre, one opacity a hair above 1/255).

The strategy (`scene_values`) draws, for a fixed N = 32 Gaussians, every value that matters to
culling: screen positions on the image or up to 6000 px off it, depths (distinct), pixel sizes
from 0.05 px to ~8000 px with 3D axis ratios up to e^10 (2D condition numbers past 1e8 after the
0.3 px² dilation), rotations (quaternions, not unit length, zero included), opacities anywhere
or within 1e-6..5% of 1/255 on either side. Shapes never change, so every example
reuses the compiled programs.

Binning level (no render; images 1024 to 16384 px wide): at probe pixels on and around each
Gaussian's 1/255 ellipse, every pixel whose alpha test passes (the float test of the
compositing code in the scene's dtype, or the exact test on the same inputs in float64) lies in
the Gaussian's pixel box, its tile rectangle and, in that tile, in both strip masks (difference
and hoisted forms); every pixel whose hoisted float test passes inside a listed tile is in the
hoisted strip mask; and the hoisted exponent (Eq. 8–10, tile-local) is within
`lgs_jax.hoist.error_bound` of its float64 value.

Render level (40x24 in the default set, 3840x2160 in the slow set): `tiles` and `reference` equal
`brute` in float64 (F64_ATOL); in float32 their error against the float64 `brute` image exceeds
float32 `brute`'s own by more than F32_ATOL on at most F32_FLIP_SHARE of the pixels away from
alpha thresholds (`threshold_band`: where a Gaussian's exponent is within both forms' rounding
of ln(1/255); there, and for stop-test flips, a pixel moves by at most one Gaussian). A
Gaussian whose opacity is within ~1e-6 of 1/255 sits at the threshold over its whole footprint:
the hoisted form's test compares ln α with ln(1/255), whose ulp (~5e-7) is coarser than the
difference form's α >= 1/255, so such a Gaussian flips over large areas (hypothesis found one
over 6% of the image); images are finite; Gaussians that binning gives no tile
change no bit of the brute-force image; permuting Gaussians of distinct depths changes no bit.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import HealthCheck, assume, event, given, settings, strategies as st

import lgs_jax
from lgs_jax import alpha as alpha_forms
from lgs_jax import binning, hoist
from lgs_jax.composite import centre_offsets, gaussian_alpha, passes
from lgs_jax.layout import TILE
from lgs_jax.pairs import strip_mask_columns, table_columns, table_offsets
from lgs_jax.projection import project
from tests import scenes
from tests.compare import F32_ATOL, F32_FLIP_SHARE, F64_ATOL, assert_render_close

N = scenes.N  # Gaussians per example (fixed: one compile per program)
RENDER_W, RENDER_H = scenes.W, scenes.H  # 3x2 tiles, the edge ones partial
CAPACITY = scenes.CAPACITY  # >= every Gaussian in every tile (unbounded needles are)
# (The render level uses tests/scenes.py's shapes and capacity, so that its programs are the
# ones the backend tests compile: one compile each in a CI run that shares the cache.)
WIDTHS = (1024, 4096, 8192, 16384)  # binning level: 16:9 images up to 16K
PROBES = 8  # probe directions per Gaussian, each probed at a 3x3 pixel neighbourhood
CAP = 0.99  # the 3dgs convention's alpha cap
ALPHA_MIN = 1 / 255
LN_MIN = np.log(ALPHA_MIN)
COLOURS = np.random.default_rng(0).normal(0, 1.5, (N, 1, 3))  # SH band 0 per Gaussian
FEW = max(4, settings.default.max_examples // 4)  # render-level examples (profile-scaled)


def _each(*strategies):
    """A fixed-length (N,) float64 array whose entries are drawn from any of `strategies`."""
    return st.lists(st.one_of(*strategies), min_size=N, max_size=N).map(np.asarray)


def _near_threshold_logit(rel):
    o = ALPHA_MIN * (1 + rel)
    return float(np.log(o / (1 - o)))


@st.composite
def scene_values(draw, width: int, height: int):
    """Float64 values of N Gaussians for a `width` x `height` camera (`scenes.camera`):
    screen position (px), depth, pixel scale, axis ratio, quaternion, logit opacity. (Colours
    are fixed per index, `COLOURS`: culling never reads them.)"""
    u = draw(_each(st.floats(-0.25 * width, 1.25 * width), st.floats(-6000.0, -0.25 * width),
                   st.floats(1.25 * width, width + 6000.0)))
    v = draw(_each(st.floats(-0.25 * height, 1.25 * height), st.floats(-6000.0, 0.0),
                   st.floats(height, height + 6000.0)))
    depth = draw(st.lists(st.floats(0.5, 20.0), min_size=N, max_size=N, unique=True)
                 .map(np.asarray))
    log_px = draw(_each(st.floats(-3.0, 9.0)))  # largest axis: e^-3 to e^9 px
    log_ratio = draw(_each(st.floats(0.0, 10.0), st.just(0.0)))  # 3D largest / smallest axis
    mid = draw(_each(st.floats(0.0, 1.0)))  # where the middle axis sits between them
    quat = draw(st.lists(st.floats(-1.0, 1.0), min_size=4 * N, max_size=4 * N)
                .map(lambda q: np.asarray(q).reshape(N, 4)))
    logit = draw(_each(st.floats(-6.0, 8.0),
                       st.floats(-5e-2, 5e-2).map(_near_threshold_logit),
                       st.floats(-1e-6, 1e-6).map(_near_threshold_logit)))
    return dict(u=u, v=v, depth=depth, log_px=log_px, log_ratio=log_ratio, mid=mid, quat=quat,
                logit=logit)


def gaussians(values: dict, width: int, height: int, dtype) -> lgs_jax.Gaussians:
    """The Gaussians of `scene_values` for `scenes.camera(width, height)` (focal 0.9·width,
    principal point at the centre, looking down +z), in `dtype`."""
    f = 0.9 * width
    z = values["depth"]
    means = np.stack([(values["u"] - width / 2) * z / f, (values["v"] - height / 2) * z / f, z],
                     -1)
    big = values["log_px"] + np.log(z / f)  # world log-scale of the largest axis
    ratio = values["log_ratio"]
    log_scales = np.stack([big, big - values["mid"] * ratio, big - ratio], -1)
    g = lgs_jax.Gaussians(means=means, quats=values["quat"], log_scales=log_scales,
                          logit_opacities=values["logit"], sh=COLOURS)
    return scenes.cast(g, dtype)


# ------------------------------------------------------------------ binning level, to 16K

@st.composite
def probe_values(draw, width: int, height: int):
    """Per Gaussian and probe: a target point on or near the image (the probe looks from the
    Gaussian's centre towards it) and a relative level ε of the ellipse q = τ(1 + ε). The
    targets come from a drawn seed; the level of each Gaussian's probes is drawn (so that
    hypothesis can steer them onto the ellipse) and spread over its probes by the seed."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    target = rng.uniform(-0.1, 1.1, (N, PROBES, 2)) * [width, height]
    level = draw(_each(st.floats(-1e-7, 1e-7), st.floats(-1e-5, 1e-5), st.floats(-3e-2, 3e-2)))
    return target, level[:, None] * rng.uniform(0, 1, (N, PROBES))


def probe_pixels(p, target, level, width, height):
    """(gaussian, column, row, keep) of the N·PROBES·9 probe pixels (fixed count: one compile):
    the 3x3 pixels around each point where the ray from a Gaussian's centre towards its target
    meets the ellipse q = τ(1 + ε) (float64, from the projection's own conic); `keep` marks
    those of valid Gaussians inside the image (the others are pixel (0, 0), not checked)."""
    f64 = lambda x: np.asarray(x, np.float64)
    mean, conic, o = f64(p.mean2d), f64(p.conic), f64(p.opacity)
    tau = 2 * np.log(np.maximum(255 * o, 1.0))
    d = target - mean[:, None]
    d = d / np.maximum(np.hypot(d[..., 0], d[..., 1]), 1e-30)[..., None]
    qd = (conic[:, None, 0] * d[..., 0] ** 2 + 2 * conic[:, None, 1] * d[..., 0] * d[..., 1]
          + conic[:, None, 2] * d[..., 1] ** 2)
    with np.errstate(invalid="ignore", divide="ignore"):
        r = np.sqrt(tau[:, None] * (1 + level) / qd)
    point = mean[:, None] + np.where(np.isfinite(r), r, 0.0)[..., None] * d
    ok = np.isfinite(point).all(-1) & (np.abs(point).max(-1) < 1e7)
    point = np.where(ok[..., None], point, -10.0)
    step = np.stack(np.meshgrid([-1, 0, 1], [-1, 0, 1]), -1).reshape(9, 2)
    pix = (np.floor(point)[:, :, None, :] + step).reshape(-1, 2)  # (N·PROBES·9, 2)
    gauss = np.repeat(np.arange(N), PROBES * 9)
    keep = ((pix[:, 0] >= 0) & (pix[:, 0] < width) & (pix[:, 1] >= 0) & (pix[:, 1] < height)
            & np.asarray(p.valid)[gauss])
    pix = np.where(keep[:, None], pix, 0).astype(np.int64)
    return gauss, pix[:, 0], pix[:, 1], keep


@jax.jit
def _float_tests(p, gauss, col, row, width, height):
    """At probe pixels (gauss, col, row), in the scene's dtype: the compositing code's alpha
    test, whether the pixel is in the Gaussian's pixel box, its tile rectangle and the strip
    masks (difference, hoisted) of its tile, the hoisted form's raw exponent V·B in the tile's
    frame (RasterConfig's default) and its alpha test. One compile per dtype: the image size
    is traced."""
    dt = p.mean2d.dtype
    cols = [x[gauss] for x in table_columns(p)]
    mx, my, a, b, c, o = cols[:6]
    px, py = (col + 0.5).astype(dt), (row + 0.5).astype(dt)
    power, alpha = gaussian_alpha(centre_offsets((mx, my), cols[10:12], px, py), (a, b, c), o,
                                  jnp.asarray(CAP, dt))
    x0, x1, y0, y1, _ = (t[gauss] for t in binning.pixel_box(p, width, height))
    tx0, ty0, nx, ny, _ = (t[gauss] for t in binning.tile_rects(p, width, height))
    tx, ty = col // TILE, row // TILE
    strip = (row % TILE) // 2
    in_strip = [(strip_mask_columns(cols, tx, ty, lgs_jax.RasterConfig(hoist=h)) >> strip) & 1
                == 1 for h in (False, True)]
    origin = jnp.stack([tx * TILE, ty * TILE], -1).astype(dt)
    log_o = jnp.log(o)
    delta = jnp.stack(table_offsets(cols, tx, ty, lgs_jax.RasterConfig()), -1)
    v = hoist.hoist(delta, jnp.stack([a, b, c], -1), log_o, jnp.zeros_like(delta))
    raw = hoist.evaluate_terms([v[:, k] for k in range(6)], px - origin[:, 0],
                               py - origin[:, 1])
    _, hoisted_pass, _ = alpha_forms.hoisted(raw, log_o, jnp.asarray(CAP, dt))
    return dict(float_pass=passes(power, alpha),
                in_box=(col >= x0) & (col <= x1) & (row >= y0) & (row <= y1),
                in_tiles=(tx >= tx0) & (tx < tx0 + nx) & (ty >= ty0) & (ty < ty0 + ny),
                in_strip_difference=in_strip[0], in_strip_hoisted=in_strip[1],
                hoisted_pass=hoisted_pass, raw=raw)


def check_binning_covers(p, width, height, gauss, col, row, keep):
    """The coverage properties of the module docstring at probe pixels (gauss, col, row) where
    `keep`."""
    dt = np.dtype(p.mean2d.dtype)
    u = np.finfo(dt).eps / 2
    got = {k: np.asarray(v) for k, v in _float_tests(
        p, jnp.asarray(gauss, jnp.int32), jnp.asarray(col, jnp.int32),
        jnp.asarray(row, jnp.int32), jnp.int32(width), jnp.int32(height)).items()}
    table = [np.asarray(c)[gauss] for c in table_columns(p)]
    cols = table[:6]
    # The exact test on the same inputs: q <= τ (the product o·e^power >= 1/255, power <= 0),
    # at the centre μ = mean2d + mean2d_lo.
    up = [np.asarray(x, np.float64) for x in cols]
    up[0], up[1] = (up[i] + np.asarray(table[10 + i], np.float64) for i in range(2))
    dx, dy = up[0] - (col + 0.5), up[1] - (row + 0.5)
    power64 = -0.5 * (up[2] * dx * dx + up[4] * dy * dy) - up[3] * dx * dy
    exact_pass = (power64 <= 0) & (up[5] * np.exp(power64) >= ALPHA_MIN)
    origin = np.stack([col // TILE, row // TILE], -1).astype(np.float64) * TILE
    log_o64 = np.log(np.maximum(up[5], 1e-300))  # o = 0 only where `keep` is False
    raw64 = log_o64 + power64
    bound = np.asarray(hoist.error_bound(
        np.stack(up[:2], -1), np.stack(up[2:5], -1), log_o64, origin,
        np.abs(col + 0.5 - origin[:, 0]), np.abs(row + 0.5 - origin[:, 1]), 16 * u))

    def where(bad):
        k = int(np.flatnonzero(bad)[0])
        return (f"{dt.name} {width}x{height}: Gaussian {gauss[k]} pixel ({col[k]}, {row[k]}), "
                f"mean ({cols[0][k]:.6g}, {cols[1][k]:.6g}), conic ({cols[2][k]:.6g}, "
                f"{cols[3][k]:.6g}, {cols[4][k]:.6g}), o {cols[5][k]:.9g}")

    passing = (got["float_pass"] | exact_pass) & keep
    for name in ("in_box", "in_tiles", "in_strip_difference", "in_strip_hoisted"):
        missed = passing & ~got[name]
        assert not missed.any(), f"{name} misses a passing pixel: {where(missed)}"
    missed = got["hoisted_pass"] & keep & got["in_tiles"] & ~got["in_strip_hoisted"]
    assert not missed.any(), f"hoisted strip mask misses a hoisted pass: {where(missed)}"
    err = np.where(keep, np.abs(np.asarray(got["raw"], np.float64) - raw64), 0.0)
    over = err > bound
    assert not over.any(), f"hoisted exponent error {err[over].max():.3g} over bound: {where(over)}"
    return int(passing.sum())


@settings(suppress_health_check=[HealthCheck.large_base_example])  # N Gaussians' values
@given(data=st.data(), width=st.sampled_from(WIDTHS))
def test_binning_covers_every_passing_pixel_to_16k(data, width):
    """Exact culling at the binning level on images 1K to 16K wide, float32 and float64."""
    height = width * 9 // 16
    values = data.draw(scene_values(width, height), label="scene")
    target, level = data.draw(probe_values(width, height), label="probes")
    for dtype in (np.float32, np.float64):
        p = project(gaussians(values, width, height, dtype), scenes.camera(width, height, dtype))
        passing = check_binning_covers(p, width, height,
                                       *probe_pixels(p, target, level, width, height))
        event(f"{dtype.__name__}: {'no' if passing == 0 else 'some'} passing probe pixels")


def test_binning_covers_faint_huge_gaussians_at_the_corner():
    """The case hypothesis's thorough profile shrank to when the box's rounding pad was removed
    (kept here for the default profile, which finds it rarely): Gaussians thousands of pixels
    wide (conic ~1e-7) at the image corner, their opacity a hair above 1/255, so that the
    passing region is a few pixels whose edge is decided by rounding; every pixel of the
    corner's 48x48 window is probed for every Gaussian."""
    from lgs_jax.projection import Projected

    rng = np.random.default_rng(0)
    opacity = ALPHA_MIN * (1 + np.concatenate([[2.8e-7], rng.uniform(1e-8, 3e-6, N - 1)]))
    conic = np.array([8.78369e-08, -1.38928e-08, 1.0472e-07]) * rng.uniform(0.5, 2, (N, 1))
    conic[0] = [8.78369e-08, -1.38928e-08, 1.0472e-07]
    mean = np.where(np.arange(N)[:, None] == 0, 0.0, rng.uniform(-3, 3, (N, 2)))
    f32 = lambda x: jnp.asarray(x, jnp.float32)
    p = Projected(mean2d=f32(mean), mean2d_lo=f32(np.zeros((N, 2))), cov2d=f32(np.zeros((N, 3))),
                  conic=f32(conic),
                  depth=f32(np.ones(N)), opacity=f32(opacity), rgb=f32(np.zeros((N, 3))),
                  valid=jnp.ones(N, bool), invalid=jnp.zeros(N, bool))
    col, row = (x.ravel() for x in np.meshgrid(np.arange(48), np.arange(48)))
    gauss = np.repeat(np.arange(N), col.size)
    passing = check_binning_covers(p, 1024, 576, gauss, np.tile(col, N), np.tile(row, N),
                                   np.ones(gauss.size, bool))
    assert passing > 0


# ------------------------------------------------------------------ render level

def _render(g, cam, backend, capacity=CAPACITY):
    return lgs_jax.render(g, cam, background=np.asarray(scenes.BACKGROUND, g.means.dtype),
                          backend=backend, config=lgs_jax.RasterConfig(), capacity=capacity)


def threshold_band(p, width, height):
    """(H, W) bool: pixels where some valid Gaussian's alpha test may round either way between
    the difference form (`brute`) and the hoisted form (`tiles`' default): its exponent,
    evaluated in float64 on the float32 inputs, lies within both forms' evaluation bounds
    (difference: 8u of its terms; hoisted: lgs_jax.hoist.error_bound over the tile) plus the
    threshold's own rounding (ln(1/255) has an ulp of ~5e-7) of ln(1/255)."""
    u = np.finfo(np.float32).eps / 2
    f64 = lambda x: np.asarray(x, np.float64)
    mean, conic, opacity = f64(p.mean2d), f64(p.conic), f64(p.opacity)
    px, py = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
    ox, oy = np.floor(px / TILE) * TILE, np.floor(py / TILE) * TILE
    near = np.zeros((height, width), bool)
    for k in np.flatnonzero(np.asarray(p.valid)):
        a, b, c = conic[k]
        dx, dy = mean[k, 0] - px, mean[k, 1] - py
        log_o = np.log(opacity[k])
        half, cross = 0.5 * (a * dx * dx + c * dy * dy), b * dx * dy
        hoisted = np.asarray(hoist.error_bound_terms(a, b, c, mean[k, 0] - ox, mean[k, 1] - oy,
                                                     log_o, px - ox, py - oy, 16 * u))
        band = hoisted + 8 * u * (half + np.abs(cross) + abs(log_o)) + 64 * u * (1 - LN_MIN)
        near |= np.abs(log_o - half - cross - LN_MIN) <= band
    return near


def check_culled_equals_brute(values, width, height, capacity):
    """The render-level properties against `brute` (module docstring)."""
    g64 = gaussians(values, width, height, np.float64)
    cam64 = scenes.camera(width, height, np.float64)
    truth = _render(g64, cam64, "brute", capacity)
    for backend in ("tiles", "reference"):
        out = _render(g64, cam64, backend, capacity)
        for field in ("image", "alpha", "depth"):
            assert_render_close(getattr(out, field), getattr(truth, field), atol=F64_ATOL,
                                what=f"{backend} float64 {field}")
    g32, cam32 = scenes.cast(g64, np.float32), scenes.camera(width, height, np.float32)
    brute32 = _render(g32, cam32, "brute", capacity)
    want = np.asarray(truth.image)
    base = np.abs(np.asarray(brute32.image, np.float64) - want).max(-1)
    near = threshold_band(project(g32, cam32), width, height)
    event(f"{'some' if near.any() else 'no'} pixels at an alpha threshold")
    for backend in ("tiles", "reference"):
        out = _render(g32, cam32, backend, capacity)
        image = np.asarray(out.image, np.float64)
        assert np.all(np.isfinite(image)) and np.all(np.isfinite(np.asarray(out.alpha)))
        excess = np.abs(image - want).max(-1) - base
        share = np.sum(excess[~near] > F32_ATOL) / excess.size
        assert share <= F32_FLIP_SHARE, (
            f"{backend} float32: {share:.2%} of the pixels away from alpha thresholds further "
            f"from float64 brute force than float32 brute force by > {F32_ATOL} "
            f"(max {excess[~near].max(initial=0):.3g})")
        assert excess.max() <= 2.0, f"{backend} float32: a pixel moved by {excess.max():.3g}"


@settings(max_examples=FEW)
@given(values=scene_values(RENDER_W, RENDER_H))
def test_culled_renders_equal_brute_force(values):
    check_culled_equals_brute(values, RENDER_W, RENDER_H, CAPACITY)


@settings(max_examples=FEW)
@given(values=scene_values(RENDER_W, RENDER_H))
def test_gaussians_without_tiles_change_no_bit(values):
    """Removing (opacity 0) every Gaussian that binning gives no tile leaves the float32
    brute-force image (which never reads the tiles) and the `tiles` image bit for bit."""
    g = gaussians(values, RENDER_W, RENDER_H, np.float32)
    cam = scenes.camera(RENDER_W, RENDER_H, np.float32)
    _, _, nx, ny, _ = binning.tile_rects(project(g, cam), RENDER_W, RENDER_H)
    tileless = np.asarray(nx * ny) == 0
    event(f"{'no' if not tileless.any() else 'some'} Gaussians without tiles")
    removed = dataclasses.replace(g, logit_opacities=np.where(
        tileless, -np.inf, g.logit_opacities).astype(np.float32))
    for backend in ("brute", "tiles"):
        np.testing.assert_array_equal(_render(removed, cam, backend).image,
                                      _render(g, cam, backend).image, err_msg=backend)


@settings(max_examples=FEW)
@given(values=scene_values(RENDER_W, RENDER_H), perm=st.permutations(range(N)))
def test_permuting_gaussians_of_distinct_depths_changes_no_bit(values, perm):
    g = gaussians(values, RENDER_W, RENDER_H, np.float32)
    assume(np.unique(np.asarray(g.means[:, 2])).size == N)
    perm = np.asarray(perm)
    shuffled = lgs_jax.Gaussians(*(np.asarray(x)[perm] for x in (
        g.means, g.quats, g.log_scales, g.logit_opacities, g.sh)))
    cam = scenes.camera(RENDER_W, RENDER_H, np.float32)
    for backend in ("brute", "tiles"):
        np.testing.assert_array_equal(_render(shuffled, cam, backend).image,
                                      _render(g, cam, backend).image, err_msg=backend)


@pytest.mark.slow  # 3840x2160: its own compiles of three backends in two dtypes
@settings(max_examples=3)
@given(values=scene_values(3840, 2160))
def test_culled_renders_equal_brute_force_4k(values):
    check_culled_equals_brute(values, 3840, 2160, N * 240 * 135)
