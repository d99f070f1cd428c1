"""Exact tile binning: which 16x16 tiles can a Gaussian's alpha test pass in?

A Gaussian passes the alpha test only inside the ellipse q(d) = dᵀ Q d <= τ, τ = 2 ln(255·o)
(docs/conventions.md, "What binning may and may not do"), where d = mean2d − pixel centre and Q
is the conic. The test itself runs in floating point, so a pixel just outside that ellipse can
pass. This module bounds that rounding and pads the box so that the tile rectangle holds
**every** pixel whose rounded alpha test passes; nothing is truncated (no 3σ radius, no 0.95
shrink).

Rounding bound (u = unit roundoff of the dtype, 2^-24 for float32). The difference form
p̂ = −½(a·dx² + c·dy²) − b·dx·dy evaluated in floating point obeys |p̂ − p| <= γ·S with
S = ½(a·dx² + c·dy²) + |b·dx·dy| <= (a + c)·|d|² <= K·q, K = (a + c)²/det(Q) >= 4 (since
|b| <= √(ac) <= (a + c)/2 and |d|² <= q/λ_min(Q) <= q·(a + c)/det), and γ = 16u covers the
subtraction, products, sums and the rounding of Q's determinant. The test passes only if
p̂ >= −τ/2 − δ (δ = 64u absorbs exp, the product with o and the 1/255 constant), hence
q·(1 − 2γK) <= τ + 2δ, i.e. q <= τ_pad with

    τ_pad = (τ + 2δ) / (1 − 2γK).

For 2γK >= 1/2 (float32: K >~ 5e5, needles whose float32 conic cannot bound them) the region is
treated as unbounded and the Gaussian is binned to every tile: slow but exact, and counted in
`RenderStats.n_unbounded`. The ellipse q <= τ_pad has the exact half-extents
rx = √(τ_pad·c/det), ry = √(τ_pad·a/det); pixel column j is inside iff |j + 0.5 − mx| <= rx.

The centre is μ = mean2d + mean2d_lo (lgs_jax.projection) and the test's offset
d = (mean2d − p) + mean2d_lo errs by at most 2u relative to d (one rounding where mean2d − p is
exact, Sterbenz's lemma; otherwise |mean2d − p| >= |mean2d|/2 >= |mean2d_lo|/u), within γ. The
boxes are centred at mx = mean2d, |mean2d_lo| <= u·|mx| from μ, which their slack
8u·(|mx| + r + 1) holds besides its own rounding (as the strip masks' slack does,
lgs_jax.warp_masks).
"""

from __future__ import annotations

import dataclasses
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
from jax import lax

from .layout import TILE, tile_grid
from .projection import Projected, depth_order

MAX_PAIRS = 2**31 - 1  # pair indices are int32
SORT16_TILES = 2**16 - 1  # the tile sort takes uint16 keys up to this many tiles (+1 padding key)


@jax.tree_util.register_dataclass
@dataclasses.dataclass
class PaddedEllipse:
    """Per-Gaussian ellipse q(d) <= tau_pad that holds every pixel whose rounded alpha test (in
    the difference form) can pass; `det_lo` is a lower bound of det(Q) > 0 (where bounded)."""

    tau: Any  # 2 ln(255·o), the exact threshold
    tau_pad: Any
    det_lo: Any
    unbounded: Any  # valid Gaussians whose rounding cannot be bounded: bin to the whole image


def padded_ellipse(p: Projected, gamma_ulps: float = 16.0) -> PaddedEllipse:
    """τ_pad = (τ + 2δ) / (1 − 2γK) of the module docstring, with its unbounded cases."""
    return ellipse_bound(p.conic[:, 0], p.conic[:, 1], p.conic[:, 2], p.opacity, p.valid,
                         gamma_ulps)


def ellipse_bound(a, b, c, opacity, valid=None, gamma_ulps: float = 16.0) -> PaddedEllipse:
    """`padded_ellipse` on columns: conic (a, b, c) and opacity of Gaussians (`valid`: None
    where every one is, as for the Gaussians of tile pairs). The pair kernels' staging computes
    it on its lane vectors where a stored column per field would live through the whole
    gradient (lgs_jax.pairs.strip_mask_columns)."""
    u = jnp.finfo(a.dtype).eps / 2
    tau = 2.0 * jnp.log(jnp.maximum(255.0 * opacity, 1.0))
    tau_slack = tau * (1 + 4 * u) + 128 * u  # rounding of tau itself and the 2δ slack
    det = a * c - b * b
    det_lo = det - 4 * u * (a * c + b * b)
    trace = a + c
    k = trace * trace / jnp.where(det_lo > 0, det_lo, 1.0)
    shrink = 1.0 - 2.0 * gamma_ulps * u * k
    unbounded = (det_lo <= 0) | (shrink < 0.5)
    if valid is not None:
        unbounded = valid & unbounded
    return PaddedEllipse(tau=tau, tau_pad=tau_slack / jnp.where(unbounded, 1.0, shrink),
                         det_lo=jnp.where(unbounded | (det_lo <= 0), 1.0, det_lo),
                         unbounded=unbounded)


def pixel_box(p: Projected, width: int, height: int):
    """Inclusive pixel ranges that hold every pixel where the rounded alpha test can pass.

    Returns (x0, x1, y0, y1, unbounded), int32 pixel indices clipped to the image (empty when
    x0 > x1 or y0 > y1; invalid Gaussians are empty), and a bool for Gaussians whose rounding
    bound failed (binned to the whole image).
    """
    u = jnp.finfo(p.mean2d.dtype).eps / 2
    e = padded_ellipse(p)
    unbounded = e.unbounded
    rx = jnp.sqrt(e.tau_pad * p.conic[:, 2] / e.det_lo) * (1 + 8 * u)
    ry = jnp.sqrt(e.tau_pad * p.conic[:, 0] / e.det_lo) * (1 + 8 * u)
    mx, my = p.mean2d[:, 0], p.mean2d[:, 1]

    def axis_range(m, r, n):
        slack = 8 * u * (jnp.abs(m) + r + 1.0)
        lo = jnp.clip(m - r - 0.5 - slack, -1.0, n)
        hi = jnp.clip(m + r - 0.5 + slack, -1.0, n)
        i0 = jnp.maximum(jnp.ceil(lo), 0).astype(jnp.int32)
        i1 = jnp.minimum(jnp.floor(hi), n - 1).astype(jnp.int32)
        return i0, i1

    x0, x1 = axis_range(mx, rx, width)
    y0, y1 = axis_range(my, ry, height)
    x0 = jnp.where(unbounded, 0, x0)
    x1 = jnp.where(unbounded, width - 1, x1)
    y0 = jnp.where(unbounded, 0, y0)
    y1 = jnp.where(unbounded, height - 1, y1)
    empty = ~p.valid
    x1 = jnp.where(empty, -1, x1)
    y1 = jnp.where(empty, -1, y1)
    return x0, x1, y0, y1, unbounded


def tile_rects(p: Projected, width: int, height: int):
    """Tile rectangles (tx0, ty0, nx, ny) per Gaussian, nx = ny = 0 when it touches no pixel."""
    x0, x1, y0, y1, unbounded = pixel_box(p, width, height)
    nonempty = (x0 <= x1) & (y0 <= y1)
    tx0, ty0 = x0 // TILE, y0 // TILE
    nx = jnp.where(nonempty, x1 // TILE - tx0 + 1, 0)
    ny = jnp.where(nonempty, y1 // TILE - ty0 + 1, 0)
    return tx0, ty0, nx, ny, unbounded


@jax.tree_util.register_dataclass
@dataclasses.dataclass
class TileBins:
    """Tile–Gaussian pairs sorted by (tile, depth, index), with per-tile ranges.

    Attributes:
      gauss: (capacity,) int32 Gaussian index of each pair (pairs past `tile_end[-1]` are padding).
      tile: (capacity,) int32 tile index of each pair (row-major; n_tiles for padding).
      slot: (capacity,) int32 emission slot of each pair (`emit_pairs`: Gaussian-major, in depth
        order): a permutation of arange(capacity), the tile sort's. A Gaussian's pairs fill
        consecutive emission slots, so per-pair values stored at their slot (the Pallas
        backward kernels) or gathered with the inverse permutation
        (backends.backward.per_gaussian_sum) are grouped per Gaussian without a second sort.
      tile_start, tile_end: (n_tiles,) int32 half-open ranges of each tile's pairs in `gauss`.
      emitted_tile: (capacity,) the tile of each emission slot, the tile sort's key
        (`sort_key`: uint16 up to `SORT16_TILES` tiles, else int32). A tile's pairs are its
        slots in ascending order (the sort is stable), so whether a pair is among its tile's
        first m follows from its slot alone (backends.pallas.gaussian_grads.walked_rows).
      first, count: (N,) int32 per Gaussian: its pairs fill emission slots [first, first + count)
        (count = 0 for a Gaussian with no pair within the capacity), in ascending tile order.
        The Pallas backward sums each Gaussian's pair rows there (backends.pallas.gaussian_grads).
      pairs_required: int32 number of pairs the scene needs (saturates at 2^31 − 1).
      overflow: bool, pairs_required > capacity: the tail (farthest Gaussians) was dropped.
      n_unbounded: int32 Gaussians binned to every tile because rounding could not bound them.
    """

    gauss: Any
    tile: Any
    slot: Any
    tile_start: Any
    tile_end: Any
    emitted_tile: Any
    first: Any
    count: Any
    pairs_required: Any
    overflow: Any
    n_unbounded: Any


def total_pairs(counts):
    """Σ counts, exact below 2^31 and saturated at 2^31 − 1 above.

    Per-Gaussian counts are < 2^24 (tiles per image are validated), so the total is estimated in
    float32 first: an int32 sum is exact whenever that estimate is below 2^31·(1 − 2^-10), a
    margin far above float32's summation error for any N that fits in memory.
    """
    estimate = jnp.sum(counts.astype(jnp.float32))
    fits = estimate < 2.0**31 * (1 - 2.0**-10)
    return jnp.where(fits, jnp.sum(counts), MAX_PAIRS).astype(jnp.int32)


def count_pairs(p: Projected, width: int, height: int):
    """Number of tile–Gaussian pairs the scene needs (see `total_pairs`)."""
    _, _, nx, ny, _ = tile_rects(p, width, height)
    return total_pairs(nx * ny)


def tile_ranges(tile, n_tiles: int):
    """Half-open ranges [start, end) of each tile's pairs in `tile`, sorted ascending with padding
    pairs (tile == n_tiles) last.

    The first pair of each distinct tile stores its position (one writer per slot: a plain,
    deterministic store); a reverse running minimum gives empty tiles the next tile's start.
    O(pairs), no per-tile binary search (which costs a kernel launch per bisection step on GPUs).
    """
    cap = tile.shape[0]
    pos = jnp.arange(cap, dtype=jnp.int32)
    first = jnp.concatenate([jnp.ones((1,), bool), tile[1:] != tile[:-1]])
    firsts = jnp.full((n_tiles + 1,), cap, jnp.int32).at[jnp.where(first, tile, n_tiles + 1)].set(
        pos, mode="drop", unique_indices=True)
    firsts = lax.cummin(firsts, axis=0, reverse=True)
    return firsts[:n_tiles], firsts[1:]


def segment_of_slot(starts, counts, capacity: int):
    """For every slot s < capacity, the segment k whose range [starts[k], starts[k] + counts[k])
    holds it, where the ranges tile [0, Σ counts) in order of k (an exclusive prefix sum);
    slots past the total get the last segment, n − 1.

    Each non-empty segment stores its index at its first slot (distinct slots: a plain,
    deterministic store) and a running maximum fills the slots between: O(slots), where
    `searchsorted(ends, slots)` reads log2(n) scattered ends per slot."""
    n = counts.shape[0]
    first = jnp.where((counts > 0) & (starts >= 0) & (starts < capacity), starts, capacity)
    marks = jnp.zeros((capacity + 1,), jnp.int32).at[first].set(
        jnp.arange(n, dtype=jnp.int32), mode="drop", unique_indices=True)
    k = lax.cummax(marks[:capacity], axis=0)
    total = starts[-1] + counts[-1]
    return jnp.where(jnp.arange(capacity, dtype=jnp.int32) < total, k, n - 1)


@jax.tree_util.register_dataclass
@dataclasses.dataclass
class Emission:
    """The pairs `emit_pairs` makes, in emission order (Gaussian-major, depth order).

    Attributes:
      tile, gauss: (capacity,) int32 tile and Gaussian of each slot (tile = n_tiles: padding).
      total: int32 pairs the scene needs (`total_pairs`).
      n_unbounded: int32 Gaussians binned to every tile.
      first, count: (N,) int32 per Gaussian, as `TileBins.first` and `TileBins.count`.
    """

    tile: Any
    gauss: Any
    total: Any
    n_unbounded: Any
    first: Any
    count: Any


class SlotPlan(NamedTuple):
    """What `emit_pairs` knows per Gaussian before it fills the slots (`expand_slots`).

    Per depth rank k: order[k] (the k-th Gaussian of `depth_order`), start[k] (its first slot:
    an exclusive prefix sum of the tile counts, 2^31 − 1 from where it passes that: so
    non-decreasing) and kept[k] (its slots within the capacity; 0 for a Gaussian with no tile
    or starting past the capacity); per Gaussian index, rect =
    (tx0, ty0, nx): its tile rectangle's corner and width (nx >= 1). Slot start[k] + i,
    i < kept[k], holds Gaussian order[k] and tile (ty0 + i // nx)·tiles_x + tx0 + i % nx; slots
    from `total` on are padding (tile n_tiles, Gaussian order[-1]).
    """

    order: Any
    start: Any
    kept: Any
    rect: Any
    total: Any
    tiles_x: int
    n_tiles: int
    capacity: int


def expand_slots(plan: SlotPlan):
    """(tile, gauss) of every slot (`SlotPlan`) in XLA: `segment_of_slot` finds each slot's
    depth rank (no scatter-add, so deterministic on GPUs), then a row gather per slot of
    (start, Gaussian) and one of the Gaussian's rectangle (one five-column row per slot, the
    rectangles gathered in depth order first, was slower; so was a Pallas Triton kernel writing
    each Gaussian's run, as gsplat's `isect_tiles`: docs/design-notes.md)."""
    k = segment_of_slot(plan.start, plan.kept, plan.capacity)
    per_k = jnp.stack([plan.start, plan.order], -1)[k]  # one row gather per slot
    g = per_k[:, 1]
    rect = plan.rect[g]
    slot = jnp.arange(plan.capacity, dtype=jnp.int32)
    local = slot - per_k[:, 0]
    tile = (rect[:, 1] + local // rect[:, 2]) * plan.tiles_x + rect[:, 0] + local % rect[:, 2]
    return jnp.where(slot < plan.total, tile, plan.n_tiles), g


def slot_plan(p: Projected, width: int, height: int, capacity: int):
    """(plan, inside, unbounded): the `SlotPlan` of `emit_pairs` (Gaussian k of the depth order
    owns slots [start[k], start[k] + kept[k])), whether rank k's run starts within the capacity
    (by depth rank), and `tile_rects`' unbounded flags (by Gaussian index)."""
    if not 0 < capacity <= MAX_PAIRS:
        raise ValueError(f"capacity: must be in [1, 2^31 - 1], got {capacity}")
    tiles_x, tiles_y = tile_grid(width, height)
    tx0, ty0, nx, ny, unbounded = tile_rects(p, width, height)
    # The counts are stored before the depth-order gather: fused into it, XLA recomputed each
    # Gaussian's rectangle at its depth rank, six scattered reads per Gaussian.
    counts = lax.optimization_barrier(nx * ny)
    order = depth_order(p)
    counts_sorted = counts[order]
    starts = jnp.cumsum(counts_sorted) - counts_sorted  # exact while the sums fit int32
    # From the first rank past 2^31 − 1 on (in int32 the first such start wraps negative, the
    # counts being < 2^24; later ones may wrap back into range) every start becomes 2^31 − 1:
    # non-decreasing and past every capacity, by one reduction instead of a running maximum.
    rank = jnp.arange(order.shape[0], dtype=jnp.int32)
    wrapped = jnp.min(jnp.where(starts < 0, rank, order.shape[0]))
    starts = jnp.where(rank < wrapped, jnp.minimum(starts, MAX_PAIRS), MAX_PAIRS)
    inside = (counts_sorted > 0) & (starts >= 0) & (starts < capacity)
    kept = jnp.where(inside, jnp.minimum(counts_sorted, capacity - starts), 0)
    rect = jnp.stack([tx0, ty0, jnp.maximum(nx, 1)], -1)
    plan = SlotPlan(order=order, start=starts, kept=kept, rect=rect, total=total_pairs(counts),
                    tiles_x=tiles_x, n_tiles=tiles_x * tiles_y, capacity=capacity)
    return plan, inside, unbounded


def emit_pairs(p: Projected, width: int, height: int, capacity: int) -> Emission:
    """Tile–Gaussian pairs in (depth, index) order.

    Gaussian k of the depth order owns slots [starts[k], starts[k] + counts[k]) (an exclusive
    prefix sum of its tile counts); slot s is local tile s − starts[k] of its rectangle, row by
    row; slots past the total get tile = n_tiles (padding, sorts last): `expand_slots` fills
    them from the per-Gaussian `SlotPlan` (`slot_plan`). Each Gaussian's (first slot, count
    within the capacity) is stored at its index (a permutation: one writer per element).
    """
    plan, inside, unbounded = slot_plan(p, width, height, capacity)
    tile, g = expand_slots(plan)
    first_count = jnp.zeros((plan.order.shape[0], 2), jnp.int32).at[plan.order].set(
        jnp.stack([jnp.where(inside, plan.start, 0), plan.kept], -1), unique_indices=True)
    return Emission(tile=tile, gauss=g, total=plan.total,
                    n_unbounded=jnp.sum(unbounded, dtype=jnp.int32),
                    first=first_count[:, 0], count=first_count[:, 1])


def sort_key(tile, n_tiles: int):
    """The tile sort's keys: `tile` as uint16 where the tiles and the padding value n_tiles fit
    (`sort_pairs`), else `tile` itself."""
    return tile.astype(jnp.uint16) if n_tiles <= SORT16_TILES else tile


def sort_pairs(tile, gauss, n_tiles: int):
    """Stable sort of the emitted pairs by tile (each tile's list stays in (depth, index) order)
    and the tiles' ranges: (tile, gauss, slot, tile_start, tile_end), where slot is each sorted
    pair's emission slot (the sort's permutation: the payload sorted with the tiles is
    arange(capacity)) and gauss = gauss_emitted[slot].

    Where the tiles and the padding value n_tiles fit 16 bits (up to 65535 tiles: 4K has
    32400), the keys are sorted as uint16: the same permutation (a stable sort of the same
    order), and XLA's GPU radix sort (CUB) on 16-bit keys is faster than on int32 keys. Signed
    int16 keys are not rewritten to CUB and are much slower. The payload must stay the iota
    (then `gauss[slot]`, a gather): XLA lowers a stable two-operand sort to CUB only when one
    operand is an iota (its StableSortExpander makes that the tie-break, a comparator XLA's
    SortRewriter recognises); sorting the Gaussians along instead would get an iota added,
    three operands, and a comparison sort (xla/service/gpu/transforms/sort_rewriter.cc).
    """
    slot = jnp.arange(tile.shape[0], dtype=jnp.int32)
    key, slot = lax.sort((sort_key(tile, n_tiles), slot), num_keys=1, is_stable=True)
    tile = key.astype(jnp.int32)
    return (tile, gauss[slot], slot) + tile_ranges(tile, n_tiles)


def before_emission(p: Projected, values):
    """(p, values) with `values` (any pytree, e.g. a backend's `prepare`d inputs) ordered before
    the pair emission of `bin_gaussians(p, ...)`: an optimization barrier with the validity
    flags, which every per-Gaussian column of the emission reads. XLA would otherwise compute
    the emission's columns (depth keys, tile rectangles and counts) first and keep them live
    while `values` are computed, next to their own inputs: at scale, the peak of the
    temporaries. The same values."""
    valid, values = lax.optimization_barrier((p.valid, values))
    return dataclasses.replace(p, valid=valid), values


def bin_gaussians(p: Projected, width: int, height: int, capacity: int) -> TileBins:
    """`emit_pairs` then `sort_pairs`: every tile's pairs, sorted by (depth, index) because the
    pairs are emitted in depth order and the tile sort is stable."""
    tiles_x, tiles_y = tile_grid(width, height)
    e = emit_pairs(p, width, height, capacity)
    tile, gauss, slot, start, end = sort_pairs(e.tile, e.gauss, tiles_x * tiles_y)
    return TileBins(gauss=gauss, tile=tile, slot=slot, tile_start=start, tile_end=end,
                    emitted_tile=sort_key(e.tile, tiles_x * tiles_y),
                    first=e.first, count=e.count, pairs_required=e.total,
                    overflow=e.total > capacity, n_unbounded=e.n_unbounded)
