"""The exchange of Gaussian parallelism: projected records sent to the devices whose image band
they reach.

Bands. The image's tiles_y rows of 16x16 tiles are split into D bands of R = ceil(tiles_y / D)
tile rows: device d owns tile rows [d·R, (d + 1)·R) (the last bands may be short or empty) and
composites the pixels of those rows.

Which bands a Gaussian reaches: those its tile rectangle (`binning.tile_rects`, the rectangle
the pair emission bins it to) overlaps. The rectangle is a conservative box: it holds every
pixel where the Gaussian's rounded alpha test can pass. So a Gaussian not sent to a band passes
the alpha test at none of its pixels, and leaving it out of that band's tile lists changes no
bit of them, even where another compilation of the same rectangle (a fusion contracting a
multiply-add its own way) would round an edge into the band.

Records. A projected Gaussian travels as one row of `record_width(C)` numbers of its dtype:
mean2d (2), mean2d_lo (2), conic (3), depth, opacity, colour (C), the fields
`render.composite_projected` reads. The validity flag is not sent: a valid Gaussian has
opacity >= 1/255 and every other row opacity 0 (`projection.Projected`), so valid = opacity > 0
at the destination. `cov2d` is not sent either (the compositing never reads it; the
destination holds the unit placeholder).

Packing. Per destination d, the records of the Gaussians reaching band d fill `capacity` slots
in ascending local index (the k-th slot holds the k-th such Gaussian, found by a binary search
of the running count: no scatter), the rest padding (opacity 0: culled). A count above the
capacity is reported (`counts`), never dropped silently: the caller grows the capacity.
Concatenated in source order at the destination, the received rows of valid Gaussians are in
ascending global index (source s holds global rows [s·n, (s + 1)·n)), the tie-break order of
`projection.depth_order`, so each tile's list is the one-device list.

The gradient travels back the same way: `lax.all_to_all`'s transpose is an all-to-all, and the
packing's gathers (one per destination, unique in-bounds indices) transpose to stores; a
source's cotangent of a Gaussian is the sum over destinations, in destination order, of what
each sent back.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from .. import binning
from ..layout import TILE
from ..projection import Projected

RECORD_FIELDS = (("mean2d", 2), ("mean2d_lo", 2), ("conic", 3), ("depth", 1), ("opacity", 1))
"""Fields of an exchanged record before the colour, and their widths."""


def record_width(channels: int = 3) -> int:
    """Numbers per exchanged record: 9 + the colour's channels (12 for RGB)."""
    return sum(w for _, w in RECORD_FIELDS) + channels


def band_rows(height: int, devices: int) -> int:
    """R, the tile rows of each of the `devices` bands of an image `height` pixels high."""
    tiles_y = -(-height // TILE)
    return -(-tiles_y // devices)


def band_masks(p: Projected, width: int, height: int, devices: int):
    """(devices, n) bool: which bands each projected Gaussian's tile rectangle overlaps (none
    for a Gaussian without tiles: invalid, transparent or off screen)."""
    _, ty0, nx, ny, _ = binning.tile_rects(p, width, height)
    r = band_rows(height, devices)
    lo = jnp.arange(devices, dtype=jnp.int32)[:, None] * r
    return (nx * ny > 0)[None] & (ty0[None] < lo + r) & (ty0[None] + ny[None] > lo)


def band_pairs(p: Projected, masks, width: int, height: int):
    """(devices,) int32: the tile–Gaussian pairs each destination's render of the records sent
    to it needs from this source (each Gaussian's whole rectangle: the destination bins the full
    image grid), saturating as `binning.total_pairs`."""
    _, _, nx, ny, _ = binning.tile_rects(p, width, height)
    return jax.vmap(lambda m: binning.total_pairs(jnp.where(m, nx * ny, 0)))(masks)


def to_records(p: Projected):
    """(n, record_width(C)) rows of the exchanged fields (module docstring)."""
    cols = [getattr(p, name).reshape(p.depth.shape[0], -1) for name, _ in RECORD_FIELDS]
    return jnp.concatenate(cols + [p.rgb], axis=1)


def from_records(rows) -> Projected:
    """The `Projected` a destination composites from received record rows (valid where the
    opacity is positive; padding and culled rows hold the projection's placeholders)."""
    mean2d, mean2d_lo, conic, depth, opacity, rgb = (rows[:, 0:2], rows[:, 2:4], rows[:, 4:7],
                                                     rows[:, 7], rows[:, 8], rows[:, 9:])
    valid = opacity > 0
    unit = jnp.asarray([1.0, 0.0, 1.0], rows.dtype)
    conic = jnp.where(valid[:, None], conic, unit)
    return Projected(mean2d=mean2d, mean2d_lo=mean2d_lo,
                     cov2d=jnp.broadcast_to(unit, conic.shape), conic=conic, depth=depth,
                     opacity=opacity, rgb=rgb, valid=valid, invalid=jnp.zeros_like(valid))


def packed_indices(mask, capacity: int):
    """(capacity,) int32: the local indices of the first `capacity` set entries of `mask` in
    ascending order, then n + slot for the empty slots (out of bounds, so distinct and sorted),
    and the number of set entries (int32, may exceed the capacity)."""
    n = mask.shape[0]
    running = jnp.cumsum(mask, dtype=jnp.int32)
    slot = jnp.arange(capacity, dtype=jnp.int32)
    idx = jnp.searchsorted(running, slot + 1, side="left").astype(jnp.int32)
    count = running[-1] if n else jnp.int32(0)
    return jnp.where(slot < count, idx, n + slot), count


def pack(records, masks, capacity: int):
    """((devices, capacity, width) send buffer, (devices,) int32 counts): per destination, the
    records of the Gaussians its mask selects (`packed_indices`), padding rows zero. One gather
    per destination, so the transpose sums a Gaussian's cotangents over destinations in a fixed
    order (one batched gather would transpose to a scatter-add with colliding indices)."""
    bufs, counts = [], []
    for d in range(masks.shape[0]):
        idx, count = packed_indices(masks[d], capacity)
        bufs.append(records.at[idx].get(mode="fill", fill_value=0, unique_indices=True,
                                        indices_are_sorted=True))
        counts.append(count)
    return jnp.stack(bufs), jnp.stack(counts)


def exchange(send, axis: str):
    """The all-to-all: `send` (D, capacity, width) with row block d for device d becomes
    (D·capacity, width), block s from device s (source order)."""
    received = lax.all_to_all(send, axis, split_axis=0, concat_axis=0)
    return received.reshape(-1, send.shape[-1])


@dataclasses.dataclass(frozen=True)
class Traffic:
    """Bytes one view's exchange moves between devices (off-device only: a source's block for
    itself stays local).

    Attributes:
      forward: records that reach another device's band (slots actually filled) x record bytes.
      backward: the same records' cotangents (same width and dtype) coming back.
      buffer: what the fixed-size buffers move: D·(D − 1)·capacity rows each way, the traffic of
        an all-to-all of the padded buffers.
    """

    forward: int
    backward: int
    buffer: int


def traffic(counts, capacity: int, channels: int = 3, itemsize: int = 4) -> Traffic:
    """`Traffic` of one view from the (sources, destinations) counts of records sent (a numpy
    array: the exchange's `ShardedStats.exchange_counts`)."""
    c = np.asarray(counts, np.int64)
    off = int(c.sum() - np.trace(c))
    row = record_width(channels) * itemsize
    d = c.shape[0]
    return Traffic(forward=off * row, backward=off * row, buffer=2 * d * (d - 1) * capacity * row)

