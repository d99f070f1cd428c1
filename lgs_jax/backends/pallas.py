"""`pallas` and `pallas_vanilla` backends: the rasterization stage as Pallas kernels, forward and
backward, on Triton (lgs_jax.backends.pallas_triton) or Mosaic GPU
(lgs_jax.backends.pallas_mosaic), with the per-pair arithmetic both share in
lgs_jax.backends.kernel_steps. This module picks the implementation (`plan`) and wires the
kernels into a custom_vjp.

Projection, binning and sorting stay in XLA (shared with the `tiles` backend). The plain-jnp
counterpart of each kernel, which the tests compare them with, is lgs_jax.backends.tiles (same
masks, same hoisted arithmetic, same blending semantics, same backward walk) and
lgs_jax.backends.reference (per-pixel semantics).

`pallas` runs the Local-GS kernel (Sec. III; a forward-only render whose pair buffer reaches
`KernelConfig.vanilla_from_pairs`, if set, runs the vanilla kernel instead): a
hoisted 6-vector V per (tile, Gaussian) pair (Eq. 8; built in the Mosaic GPU kernels,
lgs_jax.backends.mosaic_staging, or in XLA, `kernel_steps.pair_records`), ln α as
V·[x'², x'y', y'², x', y', 1] per pixel (Eq. 10), the strip masks as warp-uniform predicates
or branches (Sec. III-C), exact or fast (Sec. III-D) blending. `pallas_vanilla` runs the
original 3DGS rasterizer (difference form, per-pixel termination, a tile-wide early exit); it
ignores the Local-GS switches (it is the baseline the paper measures against) but honours
`convention` and `blend`.

Programs run tiles in order of decreasing list length (longest-first scheduling: the slowest
programs start first and short ones fill in behind them; each writes its own output row). Both
kernels write each pixel's stop pair, which is all the backward needs besides the final T (a
render no gradient follows may keep only each block's latest, `KernelConfig.mosaic_block_stops`,
and may write the colour as an image, `mosaic_image_layout`: the forward's lean outputs).

Backward (both backends): the backward kernel walks each tile's pairs back to front from the
last pair any pixel blended, with the forward's own α arithmetic (hoisted V·B clamped at ln o, or
the difference form: the vanilla forward's backward is the Local-GS backward with hoist and
warp_cull off) and strip masks: the walk of lgs_jax.backends.backward, one pair per step. Each
pair's gradient, summed over its tile's pixels, is stored as a row in a buffer of rows for the
walked pairs only, numbered in emission-slot order (gaussian_grads.RowLayout; one writer per
row, no atomics): each Gaussian's rows are consecutive; a second kernel
(lgs_jax.backends.gaussian_grads) chains each Gaussian's rows through Eq. 8 (hoisted form) and
sums them, one lane per Gaussian in slot order: deterministic, and no per-pair XLA pass.

Implementation. `RasterConfig.kernel` picks "triton" or "mosaic" for every kernel; "auto" runs
`tuning.auto_*` per kernel on the GPU and Triton in interpret mode, and under differentiation
the forward of the backward's implementation (`Plan.for_gradients`), so that forward and
backward evaluate α with the same compiler's arithmetic (the compilers' exp and multiply-add
contraction can differ by an ulp, which could flip an alpha test between them). Without a GPU
the kernels run in Pallas interpret mode (slow, meant for tests); `stats.kernel` names the
forward kernel that ran ("localgs-triton", "vanilla-mosaic", ...), `stats.interpreted` says
whether it was interpreted.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
from jax import lax

from .. import pairs
from ..binning import TileBins
from ..composite import PixelState
from ..config import RasterConfig
from ..layout import STRIPS, TILE_PIXELS, image_tiles, tile_grid, tiled_image_to_tiles
from ..projection import Projected
from . import (backward, backward_segments, block_order, gaussian_grads, kernel_steps,
               pallas_mosaic, pallas_triton, table_kernel)
from .interface import Backend, RasterResult, stop_within, tile_last


@dataclasses.dataclass(frozen=True)
class Plan:
    """Everything static about one Pallas rasterization, resolved once per trace (`plan`).

    Attributes:
      config: the RasterConfig rendered.
      vanilla: the vanilla kernel (else Local-GS).
      routed: the `pallas` backend running the vanilla kernel for a forward-only render
        (`KernelConfig.vanilla_from_pairs`); `for_gradients` goes back to Local-GS.
      forward, backward: "triton" or "mosaic", the forward and backward kernels' implementation.
      interpret: the kernels run in Pallas interpret mode.
      forward_pixels, backward_pixels: Mosaic GPU pixels per block (128 or 256).
      image: the forward writes its colour as one (tiles_y·16, tiles_x·16, 3) image
        (`KernelConfig.mosaic_image_layout`), else as per-tile planes; the same for a render
        and for the forward a backward follows (custom_vjp's two must return alike).
      block_stops: the stop pairs returned are each block's latest, (n_tiles, 256 /
        forward_pixels) (`KernelConfig.mosaic_block_stops`): written so by a render's Local-GS
        Mosaic GPU forward, reduced so from the pixels' by the forward a backward follows.
    """

    config: RasterConfig
    vanilla: bool
    forward: str
    backward: str
    interpret: bool
    forward_pixels: int
    backward_pixels: int
    routed: bool = False
    image: bool = False
    block_stops: bool = False

    @property
    def kernel_name(self) -> str:
        """The forward kernel `render` reports in `stats.kernel`, e.g. "localgs-mosaic"."""
        return f"{'vanilla' if self.vanilla else 'localgs'}-{self.forward}"

    def for_gradients(self) -> Plan:
        """The plan of the forward whose residuals the backward kernel uses (and of that
        backward): with kernel="auto", the forward of the backward's implementation, and the
        backend's own kernel where a forward-only render would be `routed`; and with a Triton
        backward, records built in XLA (`tuning.mosaic_pair_source` "records"), which it
        reads."""
        config = self.config
        if config.tuning.mosaic_pair_source != "records" and self.backward != "mosaic":
            # A Triton backward reads records: the forward reads the same ones.
            tuning = dataclasses.replace(config.tuning, mosaic_pair_source="records")
            config = dataclasses.replace(config, tuning=tuning)
        if config.kernel != "auto":
            return dataclasses.replace(self, config=config)
        return dataclasses.replace(self, config=config, forward=self.backward,
                                   vanilla=self.vanilla and not self.routed, routed=False)


def interpreted(config: RasterConfig) -> bool:
    """Whether the kernels run in interpret mode (`KernelConfig.interpret`; by default when JAX's
    default backend is not a GPU)."""
    interpret = config.tuning.interpret
    return jax.default_backend() != "gpu" if interpret is None else interpret


def block_pixels(fixed: int | None, n_tiles: int, config: RasterConfig) -> int:
    """Pixels per Mosaic GPU block: `fixed` if set, else whole tiles (256) from
    `tuning.mosaic_whole_tile_from` tiles on (short lists: one block's per-tile work and record
    loads serve twice the pixels) and half tiles (128) below (long lists: two blocks stop
    independently and, in the backward, skip the pairs none of their four strips takes)."""
    if fixed is not None:
        return fixed
    return 256 if n_tiles >= config.tuning.mosaic_whole_tile_from else 128


def plan(config: RasterConfig, vanilla: bool, n_tiles: int, capacity: int = 0) -> Plan:
    """Resolve `config` for an image of `n_tiles` tiles and a pair buffer of `capacity` on this
    platform."""
    t = config.tuning
    interpret = interpreted(config)
    routed = (not vanilla and config.kernel == "auto" and t.vanilla_from_pairs is not None
              and capacity >= t.vanilla_from_pairs)
    vanilla = vanilla or routed
    if config.kernel != "auto":
        forward = backward_impl = config.kernel
    elif interpret:
        forward = backward_impl = "triton"
    else:
        forward, backward_impl = (t.auto_vanilla if vanilla else t.auto_localgs), t.auto_backward
    forward_pixels = t.mosaic_forward_pixels
    if forward_pixels is None and not vanilla and pallas_mosaic.compacts(config):
        forward_pixels = 128  # compacted blocks: half tiles (KernelConfig.mosaic_compact)
    resolved = Plan(config=config, vanilla=vanilla, forward=forward, backward=backward_impl,
                    interpret=interpret,
                    forward_pixels=block_pixels(forward_pixels, n_tiles, config),
                    backward_pixels=block_pixels(t.mosaic_backward_pixels, n_tiles, config),
                    routed=routed)
    local_mosaic = lambda q: q.forward == "mosaic" and not q.vanilla
    # the forwards that write an image (pallas_mosaic.forward)
    writes = lambda q: local_mosaic(q) and q.forward_pixels == 128
    image = (t.mosaic_image_layout and writes(resolved) and writes(resolved.for_gradients()))
    block_stops = t.mosaic_block_stops and local_mosaic(resolved)
    return dataclasses.replace(resolved, image=image, block_stops=block_stops)


def describe(vanilla: bool):
    """`Backend.describe` of the two Pallas backends (kernel name and interpret mode)."""
    def kernel(config: RasterConfig) -> tuple[str, bool]:
        resolved = plan(config, vanilla, n_tiles=0)
        return resolved.kernel_name, resolved.interpret

    return kernel


def _longest_first(bins: TileBins, config: RasterConfig):
    """Tiles from the longest list to the shortest (`KernelConfig.block_order`)."""
    return block_order.longest_first(bins.tile_end - bins.tile_start, config.tuning.block_order)


def _vanilla_model(config: RasterConfig) -> RasterConfig:
    """The switches the vanilla kernel's arithmetic corresponds to: the difference form on the
    tile's whole list (its backward is the Local-GS backward kernel with these)."""
    return dataclasses.replace(config, hoist=False, warp_cull=False)


def _every_strip(bins: TileBins):
    """Strip–Gaussian pairs without warp culling: every strip of every real pair's tile."""
    return STRIPS * jnp.sum(bins.tile < bins.tile_start.shape[0], dtype=jnp.int32)


def _records(p: Projected, bins: TileBins, tiles_x: int, config: RasterConfig):
    """(strip masks or None, pair records, strip–Gaussian pairs) of the Local-GS kernels, built
    in XLA (`pairs`, `kernel_steps.pair_records`)."""
    pg = pairs.gather(p, bins.gauss)
    if not config.warp_cull:
        return None, kernel_steps.pair_records(pg, bins, tiles_x, config), _every_strip(bins)
    masks = pairs.strip_masks(pg, bins, tiles_x, config)
    strip_pairs = jnp.sum(lax.population_count(masks), dtype=jnp.int32)
    return masks, kernel_steps.pair_records(pg, bins, tiles_x, config, masks), strip_pairs


def _backward_staged(plan_: Plan) -> bool:
    """Whether the backward kernel reads (Gaussian ids, `pairs.gaussian_table`) as its
    (masks, records): a Mosaic GPU backward with `tuning.mosaic_pair_source` "gaussians"."""
    return (plan_.backward == "mosaic"
            and plan_.config.tuning.mosaic_pair_source == "gaussians")


def _forward_staged(plan_: Plan) -> bool:
    """Whether the forward kernel reads (Gaussian ids, `pairs.gaussian_table`): a Local-GS
    Mosaic GPU forward with `tuning.mosaic_pair_source` "gaussians"."""
    return (plan_.config.tuning.mosaic_pair_source == "gaussians" and not plan_.vanilla
            and plan_.forward == "mosaic")


def gaussian_table(p: Projected, config: RasterConfig, n_tiles: int, capacity: int):
    """`Backend.gaussian_table` of the `pallas` backend: the table a staged Local-GS forward
    reads (lgs_jax.backends.table_kernel), built by `render` before binning (the backward reads
    the same one), else None. None too where the forward a backward follows does not read it
    (a Triton backward: records built in XLA, `Plan.for_gradients`), which would leave it
    unused under differentiation; such a forward alone builds it itself (`_kernel_inputs`).
    Not differentiated: the backward kernel's gradients are the projected fields' whole
    derivative."""
    plan_ = plan(config, False, n_tiles, capacity)
    if not (_forward_staged(plan_) and _forward_staged(plan_.for_gradients())):
        return None
    return table_kernel.gaussian_table(lax.stop_gradient(p), plan_.interpret)


def _kernel_inputs(p: Projected, bins: TileBins, tiles_x: int, plan_: Plan):
    """(forward kernel data, strip–Gaussian pairs, what the backward kernel reads).

    With `tuning.mosaic_pair_source` "gaussians" the Mosaic GPU kernels build their records
    themselves from the pairs' Gaussian ids and `pairs.gaussian_table` (written by
    lgs_jax.backends.table_kernel, staged by lgs_jax.backends.mosaic_staging): the Local-GS
    forward gets (ids, table) and reports the strip pairs as not counted (−1), and a Mosaic GPU
    backward reads (ids, table) too, so no per-pair record is built in XLA. Otherwise (masks,
    records) from `_records` (the vanilla forward reads Gaussian rows by id; its backward,
    records of `_vanilla_model`, or (ids, table) on Mosaic GPU; it counts every strip of every
    pair)."""
    config = plan_.config
    model = _vanilla_model(config) if plan_.vanilla else config
    gaussians = config.tuning.mosaic_pair_source == "gaussians"
    table = bins.table  # `render` built it where the forward reads it (`gaussian_table`)
    if gaussians and table is None:
        table = table_kernel.gaussian_table(p, plan_.interpret)
    staged = (bins.gauss, table) if gaussians else None
    forward_staged = _forward_staged(plan_)
    backward_staged = _backward_staged(plan_)
    if forward_staged and backward_staged:
        return staged, jnp.int32(-1), staged
    vanilla_data = (bins.gauss, kernel_steps.gaussian_rows(p))
    if plan_.vanilla and backward_staged:
        return vanilla_data, _every_strip(bins), staged
    masks, records, strip_pairs = _records(p, bins, tiles_x, model)
    saved = staged if backward_staged else (masks, records)
    if forward_staged:
        return staged, jnp.int32(-1), saved
    if plan_.vanilla:
        return vanilla_data, strip_pairs, saved
    return (jnp.zeros((1,), jnp.int32) if masks is None else masks, records), strip_pairs, saved


def _segment(plan_: Plan) -> int | None:
    """The backward's segment length (`KernelConfig.mosaic_backward_segment`) where it applies:
    a Local-GS Mosaic GPU forward (which stores the checkpoints) and a Mosaic GPU backward."""
    mosaic = plan_.forward == "mosaic" and plan_.backward == "mosaic" and not plan_.vanilla
    return plan_.config.tuning.mosaic_backward_segment if mosaic else None


def _forward(p: Projected, bins: TileBins, width: int, height: int, plan_: Plan,
             segment: int | None = None, render: bool = False):
    """Per tile (n_tiles, 256): the state, the stop pairs (each pixel's, or each block's latest
    with `Plan.block_stops`), the strip–Gaussian pairs the kernel had to visit, and (masks,
    records, tile order, entry, each pixel's stop pair) for the backward; with a `segment`,
    entry = the segments' entering carries (`backward_segments.entries`; else ()). `render`:
    no backward follows (the kernel writes block stops itself, and the pixels' are None)."""
    dt = p.mean2d.dtype
    tiles_x, _ = tile_grid(width, height)
    order = _longest_first(bins, plan_.config)
    data, strip_pairs, saved = _kernel_inputs(p, bins, tiles_x, plan_)
    args = (plan_.vanilla, plan_.config, plan_.interpret)
    if plan_.forward == "mosaic":
        outs = pallas_mosaic.forward(*args, plan_.forward_pixels, tiles_x, order, bins, data, dt,
                                     segment=segment, image=plan_.image,
                                     block_stops=plan_.block_stops and render)
    else:
        outs = pallas_triton.forward(*args, tiles_x, order, bins, data, dt)
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
                if bins.row_capacity is not None else None)
        entry = backward_segments.entries(final_at, checks, bins, segment, last)
        # The entries before what reads the stop pairs after the forward: XLA would otherwise
        # subtract just before the backward kernel, keeping the four planes live next to the
        # cotangents (H200, 0.09M Gaussians at 4K: 348 -> 282 MiB; a barrier with the planes
        # themselves did as well there and cost 8 MiB at 5.8M Gaussians at 1080p).
        entry, stop_at = lax.optimization_barrier((entry, stop_at))
    stops = stop_at
    if plan_.block_stops and not render:  # the render's (n_tiles, blocks) from the pixels'
        blocks = TILE_PIXELS // plan_.forward_pixels
        stops = jnp.max(stop_at.reshape(stop_at.shape[0], blocks, -1), axis=-1)
    state = PixelState(color=color, trans=t, depth=d, done=jnp.zeros(t.shape, bool))
    pixel_stops = None if render and plan_.block_stops else stop_at
    return state, stops, strip_pairs, saved + (order, entry, pixel_stops)


def _gradients(p: Projected, bins: TileBins, width: int, height: int, plan_: Plan, trans,
               returned_stops, saved, cotangents):
    """(N, 10) per-Gaussian gradients of (mean2d, conic, opacity, rgb, depth) from the backward
    kernel's pair rows. The backward reads each pixel's stop pair from `saved`, not the stops
    the forward returned (per block with `Plan.block_stops`)."""
    del returned_stops
    plan_ = plan_.for_gradients()
    masks, records, order, entry, stop_at = saved
    config = _vanilla_model(plan_.config) if plan_.vanilla else plan_.config
    dt = p.mean2d.dtype
    tiles_x, _ = tile_grid(width, height)
    g_color, g_trans, g_depth = cotangents
    layout = gaussian_grads.rows_of(bins, stop_at)
    # The cotangents' per-tile planes made after the row layout, by a dependency on it: a
    # select on a predicate that always holds (end is a pair index), the same values. XLA
    # made them from the loss's cotangent at the program's start and kept them through the
    # forward kernel, where the temporaries peak (lego x16 1080p gradient compiled for the
    # H200: 353.1 -> 327.6 MiB). A barrier would keep its inputs instead: as many bytes.
    ready = layout.end[0] >= 0
    g_color, g_trans = (jnp.where(ready, x, jnp.zeros_like(x)) for x in (g_color, g_trans))
    if plan_.image:  # the colour image's cotangent, per tile: (n_tiles, 256, 3)
        g_color = tiled_image_to_tiles(g_color)
    masks = jnp.zeros((1,), jnp.int32) if masks is None else masks
    lane_rows = (trans, stop_at, g_color[..., 0], g_color[..., 1], g_color[..., 2], g_trans)
    if g_depth is not None or plan_.backward != "mosaic":  # the Mosaic GPU kernel takes None
        lane_rows += (backward.depth_cotangent(g_depth, trans),)
    if plan_.backward == "mosaic":
        segments = (backward_segments.split(bins, layout.end, _segment(plan_),
                                            compacted=bins.row_capacity is not None,
                                            order=config.tuning.block_order) if entry
                    else backward_segments.whole_tiles(order, bins, layout.end))
        # without a depth cotangent the kernel takes no D − D_hi entry either (XLA then drops
        # its subtraction: 10 MiB at 10M Gaussians at 4K)
        rows = pallas_mosaic.backward_rows(config, plan_.interpret, plan_.backward_pixels,
                                           tiles_x, segments, bins, layout, masks, records,
                                           lane_rows, dt, entry if g_depth is not None
                                           else entry[:4])
    else:
        rows = pallas_triton.backward_rows(config, plan_.interpret, tiles_x, order, bins, layout,
                                           masks, records, lane_rows, dt)
    # A staged backward's records are the Gaussian table, whose first columns are the fields
    # `sums` reads.
    return gaussian_grads.sums(rows, layout, records if _backward_staged(plan_) else p,
                               tiles_x, config, plan_.interpret)


def _forward_for_gradients(p, bins, width, height, plan_: Plan):
    plan_ = plan_.for_gradients()
    return _forward(p, bins, width, height, plan_, _segment(plan_))


def _render_forward(p, bins, width, height, plan_: Plan):
    return _forward(p, bins, width, height, plan_, render=True)


_COMPOSITE = backward.differentiable(_render_forward, _gradients, _forward_for_gradients)


def rasterize(p: Projected, bins: TileBins, width: int, height: int, config: RasterConfig,
              vanilla: bool = False) -> RasterResult:
    """Composite every tile with the Local-GS (or vanilla) kernel (differentiable: a custom_vjp
    whose backward is the backward kernel)."""
    plan_ = plan(config, vanilla, bins.tile_start.shape[0], bins.gauss.shape[0])
    color, trans, depth, stop, strip_pairs = _COMPOSITE(p, bins, width, height, plan_)
    return RasterResult(color=color, trans=trans, depth=depth, stop=stop, strip_pairs=strip_pairs,
                        kernel=plan_.kernel_name, interpreted=plan_.interpret,
                        image_color=plan_.image)


LOCALGS = Backend("pallas", rasterize, describe=describe(False), pair_rows=True,
                  gaussian_table=gaussian_table)
VANILLA = Backend("pallas_vanilla", lambda *args: rasterize(*args, vanilla=True),
                  describe=describe(True), pair_rows=True)
