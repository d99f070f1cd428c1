"""`tiles` backend: the Local-GS rasterizer (Sec. III) as jitted JAX.

Layout. The screen is 16x16 tiles; each tile is eight 16x2 strips, each strip the 32 pixels of
one warp. A strip owns a list of Gaussians in (depth, index) order: with `warp_cull` the tile's
pairs whose strip-mask bit is set (emitted once by prefix counts and a store to distinct slots),
otherwise the tile's whole list.

Work scales with the pairs a scene has, not with its worst tile: strips are sorted by list
length and processed in groups of GROUP strips; a group runs only as many CHUNK-Gaussian steps
as its longest list needs (empty strips run none) and stops early once all its pixels are
done.

Per staged chunk, ln α for group x 32 pixels x chunk Gaussians is the pixel basis times the
hoisted vectors (Eq. 9–10) as six fused elementwise products (`hoist.dot_basis`: no matrix unit,
so no TF32 on GPUs, and the backward reproduces the forward's bits under any batching), or the
difference form when `hoist` is off; the chunk is then blended in order (Algorithm 1,
`blend_chunk`):

  exact: per-pixel semantics of the contract: a pixel stops at the first Gaussian with
         T·(1 − α) < 1e-4 (which is not blended); alpha tests are masks.
  fast:  the paper's warp-coherent blending (w = α·T; C += f·w; T −= w, Sec. III-D): no
         per-pixel stop; a strip stops when all 32 pixels have T < 1e-4 (checked per chunk).

Bound on `fast` (derived here, tested in tests/backends/test_tiles.py). Until the exact
pixel's stop at Gaussian k*, both modes blend the same Gaussians. The exact pixel then keeps
T_e = T_{k*}, with T_{k*}·(1 − α_{k*}) < 1e-4, so T_e < 1e-4 / (1 − cap). The fast pixel
additionally blends weights w_j (j >= k*) with Σ w_j <= T_e, moving colour from background to
those Gaussians:

  |image_fast − image_exact| <= T_e · max_j |rgb_j − background| < 1e-4/(1 − cap) · max|rgb − bg|
  |alpha_fast − alpha_exact| < 1e-4/(1 − cap),  |depth_fast − depth_exact| < 1e-4/(1 − cap)·max z

i.e. 0.01 (3dgs, cap 0.99) or 0.1 (gsplat, cap 0.999) times the colour range, plus rounding.

Differentiable: `rasterize` is a custom_vjp of `forward` and `gradients`. The forward records
where each pixel stopped (the pair whose stop test fired, or the first pair its strip never
processed); the backward (lgs_jax.backends.backward.walk) walks each tile back to front with the
same α model (lgs_jax.alpha: V·B clamped at ln o, or the difference form) gated by the same
strip masks, and chains ∂L/∂V to the Gaussian through Eq. 8 (lgs_jax.pairs.chain_hoisted_rows).
They are the plain-jnp counterparts of the Pallas kernels (lgs_jax.backends.pallas).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp
from jax import lax

from .. import alpha as alpha_model
from .. import hoist, pairs
from ..binning import TileBins
from ..composite import PixelState, blend_weights, centre_offsets, stops
from ..config import RasterConfig
from ..layout import (STRIP_PIXELS, STRIPS, TILE_PIXELS, frame, pixel_centres, strip_pixels,
                      tile_grid)
from ..projection import Projected
from . import backward
from .custom_vjp import differentiable
from .interface import Backend, BackendInputs, RasterResult, stop_within

GROUP = 256  # strips composited together
CHUNK = 16  # Gaussians per staged batch (fast blending tests its strip-wide stop once per batch)


@jax.tree_util.register_dataclass
@dataclasses.dataclass
class TilesStats:
    """The `tiles` backend's counts (`RenderStats.backend_stats`).

    Attributes:
      strip_pairs: strip–Gaussian pairs in the strips' lists (8·pairs without warp culling), so
        strip_pairs / (8·pairs) is the share of the work the strip masks keep.
    """

    strip_pairs: Any


def pixel_basis(lx, ly, px, py, config: RasterConfig):
    """Pixel basis (Eq. 9) in the hoisting frame (lgs_jax.layout.frame), from tile-local
    (lx, ly) and global (px, py) pixel centres; None without hoisting."""
    return hoist.basis(*frame(lx, ly, px, py, config)) if config.hoist else None


def evaluate(p: Projected, g, v, basis, px, py, config: RasterConfig):
    """(α, hit) of Gaussians g (n, G) at the pixels of n strips (n, P): arrays (G, n, P).

    hoist: with v (n, G, 7) from `pairs.hoisted_vectors`, raw = basis·V (Eq. 10,
    `hoist.dot_basis`) and `alpha.hoisted`. Otherwise the difference form, `alpha.difference`.
    """
    cap = jnp.asarray(config.alpha_cap, p.mean2d.dtype)
    if config.hoist:
        raw = hoist.dot_basis(jnp.swapaxes(v, 0, 1)[:, :, None, :6], basis[None])
        alpha, hit, _ = alpha_model.hoisted(raw, v[..., 6].T[:, :, None], cap)
        return alpha, hit
    m, lo, q = (jnp.swapaxes(x[g], 0, 1)[:, :, None]  # (G, n, 1, ...)
                for x in (p.mean2d, p.mean2d_lo, p.conic))
    d = centre_offsets((m[..., 0], m[..., 1]), (lo[..., 0], lo[..., 1]), px[None], py[None])
    alpha, hit, _ = alpha_model.difference(d, tuple(q[..., i] for i in range(3)),
                                           p.opacity[g].T[:, :, None], cap)
    return alpha, hit


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
        raise ValueError(f"backend='tiles' with warp_cull indexes strip lists of 8 x {cap} "
                         f"pair slots in int32, so it renders at most 2^28 tile-Gaussian pairs; "
                         f"use backend='pallas', or RasterConfig(warp_cull=False)")
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


def _strip_order(counts, group: int):
    """Strips by decreasing list length, padded to whole groups: (order, sorted counts,
    number of groups)."""
    n_strips = counts.shape[0]
    n_groups = -(-n_strips // group)
    pad = jnp.zeros(n_groups * group - n_strips, jnp.int32)
    order = jnp.argsort(-counts, stable=True).astype(jnp.int32)
    return (jnp.concatenate([order, pad]), jnp.concatenate([counts[order], pad]), n_groups)


def _run_group(sid, cnt, lookup, p: Projected, bins: TileBins, pair_v, feats, tiles_x: int,
               config: RasterConfig):
    """Composite one group of strips `sid` with list lengths `cnt` (sorted, longest first):
    chunks of CHUNK pairs while any strip of the group still blends. Returns the
    group's state and stop pairs (capacity where a strip ran through its list)."""
    dt = p.mean2d.dtype
    cap = bins.gauss.shape[0]
    group, chunk = sid.shape[0], CHUNK
    lx, ly, px, py = strip_pixels(sid, tiles_x, dt)
    basis = pixel_basis(lx, ly, px, py, config)
    n_chunks = (cnt[0] + chunk - 1) // chunk

    def active(c, state):
        more = c * chunk < cnt
        if config.blend == "exact":
            return more & ~jnp.all(state.done, -1)
        return more & ~jnp.all(stops(state.trans, config), -1)

    def record_strip_stops(c, state, stop_at):
        """Strips that stopped with pairs left: those pairs were never blended."""
        left = (c * chunk < cnt) & ~active(c, state)
        first = jnp.clip(lookup(sid, jnp.full((group, 1), c * chunk)), 0, cap - 1)
        return jnp.where(left[:, None] & (stop_at == cap), first, stop_at)

    def cond(carry):
        c, state, _ = carry
        return (c < n_chunks) & jnp.any(active(c, state))

    def body(carry):
        c, state, stop_at = carry
        stop_at = record_strip_stops(c, state, stop_at)
        j = c * chunk + jnp.arange(chunk, dtype=jnp.int32)
        valid = (j[None, :] < cnt[:, None]) & active(c, state)[:, None]
        k = jnp.clip(lookup(sid, j[None, :]), 0, cap - 1)  # (group, chunk)
        g = bins.gauss[k]
        alpha, hit = evaluate(p, g, pair_v[k] if config.hoist else None, basis, px, py, config)
        hit = hit & valid.T[:, :, None]
        state, stop_at = blend_chunk(state, stop_at, alpha, hit, feats[g.T], k.T, config)
        return c + 1, state, stop_at

    init = (jnp.int32(0), PixelState.empty((group, STRIP_PIXELS), dt),
            jnp.full((group, STRIP_PIXELS), cap, jnp.int32))
    c, state, stop_at = lax.while_loop(cond, body, init)
    return state, record_strip_stops(c, state, stop_at)


def forward(p: Projected, bins: TileBins, extra, width: int, height: int,
            config: RasterConfig):
    """Per tile (n_tiles, 256): the state, each pixel's stop pair index (the pair whose stop test
    fired, or the first pair its strip never processed; the tile's end if neither), the number
    of strip–Gaussian pairs, and (masks, pair vectors) for the backward (None where off).
    `extra` is unused (lgs_jax.backends.custom_vjp's signature)."""
    del extra
    dt = p.mean2d.dtype
    cap = bins.gauss.shape[0]
    group = GROUP
    tiles_x, tiles_y = tile_grid(width, height)
    n_strips = tiles_x * tiles_y * STRIPS
    masks = pair_v = None
    if config.warp_cull or config.hoist:
        pg = pairs.gather(p, bins.gauss)
    if config.warp_cull:
        # Materialise the masks once: fused into their (8, capacity) consumers, XLA would
        # recompute the tight box for every strip bit.
        masks = lax.optimization_barrier(pairs.strip_masks(pg, bins, tiles_x, config))
    if config.hoist:
        pair_v = pairs.hoisted_vectors(pg, bins, tiles_x, config)
    counts, lookup = strip_lists(bins, masks, config.warp_cull)
    order, counts_sorted, n_groups = _strip_order(counts, group)
    feats = jnp.concatenate([p.rgb, p.depth[:, None]], -1)  # (N, 4): colour and depth

    def group_cond(carry):
        gi, _ = carry
        return (gi < n_groups) & (counts_sorted[jnp.minimum(gi, n_groups - 1) * group] > 0)

    def group_body(carry):
        gi, out = carry
        sid = lax.dynamic_slice(order, (gi * group,), (group,))
        cnt = lax.dynamic_slice(counts_sorted, (gi * group,), (group,))
        done = _run_group(sid, cnt, lookup, p, bins, pair_v, feats, tiles_x, config)
        out = jax.tree.map(lambda o, x: lax.dynamic_update_slice_in_dim(o, x, gi * group, 0),
                           out, done)
        return gi + 1, out

    out = (PixelState.empty((n_groups * group, STRIP_PIXELS), dt),
           jnp.full((n_groups * group, STRIP_PIXELS), cap, jnp.int32))
    out = lax.while_loop(group_cond, group_body, (jnp.int32(0), out))[1]
    inverse = jnp.argsort(order[:n_strips]).astype(jnp.int32)  # strip id -> sorted position
    # (n_strips, 32) in tile-major strip order is exactly (n_tiles, 16 rows, 16 cols) per tile.
    state, stop_at = jax.tree.map(lambda x: x[inverse].reshape((tiles_x * tiles_y, TILE_PIXELS)
                                                               + x.shape[2:]), out)
    return state, stop_within(stop_at, bins.tile_end), jnp.sum(counts), (masks, pair_v)


def gradients(p: Projected, bins: TileBins, extra, width: int, height: int,
              config: RasterConfig, trans, stop_at, saved, cotangents):
    """(N, 10) per-Gaussian gradients of (mean2d, conic, opacity, rgb, depth): the backward walk
    with the forward's own arithmetic (hoisted or difference form) and its strip masks, from
    `forward`'s saved (masks, pair vectors), the final T and each pixel's stop pair."""
    del extra
    masks, pair_v = saved
    dt = p.mean2d.dtype
    tiles_x, tiles_y = tile_grid(width, height)
    tile = jnp.arange(tiles_x * tiles_y, dtype=jnp.int32)[:, None]
    k = jnp.arange(TILE_PIXELS, dtype=jnp.int32)
    lx, ly, px, py = pixel_centres(tile, k[None], tiles_x, dt)
    gate = None
    if config.warp_cull:
        strip = k // STRIP_PIXELS
        gate = lambda kk: ((masks[kk][:, None] >> strip[None]) & 1) == 1
    g_color, g_trans, g_depth = cotangents
    common = (bins, p.rgb, p.depth, trans, stop_at, g_color, g_trans,
              backward.depth_cotangent(g_depth, trans))
    if not config.hoist:
        rows = backward.walk(*common, backward.difference_alpha(
            p.mean2d, p.mean2d_lo, p.conic, p.opacity, (px, py), config, gate), 6)
    else:
        basis = pixel_basis(jnp.broadcast_to(lx, px.shape), jnp.broadcast_to(ly, px.shape), px,
                            py, config)
        rows = backward.walk(*common, backward.hoisted_alpha(pair_v, basis, config, gate), 7)
        rows = pairs.chain_hoisted_rows(pairs.gather(p, bins.gauss), bins, rows, tiles_x, config)
    return backward.per_gaussian_sum(rows, bins, p.mean2d.shape[0])


_composite = differentiable(forward, gradients)


def rasterize(p: Projected, bins: TileBins, width: int, height: int, config: RasterConfig,
              inputs: BackendInputs = BackendInputs()) -> RasterResult:
    """Composite every strip (differentiable: a custom_vjp whose backward walks each tile back
    to front with this backend's own α arithmetic and strip masks)."""
    del inputs
    color, trans, depth, stop, strip_pairs = _composite(p, bins, None, width, height, config)
    return RasterResult(color=color, trans=trans, depth=depth, stop=stop,
                        stats=TilesStats(strip_pairs=strip_pairs))


BACKEND = Backend("tiles", rasterize,
                  empty_stats=lambda config: TilesStats(strip_pairs=jnp.int32(0)))
