"""lgs_jax.backends.pallas.rows: the backward's per-pair row reduction. The transposing
butterfly runs only on a GPU (inline Mosaic GPU code); here its plan is simulated on a warp's
lanes in numpy, and the interpret-mode writer is checked against `pair_rows.reference`."""

import jax.numpy as jnp
import numpy as np
import pytest

from lgs_jax.backends.pallas import rows as pair_rows
from lgs_jax.backends.pallas import steps as ks


def _butterfly_sim(x, halves):
    """The transposing butterfly on a warp's lanes (x: (32, m) values in butterfly order): lane
    l sends the half its partner l ^ d keeps and adds what it receives (`transposed_row`)."""
    lanes = np.arange(32)
    vals = [x[:, r] for r in range(x.shape[1])]
    for d, h in zip((16, 8, 4, 2, 1), halves):
        partner = lanes ^ d
        if h == 0:
            vals = [vals[0] + vals[0][partner]]
            continue
        upper = (lanes & d) != 0
        merged = []
        for k in range(h):
            lo, hi = vals[k], vals[k + h] if k + h < len(vals) else np.zeros(32, x.dtype)
            send, keep = np.where(upper, lo, hi), np.where(upper, hi, lo)
            merged.append(keep + send[partner])
        vals = merged
    assert len(vals) == 1
    return vals[0]


@pytest.mark.parametrize("rows", [1, 2, 3, 5, 8, 11, 16])
def test_transposing_butterfly_leaves_every_row_sum_in_its_lane_pair(rows):
    """`pair_rows.butterfly_plan`, simulated as `transposed_row` runs it on a warp
    (`_butterfly_sim`): every row's sum over the 32 lanes ends in the lane pairs the plan names
    (one pair per row from 9 rows on; the kernel itself only runs on a GPU)."""
    halves, slot_rows = pair_rows.butterfly_plan(rows)
    x = np.random.default_rng(rows).normal(size=(32, rows))
    final = _butterfly_sim(x, halves)
    assert {r for r in slot_rows if r >= 0} == set(range(rows))
    for s, r in enumerate(slot_rows):
        assert final[2 * s] == final[2 * s + 1]
        if r >= 0:
            np.testing.assert_allclose(final[2 * s], x[:, r].sum(), rtol=1e-12)
    with pytest.raises(ValueError, match="rows"):
        pair_rows.butterfly_plan(17)


@pytest.mark.parametrize("depth,hoisted", [(False, True), (True, True), (False, False)])
def test_transposed_rows_slots_hold_each_terms_sum_and_zero_for_none(depth, hoisted):
    """`pair_rows.row_slots` for `backward_step`'s terms (hoisted: five `Scaled` of d_raw,
    d_raw and d_ln_o, else seven arrays; the colour's three, the depth's or None): the
    butterfly, simulated on the terms in its order, leaves each row's sum over the lanes in the
    slot named for it and an exact zero in a None row's; `Scaled` terms of one source meet at
    the first step as far as they go (two pairs of five)."""
    rng = np.random.default_rng(7)
    lanes = lambda: rng.normal(size=32).astype(np.float32)
    d_raw = lanes()
    model = ([ks.Scaled(d_raw, lanes()) for _ in range(5)] + [d_raw] if hoisted
             else [lanes() for _ in range(6)])
    terms = model + [lanes() for _ in range(4)] + [lanes() if depth else None]
    order, halves, slots = pair_rows.row_slots(terms)
    assert sorted(order) == [c for c, v in enumerate(terms) if v is not None]
    h = (len(order) + 1) // 2
    shared = sum(isinstance(terms[a], ks.Scaled) and isinstance(terms[b], ks.Scaled)
                 and terms[a].source is terms[b].source for a, b in zip(order, order[h:]))
    assert shared == (2 if hoisted else 0)
    final = _butterfly_sim(np.stack([ks.term(terms[c]) for c in order], -1), halves)
    for c, s in enumerate(slots):
        assert final[2 * s] == final[2 * s + 1]
        if terms[c] is None:
            assert final[2 * s] == 0
        else:
            np.testing.assert_allclose(final[2 * s], ks.term(terms[c]).sum(dtype=np.float64),
                                       rtol=1e-5, atol=1e-5)
    with pytest.raises(ValueError, match="every term is None"):
        pair_rows.row_slots([None, None])


@pytest.mark.parametrize("width", [11, 12])
def test_reference_sums_each_term_and_ends_with_the_tile(width):
    """`pair_rows.reference`: each present term's sum over the pixels (a `Scaled` or `Product` as
    its product), None as an exact zero, the tile last, in a row of `width` columns."""
    rng = np.random.default_rng(width)
    lanes = lambda: jnp.asarray(rng.normal(size=128).astype(np.float32))
    d_raw = lanes()
    terms = [ks.Scaled(d_raw, lanes()), ks.Product(lanes(), lanes()), None, d_raw]
    terms += [lanes() for _ in range(width - 1 - len(terms))]
    row = np.asarray(pair_rows.reference(terms, jnp.float32(5), width))
    assert row.shape == (width,) and row[-1] == 5 and row[2] == 0
    np.testing.assert_allclose(row[0], np.sum(np.asarray(ks.term(terms[0]))), rtol=1e-6)
    np.testing.assert_allclose(row[1], np.sum(np.asarray(ks.term(terms[1]))), rtol=1e-6)
    np.testing.assert_allclose(row[3], np.sum(np.asarray(d_raw)), rtol=1e-6)
