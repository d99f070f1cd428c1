"""numerics.centre: the split centre removes the float32 centre floor."""

import csv

import jax.numpy as jnp
import numpy as np
from hypothesis import given, strategies as st

from lgs_jax import twofloat
from numerics import centre
from tests.scenes import float_arrays


def _magnitudes():
    """16 float64 numbers ±10^e, e in [−8, 8] (the centre's arithmetic spans ~1e-8 to 1e5)."""
    return st.tuples(float_arrays(-8, 8, 16), float_arrays(-1, 1, 16)).map(
        lambda es: np.copysign(10.0 ** es[0], es[1]))


@given(a=_magnitudes(), b=_magnitudes(), scale=st.sampled_from([1e-8, 1.0, 1e8]))
def test_error_free_transformations_are_exact(a, b, scale):
    """lgs_jax.twofloat's two_sum and two_prod return the exact sum and product of float32
    numbers (as float64, which holds them: the product of two 24-bit significands has 48
    bits), where no partial product underflows (XLA flushes subnormals to zero)."""
    a = jnp.asarray(a, jnp.float32)
    b = jnp.asarray(b * scale, jnp.float32)
    up = lambda x: np.asarray(x, np.float64)
    s, e = twofloat.two_sum(a, b)
    np.testing.assert_array_equal(up(s) + up(e), up(a) + up(b))
    p, e = twofloat.two_prod(a, b)
    exact = up(a) * up(b)
    assert np.all(np.abs(up(p) + up(e) - exact) <= 2.0**-44 * np.abs(exact))


def test_quick_study_removes_the_floor(tmp_path):
    """At 16K, κ = 1, centres within 16 px: the split forms err >= 10x less than the current
    ones, and no more than the current forms at 1K."""
    assert centre.main(["--quick", "--out", str(tmp_path)]) == 0
    rows = list(csv.DictReader(open(tmp_path / "centre.csv")))

    def worst(form, res):
        return max(float(r["max_abs_total_err"]) for r in rows if r["form"] == form and
                   int(r["resolution"]) == res and float(r["anisotropy"]) == 1.0 and
                   int(r["offset_px"]) <= 16)

    for base in ("difference", "local_corner"):
        assert worst(base + "+split", 16384) * 10 <= worst(base, 16384), base
        assert worst(base + "+split", 16384) <= worst(base, 1024), base
