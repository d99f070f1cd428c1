"""`pallas` and `pallas_vanilla` backends: the rasterization stage as Pallas (Triton) kernels,
forward and backward.

Projection, binning and sorting stay in XLA (shared with the `tiles` backend). The plain-jnp
counterpart of each kernel, which the tests compare them with, is `lgs_jax.backends.tiles` (same
masks, same hoisted arithmetic, same blending semantics, same backward walk) and
`lgs_jax.backends.reference` (per-pixel semantics).

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
measures against) but honours `convention` and `blend`.

Both use exact per-pixel blending semantics (lgs_jax.composite) unless `blend="fast"`. Programs
run tiles in order of decreasing list length (longest-first scheduling: the slowest programs
start first and short ones fill in behind them; each writes its own output row). Both kernels
also write each pixel's stop pair (the pair whose stop test fired, or the first pair its program
never processed), which is all the backward needs besides the final T.

Backward kernel (both backends): one program per tile, 256 lanes (8 warps), walking the tile's
pairs back to front from the last pair any pixel blended, with the forward's own α arithmetic
(hoisted V·B clamped at ln o, or the difference form) and strip masks: the walk of
lgs_jax.backends.backward (equations there), one pair per step (`_backward_step`). Per pair, the
per-pixel gradient terms are reduced over the tile in one (256, 16) column reduction and stored
as that pair's row: each pair belongs to one tile, so every row has one writer (no atomics; rows
of pairs never visited stay zero). Rows are then chained to the Gaussian (Eq. 8 for the hoisted
form, `tiles.chain_hoisted_rows`) and summed per Gaussian by `backward.per_gaussian_sum` (sort +
segmented scan): deterministic.

Implementations. Each kernel, forward and backward, also exists on Mosaic GPU
(`lgs_jax.backends.mosaic`: a warpgroup per tile or half tile, the same per-pair functions);
`RasterConfig.kernel` picks one and "auto" takes `auto`: on the GPU `IMPL`, the faster per
kernel on the H100 (BENCHMARKS.md §6), in interpret mode Triton; under differentiation "auto"
runs the forward of the backward's implementation (`_forward_for_gradients`). Without a GPU
the kernels run in Pallas interpret mode (slow, meant for tests); `stats.kernel` names the
forward kernel that ran ("localgs-triton", "vanilla-mosaic", ...), `stats.interpreted` says
whether it was interpreted.
"""

from __future__ import annotations

import dataclasses
import functools
import os

import jax
import jax.numpy as jnp
from jax import lax
from jax.experimental import pallas as pl

from .. import hoist
from ..binning import TILE, TileBins, tile_grid
from ..composite import PixelState, blend_weights, gaussian_alpha, passes, stops
from ..config import ALPHA_MIN, RasterConfig
from ..projection import Projected
from ..warp_masks import STRIPS
from . import backward, mosaic
from .reference import tiles_to_image
from .tiles import _origin_offset, chain_hoisted_rows, pair_masks, pair_vectors

UNROLL = {"localgs": 2, "vanilla": 8}  # pairs staged per iteration (scripts/kernel_profile.py)
STRIP_PIXELS = 2 * TILE
TILE_PIXELS = TILE * TILE
ROW = 12  # packed Gaussian row (vanilla): mean x, y; conic a, b, c; ln o; o; r, g, b; z; unused
REC = 12  # packed pair record (Local-GS): see `pair_records`
GRAD_VALUES = 11  # backward pair row: 7 α-model columns, ∂L/∂rgb, ∂L/∂z
GRAD_COLUMNS = 16  # the Triton kernel's row: GRAD_VALUES padded to a power of two
KERNELS = {"pallas": "localgs", "pallas_vanilla": "vanilla"}
# config.kernel="auto": the faster implementation per kernel on the H100 (BENCHMARKS.md §6);
# in interpret mode Triton for every kernel (`auto`)
IMPL = {"localgs": "mosaic", "vanilla": "mosaic", "backward": "mosaic"}


def interpreted() -> bool:
    """Whether the kernels run in interpret mode (no GPU backend; LGS_JAX_PALLAS_LOWER=gpu forces
    GPU lowering, for `tests/test_pallas.py`'s lowering check on machines without a GPU)."""
    return jax.default_backend() != "gpu" and os.environ.get("LGS_JAX_PALLAS_LOWER") != "gpu"


def auto(kernel: str) -> str:
    """The implementation `kernel="auto"` runs for "localgs", "vanilla" or "backward": on the
    GPU the one measured faster on the H100 (IMPL); in interpret mode Triton, whose interpreter
    (jitted XLA loops) runs the same kernels orders of magnitude faster than Mosaic GPU's
    simulation of a GPU (a 500-Gaussian 64x48 frame on 2 CPU cores: 4 ms vs 11 s). Both are
    bit for bit the same in interpret mode (tests/test_pallas.py)."""
    return "triton" if interpreted() else IMPL[kernel]


def implementation(backend: str, config: RasterConfig) -> str:
    """"triton" or "mosaic": the forward kernel implementation `backend` runs with `config`."""
    return auto(KERNELS[backend]) if config.kernel == "auto" else config.kernel


def backward_implementation(config: RasterConfig) -> str:
    """The backward kernel implementation; under differentiation the forward runs the same one
    (`_forward_for_gradients`)."""
    return auto("backward") if config.kernel == "auto" else config.kernel


def kernel_name(backend: str, config: RasterConfig) -> str:
    """The forward kernel `render` reports in `stats.kernel`, e.g. "localgs-mosaic"."""
    return f"{KERNELS[backend]}-{implementation(backend, config)}"


def gaussian_rows(p: Projected):
    """(N, ROW) packed per-Gaussian data the vanilla kernel loads (through each pair's Gaussian
    id, as the original rasterizer does): one row per Gaussian."""
    o = p.opacity
    cols = [p.mean2d[:, 0], p.mean2d[:, 1], p.conic[:, 0], p.conic[:, 1], p.conic[:, 2],
            jnp.log(o), o, p.rgb[:, 0], p.rgb[:, 1], p.rgb[:, 2], p.depth, jnp.zeros_like(o)]
    return jnp.stack(cols, -1)


def pair_records(p: Projected, bins: TileBins, tiles_x: int, config: RasterConfig, masks=None):
    """(capacity, REC) per-pair rows the Local-GS kernel loads, in pair order (no indirection).

    hoist: V (Eq. 8) relative to the pair's tile origin, ln o, rgb, z: the hoisted vector is
    built once per (tile, Gaussian) pair, as the paper stages it per tile, not once per strip.
    Otherwise the Gaussian's mean, conic and opacity, then rgb, z (the difference form). The
    last column holds the pair's strip-mask bits (`masks`, exact as a float: < 2^8) or 0.
    """
    g = bins.gauss
    if config.hoist:
        head = pair_vectors(p, bins, tiles_x, config)  # (capacity, 7): V, ln o
    else:
        head = jnp.concatenate([p.mean2d[g], p.conic[g], p.opacity[g, None],
                                jnp.zeros_like(p.opacity[g, None])], -1)
    bits = jnp.zeros_like(p.depth[g]) if masks is None else masks.astype(p.depth.dtype)
    tail = jnp.concatenate([p.rgb[g], p.depth[g, None], bits[:, None]], -1)
    return jnp.concatenate([head, tail], -1)


def _frame(tile, k, tiles_x: int, config: RasterConfig, dt):
    """Coordinates of lanes k of `tile` (pixel index k = 16·row + column within the tile; a
    strip's lanes are 32 consecutive k): the hoisting frame (x', y') and the pixel centre
    (px, py). Tile-local centres are exact in any float."""
    lx, ly = (k % TILE).astype(dt) + 0.5, (k // TILE).astype(dt) + 0.5
    px = ((tile % tiles_x) * TILE).astype(dt) + lx
    py = ((tile // tiles_x) * TILE).astype(dt) + ly
    if not config.local_coords:
        return (px, py), (px, py)
    off = _origin_offset(config)
    return (lx - off, ly - off), (px, py)


def _record_alpha(rec, frame, pixel, config: RasterConfig):
    """(α, hit, aux) of one pair record at a lane vector of pixels: ln α = min(V·B, ln o)
    (Eq. 10) with hit = ln α >= ln(1/255), or the difference form (lgs_jax.composite). `aux`
    is what the backward's derivative needs (ln α and V·B, or power)."""
    dt = frame[0].dtype
    cap = jnp.asarray(config.alpha_cap, dt)
    if config.hoist:
        raw = hoist.evaluate_terms(rec[:6], *frame)
        ln_a = jnp.minimum(raw, rec[6])
        alpha = jnp.minimum(cap, jnp.exp(ln_a))
        return alpha, ln_a >= jnp.log(jnp.asarray(ALPHA_MIN, dt)), (ln_a, raw)
    power, alpha = gaussian_alpha(rec[0:2], rec[2:5], rec[5], *pixel, cap)
    return alpha, passes(power, alpha), power


def _blend(state, alpha, hit, rgb, z, pair, config: RasterConfig):
    """One Gaussian (pair index `pair`) over a lane vector of pixels by the blending rule
    (`lgs_jax.composite.blend_weights`); state = (r, g, b, T, D, done, stop pair), `done` as
    int32 0/1 (Mosaic GPU holds no 1-bit registers); exact blending records the pair at which
    a pixel's stop test fired."""
    r, g, b, t, d, done, stop_at = state
    exact = config.blend == "exact"
    w, t, stopped = blend_weights(t, alpha, hit & (done == 0) if exact else hit, config)
    if exact:
        done, stop_at = jnp.where(stopped, 1, done), jnp.where(stopped, pair, stop_at)
    return r + w * rgb[0], g + w * rgb[1], b + w * rgb[2], t, d + w * z, done, stop_at


def _running(state, config: RasterConfig):
    """Whether any lane still blends: the program-uniform loop condition."""
    if config.blend == "exact":
        return jnp.min(state[5]) == 0
    return jnp.min(stops(state[3], config).astype(jnp.int32)) == 0


def _staged_loop(start, end, lanes: int, dt, fetch, pair_alpha, config: RasterConfig, unroll: int,
                 take=None, stage=None):
    """Walk pairs [start, end) `unroll` at a time while some lane still blends; returns
    (r, g, b, T, D, stop pair) per lane.

    `fetch(j)` loads pair j's small index data (Gaussian id, mask bit) one iteration ahead.
    Each iteration evaluates its `unroll` pairs first (`pair_alpha(fetched) -> (α, hit, rgb, z)`,
    independent of the pixel state, so their loads and arithmetic overlap) and then blends them
    in order. `take(fetched)` (optional) says whether a pair concerns this program at all (its
    mask bit): pairs without it do not blend, and a group with none is skipped by one
    program-uniform branch. `stage = (begin, finish)` (optional): `begin(j)` runs at the start of
    each iteration (before its pairs are evaluated) and `finish(j)` after the loop, with the first
    pair not processed. A lane's stop pair is where its stop test fired (exact), else the first
    pair the loop did not process (`end` or beyond when it ran to the end).
    """
    def cond(carry):
        j, _, st = carry
        return (j < end) & _running(st, config)

    def body(carry):
        j, cur, st = carry
        if stage is not None:
            stage[0](j)
        nxt = [fetch(j + unroll + u) for u in range(unroll)]
        takes = [(j + u < end) & (True if take is None else take(cur[u])) for u in range(unroll)]

        def group(st):
            evaluated = [pair_alpha(f) for f in cur]
            for u, ((alpha, hit, rgb, z), ok) in enumerate(zip(evaluated, takes)):
                st = _blend(st, alpha, hit & ok, rgb, z, j + u, config)
            return st

        if take is None:
            return j + unroll, nxt, group(st)
        return j + unroll, nxt, lax.cond(functools.reduce(jnp.logical_or, takes), group,
                                         lambda st: st, st)

    zero = jnp.zeros((lanes,), dt)
    empty = (zero, zero, zero, jnp.ones((lanes,), dt), zero, jnp.zeros((lanes,), jnp.int32),
             jnp.full((lanes,), jnp.iinfo(jnp.int32).max, jnp.int32))
    first = [fetch(start + u) for u in range(unroll)]
    j, _, st = lax.while_loop(cond, body, (start, first, empty))
    if stage is not None:
        stage[1](j)
    stop_at = jnp.minimum(st[6], j) if config.blend == "exact" else jnp.full((lanes,), j)
    return st[:5] + (stop_at,)


def _store(refs, row, outputs):
    """Write (r, g, b, T, D, stop pair) to row `row` of the (programs, lanes) outputs."""
    for ref, x in zip(refs, outputs):
        ref[row, :] = x.astype(ref.dtype)


def _localgs_kernel(order_ref, start_ref, end_ref, mask_ref, rec_ref, *out_refs,
                    config: RasterConfig, tiles_x: int, last_pair: int):
    dt = rec_ref.dtype
    pid = pl.program_id(0)
    tile, s = order_ref[pid // STRIPS], pid % STRIPS
    frame, pixel = _frame(tile, s * STRIP_PIXELS + lax.iota(jnp.int32, STRIP_PIXELS), tiles_x,
                          config, dt)
    bit = jnp.left_shift(jnp.int32(1), s)

    def fetch(j):
        jj = jnp.minimum(j, last_pair)
        return jj, ((mask_ref[jj] & bit) != 0) if config.warp_cull else None

    def pair_alpha(fetched):
        rec = [rec_ref[fetched[0], c] for c in range(REC - 1)]
        alpha, hit, _ = _record_alpha(rec, frame, pixel, config)
        return alpha, hit, rec[7:10], rec[10]

    # With warp culling, the strip's mask bit decides (a warp-uniform branch, Sec. III-C).
    take = (lambda fetched: fetched[1]) if config.warp_cull else None
    _store(out_refs, tile * STRIPS + s,
           _staged_loop(start_ref[tile], end_ref[tile], STRIP_PIXELS, dt, fetch, pair_alpha, config,
                        UNROLL["localgs"], take))


def vanilla_pairs(gauss_ref, rows_ref, pixel, config: RasterConfig, last_pair: int):
    """The vanilla kernels' (fetch, pair_alpha) for `_staged_loop` (Triton and Mosaic GPU): a
    pair's Gaussian id, then that Gaussian's packed row, the difference form at `pixel`."""
    cap = jnp.asarray(config.alpha_cap, rows_ref.dtype)

    def fetch(j):
        return gauss_ref[jnp.minimum(j, last_pair)]

    def pair_alpha(gi):
        row = [rows_ref[gi, c] for c in range(ROW - 1)]
        power, alpha = gaussian_alpha(row[0:2], row[2:5], row[6], *pixel, cap)
        return alpha, passes(power, alpha), row[7:10], row[10]

    return fetch, pair_alpha


def _vanilla_kernel(order_ref, start_ref, end_ref, gauss_ref, rows_ref, *out_refs,
                    config: RasterConfig, tiles_x: int, last_pair: int):
    dt = rows_ref.dtype
    tile = order_ref[pl.program_id(0)]
    _, pixel = _frame(tile, lax.iota(jnp.int32, TILE_PIXELS), tiles_x, config, dt)
    fetch, pair_alpha = vanilla_pairs(gauss_ref, rows_ref, pixel, config, last_pair)
    _store(out_refs, tile, _staged_loop(start_ref[tile], end_ref[tile], TILE_PIXELS, dt, fetch,
                                        pair_alpha, config, UNROLL["vanilla"]))


def _compiler_params(num_warps: int):
    from jax.experimental.pallas import triton as pl_triton

    return pl_triton.CompilerParams(num_warps=num_warps, num_stages=1)


def _call(kernel, n_programs: int, lanes: int, num_warps: int, dt, args):
    out = jax.ShapeDtypeStruct((n_programs, lanes), dt)  # each program writes its own row
    stop = jax.ShapeDtypeStruct((n_programs, lanes), jnp.int32)
    return pl.pallas_call(
        kernel, out_shape=[out] * 5 + [stop], grid=(n_programs,),
        compiler_params=_compiler_params(num_warps), interpret=interpreted(),
        name=kernel.func.__name__.strip("_"),
    )(*args)


def _longest_first(bins: TileBins):
    """Tiles in order of decreasing list length (stable)."""
    return jnp.argsort(bins.tile_start - bins.tile_end, stable=True).astype(jnp.int32)


def _forward(p: Projected, bins: TileBins, width: int, height: int, config: RasterConfig,
             vanilla: bool):
    """Per tile (n_tiles, 256): the state, each pixel's stop pair, the strip–Gaussian pairs the
    kernel had to visit, and (masks, records, tile order) for the backward."""
    dt = p.mean2d.dtype
    tiles_x, tiles_y = tile_grid(width, height)
    n_tiles = tiles_x * tiles_y
    last_pair = bins.gauss.shape[0] - 1
    valid_pair = bins.tile < n_tiles
    order = _longest_first(bins)
    if vanilla:
        data = (bins.gauss, gaussian_rows(p))
        if implementation("pallas_vanilla", config) == "mosaic":
            pixels = mosaic.block_pixels("forward", n_tiles)
            kernel = functools.partial(mosaic.vanilla_kernel, config=config, tiles_x=tiles_x,
                                       last_pair=last_pair, pixels=pixels)
            outs = mosaic.call(kernel, n_tiles, pixels, dt, (order, mosaic.ranges(bins)) + data,
                               interpreted())
        else:
            kernel = functools.partial(_vanilla_kernel, config=config, tiles_x=tiles_x,
                                       last_pair=last_pair)
            outs = _call(kernel, n_tiles, TILE_PIXELS, 8, dt,
                         (order, bins.tile_start, bins.tile_end) + data)
        strip_pairs = STRIPS * jnp.sum(valid_pair, dtype=jnp.int32)
        saved = (None, pair_records(p, bins, tiles_x, _vanilla_model(config)), order)
    else:
        if config.warp_cull:
            masks = pair_masks(p, bins, tiles_x, config)
            strip_pairs = jnp.sum(lax.population_count(masks), dtype=jnp.int32)
        else:
            masks = jnp.zeros((1,), jnp.int32)
            strip_pairs = STRIPS * jnp.sum(valid_pair, dtype=jnp.int32)
        records = pair_records(p, bins, tiles_x, config, masks if config.warp_cull else None)
        if implementation("pallas", config) == "mosaic":
            pixels = mosaic.block_pixels("forward", n_tiles)
            kernel = functools.partial(mosaic.localgs_kernel, config=config, tiles_x=tiles_x,
                                       last_pair=last_pair, pixels=pixels)
            outs = mosaic.call(kernel, n_tiles, pixels, dt,
                               (order, mosaic.ranges(bins), masks, records), interpreted(),
                               mosaic.localgs_scratch(dt))
        else:
            kernel = functools.partial(_localgs_kernel, config=config, tiles_x=tiles_x,
                                       last_pair=last_pair)
            outs = _call(kernel, n_tiles * STRIPS, STRIP_PIXELS, 1, dt,
                         (order, bins.tile_start, bins.tile_end, masks, records))
        saved = (masks if config.warp_cull else None, records, order)
    # (n_strips, 32) in tile-major strip order is exactly (n_tiles, 16 rows, 16 cols) per tile.
    r, g, b, t, d, stop_at = (x.reshape(n_tiles, TILE_PIXELS) for x in outs)
    state = PixelState(color=jnp.stack([r, g, b], -1), trans=t, depth=d,
                       done=jnp.zeros(t.shape, bool))
    return state, stop_at, strip_pairs, saved


def _vanilla_model(config: RasterConfig) -> RasterConfig:
    """The switches the vanilla kernel's arithmetic corresponds to: the difference form on the
    tile's whole list (its backward is the Local-GS backward kernel with these)."""
    return dataclasses.replace(config, hoist=False, warp_cull=False)


def _columns(values, lanes: int, dt):
    """Σ over lanes of each of `values` (lane vectors), as one (lanes, GRAD_COLUMNS) column
    reduction (one cross-warp reduction per pair instead of one per value)."""
    col = lax.broadcasted_iota(jnp.int32, (lanes, GRAD_COLUMNS), 1)
    m = jnp.zeros((lanes, GRAD_COLUMNS), dt)
    for c, v in enumerate(values):
        if v is not None:
            m = jnp.where(col == c, v[:, None], m)
    return jnp.sum(m, axis=0)


def _backward_step(j, rec, mask_word, lane, carry, config: RasterConfig):
    """Pair j's step of the backward walk (lgs_jax.backends.backward.walk, equations there) at
    a lane vector of pixels: its per-lane gradient terms (7 α-model columns, ∂L/∂rgb, ∂L/∂z;
    the Triton and Mosaic GPU kernels reduce them over the tile) and the new carry (T_{k+1},
    S_C, S_Z). `lane` = (frame, pixel, strip bit, stop pair, ḡ_r, ḡ_g, ḡ_b, ḡ_D, ḡ_T·T_N)."""
    frame, pixel, bit, stop_at, g_r, g_g, g_b, g_d, g_bg = lane
    t_next, s_r, s_g, s_b, s_z = carry
    cap = jnp.asarray(config.alpha_cap, rec[0].dtype)
    alpha, hit, aux = _record_alpha(rec, frame, pixel, config)
    hit = hit & (j < stop_at)
    if config.warp_cull:
        hit = hit & ((mask_word & bit) != 0)
    one_minus = jnp.where(hit, 1 - alpha, 1)
    t_k = t_next / one_minus
    w = jnp.where(hit, alpha * t_k, 0)
    rgb, z = rec[7:10], rec[10]
    dot_c = g_r * rgb[0] + g_g * rgb[1] + g_b * rgb[2]
    dot_s = g_r * s_r + g_g * s_g + g_b * s_b
    d_alpha = jnp.where(hit, t_k * (dot_c + g_d * z) - (dot_s + g_d * s_z + g_bg) / one_minus, 0)
    if config.hoist:  # ∂(V·B)/∂V = B; the clamp at ln o passes ∂ to ln o instead
        ln_a, raw = aux
        d_ln = jnp.where(jnp.exp(ln_a) < cap, d_alpha * alpha, 0)
        on_v = raw <= rec[6]
        d_raw = jnp.where(on_v, d_ln, 0)
        x, y = frame
        model = [d_raw * (x * x), d_raw * (x * y), d_raw * (y * y), d_raw * x, d_raw * y, d_raw,
                 jnp.where(on_v, 0, d_ln)]
    else:  # the difference form: backward.difference_alpha
        power = aux
        unclamped = rec[5] * jnp.exp(power) < cap
        d_power = jnp.where(unclamped, d_alpha * alpha, 0)
        dx, dy = rec[0] - pixel[0], rec[1] - pixel[1]
        a, b, c = rec[2:5]
        model = [-d_power * (a * dx + b * dy), -d_power * (c * dy + b * dx),
                 -0.5 * d_power * dx * dx, -d_power * dx * dy, -0.5 * d_power * dy * dy,
                 jnp.where(unclamped, d_alpha * jnp.exp(power), 0), None]
    carry = (jnp.where(hit, t_k, t_next), s_r + w * rgb[0], s_g + w * rgb[1], s_b + w * rgb[2],
             s_z + w * z)
    return model + [w * g_r, w * g_g, w * g_b, w * g_d], carry


def backward_lanes(tile, k, tiles_x: int, config: RasterConfig, dt, trans, stop_at, cotangents):
    """The per-lane data of `_backward_step` for lanes k of `tile`, from the rows of the final
    T, stop pairs and cotangents (r, g, b, T, D) the kernel loaded."""
    frame, pixel = _frame(tile, k, tiles_x, config, dt)
    bit = jnp.left_shift(jnp.int32(1), k // STRIP_PIXELS)  # each lane's strip
    g_r, g_g, g_b, g_t, g_d = cotangents
    return frame, pixel, bit, stop_at, g_r, g_g, g_b, g_d, g_t * trans


def _backward_kernel(order_ref, start_ref, end_ref, mask_ref, rec_ref, trans_ref, stop_ref,
                     g_r_ref, g_g_ref, g_b_ref, g_t_ref, g_d_ref, _zeros_ref, rows_ref, *,
                     config: RasterConfig, tiles_x: int):
    """One tile's backward walk (`_backward_step`): rows_ref[k] = the pair's gradient summed
    over the tile's pixels, for every pair some pixel blended."""
    dt = rec_ref.dtype
    tile = order_ref[pl.program_id(0)]
    trans, stop_at = trans_ref[tile, :], stop_ref[tile, :]
    lane = backward_lanes(tile, lax.iota(jnp.int32, TILE_PIXELS), tiles_x, config, dt, trans,
                          stop_at, [ref[tile, :] for ref in (g_r_ref, g_g_ref, g_b_ref, g_t_ref,
                                                             g_d_ref)])
    start = start_ref[tile]
    last = jnp.minimum(end_ref[tile], jnp.max(stop_at))  # pairs at or after it: no pixel blended

    def body(i, carry):
        j = last - 1 - i
        rec = [rec_ref[j, c] for c in range(REC - 1)]
        values, carry = _backward_step(j, rec, mask_ref[j] if config.warp_cull else None, lane,
                                       carry, config)
        rows_ref[j, :] = _columns(values, TILE_PIXELS, dt)
        return carry

    zero = jnp.zeros((TILE_PIXELS,), dt)
    lax.fori_loop(0, jnp.maximum(last - start, 0), body, (trans, zero, zero, zero, zero))


def _gradients(p: Projected, bins: TileBins, width: int, height: int, config: RasterConfig,
               trans, stop_at, saved, cotangents, vanilla: bool):
    """(N, 10) per-Gaussian gradients of (mean2d, conic, opacity, rgb, depth) from the backward
    kernel's pair rows."""
    masks, records, order = saved
    if vanilla:
        config = _vanilla_model(config)
    dt = p.mean2d.dtype
    tiles_x, tiles_y = tile_grid(width, height)
    g_color, g_trans, g_depth = cotangents
    masks = jnp.zeros((1,), jnp.int32) if masks is None else masks
    lane_rows = (trans, stop_at, g_color[..., 0], g_color[..., 1], g_color[..., 2], g_trans,
                 g_depth)
    if backward_implementation(config) == "mosaic":
        pixels = mosaic.block_pixels("backward", tiles_x * tiles_y)
        kernel = functools.partial(mosaic.backward_kernel, config=config, tiles_x=tiles_x,
                                   pixels=pixels)
        rows = mosaic.backward_rows(kernel, bins, stop_at, pixels, dt,
                                    (order, mosaic.ranges(bins), masks, records) + lane_rows,
                                    interpreted())
    else:
        kernel = functools.partial(_backward_kernel, config=config, tiles_x=tiles_x)
        zeros = jnp.zeros((bins.gauss.shape[0], GRAD_COLUMNS), dt)
        rows = pl.pallas_call(
            kernel, out_shape=jax.ShapeDtypeStruct(zeros.shape, dt), grid=(tiles_x * tiles_y,),
            input_output_aliases={12: 0},  # unvisited and padding pairs keep their zero row
            compiler_params=_compiler_params(8), interpret=interpreted(),
            name="localgs_backward",
        )(order, bins.tile_start, bins.tile_end, masks, records, *lane_rows, zeros)
    if config.hoist:
        rows = chain_hoisted_rows(p, bins, rows[:, :GRAD_VALUES], tiles_x, config)
    else:
        rows = jnp.concatenate([rows[:, :6], rows[:, 7:GRAD_VALUES]], -1)
    return backward.per_gaussian_sum(rows, bins.gauss, p.mean2d.shape[0])


def _forward_for_gradients(p, bins, width, height, config, vanilla: bool):
    """The forward whose residuals the backward kernel uses: with kernel="auto" the forward of
    the backward's implementation, so that forward and backward evaluate α with the same
    compiler's arithmetic (the compilers' exp and multiply-add contraction can differ by an
    ulp, which could flip an alpha test between them)."""
    if config.kernel == "auto":
        config = dataclasses.replace(config, kernel=backward_implementation(config))
    return _forward(p, bins, width, height, config, vanilla)


_COMPOSITE = {vanilla: backward.differentiable(
    functools.partial(_forward, vanilla=vanilla), functools.partial(_gradients, vanilla=vanilla),
    functools.partial(_forward_for_gradients, vanilla=vanilla)) for vanilla in (False, True)}


def rasterize(p: Projected, bins: TileBins, width: int, height: int, config: RasterConfig,
              vanilla: bool = False) -> tuple[PixelState, jax.Array]:
    """Returns the (H·W,) pixel state (differentiable: a custom_vjp whose backward is the
    backward kernel) and the strip–Gaussian pairs the kernel had to visit (with warp culling:
    the pairs' set mask bits; otherwise 8 per pair)."""
    color, trans, depth, strip_pairs = _COMPOSITE[vanilla](p, bins, width, height, config)
    state = PixelState(color=color, trans=trans, depth=depth, done=jnp.zeros(trans.shape, bool))
    return jax.tree.map(lambda x: tiles_to_image(x, width, height), state), strip_pairs
