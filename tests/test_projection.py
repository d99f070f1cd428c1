"""Projection against the independent float64 numpy oracle (tests/oracle.py); the float32
centre carried as mean2d + mean2d_lo (lgs_jax.twofloat) and every backend taking it so."""

import collections
import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import lgs_jax
from lgs_jax import twofloat
from lgs_jax.projection import project
from lgs_jax.render import composite_projected
from tests import oracle, scenes


@given(seed=st.integers(0, 2**32 - 1), yaw=st.floats(-0.6, 0.6), antialiased=st.booleans())
def test_projection_matches_oracle_float64(seed, yaw, antialiased):
    g = scenes.scene(seed, sh_bases=16)
    cam = scenes.camera(dtype=np.float64, yaw=yaw)
    p = project(g, cam, antialiased)
    want = oracle.project_all(g, cam, antialiased)
    valid = np.asarray(p.valid)
    np.testing.assert_array_equal(valid, [w is not None for w in want])
    for i, w in enumerate(want):
        if w is None:
            continue
        np.testing.assert_allclose(p.mean2d[i], w["mean2d"], rtol=1e-11, atol=1e-9)
        np.testing.assert_allclose(p.conic[i], w["conic"], rtol=1e-9,
                                   atol=1e-12 * np.abs(w["conic"]).max())
        np.testing.assert_allclose(p.cov2d[i], w["cov2d"], rtol=1e-9,
                                   atol=1e-12 * np.abs(w["cov2d"]).max())
        np.testing.assert_allclose(p.depth[i], w["depth"], rtol=1e-13)
        o_rtol = 1e-13
        if antialiased:  # J Σc Jᵀ's entries and determinant cancel: ρ² to eps·|terms|/det
            t = w["terms"].max()  # |J| |Σc| |J|ᵀ bounds each product summed
            xx, xy, yy = w["cov2d"]
            o_rtol += 1e-15 * t * (t + w["cov2d"].max()) / (w["rho"] ** 2 * np.prod(
                np.linalg.eigvalsh([[xx, xy], [xy, yy]])))
        np.testing.assert_allclose(p.opacity[i], w["o"], rtol=o_rtol)
        np.testing.assert_allclose(p.rgb[i], w["rgb"], rtol=1e-11, atol=1e-12)


def test_invalid_gaussians_are_counted_and_finite():
    g = scenes.scene(7, kinds=("invalid", "behind", "normal"))
    p = project(g, scenes.camera(dtype=np.float64))
    invalid = np.asarray(p.invalid)
    assert invalid.any() and not np.asarray(p.valid)[invalid].any()
    for field in (p.mean2d, p.conic, p.rgb, p.opacity):
        assert np.all(np.isfinite(np.asarray(field)))


def test_opaque_logit_inf_is_valid():
    g = scenes.scene(3, kinds=("opaque",))
    p = project(g, scenes.camera(dtype=np.float64))
    want = oracle.project_all(g, scenes.camera(dtype=np.float64))
    np.testing.assert_array_equal(np.asarray(p.valid), [w is not None for w in want])
    assert np.all(np.asarray(p.opacity)[np.asarray(p.valid)] == 1.0)


def test_antialiasing_keeps_each_gaussians_integral():
    """ρ·o·2π·sqrt(det Σ2) = o·2π·sqrt(det(J Σc Jᵀ)): the dilated footprint integrates to the
    undilated one's; ρ is at most 1, near 1 for Gaussians much wider than the 0.3-pixel
    dilation and small for Gaussians much smaller than a pixel."""
    g = scenes.scene(4, kinds=("normal", "tiny", "huge_far", "opaque"))
    cam = scenes.camera(dtype=np.float64)
    plain, aa = project(g, cam), project(g, cam, True)
    valid = np.asarray(aa.valid)
    rho = np.asarray(aa.opacity)[valid] / np.asarray(plain.opacity)[valid]
    xx, xy, yy = np.asarray(plain.cov2d)[valid].T
    det_raw, det = (xx - 0.3) * (yy - 0.3) - xy * xy, xx * yy - xy * xy
    np.testing.assert_allclose(rho * np.sqrt(det), np.sqrt(det_raw), rtol=1e-9)
    assert np.all(rho <= 1) and rho.max() > 0.99 and rho.min() < 0.5
    for name in ("mean2d", "cov2d", "conic", "depth", "rgb"):
        np.testing.assert_array_equal(np.asarray(getattr(aa, name))[valid],
                                      np.asarray(getattr(plain, name))[valid], err_msg=name)


def _wide_scene(seed, n, width):
    """n float32 Gaussians in view of a 16:9 camera `width` px wide at a random pose, scene
    coordinates up to ~100 (where the camera transform rounds at the scene's size)."""
    rng = np.random.default_rng(seed)
    q = rng.normal(size=4)
    rot = np.asarray(lgs_jax.projection.quat_to_rotmat(jnp.asarray(q[None] / np.linalg.norm(q))))
    view = np.eye(4)
    view[:3, :3], view[:3, 3] = rot[0], rng.uniform(-60, 60, 3)
    height, f = width * 9 // 16, 0.9 * width
    z = rng.uniform(2, 20, n)
    cam_xyz = np.stack([rng.uniform(-0.5, 0.5, n) * z * width / f,
                        rng.uniform(-0.5, 0.5, n) * z * height / f, z], -1)
    means = (cam_xyz - view[:3, 3]) @ view[:3, :3]
    g = lgs_jax.Gaussians(means, scenes.random_quats(rng, n), rng.uniform(-3, -1, (n, 3)),
                          rng.uniform(0, 3, n), rng.normal(0, 0.5, (n, 1, 3)))
    cam = lgs_jax.Camera(viewmat=view, fx=f, fy=f, cx=width / 2, cy=height / 2, width=width,
                         height=height)
    return scenes.cast(g, np.float32), jax.tree.map(lambda x: np.asarray(x, np.float32), cam)


@jax.jit
@functools.partial(jax.grad, argnums=(0, 1))
def _centre_grads(g, cam):
    p = project(g, cam)
    return jnp.sum(jnp.where(p.valid[:, None], p.mean2d * jnp.asarray([1, -0.5], p.depth.dtype),
                             0))


@settings(max_examples=5)
@given(seed=st.integers(0, 2**32 - 1))
def test_float32_centre_is_the_float64_centre_split_in_two(seed):
    """At 16K wide, from float32 parameters: mean2d + mean2d_lo is the float64 centre of the
    same parameters to 2^-40 of the image (the plain float32 centre errs by ~1e-3 px there),
    mean2d is that centre rounded (|mean2d_lo| <= ulp(mean2d)/2), and mean2d's derivative is
    the centre's (float32 against float64, through the camera and the means)."""
    g, cam = _wide_scene(seed, 64, 16384)
    g64, cam64 = scenes.cast(g, np.float64), jax.tree.map(lambda x: np.asarray(x, np.float64),
                                                          cam)
    p32, p64 = jax.jit(project)(g, cam), jax.jit(project)(g64, cam64)
    valid = np.asarray(p32.valid)
    np.testing.assert_array_equal(valid, np.asarray(p64.valid))
    hi, lo = (np.asarray(x, np.float64)[valid] for x in (p32.mean2d, p32.mean2d_lo))
    want = np.asarray(p64.mean2d)[valid]
    assert np.abs(hi + lo - want).max() <= 2.0**-40 * 16384
    assert np.all(np.abs(lo) <= np.spacing(np.abs(hi).astype(np.float32)) / 2)
    assert not np.any(np.asarray(p64.mean2d_lo))  # float64: the centre in one number
    for got, want in zip(_centre_grads(g, cam), _centre_grads(g64, cam64)):
        for name in ("means", "viewmat", "fx", "cx"):
            if hasattr(want, name):
                a, b = np.asarray(getattr(got, name)), np.asarray(getattr(want, name))
                np.testing.assert_allclose(a, b, rtol=1e-3, atol=1e-3 * np.abs(b).max(),
                                           err_msg=name)


def _arithmetic(fn, *args, n=8):
    """Float32 operations of `fn` on (n,) columns, as written (its jaxpr): the counts of
    add/sub/mul, bit masks (and) and divisions."""
    counts = collections.Counter(e.primitive.name for e in jax.make_jaxpr(fn)(*args).jaxpr.eqns
                                 if any(v.aval.shape == (n,) for v in e.outvars))
    return counts["add"] + counts["sub"] + counts["mul"], counts["and"], counts["div"]


def test_split_centre_costs_what_twofloat_states():
    """lgs_jax.twofloat's docstring states the split centre's cost per Gaussian: these
    counts."""
    ones = jnp.ones(8, jnp.float32)
    split = lambda x: (x, 0 * x)
    assert _arithmetic(twofloat.camera_coordinates, jnp.eye(4, dtype=jnp.float32),
                       [ones] * 3) == (309, 3, 0)
    assert _arithmetic(lambda t, f: twofloat.screen_centre(*t, f, f, f, f),
                       [split(ones)] * 3, jnp.float32(900)) == (154, 6, 4)
    assert _arithmetic(twofloat.offset, ones, ones, ones) == (2, 0, 0)


C = lgs_jax.RasterConfig
# Slow: the reference shares brute's forward (composite.blend) and tiles' backward for the
# difference form; the Local-GS kernel's difference records are the vanilla kernel's backward.
LOW_PART_CASES = [
    pytest.param("brute", C(), id="brute"),
    pytest.param("reference", C(), id="reference", marks=pytest.mark.slow),
    pytest.param("tiles", C(), id="tiles"),
    pytest.param("tiles", C(hoist=False), id="tiles_difference"),
    pytest.param("pallas", C(), id="pallas"),
    pytest.param("pallas", C(hoist=False), id="pallas_difference", marks=pytest.mark.slow),
    pytest.param("pallas_vanilla", C(), id="pallas_vanilla")]


def _weighted_image(p, backend, config):
    out = composite_projected(p, 64, 48, jnp.asarray([0.2, 0.5, 0.9], jnp.float32), backend,
                              config, 128)
    w = jnp.sin(jnp.arange(out.image.size, dtype=jnp.float32)).reshape(out.image.shape)
    return jnp.sum(out.image * w), out.image


@functools.partial(jax.jit, static_argnames=("backend", "config"))
def _image_and_grad(p, backend, config):
    """The image (the forward alone: a backend's forward for gradients may be another) and
    ∂(Σ w·image)/∂p, in one program per backend (one compile where two programs and an eager
    gradient took three)."""
    image = _weighted_image(p, backend, config)[1]
    grad = jax.grad(lambda q: _weighted_image(q, backend, config)[0], allow_int=True)(p)
    return image, grad


@pytest.mark.parametrize("backend,config", LOW_PART_CASES)
def test_every_backend_takes_the_centre_with_its_low_part(backend, config):
    """Every backend, forward and backward, reads the centre as mean2d + mean2d_lo: broad
    float32 Gaussians (their alpha ellipses hold the 64x48 image, so no cull depends on the
    centre) with a low part of 0.25 px render and differentiate as with that part moved into
    mean2d (exact sums), and unlike without it. A backend dropping mean2d_lo anywhere fails."""
    n = 6
    rng = np.random.default_rng(5)
    p = scenes.projected_conics(np.float32, rng.uniform(0, 1, n), rng.uniform(0, np.pi, n),
                                np.full(n, np.log(300.0)), rng.uniform(0, 12, n),
                                rng.uniform(0, 2 * np.pi, n), rng.uniform(-1, 1, n))
    p = dataclasses.replace(p, rgb=jnp.asarray(rng.uniform(0, 1, (n, 3)), jnp.float32),
                            depth=jnp.asarray(rng.uniform(1, 2, n), jnp.float32))
    lo = jnp.asarray(np.tile([[0.25, -0.125]], (n, 1)), jnp.float32)
    split = dataclasses.replace(p, mean2d_lo=lo)
    moved = dataclasses.replace(p, mean2d=p.mean2d + lo)
    (image, got), (want, want_grad) = (_image_and_grad(q, backend, config)
                                       for q in (split, moved))
    np.testing.assert_allclose(image, want, rtol=0, atol=2e-6)
    assert np.abs(np.asarray(_image_and_grad(p, backend, config)[0]) - want).max() > 1e-3
    want = want_grad
    for name in ("mean2d", "conic", "opacity", "rgb"):
        a, b = np.asarray(getattr(got, name)), np.asarray(getattr(want, name))
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-4 * np.abs(b).max(), err_msg=name)
