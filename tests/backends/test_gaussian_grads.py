"""lgs_jax.backends.gaussian_grads: the Pallas backward's per-Gaussian chain and sum of the
emission-order pair rows, against its jnp twin (bit for bit, interpret mode) and against the
XLA path of the `tiles` backend (pairs.chain_hoisted_rows + backward.per_gaussian_sum)."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from lgs_jax import binning, pairs
from lgs_jax.backends import backward, gaussian_grads, kernel_steps as ks
from lgs_jax.config import RasterConfig as C
from lgs_jax.layout import tile_grid
from lgs_jax.projection import project
from tests import scenes

W, H = 96, 64  # 6x4 tiles
TILES_X = tile_grid(W, H)[0]


@functools.partial(jax.jit, static_argnums=(2,))
def _projected_bins(g, cam, capacity):
    p = project(g, cam)
    return p, binning.bin_gaussians(p, W, H, capacity)


@functools.partial(jax.jit, static_argnums=(3,))
def _three_ways(rows, bins, p, config):
    """(kernel, jnp twin, XLA path) per-Gaussian gradients of emission-order `rows`."""
    layout = gaussian_grads.slot_rows(bins)
    kernel = gaussian_grads.sums(rows, layout, p, TILES_X, config, interpret=True)
    twin = gaussian_grads.reference(rows, layout, p, TILES_X, config)
    sorted_rows = jnp.sum(rows[:, bins.slot, :ks.GRAD_VALUES], 0)  # the blocks added
    if config.hoist:
        per_pair = pairs.chain_hoisted_rows(pairs.gather(p, bins.gauss), bins, sorted_rows,
                                            TILES_X, config)
    else:
        per_pair = jnp.concatenate([sorted_rows[:, :6], sorted_rows[:, 7:]], -1)
    xla = backward.per_gaussian_sum(per_pair, bins, p.mean2d.shape[0])
    return kernel, twin, xla


CONFIGS = {"hoisted": C(), "center": C(origin="center"), "global": C(local_coords=False),
           "difference": C(hoist=False)}


SLOW = pytest.mark.slow


@pytest.mark.parametrize("name,capacity,blocks", [
    ("hoisted", 1024, 2), ("difference", 40, 1), ("center", 40, 2),
    pytest.param("global", 1024, 1, marks=SLOW), pytest.param("hoisted", 40, 1, marks=SLOW)])
@settings(max_examples=4)
@given(seed=st.integers(0, 2**32 - 1), yaw=st.floats(-0.3, 0.3))
def test_kernel_equals_its_twin_and_the_xla_path_float64(name, capacity, blocks, seed, yaw):
    """Random rows at every real pair's emission slot, the pair's tile in the tile column, NaN
    in padding slots (which no Gaussian may read), one or two blocks per tile, a capacity that
    holds every pair or drops the tail: the kernel equals its jnp twin bit for bit and the
    XLA path's per-pair chain and segmented sum to float64 rounding."""
    g = scenes.cast(scenes.scene(seed), np.float64)
    p, bins = _projected_bins(g, scenes.camera(W, H, yaw=yaw), capacity)
    assert bool(bins.overflow) == (capacity == 40)
    rng = np.random.default_rng(seed)
    rows = np.full((blocks, capacity, ks.ROW_WIDTH), np.nan)
    real = np.asarray(bins.tile) < bins.tile_start.shape[0]
    slot = np.asarray(bins.slot)[real]
    rows[:, slot, :ks.GRAD_VALUES] = rng.normal(size=(blocks, slot.size, ks.GRAD_VALUES))
    rows[:, slot, ks.TILE_COLUMN] = np.asarray(bins.tile)[real]
    kernel, twin, xla = (np.asarray(x) for x in _three_ways(rows, bins, p, CONFIGS[name]))
    np.testing.assert_array_equal(kernel, twin)
    assert np.all(np.isfinite(kernel))
    scale = np.max(np.abs(xla), 0) + 1e-300
    np.testing.assert_allclose(kernel / scale, xla / scale, rtol=0, atol=1e-12)
    assert np.any(kernel != 0)
