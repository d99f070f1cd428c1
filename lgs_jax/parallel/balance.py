"""Keeping a sharded pool balanced: where each Gaussian of a training pool goes so that the D
blocks of the pool (one per device of the mesh axis "gaussians") hold equal shares.

A pool (lgs_jax.train.pool) has `size` slots, `active` marking those in use; split over D
devices, block b is slots [b·B, (b + 1)·B), B = size / D. Densification activates and prunes
slots anywhere, so blocks drift apart. `balanced_order` gives the permutation that restores the
balance, by count or by a per-Gaussian weight (e.g. its tile pairs in recent views, the work it
brings its device), under two rules:

- **Order kept.** The active Gaussians keep their relative order: block b holds a contiguous
  run of them, active ranks [s_b, s_(b+1)), then its inactive slots. The render's tie-break
  is the global row order, so the rebalanced pool renders the same bits, and the active
  Gaussians in slot order (a checkpoint's or scene.ply's contents) are the same list.
- **Capacity.** A block holds at most B Gaussians: the boundaries s_b are the balanced
  targets clamped to what the blocks can hold.

Apply it to every per-Gaussian array of the run (parameters, optimizer moments, a strategy's
accumulators) with `jnp.take(x, order, axis=0)`; inactive slots move along, unchanged.
"""

from __future__ import annotations

import jax.numpy as jnp


def block_starts(active, devices: int, weights=None):
    """(devices + 1,) int32 s_0 = 0 <= s_1 <= ... <= s_D = A (A active Gaussians): block b
    takes active ranks [s_b, s_(b+1)). Targets: b·A/D rounded down (by count), or the first
    rank whose weight before it reaches b/D of the total (`weights`, per slot, >= 0); each
    clamped so that every block holds at most size / D."""
    size = active.shape[0]
    if size % devices:
        raise ValueError(f"active: {size} slots do not split into {devices} equal blocks")
    block = size // devices
    a = active.astype(jnp.int32)
    total = jnp.sum(a)
    if weights is None:
        targets = [(b * total) // devices for b in range(devices)]
    else:
        w = jnp.where(active, weights, 0).astype(jnp.float32)
        before = jnp.cumsum(w) - w  # weight of the active slots before each slot
        share = jnp.sum(w) / devices
        targets = [jnp.sum(active & (before < b * share), dtype=jnp.int32)
                   for b in range(devices)]
    starts = [jnp.int32(0)]
    for b in range(1, devices):
        lo = jnp.maximum(starts[-1], total - (devices - b) * block)
        hi = jnp.minimum(jnp.minimum(b * block, total), starts[-1] + block)
        starts.append(jnp.clip(targets[b], lo, hi).astype(jnp.int32))
    return jnp.stack(starts + [total.astype(jnp.int32)])


def balanced_order(active, devices: int, weights=None):
    """(size,) int32 `order`: slot j of the rebalanced pool takes slot order[j] (module
    docstring). Block b gets active ranks [s_b, s_(b+1)) (`block_starts`) at its front, in
    order, then inactive slots in their order. Traceable (`devices` static); a permutation
    computed by prefix sums and one store per slot (no sort, no scatter-add)."""
    size = active.shape[0]
    block = size // devices
    starts = block_starts(active, devices, weights)
    a = active.astype(jnp.int32)
    rank = jnp.cumsum(a) - a  # active rank of each active slot
    blk = jnp.searchsorted(starts[1:], rank, side="right")
    blk = jnp.minimum(blk, devices - 1)
    dest_active = blk * block + rank - starts[blk]
    counts = starts[1:] - starts[:-1]
    free_end = jnp.cumsum(block - counts)
    irank = jnp.cumsum(1 - a) - (1 - a)  # inactive rank of each inactive slot
    iblk = jnp.minimum(jnp.searchsorted(free_end, irank, side="right"), devices - 1)
    free_start = free_end[iblk] - (block - counts[iblk])
    dest_inactive = iblk * block + counts[iblk] + irank - free_start
    dest = jnp.where(active, dest_active, dest_inactive).astype(jnp.int32)
    return jnp.zeros((size,), jnp.int32).at[dest].set(jnp.arange(size, dtype=jnp.int32),
                                                       unique_indices=True)
