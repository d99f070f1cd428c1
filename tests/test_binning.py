"""Binning is exact: every pixel whose float alpha test passes lies in a listed tile.

Searched where bugs live: conics with condition numbers up to 1e8 (needles), centres thousands of
pixels outside the image, opacities within a hair of 1/255, and the real projection pipeline.
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, strategies as st

import lgs_jax
from lgs_jax import binning
from lgs_jax.composite import centre_offsets, gaussian_alpha
from lgs_jax.config import ALPHA_MIN
from lgs_jax.projection import Projected, depth_order, project
from tests import scenes

W, H = 64, 48
M = 16  # Gaussians per example


def _alpha_pass(p: Projected, width, height, cap=0.99):
    """(M, H, W) bool: the float alpha test of the compositing code, at every pixel."""
    dt = p.mean2d.dtype
    jj, ii = jnp.meshgrid(jnp.arange(width), jnp.arange(height))
    px, py = (jj + 0.5).astype(dt), (ii + 0.5).astype(dt)

    def one(m, lo, c, o):
        power, alpha = gaussian_alpha(centre_offsets(m, lo, px, py), c, o, jnp.asarray(cap, dt))
        return (power <= 0) & (alpha >= jnp.asarray(ALPHA_MIN, dt))

    return jax.vmap(one)(p.mean2d, p.mean2d_lo, p.conic, p.opacity) & p.valid[:, None, None]


def _check_covered(p: Projected, width=W, height=H):
    passing = np.asarray(_alpha_pass(p, width, height))
    x0, x1, y0, y1, _ = (np.asarray(v) for v in binning.pixel_box(p, width, height))
    tx0, ty0, nx, ny, _ = (np.asarray(v) for v in binning.tile_rects(p, width, height))
    ii, jj = np.meshgrid(np.arange(height), np.arange(width), indexing="ij")
    for m in range(passing.shape[0]):
        inside = (jj >= x0[m]) & (jj <= x1[m]) & (ii >= y0[m]) & (ii <= y1[m])
        missed = passing[m] & ~inside
        assert not missed.any(), f"Gaussian {m}: {missed.sum()} passing pixels outside its box"
        tiles = ((jj // 16 >= tx0[m]) & (jj // 16 < tx0[m] + nx[m]) & (ii // 16 >= ty0[m])
                 & (ii // 16 < ty0[m] + ny[m]))
        assert not (passing[m] & ~tiles).any(), f"Gaussian {m}: passing pixels outside tiles"
    return passing


def _arrays(lo, hi):
    return scenes.float_arrays(lo, hi, M)


@given(log_kappa=_arrays(0, np.log(1e8)), theta=_arrays(0, np.pi), log_lmin=_arrays(-8, 8),
       offset=_arrays(0, 3000), angle=_arrays(0, 2 * np.pi),
       logit=_arrays(np.log(1 / 254), 12), dtype=st.sampled_from([np.float32, np.float64]))
def test_box_covers_every_passing_pixel(log_kappa, theta, log_lmin, offset, angle, logit, dtype):
    p = scenes.projected_conics(dtype, log_kappa, theta, log_lmin, offset, angle, logit)
    _check_covered(p)


@given(log_kappa=_arrays(0, np.log(1e7)), theta=_arrays(0, np.pi), log_lmin=_arrays(-8, 6),
       angle=_arrays(0, 2 * np.pi), logit=_arrays(np.log(1 / 254), 12),
       edge=_arrays(-3e-6, 3e-6), dtype=st.sampled_from([np.float32, np.float64]))
def test_box_covers_pixels_on_the_ellipse_edge(log_kappa, theta, log_lmin, angle, logit, edge,
                                               dtype):
    p = scenes.projected_conics(dtype, log_kappa, theta, log_lmin, np.zeros(M), angle, logit,
                                edge=edge)
    _check_covered(p)


@functools.partial(jax.jit, static_argnums=1)
def _emitted_and_binned(p, cap):
    return binning.emit_pairs(p, W, H, cap), binning.bin_gaussians(p, W, H, cap)


def _check_slots(p: Projected, cap: int = 256):
    """`TileBins.slot` is the tile sort's permutation of the emitted pairs, `emitted_tile` the
    emitted tiles (as the sort's keys), and a tile's pairs are its slots in ascending order;
    `first` and `count` locate each Gaussian's pairs (256 >= M Gaussians x the 4x3 tiles of a
    W x H image; a smaller `cap` drops the tail)."""
    e, bins = _emitted_and_binned(p, cap)
    slot = np.asarray(bins.slot)
    np.testing.assert_array_equal(np.sort(slot), np.arange(slot.size))
    np.testing.assert_array_equal(np.asarray(e.gauss)[slot], bins.gauss)
    np.testing.assert_array_equal(np.asarray(e.tile)[slot], bins.tile)
    np.testing.assert_array_equal(bins.emitted_tile, np.asarray(e.tile).astype(np.uint16))
    same_tile = np.asarray(bins.tile)[1:] == np.asarray(bins.tile)[:-1]
    assert np.all(slot[1:][same_tile] > slot[:-1][same_tile])
    # Each Gaussian's pairs are the emission slots [first, first + count), and no others.
    gauss, first, count = np.asarray(e.gauss), np.asarray(bins.first), np.asarray(bins.count)
    real = np.asarray(e.tile) < bins.tile_start.shape[0]
    for i in range(first.size):
        np.testing.assert_array_equal(np.flatnonzero(real & (gauss == i)),
                                      first[i] + np.arange(count[i]))


@given(seed=st.integers(0, 2**32 - 1), yaw=st.floats(-0.5, 0.5))
def test_projected_scene_tiles_cover_passing_pixels_float32(seed, yaw):
    """The tiles of a projected scene hold every passing pixel; its bins' `slot` is the tile
    sort's permutation of the emitted pairs, and `first`/`count` locate each Gaussian's pairs,
    also when the capacity drops some."""
    g = scenes.cast(scenes.scene(seed, n=M), np.float32)
    p = project(g, scenes.camera(W, H, yaw=yaw))
    _check_covered(p)
    _check_slots(p)
    _check_slots(p, cap=24)


def test_box_is_tight_for_ordinary_gaussians():
    """Padding for rounding costs almost nothing away from needles: for κ <= 100 the box is within
    a pixel of the exact float64 ellipse box."""
    rng = np.random.default_rng(0)
    args = (rng.uniform(0, np.log(100), M), rng.uniform(0, np.pi, M), rng.uniform(-2, 5, M),
            rng.uniform(0, 20, M), rng.uniform(0, 2 * np.pi, M), rng.uniform(-4, 6, M))
    p = scenes.projected_conics(np.float32, *args)
    x0, x1, _, _, unbounded = (np.asarray(v) for v in binning.pixel_box(p, 10**6, 10**6))
    cov = np.asarray(p.cov2d, np.float64)
    tau = 2 * np.log(255 * np.asarray(p.opacity, np.float64))
    rx = np.sqrt(tau * cov[:, 0])
    mx = np.asarray(p.mean2d[:, 0], np.float64)
    assert not unbounded.any()
    ok = np.asarray(p.valid)
    assert np.all(x0[ok] >= np.ceil(mx - rx - 0.5)[ok] - 1)
    assert np.all(x1[ok] <= np.floor(mx + rx - 0.5)[ok] + 1)


def test_overflow_is_reported_under_jit():
    g = scenes.cast(scenes.scene(5, kinds=("normal", "huge_far")), np.float32)
    cam = scenes.camera()
    stats = scenes.jit_render(g, cam, capacity=2).stats  # tests/test_render.py's program too
    assert bool(stats.overflow) and int(stats.pairs_required) > 2
    full = lgs_jax.render(g, cam)
    assert int(full.stats.pairs_required) == int(stats.pairs_required)
    assert int(full.stats.capacity) >= int(stats.pairs_required)


@given(seed=st.integers(0, 2**32 - 1))
def test_tile_ranges_equal_searchsorted(seed):
    """Sorted tiles with runs, gaps (empty tiles), padding (n_tiles) or none, and one tile only."""
    rng = np.random.default_rng(seed)
    n_tiles = 12
    tile = np.sort(rng.choice(rng.integers(0, n_tiles + 1, 1 + rng.integers(0, 6)), 64))
    start, end = binning.tile_ranges(jnp.asarray(tile, jnp.int32), n_tiles)
    ids = np.arange(n_tiles)
    np.testing.assert_array_equal(start, np.searchsorted(tile, ids, side="left"))
    np.testing.assert_array_equal(end, np.searchsorted(tile, ids, side="right"))


# Jitted (capacity static): one compile per capacity drawn, where each eager operation compiled
# again at every new capacity.
_segment_of_slot = jax.jit(binning.segment_of_slot, static_argnums=2)


@given(seed=st.integers(0, 2**32 - 1), cut=st.sampled_from([0.3, 1.0, 2.0]))
def test_segment_of_slot_equals_searchsorted(seed, cut):
    """Segments with runs of empty ones (first and last included), a capacity below, at and
    above the total; slots past the total get the last segment."""
    rng = np.random.default_rng(seed)
    counts = rng.choice(np.array([0, 0, 1, 2, 7]), 40) * (rng.random(40) < 0.7)
    ends = np.cumsum(counts)
    capacity = max(1, int(cut * ends[-1]))
    got = _segment_of_slot(jnp.asarray(ends - counts, jnp.int32),
                           jnp.asarray(counts, jnp.int32), capacity)
    slots = np.arange(capacity)
    want = np.where(slots < ends[-1], np.searchsorted(ends, slots, side="right"), 39)
    np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@given(seed=st.integers(0, 2**32 - 1))
def test_depth_order_is_the_stable_order_of_depths(dtype, seed):
    """`projection.float_sort_key` orders like the floats: ties (−0 and +0 too) by index,
    negatives, the smallest normal, infinities and invalid Gaussians (last). (XLA flushes
    subnormals to zero on CPUs and GPUs, in its float sort as in the key.)"""
    rng = np.random.default_rng(seed)
    tiny = np.finfo(dtype).smallest_normal
    values = np.array([-0.0, 0.0, tiny, -tiny, 1.0, 1.0 + np.finfo(dtype).eps, -3.5, 7e30,
                       np.finfo(dtype).max, np.inf], dtype)
    depth = rng.choice(values, 64)
    valid = rng.random(64) < 0.8
    p = Projected(mean2d=None, mean2d_lo=None, cov2d=None, conic=None, depth=jnp.asarray(depth),
                  opacity=None, rgb=None, valid=jnp.asarray(valid), invalid=None)
    key = np.where(valid, depth + dtype(0), np.inf)  # −0 + 0 = +0
    np.testing.assert_array_equal(depth_order(p), np.argsort(key, kind="stable"))


@pytest.mark.parametrize("n_tiles", [12, binning.SORT16_TILES, binning.SORT16_TILES + 1])
@given(seed=st.integers(0, 2**32 - 1))
def test_tile_sort_is_the_stable_order_with_16_and_32_bit_keys(n_tiles, seed):
    """Up to SORT16_TILES tiles the keys are sorted as uint16, above as int32: either way the
    permutation is numpy's stable argsort of the tiles (ties by emission slot), the largest tile
    and the padding value (n_tiles) included."""
    rng = np.random.default_rng(seed)
    tile = rng.choice(np.array([0, 1, n_tiles // 2, n_tiles - 1, n_tiles]), 200)
    gauss = rng.integers(0, 50, 200)
    got_tile, got_gauss, slot, start, end = binning.sort_pairs(
        jnp.asarray(tile, jnp.int32), jnp.asarray(gauss, jnp.int32), n_tiles)
    want = np.argsort(tile, kind="stable")
    np.testing.assert_array_equal(slot, want)
    np.testing.assert_array_equal(got_tile, tile[want])
    np.testing.assert_array_equal(got_gauss, gauss[want])
    assert got_tile.dtype == jnp.int32
    np.testing.assert_array_equal(end[-1], np.searchsorted(tile[want], n_tiles - 1, "right"))


def test_slot_starts_past_int32_keep_the_nearest_pairs():
    """Whole-image Gaussians at 4K (32400 tiles each) whose pairs pass 2^32: with 32-bit
    integers the running slot starts wrap past 2^31 and again past 2^32 (rank 132,561 would
    start at slot 9104), yet every slot of the capacity holds the nearest Gaussian's pairs
    (an overflow drops the farthest ones, `TileBins.overflow`), never a Gaussian past the wrap."""
    n, width, height, cap = 132_600, 3840, 2160, 16384
    with jax.enable_x64(False):
        ones = jnp.ones((n,), jnp.float32)
        p = Projected(mean2d=jnp.tile(jnp.array([[1920.0, 1080.0]]), (n, 1)),
                      mean2d_lo=jnp.zeros((n, 2)),
                      cov2d=jnp.tile(jnp.array([[1e8, 0.0, 1e8]]), (n, 1)),
                      conic=jnp.tile(jnp.array([[1e-8, 0.0, 1e-8]]), (n, 1)),
                      depth=jnp.arange(1, n + 1, dtype=jnp.float32), opacity=0.9 * ones,
                      rgb=jnp.zeros((n, 3)), valid=ones > 0, invalid=ones < 0)
        e = jax.jit(binning.emit_pairs, static_argnums=(1, 2, 3))(p, width, height, cap)
        assert int(e.total) == binning.MAX_PAIRS
        np.testing.assert_array_equal(e.gauss, 0)
        np.testing.assert_array_equal(e.tile, np.arange(cap))
        assert (int(e.first[0]), int(e.count[0])) == (0, cap)
        assert int(e.count[1:].max()) == 0
