"""The per-pair arithmetic the Triton and Mosaic GPU kernels share (lgs_jax.backends.pallas.triton,
.mosaic_forward, .mosaic_backward): the record layouts, α per record, the blend step and its
loop, and the backward step. Written on lane vectors (one value per pixel a thread holds) and
scalars loaded from refs, so both Pallas lowerings compile the same functions.

Record layouts, built in XLA before the Triton kernels run (`pair_records`), or by the Mosaic
GPU kernels themselves from per-Gaussian rows (lgs_jax.backends.pallas.staging; the same
`pairs.record_columns`):
  pair record (Local-GS kernel, `pair_records`, one row per pair in pair order, no indirection):
    hoisted: V (Eq. 8, 6 values) relative to the pair's tile origin, ln o, rgb, z, strip mask;
    difference form: Δx, Δy, a, b, c, o, 0, rgb, z, strip mask, with Δ = μ − T from the tile
    origin T (`pairs.origin_offsets`: (mean2d − T) + mean2d_lo).
  Gaussian row (vanilla kernel, `gaussian_rows`, loaded through each pair's Gaussian id as the
    original rasterizer does): μx, μy, a, b, c, lo_x, o, rgb, z, lo_y (μ = mean2d + mean2d_lo).
Both forms are evaluated in the hoisting frame x' = pixel centre − T (lgs_jax.layout.frame):
the difference form at d = Δ − x', Δ from the record or, in the vanilla kernel, formed from
the row per pair as the records form it, so that the vanilla forward and its backward (the
Local-GS backward's difference form) compute the same bits. d then rounds at the size of Δ
and d (tile-local coordinates), not of the image: the split centre's accuracy at any width.
"""

from __future__ import annotations

import functools
from typing import Any, NamedTuple

import jax.numpy as jnp
from jax import lax

from ... import alpha as alpha_model
from ... import hoist, pairs
from ...binning import TileBins
from ...composite import blend_weights, stops
from ...config import RasterConfig
from ...layout import STRIP_PIXELS, frame, pixel_centres
from ...projection import Projected
from .. import backward

ROW = 12  # Gaussian row (vanilla)
REC = 12  # pair record (Local-GS); the strip mask in the last column (exact as a float: < 2^8)
GRAD_VALUES = 11  # backward pair row: 7 α-model columns, ∂L/∂rgb, ∂L/∂z
TILE_COLUMN = GRAD_VALUES  # then the pair's tile index, as a float, in rows with ∂L/∂z (row_width)


def row_width(depth: bool) -> int:
    """Columns of the Mosaic GPU backward's pair rows: the GRAD_VALUES values and the tile (48
    bytes), or, where the loss does not reach the depth (its cotangent a symbolic zero,
    `backward.depth_cotangent`), the values without ∂L/∂z, which would be zero, and the tile in
    column GRAD_VALUES − 1 (44 bytes: 4 bytes less per walked pair, 40 MiB at 10M Gaussians)."""
    return GRAD_VALUES + 1 if depth else GRAD_VALUES


def gaussian_rows(p: Projected):
    """(N, ROW) per-Gaussian rows of the vanilla kernel (module docstring)."""
    cols = [p.mean2d[:, 0], p.mean2d[:, 1], p.conic[:, 0], p.conic[:, 1], p.conic[:, 2],
            p.mean2d_lo[:, 0], p.opacity, p.rgb[:, 0], p.rgb[:, 1], p.rgb[:, 2], p.depth,
            p.mean2d_lo[:, 1]]
    return jnp.stack(cols, -1)


def pair_records(pg: pairs.PairGaussians, bins: TileBins, tiles_x: int, config: RasterConfig,
                 masks=None):
    """(capacity, REC) pair records of the Local-GS kernel (module docstring), in pair order,
    from the pairs' Gaussian fields (`pairs.gather`; `pairs.record_columns`): the hoisted vector
    is built once per (tile, Gaussian) pair, as the paper stages it per tile, not once per strip.
    `masks`: the pairs' strip masks (0 in the last column if None)."""
    t = bins.tile
    return jnp.stack(pairs.record_columns(pairs.columns(pg), t % tiles_x, t // tiles_x, config,
                                          masks), -1)


def lane_coordinates(tile, k, tiles_x: int, config: RasterConfig, dt):
    """The hoisting frame (x', y') of pixels k of `tile` (lgs_jax.layout)."""
    return frame(*pixel_centres(tile, k, tiles_x, dt), config)


def lane_offsets(delta, frame_xy):
    """The difference form's d = Δ − x' (per lane) from a pair's Δ = μ − T (module docstring)."""
    return delta[0] - frame_xy[0], delta[1] - frame_xy[1]


def record_alpha(rec, frame_xy, config: RasterConfig):
    """(α, hit, aux) of one pair record at a lane vector of pixels (lgs_jax.alpha): hoisted,
    raw = `hoist.evaluate_terms` (Eq. 10) and aux = (ln α, raw); or the difference form at
    d = `lane_offsets`, aux = (power, d)."""
    cap = jnp.asarray(config.alpha_cap, frame_xy[0].dtype)
    if config.hoist:
        raw = hoist.evaluate_terms(rec[:6], *frame_xy)
        alpha, hit, ln_a = alpha_model.hoisted(raw, rec[6], cap)
        return alpha, hit, (ln_a, raw)
    d = lane_offsets(rec[0:2], frame_xy)
    alpha, hit, power = alpha_model.difference(d, rec[2:5], rec[5], cap)
    return alpha, hit, (power, d)


NOT_STOPPED = jnp.iinfo(jnp.int32).max  # a stop pair no pair has (indices are int32 offsets)


def blend(state, alpha, hit, rgb, z, pair, config: RasterConfig):
    """One Gaussian (pair index `pair`) over a lane vector of pixels by the blending rule
    (`lgs_jax.composite.blend_weights`); state = (r, g, b, T, D, stop pair): exact blending
    records the pair at which a pixel's stop test fired, and a pixel is done once it has one
    (stop pair != NOT_STOPPED: one int32 serves as flag and index; Mosaic GPU holds no 1-bit
    registers)."""
    r, g, b, t, d, stop_at = state
    exact = config.blend == "exact"
    w, t, stopped = blend_weights(t, alpha, hit & (stop_at == NOT_STOPPED) if exact else hit,
                                  config)
    if exact:
        stop_at = jnp.where(stopped, pair, stop_at)
    return r + w * rgb[0], g + w * rgb[1], b + w * rgb[2], t, d + w * z, stop_at


def running(state, config: RasterConfig):
    """Whether any lane still blends: the program-uniform loop condition."""
    if config.blend == "exact":
        return jnp.max(state[5]) == NOT_STOPPED
    return jnp.min(stops(state[3], config).astype(jnp.int32)) == 0


def staged_loop(start, end, lanes: int, dt, fetch, pair_alpha, config: RasterConfig, unroll: int,
                take=None, stage=None, checkpoint=None, more=None):
    """Walk pairs [start, end) `unroll` at a time while some lane still blends; returns
    (r, g, b, T, D, stop pair) per lane.

    `fetch(j)` loads pair j's small index data (Gaussian id, mask bit) one iteration ahead.
    Each iteration evaluates its `unroll` pairs first (`pair_alpha(fetched) -> (α, hit, rgb, z)`,
    independent of the pixel state, so their loads and arithmetic overlap) and then blends them
    in order. `take(fetched)` (optional) says whether a pair concerns this program at all (its
    mask bit): pairs without it do not blend, and a group with none is skipped by one
    program-uniform branch. `stage = (begin, finish)` (optional): `begin(j)` runs at the start of
    each iteration (before its pairs are evaluated) and `finish(j)` after the loop, with the first
    pair not processed. `checkpoint(j, state)` (optional) runs at the start of each iteration
    with the state before pair j. `more(state)` (optional): `running`'s test, another way (the
    Mosaic GPU kernels' one reduction, `inline.running`). A lane's stop pair is where its
    stop test fired (exact), else the first pair the loop did not process (`end` or beyond when
    it ran to the end).
    """
    def cond(carry):
        j, _, st = carry
        return (j < end) & (running(st, config) if more is None else more(st))

    def body(carry):
        j, cur, st = carry
        if checkpoint is not None:
            checkpoint(j, st)
        if stage is not None:
            stage[0](j)
        nxt = [fetch(j + unroll + u) for u in range(unroll)]
        takes = [(j + u < end) & (True if take is None else take(cur[u])) for u in range(unroll)]

        def group(st):
            evaluated = [pair_alpha(f) for f in cur]
            for u, ((alpha, hit, rgb, z), ok) in enumerate(zip(evaluated, takes)):
                st = blend(st, alpha, hit & ok, rgb, z, j + u, config)
            return st

        if take is None:
            return j + unroll, nxt, group(st)
        return j + unroll, nxt, lax.cond(functools.reduce(jnp.logical_or, takes), group,
                                         lambda st: st, st)

    first = [fetch(start + u) for u in range(unroll)]
    j, _, st = lax.while_loop(cond, body, (start, first, empty_state(lanes, dt)))
    if stage is not None:
        stage[1](j)
    stop_at = jnp.minimum(st[5], j) if config.blend == "exact" else jnp.full((lanes,), j)
    return st[:5] + (stop_at,)


def empty_state(lanes: int, dt):
    """The blend state (`blend`) of `lanes` pixels before any pair: r = g = b = D = 0, T = 1,
    no stop pair."""
    zero = jnp.zeros((lanes,), dt)
    return (zero, zero, zero, jnp.ones((lanes,), dt), zero,
            jnp.full((lanes,), NOT_STOPPED, jnp.int32))


def vanilla_pairs(gauss_ref, rows_ref, tile, tiles_x: int, frame_xy, config: RasterConfig,
                  last_pair: int):
    """The vanilla kernels' (fetch, pair_alpha) for `staged_loop`: a pair's Gaussian id, then
    that Gaussian's row, the difference form at lanes `frame_xy` of `tile` (its Δ formed from
    the row as `pairs.origin_offsets` forms the records')."""
    cap = jnp.asarray(config.alpha_cap, rows_ref.dtype)
    tx, ty = tile % tiles_x, tile // tiles_x

    def fetch(j):
        return gauss_ref[jnp.minimum(j, last_pair)]

    def pair_alpha(gi):
        row = [rows_ref[gi, c] for c in range(ROW)]
        delta = pairs.origin_offsets(row[0:2], (row[5], row[11]), tx, ty, config)
        alpha, hit, _ = alpha_model.difference(lane_offsets(delta, frame_xy), row[2:5], row[6],
                                               cap)
        return alpha, hit, row[7:10], row[10]

    return fetch, pair_alpha


def backward_lanes(tile, k, tiles_x: int, config: RasterConfig, dt, trans, stop_at, cotangents):
    """The per-lane data of `backward_step` for lanes k of `tile`, from the rows of the final
    T, stop pairs and cotangents (r, g, b, T, D) the kernel loaded: (frame, strip bit, stop
    pair, ḡ_r, ḡ_g, ḡ_b, ḡ_D, ḡ_T·T_N); D None where the loss does not reach the depth
    (`backward.walk_step` leaves its terms out)."""
    frame_xy = lane_coordinates(tile, k, tiles_x, config, dt)
    bit = jnp.left_shift(jnp.int32(1), k // STRIP_PIXELS)  # each lane's strip
    g_r, g_g, g_b, g_t, g_d = cotangents
    return frame_xy, bit, stop_at, g_r, g_g, g_b, g_d, g_t * trans


class Scaled(NamedTuple):
    """A gradient term source · factor whose factor is the lane's own and the same at every pair
    of the walk (a pixel's basis value x², xy, y², x, y). The GPU reduction
    (`rows.transposed_row`) then chooses between two terms of one source by their
    factors, once per walk, instead of between their products at every pair."""
    source: Any
    factor: Any


class Product(NamedTuple):
    """A gradient term a · b whose factors both change from pair to pair (w · ḡ_r). The GPU
    reduction forms the products in its per-thread sums, as multiply-adds after the first
    pixel's (`rows.transposed_row`), where a term passed in formed costs a multiply per pixel
    and an add; unlike `Scaled` terms, products are never paired by a shared factor."""
    a: Any
    b: Any


def term(value):
    """A gradient term's per-lane values (`backward_step`'s terms: an array, `Scaled`,
    `Product` or None)."""
    if isinstance(value, Scaled):
        return value.source * value.factor
    return value.a * value.b if isinstance(value, Product) else value


def backward_step(j, rec, mask_word, lane, carry, config: RasterConfig, quotients=None):
    """Pair j's step of the backward walk (`backward.walk_step`, equations in
    lgs_jax.backends.backward) at a lane vector of pixels: its per-lane gradient terms (7
    α-model columns, ∂L/∂rgb, ∂L/∂z; arrays, `Scaled` or `Product` products or None for a
    zero term, each `term`'s value; the kernels reduce them over their pixels) and the new
    carry (T_{k+1}, S_r, S_g, S_b, S_Z). `quotients`: `backward.walk_step`'s."""
    frame_xy, bit, stop_at, g_r, g_g, g_b, g_d, g_bg = lane
    cap = jnp.asarray(config.alpha_cap, rec[0].dtype)
    alpha, hit, aux = record_alpha(rec, frame_xy, config)
    hit = hit & (j < stop_at)
    if config.warp_cull:
        hit = hit & ((mask_word & bit) != 0)
    rgb, z = rec[7:10], rec[10]
    t, w, d_alpha, sums = backward.walk_step(carry[0], alpha, hit, rgb, z, carry[1:],
                                             (g_r, g_g, g_b, g_d, g_bg), quotients)
    if config.hoist:  # ∂(V·B)/∂V = B; the clamp at ln o passes ∂ to ln o instead
        ln_a, raw = aux
        d_raw, d_ln_o = alpha_model.hoisted_vjp(d_alpha, alpha, ln_a, raw, rec[6], cap)
        x, y = frame_xy
        # as `Scaled` the basis terms pair up in the GPU reduction's first step without
        # selects; d_raw · 1 and the colour terms stay plain (as `Scaled` they cost registers,
        # and so blocks per SM; docs/design-notes.md)
        model = [Scaled(d_raw, x * x), Scaled(d_raw, x * y), Scaled(d_raw, y * y),
                 Scaled(d_raw, x), Scaled(d_raw, y), d_raw, d_ln_o]
    else:
        model = alpha_model.difference_vjp(d_alpha, alpha, *aux, rec[2:5], rec[5], cap) + [None]
    colour = [Product(w, g_r), Product(w, g_g), Product(w, g_b),
              None if g_d is None else Product(w, g_d)]
    return model + colour, (t,) + sums
