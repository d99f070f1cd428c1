"""lgs_jax.backends.pallas.segments: the Mosaic GPU backward with each tile's walk split into
segments (`KernelConfig.backward_segment`), entering from the forward's checkpoints. The
segment table against numpy; gradients against the whole walk's (float64 to 1e-12 of their
scale: the sums behind a segment are C − C_hi instead of a running sum, so the float32 bits
differ); the split kernels lower for the GPU."""


import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import lgs_jax
from lgs_jax import binning
from lgs_jax.backends import REGISTRY
from lgs_jax.backends.pallas import mosaic_forward, order as block_order, segments
from lgs_jax.projection import project
from tests import scenes
from tests.devices import gpu_only

C, K = lgs_jax.RasterConfig, lgs_jax.KernelConfig
W = H = 32


def _random_walks(g, seed: int, share: float):
    """(bins of g on a W x H image, tile starts, random walk ends `last` in [start, start +
    share·length], the rng that drew them)."""
    _, bins = scenes.projected_bins(g, scenes.camera(W, H), 1024)
    rng = np.random.default_rng(seed)
    start, end = np.asarray(bins.tile_start), np.asarray(bins.tile_end)
    last = start + np.floor((end - start) * share * rng.uniform(size=start.shape)).astype(np.int32)
    return bins, start, last, rng


@settings(max_examples=10)
@given(seed=st.integers(0, 2**32 - 1), share=st.floats(0, 1), segment=st.sampled_from([8, 16, 64]))
def test_split_covers_each_tiles_rows_once_in_segments_of_its_walk(seed, share, segment):
    """Random walks: each tile's real segments tile its walked pairs [start, last) in order,
    every one but the last exactly `segment` pairs with checkpoint base + m (the forward's row
    for pair lo + segment), the last one the rest, no checkpoint; the table's other rows are
    empty; segments come longest first (by `order.bucket`)."""
    g = scenes.cast(scenes.scene(seed), np.float64)
    bins, start, last, rng = _random_walks(g, seed, share)
    table = np.asarray(jax.jit(segments.split, static_argnums=(2,))(
        bins, jnp.asarray(last), segment))
    base, n_rows = jax.jit(segments.checkpoints, static_argnums=1)(bins, segment)
    base = np.asarray(base)
    assert table.shape == (start.size + 1024 // segment, segments.COLUMNS)
    real = np.zeros(len(table), bool)
    for t in range(start.size):
        mine = np.flatnonzero((table[:, 0] == t) & (table[:, 2] > table[:, 1]))
        if last[t] == start[t]:
            continue
        segs = table[mine][np.argsort(table[mine, 1])]
        real[mine] = True
        np.testing.assert_array_equal(segs[:, 1], start[t] + segment * np.arange(len(segs)))
        assert segs[-1, 2] == last[t] and segs[-1, 3] == -1
        assert len(segs) == -(-(last[t] - start[t]) // segment)
        np.testing.assert_array_equal(segs[:-1, 2], segs[:-1, 1] + segment)
        np.testing.assert_array_equal(segs[:-1, 3], base[t] + np.arange(len(segs) - 1))
        assert np.all(segs[:-1, 3] < n_rows)
    assert np.all(table[~real, 1] == table[~real, 2])  # the rest: empty
    length = table[:, 2] - table[:, 1]
    key = np.asarray(block_order.bucket(jnp.asarray(length)))
    assert np.all(np.diff(key) <= 0)


@settings(max_examples=10)
@given(seed=st.integers(0, 2**32 - 1), share=st.floats(0.3, 1), segment=st.sampled_from([4, 8]))
def test_entries_hold_each_segments_carry_where_split_reads_it(seed, share, segment):
    """Random walks, rows for exactly the walked pairs: at the index `split` gives each segment
    that enters from a checkpoint, `entries` holds (C − C_hi for r, g, b; T_hi; D − D_hi) of its
    tile's final planes and the forward's checkpoint row that the full `split` gives it: in the
    forward's rows, and with walked rows compacted into row_capacity // segment + 1 rows
    (tiles of tens of pairs: some segments enter from checkpoints, asserted)."""
    g = scenes.saturating(seed, 200, np.float64)
    bins, start, last, rng = _random_walks(g, seed, share)
    rows = max(int(np.sum(last - start)), 1)
    _, n_full = segments.checkpoints(bins, segment)
    n_tiles = bins.tile_start.shape[0]
    final = tuple(rng.normal(size=(n_tiles, 256)) for _ in range(4))
    full = tuple(rng.normal(size=(n_full, 256)) for _ in range(5))

    @jax.jit
    def run(bins, last, final, full):
        final_at = lambda tile: tuple(x[tile] for x in final)
        return (segments.entries(final_at, full, bins, segment),
                segments.entries(final_at, full, bins, segment, last, rows),
                segments.split(bins, last, segment),
                segments.split(bins, last, segment, rows))

    in_place, compacted, table, table_c = run(bins, jnp.asarray(last), final, full)
    assert compacted[0].shape == (rows // segment + 1, 256)
    np.testing.assert_array_equal(np.asarray(table)[:, :3], np.asarray(table_c)[:, :3])
    src, dst = np.asarray(table)[:, 3], np.asarray(table_c)[:, 3]
    np.testing.assert_array_equal(src >= 0, dst >= 0)
    assert np.any(src >= 0)
    tile, src, dst = np.asarray(table)[src >= 0, 0], src[src >= 0], dst[dst >= 0]
    expected = [final[0][tile] - full[0][src], final[1][tile] - full[1][src],
                final[2][tile] - full[2][src], full[3][src], final[3][tile] - full[4][src]]
    for want, a, b in zip(expected, in_place, compacted):
        np.testing.assert_array_equal(np.asarray(a)[src], want)
        np.testing.assert_array_equal(np.asarray(b)[dst], want)


def _grads(g, cam, w, config, row_capacity=None, depth=True, capacity=2048):
    @jax.jit
    def grads(g):
        def loss(g):
            out = lgs_jax.render(g, cam, backend="pallas", config=config, capacity=capacity,
                                 row_capacity=row_capacity)
            total = jnp.sum(out.image * w) + jnp.sum(out.alpha * w[..., 0])
            if depth:  # else no depth cotangent: the kernel takes no D entries
                total = total + 0.1 * jnp.sum(out.depth * w[..., 1])
            return total, out.stats
        return jax.grad(loss, has_aux=True)(g)
    return grads(g)


@pytest.mark.parametrize("dtype,pixels,rows,size,depth", [
    # the default set checks the split's carries (test_entries_hold_each_segments_carry_...)
    pytest.param(np.float64, 128, True, 16, True, marks=pytest.mark.slow),
    pytest.param(np.float64, (128, 256), False, 16, False, marks=pytest.mark.slow),
    pytest.param(np.float64, 256, False, 32, True, marks=pytest.mark.slow),
    pytest.param(np.float32, 128, True, 32, True, marks=[pytest.mark.slow, gpu_only(
        "CI time: the float64 cases check the same kernels in interpret mode")])])
@settings(max_examples=1)  # interpret mode
@given(seed=st.integers(0, 2**32 - 1))
def test_split_backward_gives_the_whole_walks_gradients(dtype, pixels, rows, size, depth, seed):
    """Segments of 16 pairs (tiles walk tens of pairs, asserted): the gradients equal those of
    the whole walk to 1e-12 of their scale in float64 (5e-5 in float32), half and whole
    tiles (and half-tile forward blocks under whole-tile backward blocks, as at 4K, where a
    pixel that stops inside a segment may belong to a forward block that never reached the
    segment's checkpoint: interpret mode fills unwritten memory with NaN), rows in a buffer of
    the pair capacity or of the walked pairs (the checkpoints compacted), on one tile (default
    set) or four; with one row fewer than the walked pairs (an overflow, reported), finite
    gradients; with a loss on the depth or without one (the kernel then takes no D entries)."""
    g, cam = scenes.saturating(seed, 200, dtype), scenes.camera(size, size, dtype=dtype)
    w = np.random.default_rng(seed).normal(size=(size, size, 3)).astype(dtype)
    forward, backward = pixels if isinstance(pixels, tuple) else (pixels, pixels)
    config = lambda segment: C(kernel="mosaic", tuning=K(
        forward_pixels=forward, backward_pixels=backward, backward_segment=segment))
    # 256 pairs per tile: each of the 200 Gaussians pairs with a tile once at most (interpret
    # mode's time grows with the buffers)
    grads = functools.partial(_grads, g, cam, w, depth=depth, capacity=256 * (size // 16) ** 2)
    whole, stats = grads(config(None))
    assert not bool(stats.overflow)
    walked = int(stats.backend_stats.pairs_walked)
    assert walked > 2 * 16 * (size // 16) ** 2  # more than two segments per tile on average
    split, _ = grads(config(16), walked if rows else None)
    if rows:
        short, short_stats = grads(config(16), walked - 1)
        assert bool(short_stats.backend_stats.row_overflow)
        assert all(np.all(np.isfinite(x)) for x in jax.tree.leaves(short))
    tol = 1e-12 if dtype == np.float64 else 5e-5
    for name, a, b in zip(scenes.FIELDS, jax.tree.leaves(whole), jax.tree.leaves(split)):
        a, b = np.asarray(a), np.asarray(b)
        assert np.all(np.isfinite(b)), name
        np.testing.assert_allclose(b, a, rtol=0, atol=tol * (np.max(np.abs(a)) + 1e-300),
                                   err_msg=name)


@pytest.mark.slow  # interpret mode, 700 pairs: about a minute
def test_compacted_forward_under_whole_tile_backward_blocks_gives_the_whole_walks_gradients():
    """Segments of 128 pairs, where the forward walks each chunk's own pairs
    (`mosaic_forward.compacts`), half-tile forward blocks under a whole-tile backward block:
    the top half stops after 281-455 pairs, so its forward block stores no checkpoint past
    them while pixels of it stop inside (384, 512] (asserted). With the walked rows (the
    checkpoints compacted too) the gradients equal the whole walk's to 1e-12 of their scale
    (with a checkpoint read for stop > lo instead of stop > hi they were NaN here)."""
    size, dtype = 16, np.float64
    g, cam = scenes.half_walled(0, 700, dtype), scenes.camera(size, size, dtype=dtype)
    w = np.random.default_rng(0).normal(size=(size, size, 3)).astype(dtype)
    config = lambda segment: C(kernel="mosaic", tuning=K(backward_pixels=256,
                                                         backward_segment=segment))
    assert mosaic_forward.compacts(config(128))
    p = project(g, cam)
    bins = binning.bin_gaussians(p, size, size, 2048)
    # each forward block's latest stop pair (Plan.block_stops): block 0 is the
    # top half, whose latest pixel stops inside (384, 512) iff some stop there and none after
    stop = np.asarray(REGISTRY["pallas"].rasterize(p, bins, size, size, config(None)).stop)
    assert stop.shape == (1, 2) and 384 < stop[0, 0] < 512
    whole, stats = _grads(g, cam, w, config(None))
    split, _ = _grads(g, cam, w, config(128), int(stats.backend_stats.pairs_walked))
    for name, a, b in zip(scenes.FIELDS, jax.tree.leaves(whole), jax.tree.leaves(split)):
        a, b = np.asarray(a), np.asarray(b)
        np.testing.assert_allclose(b, a, rtol=0, atol=1e-12 * np.max(np.abs(a)), err_msg=name)


def test_split_kernels_lower_for_the_gpu(monkeypatch):
    """The forward storing checkpoints and the split backward lower through Mosaic GPU."""
    from jax._src.pallas.triton import gpu_info  # gaussian_grads is a Triton kernel

    monkeypatch.setattr(gpu_info, "get_gpu_info",
                        lambda: gpu_info.get_gpu_info_from_version(gpu_info.GpuVersion.H100))
    config = C(kernel="mosaic", tuning=K(interpret=False, backward_segment=64))
    g = scenes.cast(scenes.scene(0), np.float32)
    image = lambda g, c: lgs_jax.render(g, c, backend="pallas", config=config,
                                        capacity=scenes.CAPACITY).image
    grad = jax.value_and_grad(lambda g, c: jnp.sum(image(g, c) ** 2))
    text = jax.jit(grad).trace(g, scenes.camera()).lower(lowering_platforms=("cuda",)).as_text()
    assert text.count("mosaic_gpu") >= 2


def test_a_segment_the_unroll_does_not_divide_says_how_to_fix_it():
    with pytest.raises(ValueError, match="backward_segment: 100 .* or to None"):
        K(unroll=8, backward_segment=100)

