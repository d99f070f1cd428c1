"""lgs_jax.backends.pallas.mosaic_forward (with .staging and .warp_lists): the Mosaic GPU forward
kernels build their pair records in the kernel from the Gaussian table and, with exact blending
and warp culling, walk per-warp lists (`compact_loop`). Against the Triton kernels (records
built in XLA, every pair walked) the images are bit for bit the same in interpret mode (the same
functions compute the records; the image to `assert_composites_equal`'s ulp, the layouts
differing); on the GPU the two compilers' arithmetic differs by ulps, so there the compacted
walk is compared with the Mosaic GPU kernel's own full walk (a backward segment that is no
multiple of 128 turns compaction off), bit for bit in float32.

The dense scenes put 640 Gaussians of the adversarial kinds on one 16x16 tile, whose list
(about 290 pairs) crosses the 128-pair chunks (asserted), with faint and huge Gaussians so that
pixels do not stop before the later chunks, and half-tile blocks with pairs to drop and to
keep."""

import dataclasses
import functools

import jax
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import lgs_jax
from lgs_jax import pairs
from lgs_jax.backends import pallas
from lgs_jax.backends.pallas import mosaic_forward
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
COMPACT, FULL = K(), K(backward_segment=64)  # a segment no multiple of 128: every pair walked


def _render(g, cam, config, capacity=CAPACITY):
    return lgs_jax.render(g, cam, background=np.asarray(scenes.BACKGROUND, g.means.dtype),
                          backend="pallas", config=config, capacity=capacity)


@functools.partial(jax.jit, static_argnums=2)
def _renders(g, cam, configs):
    """`_render` at each of `configs`, in one program: compiled together, the renders cost
    about a third less than apart."""
    return [_render(g, cam, c) for c in configs]


# The dense tile's renders of the default tests: the Triton kernel, the Mosaic GPU kernel
# (compacted) and its full walk, in one program.
DENSE_RENDERS = (C(kernel="triton"), C(kernel="mosaic"), C(kernel="mosaic", tuning=FULL))


@jax.jit
def _bins_and_masks(g, cam):
    """The bins of `g` at CAPACITY and their pairs' strip masks (default configuration)."""
    p, bins = scenes.projected_bins(g, cam, CAPACITY)
    return bins, pairs.strip_masks(pairs.gather(p, bins.gauss), bins, 1, C())


def _dense_tile(seed, dtype=np.float32):
    g = scenes.cast(scenes.scene(seed, kinds=DENSE, n=N_DENSE), dtype)
    cam = scenes.camera(dtype=dtype, **TILE_CAMERA)
    bins, masks = _bins_and_masks(g, cam)
    n = int(bins.tile_end[0])
    assert not bins.overflow and n > 2 * mosaic_forward.LANES
    masks = np.asarray(masks)[:n]
    for half in (0x0F, 0xF0):  # each half-tile block has pairs to drop and pairs to keep
        assert 0 < np.count_nonzero(masks & half) < n
    return g, cam


def _assert_same(got, want, err_msg=""):
    """Bit for bit, except float64 on the GPU: there two separately compiled kernels' float64
    arithmetic may differ by ulps (the compiler's multiply-add contractions)."""
    if ON_GPU and np.asarray(want).dtype == np.float64:
        np.testing.assert_allclose(got, want, rtol=0, atol=F64_ATOL, err_msg=err_msg)
    else:
        np.testing.assert_array_equal(got, want, err_msg=err_msg)


GPU_ONLY = gpu_only(
    "CI time: in interpret mode test_backend.py's Mosaic GPU tests cover these switches on "
    "lists within one chunk")


@pytest.mark.parametrize("name,dtype", [("local_gs", np.float32)] + [
    pytest.param(*case, marks=GPU_ONLY) for case in (
        ("difference", np.float32), ("global", np.float64), ("no_cull", np.float32),
        ("center", np.float64), ("gsplat", np.float32))])
@settings(max_examples=1)  # interpret mode: one block at a time
@given(seed=st.integers(0, 2**32 - 1))
def test_records_built_in_the_kernel_equal_the_triton_kernels(name, dtype, seed):
    """Lists across several 128-pair chunks: the Mosaic GPU forward (records staged per chunk,
    per-warp lists where it compacts) against the Triton kernel reading XLA's records."""
    g, cam = _dense_tile(seed, dtype)
    config = CONFIGS[name]
    want, got = _renders(g, cam, DENSE_RENDERS if config == C() else tuple(
        dataclasses.replace(config, kernel=k) for k in ("triton", "mosaic")))[:2]
    assert got.stats.backend_stats.kernel == "localgs-mosaic"
    assert int(got.stats.backend_stats.strip_pairs) == -1  # not counted
    for field in ("image", "alpha", "depth"):
        a, b = getattr(got, field), getattr(want, field)
        if not ON_GPU:
            if field == "image" and mosaic_forward.compacts(config):
                assert_composites_equal(a, b)  # the compacted forward writes an image
            else:
                np.testing.assert_array_equal(a, b, err_msg=field)
        elif dtype == np.float64:
            np.testing.assert_allclose(a, b, rtol=0, atol=F64_ATOL, err_msg=field)
        else:  # the records' arithmetic compiled by Mosaic GPU, not XLA: ulps apart
            assert_render_close(a, b, atol=F32_ATOL, max_flip_share=F32_FLIP_SHARE,
                                flip_atol=2.0, what=field)


@pytest.mark.slow
@settings(max_examples=1)
@given(seed=st.integers(0, 2**32 - 1))
def test_gradients_with_records_built_in_the_kernels_equal_the_triton_kernels(seed):
    """Forward and backward kernels building their records from the table give the gradients
    of the Triton kernels reading XLA's records: bit for bit in interpret mode (on the GPU
    within the float32 gradient tolerance). The dense scene's walks enter chunks part-way and
    cross chunk boundaries downward."""
    dtype = np.float32
    g, cam = _dense_tile(seed, dtype)
    w = np.random.default_rng(seed % 2**16).normal(size=(cam.height, cam.width, 3))
    grads = {}
    for kernel in ("triton", "mosaic"):
        config = C(kernel=kernel, tuning=K(backward_pixels=128))
        loss = lambda g, config=config: jax.numpy.sum(_render(g, cam, config).image
                                                      * w.astype(dtype))
        grads[kernel] = jax.tree.leaves(jax.grad(loss)(g))
    for got, want in zip(grads["mosaic"], grads["triton"]):
        if ON_GPU:
            np.testing.assert_allclose(got, want, rtol=2e-3, atol=2e-3 * np.abs(want).max())
        else:
            np.testing.assert_array_equal(got, want)


@settings(max_examples=1)  # interpret mode: about 20 s per render
@given(seed=st.integers(0, 2**32 - 1), dtype=st.sampled_from([np.float32, np.float64]))
def test_compacted_forward_is_the_full_walk_to_the_bit(seed, dtype):
    """Each warp walks only the pairs whose strip mask has its strip's bit (of a list crossing
    three 128-pair chunks): the same images and walked pairs as every pair walked (exact
    blending: a dropped pair blends nothing in the warp; each list keeps pair order), bit for
    bit (`_assert_same`)."""
    g, cam = _dense_tile(seed, dtype)
    out = dict(zip((COMPACT, FULL), _renders(g, cam, DENSE_RENDERS)[1:]))
    assert DENSE_RENDERS[1] == C(kernel="mosaic", tuning=COMPACT)
    assert pallas.plan(C(kernel="mosaic", tuning=FULL), False, 1).forward_pixels == 128
    for field in ("image", "alpha", "depth"):
        _assert_same(getattr(out[COMPACT], field), getattr(out[FULL], field), err_msg=field)
    assert (int(out[COMPACT].stats.backend_stats.pairs_walked)
            == int(out[FULL].stats.backend_stats.pairs_walked))


@pytest.mark.slow  # CI time: test_backend's Mosaic GPU against Triton runs these scenes
@settings(max_examples=3)
@given(seed=st.integers(0, 2**32 - 1), dtype=st.sampled_from([np.float32, np.float64]))
def test_compacted_forward_on_partial_tiles_and_short_lists(seed, dtype):
    """The compaction on the suite's small scenes (every kind, 3x2 tiles, partial edge tiles,
    lists within one chunk, warps with nothing to keep): the full walk's images and walked
    pairs."""
    g, cam = scenes.cast(scenes.scene(seed), dtype), scenes.camera(dtype=dtype)
    out = {t: _render(g, cam, C(kernel="mosaic", tuning=t), scenes.CAPACITY)
           for t in (COMPACT, FULL)}
    for field in ("image", "alpha", "depth"):
        _assert_same(getattr(out[COMPACT], field), getattr(out[FULL], field), err_msg=field)
    assert (int(out[COMPACT].stats.backend_stats.pairs_walked)
            == int(out[FULL].stats.backend_stats.pairs_walked))


@pytest.mark.slow
@pytest.mark.parametrize("backward_pixels", [128, 256])
@settings(max_examples=1)
@given(seed=st.integers(0, 2**32 - 1))
def test_compacted_forward_gives_the_full_walks_gradients_and_split_entries(backward_pixels,
                                                                           seed):
    """The compacted forward's stop pairs and the split backward's entries (stored at chunk
    starts, segments of 128) against the unsplit walk's gradients (segment None): the same to
    5e-5 of their scale, as test_segments' float32 bound (the segments' sums C − C_hi are
    differences where the whole walk carries a running sum), with half-tile backward blocks and
    with whole-tile ones over the half-tile forward blocks (a half whose pixels all stopped
    before a segment wrote no entry there, `segments.enter`)."""
    g, cam = _dense_tile(seed, np.float32)
    w = np.random.default_rng(seed % 2**16).normal(size=(cam.height, cam.width, 3))
    w = w.astype(np.float32)
    grads = {}
    for segment in (128, None):
        config = C(kernel="mosaic", tuning=K(backward_pixels=backward_pixels,
                                             backward_segment=segment))
        loss = lambda g, config=config: jax.numpy.sum(_render(g, cam, config).image * w)
        grads[segment] = jax.tree.leaves(jax.grad(loss)(g))
    for got, want in zip(grads[128], grads[None]):
        assert np.all(np.isfinite(got))
        np.testing.assert_allclose(got, want, rtol=0, atol=5e-5 * np.abs(want).max())


@pytest.mark.slow  # CI time: the default set runs each block size in other tests
@settings(max_examples=1)
@given(seed=st.integers(0, 2**32 - 1))
def test_block_sizes_give_the_same_images(seed):
    """The forwards that run the block size they are given (the vanilla kernel; the Local-GS
    kernel without warp culling): half-tile and whole-tile blocks give the same images, bit for
    bit, and an empty scene renders the background."""
    g = scenes.cast(scenes.scene(seed), np.float32)
    empty = scenes.cast(scenes.scene(seed, kinds=("behind", "invalid")), np.float32)
    cam = scenes.camera()
    for backend, config in (("pallas_vanilla", C(kernel="mosaic")),
                            ("pallas", C(kernel="mosaic", warp_cull=False))):
        outs = {}
        for pixels in (128, 256):
            tuned = dataclasses.replace(config, tuning=K(forward_pixels=pixels))
            outs[pixels] = lgs_jax.render(g, cam, background=np.asarray(scenes.BACKGROUND),
                                          backend=backend, config=tuned,
                                          capacity=scenes.CAPACITY)
            background = lgs_jax.render(empty, cam, background=np.asarray(scenes.BACKGROUND),
                                        backend=backend, config=tuned,
                                        capacity=scenes.CAPACITY).image
            np.testing.assert_array_equal(background, np.broadcast_to(
                np.asarray(scenes.BACKGROUND, background.dtype), background.shape))
        for field in ("image", "alpha", "depth"):
            a, b = getattr(outs[128], field), getattr(outs[256], field)
            if field == "image" and backend == "pallas" and not ON_GPU:
                assert_composites_equal(a, b)  # 128-pixel blocks write an image, 256 planes
            else:
                np.testing.assert_array_equal(a, b, err_msg=f"{backend} {field}")


def test_render_stops_are_per_block():
    """A render no gradient follows keeps each block's latest stop pair: (n_tiles, 2) for the
    compacted forward's half-tile blocks."""
    g, cam = scenes.scene(0), scenes.camera()
    p, bins = jax.eval_shape(scenes.projected_bins, g, cam)  # shapes only: nothing compiled
    stops = jax.eval_shape(lambda p, bins: pallas.rasterize(
        p, bins, cam.width, cam.height, C(kernel="mosaic")).stop, p, bins)
    assert stops.shape == (bins.tile_start.shape[0], 2)


@pytest.mark.parametrize("dtype,config", [
    (np.float32, C(kernel="mosaic")),
    # slow: test_backend.py's test_kernels_lower_for_the_gpu[localgs-fast] lowers the fast
    # blending kernels, forward and backward, in float32
    pytest.param(np.float32, C(kernel="mosaic", blend="fast"), marks=pytest.mark.slow),
    pytest.param(np.float64, C(kernel="mosaic"), marks=pytest.mark.slow)])
def test_in_kernel_staging_lowers_for_the_gpu(dtype, config, monkeypatch):
    """The staging kernels, forward and backward, lower through Mosaic GPU (inline gather,
    lane-vector strip masks, shared-memory stores, the barrier), float32 and float64; the
    compacted forward (ballots, population counts, the per-warp lists) with its lean outputs
    (strided stores of the colour image; a block's maximum stop pair). Not what the GPU
    compiler's LLVM translation may still reject: the tests above run the kernels on a
    GPU."""
    from jax._src.pallas.triton import gpu_info  # gaussian_grads is a Triton kernel

    monkeypatch.setattr(gpu_info, "get_gpu_info",
                        lambda: gpu_info.get_gpu_info_from_version(gpu_info.GpuVersion.H100))
    config = dataclasses.replace(config, tuning=K(interpret=False))
    g = scenes.cast(scenes.scene(0), dtype)
    image = lambda g, c: lgs_jax.render(g, c, backend="pallas", config=config,
                                        capacity=scenes.CAPACITY).image
    grad = jax.value_and_grad(lambda g, c: jax.numpy.sum(image(g, c) ** 2))
    lower = lambda f: jax.jit(f).trace(g, scenes.camera(dtype=dtype)).lower(
        lowering_platforms=("cuda",)).as_text()
    assert "mosaic_gpu" in lower(image)
    assert lower(grad).count("mosaic_gpu") >= 2  # the staging forward and backward kernels


def test_render_builds_the_table_before_binning_as_the_backend_would():
    """`render` has the `pallas` backend prepare its Gaussian table before binning
    (`Backend.prepare`) where the Mosaic GPU kernels read it; given none, the backend builds
    the same table itself: the same outputs, bit for bit."""
    from lgs_jax.backends import BackendInputs
    from lgs_jax.backends.pallas import backend

    g = scenes.scene(3, kinds=DENSE, n=48)
    cam = scenes.camera(dtype=np.float32, **TILE_CAMERA)
    config = C(kernel="mosaic")

    @jax.jit
    def run(g, cam):  # the scene and camera as arguments: one compile
        p, bins = scenes.projected_bins(g, cam, CAPACITY)
        table = backend.prepare(p, config, 1, CAPACITY)
        outs = [pallas.rasterize(p, bins, cam.width, cam.height, config, BackendInputs(t))
                for t in (None, table)]
        return p, table, [(o.color, o.trans, o.depth, o.stop) for o in outs]

    p, table, outs = run(scenes.cast(g, np.float32), cam)
    assert table is not None and table.shape == (g.num, pairs.TABLE_COLUMNS)
    assert backend.prepare(p, C(kernel="triton"), 1, CAPACITY) is None
    for a, b in zip(*(jax.tree.leaves(o) for o in outs)):
        assert np.array_equal(np.asarray(a), np.asarray(b))
