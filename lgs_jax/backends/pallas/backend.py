"""The `pallas` and `pallas_vanilla` backends: the Pallas kernels wired into a custom_vjp.

`forward` runs the forward kernel (Mosaic GPU, lgs_jax.backends.pallas.mosaic_forward, or
Triton, .triton) and returns the pixel state with what the backward reuses; `gradients` runs the
backward kernel (.mosaic_backward or .triton) and the per-Gaussian sums (.gaussian_grads);
`rasterize` is the backend's entry point, a custom_vjp of the two. Projection, binning and
sorting stay in XLA (shared with the other backends).

`pallas` runs the Local-GS kernel (Sec. III): a hoisted 6-vector V per (tile, Gaussian) pair
(Eq. 8), ln α as V·[x'², x'y', y'², x', y', 1] per pixel (Eq. 10), the strip masks (Sec.
III-C), exact or fast (Sec. III-D) blending. `pallas_vanilla` runs the original 3DGS
rasterizer (difference form, per-pixel termination, a tile-wide early exit): the baseline the
paper measures against; it ignores the Local-GS switches but honours `convention` and `blend`.

Programs take tiles longest list first (.order: the slowest start first, short ones fill in
behind them; each writes its own output row). Both forward kernels write each pixel's stop
pair, which is all the backward needs besides the final T.

Backward: the backward kernel walks each tile's pairs back to front from the last pair any
pixel blended, with the forward's own α arithmetic (hoisted V·B clamped at ln o, or the
difference form: the vanilla forward's backward is the Local-GS backward with hoist and
warp_cull off) and strip masks: the walk of lgs_jax.backends.backward, one pair per step. Each
pair's gradient, summed over a block's pixels, is stored as a row in a buffer of rows for the
walked pairs only, numbered in emission-slot order (gaussian_grads.RowLayout; one writer per
row, no atomics); a second kernel chains each Gaussian's rows through Eq. 8 (hoisted form) and
sums them, one lane per Gaussian in slot order: deterministic.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp
from jax import lax

from ...binning import TileBins
from ...composite import PixelState
from ...config import RasterConfig
from ...layout import TILE_PIXELS, image_tiles, tile_grid, tiled_image_to_tiles
from ...projection import Projected
from .. import backward
from ..custom_vjp import differentiable
from ..interface import (Backend, BackendInputs, RasterResult, pairs_walked, stop_within,
                         tile_last)
from . import gaussian_grads, mosaic_backward, mosaic_forward, order, segments, table, triton
from . import steps as ks
from .plan import Plan, plan


@jax.tree_util.register_dataclass
@dataclasses.dataclass
class PallasStats:
    """The Pallas backends' counts (`RenderStats.backend_stats`; batched under vmap).

    Attributes:
      strip_pairs: strip–Gaussian pairs the Triton kernels' lists hold (8·pairs without warp
        culling), −1 where the Local-GS Mosaic GPU kernel builds its records itself and does
        not count them.
      pairs_walked: pairs some pixel of their tile reached (each tile's pairs up to its
        pixels' latest stop): the rows the backward needs with a `row_capacity`.
      row_overflow: pairs_walked > row_capacity (the backward's gradients lack the rows past
        it; the image is complete); False without a row capacity.
      kernel: the forward kernel, "localgs-mosaic", "localgs-triton", "vanilla-mosaic" or
        "vanilla-triton" (static).
      interpreted: the kernels ran in Pallas interpret mode (static).
    """

    strip_pairs: Any
    pairs_walked: Any
    row_overflow: Any
    kernel: str = dataclasses.field(default="", metadata=dict(static=True))
    interpreted: bool = dataclasses.field(default=False, metadata=dict(static=True))


def _kernel_inputs(p: Projected, bins: TileBins, gaussian_table, tiles_x: int, plan_: Plan):
    """(forward kernel data, strip–Gaussian pairs, what the backward kernel reads).

    Mosaic GPU: the kernels build their pair records themselves from the pairs' Gaussian ids and
    `pairs.gaussian_table` (`gaussian_table` if given, else written here by .table): the
    Local-GS forward and the backward read (ids, table), the vanilla forward reads each pair's
    `steps.gaussian_rows` row by id. Triton: (masks, records) built in XLA (`triton.records`,
    of the vanilla kernel's α model for its backward), the vanilla forward again by id."""
    if plan_.kernel == "mosaic":
        if gaussian_table is None:
            gaussian_table = table.gaussian_table(p, plan_.interpret)
        staged = (bins.gauss, gaussian_table)
        if plan_.vanilla:
            return (bins.gauss, ks.gaussian_rows(p)), triton.every_strip(bins), staged
        return staged, jnp.int32(-1), staged
    masks, records, strip_pairs = triton.records(p, bins, tiles_x, plan_.model)
    if plan_.vanilla:
        return (bins.gauss, ks.gaussian_rows(p)), strip_pairs, (masks, records)
    return (masks, records), strip_pairs, (masks, records)


def forward(p: Projected, bins: TileBins, gaussian_table, width: int, height: int, plan_: Plan,
            render: bool = False):
    """(state, stops, strip pairs, saved) per tile (n_tiles, 256): the pixel state, the stop
    pairs (each pixel's, or each block's latest where `plan_.block_stops` and `render`), the
    strip–Gaussian pairs (`PallasStats.strip_pairs`), and what `gradients` reads: (the
    backward kernel's two inputs, tile order, segment entries, each pixel's stop pair).
    `render`: no backward follows (no segment checkpoints; block stops written by the kernel;
    the pixels' stop pairs None). `gaussian_table`: `pairs.gaussian_table`, or None to build
    it here (Mosaic GPU only)."""
    dt = p.mean2d.dtype
    tiles_x, _ = tile_grid(width, height)
    tile_order = order.longest_first(bins.tile_end - bins.tile_start)
    data, strip_pairs, saved = _kernel_inputs(p, bins, gaussian_table, tiles_x, plan_)
    segment = None if render else plan_.segment
    args = (plan_.vanilla, plan_.config, plan_.interpret)
    if plan_.kernel == "mosaic":
        outs = mosaic_forward.forward(*args, plan_.forward_pixels, tiles_x, tile_order, bins,
                                      data, dt, segment=segment, image=plan_.image,
                                      block_stops=plan_.block_stops and render)
    else:
        outs = triton.forward(*args, tiles_x, tile_order, bins, data, dt)
    if plan_.image:
        (color, t, d, stop_at), checks = outs[:4], outs[4:]
        final_at = lambda tile: (*image_tiles(color, tile, tiles_x), d[tile])
    else:
        (r, g, b, t, d, stop_at), checks = outs[:6], outs[6:]
        color = jnp.stack([r, g, b], -1)
        final_at = lambda tile: (r[tile], g[tile], b[tile], d[tile])
    stop_at = stop_within(stop_at, bins.tile_end)
    entry = ()
    if segment is not None:  # with walked rows, the walked pairs' checkpoints only
        last = (tile_last(stop_at, bins.tile_start, bins.tile_end)
                if plan_.rows is not None else None)
        entry = segments.entries(final_at, checks, bins, segment, last, plan_.rows)
        # The entries before what reads the stop pairs after the forward: XLA would otherwise
        # subtract just before the backward kernel, keeping the four planes live next to the
        # cotangents.
        entry, stop_at = lax.optimization_barrier((entry, stop_at))
    stops = stop_at
    if plan_.block_stops and not render:  # the render's (n_tiles, blocks) from the pixels'
        blocks = TILE_PIXELS // plan_.forward_pixels
        stops = jnp.max(stop_at.reshape(stop_at.shape[0], blocks, -1), axis=-1)
    state = PixelState(color=color, trans=t, depth=d, done=jnp.zeros(t.shape, bool))
    pixel_stops = None if render and plan_.block_stops else stop_at
    return state, stops, strip_pairs, saved + (tile_order, entry, pixel_stops)


def gradients(p: Projected, bins: TileBins, gaussian_table, width: int, height: int,
              plan_: Plan, trans, returned_stops, saved, cotangents):
    """(N, 10) per-Gaussian gradients of (mean2d, conic, opacity, rgb, depth) (the
    backward.PAIR_COLUMNS order) from the backward kernel's pair rows, given `forward`'s
    `saved` (for a forward with `render` False) and the cotangents of its colour (per tile, or
    the image with `plan_.image`), T and depth (None: a symbolic zero). The backward reads
    each pixel's stop pair from `saved`, not the stops the forward returned."""
    del returned_stops, gaussian_table  # the table, where the kernels read it, is in `saved`
    first, second, tile_order, entry, stop_at = saved
    config = plan_.model
    dt = p.mean2d.dtype
    tiles_x, _ = tile_grid(width, height)
    g_color, g_trans, g_depth = cotangents
    layout = gaussian_grads.rows_of(bins, stop_at, plan_.rows)
    # The cotangents' per-tile planes made after the row layout, by a dependency on it: a
    # select on a predicate that always holds (end is a pair index), the same values. XLA
    # made them from the loss's cotangent at the program's start and kept them through the
    # forward kernel, where the temporaries peak. A barrier would keep its inputs instead.
    ready = layout.end[0] >= 0
    g_color, g_trans = (jnp.where(ready, x, jnp.zeros_like(x)) for x in (g_color, g_trans))
    if plan_.image:  # the colour image's cotangent, per tile: (n_tiles, 256, 3)
        g_color = tiled_image_to_tiles(g_color)
    lane_rows = (trans, stop_at, g_color[..., 0], g_color[..., 1], g_color[..., 2], g_trans)
    if g_depth is not None or plan_.kernel != "mosaic":  # the Mosaic GPU kernel takes None
        lane_rows += (backward.depth_cotangent(g_depth, trans),)
    if plan_.kernel == "mosaic":
        segs = (segments.split(bins, layout.end, plan_.segment, plan_.rows) if entry
                else segments.whole_tiles(tile_order, bins, layout.end))
        # without a depth cotangent the kernel takes no D − D_hi entry either (XLA then drops
        # its subtraction)
        rows = mosaic_backward.backward_rows(config, plan_.interpret, plan_.backward_pixels,
                                             tiles_x, segs, bins, layout, second, lane_rows,
                                             dt, entry if g_depth is not None else entry[:4])
        # the table holds the fields `sums` reads
        return gaussian_grads.sums(rows, layout, second, tiles_x, config, plan_.interpret)
    rows = triton.backward_rows(config, plan_.interpret, tiles_x, tile_order, bins, layout,
                                first, second, lane_rows, dt)
    return gaussian_grads.sums(rows, layout, p, tiles_x, config, plan_.interpret)


def _render_forward(p, bins, gaussian_table, width, height, plan_: Plan):
    return forward(p, bins, gaussian_table, width, height, plan_, render=True)


_COMPOSITE = differentiable(_render_forward, gradients, forward)


def rasterize(p: Projected, bins: TileBins, width: int, height: int, config: RasterConfig,
              inputs: BackendInputs = BackendInputs(), vanilla: bool = False) -> RasterResult:
    """Composite every tile with the Local-GS (or vanilla) kernel (differentiable: a custom_vjp
    whose backward is the backward kernel)."""
    plan_ = plan(config, vanilla, bins.tile_start.shape[0], inputs.row_capacity)
    color, trans, depth, stop, strip_pairs = _COMPOSITE(p, bins, inputs.prepared, width,
                                                        height, plan_)
    walked = pairs_walked(stop, bins.tile_start, bins.tile_end)
    rows = inputs.row_capacity
    stats = PallasStats(strip_pairs=strip_pairs, pairs_walked=walked,
                        row_overflow=jnp.bool_(False) if rows is None else walked > rows,
                        kernel=plan_.kernel_name, interpreted=plan_.interpret)
    return RasterResult(color=color, trans=trans, depth=depth, stop=stop, stats=stats,
                        image_color=plan_.image)


def empty_stats(vanilla: bool):
    """`Backend.empty_stats` of the two Pallas backends."""
    def stats(config: RasterConfig) -> PallasStats:
        resolved = plan(config, vanilla, n_tiles=0)
        zero = jnp.int32(0)
        return PallasStats(strip_pairs=zero, pairs_walked=zero, row_overflow=jnp.bool_(False),
                           kernel=resolved.kernel_name, interpreted=resolved.interpret)

    return stats


def prepare(p: Projected, config: RasterConfig, n_tiles: int, capacity: int):
    """`Backend.prepare` of `pallas`: the Gaussian table the Local-GS Mosaic GPU kernels read
    (.table; not differentiated: the backward kernel's gradients are the projected fields'
    whole derivative), None for the Triton kernels."""
    del capacity
    plan_ = plan(config, False, n_tiles)
    if plan_.kernel != "mosaic":
        return None
    return table.gaussian_table(lax.stop_gradient(p), plan_.interpret)


LOCALGS = Backend("pallas", rasterize, empty_stats=empty_stats(False), prepare=prepare,
                  row_capacity=True)
VANILLA = Backend("pallas_vanilla", lambda *args: rasterize(*args, vanilla=True),
                  empty_stats=empty_stats(True), row_capacity=True)
