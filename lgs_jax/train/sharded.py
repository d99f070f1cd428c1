"""Gaussian-parallel training (`FitConfig.gaussian_devices` = D > 1): the pool, its Adam
moments and its strategy's accumulators split over D devices, rendered through
`lgs_jax.parallel` (docs/multi-gpu.md).

The mesh (`mesh`, `mesh_of`). D devices along "gaussians"; with `FitConfig.devices` = V > 1
too, V x D devices, V rows ("views") of D: every row holds the whole state split in the same D
blocks (whole along "views"), and renders its share of each step's batch of views (B/V of
them, B a multiple of V). Every sharding of the run is built from the mesh (`whole`, `blocks`,
`shardings`).

Slots and rows. A run's slots are those of the one-device run: where a refinement puts each new
Gaussian (`ops.allocate`), which random numbers each slot draws. On D devices the slots are
stored permuted: row j of every per-Gaussian array holds slot order[j], and the rows are split
in D contiguous blocks over the mesh axis "gaussians".
`parallel.balance.balanced_order(active, D)` picks the order: every block holds an equal share
of the active Gaussians (within one: each device sends about as many records to each band, so
the exchange's buffers stay small), and the active Gaussians keep their relative order (the
render's tie-break, and scene.ply's order). The run state carries `order`
(`lgs_jax.train.sharded_state` places, refines and saves it).

The step (`step.train_step` with `Setup.gaussian_devices` = D): the views are rendered by
`parallel.render_sharded` (`render_views`; each row of the mesh its share of the views), each
device compositing its band of image rows from the projected records the others of its row
send it; the images are then gathered whole on every device (`with_sharding_constraint`) and
the loss is the one-device function of the whole images (compiled in another program: its sums
may round differently), their mean over the batch. The gradient flows back through the
exchange to the rows that sent the records; JAX's transpose of the `shard_map` sums each
block's gradient over the rows of the mesh (a psum over "views", the only communication the
views add). Adam and the strategies' per-step updates are elementwise over the Gaussians, so
each device updates its own block in place, every row the same (a strategy's sum over the
batch's views, as the default strategy's screen gradients, is summed per row, then across
rows). Random numbers drawn per slot (MCMC's noise on
the means) are taken in slot order (`StepInfo.slots`), so every slot draws what it draws on one
device.

Determinism. The forward is the one-device bits, on any mesh. Each Gaussian's gradient with
respect to its projected fields is the same K tile rows summed in another order (one per band,
then across bands), within 2·γ_(K−1)·Σ_t |r_t| of the one-device sum
(lgs_jax.parallel.gaussian_parallel); on V rows, the views' gradients (and the strategies'
sums over views) are summed per row, then across rows: one more re-association of the batch's
sum. Adam's scale-free update turns such a
difference, where a gradient is within rounding of zero, into up to a learning rate, so runs on
different meshes whose refinements decide the same stay within `drift_bound` of each other
(docs/multi-gpu.md), not to the bit. Everything else (the strategies' updates, refinements, the
layout) is elementwise or exact.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
from jax.sharding import NamedSharding, PartitionSpec

from .. import parallel
from .pool import per_gaussian


@functools.cache
def mesh(gaussians: int, views: int = 1) -> jax.sharding.Mesh:
    """The mesh of a run over `views` x `gaussians` devices, the first ones of `jax.devices()`
    (`parallel.gaussian_mesh`): 1-D ("gaussians",) for one view row, else 2-D ("views",
    "gaussians"), each row of the mesh a replica of the pool split `gaussians` ways."""
    return parallel.gaussian_mesh(gaussians, views)


def mesh_of(config) -> jax.sharding.Mesh:
    """`mesh(config.gaussian_devices, config.devices)`: the mesh of a run of `config` (a
    `FitConfig` or a `Setup`)."""
    return mesh(config.gaussian_devices, config.devices)


def whole(m: jax.sharding.Mesh) -> NamedSharding:
    """Whole on every device of mesh `m`."""
    return NamedSharding(m, PartitionSpec())


def blocks(m: jax.sharding.Mesh) -> NamedSharding:
    """Rows in contiguous blocks over `m`'s "gaussians", whole along "views"."""
    return parallel.gaussian_sharding(m)


def shardings(m: jax.sharding.Mesh, parts: tuple, size: int, views=None):
    """The shardings on mesh `m` of a run's (pool, opt_state, strategy_state) with `size` rows
    and of its views' parameters `views`: per-Gaussian leaves (leading axis `size`, as
    `pool.per_gaussian` finds them) in blocks over "gaussians" (whole along "views"), the rest
    (counts, the scene scale, the views' parameters, and empty leaves, as the higher SH bands
    of degree 0, whose blocks XLA gives back whole: one sharding, one compile) whole on every
    device. Returns (parts', views')."""
    rows = jax.tree.map(lambda x: x if isinstance(x, NamedSharding) else whole(m),
                        per_gaussian(parts, size, lambda x: blocks(m) if x.size else whole(m)))
    return rows, jax.tree.map(lambda _: whole(m), views)


def constrained(m: jax.sharding.Mesh, parts: tuple, size: int, views=None):
    """(parts, views) constrained (inside jit) to their `shardings` on `m`."""
    rows, everywhere = shardings(m, parts, size, views)
    return (jax.lax.with_sharding_constraint(parts, rows),
            jax.lax.with_sharding_constraint(views, everywhere))


def render_views(setup, capacity: int, exchange: int, g, cams, background, offsets,
                 sh_bands=None):
    """The training render of a batch of views `cams` (stacked) of the rows `g` (split over
    `mesh_of(setup)`'s "gaussians"), with screen `offsets` (B, rows, 2) or None and the SH
    bands in use `sh_bands` (`render`'s): (images
    (B, H, W, 3) whole on every device, `parallel.ShardedStats`, visible (B, rows)). On a
    mesh with "views" the batch is split over its rows, each row rendering its share
    Gaussian-parallel (`parallel.render_sharded`)."""
    m = mesh_of(setup)
    out = parallel.render_sharded(parallel.GaussianShards(g, g.num), cams, m,
                                  capacity=capacity, exchange_capacity=exchange,
                                  background=background, backend=setup.backend,
                                  config=setup.recipe.raster, screen_offsets=offsets,
                                  sh_bands=sh_bands)
    images = jax.lax.with_sharding_constraint(out.image, whole(m))
    return images, out.stats, out.visible


def buffer_metrics(stats) -> dict:
    """A step's buffer report from its `ShardedStats`: overflow (some device's pairs),
    pairs (the most a device needed), exchange_overflow, exchange_required (the most records
    a device sent another)."""
    return dict(overflow=jnp.any(stats.overflow), pairs=jnp.max(stats.pairs_required),
                exchange_overflow=jnp.any(stats.exchange_overflow),
                exchange_required=jnp.max(stats.exchange_required))


ADAM_BETAS = (0.9, 0.999)  # `optim.optimizer`'s


def adam_step_ratio(t: int, betas=ADAM_BETAS) -> float:
    """c_t, the most |Adam's update| / lr can be at update t (1-based), whatever the gradients
    before it (moments started at zero, copied or reset at any step before t):
    c_t = (1 − β1)·√(1 − β2^t) / ((1 − β1^t)·√(1 − β2)) · √(Σ_(k<t) (β1²/β2)^k)
    (Cauchy–Schwarz on m_t = (1 − β1)·Σ β1^(t−i)·g_i against v_t = (1 − β2)·Σ β2^(t−i)·g_i²)."""
    b1, b2 = betas
    tail = sum((b1 * b1 / b2) ** k for k in range(t))
    return ((1 - b1) * (1 - b2 ** t) ** 0.5 / ((1 - b1 ** t) * (1 - b2) ** 0.5)) * tail ** 0.5


def drift_bound(recipe, steps: int, scene_scale: float) -> dict[str, float]:
    """Per parameter group, 2·Σ_(t=1..steps) c_t·lr (lr the group's largest rate,
    `adam_step_ratio`): two runs from the same start whose refinements decide the same and
    only copy, prune or reset parameters each move an element by at most c_t·lr at update t,
    so they differ by at most this (plus the rounding of the additions, 2·steps·u·|θ|), however
    their gradients differ (docs/multi-gpu.md)."""
    total = 2 * sum(adam_step_ratio(t) for t in range(1, steps + 1))
    rates = dict(means=recipe.lr_means * scene_scale, quats=recipe.lr_quats,
                 log_scales=recipe.lr_log_scales, logit_opacities=recipe.lr_logit_opacities,
                 sh_dc=recipe.lr_sh_dc, sh_rest=recipe.lr_sh_rest)
    return {k: total * lr for k, lr in rates.items()}
