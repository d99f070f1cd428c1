"""The Pallas backward's last step: each Gaussian's pair rows chained to its screen-space
parameters and summed, one lane per Gaussian, in a fixed order.

The backward kernels (lgs_jax.backends.pallas_mosaic, pallas_triton) store each pair's row at
the pair's emission slot (`TileBins.slot`), where a Gaussian's pairs are the consecutive slots
[first, first + count) in ascending tile order (`TileBins.first`, `TileBins.count`). A row
holds the pair's gradient summed over one block's pixels (`kernel_steps.GRAD_VALUES` values:
the α model's 7 columns, ∂L/∂rgb, ∂L/∂z) and, in column `kernel_steps.TILE_COLUMN`, its tile
index as a float (exact: images have fewer than 2^24 tiles, lgs_jax.scene checks); rows of
pairs no pixel reached are zero. For Gaussian g this computes, walking its slots in order,

    hoisted (Eq. 8):  Σ_pairs [∂L/∂μ, ∂L/∂(a, b, c), ∂L/∂ln o + clamp, ∂L/∂rgb, ∂L/∂z]
                      with ∂L/∂(a, b, c, Δ, ln o) = hoist.hoist_terms_vjp(∂L/∂V, a, b, c, Δ),
                      Δ = μ − T(tile), then ∂L/∂o = Σ ∂L/∂ln o / o;
    difference form:  Σ_pairs [∂L/∂μ, ∂L/∂(a, b, c), ∂L/∂o, ∂L/∂rgb, ∂L/∂z],

the blocks of a pair added in block order first. One lane owns one Gaussian's sum, so the
result is deterministic without atomics, and nothing per pair is materialised beyond the rows:
no chained copy, no permutation, no segmented scan (the XLA path the `tiles` backend takes,
pairs.chain_hoisted_rows then backends.backward.per_gaussian_sum: the same values, summed in
another association).

`sums` is the Pallas Triton kernel (one program per `LANES` Gaussians, looping to the longest
count among them; per-lane gathers of rows, which Mosaic GPU's Pallas cannot express);
`reference` the same arithmetic in jnp over all Gaussians at once (tests).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
from jax import lax
from jax.experimental import pallas as pl
from jax.experimental.pallas import triton as plt

from .. import hoist
from ..binning import TileBins
from ..config import RasterConfig
from ..layout import tile_origin_axis
from ..projection import Projected
from . import kernel_steps as ks

LANES = 32  # Gaussians per program (one warp): a program loops to its lanes' longest count;
# 128 lanes took 2.70 ms at 10M/4K, 32 lanes 1.53 (BENCHMARKS.md §7)
COLUMNS = 10  # ∂L/∂(mean2d x, y; conic a, b, c; opacity; rgb r, g, b; depth)


def _pair_terms(vals, tile, fields, tiles_x: int, config: RasterConfig):
    """One pair's contribution to its Gaussian's COLUMNS sums (∂L/∂ln o in the opacity column
    for the hoisted form, divided by o once at the end). vals: the row's GRAD_VALUES values
    (blocks added); tile: its tile index (int32); fields = (μx, μy, a, b, c)."""
    if not config.hoist:
        return list(vals[0:6]) + list(vals[7:11])
    mx, my, a, b, c = fields
    dt = mx.dtype
    ox = tile_origin_axis(tile % tiles_x, config, dt)
    oy = tile_origin_axis(tile // tiles_x, config, dt)
    d_a, d_b, d_c, d_dx, d_dy, d_ln_o = hoist.hoist_terms_vjp(vals[0:6], a, b, c, mx - ox,
                                                              my - oy)
    return [d_dx, d_dy, d_a, d_b, d_c, d_ln_o + vals[6]] + list(vals[7:11])


def _finish(acc, opacity, config: RasterConfig):
    """The hoisted form's ∂L/∂o = ∂L/∂ln o / o (zero where o = 0: invalid Gaussians)."""
    if not config.hoist:
        return acc
    o_ok = opacity > 0
    d_o = jnp.where(o_ok, acc[5] / jnp.where(o_ok, opacity, 1), 0)
    return acc[:5] + [d_o] + acc[6:]


def _fields(p: Projected):
    return p.mean2d, p.conic, p.opacity


def _walk(rows, blocks: int, first, count, fields, opacity, tiles_x: int,
          config: RasterConfig):
    """COLUMNS sums (arrays shaped as `first`) of the Gaussians whose slots are [first,
    first + count): each slot's blocks added in block order, chained (`_pair_terms`), summed in
    slot order; `rows` is the (blocks, capacity, >= TILE_COLUMN + 1) ref (kernel) or array
    (`reference`), indexed alike. fields = (μx, μy, a, b, c), opacity: of those Gaussians."""
    def body(i, acc):
        live = i < count
        s = jnp.where(live, first + i, 0)  # lanes done read slot 0 (cached) and keep acc
        vals = [functools.reduce(lambda x, y: x + y, [rows[w, s, col] for w in range(blocks)])
                for col in range(ks.GRAD_VALUES)]
        tile = rows[0, s, ks.TILE_COLUMN].astype(jnp.int32)
        terms = _pair_terms(vals, tile, fields, tiles_x, config)
        return tuple(jnp.where(live, x + t, x) for x, t in zip(acc, terms))

    zero = jnp.zeros(first.shape, opacity.dtype)
    acc = lax.fori_loop(0, jnp.max(count), body, (zero,) * COLUMNS)
    return _finish(list(acc), opacity, config)


def _kernel(first_ref, count_ref, mean_ref, conic_ref, opacity_ref, rows_ref, out_ref, *,
            config: RasterConfig, tiles_x: int, n: int, blocks: int, lanes: int):
    g = pl.program_id(0) * lanes + lax.iota(jnp.int32, lanes)
    gi = jnp.minimum(g, n - 1)
    fields = (mean_ref[gi, 0], mean_ref[gi, 1], conic_ref[gi, 0], conic_ref[gi, 1],
              conic_ref[gi, 2])
    count = jnp.where(g < n, count_ref[gi], 0)
    sums_ = _walk(rows_ref, blocks, first_ref[gi], count, fields, opacity_ref[gi], tiles_x,
                  config)
    for col, v in enumerate(sums_):
        out_ref[g, col] = v  # rows n and up: padding (distinct rows, dropped)


def sums(rows, bins: TileBins, p: Projected, tiles_x: int, config: RasterConfig,
         interpret: bool, lanes: int = LANES):
    """(N, COLUMNS) per-Gaussian gradients from the backward kernels' emission-order rows
    (blocks, capacity, >= TILE_COLUMN + 1) (module docstring), by the Triton kernel with
    `lanes` Gaussians per program (a multiple of 32: one warp per 32; each program loops to
    its lanes' longest count, so fewer lanes idle less where counts vary)."""
    if lanes % 32:
        raise ValueError(f"lanes: expected a multiple of 32, got {lanes}")
    n, blocks = p.mean2d.shape[0], rows.shape[0]
    programs = pl.cdiv(n, lanes)
    kernel = functools.partial(_kernel, config=config, tiles_x=tiles_x, n=n, blocks=blocks,
                               lanes=lanes)
    out = pl.pallas_call(
        kernel, out_shape=jax.ShapeDtypeStruct((programs * lanes, COLUMNS), rows.dtype),
        grid=(programs,), interpret=interpret,
        compiler_params=plt.CompilerParams(num_warps=lanes // 32, num_stages=1),
        name="gaussian_grads",
    )(bins.first, bins.count, *_fields(p), rows)
    return out[:n]


def reference(rows, bins: TileBins, p: Projected, tiles_x: int, config: RasterConfig):
    """`sums` in jnp: every Gaussian at once, the same walk over its slots and the same
    arithmetic (`_walk`; tests compare the kernel with it in interpret mode)."""
    mean, conic, opacity = _fields(p)
    fields = (mean[:, 0], mean[:, 1], conic[:, 0], conic[:, 1], conic[:, 2])
    return jnp.stack(_walk(rows, rows.shape[0], bins.first, bins.count, fields, opacity,
                           tiles_x, config), -1)
