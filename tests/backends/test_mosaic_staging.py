"""lgs_jax.backends.mosaic_staging: the Local-GS Mosaic GPU forward building its pair records in
the kernel from per-Gaussian rows (`KernelConfig.mosaic_pair_source="gaussians"`) against the
records XLA builds ("records"). In interpret mode the images are bit for bit the same (the
same functions compute the records); on the GPU the kernel's arithmetic is Mosaic GPU's, so
within the float32 tolerance of the other kernel comparisons. The scenes put 640 Gaussians of
the adversarial kinds on one 16x16 tile, whose list (about 290 pairs) crosses the 128-pair
chunks (asserted), with faint and huge Gaussians so that pixels do not stop before the later
chunks."""

import dataclasses

import jax
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import lgs_jax
from lgs_jax import binning, pairs
from lgs_jax.backends import mosaic_staging, pallas, pallas_mosaic
from lgs_jax.projection import project
from tests import scenes
from tests.compare import (F32_ATOL, F32_FLIP_SHARE, F64_ATOL, assert_composites_equal,
                           assert_render_close)
from tests.devices import ON_GPU, gpu_only

C = lgs_jax.RasterConfig
K = lgs_jax.KernelConfig
DENSE = ("huge_far", "faint", "needle", "normal", "tiny", "invalid", "behind")
N_DENSE = 640
TILE_CAMERA = dict(width=16, height=16)  # one tile: every pair in one list
CAPACITY = 4096
CONFIGS = {"local_gs": C(), "difference": C(hoist=False), "no_cull": C(warp_cull=False),
           "center": C(origin="center"), "global": C(local_coords=False), "gsplat": C("gsplat")}


def _render(g, cam, config, source, pixels):
    config = dataclasses.replace(config, kernel="mosaic", tuning=K(
        mosaic_pair_source=source, mosaic_forward_pixels=pixels))
    return lgs_jax.render(g, cam, background=np.asarray(scenes.BACKGROUND, g.means.dtype),
                          backend="pallas", config=config, capacity=CAPACITY)


GPU_ONLY = gpu_only(
    "CI time: in interpret mode the Mosaic GPU tests of test_pallas.py cover this case on lists "
    "within one chunk")


@pytest.mark.parametrize("name,dtype,pixels", [("local_gs", np.float32, 256)] + [
    pytest.param(*case, marks=GPU_ONLY) for case in (
        ("difference", np.float32, 128), ("global", np.float64, 256),
        ("no_cull", np.float32, 256), ("center", np.float64, 128), ("gsplat", np.float32, 256))])
@settings(max_examples=1)  # interpret mode: one block at a time, about 20 s per render
@given(seed=st.integers(0, 2**32 - 1))
def test_records_built_in_the_kernel_equal_the_xla_records(name, dtype, pixels, seed):
    g = scenes.cast(scenes.scene(seed, kinds=DENSE, n=N_DENSE), dtype)
    cam = scenes.camera(dtype=dtype, **TILE_CAMERA)
    bins = binning.bin_gaussians(project(g, cam), cam.width, cam.height, CAPACITY)
    assert not bins.overflow
    assert int(np.max(bins.tile_end - bins.tile_start)) > mosaic_staging.LANES
    want = _render(g, cam, CONFIGS[name], "records", pixels)
    got = _render(g, cam, CONFIGS[name], "gaussians", pixels)
    assert got.stats.kernel == "localgs-mosaic"
    assert int(got.stats.strip_pairs) == -1  # not counted
    for field in ("image", "alpha", "depth"):
        a, b = getattr(got, field), getattr(want, field)
        if not ON_GPU:
            np.testing.assert_array_equal(a, b, err_msg=field)
        elif dtype == np.float64:
            np.testing.assert_allclose(a, b, rtol=0, atol=F64_ATOL, err_msg=field)
        else:  # the records' arithmetic compiled by Mosaic GPU, not XLA: ulps apart
            assert_render_close(a, b, atol=F32_ATOL, max_flip_share=F32_FLIP_SHARE,
                                flip_atol=2.0, what=field)


@pytest.mark.parametrize("name,pixels", [
    pytest.param("difference", 256, marks=pytest.mark.slow),
    pytest.param("local_gs", 128, marks=GPU_ONLY)])
@settings(max_examples=1)
@given(seed=st.integers(0, 2**32 - 1))
def test_gradients_with_records_built_in_the_kernels_equal_the_xla_records(name, pixels, seed):
    """Forward and backward kernels both building their records from Gaussians give the
    gradients of XLA's records: bit for bit in interpret mode (on the GPU within the float32
    gradient tolerance: the Mosaic GPU arithmetic of the records). The dense scene's walks
    enter chunks part-way and cross chunk boundaries downward. (On lists within one chunk,
    test_backward_kernel_equals_the_tiles_walk covers the default Mosaic GPU backward.)"""
    dtype = np.float32
    g = scenes.cast(scenes.scene(seed, kinds=DENSE, n=N_DENSE), dtype)
    cam = scenes.camera(dtype=dtype, **TILE_CAMERA)
    w = np.random.default_rng(seed % 2**16).normal(size=(cam.height, cam.width, 3))
    grads = {}
    for source in ("records", "gaussians"):
        config = dataclasses.replace(CONFIGS[name], kernel="mosaic", tuning=K(
            mosaic_pair_source=source, mosaic_forward_pixels=pixels,
            mosaic_backward_pixels=pixels))
        loss = lambda g, config=config: jax.numpy.sum(lgs_jax.render(
            g, cam, background=np.asarray(scenes.BACKGROUND, dtype), backend="pallas",
            config=config, capacity=CAPACITY).image * w.astype(dtype))
        grads[source] = jax.tree.leaves(jax.grad(loss)(g))
    for got, want in zip(grads["gaussians"], grads["records"]):
        if ON_GPU:
            np.testing.assert_allclose(got, want, rtol=2e-3, atol=2e-3 * np.abs(want).max())
        else:
            np.testing.assert_array_equal(got, want)


def test_plans_under_differentiation():
    """A Mosaic GPU backward builds its records from Gaussians too, so the forward under
    differentiation keeps the setting; a Triton backward reads XLA's records, and so does the
    forward before it (`Plan.for_gradients`)."""
    mosaic = C(kernel="mosaic", tuning=K(mosaic_pair_source="gaussians"))
    assert pallas.plan(mosaic, False, 6).for_gradients().config == mosaic
    mixed = C(tuning=K(interpret=False, auto_backward="triton", mosaic_pair_source="gaussians"))
    plan = pallas.plan(mixed, False, 6)
    assert (plan.forward, plan.backward) == ("mosaic", "triton")
    assert plan.for_gradients().forward == "triton"
    assert plan.for_gradients().config.tuning.mosaic_pair_source == "records"


@pytest.mark.parametrize("dtype,compact,warps", [
    (np.float32, False, False), (np.float32, True, False), (np.float32, True, True),
    pytest.param(np.float64, False, False, marks=pytest.mark.slow),
    pytest.param(np.float64, True, True, marks=pytest.mark.slow)])
def test_in_kernel_staging_lowers_for_the_gpu(dtype, compact, warps, monkeypatch):
    """The staging kernels, forward and backward, lower through Mosaic GPU (inline gather,
    lane-vector strip masks without floor or ceil, shared-memory stores, the barrier), float32
    and float64; the compacted forward (`mosaic_compact`: ballot, population counts, the
    per-lane partition) and, with it, the lean outputs (`mosaic_image_layout`: strided stores
    of (8, 16) boxes; `mosaic_block_stops`: a block's maximum, one scalar store). Not what
    the GPU compiler's LLVM translation may still reject: the tests above run the kernels on a
    GPU. With `warps`, the per-warp lists (`mosaic_warp_lists`: four ballots per warp, per-lane
    shared-memory reads)."""
    from jax._src.pallas.triton import gpu_info  # gaussian_grads is a Triton kernel

    monkeypatch.setattr(gpu_info, "get_gpu_info",
                        lambda: gpu_info.get_gpu_info_from_version(gpu_info.GpuVersion.H100))
    config = C(kernel="mosaic", tuning=K(interpret=False, mosaic_pair_source="gaussians",
                                         mosaic_compact=compact, mosaic_image_layout=compact,
                                         mosaic_block_stops=compact, mosaic_warp_lists=warps))
    g = scenes.cast(scenes.scene(0), dtype)
    image = lambda g, c: lgs_jax.render(g, c, backend="pallas", config=config,
                                        capacity=scenes.CAPACITY).image
    grad = jax.value_and_grad(lambda g, c: jax.numpy.sum(image(g, c) ** 2))
    lower = lambda f: jax.jit(f).trace(g, scenes.camera(dtype=dtype)).lower(
        lowering_platforms=("cuda",)).as_text()
    assert "mosaic_gpu" in lower(image)
    assert lower(grad).count("mosaic_gpu") >= 2  # the staging forward and backward kernels


@pytest.mark.parametrize("tuning,match", [
    (dict(mosaic_pair_source="pairs"), "tuning.mosaic_pair_source"),
    (dict(mosaic_pair_source="gaussians", mosaic_unroll_localgs=6, mosaic_chunk=60),
     "tuning.mosaic_unroll_localgs")])
def test_bad_pair_source_settings_raise(tuning, match):
    with pytest.raises(ValueError, match=match):
        K(**tuning)


WALKS = (False, True, "warps")  # the full walk, compacted per block, per-warp lists


def _compact_config(compact, segment=None, backward_pixels=128):
    """The Mosaic GPU kernels in half-tile forward blocks, walking every pair (compact False),
    compacted per block (True) or per warp ("warps": `KernelConfig.mosaic_warp_lists`)."""
    return C(kernel="mosaic", tuning=K(mosaic_compact=bool(compact), mosaic_forward_pixels=128,
                                        mosaic_backward_pixels=backward_pixels,
                                        mosaic_backward_segment=segment,
                                        mosaic_warp_lists=compact == "warps"))


def _dense_tile(seed):
    g = scenes.scene(seed, kinds=DENSE, n=N_DENSE)
    cam = scenes.camera(**TILE_CAMERA)
    p = project(g, cam)
    bins = binning.bin_gaussians(p, cam.width, cam.height, CAPACITY)
    n = int(bins.tile_end[0])
    assert n > 2 * mosaic_staging.LANES
    masks = np.asarray(pairs.strip_masks(pairs.gather(p, bins.gauss), bins, 1, C()))[:n]
    for half in (0x0F, 0xF0):  # each half-tile block has pairs to drop and pairs to keep
        assert 0 < np.count_nonzero(masks & half) < n
    return g, cam


def _assert_same(got, want, err_msg=""):
    """Bit for bit, except float64 on the GPU: there the two kernels are compiled separately
    and their float64 arithmetic differed by ulps (up to 8e-15 on the dense tile, H200: the
    compiler's multiply-add contractions; float32 was bit for bit; BENCHMARKS.md §7)."""
    if ON_GPU and np.asarray(want).dtype == np.float64:
        np.testing.assert_allclose(got, want, rtol=0, atol=F64_ATOL, err_msg=err_msg)
    else:
        np.testing.assert_array_equal(got, want, err_msg=err_msg)


@settings(max_examples=1)  # interpret mode: about 20 s per render
@given(seed=st.integers(0, 2**32 - 1), dtype=st.sampled_from([np.float32, np.float64]))
def test_compacted_forward_is_the_forward_to_the_bit(seed, dtype):
    """`KernelConfig.mosaic_compact`: each half-tile block walks only the pairs whose strip mask
    reaches its strips (of a list crossing three 128-pair chunks), and with `mosaic_warp_lists`
    each warp only those of its strip: the same images (exact blending: a dropped pair blends
    nothing in the block or warp; each list keeps pair order), bit for bit (`_assert_same`)."""
    g, cam = _dense_tile(seed)
    g, cam = scenes.cast(g, dtype), scenes.camera(dtype=dtype, **TILE_CAMERA)
    out = {c: lgs_jax.render(g, cam, backend="pallas", config=_compact_config(c),
                             capacity=CAPACITY) for c in WALKS}
    for compact in WALKS[1:]:
        assert out[compact].stats.kernel == "localgs-mosaic"
        for field in ("image", "alpha", "depth"):
            _assert_same(getattr(out[compact], field), getattr(out[False], field),
                         err_msg=f"{compact} {field}")


@settings(max_examples=3)
@given(seed=st.integers(0, 2**32 - 1), dtype=st.sampled_from([np.float32, np.float64]))
def test_compacted_forward_on_partial_tiles_and_short_lists(seed, dtype):
    """The compaction on the suite's small scenes (every kind, 3x2 tiles, partial edge tiles,
    lists within one chunk, half-tile blocks with nothing to keep): the full walk's images and
    pair counts, per block and per warp."""
    g, cam = scenes.cast(scenes.scene(seed), dtype), scenes.camera(dtype=dtype)
    out = {c: lgs_jax.render(g, cam, backend="pallas", config=_compact_config(c),
                             capacity=scenes.CAPACITY) for c in WALKS}
    for compact in WALKS[1:]:
        for field in ("image", "alpha", "depth"):
            _assert_same(getattr(out[compact], field), getattr(out[False], field),
                         err_msg=f"{compact} {field}")
        assert int(out[compact].stats.pairs_walked) == int(out[False].stats.pairs_walked)


@pytest.mark.slow
@pytest.mark.parametrize("backward_pixels", [128, 256])
@settings(max_examples=1)
@given(seed=st.integers(0, 2**32 - 1))
def test_compacted_forward_gives_the_same_gradients_and_split_entries(backward_pixels, seed):
    """The compacted forward's stop pairs and the split backward's entries (stored at chunk
    starts, segments of 128) are those of the full walk: the same gradients to the bit
    (float32; H200: bit for bit), with half-tile backward blocks and with whole-tile ones over
    the half-tile forward blocks (the default at 4K: a half whose pixels all stopped before a
    segment wrote no entry there, `backward_segments.enter`)."""
    g, cam = _dense_tile(seed)
    g, cam = scenes.cast(g, np.float32), scenes.camera(dtype=np.float32, **TILE_CAMERA)
    w = np.random.default_rng(seed % 2**16).normal(size=(cam.height, cam.width, 3))
    w = w.astype(np.float32)
    grads = {}
    for compact in WALKS:
        config = _compact_config(compact, segment=128, backward_pixels=backward_pixels)
        loss = lambda g, config=config: jax.numpy.sum(lgs_jax.render(
            g, cam, backend="pallas", config=config, capacity=CAPACITY).image * w)
        grads[compact] = jax.tree.leaves(jax.grad(loss)(g))
    for compact in WALKS[1:]:
        for got, want in zip(grads[compact], grads[False]):
            np.testing.assert_array_equal(got, want, err_msg=str(compact))


def test_compaction_applies_where_its_conditions_hold():
    """`mosaic_compact` (the default) compacts the Local-GS forward where it can: records built
    from Gaussians, exact blending, strip masks, the split backward's entries at chunk starts
    (segments of a multiple of 128 pairs, or whole walks), in either α form; elsewhere the
    forward walks every pair, in the block size it would have without."""
    assert pallas_mosaic.compacts(C())
    assert pallas_mosaic.compacts(C(hoist=False))
    assert pallas_mosaic.compacts(C(tuning=K(mosaic_backward_segment=None)))
    for off in (C(tuning=K(mosaic_compact=False)), C(blend="fast"), C(warp_cull=False),
                C(tuning=K(mosaic_pair_source="records")),
                C(tuning=K(mosaic_backward_segment=64))):
        assert not pallas_mosaic.compacts(off)
        assert pallas.plan(dataclasses.replace(off, kernel="mosaic"), False,
                           10**5).forward_pixels == 256
    with pytest.raises(ValueError, match="tuning.mosaic_compact"):
        K(mosaic_compact=1)
    compact = C(kernel="mosaic")
    assert pallas.plan(compact, False, 10**5).forward_pixels == 128  # whole tiles otherwise
    assert pallas.plan(compact, True, 10**5).forward_pixels == 256  # the vanilla kernel's


def test_warp_lists_apply_in_compacted_half_tile_blocks():
    """`mosaic_warp_lists` walks per-warp lists where the forward compacts in half-tile blocks
    (a warp is one strip); whole-tile blocks and full walks keep their own walks."""
    assert pallas_mosaic.warp_lists(C(), 128)  # the default
    assert not pallas_mosaic.warp_lists(C(), 256)
    assert not pallas_mosaic.warp_lists(C(tuning=K(mosaic_warp_lists=False)), 128)
    assert not pallas_mosaic.warp_lists(C(blend="fast"), 128)
    assert not pallas_mosaic.warp_lists(C(tuning=K(mosaic_compact=False)), 128)
    with pytest.raises(ValueError, match="tuning.mosaic_warp_lists"):
        K(mosaic_warp_lists="yes")


def _lean(on: bool, segment=None):
    """The Local-GS forward with (or without) both of its lean outputs: the colour as an image
    (`KernelConfig.mosaic_image_layout`) and each block's latest stop (`mosaic_block_stops`)."""
    return C(kernel="mosaic", tuning=K(mosaic_image_layout=on, mosaic_block_stops=on,
                                       mosaic_forward_pixels=128, mosaic_backward_segment=segment))


@settings(max_examples=1)  # interpret mode
@given(seed=st.integers(0, 2**32 - 1))
def test_lean_forward_renders_the_planes_images(seed):
    """`KernelConfig.mosaic_image_layout` and `mosaic_block_stops`: the Local-GS forward writing
    its colour as an image and each block's latest stop pair gives the images of the per-tile
    planes, bit for bit (on the GPU: the same stores of the same values; in interpret mode the
    alpha and depth, and the image to `assert_composites_equal`'s ulp),
    and the same walked pairs, on the suite's scenes (partial edge tiles) with their
    background."""
    g, cam = scenes.scene(seed), scenes.camera()
    background = np.asarray(scenes.BACKGROUND, np.float32)
    out = {on: lgs_jax.render(g, cam, background=background, backend="pallas",
                              config=_lean(on), capacity=scenes.CAPACITY) for on in (True, False)}
    for field in ("image", "alpha", "depth"):
        got, want = getattr(out[True], field), getattr(out[False], field)
        if field == "image" and not ON_GPU:
            assert_composites_equal(got, want)
        else:
            _assert_same(got, want, err_msg=field)
    assert int(out[True].stats.pairs_walked) == int(out[False].stats.pairs_walked)
    p = project(g, cam)
    bins = binning.bin_gaussians(p, cam.width, cam.height, scenes.CAPACITY)
    stops = jax.eval_shape(lambda p, bins: pallas.rasterize(
        p, bins, cam.width, cam.height, _lean(True)).stop, p, bins)
    assert stops.shape == (bins.tile_start.shape[0], 2)  # one per block of 128 pixels


@pytest.mark.slow  # interpret mode: about 50 s (CI: test_gradients runs the default, lean)
@settings(max_examples=1)
@given(seed=st.integers(0, 2**32 - 1))
def test_lean_forward_gives_the_planes_gradients(seed):
    """With both lean outputs the gradients of a loss of image, alpha and depth are the
    planes', bit for bit, and so are the walked pairs under differentiation (the forward a
    backward follows keeps its pixels' stops and reduces them), with split backward segments
    (their entries gathered from the image) and the walked rows, on partial tiles (40x24) with
    a background. The image itself: bit for bit on the GPU; in interpret mode to
    `assert_composites_equal`'s ulp (XLA on the CPU blends the background into the lean image
    in another fusion than into the planes': seed 0 differs by one ulp at 2 of 2880 values)."""
    dtype = np.float32
    g, cam = scenes.saturating(seed, 150, dtype), scenes.camera(40, 24, dtype=dtype)
    w = np.random.default_rng(seed % 2**16).normal(size=(24, 40, 3)).astype(dtype)
    render = lambda g, on, rows=None: lgs_jax.render(
        g, cam, background=np.asarray([0.2, 0.5, 0.9], dtype), backend="pallas",
        config=_lean(on, 16), capacity=2048, row_capacity=rows)
    rows = int(render(g, False).stats.pairs_walked)
    assert rows > 2 * 16 * 6  # segments to enter on the 3x2 tiles

    def loss(g, on):
        o = render(g, on, rows)
        return (jax.numpy.sum(o.image * w) + jax.numpy.sum(o.alpha * w[..., 0])
                + jax.numpy.sum(o.depth * w[..., 1])), (o.image, o.alpha, o.depth,
                                                        o.stats.pairs_walked)

    run = jax.jit(jax.grad(loss, has_aux=True), static_argnums=1)
    assert pallas.plan(_lean(True, 16), False, 6).image
    got, want = run(g, True), run(g, False)
    for name, a, b in zip(scenes.FIELDS + ("image", "alpha", "depth", "pairs_walked"),
                          jax.tree.leaves(got), jax.tree.leaves(want)):
        if name == "image" and not ON_GPU:  # as test_lean_forward_renders_the_planes_images
            assert_composites_equal(a, b)
        else:
            _assert_same(a, b, err_msg=name)


def test_lean_forward_applies_where_its_conditions_hold():
    """`mosaic_image_layout` where the render's forward and the one a gradient runs are both the
    Local-GS Mosaic GPU kernel in blocks of 128 pixels (custom_vjp's two must return alike),
    the planes elsewhere; `mosaic_block_stops` where the render's forward is the Local-GS Mosaic
    GPU kernel (the gradient's reduces its pixels' stops)."""
    on = lambda **kw: C(kernel="mosaic", tuning=K(mosaic_image_layout=True,
                                                  mosaic_block_stops=True, **kw))
    both = pallas.plan(on(), False, 10**5)  # compacted: blocks of 128 pixels
    assert both.image and both.block_stops
    vanilla = pallas.plan(on(), True, 10**5)
    assert not vanilla.image and not vanilla.block_stops
    whole = pallas.plan(on(mosaic_compact=False), False, 10**5)  # blocks of 256 pixels
    assert not whole.image and whole.block_stops
    triton = pallas.plan(dataclasses.replace(on(), kernel="triton"), False, 10**5)
    assert not triton.image and not triton.block_stops
    default = pallas.plan(C(kernel="mosaic"), False, 10**5)
    assert default.image and default.block_stops  # on by default
    routed = C(tuning=K(mosaic_image_layout=True, vanilla_from_pairs=1, interpret=False))
    assert not pallas.plan(routed, False, 10**5, capacity=2).image  # vanilla, Local-GS under grad
    for name in ("mosaic_image_layout", "mosaic_block_stops"):
        with pytest.raises(ValueError, match=f"tuning.{name}"):
            K(**{name: 1})


def test_table_render_builds_before_binning_is_the_one_the_backend_builds():
    """`render` hands the `pallas` backend its Gaussian table (`Backend.gaussian_table`, built
    before binning, `TileBins.table`) only where a staged Local-GS forward reads it, with or
    without a backward after it (not with a Triton backward, which reads records); without
    one in the bins the backend builds the same table itself: the same outputs, bit for bit."""
    g = scenes.scene(3, kinds=DENSE, n=48)
    cam = scenes.camera(dtype=np.float32, **TILE_CAMERA)
    p = project(scenes.cast(g, np.float32), cam)
    config = C(kernel="mosaic")
    table = pallas.gaussian_table(p, config, 1, CAPACITY)
    assert table is not None and table.shape == (g.num, pairs.TABLE_COLUMNS)
    triton_backward = C(tuning=K(interpret=False, auto_backward="triton"))  # a Mosaic forward
    assert pallas.plan(triton_backward, False, 1).forward == "mosaic"
    for other in (C(kernel="triton"), C(kernel="mosaic", tuning=K(mosaic_pair_source="records")),
                  triton_backward):
        assert pallas.gaussian_table(p, other, 1, CAPACITY) is None
    outs = [pallas.rasterize(p, binning.bin_gaussians(p, cam.width, cam.height, CAPACITY, None,
                                                      t), cam.width, cam.height, config)
            for t in (None, table)]
    for a, b in zip(*(jax.tree.leaves((o.color, o.trans, o.depth, o.stop)) for o in outs)):
        assert np.array_equal(np.asarray(a), np.asarray(b))
