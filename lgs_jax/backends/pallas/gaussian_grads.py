"""The Pallas backward's last step: each Gaussian's pair rows chained to its screen-space
parameters and summed, one lane per Gaussian, in a fixed order.

The backward kernels (lgs_jax.backends.pallas.mosaic_backward, .triton) store each walked pair's
row at its row in emission-slot order (`RowLayout`; a Gaussian's pairs are the consecutive slots
[first, first + count) in ascending tile order, `TileBins.first`, `TileBins.count`). A row
holds the pair's gradient summed over one block's pixels (`steps.GRAD_VALUES` values:
the α model's 7 columns, ∂L/∂rgb, ∂L/∂z; the Mosaic GPU kernel leaves ∂L/∂z out where the loss
does not reach the depth, `steps.row_width`) and then its tile index as a float (exact:
images have fewer than 2^24 tiles, lgs_jax.scene checks); a block's row of a pair none of its
pixels reached is zero. For Gaussian g this computes, walking its
rows in order,

    hoisted (Eq. 8):  Σ_pairs [∂L/∂μ, ∂L/∂(a, b, c), ∂L/∂ln o + clamp, ∂L/∂rgb, ∂L/∂z]
                      with ∂L/∂(a, b, c, Δ, ln o) = hoist.hoist_terms_vjp(∂L/∂V, a, b, c, Δ),
                      Δ = μ − T(tile) = (mean2d − T) + mean2d_lo (pairs.origin_offsets, as
                      the forward's records), then ∂L/∂o = Σ ∂L/∂ln o / o;
    difference form:  Σ_pairs [∂L/∂μ, ∂L/∂(a, b, c), ∂L/∂o, ∂L/∂rgb, ∂L/∂z],

the blocks of a pair added in block order first. One lane owns one Gaussian's sum, so the
result is deterministic without atomics, and nothing per pair is materialised beyond the rows:
no chained copy, no permutation, no segmented scan (the XLA path the `tiles` backend takes,
pairs.chain_hoisted_rows then backends.backward.per_gaussian_sum: the same values, summed in
another association).

Where the rows are (`RowLayout`, `walked_rows`): only the pairs some pixel of their tile
reached get rows (most pairs of a large scene are behind opaque ones), numbered in emission-slot
order, so a Gaussian's rows are consecutive and summed in slot order. A row per pair at its
emission slot (a zero row for a pair no pixel reached, which adds +0) would give the same
gradients to the bit. The buffer holds render's `row_capacity` rows, or the pair capacity's
(never too few) without one.

`sums` is the Pallas Triton kernel (one program per `LANES` Gaussians, looping to the longest
count among them; per-lane gathers of rows, which Mosaic GPU's Pallas cannot express);
`reference` the same arithmetic in jnp over all Gaussians at once (tests).
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Any

import jax
import jax.numpy as jnp
from jax import lax
from jax.experimental import pallas as pl
from jax.experimental.pallas import triton as plt

from ... import hoist, pairs
from ...binning import TileBins
from ...config import RasterConfig
from ...projection import Projected
from ..interface import tile_last
from . import steps as ks

LANES = 32  # Gaussians per program (one warp): a program loops to its lanes' longest count
COLUMNS = 10  # ∂L/∂(mean2d x, y; conic a, b, c; opacity; rgb r, g, b; depth)


@jax.tree_util.register_dataclass
@dataclasses.dataclass
class RowLayout:
    """Where the backward kernels write pair rows and where `sums` reads them.

    Attributes:
      at: (capacity,) int32 row of pair j (list order, as `TileBins.gauss`); pairs without a
        row (and rows past the buffer: an overflow) point at the spare last row, never read.
      end: (n_tiles,) int32 pairs [tile_start, end) of each tile get rows, the others none.
      first, count: (N,) int32 each Gaussian's rows [first, first + count), in slot order.
      size: rows in the buffer (static), the spare included where there is one.
    """

    at: Any
    end: Any
    first: Any
    count: Any
    size: int = dataclasses.field(metadata=dict(static=True))


def walked_rows(bins: TileBins, stop, row_capacity: int) -> RowLayout:
    """Rows for the walked pairs only (`interface.tile_last` of the forward's `stop`),
    numbered by an exclusive running count over emission slots (a Gaussian's walked slots get
    consecutive rows), `row_capacity` of them and a spare: rows from row_capacity on (more
    walked pairs than rows, which the render's `stats.row_overflow` reports) go to the spare,
    and `count` stops at row_capacity, so nothing is written or read out of bounds (the
    render's stats report the overflow)."""
    capacity, n_tiles = bins.gauss.shape[0], bins.tile_start.shape[0]
    last = tile_last(stop, bins.tile_start, bins.tile_end)
    real = bins.tile < n_tiles
    index = jnp.arange(capacity, dtype=jnp.int32)
    walked = real & (index < last[jnp.where(real, bins.tile, 0)])  # by list index
    # The same flags by slot, without permuting them (a scatter at random slots): a tile's
    # pairs are its slots in ascending order (`TileBins.emitted_tile`), so a slot is walked
    # iff it is at most the slot of its tile's last walked pair (−1 where the tile walked
    # none).
    last_slot = jnp.where(last > bins.tile_start, bins.slot[jnp.maximum(last - 1, 0)], -1)
    tile_of_slot = bins.emitted_tile.astype(jnp.int32)
    emitted = tile_of_slot < n_tiles
    by_slot = emitted & (index <= last_slot[jnp.where(emitted, tile_of_slot, 0)])
    before = jnp.concatenate([jnp.zeros((1,), jnp.int32),
                              jnp.cumsum(by_slot, dtype=jnp.int32)])  # (capacity + 1,)
    # Unwalked pairs (most of them at scale) read entry 0, which stays cached, instead of a
    # random one.
    at = jnp.where(walked, jnp.minimum(before[jnp.where(walked, bins.slot, 0)], row_capacity),
                   row_capacity)
    # first + count <= capacity (`TileBins.first`, `count`: the pairs within the capacity)
    row_first = jnp.minimum(before[bins.first], row_capacity)
    row_end = jnp.minimum(before[bins.first + bins.count], row_capacity)
    # Together: XLA would otherwise compute first and count (which only `sums` reads) after
    # the backward kernel, keeping `before`, `bins.first` and what that is made of live
    # through it, where the memory peaks.
    at, row_first, count = lax.optimization_barrier((at, row_first, row_end - row_first))
    return RowLayout(at=at, end=last, first=row_first, count=count, size=row_capacity + 1)


def rows_of(bins: TileBins, stop, rows: int | None) -> RowLayout:
    """`walked_rows` in `rows` rows, or the pair capacity's where `rows` is None."""
    capacity = bins.gauss.shape[0]
    return walked_rows(bins, stop, capacity if rows is None else rows)


def _pair_terms(vals, tile, fields, tiles_x: int, config: RasterConfig):
    """One pair's contribution to its Gaussian's COLUMNS sums (∂L/∂ln o in the opacity column
    for the hoisted form, divided by o once at the end). vals: the row's GRAD_VALUES values
    (blocks added); tile: its tile index (int32); fields = (μx, μy, a, b, c, lo_x, lo_y)
    (mean2d, the conic, mean2d_lo)."""
    if not config.hoist:
        return list(vals[0:6]) + list(vals[7:11])
    mx, my, a, b, c, lo_x, lo_y = fields
    dx, dy = pairs.origin_offsets((mx, my), (lo_x, lo_y), tile % tiles_x, tile // tiles_x,
                                  config)
    d_a, d_b, d_c, d_dx, d_dy, d_ln_o = hoist.hoist_terms_vjp(vals[0:6], a, b, c, dx, dy)
    return [d_dx, d_dy, d_a, d_b, d_c, d_ln_o + vals[6]] + list(vals[7:11])


def _finish(acc, opacity, config: RasterConfig):
    """The hoisted form's ∂L/∂o = ∂L/∂ln o / o (zero where o = 0: invalid Gaussians)."""
    if not config.hoist:
        return acc
    o_ok = opacity > 0
    d_o = jnp.where(o_ok, acc[5] / jnp.where(o_ok, opacity, 1), 0)
    return acc[:5] + [d_o] + acc[6:]


def _sources(fields):
    """(arrays, spec) where Gaussian g's (μx, μy, a, b, c, lo_x, lo_y, o) (mean2d, the conic,
    mean2d_lo, the opacity) are arrays[i][g, col] for (i, col) in spec (arrays[i][g] where col
    is None): from a `Projected`, or from `pairs.gaussian_table` (which the Mosaic GPU
    backward reads anyway: reading it here keeps the separate (N, 2), (N, 3) and (N,) fields
    from living through the backward kernel)."""
    if isinstance(fields, Projected):
        return ((fields.mean2d, fields.conic, fields.mean2d_lo, fields.opacity),
                ((0, 0), (0, 1), (1, 0), (1, 1), (1, 2), (2, 0), (2, 1), (3, None)))
    return (fields,), tuple((0, i) for i in (0, 1, 2, 3, 4, 10, 11, 5))


def _take(arrays, spec, g):
    """Gaussian(s) g's (μx, μy, a, b, c, lo_x, lo_y, o) (`_sources`; g an index array or a
    full slice)."""
    return [arrays[i][g] if col is None else arrays[i][g, col] for i, col in spec]


def _walk(rows, blocks: int, first, count, fields, opacity, tiles_x: int,
          config: RasterConfig):
    """COLUMNS sums (arrays shaped as `first`) of the Gaussians whose slots are [first,
    first + count): each slot's blocks added in block order, chained (`_pair_terms`), summed in
    slot order; `rows` is the (blocks, capacity, >= n + 1) ref (kernel) or array
    (`reference`), indexed alike: n = GRAD_VALUES values, then the tile in column n; rows of
    `steps.row_width(False)` columns have no ∂L/∂z (n = GRAD_VALUES − 1, the depth's
    sums zero). fields = (μx, μy, a, b, c, lo_x, lo_y), opacity: of those Gaussians."""
    n = ks.GRAD_VALUES if rows.shape[-1] > ks.row_width(False) else ks.GRAD_VALUES - 1

    def body(i, acc):
        live = i < count
        s = jnp.where(live, first + i, 0)  # lanes done read slot 0 (cached) and keep acc
        vals = [functools.reduce(lambda x, y: x + y, [rows[w, s, col] for w in range(blocks)])
                for col in range(n)]
        vals += [jnp.zeros_like(vals[0])] * (ks.GRAD_VALUES - n)
        tile = rows[0, s, n].astype(jnp.int32)
        terms = _pair_terms(vals, tile, fields, tiles_x, config)
        return tuple(jnp.where(live, x + t, x) for x, t in zip(acc, terms))

    zero = jnp.zeros(first.shape, opacity.dtype)
    acc = lax.fori_loop(0, jnp.max(count), body, (zero,) * COLUMNS)
    return _finish(list(acc), opacity, config)


def _kernel(first_ref, count_ref, *refs, spec, config: RasterConfig, tiles_x: int, n: int,
            blocks: int, lanes: int):
    field_refs, rows_ref, out_refs = refs[:-COLUMNS - 1], refs[-COLUMNS - 1], refs[-COLUMNS:]
    # Lanes past the last Gaussian walk the last one again and store the same bits at its
    # index: the outputs need no padding (a padded output's slice is a copy XLA cannot fuse
    # away).
    g = jnp.minimum(pl.program_id(0) * lanes + lax.iota(jnp.int32, lanes), n - 1)
    *fields, opacity = _take(field_refs, spec, g)
    # Read before any store: the first two outputs may be these inputs' buffers (`sums`).
    first, count = (lax.bitcast_convert_type(ref[g], jnp.int32) for ref in (first_ref, count_ref))
    sums_ = _walk(rows_ref, blocks, first, count, fields, opacity, tiles_x, config)
    for out_ref, v in zip(out_refs, sums_):
        out_ref[g] = v


def sums(rows, layout: RowLayout, fields, tiles_x: int, config: RasterConfig,
         interpret: bool, lanes: int = LANES):
    """(N, COLUMNS) per-Gaussian gradients from the backward kernels' rows (blocks,
    layout.size, >= TILE_COLUMN + 1; or `steps.row_width(False)`: without ∂L/∂z, the
    tile in column TILE_COLUMN − 1) (module docstring), by the Triton kernel with
    `lanes` Gaussians per program (a multiple of 32: one warp per 32; each program loops to
    its lanes' longest count, so fewer lanes idle less where counts vary). `fields`: the
    Gaussians' centre (mean2d, mean2d_lo), conic and opacity, a `Projected` or a table
    (`_sources`).

    In float32 the kernel takes `layout.first` and `count` as float32 bits and writes its
    first two columns into their buffers (aliased outputs: a lane reads its Gaussian's first
    and count before it stores), so two of the ten (N,) columns take no memory of their own
    where nothing reads the layout afterwards (at scale the walked-rows backward's memory
    peaks in this kernel); XLA copies them first where something does."""
    if lanes % 32:
        raise ValueError(f"lanes: expected a multiple of 32, got {lanes}")
    arrays, spec = _sources(fields)
    n, blocks = arrays[0].shape[0], rows.shape[0]
    programs = pl.cdiv(n, lanes)
    kernel = functools.partial(_kernel, spec=spec, config=config, tiles_x=tiles_x, n=n,
                               blocks=blocks, lanes=lanes)
    dt = rows.dtype
    aliased = jnp.dtype(dt).itemsize == jnp.dtype(layout.first.dtype).itemsize
    first, count = ((lax.bitcast_convert_type(x, dt) for x in (layout.first, layout.count))
                    if aliased else (layout.first, layout.count))
    columns = pl.pallas_call(
        kernel, out_shape=(jax.ShapeDtypeStruct((n,), dt),) * COLUMNS,
        input_output_aliases={0: 0, 1: 1} if aliased else {},
        grid=(programs,), interpret=interpret,
        compiler_params=plt.CompilerParams(num_warps=lanes // 32, num_stages=1),
        name="gaussian_grads",
    )(first, count, *arrays, rows)
    return jnp.stack(columns, -1)  # its consumers' column slices take the columns themselves


def reference(rows, layout: RowLayout, fields, tiles_x: int, config: RasterConfig):
    """`sums` in jnp: every Gaussian at once, the same walk over its slots and the same
    arithmetic (`_walk`; tests compare the kernel with it in interpret mode)."""
    *values, opacity = _take(*_sources(fields), slice(None))
    return jnp.stack(_walk(rows, rows.shape[0], layout.first, layout.count, values, opacity,
                           tiles_x, config), -1)
