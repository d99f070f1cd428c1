"""lgs_jax.backends.pallas.backend: the `pallas` / `pallas_vanilla` backends against `reference`
and `tiles`.

Without a GPU the kernels run in Pallas interpret mode (what CI exercises); on a GPU the same
tests run the compiled kernels (scripts/gpu_check.sh). The default set runs one representative
per kernel and per switch; the products (every switch x kernel x dtype, more examples) are
marked slow (`python -m pytest -m slow`).
`test_kernels_lower_for_the_gpu` lowers every kernel variant, forward and backward, through the
Triton or Mosaic GPU lowering on any machine (the GPU description is faked), so a primitive a
lowering lacks fails here, not first on the GPU.
"""

import dataclasses

import jax
import numpy as np
import pytest
from hypothesis import example, given, settings, strategies as st

import lgs_jax
from lgs_jax.projection import project
from tests import scenes
from tests.compare import (ALPHA_CAP, F32_ATOL, F32_FLIP_SHARE, F64_ATOL, GRAD_F64_REL,
                           assert_close_to_scale, assert_composites_equal, assert_float32_close,
                           assert_render_close, assert_within_fast_bound)
from tests.devices import ON_GPU

C = lgs_jax.RasterConfig
K = lgs_jax.KernelConfig
SLOW = pytest.mark.slow
AUTO = "mosaic" if ON_GPU else "triton"  # what kernel="auto" runs here (pallas.plan)
KERNEL = {"pallas": "localgs", "pallas_vanilla": "vanilla"}
LOCALGS = {  # the switches the Local-GS kernel honours (exact blending)
    "local_gs": C(),
    "no_cull": C(warp_cull=False),
    "difference": C(hoist=False),
    "baseline": C(hoist=False, warp_cull=False),
    "local_center": C(origin="center"),
    "global": C(local_coords=False),
    "gsplat": C("gsplat"),
    "antialiased": C(antialiased=True),
}


# default: "baseline" has both culling and hoisting off; the centre origin and the gsplat
# convention (constants of the kernel) in one case
GSPLAT_CENTER = C("gsplat", origin="center")


@pytest.mark.parametrize("name", [pytest.param(n, marks=SLOW) if n in (
    "no_cull", "difference", "antialiased", "local_center", "gsplat") else n
                                  for n in [*LOCALGS, "gsplat_center"]])
@settings(max_examples=6)  # interpret mode on CPU: ~0.7 s per example
@given(seed=st.integers(0, 2**32 - 1))
def test_localgs_kernel_equals_reference_float64(name, seed):
    g = scenes.scene(seed)
    cam = scenes.camera(dtype=np.float64)
    config = GSPLAT_CENTER if name == "gsplat_center" else LOCALGS[name]
    ref = scenes.render(g, cam, "reference", C(config.convention,
                                                antialiased=config.antialiased))
    out = scenes.render(g, cam, "pallas", config)
    assert out.stats.backend_stats.kernel == f"localgs-{AUTO}"
    assert out.stats.backend_stats.interpreted == (not ON_GPU)
    for field in ("image", "alpha", "depth"):
        assert_render_close(getattr(out, field), getattr(ref, field), atol=F64_ATOL, what=field)


@pytest.mark.parametrize("name", ["local_gs"] + [pytest.param(n, marks=SLOW) for n in (
    "difference", "local_center", "gsplat")])
@settings(max_examples=6)  # interpret mode on CPU: ~0.7 s per example
@given(seed=st.integers(0, 2**32 - 1))
def test_localgs_kernel_equals_reference_float32(name, seed):
    """Same tolerance as the tiles backend (tests/compare.py, F32_ATOL): hoisted and difference
    forms round differently; threshold flips on at most 1% of pixels."""
    g = scenes.cast(scenes.scene(seed), np.float32)
    cam = scenes.camera()
    config = LOCALGS[name]
    ref = scenes.render(g, cam, "reference", C(config.convention))
    out = scenes.render(g, cam, "pallas", config)
    assert out.image.dtype == np.float32
    assert_float32_close(out, ref)
    tiles = scenes.render(g, cam, "tiles", config)
    assert_render_close(out.image, tiles.image, atol=F32_ATOL, max_flip_share=F32_FLIP_SHARE,
                        flip_atol=2.0)
    # The Mosaic GPU kernel ("auto" on a GPU) builds its masks itself and does not count them.
    counted = out.stats.backend_stats.kernel != "localgs-mosaic"
    strip_pairs = int(tiles.stats.backend_stats.strip_pairs)
    assert int(out.stats.backend_stats.strip_pairs) == (strip_pairs if counted else -1)


@pytest.mark.parametrize("convention,dtype", [
    ("3dgs", np.float32), ("gsplat", np.float64),
    pytest.param("3dgs", np.float64, marks=SLOW), pytest.param("gsplat", np.float32, marks=SLOW)])
@settings(max_examples=6)  # interpret mode on CPU: ~0.7 s per example
@given(seed=st.integers(0, 2**32 - 1))
@example(seed=1711)  # H200: alpha 2.3e-5 from the reference's in 5 pixels
def test_vanilla_kernel_equals_reference(convention, dtype, seed):
    """The vanilla kernel is the reference's arithmetic in the reference's order."""
    g = scenes.cast(scenes.scene(seed), dtype)
    cam = scenes.camera(dtype=dtype)
    ref = scenes.render(g, cam, "reference", C(convention))
    out = scenes.render(g, cam, "pallas_vanilla", C(convention))
    assert out.stats.backend_stats.kernel == f"vanilla-{AUTO}"
    for field in ("image", "alpha", "depth"):
        # float32: 1e-5 of the field's scale (depth is in scene units), 5e-5 on the GPU, where
        # the Mosaic kernel's exp and multiply-adds round differently from XLA's (H100: depth
        # 5.8e-6 of scale, image 3.9e-6; H200, seed 1711: alpha 2.3e-5 in 5 pixels of 960,
        # where long lists accumulate it); interpret mode matches to 1e-6.
        scale = max(1.0, float(np.abs(np.asarray(getattr(ref, field))).max()))
        atol = F64_ATOL if dtype == np.float64 else (5e-5 if ON_GPU else 1e-5) * scale
        assert_render_close(getattr(out, field), getattr(ref, field), atol=atol,
                            max_flip_share=0.0 if dtype == np.float64 else 0.005,
                            flip_atol=2.0, what=field)


MOSAIC = {**{n: ("pallas", c) for n, c in LOCALGS.items()},
          "vanilla": ("pallas_vanilla", C()), "vanilla_gsplat": ("pallas_vanilla", C("gsplat"))}


# Slow: each switch that changes the Local-GS kernel's own code path (culling off, the
# difference form, global coordinates) in float32, each convention in float64, and the vanilla
# kernel in float32. The switches run the same arithmetic in either dtype, and the origin,
# baseline and vanilla-convention cases take no path the others do not (each cost CI about
# 15 s on two cores for no new path).
# The default vanilla case runs the gsplat convention: its Triton render is the program
# test_vanilla_kernel_equals_reference[gsplat-float64] compiled (the same HLO, the persistent
# cache's); the 3dgs convention only changes constants (slow).
MOSAIC_SLOW = (("no_cull", np.float32), ("difference", np.float32), ("global", np.float32),
               ("gsplat", np.float64), ("vanilla", np.float32), ("vanilla", np.float64))


@pytest.mark.parametrize("name,dtype", [("local_gs", np.float32),
                                        ("vanilla_gsplat", np.float64)] + [
    pytest.param(n, d, marks=SLOW) for n, d in MOSAIC_SLOW])
@settings(max_examples=3)  # interpret mode: one program at a time
@given(seed=st.integers(0, 2**32 - 1))
def test_mosaic_kernels_equal_triton_kernels(name, dtype, seed):
    """The Mosaic GPU forward kernels (a warpgroup per tile or half tile) run the Triton kernels'
    arithmetic in the same order with exact blending: the same image, alpha, depth and stop
    pairs, bit for bit in interpret mode (the image to `assert_composites_equal`'s ulp: the
    Triton kernels' colour reaches the composite as planes, the Mosaic GPU kernel's as an
    image); on the GPU, float64 to 1e-9 and float32 within the
    float32 tolerance of the other kernels, relative to the field's scale (the compilers' exp
    and multiply-add contraction differ: measured 4e-5 at most in image and alpha)."""
    backend, config = MOSAIC[name]
    g = scenes.cast(scenes.scene(seed), dtype)
    cam = scenes.camera(dtype=dtype)
    outs = {k: scenes.render(g, cam, backend, dataclasses.replace(config, kernel=k))
            for k in ("triton", "mosaic")}
    assert outs["mosaic"].stats.backend_stats.kernel == KERNEL[backend] + "-mosaic"
    for field in ("image", "alpha", "depth"):
        got, want = getattr(outs["mosaic"], field), getattr(outs["triton"], field)
        if not ON_GPU and field == "image" and backend == "pallas":  # the Triton kernel's
            assert_composites_equal(got, want)  # colour is per-tile planes, this one's an image
        elif not ON_GPU or dtype == np.float64:
            np.testing.assert_allclose(got, want, rtol=0, atol=F64_ATOL if ON_GPU else 0,
                                       err_msg=field)
        else:  # the GPU's float32 exp and multiply-add contraction differ between the compilers
            # Global coordinates: the hoisted sum's cancellation (numerics/) amplifies those ulps
            # into flipped alpha tests (H100: 2.6% of depth pixels, by up to 4.6e-4).
            # Depth is in scene units: the weights' roundings scale with it (H200, no_cull,
            # seed 126: 15 of 960 depth pixels off by up to 3.2e-4 where depth reaches 4.3).
            share = 0.05 if name == "global" else F32_FLIP_SHARE
            scale = max(1.0, float(np.abs(np.asarray(want)).max()))
            assert_render_close(got, want, atol=F32_ATOL * scale, max_flip_share=share,
                                flip_atol=2.0 * scale, what=field)


@pytest.mark.parametrize("convention,kernel", [
    ("gsplat", "triton"), ("3dgs", "mosaic"),
    pytest.param("3dgs", "triton", marks=SLOW), pytest.param("gsplat", "mosaic", marks=SLOW)])
@settings(max_examples=5)  # interpret mode on CPU: ~0.7 s per example (Mosaic GPU: more)
@given(seed=st.integers(0, 2**32 - 1))
def test_fast_blending_kernel_stays_within_its_bound(convention, kernel, seed):
    """|fast − exact| <= 1e-4/(1 − cap)·max|rgb − background| (lgs_jax.backends.tiles); the
    Mosaic kernel stops per block (a tile or half tile) instead of per strip, which blends only
    more of the remaining T < 1e-4 and stays within the same bound."""
    g = scenes.scene(seed, kinds=("normal", "opaque", "layers", "tiny"))
    cam = scenes.camera(dtype=np.float64)
    bg = np.array(scenes.BACKGROUND)
    exact = scenes.render(g, cam, "reference", C(convention))
    fast = scenes.render(g, cam, "pallas", C(convention, blend="fast", kernel=kernel))
    assert_within_fast_bound(fast, exact, project(g, cam).rgb, bg, ALPHA_CAP[convention])


def test_pallas_under_jit_and_vmap_reports_overflow_and_matches_single_views():
    g = scenes.cast(scenes.scene(7), np.float32)
    cams = lgs_jax.stack_cameras([scenes.camera(yaw=y) for y in (0.0, 0.2)])
    # The scene is an argument of both programs (a closed-over constant would be folded at
    # compile time and round differently). A single view is `scenes.render`'s program (render's
    # own jit, the scene its argument), which the float32 tests above compiled.
    one = lambda g, c: scenes.render(g, c, "pallas", C())
    out = jax.jit(jax.vmap(one, in_axes=(None, 0)))(g, cams)
    # XLA vectorises the batched projection differently (CPU and GPU): 1 ulp on a few pixels,
    # as for the tiles backend (BENCHMARKS.md §3).
    for i, yaw in enumerate((0.0, 0.2)):
        np.testing.assert_allclose(out.image[i], one(g, scenes.camera(yaw=yaw)).image, rtol=0,
                                   atol=1e-6)
    # The overflow the backend reports: `render` raises on its stats with the pairs required
    # (one program, render's jitted one: under a caller's jit the same stats come back
    # unchecked, CI time).
    with pytest.raises(lgs_jax.CapacityError) as err:
        lgs_jax.render(g, scenes.camera(), backend="pallas", capacity=8)
    assert err.value.required > 8


def test_empty_and_background_only_scenes():
    g = scenes.cast(scenes.scene(1, kinds=("behind", "invalid")), np.float32)
    out = scenes.render(g, scenes.camera(), "pallas", C())
    np.testing.assert_array_equal(out.image, np.broadcast_to(
        np.asarray(scenes.BACKGROUND, np.float32), out.image.shape))


BACKWARD = {**{n: LOCALGS[n] for n in ("local_gs", "no_cull", "difference", "local_center",
                                         "global", "gsplat")},
            "fast": C(blend="fast"), "fast_gsplat": C("gsplat", blend="fast")}


def _backward_cases():
    """Default: float64, the Triton kernel with hoisting on and off, both conventions and both
    blending modes (the gsplat convention and fast blending in one case), and the Mosaic GPU
    kernel (half-tile blocks); slow: every other switch and each of those two alone,
    whole-tile Mosaic GPU blocks (both blending modes in float64, both α forms in float32; the
    conventions only change constants the Triton cases cover), and float32 for both α forms
    of both kernels (the other switches run the same float32 code paths)."""
    default = ("local_gs", "difference", "fast_gsplat")
    triton = [(n, "triton", None) for n in default]
    triton_slow = [(n, "triton", None) for n in BACKWARD if n not in default]
    mosaic = [("local_gs", "mosaic", 128)]
    mosaic_slow = [(n, "mosaic", 256) for n in ("local_gs", "fast")]
    mosaic_slow_f32 = [(n, "mosaic", 256) for n in ("local_gs", "difference")]
    return ([(*case, np.float64) for case in triton + mosaic]
            + [pytest.param(*case, np.float64, marks=SLOW) for case in triton_slow + mosaic_slow]
            + [pytest.param(*case, np.float32, marks=SLOW)
               for case in triton[:2] + mosaic + mosaic_slow_f32])


@pytest.mark.parametrize("name,kernel,pixels,dtype", _backward_cases())
@settings(max_examples=2)  # interpret mode: the kernels run serially, one program at a time
@given(seed=st.integers(0, 2**32 - 1))
def test_backward_kernel_equals_the_tiles_walk(name, kernel, seed, dtype, pixels):
    """The backward kernel (Triton: a program per tile; Mosaic GPU: a warpgroup per tile or
    half tile, `pixels` per block, forward and backward) against its plain-jnp counterpart
    (`tiles.gradients`: the same walk in XLA) on the same residuals (this kernel's forward:
    final T, stop pairs, masks, records) and random cotangents, both blending modes (`fast` has
    no reference image to compare with: this is where its backward is checked)."""
    config = dataclasses.replace(BACKWARD[name], kernel=kernel,
                                 tuning=K(forward_pixels=pixels, backward_pixels=pixels))
    got, want = scenes.backward_kernel_and_walk(seed, config, dtype)
    assert np.all(np.isfinite(got))
    # float32 on the GPU: the two compilers' rounding (FMA contraction, exp) meets the walk's
    # division by 1 − α (α up to 0.99): up to 2e-4 of max |∂| (the float32 walk itself is
    # about as far from the float64 walk).
    f32_tol = 1e-4 if jax.default_backend() == "cpu" else 1e-3
    tol = GRAD_F64_REL if dtype == np.float64 else f32_tol
    assert_close_to_scale(got, want, tol)
    # Same Gaussians get gradient (float64: no rounding to zero by chance).
    if dtype == np.float64:
        np.testing.assert_array_equal(np.any(got != 0, 1), np.any(want != 0, 1))


F32, F64 = np.float32, np.float64


M = C(kernel="mosaic")


LOWER = {  # id -> (backend, config, pixels per block, dtype); kernel "auto" lowers Mosaic GPU
    "localgs-compacted-f64": ("pallas", M, 256, F64),
    "localgs-fast": ("pallas", C(kernel="mosaic", blend="fast"), 256, F32),
    "vanilla-half": ("pallas_vanilla", M, 128, F32),
    "localgs-triton": ("pallas", C(kernel="triton"), 128, F32),
}
# The switches that only change constants (origin, convention) add no primitive: left out.
LOWER_SLOW = {
    "localgs": ("pallas", C(), 256, F32),
    **{f"localgs-{name}": ("pallas", LOCALGS[name], 256, F32)
       for name in ("no_cull", "difference", "baseline", "global")},
    "localgs-fast-half": ("pallas", C(blend="fast"), 128, F32),
    "vanilla": ("pallas_vanilla", C(), 256, F32),
    "vanilla-triton": ("pallas_vanilla", C(kernel="triton"), 256, F32),
}


@pytest.mark.parametrize("backend,config,pixels,dtype",
                         [pytest.param(*v, id=k) for k, v in LOWER.items()]
                         + [pytest.param(*v, id=k, marks=SLOW) for k, v in LOWER_SLOW.items()])
def test_kernels_lower_for_the_gpu(backend, config, pixels, dtype, monkeypatch):
    """Every kernel variant, forward and backward, lowers through the Pallas Triton lowering
    (to Triton IR, for an H100) or the Mosaic GPU lowering (records built in the kernels, the
    compacted forward's per-warp lists, blocks of `pixels`), so CI catches what the GPU would
    reject at lowering time (e.g. Mosaic GPU's missing bool-vector negation)."""
    from jax._src.pallas.triton import gpu_info

    monkeypatch.setattr(gpu_info, "get_gpu_info",
                        lambda: gpu_info.get_gpu_info_from_version(gpu_info.GpuVersion.H100))
    config = dataclasses.replace(config, tuning=K(interpret=False, forward_pixels=pixels,
                                                  backward_pixels=pixels))
    g = scenes.cast(scenes.scene(0), dtype)
    image = lambda g, c: lgs_jax.render(g, c, backend=backend, config=config,
                                        capacity=scenes.CAPACITY).image
    # The rendering forward, and the differentiated one with the backward kernel.
    grad = jax.value_and_grad(lambda g, c: jax.numpy.sum(image(g, c) ** 2))
    lower = lambda f: jax.jit(f).trace(g, scenes.camera(dtype=dtype)).lower(
        lowering_platforms=("cuda",)).as_text()
    forward, both = lower(image), lower(grad)
    marker = {"mosaic": "mosaic_gpu", "triton": "__gpu$xla.gpu.triton"}
    impl = "mosaic" if config.kernel == "auto" else config.kernel
    assert marker[impl] in forward
    # Under grad: the backward kernel and a forward of the same implementation, and the
    # per-Gaussian chain and sum (gaussian_grads, a Triton kernel for both; the Local-GS
    # Mosaic GPU kernels' table, a Triton kernel too).
    assert both.count(marker[impl]) >= (2 if impl == "mosaic" else 3)
    assert "gaussian_grads" in both
    if impl == "mosaic":  # gaussian_grads and the Gaussian table
        assert both.count(marker["triton"]) == 2
    else:
        assert marker["mosaic"] not in both
