"""A Gaussian-parallel run's state (`sharded`: slots stored in rows permuted by `order`, split
over the D devices of a mesh's "gaussians" axis, whole along its "views" axis, if any): placed
balanced, refined in slot order, saved as the one-device run saves it, its buffers sized, its
held-out views rendered sharded. The functions take the run's mesh (`sharded.mesh`).

- `balanced(mesh, parts, weights)`: the rows of (pool, opt_state, strategy_state), given
  in slot order, permuted by `balance.balanced_order(active, D, weights)` and placed in blocks
  over the mesh; returns them and `order` (row j holds slot order[j]). The weights are `work`
  (per slot: Σ over a few training views, `balance_views`, of 1 + the Gaussian's tile pairs
  in the view, the projection and binning a device does for it), so the blocks share the
  pairs, not just the count (without weights: by count).
- `in_slot_order(parts, order)`: back to slot order (the one-device layout): what a refinement
  runs on and a checkpoint holds, so a checkpoint is the one-device run's file and `--resume`
  takes it on any device count.
- `refine`: the one-device refinement (`step.refine`) of the state in slot order, the pool
  grown to multiples of D, then balanced again. Every operation of a refinement is
  elementwise, a gather, an integer count or a sort, so it gives the bits it gives on one
  device, split or not.
- `first_sizes`: the pair and exchange buffers of a new or resumed run, from its first
  training view (`parallel.count_sharded`) times the pair headroom.
- `Evaluations`, `render_views`: held-out scores and renders through `parallel.render_sharded`
  (the bits of `render`), buffers counted first.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from .. import parallel
from ..config import RasterConfig
from ..parallel.balance import balanced_order
from ..binning import tile_rects
from ..parallel.shards import padded_rows, shard_count
from ..projection import project
from ..render import pair_capacity
from . import heldout, sharded
from . import step as step_mod
from .pool import Pool, grow, per_gaussian, render_gaussians

shown = jax.jit(render_gaussians)
_order = jax.jit(balanced_order, static_argnums=1)


@functools.partial(jax.jit, static_argnames=("mesh",))
def _permuted(parts, order, *, mesh):
    size = order.shape[0]
    out = per_gaussian(parts, size, lambda x: jnp.take(x, order, axis=0))
    return sharded.constrained(mesh, out, size)[0]


BALANCE_VIEWS = 8  # the most training views `balance_views` picks


def balance_views(views: int) -> list[int]:
    """Which of `views` training views the blocks are balanced over (`work`): at most
    `BALANCE_VIEWS`, evenly spaced, the first and last included."""
    return [int(i) for i in np.unique(np.linspace(0, views - 1, min(views, BALANCE_VIEWS)
                                                  ).round().astype(int))]


@functools.partial(jax.jit, static_argnames=("antialiased",))
def _view_work(params, active, cam, *, antialiased: bool):
    p = project(render_gaussians(params, active), cam, antialiased)
    _, _, nx, ny, _ = tile_rects(p, cam.width, cam.height)
    return 1.0 + (nx * ny).astype(jnp.float32)


def work(pool: Pool, cams: list, antialiased: bool) -> jax.Array:
    """(size,) float32 per slot: Σ over `cams` of 1 + the Gaussian's tile pairs in that view
    (its projection and its binned pairs; an inactive slot has no pair). The weight
    `balanced_order` shares out."""
    total = jnp.zeros(pool.active.shape, jnp.float32)
    for cam in cams:
        total = total + _view_work(pool.params, pool.active, cam, antialiased=antialiased)
    return total


def balanced(m, parts: tuple, weights=None):
    """((pool, opt_state, strategy_state) with rows permuted by order and placed on mesh `m`
    (`sharded.mesh`), order), from `parts` in slot order (module docstring): the blocks over
    `m`'s "gaussians" balanced by `weights` (per slot, in slot order: `work`), or by count
    without them."""
    order = jax.device_put(_order(parts[0].active, shard_count(m), weights), sharded.blocks(m))
    return _permuted(parts, order, mesh=m), order


@jax.jit
def inverse(order):
    """The permutation that undoes `order`: slot i is row inverse[i]."""
    return jnp.zeros_like(order).at[order].set(jnp.arange(order.shape[0], dtype=order.dtype),
                                               unique_indices=True)


def in_slot_order(m, parts: tuple, order) -> tuple:
    """`parts` (rows permuted by `order`) in slot order, still in blocks over mesh `m`."""
    return _permuted(parts, inverse(order), mesh=m)


def place(m, parts: tuple, views):
    """(parts, views) on mesh `m` as `sharded.shardings` says (no copy where they are)."""
    rows, whole = sharded.shardings(m, parts, parts[0].size, views)
    return jax.device_put(parts, rows), jax.device_put(views, whole)


def refine(strategy, strategy_state, pool: Pool, opt_state, order, step: int, key, cap: int,
           m, cams: list = (), antialiased: bool = False):
    """`step.refine` of the state in slot order (module docstring) on mesh `m`, then balanced
    again by `work` over `cams` (by count without them). Returns (strategy_state, pool, opt_state,
    report, order); the report's `per_device` lists the active Gaussians of each device's
    block, with cams `per_device_work` each block's work and `heaviest` the largest one
    Gaussian's (a block's work is within it of an equal share unless the block is full)."""
    devices = shard_count(m)
    pool, opt_state, strategy_state = in_slot_order(m, (pool, opt_state, strategy_state), order)
    strategy_state, pool, opt_state, report = step_mod.refine(
        strategy, strategy_state, pool, opt_state, step, key, cap, devices)
    weights = work(pool, cams, antialiased) if cams else None
    (pool, opt_state, strategy_state), order = balanced(m, (pool, opt_state, strategy_state),
                                                        weights)
    report["per_device"] = per_device(devices, pool)
    if cams:
        w = jnp.where(pool.active, jnp.take(weights, order), 0.0)  # in row order
        report["per_device_work"] = [float(x) for x in parallel.to_host(
            jnp.sum(jnp.reshape(w, (devices, -1)), axis=1))]
        report["heaviest"] = float(parallel.to_host(jnp.max(w)))
    return strategy_state, pool, opt_state, report, order


def per_device(devices: int, pool: Pool) -> list[int]:
    """The active Gaussians of each device's block (host ints)."""
    return [int(c) for c in parallel.to_host(
        jnp.sum(jnp.reshape(pool.active, (devices, -1)), axis=1, dtype=jnp.int32))]


def padded(parts: tuple, devices: int) -> tuple:
    """(pool, opt_state, strategy_state) in slot order grown (`pool.grow`) to a multiple of
    `devices` slots (a checkpoint of another run resumed here), or as they are."""
    size = parts[0].size
    if size % devices == 0:
        return parts
    return grow(*parts, padded_rows(size, devices))


def _shards(pool: Pool) -> parallel.GaussianShards:
    return parallel.GaussianShards(shown(pool.params, pool.active), pool.size)


def counts(m, pool: Pool, cams, antialiased: bool) -> tuple[int, int]:
    """(pairs, records): the most pairs a device of mesh `m` needs to render any of `cams` and
    the most records a device sends another (`parallel.count_sharded`)."""
    shards = _shards(pool)
    need = [parallel.count_sharded(shards, cam, m, antialiased=antialiased) for cam in cams]
    return max(p for _, p in need), max(x for x, _ in need)


def first_sizes(m, pool: Pool, cam, antialiased: bool, headroom: float) -> tuple[int, int]:
    """(pair capacity, exchange capacity) of a run's step on mesh `m`: its first view's needs
    times `headroom` (`render.pair_capacity`)."""
    pairs, records = counts(m, pool, [cam], antialiased)
    return pair_capacity(pairs, headroom), pair_capacity(records, headroom)


@functools.partial(jax.jit, static_argnames=("mesh", "backend", "capacity", "exchange",
                                             "config", "score"),
                   compiler_options=step_mod.COMPILER_OPTIONS)
def _render(pool: Pool, cam, target, background, *, mesh, backend: str, capacity: int,
            exchange: int, config: RasterConfig, score: bool):
    """One held-out view of the pool: (PSNR, SSIM) against `target` with `score`, else the
    image (H, W, 3) whole on every device; and whether a buffer overflowed. On a mesh with
    "views" every row renders the view."""
    out = parallel.render_sharded(_shards(pool), cam, mesh, capacity=capacity,
                                  exchange_capacity=exchange, background=background,
                                  backend=backend, config=config)
    image = jax.lax.with_sharding_constraint(out.image, sharded.whole(mesh))
    overflow = out.stats.overflow | out.stats.exchange_overflow
    if score:
        return (*heldout.view_scores(image, target), overflow)
    return image, overflow


class Evaluations(heldout.Evaluations):
    """`heldout.Evaluations` of a pool split over the run's mesh: the held-out renders
    through `parallel.render_sharded`, both buffers counted first and sized with the run's
    headroom."""

    def __init__(self, cams, targets, background, setup, capacity: int, headroom: float,
                 mode: None = None):  # no compiles ahead
        super().__init__(cams, targets, background, setup, capacity, headroom)
        self.exchange = 1

    def score(self, pool: Pool) -> tuple[float, float]:
        s = self.setup
        pairs, records = counts(sharded.mesh_of(s), pool, self.cams, s.recipe.antialiased)
        if pairs > self.capacity:
            self.capacity = pair_capacity(pairs, self.headroom)
        if records > self.exchange:
            self.exchange = pair_capacity(records, self.headroom)
        scores = parallel.to_host([
            _render(pool, cam, jnp.asarray(target), self.background, mesh=sharded.mesh_of(s),
                    backend=s.backend, capacity=self.capacity, exchange=self.exchange,
                    config=s.recipe.raster, score=True)
            for cam, target in zip(self.cams, self.targets)])
        if any(bool(o) for _, _, o in scores):  # counted just before: cannot happen
            raise RuntimeError("a held-out view overflowed its buffers")
        return (float(np.mean([p for p, _, _ in scores])),
                float(np.mean([s for _, s, _ in scores])))

    def images(self, pool: Pool) -> list[np.ndarray]:
        images, self.capacity = render_views(sharded.mesh_of(self.setup), pool, self.cams,
                                             self.background, self.setup.backend,
                                             self.capacity, self.setup.recipe.raster)
        return images


def render_views(m, pool: Pool, cams, background, backend: str, capacity: int,
                 config: RasterConfig = RasterConfig()):
    """`step.render_views` of a pool split over mesh `m`: ([image (H, W, 3) numpy, clipped to
    [0, 1]] per camera, capacity), the buffers counted first."""
    pairs, records = counts(m, pool, cams, config.antialiased)
    capacity, exchange = max(capacity, pair_capacity(pairs)), pair_capacity(records)
    images = []
    for cam in cams:
        image, overflow = _render(pool, cam, None, background, mesh=m, backend=backend,
                                  capacity=capacity, exchange=exchange, config=config,
                                  score=False)
        image, overflow = parallel.to_host((image, overflow))
        if overflow:  # counted just before: cannot happen
            raise RuntimeError("a view overflowed its buffers")
        images.append(np.clip(image, 0.0, 1.0))
    return images, capacity
