"""What a backend is: one `rasterize` function and the result type every backend returns.

A backend composites projected Gaussians (lgs_jax.projection) into per-tile pixel state:

    rasterize(p, bins, width, height, config, inputs) -> RasterResult

with `bins` the sorted tile–Gaussian pairs (lgs_jax.binning; None for a backend that declares
`binned=False`) and `inputs` the `BackendInputs` render hands over (what the backend's
`prepare` built before binning, the backward's row capacity). It must compute the rendering
contract (docs/conventions.md) and be differentiable with respect to `p`'s float fields.
Register it in lgs_jax/backends/__init__.py; `render` looks it up by name and needs nothing
else.
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
        list), or (n_tiles, m) the latest of each of m groups of a tile's pixels; None for
        backends without pairs.
      stats: the backend's own counts (a pytree the backend defines, e.g.
        lgs_jax.backends.pallas.PallasStats), or None; render returns it as
        `RenderStats.backend_stats`.
      image_color: `color` is laid out as an image (static).
    """

    color: Any
    trans: Any
    depth: Any
    stop: Any = None
    stats: Any = None
    image_color: bool = dataclasses.field(default=False, metadata=dict(static=True))


@dataclasses.dataclass(frozen=True)
class BackendInputs:
    """What `render` hands a backend's `rasterize` besides the projection and the pairs.

    Attributes:
      prepared: what the backend's `prepare` built before binning, or None.
      row_capacity: rows of the backward's buffer of per-pair gradient rows (render's
        `row_capacity`; static), for backends that declare `row_capacity=True`, else None.
    """

    prepared: Any = None
    row_capacity: int | None = None


@dataclasses.dataclass(frozen=True)
class Backend:
    """A registered backend.

    Attributes:
      name: the `render(..., backend=name)` string.
      rasterize: (p, bins, width, height, config, inputs) -> RasterResult (module docstring).
      binned: whether it needs the tile–Gaussian pairs (False: `bins` is None).
      empty_stats: config -> the `RasterResult.stats` of a render with no Gaussians (the same
        pytree structure as a real render's; None for a backend without stats).
      prepare: (p, config, n_tiles, capacity) -> per-Gaussian inputs the backend wants built
        before binning (render orders them before the pair emission, whose temporaries they
        would otherwise share the memory peak with: `binning.before_emission`), handed back in
        `BackendInputs.prepared`; None: nothing.
      row_capacity: it takes render's `row_capacity` (a backward that stores per-pair gradient
        rows: the Pallas backends).
    """

    name: str
    rasterize: Callable[..., RasterResult]
    binned: bool = True
    empty_stats: Callable[[Any], Any] = lambda config: None
    prepare: Callable[..., Any] | None = None
    row_capacity: bool = False


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
    with a row capacity (lgs_jax.backends.pallas.gaussian_grads.walked_rows)."""
    return jnp.sum(tile_last(stop, tile_start, tile_end) - tile_start, dtype=jnp.int32)
