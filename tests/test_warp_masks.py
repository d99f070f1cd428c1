"""lgs_jax.warp_masks: the tight box of an ellipse inside a tile column (Local-GS Fig. 4, cases
A/B/C, Eq. 13–19) against a dense evaluation of the ellipse."""

import numpy as np
import pytest

from lgs_jax.warp_masks import tight_box


def _dense_y_range(conic, tau, x0, x1):
    a, b, c = conic
    xs = np.linspace(x0, x1, 200001)
    disc = c * tau - (a * c - b * b) * xs**2
    ok = disc >= 0
    r = np.sqrt(disc[ok])
    return ((-b * xs[ok] - r) / c).min(), ((-b * xs[ok] + r) / c).max()


@pytest.mark.parametrize("case,column", [("A", (-2.0, 13.0)), ("B", (-15.0, -8.0)),
                                         ("C", (-10.0, 5.0))])
def test_tight_box_cases(case, column):
    """A tilted ellipse (x-extent ±15.4) whose top point sits at x̃ = −b·d_y/a ≈ −4.9: the column
    lies right of it (case A, maximum at the left edge), left of it (case B) or around it (C)."""
    conic = np.array([0.05, 0.01, 0.02])  # det = 9e-4 > 0
    tau = 2 * np.log(255 * 0.8)
    a, b, c = conic
    d_y = np.sqrt(a * tau / (a * c - b * b))
    peak = -b * d_y / a
    x0, x1 = column
    assert {"A": peak < x0, "B": peak > x1, "C": x0 <= peak <= x1}[case]
    lo, hi, empty = (np.asarray(v) for v in
                     tight_box(a, b, c, tau, a * c - b * b, x0, x1))
    want_lo, want_hi = _dense_y_range(conic, tau, x0, x1)
    assert not empty
    assert lo <= want_lo and hi >= want_hi  # conservative
    np.testing.assert_allclose([lo, hi], [want_lo, want_hi], atol=1e-6)  # and tight
    if case == "C":
        assert hi == pytest.approx(d_y)


def test_tight_box_misses_a_column_outside_the_ellipse():
    conic = np.array([0.05, 0.0, 0.05])
    tau = 2.0  # x-extent ±√40 ≈ 6.3
    assert bool(tight_box(*np.float32(conic), tau, 0.0025, 7.0, 20.0)[2])
