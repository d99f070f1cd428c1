"""lgs_jax.backends.backward: the per-Gaussian sum of pair rows (`segment_sums` on contiguous
runs, `per_gaussian_sum` through real bins)."""

import functools

import jax
import numpy as np
from hypothesis import given, strategies as st

from lgs_jax import binning
from lgs_jax.backends import backward
from lgs_jax.projection import project
from tests import scenes

CAP, N = 300, 37  # fixed shapes: one compile


def _runs(rng, n_runs):
    """CAP ids in n_runs contiguous runs of distinct ids, in random id order, random lengths."""
    ids = rng.permutation(N)[:n_runs]
    cuts = np.sort(rng.choice(np.arange(1, CAP), n_runs - 1, replace=False))
    return np.repeat(ids, np.diff(np.concatenate([[0], cuts, [CAP]])))


@given(seed=st.integers(0, 2**32 - 1),
       runs=st.sampled_from(["sorted", "one", "few", "many"]), dropped=st.integers(0, 40))
def test_segment_sums_equal_a_float64_sum(seed, runs, dropped):
    """Every id's rows summed, whatever the runs look like: sorted ids, one id owning every row
    (a run over all chunks), a few long runs crossing chunk boundaries, many runs in no id
    order; ids with no row get zero; a tail of `dropped` rows with id N is left out."""
    rng = np.random.default_rng(seed)
    ids = {"sorted": lambda: np.sort(rng.integers(0, N, CAP)),
           "one": lambda: np.full(CAP, rng.integers(0, N)),
           "few": lambda: _runs(rng, 3),
           "many": lambda: _runs(rng, N)}[runs]().astype(np.int32)
    ids[CAP - dropped:] = N
    rows = rng.normal(size=(CAP, 4))
    sums = jax.jit(backward.segment_sums, static_argnums=2)
    got = np.asarray(sums(ids, rows, N))
    want = np.zeros((N + 1, 4))
    np.add.at(want, ids, rows)
    np.testing.assert_allclose(got, want[:N], rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(got, np.asarray(sums(ids, rows, N)))


W, H, CAPACITY = 96, 64, 1024  # 6x4 tiles: >= scenes.N x 24 pairs, so padding pairs remain


@functools.partial(jax.jit, static_argnums=(2,))
def _bins(g, cam, capacity):
    return binning.bin_gaussians(project(g, cam), W, H, capacity)


@given(seed=st.integers(0, 2**32 - 1), yaw=st.floats(-0.3, 0.3))
def test_per_gaussian_sum_through_bins_equals_a_float64_sum(seed, yaw):
    """Random rows for every pair slot of real bins (a projected test scene: Gaussians over
    many tiles, off-image and invalid ones with none): each Gaussian gets the sum of its real
    pairs' rows (tile < n_tiles; padding pairs' rows are left out), the same bits every call."""
    g = scenes.cast(scenes.scene(seed), np.float32)
    bins = _bins(g, scenes.camera(W, H, yaw=yaw), CAPACITY)
    assert not bool(bins.overflow)
    rows = np.random.default_rng(seed).normal(size=(CAPACITY, 5))
    total = jax.jit(backward.per_gaussian_sum, static_argnums=2)
    got = np.asarray(total(rows, bins, scenes.N))
    real = np.asarray(bins.tile) < bins.tile_start.shape[0]
    want = np.zeros((scenes.N, 5))
    np.add.at(want, np.asarray(bins.gauss)[real], rows[real])
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(got, np.asarray(total(rows, bins, scenes.N)))
