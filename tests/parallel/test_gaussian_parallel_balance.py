"""`lgs_jax.parallel.balance`: rebalancing a pool split over devices keeps the active Gaussians'
order, fills each block from its front, holds no block over its size and evens the blocks out
by count (within one) or by weight (within the heaviest Gaussian)."""

import jax
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from lgs_jax.parallel.balance import balanced_order, block_starts

SIZE, DEVICES = 48, 4
BLOCK = SIZE // DEVICES
order_of = jax.jit(balanced_order, static_argnums=1)

masks = st.lists(st.booleans(), min_size=SIZE, max_size=SIZE).map(np.asarray)
weights = st.lists(st.floats(0, 100, allow_nan=False), min_size=SIZE,
                   max_size=SIZE).map(lambda w: np.asarray(w, np.float32))


def _check_layout(active, order):
    order = np.asarray(order)
    assert sorted(order.tolist()) == list(range(SIZE))  # a permutation of the slots
    moved = active[order]
    kept = order[moved]
    assert np.all(np.diff(kept) > 0)  # the active Gaussians in their order
    per_block = moved.reshape(DEVICES, BLOCK)
    for row in per_block:  # each block's active ones at its front
        n = int(row.sum())
        assert row[:n].all() and not row[n:].any()
    inactive = order[~moved]
    assert np.all(np.diff(inactive) > 0)  # the inactive ones in their order too
    return per_block.sum(1)


@given(masks)
def test_gaussian_parallel_rebalance_by_count(active):
    counts = _check_layout(active, order_of(active, DEVICES))
    assert counts.max() - counts.min() <= 1
    assert counts.sum() == active.sum()


@given(masks, weights)
def test_gaussian_parallel_rebalance_by_weight(active, w):
    order = np.asarray(order_of(active, DEVICES, w))
    counts = _check_layout(active, order)
    assert counts.max() <= BLOCK
    block_weight = np.where(active, w, 0)[order].reshape(DEVICES, BLOCK).sum(1)
    share, heaviest = np.where(active, w, 0).sum() / DEVICES, np.where(active, w, 0).max()
    if counts.max() < BLOCK:  # no block clamped by its size: even to the heaviest Gaussian
        assert block_weight.max() <= share + heaviest + 1e-3 * share


def test_gaussian_parallel_rebalance_respects_block_sizes():
    # every Gaussian active, all the weight on the first four: each block still takes BLOCK
    active = np.ones(SIZE, bool)
    w = np.zeros(SIZE, np.float32)
    w[:4] = 1
    starts = np.asarray(block_starts(active, DEVICES, w))
    assert starts.tolist() == [0, 12, 24, 36, 48]
    assert np.array_equal(np.asarray(order_of(active, DEVICES, w)), np.arange(SIZE))


def test_gaussian_parallel_rebalance_refuses_uneven_blocks():
    with pytest.raises(ValueError, match="47 slots do not split into 4 equal blocks"):
        block_starts(np.ones(47, bool), 4)


def test_gaussian_parallel_work_is_each_gaussians_pairs_and_projection():
    """`sharded_state.work`, the weight training balances by: per slot and view, 1 (its
    projection) + its tile pairs; an inactive slot has none. Its views: at most 8, evenly
    spaced."""
    from lgs_jax import Camera, Gaussians, count_pairs
    from lgs_jax.train import from_gaussians, sharded_state

    rng = np.random.default_rng(3)
    n = 40
    g = Gaussians(rng.normal(size=(n, 3)).astype(np.float32),
                  rng.normal(size=(n, 4)).astype(np.float32),
                  rng.normal(-2, 0.7, (n, 3)).astype(np.float32),
                  rng.normal(0, 2, n).astype(np.float32),
                  rng.normal(size=(n, 1, 3)).astype(np.float32))
    pool = from_gaussians(g, SIZE)
    cam = Camera(viewmat=np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 4], [0, 0, 0, 1]],
                                  np.float32), fx=np.float32(40), fy=np.float32(40),
                 cx=np.float32(32), cy=np.float32(16), width=64, height=32)
    w = np.asarray(sharded_state.work(pool, [cam, cam], antialiased=False))
    active = np.asarray(pool.active)
    pairs = int(count_pairs(g, cam))
    assert pairs > n and np.all(w[~active] == 2) and w[active].sum() == 2 * (n + pairs)
    assert sharded_state.balance_views(3) == [0, 1, 2]
    picks = sharded_state.balance_views(100)
    assert len(picks) == 8 and picks[0] == 0 and picks[-1] == 99
