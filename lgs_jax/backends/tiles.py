"""`tiles` backend: the Local-GS rasterizer (Sec. III) as jitted JAX.

Layout. The screen is 16x16 tiles; each tile is eight 16x2 strips, each strip the 32 pixels of
one warp. A strip owns a list of Gaussians in (depth, index) order: with `warp_cull` the tile's
pairs whose strip-mask bit is set (emitted once by prefix counts and a store to distinct slots),
otherwise the tile's whole list.

Work scales with the pairs a scene has, not with its worst tile: strips are sorted by list
length and processed in groups of GROUP strips; a group runs only as many CHUNK-Gaussian steps as
its longest list needs (empty strips run none) and stops early once all its pixels are done.

Per staged chunk, ln α for GROUP x 32 pixels x CHUNK Gaussians is the pixel basis times the
hoisted vectors (Eq. 9–10) as six fused elementwise products (`hoist.dot_basis`: no matrix unit,
so no TF32 on GPUs, and the backward reproduces the forward's bits under any batching), or the
difference form when `hoist` is off; the chunk is then blended in order (Algorithm 1,
`blend_chunk`):

  exact: per-pixel semantics of the contract: a pixel stops at the first Gaussian with
         T·(1 − α) < 1e-4 (which is not blended); alpha tests are masks.
  fast:  the paper's warp-coherent blending (w = α·T; C += f·w; T −= w, Sec. III-D): no
         per-pixel stop; a strip stops when all 32 pixels have T < 1e-4 (checked per chunk).

Bound on `fast` (derived here, tested in tests/test_tiles.py). Until the exact pixel's stop at
Gaussian k*, both modes blend the same Gaussians. The exact pixel then keeps T_e = T_{k*}, with
T_{k*}·(1 − α_{k*}) < 1e-4, so T_e < 1e-4 / (1 − cap). The fast pixel additionally blends weights
w_j (j >= k*) with Σ w_j <= T_e, moving colour from background to those Gaussians:

  |image_fast − image_exact| <= T_e · max_j |rgb_j − background| < 1e-4/(1 − cap) · max|rgb − bg|
  |alpha_fast − alpha_exact| < 1e-4/(1 − cap),  |depth_fast − depth_exact| < 1e-4/(1 − cap)·max z

i.e. 0.01 (3dgs, cap 0.99) or 0.1 (gsplat, cap 0.999) times the colour range, plus rounding.

Differentiable: `rasterize` is a custom_vjp. The forward records where each pixel stopped (the
pair whose stop test fired, or the first pair its strip never processed); the backward
(lgs_jax.backends.backward.walk) walks each tile back to front with the same α model — V·B
clamped at ln o (`hoisted_alpha`) or the difference form — gated by the same strip masks, and
chains ∂L/∂V to the Gaussian through Eq. 8.

The hoisted forms clamp ln α at ln o (its exact maximum) instead of the difference form's
`power > 0` skip: in the expanded form that skip would fire on rounding at Gaussian centres.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax import lax

from .. import hoist
from ..binning import TILE, TileBins, padded_ellipse, tile_grid
from ..composite import PixelState, blend_weights, gaussian_alpha, passes, stops
from ..config import ALPHA_MIN, RasterConfig
from ..projection import Projected
from ..warp_masks import FULL_MASK, STRIPS, strip_mask
from . import backward
from .reference import tile_pixels, tiles_to_image

GROUP = 256  # strips processed together
CHUNK = 16  # Gaussians per staged batch
STRIP_PIXELS = 2 * TILE


def _origin_offset(config: RasterConfig) -> float:
    """Offset of the tile-local origin from the tile corner, in pixels (both axes)."""
    return TILE / 2 if config.origin == "center" else 0.0


def tile_origin(tile_x, tile_y, config: RasterConfig, dtype):
    """Origin T of the hoisting frame (Eq. 1): tile corner or centre; (0, 0) for global coords."""
    if not config.local_coords:
        return jnp.zeros(jnp.shape(tile_x) + (2,), dtype)
    off = _origin_offset(config)
    return jnp.stack([tile_x * TILE + off, tile_y * TILE + off], -1).astype(dtype)


def pair_masks(p: Projected, bins: TileBins, tiles_x: int, config: RasterConfig):
    """Strip masks of every pair (FULL_MASK for Gaussians the binning could not bound)."""
    dt = p.mean2d.dtype
    u = jnp.finfo(dt).eps / 2
    e = padded_ellipse(p)
    g, t = bins.gauss, bins.tile
    tx, ty = t % tiles_x, t // tiles_x
    tau = e.tau_pad[g]
    if config.hoist:
        origin = tile_origin(tx, ty, config, dt)
        corner = jnp.stack([tx * TILE, ty * TILE], -1).astype(dt)
        reach = jnp.maximum(jnp.abs(corner + 0.5 - origin), jnp.abs(corner + TILE - 0.5 - origin))
        err = hoist.error_bound(p.mean2d[g], p.conic[g], jnp.log(p.opacity[g]), origin,
                                reach[:, 0], reach[:, 1], 16 * u)
        tau = jnp.maximum(tau, e.tau[g] * (1 + 4 * u) + 128 * u + 2 * err)
    mask = strip_mask(p.mean2d[g], p.conic[g], tau, e.det_lo[g], tx, ty)
    mask = jnp.where(e.unbounded[g], FULL_MASK, mask)
    return jnp.where(t < bins.tile_start.shape[0], mask, 0)


def pair_vectors(p: Projected, bins: TileBins, tiles_x: int, config: RasterConfig):
    """What each pair stages (capacity, 7): the hoisted V (Eq. 8) relative to its tile's origin,
    then ln o (the clamp of ln α)."""
    g, t = bins.gauss, bins.tile
    origin = tile_origin(t % tiles_x, t // tiles_x, config, p.mean2d.dtype)
    log_o = jnp.log(p.opacity[g])
    return jnp.concatenate([hoist.hoist(p.mean2d[g], p.conic[g], log_o, origin),
                            log_o[:, None]], -1)


def pixel_basis(lx, ly, px, py, config: RasterConfig):
    """Pixel basis (Eq. 9) in the hoisting frame, from tile-local (lx, ly) and global (px, py)
    pixel centres; None without hoisting."""
    if not config.hoist:
        return None
    if not config.local_coords:
        return hoist.basis(px, py)
    off = _origin_offset(config)  # x' = pixel − origin: exact in any float
    return hoist.basis(lx - off, ly - off)


def evaluate(p: Projected, g, v, basis, px, py, config: RasterConfig):
    """(α, hit) of Gaussians g (n, G) at the pixels of n strips (n, P): arrays (G, n, P).

    hoist: with v (n, G, 7) from `pair_vectors`, ln α = basis·V (Eq. 10, `hoist.dot_basis`),
    clamped at ln o; α = min(cap, e^{ln α});
    hit = ln α >= ln(1/255) (the test in the log domain). Difference form otherwise, exactly as
    lgs_jax.composite: hit = power <= 0 and α >= 1/255.
    """
    dt = p.mean2d.dtype
    cap = jnp.asarray(config.alpha_cap, dt)
    if config.hoist:
        ln_a = hoist.dot_basis(jnp.swapaxes(v, 0, 1)[:, :, None, :6], basis[None])
        ln_a = jnp.minimum(ln_a, v[..., 6].T[:, :, None])
        return jnp.minimum(cap, jnp.exp(ln_a)), ln_a >= jnp.log(jnp.asarray(ALPHA_MIN, dt))
    m, q = jnp.swapaxes(p.mean2d[g], 0, 1), jnp.swapaxes(p.conic[g], 0, 1)  # (G, n, ...)
    power, alpha = gaussian_alpha((m[:, :, None, 0], m[:, :, None, 1]),
                                  tuple(q[:, :, None, i] for i in range(3)),
                                  p.opacity[g].T[:, :, None], px[None], py[None], cap)
    return alpha, passes(power, alpha)


def blend_chunk(state: PixelState, stop_at, alpha, hit, feats, pair, config: RasterConfig):
    """Blend a chunk of Gaussians, in order, over strips of pixels (Algorithm 1).

    alpha, hit: (G, n, P) per Gaussian and pixel (Gaussian-major); feats: (G, n, 4) colour and
    depth per Gaussian; pair: (G, n) their pair indices. A `lax.scan` over the G Gaussians: each
    step is one fused elementwise pass over the n·P pixels. Returns the state and `stop_at`
    (n, P), updated with the pair index at which a pixel's stop test fired (for the backward).

    Exact or fast blending by `composite.blend_weights`; fast has no per-pixel stop: the caller
    ends a strip when all its pixels have T < 1e-4.
    """
    def step(carry, x):
        st, stop_at = carry
        a, h, f, k = x
        f = f[:, None, :]  # (n, 1, 4)
        exact = config.blend == "exact"
        w, trans, stopped = blend_weights(st.trans, a, h & ~st.done if exact else h, config)
        done = st.done
        if exact:
            done, stop_at = done | stopped, jnp.where(stopped, k[:, None], stop_at)
        return (PixelState(color=st.color + w[..., None] * f[..., :3], trans=trans,
                           depth=st.depth + w * f[..., 3], done=done), stop_at), None

    return lax.scan(step, (state, stop_at), (alpha, hit, feats, pair))[0]


def strip_lists(bins: TileBins, masks, warp_cull: bool):
    """Per strip (n_tiles·8, tile-major): list length and a function (sid, j) -> pair index.

    With warp_cull, strip s's list is its tile's pairs with bit s set, in order. They are emitted
    once into a buffer of 8·capacity slots: pair k goes to slot strip_start + (number of earlier
    pairs of the tile with bit s set), an exclusive prefix count. Every written slot is distinct,
    so the scatter is a plain deterministic store (no accumulation, no atomics).
    """
    start, end = bins.tile_start, bins.tile_end
    if not warp_cull:
        counts = jnp.repeat(end - start, STRIPS)
        base = jnp.repeat(start, STRIPS)
        return counts, lambda sid, j: base[sid][:, None] + j
    cap = bins.gauss.shape[0]
    if STRIPS * cap >= 2**31:
        raise ValueError(f"capacity: {cap} is too large for warp_cull strip lists (< 2^28)")
    n_tiles = start.shape[0]
    bits = (masks[None, :] >> jnp.arange(STRIPS, dtype=jnp.int32)[:, None]) & 1  # (8, cap)
    before = jnp.cumsum(bits, axis=1, dtype=jnp.int32) - bits  # exclusive prefix count
    before_end = jnp.concatenate([before, (before[:, -1] + bits[:, -1])[:, None]], axis=1)
    row = jnp.arange(STRIPS, dtype=jnp.int32)
    base = before_end[row[None, :], start[:, None]]  # (n_tiles, 8)
    counts = (before_end[row[None, :], end[:, None]] - base).reshape(-1)
    strip_start = jnp.cumsum(counts, dtype=jnp.int32) - counts
    tile = jnp.minimum(bins.tile, n_tiles - 1)
    sid = tile[None, :] * STRIPS + row[:, None]  # (8, cap)
    slot = strip_start[sid] + before - base.reshape(-1)[sid]
    slot = jnp.where(bits == 1, slot, STRIPS * cap)  # cleared bits: dropped
    pair = jnp.broadcast_to(jnp.arange(cap, dtype=jnp.int32), (STRIPS, cap))
    lists = jnp.zeros(STRIPS * cap, jnp.int32).at[slot.reshape(-1)].set(
        pair.reshape(-1), mode="drop", unique_indices=True)
    return counts, lambda sid, j: lists[jnp.minimum(strip_start[sid][:, None] + j,
                                                    STRIPS * cap - 1)]


def _strip_pixels(sid, tiles_x: int, dtype):
    """Pixel centres of strips `sid`, each (n, 32), row-major within a strip: tile-local
    (lx, ly) relative to the tile corner, and global (px, py)."""
    t, s = sid // STRIPS, sid % STRIPS
    k = jnp.arange(STRIP_PIXELS)
    lx = jnp.broadcast_to(k % TILE, (sid.shape[0], STRIP_PIXELS)) + 0.5
    ly = 2 * s[:, None] + k // TILE + 0.5
    px = (t % tiles_x)[:, None] * TILE + lx
    py = (t // tiles_x)[:, None] * TILE + ly
    return tuple(v.astype(dtype) for v in (lx, ly, px, py))


def _forward(p: Projected, bins: TileBins, width: int, height: int, config: RasterConfig):
    """Per tile (n_tiles, 256): the state, each pixel's stop pair index (the pair whose stop test
    fired, or the first pair its strip never processed; capacity if neither), the number of
    strip–Gaussian pairs, and (masks, pair vectors) for the backward (None where switched off)."""
    dt = p.mean2d.dtype
    cap = bins.gauss.shape[0]
    tiles_x, tiles_y = tile_grid(width, height)
    n_strips = tiles_x * tiles_y * STRIPS
    n_groups = -(-n_strips // GROUP)

    masks = None
    if config.warp_cull:
        # Materialise the masks once: fused into their (8, capacity) consumers, XLA would
        # recompute the tight box for every strip bit (measured 4x slower on CPU).
        masks = lax.optimization_barrier(pair_masks(p, bins, tiles_x, config))
    counts, lookup = strip_lists(bins, masks, config.warp_cull)
    order = jnp.argsort(-counts, stable=True).astype(jnp.int32)
    order = jnp.concatenate([order, jnp.zeros(n_groups * GROUP - n_strips, jnp.int32)])
    counts_sorted = jnp.concatenate([counts[order[:n_strips]],
                                     jnp.zeros(n_groups * GROUP - n_strips, jnp.int32)])
    pair_v = pair_vectors(p, bins, tiles_x, config) if config.hoist else None
    feats = jnp.concatenate([p.rgb, p.depth[:, None]], -1)  # (N, 4): colour and depth

    def run_group(gi):
        sid = lax.dynamic_slice(order, (gi * GROUP,), (GROUP,))
        cnt = lax.dynamic_slice(counts_sorted, (gi * GROUP,), (GROUP,))
        lx, ly, px, py = _strip_pixels(sid, tiles_x, dt)
        basis = pixel_basis(lx, ly, px, py, config)
        n_chunks = (cnt[0] + CHUNK - 1) // CHUNK

        def active(c, state):
            more = c * CHUNK < cnt
            if config.blend == "exact":
                return more & ~jnp.all(state.done, -1)
            return more & ~jnp.all(stops(state.trans, config), -1)

        def record_strip_stops(c, state, stop_at):
            """Strips that stopped with pairs left: those pairs were never blended."""
            left = (c * CHUNK < cnt) & ~active(c, state)
            first = jnp.clip(lookup(sid, jnp.full((GROUP, 1), c * CHUNK)), 0, cap - 1)
            return jnp.where(left[:, None] & (stop_at == cap), first, stop_at)

        def cond(carry):
            c, state, _ = carry
            return (c < n_chunks) & jnp.any(active(c, state))

        def body(carry):
            c, state, stop_at = carry
            stop_at = record_strip_stops(c, state, stop_at)
            j = c * CHUNK + jnp.arange(CHUNK, dtype=jnp.int32)
            valid = (j[None, :] < cnt[:, None]) & active(c, state)[:, None]
            k = jnp.clip(lookup(sid, j[None, :]), 0, cap - 1)  # (GROUP, CHUNK)
            g = bins.gauss[k]
            alpha, hit = evaluate(p, g, pair_v[k] if config.hoist else None, basis, px, py,
                                  config)
            hit = hit & valid.T[:, :, None]
            state, stop_at = blend_chunk(state, stop_at, alpha, hit, feats[g.T], k.T, config)
            return c + 1, state, stop_at

        init = (jnp.int32(0), PixelState.empty((GROUP, STRIP_PIXELS), dt),
                jnp.full((GROUP, STRIP_PIXELS), cap, jnp.int32))
        c, state, stop_at = lax.while_loop(cond, body, init)
        return state, record_strip_stops(c, state, stop_at)

    def group_cond(carry):
        gi, _ = carry
        return (gi < n_groups) & (counts_sorted[jnp.minimum(gi, n_groups - 1) * GROUP] > 0)

    def group_body(carry):
        gi, out = carry
        out = jax.tree.map(lambda o, s: lax.dynamic_update_slice_in_dim(o, s, gi * GROUP, 0),
                           out, run_group(gi))
        return gi + 1, out

    out = (PixelState.empty((n_groups * GROUP, STRIP_PIXELS), dt),
           jnp.full((n_groups * GROUP, STRIP_PIXELS), cap, jnp.int32))
    out = lax.while_loop(group_cond, group_body, (jnp.int32(0), out))[1]
    inverse = jnp.argsort(order[:n_strips]).astype(jnp.int32)  # strip id -> sorted position
    # (n_strips, 32) in tile-major strip order is exactly (n_tiles, 16 rows, 16 cols) per tile.
    state, stop_at = jax.tree.map(lambda x: x[inverse].reshape((tiles_x * tiles_y, TILE * TILE)
                                                               + x.shape[2:]), out)
    return state, stop_at, jnp.sum(counts), (masks, pair_v)


def hoisted_alpha(vectors, basis, config: RasterConfig, gate=None):
    """The backward's `pair_alpha` (lgs_jax.backends.backward.walk) of the hoisted form:
    ln α = min(V·B, ln o) per pixel (Eq. 10), α = min(cap, e^{ln α}); seven model columns,
    ∂L/∂V (Eq. 8's six components, ∂(V·B)/∂V = B) and ∂L/∂ln o (where the clamp binds).
    vectors: (capacity, 7) from `pair_vectors`; basis: (n_tiles, 256, 6)."""
    dt = vectors.dtype
    alpha_cap = jnp.asarray(config.alpha_cap, dt)
    ln_min = jnp.log(jnp.asarray(ALPHA_MIN, dt))

    def pair_alpha(kk, g):
        v = vectors[kk]
        raw = hoist.dot_basis(v[:, None, :6], basis)
        ln_a = jnp.minimum(raw, v[:, 6:7])
        e = jnp.exp(ln_a)
        alpha, hit = jnp.minimum(alpha_cap, e), ln_a >= ln_min
        if gate is not None:
            hit = hit & gate(kk)

        def grads(d_alpha):
            d_ln = jnp.where(e < alpha_cap, d_alpha * alpha, 0)
            on_v = raw <= v[:, 6:7]
            d_raw = jnp.where(on_v, d_ln, 0)
            return ([jnp.sum(d_raw * basis[..., i], -1) for i in range(6)]
                    + [jnp.sum(jnp.where(on_v, 0, d_ln), -1)])

        return alpha, hit, grads

    return pair_alpha


def _gradients(p: Projected, bins: TileBins, width: int, height: int, config: RasterConfig,
               trans, stop_at, saved, cotangents):
    """(N, 10) per-Gaussian gradients of (mean2d, conic, opacity, rgb, depth): the backward walk
    with the forward's own arithmetic (hoisted or difference form) and its strip masks."""
    masks, pair_v = saved
    dt = p.mean2d.dtype
    tiles_x, _ = tile_grid(width, height)
    px, py = tile_pixels(width, height, dt)
    gate = None
    if config.warp_cull:
        strip = (jnp.arange(TILE * TILE) // STRIP_PIXELS).astype(jnp.int32)
        gate = lambda kk: ((masks[kk][:, None] >> strip[None]) & 1) == 1
    common = (bins, config, p.rgb, p.depth, trans, stop_at) + tuple(cotangents)
    if not config.hoist:
        rows = backward.walk(*common, backward.difference_alpha(
            p.mean2d, p.conic, p.opacity, (px, py), config, gate), 6)
    else:
        k = jnp.arange(TILE * TILE)
        lx = jnp.broadcast_to(k % TILE + 0.5, px.shape).astype(dt)
        ly = jnp.broadcast_to(k // TILE + 0.5, px.shape).astype(dt)
        basis = pixel_basis(lx, ly, px, py, config)
        rows = backward.walk(*common, hoisted_alpha(pair_v, basis, config, gate), 7)
        rows = chain_hoisted_rows(p, bins, rows, tiles_x, config)
    return backward.per_gaussian_sum(rows, bins.gauss, p.mean2d.shape[0])


def chain_hoisted_rows(p: Projected, bins: TileBins, rows, tiles_x: int, config: RasterConfig):
    """Pair rows (∂L/∂V, ∂L/∂ln o from the clamp, ∂L/∂rgb, ∂L/∂z: capacity x 11) chained to
    the pair's Gaussian through Eq. 8 (the vjp of `hoist.hoist`): (capacity, PAIR_COLUMNS)."""
    g, t = bins.gauss, bins.tile
    origin = tile_origin(t % tiles_x, t // tiles_x, config, p.mean2d.dtype)
    o = p.opacity[g]
    _, vjp = jax.vjp(lambda m, q, lo: hoist.hoist(m, q, lo, origin), p.mean2d[g], p.conic[g],
                     jnp.log(jnp.where(o > 0, o, 1)))
    d_mean, d_conic, d_log_o = vjp(rows[:, :6])
    d_o = jnp.where(o > 0, (d_log_o + rows[:, 6]) / jnp.where(o > 0, o, 1), 0)
    return jnp.concatenate([d_mean, d_conic, d_o[:, None], rows[:, 7:]], -1)


_composite = backward.differentiable(_forward, _gradients)


def rasterize(p: Projected, bins: TileBins, width: int, height: int,
              config: RasterConfig) -> tuple[PixelState, jax.Array]:
    """Returns the (H·W,) pixel state (differentiable: a custom_vjp whose backward walks each
    tile back to front with this backend's own α arithmetic and strip masks) and the number of
    strip–Gaussian pairs processed."""
    color, trans, depth, strip_pairs = _composite(p, bins, width, height, config)
    state = PixelState(color=color, trans=trans, depth=depth, done=jnp.zeros(trans.shape, bool))
    return jax.tree.map(lambda x: tiles_to_image(x, width, height), state), strip_pairs
