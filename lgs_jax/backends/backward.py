"""Backward of per-pixel compositing: each tile's list walked back to front from the final
transmittance, as the original 3DGS backward does (the `reference` and `tiles` backends'
custom_vjp; the Pallas backward kernels take the same step, `walk_step`).

With w_k = α_k·T_k, a pixel's outputs are C = Σ rgb_k·w_k, D = Σ z_k·w_k and T_N = Π (1 − α_k)
over the Gaussians blended there. Walking back over them, from T_N:

    T_k = T_{k+1} / (1 − α_k)
    ∂L/∂rgb_k = w_k·ḡ_C,   ∂L/∂z_k = w_k·ḡ_D
    ∂L/∂α_k = T_k·(ḡ_C·rgb_k + ḡ_D·z_k) − (ḡ_C·S_C + ḡ_D·S_Z + ḡ_T·T_N) / (1 − α_k)
    S_C += rgb_k·w_k,  S_Z += z_k·w_k            (the contributions behind k)

then through α = min(cap, o·e^power) (zero where the cap binds) and
power = −½(a·dx² + c·dy²) − b·dx·dy, dx = μx − px (lgs_jax.composite). Division by 1 − α is safe:
α <= cap <= 0.999.

Determinism: each step gives every tile one pair row (the pair's gradient summed over the
tile's 256 pixels, a fixed-order reduction) stored at that pair's own slot; rows are then summed
per Gaussian (`per_gaussian_sum`): put back in emission order by the inverse of the tile sort's
permutation (`TileBins.slot`; a plain store, one writer per slot), where each Gaussian's rows
are one contiguous run in ascending tile order, then a segmented sum in a fixed association
whose segment ends are stored to distinct Gaussians. No second sort, no scatter-add anywhere,
so no float atomics on GPUs. Residuals are the inputs and per-pixel state: O(pixels + pairs),
nothing per pixel per Gaussian.
"""

from __future__ import annotations


import jax.numpy as jnp
from jax import lax

from .. import alpha as alpha_model
from .. import hoist
from ..binning import TileBins
from ..composite import centre_offsets
from ..config import RasterConfig

PAIR_COLUMNS = 10  # ∂L/∂(mean2d x, y; conic a, b, c; opacity; rgb r, g, b; depth)


def walk_step(t_next, alpha, hit, rgb, z, sums, cotangents, quotients=None):
    """One pair of the walk at a set of pixels (any shape; `rgb`, `z` broadcast): the module
    docstring's recurrence, the one both the XLA walk and the Pallas backward kernels take.

    rgb = (r, g, b); sums = (S_r, S_g, S_b, S_Z) behind this pair; cotangents = (ḡ_r, ḡ_g, ḡ_b,
    ḡ_D, ḡ_T·T_N), ḡ_D None where the loss does not reach the depth: its terms are left out
    rather than multiplied by zeros (which a compiler must keep) and S_Z is carried unchanged.
    Returns (T_k where hit else T_{k+1}: the next carry, w = α·T_k, ∂L/∂α (zero where not hit),
    the sums including this pair). A miss is a pair with α = 0 (T_{k+1}/1 and 0·T_k are exact),
    one select where three took the cases apart (`hit`: fewer instructions in the GPU kernels'
    pair step, the same bits). `quotients(1 − α, (x, y))` gives the two
    divisions by 1 − α (the Mosaic GPU kernel's own, `pallas.quotients.quotients`), `/` if None.
    """
    g_r, g_g, g_b, g_d, g_bg = cotangents
    s_r, s_g, s_b, s_z = sums
    alpha = jnp.where(hit, alpha, 0)  # a miss: 1 − α = 1, so T_k = T_{k+1} and w = 0, exactly
    one_minus = 1 - alpha
    dot_s = g_r * s_r + g_g * s_g + g_b * s_b
    if g_d is not None:
        dot_s = dot_s + g_d * s_z
    t_k, behind = (quotients or _divide)(one_minus, (t_next, dot_s + g_bg))
    w = alpha * t_k
    dot_c = g_r * rgb[0] + g_g * rgb[1] + g_b * rgb[2]
    if g_d is not None:
        dot_c, s_z = dot_c + g_d * z, s_z + w * z
    d_alpha = jnp.where(hit, t_k * dot_c - behind, 0)
    sums = (s_r + w * rgb[0], s_g + w * rgb[1], s_b + w * rgb[2], s_z)
    return t_k, w, d_alpha, sums


def _divide(denominator, numerators):
    return tuple(x / denominator for x in numerators)


def walk(bins: TileBins, rgb, depth, trans, stop_at, g_color, g_trans, g_depth, pair_alpha,
         n_model: int):
    """(capacity, n_model + 4) gradient rows of every pair, walking all tiles back to front in
    lockstep (step s visits each tile's pair end − 1 − s).

    `pair_alpha(kk, g)` gives, for pair indices kk (n_tiles,) of Gaussians g, the forward's
    (α, hit) at every tile pixel (n_tiles, 256) and a function d_alpha -> n_model columns
    (n_tiles,): the α model's own parameters. The last four columns are ∂L/∂rgb and ∂L/∂z.
    trans, stop_at: the forward's final T and per-pixel stop pair index (n_tiles, 256); a pair
    counts at a pixel only before its stop. g_*: cotangents of the per-tile colour, T, depth.
    """
    dt = trans.dtype
    cap = bins.gauss.shape[0]
    start, end = bins.tile_start, bins.tile_end
    cot = (g_color[..., 0], g_color[..., 1], g_color[..., 2], g_depth, g_trans * trans)

    def body(carry):
        s, t_next, sums, rows = carry
        k = end - 1 - s
        active = k >= start
        kk = jnp.clip(k, 0, cap - 1)
        g = bins.gauss[kk]
        c, z = rgb[g], depth[g][:, None]
        alpha, hit, model_grads = pair_alpha(kk, g)
        hit = hit & active[:, None] & (k[:, None] < stop_at)
        t, w, d_alpha, sums = walk_step(t_next, alpha, hit, [c[:, None, i] for i in range(3)], z,
                                        sums, cot)
        row = jnp.stack(model_grads(d_alpha) + [
            jnp.sum(w * cot[0], -1), jnp.sum(w * cot[1], -1), jnp.sum(w * cot[2], -1),  # ∂/∂rgb
            jnp.sum(w * g_depth, -1),  # ∂/∂z
        ], -1)
        slot = jnp.where(active, k, cap)  # each tile's own pair: distinct slots, plain stores
        rows = rows.at[slot].set(row, mode="drop", unique_indices=True)
        return s + 1, t, sums, rows

    zero = jnp.zeros(trans.shape, dt)
    init = (jnp.int32(0), trans, (zero,) * 4, jnp.zeros((cap, n_model + 4), dt))
    return lax.while_loop(lambda c: c[0] < jnp.max(end - start), body, init)[3]


def difference_alpha(mean2d, mean2d_lo, conic, opacity, pixels, config: RasterConfig,
                     gate=None):
    """The walk's `pair_alpha` of the difference form (lgs_jax.alpha.difference, at the
    offsets `composite.centre_offsets`): six model columns, ∂L/∂(μx, μy, a, b, c, o).
    `gate(kk)` (optional): which pixels a pair may touch."""
    px, py = pixels
    cap = jnp.asarray(config.alpha_cap, mean2d.dtype)

    def pair_alpha(kk, g):
        m, lo, q, o = mean2d[g], mean2d_lo[g], conic[g], opacity[g][:, None]
        d = centre_offsets((m[:, 0:1], m[:, 1:2]), (lo[:, 0:1], lo[:, 1:2]), px, py)
        conic_g = (q[:, 0:1], q[:, 1:2], q[:, 2:3])
        alpha, hit, power = alpha_model.difference(d, conic_g, o, cap)
        if gate is not None:
            hit = hit & gate(kk)

        def grads(d_alpha):
            return [jnp.sum(col, -1) for col in alpha_model.difference_vjp(
                d_alpha, alpha, power, d, conic_g, o, cap)]

        return alpha, hit, grads

    return pair_alpha


def hoisted_alpha(vectors, basis, config: RasterConfig, gate=None):
    """The walk's `pair_alpha` of the hoisted form (lgs_jax.alpha.hoisted, raw = V·B as
    `hoist.dot_basis`): seven model columns, ∂L/∂V (Eq. 8's six components, ∂(V·B)/∂V = B) and
    ∂L/∂ln o (where the clamp binds). vectors: (capacity, 7) from
    `lgs_jax.pairs.hoisted_vectors`; basis: (n_tiles, 256, 6)."""
    cap = jnp.asarray(config.alpha_cap, vectors.dtype)

    def pair_alpha(kk, g):
        v = vectors[kk]
        raw = hoist.dot_basis(v[:, None, :6], basis)
        alpha, hit, ln_a = alpha_model.hoisted(raw, v[:, 6:7], cap)
        if gate is not None:
            hit = hit & gate(kk)

        def grads(d_alpha):
            d_raw, d_ln_o = alpha_model.hoisted_vjp(d_alpha, alpha, ln_a, raw, v[:, 6:7], cap)
            return [jnp.sum(d_raw * basis[..., i], -1) for i in range(6)] + [jnp.sum(d_ln_o, -1)]

        return alpha, hit, grads

    return pair_alpha


def pair_rows(fields, bins: TileBins, pixels, config: RasterConfig, trans, stop_at, g_color,
              g_trans, g_depth):
    """(capacity, PAIR_COLUMNS) gradient rows of the difference form (the reference backend).
    fields = (mean2d, mean2d_lo, conic, opacity, rgb, depth); pixels = (px, py),
    (n_tiles, 256)."""
    mean2d, mean2d_lo, conic, opacity, rgb, depth = fields
    return walk(bins, rgb, depth, trans, stop_at, g_color, g_trans, g_depth,
                difference_alpha(mean2d, mean2d_lo, conic, opacity, pixels, config), 6)


SUM_CHUNK = 16  # rows summed sequentially per chunk in `segment_sums`


def _segmented_scan(starts, vals):
    """Inclusive scan of vals restarting where `starts` is set (fixed association)."""
    def combine(left, right):
        (fl, vl), (fr, vr) = left, right
        return fl | fr, jnp.where(fr[..., None], vr, vl + vr)

    return lax.associative_scan(combine, (starts, vals))[1]


def segment_sums(ids, vals, n: int):
    """Σ of the rows `vals` (rows, C) per id (n, C), for ids whose equal values are contiguous
    (each id one run; rows with id n are dropped; ids without rows get zero), deterministically
    (no scatter-add, a fixed association): a segmented sum in two levels. Within chunks of
    SUM_CHUNK consecutive rows, left to right (one fused pass over the rows); across chunks, a
    segmented scan of the chunks' last partial sums (1/SUM_CHUNK of the rows), whose carry is
    added to the rows of the segment still open at a chunk's start. One store per segment end
    (one run per id: distinct targets). A segmented scan over all rows costs log2(rows) passes
    over them; this costs one, plus that scan over the chunk tails."""
    m, cols = vals.shape
    pad = -m % SUM_CHUNK  # padding rows: id n (dropped at the end), zero
    ids = jnp.concatenate([ids, jnp.full((pad,), n, ids.dtype)])
    vals = jnp.concatenate([vals, jnp.zeros((pad, cols), vals.dtype)])
    ids2, vals3 = ids.reshape(-1, SUM_CHUNK), vals.reshape(-1, SUM_CHUNK, cols)
    acc, within = vals3[:, 0], [vals3[:, 0]]
    for i in range(1, SUM_CHUNK):  # sequential within each chunk
        acc = jnp.where((ids2[:, i] == ids2[:, i - 1])[:, None], acc + vals3[:, i], vals3[:, i])
        within.append(acc)
    within = jnp.stack(within, 1)
    tail_ids = ids2[:, -1]
    tail_sums = _segmented_scan(jnp.concatenate([jnp.ones((1,), bool),
                                                 tail_ids[1:] != tail_ids[:-1]]), within[:, -1])
    open_at_start = tail_ids[:-1] == ids2[1:, 0]  # chunk k continues chunk k − 1's segment
    carry = jnp.concatenate([jnp.zeros((1, cols), vals.dtype),
                             jnp.where(open_at_start[:, None], tail_sums[:-1], 0)])
    in_open = (ids2 == ids2[:, :1])[..., None]
    sums = (within + jnp.where(in_open, carry[:, None, :], 0)).reshape(-1, cols)
    ends = jnp.concatenate([ids[1:] != ids[:-1], jnp.ones((1,), bool)])
    target = jnp.where(ends, ids, n)
    return jnp.zeros((n, cols), vals.dtype).at[target].set(sums, mode="drop",
                                                          unique_indices=True)


def per_gaussian_sum(rows, bins: TileBins, n: int):
    """Σ of the pair rows (capacity, C), in the bins' sorted pair order, per Gaussian (n, C):
    the rows put back in emission order (`TileBins.slot`'s inverse permutation: a plain int32
    store, one writer per slot, then one gather of the rows), where each Gaussian's pairs are
    one run in ascending tile order, then `segment_sums` (padding pairs, tile == n_tiles,
    dropped). Deterministic: no sort, no scatter-add."""
    cap = rows.shape[0]
    inv = jnp.zeros((cap,), jnp.int32).at[bins.slot].set(jnp.arange(cap, dtype=jnp.int32),
                                                          unique_indices=True)
    ids = jnp.where(bins.tile[inv] < bins.tile_start.shape[0], bins.gauss[inv], n)
    return segment_sums(ids, rows[inv], n)


def depth_cotangent(g_depth, trans):
    """ḡ_D as an array: zeros shaped as `trans` where it is None (a symbolic zero:
    lgs_jax.backends.custom_vjp)."""
    return jnp.zeros_like(trans) if g_depth is None else g_depth
