"""The order in which the Pallas kernels' blocks take their work (tiles in the forward, segments
in the split backward): longest first, so that the longest lists start early and the last wave
of blocks is short. Only the schedule depends on it: every block writes its own outputs, so any
order gives the same bits.

The order is a counting sort by buckets of the lengths, four per octave (`longest_first`): a few
fused XLA passes and no sort (on GPUs XLA sorts arrays of 16k keys and more with CUB, whose
launches run outside XLA's command buffers and cost host time every call); a bucket's lengths
are within a factor 1.25 of each other. `reference` is the exact order it approximates.
"""

from __future__ import annotations

import jax.numpy as jnp
from jax import lax

SUB_OCTAVES = 4  # buckets per doubling of the length (its two bits below the leading one)
BUCKETS = SUB_OCTAVES * 32  # every int32 length has one


def bucket(lengths):
    """Bucket of each length (int32 >= 0): 4·b + s, where 2^b <= length + 1 < 2^(b+1) and s is
    the two bits below the leading one (0 for b < 2), so a bucket spans a quarter of an octave
    (its lengths + 1 within a factor 1.25): non-decreasing in the length, 0 for length 0
    alone. Integer arithmetic (`lax.clz`), the same on every platform."""
    v = lengths.astype(jnp.int32) + 1
    b = 31 - lax.clz(v)
    s = jnp.where(b >= 2, lax.shift_right_logical(v, jnp.maximum(b - 2, 0)) & 3, 0)
    return SUB_OCTAVES * b + s


def longest_first(lengths):
    """A permutation (int32) of the indices of `lengths` from the highest bucket to the lowest
    (`bucket`), in index order within a bucket: a stable counting sort (the buckets' sizes,
    their prefix sum, each index's rank in its bucket from a prefix sum of the bucket one-hot
    matrix, one scatter to the positions), no sort."""
    n = lengths.shape[0]
    key = BUCKETS - 1 - bucket(lengths)  # the longest first
    onehot = (key[:, None] == jnp.arange(BUCKETS, dtype=jnp.int32)).astype(jnp.int32)
    ranks = jnp.cumsum(onehot, axis=0)  # (n, BUCKETS): entries of each bucket up to here
    sizes = ranks[-1]
    first = jnp.cumsum(sizes) - sizes
    index = jnp.arange(n, dtype=jnp.int32)
    position = first[key] + ranks[index, key] - 1
    return jnp.zeros(n, jnp.int32).at[position].set(index, unique_indices=True)


def reference(lengths):
    """The exact longest-first order (a stable argsort of the lengths, decreasing), which
    `longest_first` approximates within a bucket."""
    return jnp.argsort(-lengths, stable=True).astype(jnp.int32)
