"""Gaussian parallelism (model parallelism, as Grendel): a scene split over D devices renders
as the whole scene does on one.

Per view, in one `jax.shard_map` over the mesh axis "gaussians" (lgs_jax.parallel.shards):
  1. each device projects its block of Gaussians (`projection.project`);
  2. packs, per destination band, the records of its Gaussians whose tile rectangle reaches
     that band (lgs_jax.parallel.exchange: fixed capacity, counts reported);
  3. `lax.all_to_all` delivers them: device d holds every Gaussian reaching band d, in global
     row order;
  4. device d composites the full image's tile grid from what it received
     (`render.composite_projected`) and keeps its band's pixel rows;
  5. the bands, disjoint, are the output's blocks along the image rows (no arithmetic).

Forward: bit-identical to `render` of the whole scene (image, alpha, depth, visible). Every
pixel of band d is composited from its tile's list, which holds the same Gaussians (all those
reaching the band, exchange docstring) with the same bits (records are copied, the projection
is elementwise) in the same (depth, index) order (received rows are in global order).

Backward: JAX differentiates through the shard_map; the all-to-all transposes to an all-to-all,
and each source sums its Gaussians' cotangents over the destinations. A Gaussian's cotangent of
its projected fields is the sum over its tiles of one gradient row each (the same bits as on
one device, the walk of a tile being the same). One device sums those rows in emission order,
16 at a time then across chunks (backends.backward.segment_sums), an association set by where
the Gaussian's rows fall in the whole pair buffer; here each band sums its own tiles' rows
(where they fall in its buffer) and the source adds the band sums. A device's tiles outside its
band get zero cotangents, so their rows are exact zeros. Both are sums of the same K numbers
(K = the Gaussian's tiles), so (any order of summation: Higham, Accuracy and Stability of
Numerical Algorithms, ch. 4)

    |ĝ_sharded − ĝ_one| <= 2·γ_(K−1)·Σ_t |r_t|,   γ_m = m·u / (1 − m·u),

u the unit roundoff (2^-24 float32, 2^-53 float64), r_t the Gaussian's row of tile t. The
projection's backward then maps both through the same Jacobian. The background's and the
camera's gradients, sums over pixels, are likewise re-associated (each device sums its band,
then a psum). `tests/parallel` checks the bound, row by row.

Batched cameras render one view after another (`_over_views`), each view bit-identical to
`render` of that view alone.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax
from jax.sharding import PartitionSpec as P

from .. import binning
from ..config import RasterConfig
from ..layout import TILE
from ..projection import Projected, project, shifted
from ..render import (BACKENDS, CapacityError, composite_projected, default_backend,
                      pair_capacity)
from ..scene import Camera, validate_background, validate_camera, validate_gaussians
from . import exchange
from .shards import GAUSSIANS, VIEWS, GaussianShards, shard_count, to_host


@jax.tree_util.register_dataclass
@dataclasses.dataclass
class ShardedStats:
    """Counts of a sharded render (int32 / bool arrays; a leading view axis for batched
    cameras).

    Attributes:
      n_valid, n_invalid, n_transparent, n_unbounded: as `render.RenderStats`, of the real
        Gaussians (the padding rows are not counted).
      pairs_required: (D,) tile–Gaussian pairs each device's render needs (each received
        Gaussian's whole tile rectangle; where the exchange left records behind, theirs
        counted too, from the sources' plans).
      capacity: the pair buffer of each device.
      overflow: some device's pairs_required > capacity (its band lacks the farthest pairs).
      exchange_counts: (D, D) records source s must send to destination d ([s, d]).
      exchange_required: the largest of them: the exchange capacity that holds every record.
      exchange_capacity: the records each source can send each destination.
      exchange_overflow: exchange_required > exchange_capacity (records were left behind).
      backend: the backend that composited (static).
    """

    n_valid: Any
    n_invalid: Any
    n_transparent: Any
    n_unbounded: Any
    pairs_required: Any
    capacity: Any
    overflow: Any
    exchange_counts: Any
    exchange_required: Any
    exchange_capacity: Any
    exchange_overflow: Any
    backend: str = dataclasses.field(metadata=dict(static=True))


@jax.tree_util.register_dataclass
@dataclasses.dataclass
class ShardedOutput:
    """image (H, W, 3), alpha (H, W), depth (H, W) as `render.RenderOutput` (a leading view
    axis for batched cameras), whole images assembled from the devices' bands (sharded along
    the rows: band d on device d); visible (D·n,) over the padded rows, sharded as the
    Gaussians; stats a `ShardedStats`."""

    image: Any
    alpha: Any
    depth: Any
    visible: Any
    stats: ShardedStats


def _source_counts(p, unbounded):
    """Per-source int32 counts: valid, invalid, transparent, unbounded."""
    i32 = functools.partial(jnp.sum, dtype=jnp.int32)
    return jnp.stack([i32(p.valid), i32(p.invalid), i32(~p.valid & ~p.invalid), i32(unbounded)])


def _composite_band(p, background, *, width: int, height: int, devices: int, backend: str,
                    config: RasterConfig, capacity: int, exchange_capacity: int):
    """The per-device program from this device's projected Gaussians `p` (module docstring,
    steps 2–4): a dict of this device's blocks of the outputs, each with a leading axis of 1
    where the output has no row axis to split."""
    masks = exchange.band_masks(p, width, height, devices)
    _, _, nx, ny, unbounded = binning.tile_rects(p, width, height)
    send, counts = exchange.pack(exchange.to_records(p), masks, exchange_capacity)
    planned = exchange.band_pairs(p, masks, width, height)  # the pairs it brings each device
    q = exchange.from_records(exchange.exchange(send, GAUSSIANS))
    out = composite_projected(q, width, height, background, backend, config, capacity)
    band = exchange.band_rows(height, devices) * TILE
    start = lax.axis_index(GAUSSIANS) * band

    def rows(x):
        x = jnp.pad(x, [(0, devices * band - height)] + [(0, 0)] * (x.ndim - 1))
        return lax.dynamic_slice_in_dim(x, start, band, axis=0)

    one = lambda x: jnp.reshape(x, (1,) + jnp.shape(x))
    return dict(image=rows(out.image), alpha=rows(out.alpha), depth=rows(out.depth),
                visible=nx * ny > 0, sources=one(_source_counts(p, unbounded)),
                counts=one(counts), pairs=one(out.stats.pairs_required), planned=one(planned))


def _over_sources(x):
    """(…, D) int32 sums over the sources' axis of (…, sources, D), saturating as
    `binning.total_pairs`."""
    rows = jnp.moveaxis(x, -2, -1)
    return jax.vmap(binning.total_pairs)(rows.reshape(-1, rows.shape[-1])).reshape(
        rows.shape[:-1])


def _one_view(g, cam, background, offsets, sh_bands, **static):
    """`_composite_band` of this device's Gaussians `g` projected through `cam` (step 1)."""
    p = project(g, cam, static["config"].antialiased, None, sh_bands)
    if offsets is not None:
        p = shifted(p, offsets)
    return _composite_band(p, background, width=cam.width, height=cam.height, **static)


def _assembled(out: dict, height: int, padding: int, backend: str, capacity: int,
               exchange_capacity: int) -> ShardedOutput:
    """The `ShardedOutput` of the shard_map's outputs (image rows past `height` cut; counts
    summed over sources, the `padding` rows taken out of the invalid ones)."""
    cut = lambda x: x[..., :height, :, :] if x.ndim == out["alpha"].ndim + 1 else x[..., :height, :]
    totals = jnp.sum(out["sources"], axis=-2, dtype=jnp.int32)  # (…, 4) over sources
    counts = out["counts"]  # (…, sources, destinations)
    required = jnp.max(counts, axis=(-2, -1))
    # a destination some source could not send every record counts the pairs of the plans
    short = jnp.any(counts > exchange_capacity, axis=-2)
    pairs = jnp.where(short, jnp.maximum(out["pairs"], _over_sources(out["planned"])),
                      out["pairs"])
    stats = ShardedStats(
        n_valid=totals[..., 0], n_invalid=totals[..., 1] - padding,
        n_transparent=totals[..., 2], n_unbounded=totals[..., 3], pairs_required=pairs,
        capacity=jnp.int32(capacity), overflow=jnp.any(pairs > capacity, axis=-1),
        exchange_counts=counts, exchange_required=required,
        exchange_capacity=jnp.int32(exchange_capacity),
        exchange_overflow=required > exchange_capacity, backend=backend)
    return ShardedOutput(image=cut(out["image"]), alpha=cut(out["alpha"]),
                         depth=cut(out["depth"]), visible=out["visible"], stats=stats)


def _over_views(one):
    """`one(g, cam, background, offsets, sh_bands)` over a batch of cameras (and offsets),
    one view after another (`lax.map`): each view is the program of one view, so its bits are
    those of `render` of that view alone (`jax.vmap` would compile batched fusions, which may
    round differently)."""
    def view(g, background, sh_bands, v):
        # With the view's camera behind one barrier, no part of the projection is invariant in
        # the loop: XLA hoisted those parts out of it, compiled apart and rounded differently.
        g, cam, offsets = lax.optimization_barrier((g, v[0], v[1]))
        return one(g, cam, background, offsets, sh_bands)

    def over(g, cams, background, offsets, sh_bands):
        return lax.map(functools.partial(view, g, background, sh_bands), (cams, offsets))
    return over


@functools.partial(jax.jit, static_argnames=("num", "mesh", "batched", "backend", "config",
                                             "capacity", "exchange_capacity"))
def _render_sharded(g, cam, background, offsets, sh_bands, *, num: int, mesh, batched: bool,
                    backend: str, config: RasterConfig, capacity: int, exchange_capacity: int):
    devices = shard_count(mesh)
    one = functools.partial(_one_view, devices=devices, backend=backend, config=config,
                            capacity=capacity, exchange_capacity=exchange_capacity)
    if batched:
        one = _over_views(one)
    lead = ((VIEWS,) if VIEWS in mesh.axis_names else (None,)) if batched else ()
    split = P(*lead, GAUSSIANS)
    off_spec = None if offsets is None else split
    bands_spec = None if sh_bands is None else P()
    body = jax.shard_map(one, mesh=mesh,
                         in_specs=(P(GAUSSIANS), P(*lead), P(), off_spec, bands_spec),
                         out_specs=split, check_vma=False)
    return _assembled(body(g, cam, background, offsets, sh_bands), cam.height, g.num - num,
                      backend, capacity, exchange_capacity)


@functools.partial(jax.jit, static_argnames=("width", "height", "mesh", "backend", "config",
                                             "capacity", "exchange_capacity"))
def composite_sharded(p: Projected, background, *, width: int, height: int, mesh,
                      backend: str, config: RasterConfig, capacity: int,
                      exchange_capacity: int) -> ShardedOutput:
    """`render_sharded` from projected Gaussians on (the sharded counterpart of
    `render.composite_projected`): `p`'s rows split in blocks over `mesh`'s "gaussians" axis
    (one view, no "views" axis), composited over `background` (3,). Differentiable with respect
    to `p`'s float fields and `background`; nothing is validated here."""
    one = functools.partial(_composite_band, width=width, height=height,
                            devices=shard_count(mesh), backend=backend, config=config,
                            capacity=capacity, exchange_capacity=exchange_capacity)
    body = jax.shard_map(one, mesh=mesh, in_specs=(P(GAUSSIANS), P()), out_specs=P(GAUSSIANS),
                         check_vma=False)
    return _assembled(body(p, background), height, 0, backend, capacity, exchange_capacity)

class ExchangeCapacityError(ValueError):
    """The exchange buffer holds fewer records than a source must send a destination."""

    def __init__(self, required: int, capacity: int):
        self.required, self.capacity = required, capacity
        super().__init__(f"exchange_capacity={capacity} holds fewer than the {required} records "
                         f"a device must send another; pass exchange_capacity >= {required} "
                         f"(e.g. {pair_capacity(required)})")


def _source_plan(g, cam, offsets, *, devices: int, antialiased: bool):
    """Per source: the records it sends each destination and the pairs they bring there."""
    width, height = cam.width, cam.height
    p = project(g, cam, antialiased)
    if offsets is not None:
        p = shifted(p, offsets)
    masks = exchange.band_masks(p, width, height, devices)
    counts = jnp.sum(masks, axis=1, dtype=jnp.int32)
    return jnp.stack([counts, exchange.band_pairs(p, masks, width, height)])[None]


@functools.partial(jax.jit, static_argnames=("mesh", "antialiased"))
def _count_sharded(g, cam, offsets, *, mesh, antialiased: bool):
    one = functools.partial(_source_plan, devices=shard_count(mesh), antialiased=antialiased)
    off_spec = None if offsets is None else P(GAUSSIANS)
    return jax.shard_map(one, mesh=mesh, in_specs=(P(GAUSSIANS), P(), off_spec),
                         out_specs=P(GAUSSIANS), check_vma=False)(g, cam, offsets)


def count_sharded(shards: GaussianShards, camera: Camera, mesh, *, antialiased: bool = False,
                  screen_offsets=None) -> tuple[int, int]:
    """(exchange_required, pairs_required) of `render_sharded` of one view, counted without
    exchanging: the most records a source sends a destination, and the most pairs a device's
    render needs (saturating at 2^31 − 1). Eager (host ints)."""
    plan = to_host(_count_sharded(shards.gaussians, camera, screen_offsets, mesh=mesh,
                                  antialiased=bool(antialiased))).astype(np.int64)
    return int(plan[:, 0].max()), int(min(plan[:, 1].sum(axis=0).max(), binning.MAX_PAIRS))


def _batch(camera: Camera, mesh) -> int | None:
    """Views in a batched camera (leaves with a leading axis), None for one camera; checked
    against the mesh's "views" axis (which splits a batch evenly, or renders one camera on
    every row)."""
    batch = None if np.ndim(camera.fx) == 0 else int(np.shape(camera.fx)[0])
    validate_camera(camera if batch is None else jax.tree.map(lambda x: x[0], camera))
    if VIEWS in mesh.axis_names and batch is not None and batch % mesh.shape[VIEWS]:
        raise ValueError(f"camera: a mesh with {mesh.shape[VIEWS]} {VIEWS!r} splits a batch of "
                         f"cameras evenly; got {batch}")
    return batch


def _checked_capacity(name: str, value) -> int:
    if not isinstance(value, (int, np.integer)) or not 0 < value <= binning.MAX_PAIRS:
        raise ValueError(f"{name}: expected an int in [1, 2^31 - 1] or None, got {value!r}")
    return int(value)


def render_sharded(shards: GaussianShards, camera: Camera, mesh, *, capacity: int | None = None,
                   exchange_capacity: int | None = None, background=None,
                   backend: str | None = None, config: RasterConfig | None = None,
                   screen_offsets=None, sh_bands=None) -> ShardedOutput:
    """Render the scene split over `mesh`'s "gaussians" axis through `camera` (module
    docstring): the image `render` gives for the whole scene, composited band by band.

    Args:
      shards: the scene (`shard_gaussians(g, mesh)`).
      camera: a `Camera`, or a batch of them (leaves with a leading view axis: then every
        output has one). A mesh with a "views" axis (`gaussian_mesh(d, views=v)`) splits the
        batch over its rows (data parallelism over views), each row a replica of the scene;
        one camera is rendered on every row (the outputs whole along "views").
      mesh: the device mesh the shards live on.
      capacity: the pair buffer of each device. None (eager only, one camera): counted first
        (`count_sharded`), then rounded up with `render.pair_capacity`. Under jit/grad pass an
        int and check `stats.overflow` (`render_sharded_growing` does that loop).
      exchange_capacity: the records a source can send each destination; None and ints as
        `capacity`, checked by `stats.exchange_overflow`.
      background: as `render`'s (one for every view).
      backend: as `render`'s, a tile backend (not "brute").
      config: as `render`'s.
      screen_offsets: optional (D·n, 2) (or (views, D·n, 2)) added to the projected means, as
        `render`'s, sharded as the Gaussians.
      sh_bands: as `render`'s (K,), on every device.

    Raises:
      ValueError: a bad argument. CapacityError / ExchangeCapacityError: an eager call whose
        pairs or records overflow the buffers given.
    """
    g = shards.gaussians
    validate_gaussians(g)
    devices = shard_count(mesh)
    if g.num % devices:
        raise ValueError(f"shards: {g.num} rows do not split into {devices} equal blocks; "
                         "use shard_gaussians")
    batch = _batch(camera, mesh)
    config = RasterConfig() if config is None else config
    backend = default_backend() if backend is None else backend
    if backend not in BACKENDS or backend == "brute":
        raise ValueError(f"backend: expected a tile backend of {BACKENDS}, got {backend!r}")
    background = jnp.zeros((3,), g.dtype) if background is None else background
    validate_background(background)
    traced = any(isinstance(x, jax.core.Tracer) for x in jax.tree.leaves((g, camera)))
    if capacity is None or exchange_capacity is None:
        if traced or batch is not None:
            raise ValueError("capacity, exchange_capacity: pass ints under jit/grad and for "
                             "batched cameras (count one view with count_sharded), then check "
                             "stats.overflow and stats.exchange_overflow")
        need_x, need_p = count_sharded(shards, camera, mesh, antialiased=config.antialiased,
                                       screen_offsets=screen_offsets)
        capacity = pair_capacity(need_p) if capacity is None else capacity
        exchange_capacity = (pair_capacity(need_x) if exchange_capacity is None
                             else exchange_capacity)
    if sh_bands is not None and np.shape(sh_bands) != (g.sh.shape[1],):
        raise ValueError(f"sh_bands: expected shape ({g.sh.shape[1]},), got "
                         f"{np.shape(sh_bands)}")
    out = _render_sharded(g, camera, jnp.asarray(background, g.dtype), screen_offsets, sh_bands,
                          num=shards.num, mesh=mesh, batched=batch is not None, backend=backend,
                          config=config, capacity=_checked_capacity("capacity", capacity),
                          exchange_capacity=_checked_capacity("exchange_capacity",
                                                              exchange_capacity))
    if not traced:
        _raise_overflow(out.stats)
    return out


def _raise_overflow(stats: ShardedStats) -> None:
    if np.any(to_host(stats.exchange_overflow)):
        raise ExchangeCapacityError(int(np.max(to_host(stats.exchange_required))),
                                    int(to_host(stats.exchange_capacity)))
    if np.any(to_host(stats.overflow)):
        raise CapacityError(int(np.max(to_host(stats.pairs_required))),
                            int(to_host(stats.capacity)))


def grown_capacities(stats, capacity: int, exchange_capacity: int) -> tuple[int, int] | None:
    """The (capacity, exchange_capacity) to retry with after a render whose `ShardedStats`
    (any pytree holding them) report an overflow, or None when nothing overflowed: each
    overflowing buffer grown to `pair_capacity` of the largest requirement (a render whose
    exchange overflowed counts the pairs of the records it left behind: both grow at once)."""
    found = [s for s in jax.tree.leaves(stats, is_leaf=lambda x: isinstance(x, ShardedStats))
             if isinstance(s, ShardedStats)]
    if not found:
        raise ValueError("stats: holds no ShardedStats to check for overflow")
    big = lambda name: max(int(np.max(to_host(getattr(s, name)))) for s in found)
    over = lambda name: any(bool(np.any(to_host(getattr(s, name)))) for s in found)
    if not over("overflow") and not over("exchange_overflow"):
        return None
    if big("pairs_required") >= binning.MAX_PAIRS:
        raise CapacityError(big("pairs_required"), capacity)
    if over("overflow"):
        capacity = pair_capacity(big("pairs_required"))
    if over("exchange_overflow"):
        exchange_capacity = pair_capacity(big("exchange_required"))
    return capacity, exchange_capacity


def render_sharded_growing(render_fn, *args, capacity: int, exchange_capacity: int, **kwargs):
    """Call `render_fn(*args, capacity=..., exchange_capacity=..., **kwargs)` (typically a
    jitted function of `render_sharded`, returning a pytree with its `ShardedStats`), growing
    the buffers that overflowed (`grown_capacities`) until none does. Returns (result,
    capacity, exchange_capacity): keep them for the next call."""
    while True:
        result = render_fn(*args, capacity=capacity, exchange_capacity=exchange_capacity,
                           **kwargs)
        grown = grown_capacities(result, capacity, exchange_capacity)
        if grown is None:
            return result, capacity, exchange_capacity
        capacity, exchange_capacity = grown
