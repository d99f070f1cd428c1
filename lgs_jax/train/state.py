"""A run's state (`RunState`: what a checkpoint restores): made fresh from the start's Gaussians,
restored from a checkpoint, saved; the pool as a plain scene."""

from __future__ import annotations

import dataclasses
import json
import os

import jax
import jax.numpy as jnp

from ..io.ply import save_ply
from ..backends import REGISTRY
from ..render import count_pairs, next_pow2, pair_capacity
from . import appearance, checkpoint, processes, report, sharded, sharded_state, view_params
from .ahead import Sizes
from .config import FitConfig, Setup, row_headroom
from ..files import written
from .feed import RunData
from ..parallel.shards import padded_rows, to_host
from .init import start_gaussians
from .optim import optimizer
from .pool import Pool, active_gaussians, from_gaussians, render_gaussians


@dataclasses.dataclass
class RunState:
    """Everything a checkpoint restores."""

    pool: Pool
    opt_state: object
    strategy_state: object
    step: int
    capacity: int  # tile-Gaussian pairs per training view
    eval_capacity: int
    skipped: int = 0
    rows: int | None = None  # the backward's rows per training view (None: one per pair slot)
    views: object = None  # the training views' own parameters and optimizers (`view_params`)
    # Gaussian parallel (`sharded`): the records a device can send another per view, and the
    # slot each row of the pool holds (None on one device)
    exchange: int | None = None
    order: object = None

    @property
    def saved(self) -> tuple:
        """What `checkpoint.save` writes, in `checkpoint.PARTS` order (a sharded run's rows in
        their stored order: `save` puts them in slot order)."""
        return self.pool, self.opt_state, self.strategy_state, self.views


def parts(st: RunState) -> dict:
    """The state's parts by name, as `report.memory_parts` reports them."""
    return dict(pool=st.pool, optimizer=st.opt_state, strategy=st.strategy_state,
                views=st.views)


def templates(setup: Setup, size: int, rd: RunData, seed: int, g=None):
    """(pool, opt_state, strategy_state, views) at `size` slots: from Gaussians g, or
    zeros; with app_opt the pool's features and the appearance head drawn from `seed`; the
    pool in setup.dtype."""
    recipe = setup.recipe
    bases = (recipe.sh_degree + 1) ** 2
    z = lambda *shape: jnp.zeros((size,) + shape, setup.dtype)
    if g is None:
        params = dict(means=z(3), quats=z(4), log_scales=z(3), logit_opacities=z(),
                      sh=z(bases, 3))
        pool = Pool(params, jnp.zeros(size, bool))
    else:
        pool = from_gaussians(jax.tree.map(jnp.asarray, g), size)
    key_features, key_head = jax.random.split(jax.random.fold_in(jax.random.key(seed), 7))
    if recipe.app_opt:
        features = z(appearance.FEATURES) if g is None else appearance.init_features(
            key_features, size)
        pool = Pool(dict(pool.params, features=features), pool.active)
    opt = optimizer(recipe, setup.steps, setup.scene_scale)
    return (pool, opt.init(pool.params), setup.strategy.init(pool, rd.scene_scale),
            view_params.init(recipe, len(rd.train_names), setup.steps, key_head))


shown = jax.jit(render_gaussians)  # the pool as `render` sees it (`pool.render_gaussians`)


def pairs(pool: Pool, cam, antialiased: bool = False) -> int:
    """Tile–Gaussian pairs of the pool's active Gaussians in one view (`lgs_jax.count_pairs`)."""
    return int(to_host(count_pairs(shown(pool.params, pool.active), cam,
                                   antialiased=antialiased)))


def active_count(pool: Pool) -> int:
    """The pool's active Gaussians (a host int, read as `parallel.to_host` reads)."""
    return int(to_host(jnp.sum(pool.active)))


def fresh(config: FitConfig, setup: Setup, rd: RunData, log) -> RunState:
    """The state at step 0: the start's Gaussians (`init.start_gaussians`) in a pool of
    config.pool_size slots (default: the most Gaussians the strategy can reach in the run,
    `Strategy.max_count`, so that the pool never grows and its step never recompiles; where it
    has no bound, the next power of two), the pair capacity (and rows) of the first training
    view."""
    cap = config.max_gaussians
    g = start_gaussians(rd, config, log)
    reach = setup.strategy.max_count(g.num, config.steps, cap)
    size = config.pool_size or (next_pow2(g.num) if reach is None else reach)
    size = max(min(size, cap), g.num)  # g.num <= cap
    size = padded_rows(size, setup.gaussian_devices)
    pool, opt_state, sstate, views = templates(setup, size, rd, config.seed, g)
    log(f"{g.num} Gaussians in a pool of {pool.size} (cap {cap}); scene scale "
        f"{rd.scene_scale:.3f}")
    if setup.gaussian_devices > 1:
        return _sharded(config, setup, rd, (pool, opt_state, sstate, views), step=0,
                        eval_capacity=None)
    capacity = pair_capacity(pairs(pool, rd.train_camera(0), setup.recipe.antialiased),
                             config.pair_headroom)
    return RunState(pool, opt_state, sstate, 0, capacity, capacity,
                    rows=start_rows(config, setup, capacity), views=views)


def start_rows(config: FitConfig, setup: Setup, capacity: int) -> int | None:
    """The backward's rows a fresh run starts with: those of its pair capacity
    (`ahead.Sizes.rows_for` at the run's headroom, `config.row_headroom`: the first view's
    pairs times it; the walked pairs are among them, so the first step's rows do not
    overflow), or None (a row per pair slot) where the headroom is None or the backend stores
    no rows."""
    if not REGISTRY[setup.backend].row_capacity:
        return None
    return sizes(config).rows_for(capacity)


def sizes(config: FitConfig) -> Sizes:
    """How a run's step buffers are sized and grow (`ahead.Sizes`): at its pair headroom and
    its row headroom (the field, or where None the default that `.config.row_headroom`
    gives)."""
    return Sizes(config.pair_headroom, row_headroom(config))


def balance_cameras(rd: RunData) -> list:
    """The training cameras a Gaussian-parallel run balances its blocks over
    (`sharded_state.balance_views`)."""
    return [rd.train_camera(i) for i in sharded_state.balance_views(len(rd.train_names))]


def _sharded(config: FitConfig, setup: Setup, rd: RunData, parts: tuple, step: int,
             eval_capacity: int | None, skipped: int = 0) -> RunState:
    """The state of a run split over setup.gaussian_devices devices (`sharded_state`, on the
    run's mesh `sharded.mesh_of(setup)`) from `parts` (pool, opt_state, strategy_state, views)
    in slot order: the pool padded to equal blocks, balanced (`sharded_state.work` over
    `balance_cameras`) and placed; both buffers sized from the first training view."""
    m = sharded.mesh_of(setup)
    padded = sharded_state.padded(parts[:3], setup.gaussian_devices)
    weights = sharded_state.work(padded[0], balance_cameras(rd), setup.recipe.antialiased)
    (pool, opt_state, sstate), order = sharded_state.balanced(m, padded, weights)
    views = sharded_state.place(m, (pool, opt_state, sstate), parts[3])[1]
    capacity, exchange = sharded_state.first_sizes(m, pool, rd.train_camera(0),
                                                   setup.recipe.antialiased,
                                                   config.pair_headroom)
    return RunState(pool, opt_state, sstate, step, capacity,
                    capacity if eval_capacity is None else eval_capacity, skipped, views=views,
                    exchange=exchange, order=order)


def resumed(config: FitConfig, setup: Setup, rd: RunData, log) -> RunState:
    """The state of the checkpoint in config.out (checked by `rundir.resume_problem` first),
    read by every process; metrics.jsonl's rows after its step dropped (a run that stopped
    after its last checkpoint redoes them, and the resumed log reads as one run) by the one
    that writes the run folder (`processes.writer`)."""
    out = config.out

    def read():  # on every process (`processes.together`): OUT on a file system all of them see
        meta = checkpoint.read_meta(out)
        return meta, checkpoint.restore(out, templates(setup, meta["pool_size"], rd, config.seed),
                                        meta["step"])
    meta, (pool, opt_state, sstate, views) = processes.together(read)
    if processes.writer():
        _forget_after(os.path.join(out, "metrics.jsonl"), meta["step"])
    processes.synced("resumed")  # the others read metrics.jsonl next (`loop._early_stop`)
    log(f"resumed at step {meta['step']} ({active_count(pool)} Gaussians)")
    if setup.gaussian_devices > 1:
        return _sharded(config, setup, rd, (pool, opt_state, sstate, views), meta["step"],
                        meta["eval_capacity"], meta["skipped"])
    rows = meta.get("rows") if row_headroom(config) is not None else None
    return RunState(pool, opt_state, sstate, meta["step"], meta["capacity"],
                    meta["eval_capacity"], meta["skipped"], rows, views)


def _forget_after(path: str, step: int) -> None:
    if not os.path.exists(path):
        return
    rows = [r for r in report.read_metrics(path)
            if r.get("step", 0) <= step and r.get("refine_step", -1) < step
            and r.get("grown_step", 0) <= step]
    with written(path) as tmp, open(tmp, "w") as f:
        f.writelines(json.dumps(r) + "\n" for r in rows)


def save(out: str, config: FitConfig, st: RunState, data: dict) -> None:
    """The checkpoint of `st` (`data`: `checkpoint.data_of` the run's data) and scene.ply,
    read on every process (`parallel.to_host`), written by the one that writes the run folder
    (`processes.writer`)."""
    meta = dict(step=st.step, capacity=st.capacity, rows=st.rows, eval_capacity=st.eval_capacity,
                pool_size=st.pool.size, skipped=st.skipped, config=checkpoint.config_of(config),
                data=data)
    parts = st.saved
    if st.order is not None:
        parts = (*sharded_state.in_slot_order(sharded.mesh_of(config), parts[:3], st.order),
                 parts[3])
    parts, g = to_host(parts), active_gaussians(scene(st))
    if not processes.writer():
        return
    checkpoint.save(out, parts, meta)
    with written(os.path.join(out, "scene.ply")) as tmp:
        save_ply(tmp, g)


_baked = jax.jit(appearance.baked)


def scene(st: RunState) -> Pool:
    """The pool as a plain scene: with appearance embeddings, at the training views' average
    appearance (`appearance.baked`); else the pool itself."""
    if st.views is None or "head" not in st.views:
        return st.pool
    return Pool(_baked(st.pool.params, st.views["head"][0], st.views["embed"][0]),
                st.pool.active)
