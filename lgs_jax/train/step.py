"""The jitted pieces of a run: one training step, one refinement (with pool growth), renders.

`train_step` (one jit per Setup, pair capacity, backward rows and pool size): render the batch of
views from the pool (inactive slots culled, SH bands beyond the schedule zeroed), loss = mean over
views of (1 − λ)·L1 + λ·(1 − SSIM) plus the strategy's and the views' own regularisers; gradients
w.r.t. the parameters (and, for strategies that ask, w.r.t. zero screen offsets of the projected
means: ∂loss/∂mean2d); one Adam update (and one of the views' own parameters, `view_params`: pose
deltas with `Recipe.pose_opt`, colour corrections with `Recipe.color_opt`, bilateral grids with
`Recipe.bilateral_grid`, appearance embeddings and their head with `Recipe.app_opt`, each view's
Gaussians then seen with their band 0 moved, `appearance.seen`); then the strategy's per-step
update. A step whose loss or gradients (active slots) are not finite changes nothing: it
returns its inputs with ok False (`fit` reports it). Finite gradients keep finite parameters
finite: Adam's step is at most `sharded.adam_step_ratio` times the rate. A view whose tile pairs
overflow the capacity, or whose walked pairs overflow the backward's rows (`render`'s
row_capacity), is reported (overflow, pairs, row_overflow, walked) and changes nothing either:
`fit` grows what overflowed and runs the same step again on the state it returned, so no pair is
ever dropped.

The state (pool, optimizer, strategy, views) is donated: the step updates it in place, so a
run holds one copy of it, not two. Whether the step applies is decided before the update from
the loss and the gradients, so the guard `where(apply, new, old)` fuses into the update
elementwise; a guard on the new parameters would need the whole new state beside the old.

Every piece is compiled with XLA's autotuning off (`COMPILER_OPTIONS`). On a GPU, XLA picks
among kernel configurations, reductions' included, by timing them while it compiles
(even a `jnp.sum`, whose bits then depend on the pick), so the same program compiled
twice, e.g. once ahead in a thread beside running steps (`ahead.py`) and once when the GPU is
idle, could round differently. Without autotuning a compile picks by fixed rules.
"""

from __future__ import annotations

import dataclasses
import functools
import types

import jax
import jax.numpy as jnp
import numpy as np
import optax

from ..config import RasterConfig
from ..parallel import to_host
from ..render import next_pow2, render, render_growing
from . import appearance, camera_opt, exports, sharded, view_params
from .losses import loss_fn, psnr
from .optim import means_schedule, optimizer
from .pool import Pool, grow, render_gaussians, sh_mask
from .config import Setup
from .feed import to_float
from .strategy import StepInfo

# module docstring; no effect on a CPU; read-only (jit keeps a reference)
COMPILER_OPTIONS = types.MappingProxyType({"xla_gpu_autotune_level": 0})


def lowering() -> exports.Lowering | None:
    """How `train_step`'s programs are lowered on one device: through export entries in the
    persistent cache's directory (`exports`), with the step's donated state (its first four
    arguments) and compiler options; None (`train_step` called) where no cache is set."""
    if exports.directory() is None:
        return None
    return exports.Lowering(exports.directory(), donate=(0, 1, 2, 3),
                            compiler_options=dict(COMPILER_OPTIONS))


def _finite(tree, active) -> jax.Array:
    """All per-Gaussian leaves finite on the active rows (an inactive row reaches no pixel,
    and keeps the finite values it had when active, or zeros)."""
    ok = jnp.bool_(True)
    for x in jax.tree.leaves(tree):
        fin = jnp.isfinite(x)
        if x.ndim >= 1 and x.shape[0] == active.shape[0]:
            fin = fin | jnp.reshape(~active, active.shape + (1,) * (x.ndim - 1))
        ok = ok & jnp.all(fin)
    return ok


def _select(flag, new, old):
    return jax.tree.map(lambda a, b: jnp.where(flag, a, b), new, old)


def distinct(tree):
    """`tree` with every leaf that is an earlier leaf's array object copied: a call cannot
    donate one buffer twice (a state built outside a step may hold one array in two places)."""
    seen = set()

    def one(x):
        if id(x) in seen:
            return jnp.copy(x)
        seen.add(id(x))
        return x
    return jax.tree.map(one, tree)


@functools.cache
def mesh(devices: int):
    """The 1-D mesh "views" over the first `devices` devices (`Setup.devices`)."""
    return jax.make_mesh((devices,), ("views",), devices=jax.devices()[:devices],
                         axis_types=(jax.sharding.AxisType.Auto,))  # XLA moves the inputs


def replicated(setup: Setup):
    """Where a run of `setup` keeps what every device holds whole (None on one device): on
    every device of `mesh(setup.devices)` (data parallel: the whole state; the steps' outputs
    are constrained to it and `fit` places its state there, so that every step sees the
    shardings it was compiled for, no second compile), or of `sharded.mesh_of(setup)`
    (Gaussian parallel: what is not split in blocks)."""
    if setup.gaussian_devices > 1:
        return sharded.whole(sharded.mesh_of(setup))
    if setup.devices == 1:
        return None
    return jax.sharding.NamedSharding(mesh(setup.devices), jax.sharding.PartitionSpec())


def over_batch(fn):
    """`fn(*per_view)` over a batch (the leading axis of every argument), one view after
    another as `over_views` does on one device (a single view: `fn` itself)."""
    def batched(*per_view):
        if jax.tree.leaves(per_view)[0].shape[0] == 1:
            out = fn(*jax.tree.map(lambda x: x[0], per_view))
            return jax.tree.map(lambda x: jnp.asarray(x)[None], out)
        return jax.lax.map(lambda views: fn(*views), per_view)
    return batched


def over_views(one, devices: int, vectorize: bool = False):
    """`one(g, cam, target, offsets, look)` over a batch of views (the leading axis of all but
    g, which they share), stacked outputs: one view after another (`lax.map`; a single view is
    `one` itself) or with `vectorize` through `jax.vmap` (for the Pallas backends, whose
    kernels take the views as one more grid axis). Under vmap the XLA backends' loops and
    conditions on per-view values become selects that run every branch to the pair capacity,
    which costs far more than the views one by one. With `devices` > 1 the batch is split
    across the first `devices` devices (a `shard_map` over a mesh axis "views", each device
    rendering its share of the views with the whole scene; the gradient of the shared scene
    sums the devices' parts, an all-reduce)."""
    def batched(g, *per_view):
        if vectorize:
            return jax.vmap(one, in_axes=(None, 0, 0, 0, 0))(g, *per_view)
        return over_batch(functools.partial(one, g))(*per_view)

    if devices == 1:
        return batched
    whole, views = jax.sharding.PartitionSpec(), jax.sharding.PartitionSpec("views")
    # check_vma off: the renderer's loops start from replicated carries that become per-device
    # values, which the check would have us cast by hand; nothing in `one` communicates
    return jax.shard_map(batched, mesh=mesh(devices), in_specs=(whole,) + (views,) * 4,
                         out_specs=views, check_vma=False)


def score(recipe, image, target, look: dict):
    """(loss, mse) of one view's render `image` (H, W, 3) against `target`, the render first
    corrected by the view's rows `look` of its appearance parts (`view_params.corrected`)."""
    image = view_params.corrected(image, look)
    return (loss_fn(image, target, recipe.ssim_lambda, recipe.ssim_padding),
            jnp.mean((image - target) ** 2))


def loss_and_grads(setup: Setup, capacity: int, rows: int | None, pool: Pool, cams, targets,
                   background, step, idx, per_view=None, exchange: int | None = None):
    """The loss of `train_step` (module docstring) on views `cams` (stacked, at the images'
    size) against `targets` (B, H, W, 3) and its gradients: ((loss, (mse, stats, visible)),
    (param grads, screen grads or None, grads of the views' own parameters or None));
    `per_view`: the views' own parameters {name: (views, SIZE)}
    (`view_params`), whose rows of the views `idx` move their poses (`camera_opt.adjusted`)
    and correct their renders (`view_params.corrected`: colour maps, bilateral grids), or
    None; their regularizer (the grids' total variation) adds to the loss. With
    `setup.gaussian_devices` > 1 the pool's rows are split over that many devices and the views
    are rendered by `sharded.render_views` with `exchange` records per device pair (with
    `setup.devices` > 1 too, the views split over the rows of a mesh of `setup.devices` x
    `setup.gaussian_devices`), the loss taken on the whole images."""
    s = setup
    bands = sh_mask(step, pool.params["sh"].shape[1], s.recipe.sh_every)
    need2d = s.strategy.needs_screen_grads

    def loss_of(params, offsets, per_view):
        g = render_gaussians(params, pool.active)
        own = view_params.rows(per_view, idx) or {}
        views = cams if "pose" not in own else camera_opt.adjusted(cams, own["pose"])
        look = {k: v for k, v in own.items() if k in view_params.APPEARANCE}
        if "embed" in own:  # each view's change of band 0 (`appearance.seen`), 0 where inactive
            dc = jax.vmap(appearance.dc_change, in_axes=(None, 0, None))(
                own["head"], own["embed"], params["features"])
            look["dc"] = jnp.where(pool.active[None, :, None, None], dc, 0.0)

        def one(g, cam, target, off, look):
            if "dc" in look:
                g = appearance.with_dc_change(g, look["dc"])
            o = render(g, cam, background=background, backend=s.backend, capacity=capacity,
                       config=s.recipe.raster, screen_offsets=off,
                       row_capacity=rows, sh_bands=bands)
            return (*score(s.recipe, o.image, target, look), o.stats, o.visible)

        if s.gaussian_devices > 1:
            images, stats, visible = sharded.render_views(s, capacity, exchange, g, views,
                                                          background, offsets, bands)
            losses, mse = over_batch(functools.partial(score, s.recipe))(images, targets, look)
        else:
            losses, mse, stats, visible = over_views(one, s.devices, s.backend.startswith(
                "pallas"))(g, views, targets, offsets, look)
        total = (jnp.mean(losses) + s.strategy.regularizer(params, pool.active)
                 + view_params.regularizer(s.recipe, per_view))
        return total, (jnp.mean(mse), stats, visible)

    offsets = (jnp.zeros((targets.shape[0], pool.size, 2), pool.params["means"].dtype)
               if need2d else None)
    return jax.value_and_grad(loss_of, argnums=(0, 1, 2), has_aux=True)(pool.params, offsets,
                                                                         per_view)


def step_keys(key, step):
    """(key of the training step, key of the refinement) at `step`: from the run's key and the
    step alone, so a resumed run draws what an uninterrupted one would."""
    return jax.random.split(jax.random.fold_in(key, step))


def row_stats(stats):
    """(row_overflow, pairs_walked) of a render's stats: the backward's rows of the Pallas
    backends (`PallasStats`), (False, 0) for backends that store no pair rows."""
    own = stats.backend_stats
    if not hasattr(own, "pairs_walked"):
        return jnp.zeros(stats.overflow.shape, bool), jnp.zeros(stats.overflow.shape, jnp.int32)
    return own.row_overflow, own.pairs_walked


@functools.partial(jax.jit, static_argnames=("setup", "capacity", "rows", "exchange"),
                   donate_argnames=("pool", "opt_state", "strategy_state", "views"),
                   compiler_options=COMPILER_OPTIONS)
def train_step(pool: Pool, opt_state, strategy_state, views, all_cams, targets, idx,
               background, step, key, slots=None, go=True, *, setup: Setup, capacity: int,
               rows: int | None = None, exchange: int | None = None):
    """One step at 0-based index `step` on the training views `idx` (B,) of `all_cams`
    (stacked, `data.stack_any`), whose images are `targets` (B, H, W, 3), 8-bit or float,
    converted here to the training arithmetic's dtype (`feed.to_float`; `feed.TrainViews`:
    the same program whether the capture's images live on the device or are streamed), which
    set the size the views are rendered at (a capture of several sizes: a compile per size);
    `views`: the training views' own parameters and their optimizer states (`view_params`:
    pose deltas, colour corrections), or None; `key` is the run's; `rows`: the backward's row
    buffer (`render`'s row_capacity). Returns (pool, opt_state, strategy_state, views,
    metrics): loss, psnr (training views), ok (finite), overflow, pairs (largest
    per-view pair count), row_overflow, walked (largest per-view count of walked pairs), fits
    (no buffer overflowed), count (active Gaussians), and all of them in `packed`, the one
    array `fit` reads back (`read_metrics`). With `setup.gaussian_devices` > 1
    (`sharded`): the state's rows split over that many devices, `slots` the slot each row
    holds, `exchange` the records each device can send another; pairs are per device, and
    row_overflow and walked give way to exchange_overflow and exchange_required
    (`sharded.buffer_metrics`). The step applies
    where ok, nothing overflowed and `go` (a bool scalar: `fit` passes the previous step's
    fits, so that a step dispatched before the previous one's metrics were read changes
    nothing where that one must be redone); else it returns its state unchanged. The state
    arguments are donated: use the returned state, never the arguments, after a call."""
    targets = to_float(targets, setup.precision)
    cams = dataclasses.replace(jax.tree.map(lambda x: x[idx], all_cams),
                               width=targets.shape[2], height=targets.shape[1])
    (loss, (mse, stats, visible)), (grads, grads2d, grads_views) = loss_and_grads(
        setup, capacity, rows, pool, cams, targets, background, step, idx,
        view_params.params(views), exchange)
    opt = optimizer(setup.recipe, setup.steps, setup.scene_scale)
    updates, new_opt = opt.update(grads, opt_state, pool.params)
    new_pool = Pool(optax.apply_updates(pool.params, updates), pool.active)
    lr = means_schedule(setup.recipe, setup.steps, setup.scene_scale)(step + 1)
    info = StepInfo(grads2d, visible, lr, cams.width, cams.height, slots)
    new_state, new_pool, new_opt = setup.strategy.step(strategy_state, new_pool, new_opt, info,
                                                       step, step_keys(key, step)[0])
    ok = jnp.isfinite(loss) & _finite(grads, pool.active)
    if grads2d is not None:
        ok = ok & _finite(jnp.swapaxes(grads2d, 0, 1), pool.active)
    new_views = views
    if views is not None:
        new_views = view_params.update(setup.recipe, setup.steps, views, grads_views)
        ok = ok & jnp.all(jnp.stack([jnp.all(jnp.isfinite(x)) for x in
                                     jax.tree.leaves(grads_views)]))
    if setup.gaussian_devices > 1:
        buffers = sharded.buffer_metrics(stats)
        fits = ~(buffers["overflow"] | buffers["exchange_overflow"])
    else:
        row_overflow, walked = row_stats(stats)
        buffers = dict(overflow=jnp.any(stats.overflow), pairs=jnp.max(stats.pairs_required),
                       row_overflow=jnp.any(row_overflow), walked=jnp.max(walked))
        fits = ~(buffers["overflow"] | buffers["row_overflow"])
    pool, opt_state, strategy_state, views = _select(
        ok & fits & go, (new_pool, new_opt, new_state, new_views),
        (pool, opt_state, strategy_state, views))
    if setup.gaussian_devices > 1:
        (pool, opt_state, strategy_state), views = sharded.constrained(
            sharded.mesh_of(setup), (pool, opt_state, strategy_state), pool.size, views)
    elif setup.devices > 1:
        pool, opt_state, strategy_state, views = jax.lax.with_sharding_constraint(
            (pool, opt_state, strategy_state, views), replicated(setup))
    metrics = dict(loss=loss, psnr=psnr(mse), ok=ok, **buffers, fits=fits,
                   count=jnp.sum(pool.active, dtype=jnp.int32))
    return pool, opt_state, strategy_state, views, dict(metrics, packed=packed(metrics))


def packed(metrics: dict) -> jax.Array:
    """The values of `metrics` (arrays) in one int32 vector, by sorted key, bit for bit: a
    bool as 0 or 1, a 4-byte value as one word, an 8-byte value (float64, int64) as two. The
    one array `fit` copies to the host after a step (`read_metrics`), instead of one copy per
    value."""
    words = []
    for name in sorted(metrics):
        x = jnp.asarray(metrics[name])
        if x.dtype == jnp.bool_:
            words.append(x.astype(jnp.int32).reshape(-1))
        else:
            words.append(jax.lax.bitcast_convert_type(x, jnp.int32).reshape(-1))
    return jnp.concatenate(words)


def read_metrics(metrics: dict) -> dict:
    """A step's metrics (`train_step`'s, on the device) on the host as Python scalars, read
    through their `packed` vector: one copy from the device; the layout from the arrays'
    dtypes and shapes, which the host knows without reading them. An array of several values
    comes back as a numpy array."""
    words = np.asarray(to_host(metrics["packed"]))
    out, at = {}, 0
    for name in sorted(k for k in metrics if k != "packed"):
        x = metrics[name]
        dtype, size = np.dtype(x.dtype), int(np.prod(x.shape))
        n = size * (1 if dtype == np.bool_ else dtype.itemsize // 4)
        chunk = words[at:at + n]
        at += n
        values = chunk != 0 if dtype == np.bool_ else chunk.view(dtype)
        out[name] = values.reshape(x.shape).item() if size == 1 else values.reshape(x.shape)
    return out


def _refined(strategy_state, pool: Pool, opt_state, step, key, *, strategy, cap: int):
    return strategy.refine(strategy_state, pool, opt_state, step, step_keys(key, step)[1], cap)


_refine = jax.jit(_refined, static_argnames=("strategy", "cap"),
                  compiler_options=COMPILER_OPTIONS)
# the same with the state donated: its outputs take the arguments' buffers, so a refinement
# holds the state once (and the new values a strategy computes beside it: none for the
# built-in strategies, which write their rows in place: `ops.relocate_and_add`,
# `ops.clone_and_split`), not twice
_refine_in_place = jax.jit(_refined, static_argnames=("strategy", "cap"),
                           donate_argnames=("strategy_state", "pool", "opt_state"),
                           compiler_options=COMPILER_OPTIONS)


@functools.partial(jax.jit, static_argnames=("strategy", "cap"),
                   compiler_options=COMPILER_OPTIONS)
def _shortfall(strategy_state, pool: Pool, opt_state, step, key, *, strategy, cap: int):
    """The new slots a refinement wants beyond the free ones (its report's needed − free):
    XLA computes the counts alone, not the refined parameters."""
    report = strategy.refine(strategy_state, pool, opt_state, step, step_keys(key, step)[1],
                             cap)[3]
    return report["needed"] - report["free"]


def refine(strategy, strategy_state, pool: Pool, opt_state, step: int, key, cap: int,
           multiple: int = 1, in_place: bool = False):
    """`strategy.refine` at `step` (`key`: the run's; `cap`: at most so many Gaussians), the
    pool first grown (doubled, at most to `cap` slots rounded up to a multiple of `multiple`,
    and to such a multiple) while the refinement needs more new slots than are free, so nothing
    is cut short below the cap. A refinement that would make an active parameter non-finite is
    not applied (the strategy's report: ok False). Returns (state, pool, opt_state, report):
    the report's counts as ints, plus `grown_to` (the new pool size, or 0). `in_place`: the
    state's arrays are donated (used up: read only the returned state afterwards), so that the
    refinement holds the state once, not twice (`fit` does this; its memory peaked here
    otherwise); below the largest pool, the shortfall of slots is counted first
    (`_shortfall`), and the pool grown before the one refinement that uses the state up."""
    grown_to, slots = 0, -(-cap // multiple) * multiple
    while True:
        counted = in_place and pool.size < slots  # a growth may follow: the state kept
        if counted:
            short = int(to_host(_shortfall(strategy_state, pool, opt_state, step, key,
                                           strategy=strategy, cap=cap)))
        if not counted or short <= 0:
            fn = _refine_in_place if in_place else _refine
            state, new_pool, new_opt, report = fn(strategy_state, pool, opt_state, step, key,
                                                  strategy=strategy, cap=cap)
            report = {k: int(v) for k, v in to_host(report).items()}
            short = report["needed"] - report["free"]
            if in_place or short <= 0 or pool.size >= slots:
                return state, new_pool, new_opt, dict(report, grown_to=grown_to)
        grown_to = min(slots, max(2 * pool.size, next_pow2(pool.size + short)))
        grown_to = -(-grown_to // multiple) * multiple
        pool, opt_state, strategy_state = grow(pool, opt_state, strategy_state, grown_to)


@functools.partial(jax.jit, static_argnames=("backend", "capacity", "config"),
                   compiler_options=COMPILER_OPTIONS)
def _render_pool(pool: Pool, cam, background, *, backend: str, capacity: int,
                 config: RasterConfig):
    return render(render_gaussians(pool.params, pool.active), cam, background=background,
                  backend=backend, capacity=capacity, config=config)


def render_views(pool: Pool, cams, background, backend: str, capacity: int,
                 config: RasterConfig = RasterConfig()):
    """([image (H, W, 3) numpy, clipped to [0, 1]] per camera, capacity): every active
    Gaussian with all its SH bands (gsplat evaluates at full degree) under `config`, capacity
    grown as needed."""
    images = []
    fn = functools.partial(_render_pool, backend=backend, config=config)
    for cam in cams:
        out, capacity = render_growing(fn, pool, cam, background, capacity=capacity)
        images.append(np.clip(np.asarray(out.image), 0.0, 1.0))
    return images, capacity
