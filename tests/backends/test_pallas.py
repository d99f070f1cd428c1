"""`pallas` / `pallas_vanilla` backends against `reference` and `tiles`.

Without a GPU the kernels run in Pallas interpret mode (what CI exercises); on a GPU the same
tests run the compiled kernels (scripts/mosaic_gpu_check.sh, scripts/grad_gpu_check.sh). The
default set runs one representative per kernel and per switch; the products (every switch x
kernel x dtype, more examples) are marked slow (`python -m pytest -m slow`).
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
from lgs_jax.backends import kernel_steps as ks
from lgs_jax.backends import mosaic_rows, mosaic_tma, pallas
from lgs_jax.projection import project
from tests import scenes
from tests.compare import (ALPHA_CAP, F32_ATOL, F32_FLIP_SHARE, F64_ATOL, GRAD_F64_REL,
                           assert_close_to_scale, assert_composites_equal, assert_float32_close,
                           assert_render_close, assert_within_fast_bound)
from tests.devices import ON_GPU, gpu_only

C = lgs_jax.RasterConfig
K = lgs_jax.KernelConfig
SLOW = pytest.mark.slow
AUTO = "mosaic" if ON_GPU else "triton"  # what kernel="auto" runs here (KernelConfig)
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


@pytest.mark.parametrize("name", [pytest.param(n, marks=SLOW) if n in ("no_cull", "difference",
                                                                        "antialiased")
                                  else n for n in LOCALGS])  # "baseline": both off
@settings(max_examples=10)  # interpret mode on CPU: ~0.7 s per example
@given(seed=st.integers(0, 2**32 - 1))
def test_localgs_kernel_equals_reference_float64(name, seed):
    g = scenes.scene(seed)
    cam = scenes.camera(dtype=np.float64)
    config = LOCALGS[name]
    ref = scenes.render(g, cam, "reference", C(config.convention,
                                                antialiased=config.antialiased))
    out = scenes.render(g, cam, "pallas", config)
    assert out.stats.kernel == f"localgs-{AUTO}"
    assert out.stats.interpreted == (not ON_GPU)
    for field in ("image", "alpha", "depth"):
        assert_render_close(getattr(out, field), getattr(ref, field), atol=F64_ATOL, what=field)


@pytest.mark.parametrize("name", ["local_gs"] + [pytest.param(n, marks=SLOW) for n in (
    "difference", "local_center", "gsplat")])
@settings(max_examples=10)  # interpret mode on CPU: ~0.7 s per example
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
    counted = out.stats.kernel != "localgs-mosaic"
    assert int(out.stats.strip_pairs) == (int(tiles.stats.strip_pairs) if counted else -1)


@pytest.mark.parametrize("convention,dtype", [
    ("3dgs", np.float32), ("gsplat", np.float64),
    pytest.param("3dgs", np.float64, marks=SLOW), pytest.param("gsplat", np.float32, marks=SLOW)])
@settings(max_examples=10)  # interpret mode on CPU: ~0.7 s per example
@given(seed=st.integers(0, 2**32 - 1))
@example(seed=1711)  # H200: alpha 2.3e-5 from the reference's in 5 pixels
def test_vanilla_kernel_equals_reference(convention, dtype, seed):
    """The vanilla kernel is the reference's arithmetic in the reference's order."""
    g = scenes.cast(scenes.scene(seed), dtype)
    cam = scenes.camera(dtype=dtype)
    ref = scenes.render(g, cam, "reference", C(convention))
    out = scenes.render(g, cam, "pallas_vanilla", C(convention))
    assert out.stats.kernel == f"vanilla-{AUTO}"
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
MOSAIC_SLOW = (("no_cull", np.float32), ("difference", np.float32), ("global", np.float32),
               ("gsplat", np.float64), ("vanilla", np.float32))


@pytest.mark.parametrize("name,dtype", [("local_gs", np.float32), ("vanilla", np.float64)] + [
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
    assert outs["mosaic"].stats.kernel == KERNEL[backend] + "-mosaic"
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


@pytest.mark.parametrize("backend,chunk,pixels", [
    ("pallas", 8, 256), pytest.param("pallas", 16, 128, marks=SLOW),
    pytest.param("pallas_vanilla", 8, 256, marks=SLOW),
    pytest.param("pallas_vanilla", 16, 128, marks=SLOW)])
@settings(max_examples=2)
@given(seed=st.integers(0, 2**32 - 1))
def test_mosaic_layouts_equal(backend, chunk, pixels, seed):
    """The Mosaic GPU forward kernels in each layout (`KernelConfig.mosaic_forward_pixels`:
    half-tile or whole-tile warpgroup blocks; Local-GS float32 records staged through shared
    memory, with chunks small enough that every tile list of the test scenes spans several:
    chunk boundaries, partial last chunks, the copy still in flight at an early exit) equal the
    simplest layout (half tiles, records read from global memory) bit for bit (on a CPU the
    image to `assert_composites_equal`'s ulp: whole-tile blocks write planes); an empty scene
    (no pair anywhere) renders the background. float64 records are never staged (no 64-bit
    float TMA)."""
    dtype = np.float32
    xla_records = C(tuning=K(mosaic_pair_source="records"))
    assert not mosaic_tma.staged(xla_records, np.float64)
    assert mosaic_tma.staged(xla_records, np.float32)
    assert not mosaic_tma.staged(C(), np.float32)  # records built in the kernels instead
    g = scenes.cast(scenes.scene(seed), dtype)
    empty = scenes.cast(scenes.scene(seed, kinds=("behind", "invalid")), dtype)
    cam = scenes.camera(dtype=dtype)
    outs = {}
    for layout in ((0, 128), (chunk, pixels)):
        config = C(kernel="mosaic", tuning=K(mosaic_pair_source="records",
                                             mosaic_chunk=layout[0], mosaic_unroll_localgs=8,
                                             mosaic_forward_pixels=layout[1]))
        outs[layout] = scenes.render(g, cam, backend, config)
        background = scenes.render(empty, cam, backend, config).image
        np.testing.assert_array_equal(background, np.broadcast_to(
            np.asarray(scenes.BACKGROUND, background.dtype), background.shape))
    for field in ("image", "alpha", "depth"):
        got, want = getattr(outs[chunk, pixels], field), getattr(outs[0, 128], field)
        if field == "image" and not ON_GPU and backend == "pallas":  # Local-GS: 128-pixel
            assert_composites_equal(got, want)  # blocks write an image, 256-pixel ones planes
        else:
            np.testing.assert_array_equal(got, want, err_msg=field)


@gpu_only("CI time: TMA staging of XLA's records is not the default "
          "(KernelConfig.mosaic_pair_source); interpret mode has no TMA")
@pytest.mark.parametrize("backend,pixels", [("pallas", 128)])
@settings(max_examples=1)
@given(seed=st.integers(0, 2**32 - 1))
def test_mosaic_backward_staging_is_bit_for_bit(backend, pixels, seed):
    """The Mosaic GPU backward kernel with its float32 XLA records staged in shared memory, in
    chunks of 8 so that every tile's walk crosses several (chunks entered part-way, the copy
    of the chunk below started at each boundary), gives the gradients of records read from
    global memory bit for bit."""
    g = scenes.cast(scenes.scene(seed), np.float32)
    cam = scenes.camera()
    w = np.random.default_rng(seed % 2**16).normal(size=(cam.height, cam.width, 3))
    grads = []
    for chunk in (0, 8):
        config = C(kernel="mosaic", tuning=K(mosaic_pair_source="records", mosaic_chunk=chunk,
                                             mosaic_backward_pixels=pixels))
        loss = lambda g, config=config: jax.numpy.sum(
            scenes.render(g, cam, backend, config).image * w.astype(np.float32))
        grads.append(jax.tree.leaves(jax.grad(loss)(g)))
    for staged, unstaged in zip(*grads):
        np.testing.assert_array_equal(staged, unstaged)



def _butterfly_sim(x, halves):
    """The transposing butterfly on a warp's lanes (x: (32, m) values in butterfly order): lane
    l sends the half its partner l ^ d keeps and adds what it receives (`transposed_row`)."""
    lanes = np.arange(32)
    vals = [x[:, r] for r in range(x.shape[1])]
    for d, h in zip((16, 8, 4, 2, 1), halves):
        partner = lanes ^ d
        if h == 0:
            vals = [vals[0] + vals[0][partner]]
            continue
        upper = (lanes & d) != 0
        merged = []
        for k in range(h):
            lo, hi = vals[k], vals[k + h] if k + h < len(vals) else np.zeros(32, x.dtype)
            send, keep = np.where(upper, lo, hi), np.where(upper, hi, lo)
            merged.append(keep + send[partner])
        vals = merged
    assert len(vals) == 1
    return vals[0]


@pytest.mark.parametrize("rows", [1, 2, 3, 5, 8, 11, 16])
def test_transposing_butterfly_leaves_every_row_sum_in_its_lane_pair(rows):
    """`mosaic_rows.butterfly_plan`, simulated as `transposed_row` runs it on a warp
    (`_butterfly_sim`): every row's sum over the 32 lanes ends in the lane pairs the plan names
    (one pair per row from 9 rows on; the kernel itself only runs on a GPU)."""
    halves, slot_rows = mosaic_rows.butterfly_plan(rows)
    x = np.random.default_rng(rows).normal(size=(32, rows))
    final = _butterfly_sim(x, halves)
    assert {r for r in slot_rows if r >= 0} == set(range(rows))
    for s, r in enumerate(slot_rows):
        assert final[2 * s] == final[2 * s + 1]
        if r >= 0:
            np.testing.assert_allclose(final[2 * s], x[:, r].sum(), rtol=1e-12)
    with pytest.raises(ValueError, match="rows"):
        mosaic_rows.butterfly_plan(17)


@pytest.mark.parametrize("depth,hoisted", [(False, True), (True, True), (False, False)])
def test_transposed_rows_slots_hold_each_terms_sum_and_zero_for_none(depth, hoisted):
    """`mosaic_rows.row_slots` for `backward_step`'s terms (hoisted: five `Scaled` of d_raw,
    d_raw and d_ln_o, else seven arrays; the colour's three, the depth's or None): the
    butterfly, simulated on the terms in its order, leaves each row's sum over the lanes in the
    slot named for it and an exact zero in a None row's; `Scaled` terms of one source meet at
    the first step as far as they go (two pairs of five)."""
    rng = np.random.default_rng(7)
    lanes = lambda: rng.normal(size=32).astype(np.float32)
    d_raw = lanes()
    model = ([ks.Scaled(d_raw, lanes()) for _ in range(5)] + [d_raw] if hoisted
             else [lanes() for _ in range(6)])
    terms = model + [lanes() for _ in range(4)] + [lanes() if depth else None]
    order, halves, slots = mosaic_rows.row_slots(terms)
    assert sorted(order) == [c for c, v in enumerate(terms) if v is not None]
    h = (len(order) + 1) // 2
    shared = sum(isinstance(terms[a], ks.Scaled) and isinstance(terms[b], ks.Scaled)
                 and terms[a].source is terms[b].source for a, b in zip(order, order[h:]))
    assert shared == (2 if hoisted else 0)
    final = _butterfly_sim(np.stack([ks.term(terms[c]) for c in order], -1), halves)
    for c, s in enumerate(slots):
        assert final[2 * s] == final[2 * s + 1]
        if terms[c] is None:
            assert final[2 * s] == 0
        else:
            np.testing.assert_allclose(final[2 * s], ks.term(terms[c]).sum(dtype=np.float64),
                                       rtol=1e-5, atol=1e-5)
    with pytest.raises(ValueError, match="every term is None"):
        mosaic_rows.row_slots([None, None])


def test_plan_routes_large_forward_renders_to_the_vanilla_kernel():
    """`KernelConfig.vanilla_from_pairs`: with kernel "auto" a `pallas` plan whose pair buffer
    reaches the threshold runs the vanilla kernel forward, and Local-GS again under
    differentiation; never for an explicit kernel, nor with the threshold None."""
    gpu = C(tuning=K(interpret=False, vanilla_from_pairs=2**24))
    assert not pallas.plan(C(tuning=K(interpret=False)), False, 1, 2**30).vanilla  # the default
    assert not pallas.plan(gpu, False, 1, 2**24 - 1).vanilla
    routed = pallas.plan(gpu, False, 1, 2**24)
    assert routed.vanilla and routed.kernel_name == "vanilla-mosaic"
    assert not routed.for_gradients().vanilla
    assert pallas.plan(gpu, True, 1, 2**24).for_gradients().vanilla  # pallas_vanilla stays
    assert not pallas.plan(C(kernel="mosaic", tuning=K(interpret=False)), False, 1, 2**30).vanilla
    assert not pallas.plan(C(tuning=K(vanilla_from_pairs=None)), False, 1, 2**30).vanilla
    with pytest.raises(ValueError, match="tuning.vanilla_from_pairs"):
        K(vanilla_from_pairs=0)


def test_routed_render_is_vanillas_image_and_localgs_gradients():
    """Routed end to end (threshold 1): the image is `pallas_vanilla`'s bit for bit and names
    its kernel; the gradients are the unrouted `pallas` gradients bit for bit."""
    g = scenes.cast(scenes.scene(7), np.float32)
    cam = scenes.camera()
    routed = C(tuning=K(vanilla_from_pairs=1))
    out = scenes.render(g, cam, "pallas", routed)
    ref = scenes.render(g, cam, "pallas_vanilla", routed)
    assert out.stats.kernel == f"vanilla-{AUTO}"
    np.testing.assert_array_equal(out.image, ref.image)
    w = jax.random.uniform(jax.random.key(2), out.image.shape)
    grad = lambda cf: jax.grad(lambda g: (scenes.render(g, cam, "pallas", cf).image
                                          * w).sum())(g)
    for a, b in zip(jax.tree.leaves(grad(routed)), jax.tree.leaves(grad(C()))):
        np.testing.assert_array_equal(a, b)


def test_plan_resolves_implementation_and_block_size():
    """kernel="auto" runs Mosaic GPU for every kernel on the GPU (`KernelConfig.auto_*`) and
    Triton in interpret mode; an explicit kernel runs everywhere; under differentiation "auto"
    runs the backward's implementation forward. Mosaic forward blocks are whole tiles from
    `mosaic_whole_tile_from` tiles on, half tiles below, unless fixed; backward blocks whole
    tiles unless set to None (then by the same rule)."""
    gpu = C(tuning=K(interpret=False))
    assert [pallas.plan(gpu, v, 1).forward for v in (False, True)] == ["mosaic", "mosaic"]
    mixed = C(tuning=K(interpret=False, auto_localgs="triton"))
    assert (pallas.plan(mixed, False, 1).forward, pallas.plan(mixed, False, 1).backward) == (
        "triton", "mosaic")
    assert pallas.plan(mixed, False, 1).for_gradients().forward == "mosaic"
    explicit = C(kernel="triton", tuning=K(interpret=False, auto_localgs="mosaic"))
    assert pallas.plan(explicit, False, 1).for_gradients().forward == "triton"
    interp = C(tuning=K(interpret=True))
    assert (pallas.plan(interp, False, 1).forward, pallas.plan(interp, True, 1).backward) == (
        "triton", "triton")
    assert pallas.plan(interp, True, 1).kernel_name == "vanilla-triton"
    # BENCHMARKS.md §6: whole tiles from 8192 tiles on (3840x2160: 32,400 tiles), half below;
    # the compacted Local-GS forward (the default) in half tiles (§7).
    full = C(tuning=K(interpret=False, mosaic_compact=False))
    for config, vanilla in ((full, False), (gpu, True)):
        assert [pallas.plan(config, vanilla, t).forward_pixels
                for t in (1, 8191, 8192, 32400)] == [128, 128, 256, 256]
    assert [pallas.plan(gpu, False, t).forward_pixels for t in (1, 32400)] == [128, 128]
    # the backward in whole tiles at every size by default (its rows: one per pair and block)
    assert [pallas.plan(gpu, False, t).backward_pixels for t in (1, 8160, 32400)] == [256] * 3
    by_tiles = C(tuning=K(mosaic_backward_pixels=None))
    assert [pallas.plan(by_tiles, False, t).backward_pixels for t in (8191, 8192)] == [128, 256]
    with pytest.raises(ValueError, match="tuning.mosaic_chunk"):
        K(mosaic_chunk=12)
    with pytest.raises(ValueError, match="tuning.mosaic_forward_pixels"):
        K(mosaic_forward_pixels=64)


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
    # compile time and round differently).
    one = jax.jit(lambda g, c: lgs_jax.render(g, c, backend="pallas", capacity=scenes.CAPACITY))
    out = jax.jit(jax.vmap(one, in_axes=(None, 0)))(g, cams)
    # XLA vectorises the batched projection differently (CPU and GPU): 1 ulp on a few pixels,
    # as for the tiles backend (BENCHMARKS.md §3).
    for i, yaw in enumerate((0.0, 0.2)):
        np.testing.assert_allclose(out.image[i], one(g, scenes.camera(yaw=yaw)).image, rtol=0,
                                   atol=1e-6)
    small = jax.jit(lambda c: lgs_jax.render(g, c, backend="pallas", capacity=8).stats)(
        scenes.camera())
    assert bool(small.overflow) and int(small.pairs_required) > 8
    with pytest.raises(lgs_jax.CapacityError):
        lgs_jax.render(g, scenes.camera(), backend="pallas", capacity=8)


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
    blending modes, and the Mosaic GPU kernel (half-tile blocks); slow: every other switch,
    whole-tile Mosaic GPU blocks (both blending modes in float64, both α forms in float32; the
    conventions only change constants the Triton cases cover), and float32 for both α forms
    of both kernels (the other switches run the same float32 code paths)."""
    default = ("local_gs", "difference", "gsplat", "fast")
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
    (`tiles._gradients`: the same walk in XLA) on the same residuals (this kernel's forward:
    final T, stop pairs, masks, records) and random cotangents, both blending modes (`fast` has
    no reference image to compare with: this is where its backward is checked)."""
    config = dataclasses.replace(BACKWARD[name], kernel=kernel,
                                 tuning=K(mosaic_forward_pixels=pixels,
                                          mosaic_backward_pixels=pixels))
    got, want = scenes.backward_kernel_and_walk(seed, config, dtype)
    assert np.all(np.isfinite(got))
    # float32 on the GPU: the two compilers' rounding (FMA contraction, exp) meets the walk's
    # division by 1 − α (α up to 0.99): seed 5038 ("fast", Mosaic) differs by 1.9e-4 of max |∂|,
    # where the float32 walk itself is 1.5e-4 off the float64 walk (BENCHMARKS.md §6).
    f32_tol = 1e-4 if jax.default_backend() == "cpu" else 1e-3
    tol = GRAD_F64_REL if dtype == np.float64 else f32_tol
    assert_close_to_scale(got, want, tol)
    # Same Gaussians get gradient (float64: no rounding to zero by chance).
    if dtype == np.float64:
        np.testing.assert_array_equal(np.any(got != 0, 1), np.any(want != 0, 1))


F32, F64 = np.float32, np.float64


M = C(kernel="mosaic")


LOWER = {  # id -> (backend, config, mosaic_chunk, pixels per block, dtype); "auto" is Mosaic GPU
    "localgs-fast-staged": ("pallas", C(kernel="mosaic", blend="fast"), 64, 256, F32),
    "localgs-staged-f64": ("pallas", M, 64, 256, F64),
    "vanilla-half": ("pallas_vanilla", M, 0, 128, F32),
}
# Kernel "auto" lowers Mosaic GPU here (interpret=False), the same programs as kernel="mosaic";
# the switches that only change constants (origin, convention) add no primitive and are left out.
LOWER_SLOW = {
    "localgs": ("pallas", C(), 0, 256, F32),
    "localgs-staged-half": ("pallas", M, 64, 128, F32),
    **{f"localgs-{name}": ("pallas", LOCALGS[name], 0, 256, F32)
       for name in ("no_cull", "difference", "baseline", "global")},
    "localgs-fast": ("pallas", C(blend="fast"), 0, 256, F32),
    "vanilla": ("pallas_vanilla", C(), 0, 256, F32),
    "localgs-staged": ("pallas", M, 64, 256, F32),
    "localgs-half": ("pallas", M, 0, 128, F32),
}


@pytest.mark.parametrize("backend,config,chunk,pixels,dtype",
                         [pytest.param(*v, id=k) for k, v in LOWER.items()]
                         + [pytest.param(*v, id=k, marks=SLOW) for k, v in LOWER_SLOW.items()])
def test_kernels_lower_for_the_gpu(backend, config, chunk, pixels, dtype, monkeypatch):
    """Every kernel variant, forward and backward, lowers through the Pallas Triton lowering
    (to Triton IR, for an H100) or the Mosaic GPU lowering (records built in XLA, read from
    global memory or staged in shared memory by TMA: `chunk`; blocks of `pixels`; records
    built in the kernels: tests/backends/test_mosaic_staging.py), so CI catches what the GPU
    would reject at lowering time (e.g. Mosaic GPU's missing bool-vector negation, or a float64
    TMA copy)."""
    from jax._src.pallas.triton import gpu_info

    monkeypatch.setattr(gpu_info, "get_gpu_info",
                        lambda: gpu_info.get_gpu_info_from_version(gpu_info.GpuVersion.H100))
    config = dataclasses.replace(config, tuning=K(
        interpret=False, mosaic_pair_source="records", mosaic_chunk=chunk,
        mosaic_forward_pixels=pixels,
        mosaic_backward_pixels=pixels))
    g = scenes.cast(scenes.scene(0), dtype)
    image = lambda g, c: lgs_jax.render(g, c, backend=backend, config=config,
                                        capacity=scenes.CAPACITY).image
    # The rendering forward, and the differentiated one with the backward kernel.
    grad = jax.value_and_grad(lambda g, c: jax.numpy.sum(image(g, c) ** 2))
    lower = lambda f: jax.jit(f).trace(g, scenes.camera(dtype=dtype)).lower(
        lowering_platforms=("cuda",)).as_text()
    forward, both = lower(image), lower(grad)
    marker = {"mosaic": "mosaic_gpu", "triton": "__gpu$xla.gpu.triton"}
    impl = "mosaic" if config.kernel == "auto" else config.kernel  # KernelConfig's auto_*
    assert marker[impl] in forward
    # Under grad: the backward kernel and a forward of the same implementation, and the
    # per-Gaussian chain and sum (gaussian_grads, a Triton kernel for both).
    assert both.count(marker[impl]) >= (2 if impl == "mosaic" else 3)
    assert "gaussian_grads" in both
    if impl == "mosaic":
        assert both.count(marker["triton"]) == 1
    else:
        assert marker["mosaic"] not in both
