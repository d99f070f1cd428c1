"""`pallas` and `pallas_vanilla` backends: the rasterization stage as Pallas (Triton) kernels.

Projection, binning and sorting stay in XLA (shared with the `tiles` backend). The plain-jnp
counterpart of each kernel, which the tests compare them with, is `lgs_jax.backends.tiles` (same
masks, same hoisted arithmetic, same blending semantics) and `lgs_jax.backends.reference`
(per-pixel semantics).

Local-GS kernel (`backend="pallas"`, Sec. III): one program per 16x2 strip, `num_warps=1`, so a
program is one warp and its 32 lanes are the strip's pixels. It walks its tile's pairs in order,
reading one record per pair (`pair_records`): the hoisted 6-vector V (Eq. 8), built once per
(tile, Gaussian) pair relative to the tile origin, then ln o, colour and depth; each pixel
evaluates ln α as a 6-term sum in its local coordinates (Eq. 10). With `warp_cull` a pair whose
strip-mask bit is clear does not blend, and a staged group of pairs with no bit set is skipped
by one warp-uniform branch (Sec. III-C). The strip stops as a unit once every lane is done
(`exact`: each pixel's stop test fired; `fast`: every T below 1e-4, the paper's coherent
blending). Pairs are staged UNROLL["localgs"] at a time: their mask bits are fetched one
iteration ahead, the group's α are computed together (independent work that overlaps), then
blended in order, so the serial chain per pair is the blend alone.

Vanilla kernel (`backend="pallas_vanilla"`, the original 3DGS rasterizer): one program per 16x16
tile with 8 warps (256 lanes), the difference form, per-pixel termination, and a tile-wide early
exit when every pixel is done. It ignores the Local-GS switches (it is the baseline the paper
measures against) but honours `convention`.

Both use exact per-pixel blending semantics (lgs_jax.composite) unless `blend="fast"` (Local-GS
only). Programs run tiles in order of decreasing list length (longest-first scheduling: the
slowest programs start first and short ones fill in behind them; each writes its own output
row). Without a GPU the kernels run in Pallas interpret mode (slow, meant for tests);
`stats.kernel` names the kernel that ran, `stats.interpreted` says whether it was interpreted.
"""

from __future__ import annotations

import functools
import os

import jax
import jax.numpy as jnp
from jax import lax
from jax.experimental import pallas as pl

from .. import hoist
from ..binning import TILE, TileBins, tile_grid
from ..composite import PixelState, gaussian_alpha, passes, stops
from ..config import ALPHA_MIN, RasterConfig
from ..projection import Projected
from ..warp_masks import STRIPS
from .reference import tiles_to_image
from .tiles import _origin_offset, pair_masks, pair_vectors

UNROLL = {"localgs": 2, "vanilla": 8}  # pairs staged per iteration (scripts/kernel_profile.py)
STRIP_PIXELS = 2 * TILE
ROW = 12  # packed Gaussian row (vanilla): mean x, y; conic a, b, c; ln o; o; r, g, b; z; unused
REC = 12  # packed pair record (Local-GS): see `pair_records`
KERNELS = {"pallas": "localgs-triton", "pallas_vanilla": "vanilla-triton"}


def interpreted() -> bool:
    """Whether the kernels run in interpret mode (no GPU backend; LGS_JAX_PALLAS_LOWER=gpu forces
    GPU lowering, for `tests/test_pallas.py`'s lowering check on machines without a GPU)."""
    return jax.default_backend() != "gpu" and os.environ.get("LGS_JAX_PALLAS_LOWER") != "gpu"


def gaussian_rows(p: Projected):
    """(N, ROW) packed per-Gaussian data the vanilla kernel loads (through each pair's Gaussian
    id, as the original rasterizer does): one row per Gaussian."""
    o = p.opacity
    cols = [p.mean2d[:, 0], p.mean2d[:, 1], p.conic[:, 0], p.conic[:, 1], p.conic[:, 2],
            jnp.log(o), o, p.rgb[:, 0], p.rgb[:, 1], p.rgb[:, 2], p.depth, jnp.zeros_like(o)]
    return jnp.stack(cols, -1)


def pair_records(p: Projected, bins: TileBins, tiles_x: int, config: RasterConfig):
    """(capacity, REC) per-pair rows the Local-GS kernel loads, in pair order (no indirection).

    hoist: V (Eq. 8) relative to the pair's tile origin, ln o, rgb, z: the hoisted vector is
    built once per (tile, Gaussian) pair, as the paper stages it per tile, not once per strip.
    Otherwise the Gaussian's mean, conic and opacity, then rgb, z (the difference form).
    """
    g = bins.gauss
    if config.hoist:
        head = pair_vectors(p, bins, tiles_x, config)  # (capacity, 7): V, ln o
    else:
        head = jnp.concatenate([p.mean2d[g], p.conic[g], p.opacity[g, None],
                                jnp.zeros_like(p.opacity[g, None])], -1)
    tail = jnp.concatenate([p.rgb[g], p.depth[g, None], jnp.zeros_like(p.depth[g, None])], -1)
    return jnp.concatenate([head, tail], -1)


def _blend(state, alpha, hit, rgb, z, config: RasterConfig):
    """One Gaussian over a lane vector of pixels; state = (r, g, b, T, D, done).

    exact: the contract (lgs_jax.composite.blend): a hit whose T·(1 − α) passes the stop test
    ends the pixel unblended; otherwise C += rgb·α·T, T = T·(1 − α).
    fast: w = α·T; C += rgb·w; T −= w for every hit (Sec. III-D).
    """
    r, g, b, t, d, done = state
    if config.blend == "exact":
        hit = hit & ~done
        test_t = t * (1 - alpha)
        stop = stops(test_t, config)
        take = hit & ~stop
        w = jnp.where(take, alpha * t, 0)
        t, done = jnp.where(take, test_t, t), done | (hit & stop)
    else:
        w = jnp.where(hit, alpha * t, 0)
        t = t - w
    return r + w * rgb[0], g + w * rgb[1], b + w * rgb[2], t, d + w * z, done


def _running(state, config: RasterConfig):
    """Whether any lane still blends: the program-uniform loop condition."""
    if config.blend == "exact":
        return jnp.min(state[5].astype(jnp.int32)) == 0
    return jnp.min(stops(state[3], config).astype(jnp.int32)) == 0


def _staged_loop(start, end, state, fetch, pair_alpha, config: RasterConfig, unroll: int,
                 take=None):
    """Walk pairs [start, end) `unroll` at a time while some lane still blends.

    `fetch(j)` loads pair j's small index data (Gaussian id, mask bit) one iteration ahead.
    Each iteration evaluates its `unroll` pairs first (`pair_alpha(fetched) -> (α, hit, rgb, z)`,
    independent of the pixel state, so their loads and arithmetic overlap) and then blends them
    in order. `take(fetched)` (optional) says whether a pair concerns this program at all (its
    mask bit): pairs without it do not blend, and a group with none is skipped by one
    program-uniform branch.
    """
    def cond(carry):
        j, _, st = carry
        return (j < end) & _running(st, config)

    def body(carry):
        j, cur, st = carry
        nxt = [fetch(j + unroll + u) for u in range(unroll)]
        takes = [(j + u < end) & (True if take is None else take(cur[u])) for u in range(unroll)]

        def group(st):
            evaluated = [pair_alpha(f) for f in cur]
            for (alpha, hit, rgb, z), ok in zip(evaluated, takes):
                st = _blend(st, alpha, hit & ok, rgb, z, config)
            return st

        if take is None:
            return j + unroll, nxt, group(st)
        return j + unroll, nxt, lax.cond(functools.reduce(jnp.logical_or, takes), group,
                                         lambda st: st, st)

    first = [fetch(start + u) for u in range(unroll)]
    return lax.while_loop(cond, body, (start, first, state))[2]


def _empty(lanes: int, dt):
    """(r, g, b, T, D, done) of lanes with nothing blended (lgs_jax.composite.PixelState.empty)."""
    zero = jnp.zeros((lanes,), dt)
    return zero, zero, zero, jnp.ones((lanes,), dt), zero, jnp.zeros((lanes,), bool)


def _store(refs, row, state):
    """Write (r, g, b, T, D) to row `row` of the (programs, lanes) outputs."""
    for ref, x in zip(refs, state[:5]):
        ref[row, :] = x


def _localgs_kernel(order_ref, start_ref, end_ref, mask_ref, rec_ref, *out_refs,
                    config: RasterConfig, tiles_x: int, last_pair: int):
    dt = rec_ref.dtype
    pid = pl.program_id(0)
    tile, s = order_ref[pid // STRIPS], pid % STRIPS
    k = lax.iota(jnp.int32, STRIP_PIXELS)
    lx = (k % TILE).astype(dt) + 0.5  # tile-local pixel centres (exact in any float)
    ly = (2 * s + k // TILE).astype(dt) + 0.5
    corner_x, corner_y = ((tile % tiles_x) * TILE).astype(dt), ((tile // tiles_x) * TILE).astype(dt)
    if config.local_coords:
        off = _origin_offset(config)
        x, y = lx - off, ly - off
    else:
        x, y = corner_x + lx, corner_y + ly
    px, py = corner_x + lx, corner_y + ly
    cap = jnp.asarray(config.alpha_cap, dt)
    ln_min = jnp.log(jnp.asarray(ALPHA_MIN, dt))
    bit = jnp.left_shift(jnp.int32(1), s)

    def fetch(j):
        jj = jnp.minimum(j, last_pair)
        return jj, ((mask_ref[jj] & bit) != 0) if config.warp_cull else None

    def pair_alpha(fetched):
        rec = [rec_ref[fetched[0], c] for c in range(REC - 1)]
        if config.hoist:  # V (Eq. 8), hoisted once per pair: ln α = V·B (Eq. 10) <= ln o
            ln_a = jnp.minimum(hoist.evaluate_terms(rec[:6], x, y), rec[6])
            alpha, hit = jnp.minimum(cap, jnp.exp(ln_a)), ln_a >= ln_min
        else:
            power, alpha = gaussian_alpha(rec[0:2], rec[2:5], rec[5], px, py, cap)
            hit = passes(power, alpha)
        return alpha, hit, rec[7:10], rec[10]

    # With warp culling, the strip's mask bit decides (a warp-uniform branch, Sec. III-C).
    take = (lambda fetched: fetched[1]) if config.warp_cull else None
    _store(out_refs, tile * STRIPS + s,
           _staged_loop(start_ref[tile], end_ref[tile], _empty(STRIP_PIXELS, dt), fetch,
                        pair_alpha, config, UNROLL["localgs"], take))


def _vanilla_kernel(order_ref, start_ref, end_ref, gauss_ref, rows_ref, *out_refs,
                    config: RasterConfig, tiles_x: int, last_pair: int):
    dt = rows_ref.dtype
    tile = order_ref[pl.program_id(0)]
    k = lax.iota(jnp.int32, TILE * TILE)
    px = ((tile % tiles_x) * TILE + k % TILE).astype(dt) + 0.5
    py = ((tile // tiles_x) * TILE + k // TILE).astype(dt) + 0.5
    cap = jnp.asarray(config.alpha_cap, dt)

    def fetch(j):
        return gauss_ref[jnp.minimum(j, last_pair)]

    def pair_alpha(gi):
        row = [rows_ref[gi, c] for c in range(ROW - 1)]
        power, alpha = gaussian_alpha(row[0:2], row[2:5], row[6], px, py, cap)
        return alpha, passes(power, alpha), row[7:10], row[10]

    _store(out_refs, tile, _staged_loop(start_ref[tile], end_ref[tile], _empty(TILE * TILE, dt),
                                        fetch, pair_alpha, config, UNROLL["vanilla"]))


def _call(kernel, n_programs: int, lanes: int, num_warps: int, dt, args):
    from jax.experimental.pallas import triton as pl_triton

    out = jax.ShapeDtypeStruct((n_programs, lanes), dt)  # each program writes its own row
    return pl.pallas_call(
        kernel, out_shape=[out] * 5, grid=(n_programs,),
        compiler_params=pl_triton.CompilerParams(num_warps=num_warps, num_stages=1),
        interpret=interpreted(), name=kernel.func.__name__.strip("_"),
    )(*args)


def rasterize(p: Projected, bins: TileBins, width: int, height: int, config: RasterConfig,
              vanilla: bool = False) -> tuple[PixelState, jax.Array]:
    """Returns the (H·W,) pixel state and the strip–Gaussian pairs the kernel had to visit
    (with warp culling: the pairs' set mask bits; otherwise 8 per pair)."""
    dt = p.mean2d.dtype
    tiles_x, tiles_y = tile_grid(width, height)
    n_tiles = tiles_x * tiles_y
    last_pair = bins.gauss.shape[0] - 1
    valid_pair = bins.tile < n_tiles
    # Longest lists first: the programs that take longest start first, the short ones fill in.
    order = jnp.argsort(bins.tile_start - bins.tile_end, stable=True).astype(jnp.int32)
    if vanilla:
        kernel = functools.partial(_vanilla_kernel, config=config, tiles_x=tiles_x,
                                   last_pair=last_pair)
        outs = _call(kernel, n_tiles, TILE * TILE, 8, dt,
                     (order, bins.tile_start, bins.tile_end, bins.gauss, gaussian_rows(p)))
        strip_pairs = STRIPS * jnp.sum(valid_pair, dtype=jnp.int32)
    else:
        if config.warp_cull:
            masks = pair_masks(p, bins, tiles_x, config)
            strip_pairs = jnp.sum(lax.population_count(masks), dtype=jnp.int32)
        else:
            masks = jnp.zeros((1,), jnp.int32)
            strip_pairs = STRIPS * jnp.sum(valid_pair, dtype=jnp.int32)
        kernel = functools.partial(_localgs_kernel, config=config, tiles_x=tiles_x,
                                   last_pair=last_pair)
        outs = _call(kernel, n_tiles * STRIPS, STRIP_PIXELS, 1, dt,
                     (order, bins.tile_start, bins.tile_end, masks,
                      pair_records(p, bins, tiles_x, config)))
    # (n_strips, 32) in tile-major strip order is exactly (n_tiles, 16 rows, 16 cols) per tile.
    r, g, b, t, d = (x.reshape(n_tiles, TILE * TILE) for x in outs)
    state = PixelState(color=jnp.stack([r, g, b], -1), trans=t, depth=d,
                       done=jnp.zeros(t.shape, bool))
    return jax.tree.map(lambda x: tiles_to_image(x, width, height), state), strip_pairs
