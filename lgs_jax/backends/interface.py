"""What a backend is: one `rasterize` function and the result type every backend returns.

A backend composites projected Gaussians (lgs_jax.projection) into per-tile pixel state:

    rasterize(p, bins, width, height, config) -> RasterResult

with `bins` the sorted tile–Gaussian pairs (lgs_jax.binning; None for a backend that declares
`binned=False`). It must compute the rendering contract (conventions.md) and be differentiable
with respect to `p`'s float fields. Register it in lgs_jax/backends/__init__.py; `render` looks
it up by name and needs nothing else.
"""

from __future__ import annotations

import dataclasses
from typing import Any, Callable

import jax
import jax.numpy as jnp

# A pixel that never stopped records the end of its tile's list (its `tile_end`): the stop pair
# is always "the first pair this pixel did not blend because it was finished".


@jax.tree_util.register_dataclass
@dataclasses.dataclass
class RasterResult:
    """Per-tile output of a backend, (n_tiles, 256, ...) with pixel k of a tile at row k // 16,
    column k % 16 (lgs_jax.layout).

    Attributes:
      color: (n_tiles, 256, 3) Σ rgb·α·T over the blended Gaussians, or with `image_color`
        (tiles_y·16, tiles_x·16, 3): the tiles' pixels as an image.
      trans: (n_tiles, 256) final transmittance T.
      depth: (n_tiles, 256) Σ z·α·T.
      stop: (n_tiles, 256) int32 pair index at which each pixel stopped (its stop test fired,
        or the first pair its program never processed; the tile's end if it ran through its
        list), or (n_tiles, m) the latest of each group of a tile's pixels
        (`KernelConfig.mosaic_block_stops`: m blocks); None for backends without pairs.
      strip_pairs: int32 strip–Gaussian pairs processed (Local-GS backends; 8·pairs without
        warp culling), or None.
      kernel: name of the Pallas forward kernel that ran ("" for the XLA backends) (static).
      interpreted: the kernel ran in Pallas interpret mode (static).
      image_color: `color` is laid out as an image (static; `KernelConfig.mosaic_image_layout`).
    """

    color: Any
    trans: Any
    depth: Any
    stop: Any = None
    strip_pairs: Any = None
    kernel: str = dataclasses.field(default="", metadata=dict(static=True))
    interpreted: bool = dataclasses.field(default=False, metadata=dict(static=True))
    image_color: bool = dataclasses.field(default=False, metadata=dict(static=True))


def no_kernel(config) -> tuple[str, bool]:
    """`Backend.describe` of backends that run no Pallas kernel."""
    return "", False


@dataclasses.dataclass(frozen=True)
class Backend:
    """A registered backend.

    Attributes:
      name: the `render(..., backend=name)` string.
      rasterize: (p, bins, width, height, config) -> RasterResult (module docstring).
      binned: whether it needs the tile–Gaussian pairs (False: `bins` is None).
      describe: config -> (kernel name, interpreted), what `rasterize` would report, for renders
        that run no backend (an empty scene).
      pair_rows: its backward stores per-pair gradient rows (the Pallas backends), sized by
        `TileBins.row_capacity`.
      gaussian_table: (p, config, n_tiles, capacity) -> the per-Gaussian table its forward
        kernel reads, or None; `render` builds it before binning and hands it over as
        `TileBins.table` (None: the backend builds what it needs itself).
    """

    name: str
    rasterize: Callable[..., RasterResult]
    binned: bool = True
    describe: Callable[[Any], tuple[str, bool]] = no_kernel
    pair_rows: bool = False
    gaussian_table: Callable[..., Any] | None = None


def stop_within(stop, tile_end):
    """Stop records clipped to each tile's end (the one sentinel of `RasterResult.stop`)."""
    return jnp.minimum(stop, tile_end[:, None])


def tile_last(stop, tile_start, tile_end):
    """(n_tiles,) the end of each tile's walked pairs [tile_start, last): the latest stop pair
    of its pixels, within its range. Pairs at or after it were blended by no pixel (each
    pixel's stop is the first pair it did not blend because it was done)."""
    return jnp.clip(jnp.max(stop, axis=1), tile_start, tile_end)


def pairs_walked(stop, tile_start, tile_end):
    """Σ over tiles of their walked pairs (`tile_last`): the rows the Pallas backward writes
    with a `TileBins.row_capacity` (backends.gaussian_grads.walked_rows)."""
    return jnp.sum(tile_last(stop, tile_start, tile_end) - tile_start, dtype=jnp.int32)
