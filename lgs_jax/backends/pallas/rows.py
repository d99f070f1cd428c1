"""How the Mosaic GPU backward kernel (lgs_jax.backends.pallas.mosaic_backward) writes a pair's
row: its gradient terms summed over the block's pixels, then the pair's tile, at the pair's row
(`gaussian_grads.RowLayout`, which reads the rows there).

Two reductions (`REDUCTIONS`, `writers`):
  "transposed" (the GPU default): `transposed_row`, a transposing butterfly in inline Mosaic GPU
    code (12 shuffles per thread for an image loss's 10 terms, one exchange across the warps
    through shared memory, one barrier, one coalesced store of the row by the first warp), and
    `zero_row`, one coalesced store; `plgpu.inline_mgpu` code does not run in interpret mode;
  "terms" (interpret mode): one warpgroup `jnp.sum` per term, each stored from every thread.
The two agree to float rounding (a different summation order); each is deterministic (a fixed
order, no atomics). `reference` is the row in plain jnp.
"""

from __future__ import annotations

import functools

import jax.numpy as jnp
import numpy as np
from jax.experimental.mosaic.gpu import utils as mgpu_utils
from jax.experimental.pallas import mosaic_gpu as plgpu
from jaxlib.mlir import ir
from jaxlib.mlir.dialects import arith, memref, scf, vector
from jaxlib.mlir.dialects import math as math_dialect

from . import steps as ks
from .inline import element, threads

REDUCTIONS = ("terms", "transposed")


def resolve(reduction: str | None, interpret: bool) -> str:
    """The reduction to run: `reduction`, or by default "terms" in interpret mode (which cannot
    run inline Mosaic GPU code) and "transposed" on the GPU."""
    if reduction is None:
        return "terms" if interpret else "transposed"
    if reduction not in REDUCTIONS:
        raise ValueError(f"reduction: expected one of {REDUCTIONS}, got {reduction!r}")
    return reduction


def scratch(reduction: str, dt) -> tuple:
    """The shared memory `reduction` needs: two exchange buffers for "transposed" (used in turn,
    so one barrier per pair suffices: `transposed_row`), none for "terms"."""
    return (plgpu.SMEM((2, EXCHANGE), dt),) if reduction == "transposed" else ()


def reference(terms, tile, width: int):
    """One pair's row in jnp: the per-pixel `terms` (`steps.backward_step`'s: arrays,
    `steps.Scaled`, `steps.Product` or None) summed over the pixels, None as 0, then the tile,
    in a row of `width` columns (`steps.row_width`); what both reductions store, up to the
    order of the float summation."""
    dt = tile.dtype
    values = [jnp.zeros((), dt) if v is None else jnp.sum(ks.term(v)) for v in terms]
    return jnp.stack(values[:width - 1] + [tile])


def writers(reduction: str, rows_ref, wg, tile, pixels: int, exchange=None):
    """(store, zero) for block `wg`'s rows rows_ref[wg] (capacity, width) of tile `tile`
    (a row's ref is taken as rows_ref.at[wg, s], one subview, as the GPU runs tested it):
    store(values, s, parity) reduces a pair's width − 1 per-pixel terms (None: zero) and
    writes them and the tile at slot s, returning the next exchange buffer's index; zero(s)
    writes a zero row with the tile (a tile's other block may have a row there). The tile is
    the row's last column (`steps.row_width`); values past width − 1 (∂L/∂z where the
    loss does not reach the depth) must be None and are not stored."""
    dt = rows_ref.dtype
    tile_value = tile.astype(dt)
    width = rows_ref.shape[-1]

    def kept(values):
        assert all(v is None for v in values[width - 1:]), "a row too narrow for its values"
        return values[:width - 1]

    if reduction == "transposed":
        def store(values, s, parity):
            transposed_row(kept(values), pixels, exchange.at[parity], rows_ref.at[wg, s],
                           tile_value)
            return 1 - parity

        def zero(s):
            zero_row(rows_ref.at[wg, s], tile_value)

        return store, zero
    zero_scalar = jnp.zeros((), dt)

    def store(values, s, parity):
        for c, v in enumerate(kept(values)):
            rows_ref[wg, s, c] = zero_scalar if v is None else jnp.sum(ks.term(v))
        rows_ref[wg, s, width - 1] = tile_value
        return parity

    def zero(s):
        for c in range(width - 1):
            rows_ref[wg, s, c] = zero_scalar
        rows_ref[wg, s, width - 1] = tile_value

    return store, zero


EXCHANGE = 16 * 4  # `transposed_row`'s shared-memory exchange: 16 slots x 4 warps


def butterfly_plan(rows: int):
    """The transposing butterfly of `transposed_row` for `rows` <= 16 values per lane: the
    halving sizes h of its steps (lane distance 16, 8, ...; a step on m values keeps
    h = ceil(m / 2), a lane with the distance's bit set keeping values h..m − 1) and, per lane
    pair (2s, 2s + 1) after the last step, the row s holds (−1: none). Each lane's value
    at the end is its row's sum over the warp's 32 lanes."""
    if not 1 <= rows <= 16:
        raise ValueError(f"rows: must be in [1, 16], got {rows}")
    lanes = np.arange(32)
    table = [np.full(32, r) for r in range(rows)]
    halves = []
    for d in (16, 8, 4, 2, 1):
        m = len(table)
        if m == 1:
            halves.append(0)
            continue
        h = (m + 1) // 2
        halves.append(h)
        table = [np.where(lanes & d, table[k + h] if k + h < m else -1, table[k])
                 for k in range(h)]
    final = table[0]
    assert np.array_equal(final[0::2], final[1::2])
    return tuple(halves), tuple(int(r) for r in final[0::2])


def term_order(sources) -> tuple[int, ...]:
    """The order in which `transposed_row` lays out its m present terms for `butterfly_plan(m)`
    (positions k and k + h, h = ceil(m / 2), meet at its first step), given each term's source
    (`sources[i]`: equal for `steps.Scaled` terms of one source, None for a term of its
    own): terms of one source paired at positions (k, k + h) as far as they go, then the rest.
    A pair of one source needs no per-pair select at that step (`_butterfly`)."""
    m = len(sources)
    h = (m + 1) // 2
    groups: dict = {}
    for i, key in enumerate(sources):
        groups.setdefault(("own", i) if key is None else key, []).append(i)
    pairs, rest = [], []
    for members in groups.values():
        pairs += [members[k:k + 2] for k in range(0, len(members) - 1, 2)]
        rest += members[len(members) // 2 * 2:]
    # len(pairs) <= m // 2 = m − h: every pair finds a position k < m − h
    low = [a for a, _ in pairs] + rest[:h - len(pairs)]
    high = [b for _, b in pairs] + rest[h - len(pairs):]
    return tuple(low + high)


def row_slots(terms) -> tuple[tuple[int, ...], tuple, tuple[int, ...]]:
    """(order, halves, slot of each row) of `transposed_row` for `terms`: the present terms'
    indices in butterfly order (`term_order`), `butterfly_plan`'s halving sizes for them, and
    per row c < len(terms) the exchange slot (lane pair) holding the warp's sum of terms[c];
    a None row is given a slot no term reaches, whose sums are exact zeros (the butterfly adds
    only its padding zeros there; one exists, as fewer than 16 terms are present)."""
    present = [c for c, v in enumerate(terms) if v is not None]
    if not present:
        raise ValueError("transposed_row: every term is None (zero_row writes a zero row)")
    sources = [id(terms[c].source) if isinstance(terms[c], ks.Scaled) else None
               for c in present]
    order = tuple(present[i] for i in term_order(sources))
    halves, slot_rows = butterfly_plan(len(order))
    slots = {order[p]: s for s, p in enumerate(slot_rows) if p >= 0}
    if len(order) < len(terms):
        spare = slot_rows.index(-1)
        slots.update({c: spare for c in range(len(terms)) if c not in slots})
    return order, halves, tuple(slots[c] for c in range(len(terms)))


def transposed_row(terms, pixels: int, exchange, row, tile):
    """Store one pair's row: row[c] = Σ over the block's pixels of terms[c] (c < len(terms)),
    then row[len(terms)] = tile, from `steps.backward_step`'s terms: block-wide
    (pixels,) lane vectors (Mosaic GPU strided layout: each thread holds pixels/128 of them),
    `steps.Scaled` or `steps.Product` products of two (formed here, the pixels
    after a thread's first added by multiply-adds), or None for a zero term, left out of the
    butterfly (a zero array passed in fails the GPU compiler's LLVM translation with an
    unrealized layout cast).

    A transposing reduction (`plgpu.inline_mgpu`; GPU only): each thread adds its own pixels,
    then five butterfly steps over the warp's lanes (distance 16, 8, 4, 2, 1) halve the values
    each lane still holds, exchanging only the half its partner keeps (for 10 terms 5 + 3 + 2 +
    1 + 1 = 12 shuffles per thread, where reducing each term over the lanes takes 10 x 5 = 50),
    leaving every lane pair the warp's sum of one term (`butterfly_plan`, in `row_slots`'
    order). At the first step a lane sends one of two terms and keeps the other, two selects
    per pair of terms; for two `Scaled` terms of one source it multiplies the source by the
    factors it selected once per walk instead (the same products: the same bits). Each warp
    writes its 16 sums to `exchange` (a (EXCHANGE,) view of shared memory: slot s of warp w at
    4s + w), one barrier, and lanes 0..len(terms) of the first warp add the four warps' sums
    ((w0 + w1) + (w2 + w3)) and store the row with one coalesced store (the tile from lane
    len(terms)). The caller alternates two `exchange` buffers between consecutive reductions,
    so one barrier per pair suffices: a warp writes a buffer again only after the barrier of
    the reduction in between, which the first warp passes after reading it. Fixed order,
    no atomics: deterministic; each sum's order over the lanes is the butterfly's whatever the
    terms' order (a + b is b + a), so the bits do not depend on `row_slots`."""
    vec = pixels // 128
    order, halves, slots = row_slots(terms)
    inputs, index = [], {}  # the distinct arrays passed in, by id

    def arg(a):
        if id(a) not in index:
            index[id(a)] = len(inputs)
            inputs.append(a)
        return index[id(a)]

    specs = [tuple(map(arg, terms[c])) if isinstance(terms[c], (ks.Scaled, ks.Product))
             else (arg(terms[c]),) for c in order]
    scaled = [isinstance(terms[c], ks.Scaled) for c in order]

    @plgpu.inline_mgpu(
        arg_types=(plgpu.RefType(), plgpu.RefType(), plgpu.Layout.WG_SPLAT(()))
        + (plgpu.Layout.WG_STRIDED((pixels,), vec_size=vec),) * len(inputs))
    def reduce(_, exchange_ref, row_ref, tile_value, *arrays):
        el = ir.VectorType(arrays[0].registers.flat[0].type).element_type
        tid, _, _ = threads(ir.IntegerType.get_signless(32))
        lanes = [[element(a.registers.reshape(-1)[0], e) for e in range(vec)] for a in arrays]
        elements = [tuple(lanes[i] for i in sp) for sp in specs]
        value = _butterfly(elements, scaled, halves, arith.remui(tid, _i32(32)),
                           arith.constant(el, 0.0))
        _exchange_and_store(value, exchange_ref, row_ref, tid, slots,
                            tile_value.registers.item())

    reduce(exchange, row, tile, *inputs)


def _i32(v: int):
    return mgpu_utils.c(v, ir.IntegerType.get_signless(32))


def _shuffle(v, d: int):
    """v of lane l ^ d (a butterfly shuffle), through a 1-vector: utils.shfl_bfly cannot
    bitcast a 64-bit scalar."""
    return element(mgpu_utils.shfl_bfly(vector.broadcast(ir.VectorType.get((1,), v.type), v),
                                         d), 0)


def _own_sum(element):
    """The thread's sum over its pixels of a term: (values,) or (source, factor) per pixel, the
    products after the first added by multiply-adds (s₀f₀ + s₁f₁ as fma(s₁, f₁, s₀f₀): one
    instruction fewer per product, and one rounding)."""
    if len(element) == 1:
        return functools.reduce(arith.addf, element[0])
    (s0, *sources), (f0, *factors) = element
    return functools.reduce(lambda acc, sf: math_dialect.fma(sf[0], sf[1], acc),
                            zip(sources, factors), arith.mulf(s0, f0))


def _first_step(elements, scaled, h: int, upper, zero):
    """The butterfly's first step's (send, keep) per k < h, from the terms' per-pixel values
    (`_own_sum`'s elements; `scaled[i]`: whether term i is a `steps.Scaled`): for two
    `Scaled` terms of one source, the source times the selected factors (selects of per-walk
    values, which the compiler takes out of the pair loop)."""
    out = []
    for k in range(h):
        lo = elements[k]
        hi = elements[k + h] if k + h < len(elements) else None
        if hi is not None and scaled[k] and scaled[k + h] and lo[0] is hi[0]:
            pick = lambda a, b: [arith.select(upper, x, y) for x, y in zip(a, b)]
            out.append((_own_sum((lo[0], pick(lo[1], hi[1]))),
                        _own_sum((lo[0], pick(hi[1], lo[1])))))
            continue
        lo_sum, hi_sum = _own_sum(lo), zero if hi is None else _own_sum(hi)
        out.append((arith.select(upper, lo_sum, hi_sum), arith.select(upper, hi_sum, lo_sum)))
    return out


def _butterfly(elements, scaled, halves, lane, zero):
    """`butterfly_plan`'s steps on this lane's terms `elements` (per term its per-pixel values,
    or two factors per pixel, in `row_slots`' order; `scaled`: `_first_step`'s): the lane's one
    value at the end, the warp's sum of the term the plan assigns to its lane pair."""
    vals = None
    for d, h in zip((16, 8, 4, 2, 1), halves):
        upper = arith.cmpi(arith.CmpIPredicate.ne, arith.andi(lane, _i32(d)), _i32(0))
        if vals is None:  # the first step (at least two terms; with one, h is 0 here)
            if h:
                vals = [arith.addf(keep, _shuffle(send, d))
                        for send, keep in _first_step(elements, scaled, h, upper, zero)]
                continue
            vals = [_own_sum(elements[0])]
        if h == 0:
            vals = [arith.addf(vals[0], _shuffle(vals[0], d))]
            continue
        merged = []
        for k in range(h):
            lo = vals[k]
            hi = vals[k + h] if k + h < len(vals) else zero
            send = arith.select(upper, lo, hi)
            keep = arith.select(upper, hi, lo)
            merged.append(arith.addf(keep, _shuffle(send, d)))
        vals = merged
    return vals[0]


def _exchange_and_store(value, exchange_ref, row_ref, tid, slots, tile):
    """Each lane's warp sum `value` to exchange_ref[4·slot + warp] (slot = lane // 2), one
    barrier, then thread t <= rows (rows = len(slots)) of the first warp stores row_ref[t]: the
    four warps' sums in slot slots[t], (w0 + w1) + (w2 + w3), or, for t = rows, the tile."""
    index = ir.IndexType.get()
    rows = len(slots)
    lane, warp = arith.remui(tid, _i32(32)), arith.divui(tid, _i32(32))
    at = arith.addi(arith.muli(arith.shrui(lane, _i32(1)), _i32(4)), warp)
    memref.store(value, exchange_ref, [arith.index_cast(index, at)])
    mgpu_utils.warpgroup_barrier()
    with ir.InsertionPoint(scf.IfOp(arith.cmpi(arith.CmpIPredicate.ule, tid, _i32(rows)))
                           .then_block):
        slot = _i32(0)
        for t, s in enumerate(slots):
            slot = arith.select(arith.cmpi(arith.CmpIPredicate.eq, tid, _i32(t)), _i32(s), slot)
        four = vector.load(ir.VectorType.get((4,), value.type), exchange_ref,
                           [arith.index_cast(index, arith.muli(slot, _i32(4)))])
        p = [element(four, w) for w in range(4)]
        total = arith.addf(arith.addf(p[0], p[1]), arith.addf(p[2], p[3]))
        memref.store(arith.select(arith.cmpi(arith.CmpIPredicate.eq, tid, _i32(rows)), tile,
                                  total),
                     row_ref, [arith.index_cast(index, tid)])
        scf.yield_([])


@plgpu.inline_mgpu(arg_types=(plgpu.RefType(), plgpu.Layout.WG_SPLAT(())))
def zero_row(_, row_ref, tile_value):
    """row_ref[:] = (0, ..., 0, tile): one coalesced store by the first warp's lanes (where a
    store from Pallas would have every thread write every column)."""
    i32, index = ir.IntegerType.get_signless(32), ir.IndexType.get()
    width = ir.MemRefType(row_ref.type).shape[0]
    tid, _, _ = threads(i32)
    last = mgpu_utils.c(width - 1, i32)
    value = tile_value.registers.item()
    with ir.InsertionPoint(scf.IfOp(arith.cmpi(arith.CmpIPredicate.ule, tid, last)).then_block):
        zero = arith.constant(value.type, 0.0)
        memref.store(arith.select(arith.cmpi(arith.CmpIPredicate.eq, tid, last), value, zero),
                     row_ref, [arith.index_cast(index, tid)])
        scf.yield_([])
