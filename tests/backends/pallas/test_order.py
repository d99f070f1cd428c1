"""lgs_jax.backends.pallas.order: the bucketed longest-first order (a permutation, buckets from
the longest down, index order within a bucket, empty lengths last) and the exact order it
approximates, on lengths drawn where it matters (ties, zeros, powers of two and their
neighbours, the int32 top)."""

import jax
import jax.numpy as jnp
import numpy as np
from hypothesis import given, settings, strategies as st

from lgs_jax.backends.pallas import order as block_order

EDGES = [2 ** k + d for k in range(1, 30) for d in (-1, 0, 1)]  # powers of two and neighbours
LENGTH = st.one_of(st.integers(0, 3), st.integers(0, 5000), st.sampled_from(EDGES),
                   st.just(2 ** 31 - 2))
# a few list sizes, so that the examples run through a few compiled programs (a new size is a
# new compile of every function under test)
LENGTHS = st.sampled_from([1, 2, 7, 64, 300]).flatmap(
    lambda n: st.lists(LENGTH, min_size=n, max_size=n))
# Jitted: one compile per list size (eager, each of their operations compiles per size).
bucket, longest_first = jax.jit(block_order.bucket), jax.jit(block_order.longest_first)
reference = jax.jit(block_order.reference)


@settings(max_examples=50)
@given(values=LENGTHS)
def test_bucket_order_is_a_stable_counting_sort_by_bucket(values):
    lengths = np.array(values, np.int32)
    order = np.asarray(longest_first(jnp.asarray(lengths)))
    assert sorted(order.tolist()) == list(range(len(values)))
    key = np.asarray(bucket(jnp.asarray(lengths)))
    assert np.all(np.diff(key[order]) <= 0)
    for k in np.unique(key):  # index order within a bucket
        assert np.all(np.diff(order[key[order] == k]) > 0)
    zeros = lengths[order] == 0
    assert not np.any(zeros[:-1] & ~zeros[1:])  # empty lengths last


@settings(max_examples=50)
@given(values=LENGTHS)
def test_reference_is_the_stable_argsort_and_agrees_by_bucket(values):
    lengths = np.array(values, np.int32)
    exact = np.asarray(reference(jnp.asarray(lengths)))
    np.testing.assert_array_equal(exact, np.argsort(-lengths.astype(np.int64), kind="stable"))
    key = np.asarray(bucket(jnp.asarray(lengths)))
    bucketed = np.asarray(longest_first(jnp.asarray(lengths)))
    np.testing.assert_array_equal(key[exact], key[bucketed])  # the same buckets in turn


def test_buckets_are_quarters_of_each_octave_of_length_plus_one():
    lengths = np.array([0, 1, 2, 3, 4, 5, 6, 7, 8, 15, 16, 2 ** 31 - 2], np.int32)
    np.testing.assert_array_equal(np.asarray(bucket(jnp.asarray(lengths))),
                                  [0, 4, 4, 8, 9, 10, 11, 12, 12, 16, 16, 123])
    v = np.arange(1, 1 << 16, dtype=np.int64)  # within a bucket: less than 1.25 apart once
    key = np.asarray(bucket(jnp.asarray(v - 1, jnp.int32)))  # b >= 2
    for k in np.unique(key[v >= 4]):
        members = v[key == k]
        assert members.max() / members.min() < 1.25


def test_one_block_and_all_empty():
    for lengths in ([7], [0, 0, 0]):
        order = longest_first(jnp.array(lengths, jnp.int32))
        np.testing.assert_array_equal(np.asarray(order), np.arange(len(lengths)))
