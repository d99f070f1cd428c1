"""Gradients of `render` (the custom_vjps of `reference`, `tiles` and the Pallas backends: the
backward walk of lgs_jax.backends.backward and the Pallas backward kernels) against autodiff
through `brute` (float64), each other, central finite differences, float32, determinism, vmap and
jit. The Pallas backward kernel's own unit test against the tiles walk is in
tests/backends/test_pallas.py. Default set: one representative per backend and switch; the
products are marked slow."""

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import lgs_jax
from lgs_jax.projection import project
from tests import scenes
from tests.compare import GRAD_F64_REL, assert_close_to_scale
from tests.devices import ON_GPU

C = lgs_jax.RasterConfig
SLOW = pytest.mark.slow
FIELDS = scenes.FIELDS
W, H = scenes.W, scenes.H


def _weights(dtype, seed=0):
    rng = np.random.default_rng(seed)
    return (rng.normal(size=(H, W, 3)).astype(dtype), rng.normal(size=(H, W)).astype(dtype),
            rng.normal(size=(H, W)).astype(dtype))


def _loss(g, cam, bg, backend, config, weights):
    """A scalar of image, alpha and depth (all three outputs carry gradient)."""
    out = lgs_jax.render(g, cam, background=bg, backend=backend, config=config,
                         capacity=None if backend == "brute" else scenes.CAPACITY)
    wi, wa, wd = weights
    return jnp.sum(out.image * wi) + jnp.sum(out.alpha * wa) + 0.1 * jnp.sum(out.depth * wd)


# One jitted program per (backend, configuration, dtype), the scene, camera, background and
# weights its arguments: the tests' programs are compiled, not their examples (a hypothesis
# example costs milliseconds; a compile seconds), so every test of a backend shares it.
_grad_program = jax.jit(jax.grad(_loss, argnums=(0, 1, 2)), static_argnums=(3, 4))


# The default configuration's float64 gradients of `brute`, `reference` and `tiles`, which the
# default tests read together, in one program: compiled together, the three cost about a third
# less than apart.
TRIO = ("brute", "reference", "tiles")
_trio_program = jax.jit(lambda g, cam, bg, weights: {
    b: jax.grad(_loss, argnums=(0, 1, 2))(g, cam, bg, b, C(), weights) for b in TRIO})


def _grads(g, cam, backend, config, dtype=np.float64):
    """Gradients of `_loss` w.r.t. (Gaussians, camera, background): every test of a backend
    and configuration takes all three from one program (the camera's cost little), so the
    tests share their compiled programs."""
    bg = jnp.asarray(scenes.BACKGROUND, dtype)
    if backend in TRIO and config == C() and dtype == np.float64:
        return _trio_program(g, cam, bg, _weights(dtype))[backend]
    return _grad_program(g, cam, bg, backend, config, _weights(dtype))


@functools.partial(jax.jit, static_argnums=(3,))
def _views_and_batch(g, cams, bg, backend, weights):
    """Float32 gradients w.r.t. the Gaussians of `_loss` for each camera of `cams` alone, and
    vmapped over them: one program (the float32 tests of a fast backend read both)."""
    grad = lambda g, c: jax.grad(_loss)(g, c, bg, backend, C(), weights)
    batched = jax.vmap(grad, in_axes=(None, 0))(g, lgs_jax.stack_cameras(cams))
    return [grad(g, c) for c in cams], batched


def _float32_grads(g, backend):
    """`_views_and_batch` for the float32 scene `g` at two yaws (0 and 0.15)."""
    cams = [scenes.camera(yaw=y) for y in (0.0, 0.15)]
    return _views_and_batch(g, cams, jnp.asarray(scenes.BACKGROUND, np.float32), backend,
                            _weights(np.float32))


_invalid = jax.jit(lambda g, cam: project(g, cam).invalid)  # one compile, not one per operation


@pytest.mark.parametrize("config", [C(), pytest.param(C(antialiased=True), marks=SLOW),
                                    pytest.param(C("gsplat"), marks=SLOW)], ids=str)
@given(seed=st.integers(0, 2**32 - 1))
def test_reference_gradients_equal_autodiff_through_brute_float64(config, seed):
    """Every adversarial kind (needles, huge, opaque with logit +inf, layers, faint, NaN / inf /
    zero-quaternion rows, behind the camera): equal gradients, and no NaN or inf anywhere (for
    invalid rows too: they get exactly zero; antialiased needles whose screen covariance is
    singular in rounding too: their opacity is 0)."""
    g = scenes.scene(seed)
    cam = scenes.camera(dtype=np.float64)
    (gr, _, bgr), (gb, _, bgb) = (_grads(g, cam, b, config) for b in ("reference", "brute"))
    invalid = np.asarray(_invalid(g, cam))
    for name in FIELDS:
        want, got = np.asarray(getattr(gb, name)), np.asarray(getattr(gr, name))
        assert np.all(np.isfinite(got)), name
        assert np.all(got[invalid] == 0), name
        assert_close_to_scale(got, want, 1e-8, name)
        # No gradient lost or invented: the same Gaussians receive gradient.
        moved = lambda x: np.any(x.reshape(x.shape[0], -1) != 0, axis=1)
        np.testing.assert_array_equal(moved(got), moved(want), err_msg=name)
    assert_close_to_scale(bgr, bgb, 1e-8)


@given(seed=st.integers(0, 2**32 - 1), yaw=st.floats(-0.6, 0.6))
def test_camera_gradients_equal_autodiff_through_brute_and_are_finite(seed, yaw):
    """The camera's gradient (its world-to-camera matrix and intrinsics: what pose and
    intrinsics optimization read) through every adversarial kind: finite, and the reference's
    and tiles' equal brute's (float64). The camera sits at the world origin, where each invalid
    row's placeholder mean lies: the square root's infinite derivative there once made it NaN."""
    g = scenes.scene(seed)
    cam = scenes.camera(dtype=np.float64, yaw=yaw)
    want = _grads(g, cam, "brute", C())[1]
    for backend in ("brute", "reference", "tiles"):
        got = want if backend == "brute" else _grads(g, cam, backend, C())[1]
        for name in ("viewmat", "fx", "fy", "cx", "cy"):
            x = np.asarray(getattr(got, name))
            assert np.all(np.isfinite(x)), (backend, name)
            assert_close_to_scale(x, getattr(want, name), 1e-8, f"{backend} {name}")


@pytest.mark.parametrize("backend,config", [
    pytest.param("reference", C(), id="reference", marks=SLOW),
    pytest.param("tiles", C(blend="fast"), id="tiles_fast"),
    pytest.param("tiles", C(antialiased=True), id="tiles_antialiased", marks=pytest.mark.slow)])
def test_gradients_match_central_differences(backend, config):
    """Well-separated, moderately opaque Gaussians (no depth ties or threshold within reach of
    the step), float64, six entries of every parameter group, and the camera's (antialiased).
    (`fast` blending has no reference backend to compare with: this is its check.)"""
    g = scenes.scene(11, kinds=("normal",))
    cam = scenes.camera(dtype=np.float64)
    bg = jnp.asarray(scenes.BACKGROUND)
    weights = _weights(np.float64)
    # One program for the loss and its gradient (the differences read its value): one compile.
    value_and_grad = jax.jit(jax.value_and_grad(lambda g: _loss(g, cam, bg, backend, config,
                                                                weights)))
    f = lambda g: value_and_grad(g)[0]
    grads = value_and_grad(g)[1]
    rng = np.random.default_rng(0)
    eps = 1e-6
    for name in FIELDS:
        x = np.asarray(getattr(g, name))
        for flat in rng.choice(x.size, 6, replace=False):
            idx = np.unravel_index(flat, x.shape)
            plus, minus = x.copy(), x.copy()
            plus[idx] += eps
            minus[idx] -= eps
            shifted = lambda v: lgs_jax.Gaussians(**{**{n: getattr(g, n) for n in FIELDS},
                                                     name: v})
            fd = float(f(shifted(plus)) - f(shifted(minus))) / (2 * eps)
            got = float(np.asarray(getattr(grads, name))[idx])
            assert abs(fd - got) <= 1e-5 * max(1.0, abs(fd)), (name, idx, fd, got)
    # The camera's: its intrinsics and six entries of its world-to-camera matrix (what pose
    # and intrinsics optimization read), moved one at a time as the Gaussians' fields are.
    # Once, antialiased (its opacity depends on the camera too): the blend's cotangents
    # reach the camera through the projection alone, as checked above (CI time).
    if not config.antialiased:
        return
    value_and_grad = jax.jit(jax.value_and_grad(lambda c: _loss(g, c, bg, backend, config,
                                                                weights)))
    f = lambda c: value_and_grad(c)[0]
    grads = value_and_grad(cam)[1]
    view = np.asarray(cam.viewmat)

    def moved(name, idx, v):
        if name == "viewmat":
            m = view.copy()
            m[idx] = v
            v = m
        return dataclasses.replace(cam, **{name: v})

    entries = [(k, ()) for k in ("fx", "fy", "cx", "cy")] + [
        ("viewmat", np.unravel_index(flat, (3, 4))) for flat in rng.choice(12, 6, replace=False)]
    for name, idx in entries:
        x = float(np.asarray(getattr(cam, name))[idx])
        fd = float(f(moved(name, idx, x + eps)) - f(moved(name, idx, x - eps))) / (2 * eps)
        got = float(np.asarray(getattr(grads, name))[idx])
        assert abs(fd - got) <= 1e-5 * max(1.0, abs(fd)), (name, idx, fd, got)


@pytest.mark.slow  # the fast backends' float32 gradients are in the default set
def test_float32_gradients_are_close_to_float64():
    """Relative L2 error per parameter group, float32 vs float64 (tolerance 1e-3)."""
    g64 = scenes.scene(5, kinds=("normal", "opaque", "layers", "tiny", "needle"))
    cam64, cam32 = scenes.camera(dtype=np.float64), scenes.camera()
    g32 = scenes.cast(g64, np.float32)
    a = _grads(g64, cam64, "reference", C())[0]
    b = _grads(g32, cam32, "reference", C(), np.float32)[0]
    for name in FIELDS:
        x, y = np.asarray(getattr(a, name)), np.asarray(getattr(b, name), np.float64)
        rel = np.linalg.norm(x - y) / max(np.linalg.norm(x), 1e-30)
        assert rel < 1e-3, (name, rel)


@pytest.mark.parametrize("backend", ["tiles", pytest.param("reference", marks=SLOW),
                                     pytest.param("pallas", marks=SLOW)])
def test_gradients_are_deterministic_and_compose_with_jit_and_vmap(backend):
    g = scenes.cast(scenes.scene(2), np.float32)
    # The single views and their vmapped batch from one jitted program (shared with the
    # float32 gradient tests), run twice.
    (first, batched), (again, batched_again) = (_float32_grads(g, backend) for _ in range(2))
    for a, b in zip(jax.tree.leaves((first, batched)), jax.tree.leaves((again, batched_again))):
        np.testing.assert_array_equal(a, b)
    # XLA compiles the batched projection differently from the single one (1-ulp differences,
    # CPU and GPU alike), which can flip one pixel's alpha test and move a gradient by that
    # pixel's contribution: measured 3e-4 of the scale on this scene on the H100 and 1.9e-4 on
    # the CPU (quats; BENCHMARKS.md §5). Bits stay the same call to call (above).
    rel = 1e-3
    for i, single in enumerate(first):
        for name in FIELDS:
            want = np.asarray(getattr(single, name))
            np.testing.assert_allclose(getattr(batched, name)[i], want, rtol=0,
                                       atol=rel * np.abs(want).max(), err_msg=name)


def test_screen_space_gradients_and_visibility_for_densification():
    """∂L/∂mean2d through `screen_offsets` (zeros): equal to autodiff through brute, zero for
    Gaussians not visible, and `visible` marks exactly the Gaussians with tile pairs."""
    g = scenes.scene(4)
    cam = scenes.camera(dtype=np.float64)
    bg = jnp.asarray(scenes.BACKGROUND)
    weights = _weights(np.float64)
    zeros = jnp.zeros((g.num, 2))

    def loss(offsets, backend):
        out = lgs_jax.render(g, cam, background=bg, backend=backend, screen_offsets=offsets,
                             capacity=None if backend == "brute" else scenes.CAPACITY)
        return jnp.sum(out.image * weights[0]), out

    # One program per backend: the render read below is the differentiated one (its aux).
    grad = jax.jit(jax.grad(loss, has_aux=True), static_argnums=1)
    got, out = grad(zeros, "reference")
    got, want = np.asarray(got), np.asarray(grad(zeros, "brute")[0])
    assert_close_to_scale(got, want, 1e-8)
    visible = np.asarray(out.visible)
    assert visible.shape == (g.num,) and visible.sum() > 0
    assert np.all(got[~visible] == 0)
    # visible == has at least one tile pair
    from lgs_jax import binning

    _, _, nx, ny, _ = jax.jit(lambda g, c: binning.tile_rects(project(g, c), c.width,
                                                                c.height))(g, cam)
    np.testing.assert_array_equal(visible, np.asarray(nx * ny) > 0)
    assert int(np.sum(np.asarray(nx * ny))) == int(out.stats.pairs_required)


TILES = {"local_gs": C(), "no_cull": C(warp_cull=False), "difference": C(hoist=False),
         "global": C(local_coords=False), "center": C(origin="center"), "gsplat": C("gsplat")}


@pytest.mark.parametrize("name", [n if n == "local_gs" else pytest.param(n, marks=SLOW)
                                  for n in TILES])
@given(seed=st.integers(0, 2**32 - 1))
def test_tiles_gradients_equal_reference_gradients_float64(name, seed):
    """The tiles backward (its own hoisted arithmetic and strip masks) against the reference
    backward: equal to rounding (1e-9 of scale) on every adversarial kind."""
    g = scenes.scene(seed)
    cam = scenes.camera(dtype=np.float64)
    config = TILES[name]
    (gt, _, bgt), (gr, _, bgr) = (_grads(g, cam, b, c) for b, c in
                            (("tiles", config), ("reference", C(config.convention))))
    for field in FIELDS:
        want, got = np.asarray(getattr(gr, field)), np.asarray(getattr(gt, field))
        assert np.all(np.isfinite(got)), field
        assert_close_to_scale(got, want, GRAD_F64_REL, field)
    assert_close_to_scale(bgt, bgr, GRAD_F64_REL)


@pytest.mark.parametrize("backend", ["tiles", pytest.param("pallas", marks=SLOW)])
def test_fast_backends_float32_gradients_are_close_to_float64(backend):
    g64 = scenes.scene(5, kinds=("normal", "opaque", "layers", "tiny", "needle"))
    a = _grads(g64, scenes.camera(dtype=np.float64), "reference", C())[0]
    b = _float32_grads(scenes.cast(g64, np.float32), backend)[0][0]  # yaw 0: camera()
    for name in FIELDS:
        x, y = np.asarray(getattr(a, name)), np.asarray(getattr(b, name), np.float64)
        assert np.linalg.norm(x - y) / max(np.linalg.norm(x), 1e-30) < 1e-3, name


# `auto` differentiates through Mosaic GPU on the GPU and through Triton in interpret mode
# (KernelConfig); the `other` rows run the implementation auto does not pick here. On the CPU
# `vanilla_other` (the vanilla Mosaic GPU forward, interpreted: 24 s) is left out: its backward
# is the Mosaic kernel in the difference form, which test_pallas.py's walk test checks, and its
# forward test_mosaic_kernels_equal_triton_kernels.
OTHER = "triton" if ON_GPU else "mosaic"
PALLAS = {"local_gs": ("pallas", C()), "difference": ("pallas", C(hoist=False)),
          "global": ("pallas", C(local_coords=False)), "gsplat": ("pallas", C("gsplat")),
          "vanilla": ("pallas_vanilla", C()), "vanilla_gsplat": ("pallas_vanilla", C("gsplat")),
          "other": ("pallas", C(kernel=OTHER)),
          **({"vanilla_other": ("pallas_vanilla", C(kernel=OTHER))} if ON_GPU else {})}


@pytest.mark.parametrize("name", [n if n == "local_gs" else pytest.param(n, marks=SLOW)
                                  for n in PALLAS])
@settings(max_examples=3)  # interpret mode: the kernels run serially, one program at a time
@given(seed=st.integers(0, 2**32 - 1))
def test_pallas_gradients_equal_reference_gradients_float64(name, seed):
    """The Pallas backward (kernel in interpret mode on CPU) through `render`, against the
    reference backward, on every adversarial kind: equal to rounding, nothing lost."""
    g = scenes.scene(seed)
    cam = scenes.camera(dtype=np.float64)
    backend, config = PALLAS[name]
    (gp, _, bgp), (gr, _, bgr) = (_grads(g, cam, b, c) for b, c in
                            ((backend, config), ("reference", C(config.convention))))
    invalid = np.asarray(_invalid(g, cam))
    for field in FIELDS:
        want, got = np.asarray(getattr(gr, field)), np.asarray(getattr(gp, field))
        assert np.all(np.isfinite(got)) and np.all(got[invalid] == 0), field
        assert_close_to_scale(got, want, GRAD_F64_REL, field)
    assert_close_to_scale(bgp, bgr, GRAD_F64_REL)


@pytest.mark.parametrize("backend,config", [
    pytest.param("tiles", C(), marks=SLOW), ("pallas", C(kernel="mosaic")),
    pytest.param("pallas", C(kernel="triton"), marks=SLOW),
    pytest.param("reference", C(), marks=SLOW)])
def test_a_loss_without_depth_gives_the_gradients_of_a_zero_depth_weight(backend, config):
    """A loss of image and alpha alone leaves the depth's cotangent a symbolic zero, which the
    Mosaic GPU backward neither materialises nor reads (`backward.differentiable`): its
    gradients equal those of the same loss plus Σ depth·0 with the zeros an argument (a real
    zero plane read by the kernel)."""
    g, cam = scenes.scene(3), scenes.camera(dtype=np.float64)
    bg = jnp.asarray(scenes.BACKGROUND, np.float64)
    wi, wa, _ = _weights(np.float64)

    def loss(g, zeros):
        out = lgs_jax.render(g, cam, background=bg, backend=backend, config=config,
                             capacity=scenes.CAPACITY)
        image_alpha = jnp.sum(out.image * wi) + jnp.sum(out.alpha * wa)
        return image_alpha if zeros is None else image_alpha + jnp.sum(out.depth * zeros)

    # Both gradients in one program: its two backward passes share one forward (XLA merges
    # the identical forwards), a third less compiling than two programs.
    without, with_zeros = jax.jit(lambda g, zeros: (jax.grad(lambda g: loss(g, None))(g),
                                                    jax.grad(loss)(g, zeros)))(
        g, jnp.zeros((H, W), np.float64))
    for field in FIELDS:
        got, want = np.asarray(getattr(without, field)), np.asarray(getattr(with_zeros, field))
        np.testing.assert_array_equal(got, want, field)
        assert np.any(got != 0), field
