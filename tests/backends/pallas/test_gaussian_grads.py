"""lgs_jax.backends.pallas.gaussian_grads: the Pallas backward's per-Gaussian chain and sum of the
emission-order pair rows, against its jnp twin (bit for bit, interpret mode) and against the
XLA path of the `tiles` backend (pairs.chain_hoisted_rows + backward.per_gaussian_sum); the
walked-rows layout (`walked_rows`) against numpy, and gradients with `render`'s `row_capacity`
at the walked pairs against those of the default buffer (the pair capacity's), bit for bit."""

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import lgs_jax
from lgs_jax import binning, pairs
from lgs_jax.backends import backward
from lgs_jax.backends.pallas import gaussian_grads, steps as ks
from lgs_jax.config import RasterConfig as C
from lgs_jax.layout import tile_grid
from lgs_jax.projection import project
from tests import scenes
from tests.devices import gpu_only

W, H = 96, 64  # 6x4 tiles
TILES_X = tile_grid(W, H)[0]


@functools.partial(jax.jit, static_argnums=(2,))
def _projected_bins(g, cam, capacity):
    p = project(g, cam)
    return p, binning.bin_gaussians(p, W, H, capacity)


@functools.partial(jax.jit, static_argnums=(3,))
def _four_ways(rows, bins, p, config):
    """(kernel, kernel reading the Gaussian table, jnp twin, XLA path) per-Gaussian gradients
    of emission-order `rows`: every pair walked (each tile's pixels stop at its list's end), so
    pair rows are numbered by slot."""
    stop = jnp.broadcast_to(bins.tile_end[:, None], (bins.tile_end.shape[0], 256))
    layout = gaussian_grads.walked_rows(bins, stop, bins.gauss.shape[0])
    kernel = gaussian_grads.sums(rows, layout, p, TILES_X, config, interpret=True)
    # the fields from the Gaussian table, as the Mosaic GPU backward passes them
    from_table = gaussian_grads.sums(rows, layout, pairs.gaussian_table(p), TILES_X, config,
                                     interpret=True)
    twin = gaussian_grads.reference(rows, layout, p, TILES_X, config)
    sorted_rows = jnp.sum(rows[:, bins.slot, :ks.GRAD_VALUES], 0)  # the blocks added
    if config.hoist:
        per_pair = pairs.chain_hoisted_rows(pairs.gather(p, bins.gauss), bins, sorted_rows,
                                            TILES_X, config)
    else:
        per_pair = jnp.concatenate([sorted_rows[:, :6], sorted_rows[:, 7:]], -1)
    xla = backward.per_gaussian_sum(per_pair, bins, p.mean2d.shape[0])
    return kernel, from_table, twin, xla


# Jitted once for the tests below (eager, each of their operations compiles on its own).
_walked_rows = jax.jit(gaussian_grads.walked_rows, static_argnums=2)
_twin = jax.jit(gaussian_grads.reference, static_argnums=(3, 4))
_table = jax.jit(pairs.gaussian_table)


def _random_rows(bins, blocks: int, seed: int, fill, dtype):
    """(blocks, capacity, row_width(True)) rows: random gradient values and the pair's tile at
    every real pair's emission slot, `fill` elsewhere."""
    rows = np.full((blocks, bins.gauss.shape[0], ks.row_width(True)), fill, dtype)
    real = np.asarray(bins.tile) < bins.tile_start.shape[0]
    slot = np.asarray(bins.slot)[real]
    rng = np.random.default_rng(seed)
    rows[:, slot, :ks.GRAD_VALUES] = rng.normal(size=(blocks, slot.size, ks.GRAD_VALUES))
    rows[:, slot, ks.TILE_COLUMN] = np.asarray(bins.tile)[real]
    return rows


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
    holds every pair or drops the tail: the kernel equals its jnp twin bit for bit (reading
    the Gaussians' fields from the Projected or from the Gaussian table) and the XLA path's
    per-pair chain and segmented sum to float64 rounding."""
    g = scenes.cast(scenes.scene(seed), np.float64)
    p, bins = _projected_bins(g, scenes.camera(W, H, yaw=yaw), capacity)
    assert bool(bins.overflow) == (capacity == 40)
    rows = _random_rows(bins, blocks, seed, np.nan, np.float64)
    kernel, from_table, twin, xla = (np.asarray(x)
                                     for x in _four_ways(rows, bins, p, CONFIGS[name]))
    np.testing.assert_array_equal(kernel, twin)
    np.testing.assert_array_equal(from_table, kernel)
    assert np.all(np.isfinite(kernel))
    scale = np.max(np.abs(xla), 0) + 1e-300
    np.testing.assert_allclose(kernel / scale, xla / scale, rtol=0, atol=1e-12)
    assert np.any(kernel != 0)


@settings(max_examples=2)
@given(seed=st.integers(0, 2**32 - 1))
def test_float32_kernel_writing_into_the_layouts_buffers_equals_its_twin(seed):
    """In float32 the kernel takes the layout's first and count as float32 bits and writes
    two columns into their buffers (aliased outputs): it still equals its twin bit for bit,
    and the caller's layout is left as it was (XLA copies an aliased input that lives on).
    Pallas' interpreter gives an aliased output a copy of its input, so the kernel's order
    (each lane reads its first and count before any store) is exercised only on a GPU, by the
    gradient tests, where the layout is an intermediate XLA can alias in place."""
    # The float64 projection's program (the tests above compiled it), its fields cast to
    # float32 (mean2d_lo is 0 in float64): a float32 Projected, without a compile of its own.
    p, bins = _projected_bins(scenes.scene(seed), scenes.camera(W, H), 1024)
    p = jax.tree.map(lambda x: x.astype(np.float32) if x.dtype == np.float64 else x, p)
    stop = jnp.broadcast_to(bins.tile_end[:, None], (bins.tile_end.shape[0], 256))
    layout = _walked_rows(bins, stop, bins.gauss.shape[0])
    first, count = np.asarray(layout.first), np.asarray(layout.count)
    rows, table = jnp.asarray(_random_rows(bins, 1, seed, 0, np.float32)), _table(p)
    kernel = jax.jit(lambda r, l, t: gaussian_grads.sums(r, l, t, TILES_X, C(), True))(
        rows, layout, table)
    twin = _twin(rows, layout, table, TILES_X, C())
    np.testing.assert_array_equal(np.asarray(kernel), np.asarray(twin))
    assert np.any(np.asarray(kernel) != 0)
    np.testing.assert_array_equal(np.asarray(layout.first), first)
    np.testing.assert_array_equal(np.asarray(layout.count), count)


@settings(max_examples=2)
@given(seed=st.integers(0, 2**32 - 1))
def test_rows_without_the_depth_column_give_the_sums_of_a_zero_depth_column(seed):
    """Rows without ∂L/∂z (the Mosaic GPU backward's for a loss that does not reach the depth:
    `kernel_steps.row_width(False)`, the tile one column earlier) give the sums of the same rows
    with a zero ∂L/∂z column, bit for bit, kernel and twin (it fails where the sums read ∂L/∂z
    from the short rows, which would then sum the tiles as the depth's gradient)."""
    g = scenes.cast(scenes.scene(seed), np.float64)
    p, bins = _projected_bins(g, scenes.camera(W, H), 1024)
    stop = jnp.broadcast_to(bins.tile_end[:, None], (bins.tile_end.shape[0], 256))
    layout = _walked_rows(bins, stop, bins.gauss.shape[0])
    rows = _random_rows(bins, 2, seed, 0, np.float64)
    rows[..., ks.GRAD_VALUES - 1] = 0  # ∂L/∂z
    short = jnp.asarray(np.delete(rows, ks.GRAD_VALUES - 1, axis=-1))
    assert short.shape[-1] == ks.row_width(False)
    rows = jnp.asarray(rows)
    table = _table(p)
    full = gaussian_grads.sums(rows, layout, table, TILES_X, C(), True)
    for out in (gaussian_grads.sums(short, layout, table, TILES_X, C(), True),
                _twin(short, layout, table, TILES_X, C())):
        np.testing.assert_array_equal(np.asarray(out), np.asarray(full))
    assert np.any(np.asarray(full)[:, :9] != 0) and np.all(np.asarray(full)[:, 9] == 0)


@settings(max_examples=10)
@given(seed=st.integers(0, 2**32 - 1), share=st.floats(0, 1), spare=st.integers(-30, 5),
       wide_keys=st.booleans())
def test_walked_rows_number_each_gaussians_walked_pairs_consecutively(seed, share, spare,
                                                                      wide_keys):
    """Random stop pairs (a tile walks a random share of its list): a pair has a row iff it lies
    before its tile's latest stop; the rows of the walked pairs are 0, 1, ... in emission-slot
    order (so each Gaussian's are consecutive, [first, first + count)); with fewer rows than
    walked pairs (`spare` < 0) the pairs past them point at the spare row and the Gaussians'
    ranges stop at it. `wide_keys`: the emitted tiles as int32, as the tile sort keys them
    above `binning.SORT16_TILES` tiles."""
    g = scenes.cast(scenes.scene(seed), np.float64)
    _, bins = _projected_bins(g, scenes.camera(W, H), 1024)
    if wide_keys:
        bins = dataclasses.replace(bins, emitted_tile=bins.emitted_tile.astype(jnp.int32))
    rng = np.random.default_rng(seed)
    start, end = np.asarray(bins.tile_start), np.asarray(bins.tile_end)
    walk = np.floor((end - start) * share * rng.uniform(size=start.shape)).astype(np.int32)
    stop = start[:, None] + rng.integers(0, walk[:, None] + 1, size=(start.size, 256))
    stop[:, 0] = start + walk  # the latest stop of each tile
    last = start + walk
    tile, slot = np.asarray(bins.tile), np.asarray(bins.slot)
    walked = (tile < start.size) & (np.arange(tile.size) < last[np.minimum(tile, start.size - 1)])
    rows = max(int(walked.sum()) + spare, 1)
    layout = _walked_rows(bins, stop, rows)
    assert layout.size == rows + 1
    np.testing.assert_array_equal(layout.end, last)
    by_slot = np.zeros(tile.size, bool)
    by_slot[slot[walked]] = True
    number = np.cumsum(by_slot) - by_slot  # walked pairs numbered in slot order
    want = np.where(walked, np.minimum(number[slot], rows), rows)
    np.testing.assert_array_equal(layout.at, want)
    first, count = np.asarray(bins.first), np.asarray(bins.count)
    for i in range(first.size):
        mine = np.flatnonzero(by_slot[first[i]:first[i] + count[i]]) + first[i]
        got = np.arange(layout.first[i], layout.first[i] + layout.count[i])
        np.testing.assert_array_equal(got, np.minimum(number[mine], rows)[number[mine] < rows])


@pytest.mark.parametrize("kernel,pixels", [("triton", None), pytest.param("mosaic", 128, marks=[
    pytest.mark.slow, gpu_only("CI time: in interpret mode test_segments.py runs walked "
                               "rows through the Mosaic GPU backward (whole tiles)")])])
@settings(max_examples=1)  # interpret mode
@given(seed=st.integers(0, 2**32 - 1))
def test_a_row_capacity_at_the_walked_pairs_gives_the_defaults_gradients(kernel, pixels, seed):
    """`render(row_capacity=stats.backend_stats.pairs_walked)`: the Pallas backward with a buffer
    of exactly the walked pairs' rows gives the gradients of the default buffer (the pair
    capacity's rows), bit for bit, on a scene where most pairs are not walked (asserted); one
    row fewer is reported (`row_overflow`), never NaN, and leaves the image unchanged."""
    g, cam = scenes.saturating(seed, 200, np.float32), scenes.camera(32, 32)
    w = np.random.default_rng(seed).normal(size=(32, 32, 3)).astype(np.float32)
    config = C(kernel=kernel, tuning=lgs_jax.KernelConfig(forward_pixels=pixels,
                                                          backward_pixels=pixels))

    def grads(g, rows):
        def loss(g):
            out = lgs_jax.render(g, cam, backend="pallas", config=config, capacity=2048,
                                 row_capacity=rows)
            return jnp.sum(out.image * w), out
        return jax.grad(loss, has_aux=True)(g)

    every, out = jax.jit(grads, static_argnums=1)(g, None)
    walked = int(out.stats.backend_stats.pairs_walked)
    assert 0 < walked < int(out.stats.pairs_required) / 2  # the layout has pairs to leave out
    assert not bool(out.stats.backend_stats.row_overflow)
    # The walked rows and one fewer in one program (their backward passes share one forward):
    # a compile less than one program each.
    (got, out_walked), (short, out_short) = jax.jit(
        lambda g: (grads(g, walked), grads(g, walked - 1)))(g)
    assert not bool(out_walked.stats.backend_stats.row_overflow)
    for name, a, b in zip(scenes.FIELDS, jax.tree.leaves(got), jax.tree.leaves(every)):
        np.testing.assert_array_equal(a, b, err_msg=name)
    assert bool(out_short.stats.backend_stats.row_overflow)
    np.testing.assert_array_equal(out_short.image, out.image)
    assert all(np.all(np.isfinite(x)) for x in jax.tree.leaves(short))
