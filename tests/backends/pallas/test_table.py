"""lgs_jax.backends.pallas.table: the Triton kernel's Gaussian table equals its `reference`,
`pairs.gaussian_table` bit for bit (copies only), adversarial Gaussians included (invalid rows,
unbounded ellipses, opacity near 1/255), for any N against the program's lanes."""

import jax
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from lgs_jax import pairs
from lgs_jax.backends.pallas import table as table_kernel
from lgs_jax.projection import project
from tests import scenes
from tests.devices import ON_GPU


@pytest.mark.parametrize("dtype,lanes,n", [(np.float32, 64, 97), (np.float64, 32, 31),
                                           (np.float32, 32, 1)])
@settings(max_examples=3)
@given(seed=st.integers(0, 2**32 - 1))
def test_kernel_table_equals_the_xla_table(dtype, lanes, n, seed):
    g = scenes.scene(seed, n=n, dtype=dtype)
    p = jax.jit(project)(g, scenes.camera(dtype=dtype))
    want = np.asarray(jax.jit(table_kernel.reference)(p))
    got = np.asarray(table_kernel.gaussian_table(p, interpret=not ON_GPU, lanes=lanes))
    assert got.shape == (n, pairs.TABLE_COLUMNS) and got.dtype == dtype
    np.testing.assert_array_equal(got, want)  # NaN rows (invalid Gaussians) compare as equal


def test_lanes_must_fill_warps():
    p = project(scenes.scene(0, n=4), scenes.camera())
    with pytest.raises(ValueError, match="lanes: expected a multiple of 32"):
        table_kernel.gaussian_table(p, interpret=True, lanes=48)
