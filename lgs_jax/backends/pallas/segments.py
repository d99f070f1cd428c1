"""The Mosaic GPU backward's blocks: which pairs of which tile each one walks.

With `KernelConfig.backward_segment` None a block walks its tile's whole list, from the tile's
last stop pair down, as the forward does, and the longest walk sets the kernel's length. With a
segment length L (1024 by default), a tile's walked pairs, [start, last) (`RowLayout.end`: the
pairs that have rows), are cut at start + L, start + 2L, ... into segments, each its own
block(s).

A segment [lo, hi) that is not its tile's last enters the walk at hi with the carry the walk
would have there (lgs_jax.backends.backward):

    T_hi       the transmittance before pair hi, and
    S_hi       Σ over the pairs k >= hi a pixel blended of rgb_k·w_k (and z_k·w_k)
               = C − C_hi (D − D_hi),

where C_hi, D_hi and T_hi are the forward's state before pair hi, which the Local-GS Mosaic GPU
forward stores at every pair start + m·L of its walk (m >= 1: `checkpoints`), at index
`base[tile] + m − 1` of (n_checkpoints, 256) buffers; `entries` turns them into (T_hi, S_hi)
after the forward, and `enter` reads them in the kernel. A pixel that stopped at or before hi
enters with (T, 0) instead, which is exact for it (T and C stay constant after a pixel's stop)
and needs no checkpoint: its forward block may have exited before hi without storing one.

With walked rows (a row capacity R, render's `row_capacity`) the backward needs only the
checkpoints inside the walked pairs, (last − start − 1) // L per tile, at most R // L in all
(fewer walked pairs than rows: the stats' `row_overflow` otherwise). The forward, which learns a
tile's walked length only as it walks, still stores them at the list-length indices, and
`entries` gathers the needed ones into R // L + 1 rows right after it (`walked_checkpoints`),
so the full buffer (capacity // L rows) is not live during the backward.

Determinism: segments are disjoint, so each pair row still has one writer per block of pixels.
"""

from __future__ import annotations

import jax.numpy as jnp
from jax import lax

from ...binning import TileBins, segment_of_slot
from . import order as block_order

COLUMNS = 4  # a segment's (tile, lo, hi, checkpoint index or −1)


def _checkpoints_within(bins: TileBins, last, segment: int):
    """(n_tiles,) checkpoints inside each tile's pairs [tile_start, last): its walked pairs
    (`RowLayout.end`), or with last = tile_end its whole list (`checkpoints`)."""
    return jnp.maximum(last - bins.tile_start - 1, 0) // segment


def checkpoints(bins: TileBins, segment: int):
    """((n_tiles,) int32 base index of each tile's checkpoints, number of checkpoint rows): tile
    t stores checkpoints m = 1 .. (len_t − 1) // segment (pairs start + m·segment inside its
    list), rows base[t] .. base[t] + count − 1; at most capacity // segment in all."""
    per_tile = _checkpoints_within(bins, bins.tile_end, segment)
    return jnp.cumsum(per_tile) - per_tile, bins.gauss.shape[0] // segment + 1


def walked_checkpoints(bins: TileBins, last, segment: int, rows: int):
    """((n_tiles,) int32 base index of each tile's checkpoints in the compacted buffer, its
    rows): tile t keeps checkpoints m = 1 .. (last_t − start_t − 1) // segment, those of its
    walked pairs [tile_start, last) (`RowLayout.end`), in rows // segment + 1 rows for a row
    capacity of `rows`. Where more pairs were walked than `rows` (an overflow, reported) the
    last tiles' indices run past them; `split` clips them."""
    need = _checkpoints_within(bins, last, segment)
    return jnp.cumsum(need) - need, rows // segment + 1


def _compacted_rows(bins: TileBins, last, segment: int, rows: int):
    """(tile, source) of each of `walked_checkpoints`' rows: the tile it belongs to and the
    forward's checkpoint row (`checkpoints`) it takes (row 0 for rows past the needed ones):
    row base'[t] + m − 1 from row base[t] + m − 1 for each needed checkpoint m of tile t."""
    full_base, _ = checkpoints(bins, segment)
    base, n = walked_checkpoints(bins, last, segment, rows)
    need = _checkpoints_within(bins, last, segment)
    tile = segment_of_slot(base, need, n)
    m = jnp.arange(n, dtype=jnp.int32) - base[tile]
    return tile, jnp.where(m < need[tile], full_base[tile] + m, 0)


def entries(final_at, saved, bins: TileBins, segment: int, last=None, rows: int | None = None):
    """The carries a segment enters with (module docstring), per checkpoint row: (C − C_hi for
    r, g, b; T_hi; D − D_hi), from the forward's final r, g, b, D at the pixels of given tiles
    (`final_at(tile)`: four tile.shape + (256,) arrays, gathered from per-tile planes or from
    the colour image) and its five checkpoint buffers (C_hi for r, g, b; T_hi; D_hi:
    `checkpoints`), in their rows, or with `last` (`RowLayout.end`) and a row capacity `rows`
    (walked rows) in `walked_checkpoints`' (a gather). Subtracted here once, so the final
    planes need not live through the backward kernel (four image-sized planes); the same float
    subtraction the kernel made, so the same bits."""
    if last is None:
        base, rows = checkpoints(bins, segment)
        tile = segment_of_slot(base, _checkpoints_within(bins, bins.tile_end, segment), rows)
    else:
        tile, source = _compacted_rows(bins, last, segment, rows)
        saved = tuple(x[source] for x in saved)
    (f_r, f_g, f_b, f_d), (c_r, c_g, c_b, t_hi, d_hi) = final_at(tile), saved
    return f_r - c_r, f_g - c_g, f_b - c_b, t_hi, f_d - d_hi


def whole_tiles(order, bins: TileBins, last):
    """(n_tiles, COLUMNS): one segment per tile in `order`, its walked pairs [tile_start, last),
    no checkpoint."""
    return jnp.stack([order, bins.tile_start[order], last[order],
                      jnp.full_like(order, -1)], -1)


def split(bins: TileBins, last, segment: int, rows: int | None = None):
    """(n_tiles + capacity // segment, COLUMNS) segments of `segment` pairs of each tile's walked
    pairs [tile_start, last) (`RowLayout.end`; module docstring), longest first
    (`order.longest_first`); rows past the real segments are empty (lo = hi), as is the one
    segment of a tile that walked nothing. Checkpoint indices into the forward's buffers
    (`checkpoints`) or, with a row capacity `rows` (walked rows), into `entries`'
    (`walked_checkpoints`; clipped to its rows)."""
    n_tiles, capacity = bins.tile_start.shape[0], bins.gauss.shape[0]
    start = bins.tile_start
    count = jnp.maximum((last - start + segment - 1) // segment, 1)
    first = jnp.cumsum(count) - count
    size = n_tiles + capacity // segment
    tile = jnp.minimum(segment_of_slot(first, count, size), n_tiles - 1)
    m = jnp.arange(size, dtype=jnp.int32) - first[tile]
    real = m < count[tile]
    top = m == count[tile] - 1
    lo = jnp.where(real, start[tile] + m * segment, 0)
    hi = jnp.where(top, last[tile], lo + segment)
    hi = jnp.where(real, hi, 0)
    if rows is not None:
        base, n = walked_checkpoints(bins, last, segment, rows)
        index = jnp.where(real & ~top, jnp.minimum(base[tile] + m, n - 1), -1)
    else:
        base, _ = checkpoints(bins, segment)
        index = jnp.where(real & ~top, base[tile] + m, -1)
    first_longest = block_order.longest_first(hi - lo)
    return jnp.stack([tile, lo, hi, index], -1)[first_longest]


def enter(trans, stop_at, hi, entry_refs, check, inside, half):
    """The carry (T, S_r, S_g, S_b, S_Z) with which a block of the Mosaic GPU backward kernel
    (lgs_jax.backends.pallas.mosaic_backward) enters its segment [lo, hi), for its pixels
    (`half`, their columns of a tile's row; final `trans`, `stop_at`): at the tile's end
    (T, 0, 0, 0, 0);
    inside the block's walk, from checkpoint `check` (`entries`' rows `entry_refs`: the
    forward's T there and C − C_hi, D − D_hi; without D − D_hi where the loss does not reach
    the depth, S_Z enters as 0, which the walk then carries unread). Only for a pixel that
    blends pair hi (its stop pair is past hi), whose forward block walked past hi and so stored
    the checkpoint. A pixel that stopped at or before hi is in its final state there, so it
    enters with (T, 0, 0, 0, 0), exactly what the checkpoint would hold; its forward block may
    have stopped before hi without storing it (half-tile forward blocks under a whole-tile
    backward block, the defaults). The test must be stop > hi, not stop > lo: a pixel with
    lo < stop <= hi would read a checkpoint its block never wrote."""
    zero = jnp.zeros_like(trans)
    if not entry_refs:
        return trans, zero, zero, zero, zero
    s_r, s_g, s_b, t_hi, *s_d = entry_refs  # no D − D_hi where the loss does not reach D

    def from_checkpoint():
        c = jnp.maximum(check, 0)
        reached = stop_at > hi
        sums = [jnp.where(reached, ref[c, half], zero) for ref in (s_r, s_g, s_b)]
        s_z = jnp.where(reached, s_d[0][c, half], zero) if s_d else zero
        return jnp.where(reached, t_hi[c, half], trans), *sums, s_z

    return lax.cond(inside & (check >= 0), from_checkpoint,
                    lambda: (trans, zero, zero, zero, zero))
