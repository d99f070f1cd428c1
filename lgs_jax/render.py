"""The public entry point: `render(gaussians, camera, ...) -> RenderOutput`.

Pipeline: validate -> project (lgs_jax.projection) -> bin into 16x16 tiles (lgs_jax.binning)
-> rasterize with the chosen backend (lgs_jax.backends.REGISTRY) -> image, alpha, depth and
stats.

Capacity: tile–Gaussian pairs live in a static buffer of `capacity` pairs, and every per-pair
pass is sized by it. An eager call with `capacity=None` counts the pairs first and rounds up
with `pair_capacity` (a power of two up to 2^16, then eight sizes per octave: few recompiles,
at most 12.5% waste). Under
`jit`/`vmap` the caller passes `capacity` and reads `stats.overflow` / `stats.pairs_required`
(`render_growing` does that loop). An eager call never returns a truncated image: it raises
`CapacityError`.

Row capacity: the Pallas backward stores a gradient row per walked pair (a pair some pixel of its
tile reached) and block, in a buffer of the pair capacity's rows by default; `row_capacity`
sizes it for `stats.backend_stats.pairs_walked` instead, reported in
`stats.backend_stats.row_overflow` the same way.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from typing import Any, Callable

import jax
import jax.numpy as jnp
import numpy as np

from . import binning
from .backends import REGISTRY, BackendInputs, RasterResult
from .composite import PixelState, finish
from .config import RasterConfig
from .layout import tile_grid, tiles_to_image
from .projection import Projected, project, shifted
from .scene import (Camera, Gaussians, validate_background, validate_camera,
                    validate_gaussians)

BACKENDS = tuple(REGISTRY)


def default_backend() -> str:
    """The backend `render` uses when none is given: the fastest exact one for JAX's default
    platform (BENCHMARKS.md): `pallas` on a GPU, `tiles` elsewhere. Gradients take the render's
    backend; `lgs_jax.train`'s `fit` and `evaluate` take it as theirs."""
    return "pallas" if jax.default_backend() == "gpu" else "tiles"


class CapacityError(ValueError):
    """The pair buffer is too small (or the scene needs more than 2^31 − 1 pairs)."""

    def __init__(self, required: int, capacity: int):
        self.required, self.capacity = required, capacity
        if required >= binning.MAX_PAIRS:
            msg = "the scene needs at least 2^31 - 1 tile-Gaussian pairs, more than int32 indexes"
        else:
            msg = (f"capacity={capacity} holds fewer than the {required} tile-Gaussian pairs this "
                   f"render needs; pass capacity >= {required} (e.g. {pair_capacity(required)})")
        super().__init__(msg)


@jax.tree_util.register_dataclass
@dataclasses.dataclass
class RenderStats:
    """Counts that describe a render (int32 / bool arrays; batched under vmap).

    Attributes:
      n_valid: Gaussians that can reach the image (valid and opacity >= 1/255).
      n_invalid: Gaussians the contract calls invalid (skipped, never in the image).
      n_transparent: valid Gaussians culled because opacity < 1/255.
      n_unbounded: Gaussians whose float rounding could not be bounded, binned to every tile.
      pairs_required: tile–Gaussian pairs the scene needs (saturates at 2^31 − 1).
      capacity: size of the pair buffer used.
      overflow: pairs_required > capacity (the image lacks the farthest pairs).
      backend: name of the backend that rendered (static).
      backend_stats: the backend's own counts, or None: `tiles` a
        `backends.tiles.TilesStats` (strip pairs), `pallas` and `pallas_vanilla` a
        `backends.pallas.PallasStats` (strip pairs, walked pairs and the row overflow of
        render's `row_capacity`, the kernel that ran and whether it was interpreted).
    """

    n_valid: Any
    n_invalid: Any
    n_transparent: Any
    n_unbounded: Any
    pairs_required: Any
    capacity: Any
    overflow: Any
    backend: str = dataclasses.field(metadata=dict(static=True))
    backend_stats: Any = None


@jax.tree_util.register_dataclass
@dataclasses.dataclass
class RenderOutput:
    """image (H, W, 3) = C + T·background ((H, W, C) for `render(..., colors=(N, C))`);
    alpha (H, W) = 1 − T; depth (H, W) = Σ z·α·T;
    visible (N,) bool: the Gaussians whose alpha ellipse reaches the image (they have tile
    pairs), i.e. this view's visibility mask, which densification strategies count."""

    image: Any
    alpha: Any
    depth: Any
    stats: RenderStats
    visible: Any = None


def next_pow2(n: int) -> int:
    """Smallest power of two >= n (at least 1), capped at 2^31 − 1."""
    return min(1 << max(int(n) - 1, 0).bit_length(), binning.MAX_PAIRS)


SMALL_PAIRS = 2**16
"""Pair capacities up to this are powers of two (`pair_capacity`)."""


def pair_capacity(required: int, headroom: float = 1.0) -> int:
    """The pair-buffer size for `required` tile–Gaussian pairs times `headroom` (>= 1).

    With n = max(ceil(required·headroom), 1): the power of two >= n while n <= 2^16; above,
    n rounded up to a multiple of 2^(bit_length(n) − 4), i.e. a grid of eight sizes per octave,
    at most 12.5% above n and always a multiple of 8192; capped at 2^31 − 1. Every per-pair
    pass (emission, tile sort, pair records, backward rows) costs in proportion to the
    capacity, so powers of two would waste up to 2x; a finer grid would mean more distinct
    sizes, each a compile. Small buffers stay on powers of two: their waste costs little and
    few sizes mean few compiles.

    Raises:
      ValueError: headroom < 1 (a buffer smaller than the pairs drops pairs).
    """
    if not headroom >= 1:
        raise ValueError(f"headroom: expected a number >= 1, got {headroom!r}")
    n = max(math.ceil(int(required) * headroom), 1)
    if n <= SMALL_PAIRS:
        return next_pow2(n)
    step = 1 << (n.bit_length() - 4)
    return min(-(-n // step) * step, binning.MAX_PAIRS)


def _is_traced(tree) -> bool:
    return any(isinstance(x, jax.core.Tracer) for x in jax.tree.leaves(tree))


@functools.partial(jax.jit, static_argnames=("width", "height", "antialiased"))
def _count(g: Gaussians, cam: Camera, width: int, height: int, antialiased: bool,
           colors=None):
    return binning.count_pairs(project(g, cam, antialiased, colors), width, height)


def count_pairs(gaussians: Gaussians, camera: Camera, *, antialiased: bool = False,
                colors=None):
    """The tile–Gaussian pairs `render` of `gaussians` through `camera` needs (an int32 array,
    saturating at 2^31 − 1): the exact count the pair buffer must hold (`pair_capacity` rounds
    it up). Works under jit and vmap (the camera's image size is static)."""
    return _count(gaussians, camera, camera.width, camera.height, antialiased, colors)


def _stats(p: Projected, backend: str, capacity: int, bins: binning.TileBins | None,
           result: RasterResult) -> RenderStats:
    i32 = functools.partial(jnp.sum, dtype=jnp.int32)
    zero = jnp.int32(0)
    return RenderStats(
        n_valid=i32(p.valid), n_invalid=i32(p.invalid), n_transparent=i32(~p.valid & ~p.invalid),
        n_unbounded=bins.n_unbounded if bins else zero,
        pairs_required=bins.pairs_required if bins else zero,
        capacity=jnp.int32(capacity), overflow=bins.overflow if bins else jnp.bool_(False),
        backend=backend, backend_stats=result.stats)


@functools.partial(jax.jit, static_argnames=("backend", "config", "capacity", "row_capacity"))
def _render(g: Gaussians, cam: Camera, background, backend: str, config: RasterConfig,
            capacity: int, row_capacity: int | None, screen_offsets=None,
            colors=None, sh_bands=None) -> RenderOutput:
    p = project(g, cam, config.antialiased, colors, sh_bands)
    if screen_offsets is not None:
        p = shifted(p, screen_offsets)
    return composite_projected(p, cam.width, cam.height, background, backend, config, capacity,
                               row_capacity)


def composite_projected(p: Projected, width: int, height: int, background, backend: str,
                        config: RasterConfig, capacity: int,
                        row_capacity: int | None = None) -> RenderOutput:
    """`render` from projected Gaussians on (traceable; every argument after `background`
    static): bin `p` into a `capacity`-pair buffer, rasterize with `backend`, composite over
    `background` ((C,) for C colour channels of `p.rgb`). `render` projects and calls it; code
    that projects elsewhere (another device's shard, a cropped view) calls it directly.
    Differentiable with respect to `p`'s float fields (mean2d, conic, opacity, rgb, depth) and
    `background`; nothing is validated here (`render` does that)."""
    spec = REGISTRY[backend]
    tiles_x, tiles_y = tile_grid(width, height)
    prepare = lambda q: (None if spec.prepare is None
                         else spec.prepare(q, config, tiles_x * tiles_y, capacity))
    inputs = lambda prepared: BackendInputs(prepared, row_capacity)
    channels = p.rgb.shape[-1]
    three = channels == 3
    bins = prepared = None
    if spec.binned:
        binned, prepared = p, prepare(p) if three else None
        if prepared is not None:
            binned, prepared = binning.before_emission(p, prepared)
        bins = binning.bin_gaussians(binned, width, height, capacity)
    if three:
        result = spec.rasterize(p, bins, width, height, config, inputs(prepared))
        color = _image_color(result, width, height)
    else:
        color, result = _channel_passes(p, bins, lambda q: inputs(prepare(q)), spec.rasterize,
                                        width, height, config)
    state = PixelState(color=color, trans=tiles_to_image(result.trans, width, height),
                       depth=tiles_to_image(result.depth, width, height), done=None)
    image, alpha, depth = finish(state, background)
    return RenderOutput(image=image.reshape(height, width, channels),
                        alpha=alpha.reshape(height, width),
                        depth=depth.reshape(height, width),
                        stats=_stats(p, backend, capacity, bins, result),
                        visible=_visible(p, width, height))


def _channel_passes(p: Projected, bins, inputs, rasterize, width: int, height: int,
                    config: RasterConfig):
    """(colour (H·W, C), the first pass's `RasterResult`) of a `p` whose colour has C != 3
    channels: a backend composites three channels a pass, so the channels are padded with
    zeros to a multiple of three and composited three at a time over the same pairs, each
    pass with its own backend inputs (`inputs(q)`: what the backend prepares from that pass's
    colours), in a `lax.map` (the kernels are traced and compiled once, whatever C). Every
    pass blends the same α (the same pairs, the same arithmetic), so their transmittance and
    depth are the same bits."""
    channels = p.rgb.shape[-1]
    rgb = jnp.pad(p.rgb, ((0, 0), (0, -channels % 3)))
    chunks = rgb.reshape(rgb.shape[0], -1, 3).transpose(1, 0, 2)

    def one_pass(rgb3):
        q = dataclasses.replace(p, rgb=rgb3)
        result = rasterize(q, bins, width, height, config, inputs(q))
        return _image_color(result, width, height), result

    colors, results = jax.lax.map(one_pass, chunks)
    color = colors.transpose(1, 0, 2).reshape(width * height, -1)[:, :channels]
    return color, jax.tree.map(lambda x: x[0], results)


def _image_color(result: RasterResult, width: int, height: int):
    """A backend's colour as (H·W, 3) pixel rows."""
    if result.image_color:
        return result.color[:height, :width].reshape(height * width, 3)
    return tiles_to_image(result.color, width, height)


def _visible(p: Projected, width: int, height: int):
    _, _, nx, ny, _ = binning.tile_rects(p, width, height)
    return nx * ny > 0


def _empty_render(cam: Camera, background, dtype, backend: str,
                  config: RasterConfig) -> RenderOutput:
    h, w = cam.height, cam.width
    zero = jnp.int32(0)
    stats = RenderStats(n_valid=zero, n_invalid=zero, n_transparent=zero, n_unbounded=zero,
                        pairs_required=zero, capacity=zero, overflow=jnp.bool_(False),
                        backend=backend, backend_stats=REGISTRY[backend].empty_stats(config))
    image = jnp.broadcast_to(background, (h, w, background.shape[0])).astype(dtype)
    return RenderOutput(image=image,
                        alpha=jnp.zeros((h, w), dtype), depth=jnp.zeros((h, w), dtype),
                        stats=stats, visible=jnp.zeros((0,), bool))


def render(gaussians: Gaussians, camera: Camera, *, background=None, backend: str | None = None,
           config: RasterConfig | None = None, capacity: int | None = None,
           row_capacity: int | None = None, screen_offsets=None, colors=None,
           sh_bands=None) -> RenderOutput:
    """Render `gaussians` through `camera` (docs/conventions.md is the contract every backend
    meets).

    Args:
      gaussians: the scene; its dtype (float32 or float64) is the precision of the whole render.
      camera: a `Camera`; batch cameras with `jax.vmap` (then pass `capacity`).
      background: (3,) colour behind the scene, black by default.
      backend: "tiles" (Local-GS kernels in XLA, `config` switches), "pallas" (the Local-GS
        Pallas kernel, same switches), "pallas_vanilla" (the original 3DGS kernel in Pallas),
        "reference" (16x16 tiles, per-pixel semantics) or "brute" (all Gaussians for every
        pixel, no tiles: for small scenes). The Pallas backends run in interpret mode without a
        GPU (slow; `stats.backend_stats.interpreted`). None: `default_backend()`, the fastest
        exact backend for the platform (`stats.backend` says which ran).
      config: a `RasterConfig` (static), default `RasterConfig()`.
      capacity: size of the tile–Gaussian pair buffer. None (eager only): count, then round up
        with `pair_capacity`. Under jit/vmap pass an int and check `stats.overflow`.
      row_capacity: rows of the Pallas backends' backward buffer of per-pair gradients (48
        bytes per row and block of a tile; the memory of a gradient at scale), each a pair some
        pixel reached (`stats.backend_stats.pairs_walked`, a fraction of the pairs in large
        scenes). None: as many rows as `capacity` (nothing can overflow). An int: this many;
        the same gradients to the bit while `stats.backend_stats.row_overflow` is False. Size
        it from an earlier render's `pairs_walked` (`pair_capacity` of it leaves headroom) and
        check `row_overflow`. Other backends ignore it.
      screen_offsets: optional (N, 2) added to the projected means (pixels). Pass zeros and
        differentiate with respect to it to get ∂L/∂mean2d per Gaussian, the screen-space
        gradient densification strategies accumulate (with `visible`); binning sees the offset
        means too, so a non-zero offset renders the shifted scene exactly.
      colors: optional (N, C) per-Gaussian values composited in place of the SH colour, C >= 1
        (features, labels, normals: view-independent, used as given, no clamp; a row with a
        non-finite value is invalid, as a NaN SH coefficient makes it; `gaussians.sh` is then
        not read). The image is (H, W, C) = Σ colors·α·T + T·background, background (C,)
        (zeros by default), differentiable w.r.t. `colors` too. Three channels are
        composited in one pass, other C in ceil(C/3) passes sharing the projection and the
        pairs (each pass blends again: about C/3 times the kernel's time; one compile).
      sh_bands: optional (K,) factors of the K SH coefficients, 0 or 1 where a training
        schedule enables bands one by one (gsplat's `sh_degree`, as a traced mask: no
        recompile when a band is enabled); the colour is that of `gaussians.sh` scaled by them,
        computed inside the projection, so a gradient's backward holds no scaled copy.

    Raises:
      ValueError: a bad argument (the message names it).
      CapacityError: eager call whose pairs overflow `capacity` or exceed 2^31 − 1.
    """
    validate_gaussians(gaussians)
    validate_camera(camera)
    config = RasterConfig() if config is None else config
    if not isinstance(config, RasterConfig):
        raise ValueError(f"config: expected RasterConfig, got {type(config).__name__}")
    backend = default_backend() if backend is None else backend
    if backend not in BACKENDS:
        raise ValueError(f"backend: expected one of {BACKENDS} or None, got {backend!r}")
    dt = gaussians.dtype
    colors, background = _checked_colors(colors, background, gaussians.num, dt)
    for name, value in (("capacity", capacity), ("row_capacity", row_capacity)):
        if value is not None and (not isinstance(value, (int, np.integer))
                                  or not 0 < value <= binning.MAX_PAIRS):
            raise ValueError(f"{name}: expected an int in [1, 2^31 - 1] or None, got {value!r}")
    if gaussians.num == 0:
        return _empty_render(camera, background, dt, backend, config)
    capacity = _sized_capacity(capacity, gaussians, camera, background, backend, config, colors)
    if screen_offsets is not None and np.shape(screen_offsets) != (gaussians.num, 2):
        raise ValueError(f"screen_offsets: expected shape ({gaussians.num}, 2), got "
                         f"{np.shape(screen_offsets)}")
    rows = (int(row_capacity) if row_capacity is not None and REGISTRY[backend].row_capacity
            else None)
    if sh_bands is not None and np.shape(sh_bands) != (gaussians.sh.shape[1],):
        raise ValueError(f"sh_bands: expected shape ({gaussians.sh.shape[1]},), got "
                         f"{np.shape(sh_bands)}")
    out = _render(gaussians, camera, background, backend, config, int(capacity), rows,
                  screen_offsets, colors, sh_bands)
    if not _is_traced(out.stats.overflow) and bool(out.stats.overflow):
        raise CapacityError(int(out.stats.pairs_required), int(capacity))
    return out


def _sized_capacity(capacity, gaussians, camera, background, backend: str,
                    config: RasterConfig, colors) -> int:
    """`render`'s pair capacity: 0 for a backend without pairs, `capacity` if given, else (eager
    calls only) `pair_capacity` of the pairs the render needs."""
    if not REGISTRY[backend].binned:
        return 0  # no pair buffer
    if capacity is not None:
        return capacity
    if _is_traced((gaussians, camera, background)):
        raise ValueError("capacity: under jit/vmap/grad pass capacity=<int> (e.g. from an "
                         "eager render's stats.capacity), then check stats.overflow and "
                         "stats.pairs_required, or use lgs_jax.render_growing")
    required = int(count_pairs(gaussians, camera, antialiased=config.antialiased,
                               colors=colors))
    if required >= binning.MAX_PAIRS:
        raise CapacityError(required, 0)
    return pair_capacity(required)


def _checked_colors(colors, background, n: int, dtype):
    """`render`'s (colors, background) as arrays of `dtype`, (n, C) or None and (C,) (C = 3
    without colours; a zero background by default), or `ValueError` naming the problem."""
    channels = 3
    if colors is not None:
        shape = np.shape(colors)
        if len(shape) != 2 or shape[0] != n or shape[1] < 1:
            raise ValueError(f"colors: expected shape ({n}, C) with C >= 1 (one row per "
                             f"Gaussian), got {shape}")
        kind = jnp.result_type(colors)
        if not (jnp.issubdtype(kind, jnp.floating) or jnp.issubdtype(kind, jnp.integer)):
            raise ValueError(f"colors: expected real numbers, got dtype {kind}")
        colors, channels = jnp.asarray(colors, dtype), shape[1]
    if background is None:
        background = jnp.zeros((channels,), dtype)
    validate_background(background, channels)
    return colors, jnp.asarray(background, dtype)


def render_growing(render_fn: Callable[..., Any], *args, capacity: int, **kwargs):
    """Call `render_fn(*args, capacity=capacity, **kwargs)`, growing capacity until nothing drops.

    `render_fn` is typically a jitted function that calls `render` (and may vmap it) and returns
    either a `RenderOutput` or a pytree containing exactly one `RenderStats`. When any stats report
    overflow, capacity grows to `pair_capacity` of the largest `pairs_required` and the call is
    repeated (one recompile). Returns (result, capacity): keep the capacity for the next
    step so a training loop settles on a fixed size.
    """
    while True:
        result = render_fn(*args, capacity=capacity, **kwargs)
        stats = [x for x in jax.tree.leaves(result, is_leaf=lambda x: isinstance(x, RenderStats))
                 if isinstance(x, RenderStats)]
        if not stats:
            raise ValueError("render_fn: its result holds no RenderStats to check for overflow")
        required = max(int(np.max(np.asarray(s.pairs_required))) for s in stats)
        if not any(bool(np.any(np.asarray(s.overflow))) for s in stats):
            return result, capacity
        if required >= binning.MAX_PAIRS:
            raise CapacityError(required, capacity)
        capacity = pair_capacity(required)
