"""lgs_jax.backends.backward: the per-Gaussian sum of pair rows."""

import numpy as np
from hypothesis import given, strategies as st

from lgs_jax.backends import backward

CAP, N = 300, 37  # fixed shapes: one compile


@given(seed=st.integers(0, 2**32 - 1), runs=st.sampled_from(["random", "sorted", "one", "few"]))
def test_per_gaussian_sum_equals_a_float64_sum(seed, runs):
    """Every Gaussian's rows summed, whatever the runs look like: scattered ids, sorted ids,
    one Gaussian owning every row (a run over all chunks), a few long runs crossing chunk
    boundaries; ids with no row get zero."""
    rng = np.random.default_rng(seed)
    ids = {"random": lambda: rng.integers(0, N, CAP),
           "sorted": lambda: np.sort(rng.integers(0, N, CAP)),
           "one": lambda: np.full(CAP, rng.integers(0, N)),
           "few": lambda: rng.choice(rng.integers(0, N, 3), CAP)}[runs]().astype(np.int32)
    rows = rng.normal(size=(CAP, 4))
    got = np.asarray(backward.per_gaussian_sum(rows, ids, N))
    want = np.zeros((N, 4))
    np.add.at(want, ids, rows)
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(got, np.asarray(backward.per_gaussian_sum(rows, ids, N)))
