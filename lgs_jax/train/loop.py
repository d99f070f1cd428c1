"""`fit`: train Gaussians on a capture, with a densification strategy, into a run directory.

Per step s (0-based): the views of `data.views_for_step`, one `step.train_step` (redone with a
larger pair capacity whenever a view overflows: no pair is dropped; the capacity starts at and
grows to `pair_capacity(pairs, settings.pair_headroom)`, see `Settings`; likewise the backward's
rows where `settings.row_headroom` sizes them, `ahead.Sizes`), then `step.refine` where
the strategy asks (the pool doubles when it needs room, up to `max_gaussians`: a recompile; both
are logged).
A step whose loss, gradients or parameters would not be finite is skipped (nothing changes),
logged and recorded. Outputs in OUT: metrics.jsonl (per step: loss, training-view PSNR, active
Gaussians, seconds; per refinement: its counts; per evaluation: held-out PSNR/SSIM), checkpoints
(`checkpoint.py`; bit-identical resume), and at the end scene.ply (the active Gaussians, INRIA
PLY), cameras.json (INRIA: the training cameras, at their optimized poses with pose_opt, then
the held-out ones), colors.json (with color_opt: each training view's colour correction),
bilateral_grids.npz (with bilateral_grid: each training view's grid),
appearance.npz (with app_opt: the features, embeddings and head, `appearance.save`; scene.ply
and the held-out renders are the scene at the views' average appearance, `appearance.baked`),
heldout_<name>.png (render beside ground truth), curves.png, result.json.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import os
import time

import jax
import jax.numpy as jnp
import numpy as np

from .. import binning
from ..config import CONVENTIONS
from ..io.cameras import save_cameras
from ..io.ply import save_ply
from ..projection import project
from ..render import default_backend, next_pow2, pair_capacity, render
from . import (appearance, bilateral_grid, camera_opt, checkpoint, color_opt, report,
               view_params)
from .ahead import Sizes, Stepper, mode_of, signature
from .feed import RunData, TrainViews, nbytes, prepare, streams
from .init import start_gaussians
from .losses import PADDINGS
from .optim import optimizer
from .pool import Pool, active_gaussians, from_gaussians, render_gaussians
from .settings import Settings, Setup
from .step import refine, render_views, replicated, row_stats, train_step
from .strategy import DefaultStrategy, Strategy

@dataclasses.dataclass
class _State:
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

    @property
    def saved(self) -> tuple:
        """What `checkpoint.save` writes, in `checkpoint.PARTS` order."""
        return self.pool, self.opt_state, self.strategy_state, self.views


def _templates(setup: Setup, size: int, rd: RunData, seed: int, g=None):
    """(pool, opt_state, strategy_state, views) at `size` slots: from Gaussians g, or
    zeros; with app_opt the pool's features and the appearance head drawn from `seed`."""
    bases = (setup.settings.sh_degree + 1) ** 2
    z = lambda *shape: jnp.zeros((size,) + shape, jnp.float32)
    if g is None:
        params = dict(means=z(3), quats=z(4), log_scales=z(3), logit_opacities=z(),
                      sh_dc=z(1, 3), sh_rest=z(bases - 1, 3))
        pool = Pool(params, jnp.zeros(size, bool))
    else:
        pool = from_gaussians(jax.tree.map(jnp.asarray, g), size)
    key_features, key_head = jax.random.split(jax.random.fold_in(jax.random.key(seed), 7))
    if setup.settings.app_opt:
        features = z(appearance.FEATURES) if g is None else appearance.init_features(
            key_features, size)
        pool = Pool(dict(pool.params, features=features), pool.active)
    opt = optimizer(setup.settings, setup.steps, setup.scene_scale)
    return (pool, opt.init(pool.params), setup.strategy.init(pool, rd.scene_scale),
            view_params.init(setup.settings, len(rd.train_names), setup.steps, key_head))


def _fresh(setup: Setup, rd: RunData, seed: int, cap: int, pool_size, log) -> _State:
    g = start_gaussians(rd, setup.settings, setup.strategy, seed, cap, log)
    size = max(min(pool_size or next_pow2(g.num), cap), g.num)  # g.num <= cap
    pool, opt_state, sstate, views = _templates(setup, size, rd, seed, g)
    first = rd.train_camera(0)
    capacity = pair_capacity(int(_pairs(pool, first, setup.settings.antialiased)),
                             setup.settings.pair_headroom)
    rows = None
    if setup.settings.row_headroom is not None:
        rows = pair_capacity(_walked(setup, pool, first, jnp.asarray(rd.background), capacity),
                             setup.settings.row_headroom)
    log(f"{g.num} Gaussians in a pool of {pool.size} (cap {cap}); scene scale "
        f"{rd.scene_scale:.3f}")
    return _State(pool, opt_state, sstate, 0, capacity, capacity, rows=rows, views=views)


@functools.partial(jax.jit, static_argnames="antialiased")
def _pairs(pool: Pool, cam, antialiased: bool = False):
    """Tile-Gaussian pairs of the pool in one view."""
    return binning.count_pairs(project(render_gaussians(pool.params, pool.active), cam,
                                       antialiased), cam.width, cam.height)


def _walked(setup: Setup, pool: Pool, cam, background, capacity: int) -> int:
    """Pairs some pixel reached in one view (`RenderStats.pairs_walked`): a forward render."""
    out = render(render_gaussians(pool.params, pool.active), cam, background=background,
                 backend=setup.backend, capacity=capacity,
                 config=setup.settings.raster)
    return int(row_stats(out.stats)[1])


def _resumed(out: str, setup: Setup, rd: RunData, seed: int, log) -> _State:
    meta = checkpoint.read_meta(out)
    defaults = dataclasses.replace(setup, settings=Settings(), strategy=type(setup.strategy)())
    problem = checkpoint.config_mismatch(meta["config"], checkpoint.config_of(setup, seed),
                                         checkpoint.config_of(defaults, seed))
    if problem:
        raise ValueError(f"resume: {problem}")
    templates = _templates(setup, meta["pool_size"], rd, seed)
    pool, opt_state, sstate, views = checkpoint.restore(out, templates)
    _forget_after(os.path.join(out, "metrics.jsonl"), meta["step"])
    log(f"resumed at step {meta['step']} ({int(jnp.sum(pool.active))} Gaussians)")
    rows = meta.get("rows") if setup.settings.row_headroom is not None else None
    return _State(pool, opt_state, sstate, meta["step"], meta["capacity"],
                  meta["eval_capacity"], meta["skipped"], rows, views)


def _forget_after(path: str, step: int) -> None:
    """Drop the metrics rows of steps after `step` (a run that stopped after its last
    checkpoint redoes them), so the resumed log reads as one run."""
    if not os.path.exists(path):
        return
    rows = [r for r in report.read_metrics(path)
            if r.get("step", 0) <= step and r.get("refine_step", -1) < step]
    with open(path, "w") as f:
        f.writelines(json.dumps(r) + "\n" for r in rows)


def _save(out: str, setup: Setup, st: _State, seed: int) -> None:
    meta = dict(step=st.step, capacity=st.capacity, rows=st.rows, eval_capacity=st.eval_capacity,
                pool_size=st.pool.size, skipped=st.skipped,
                config=checkpoint.config_of(setup, seed))
    checkpoint.save(out, st.saved, meta)
    save_ply(os.path.join(out, "scene.ply"), active_gaussians(_scene(st)))


_baked = jax.jit(appearance.baked)


def _scene(st: _State) -> Pool:
    """The pool as a plain scene: with appearance embeddings, at the training views' average
    appearance (`appearance.baked`); else the pool itself."""
    if st.views is None or "head" not in st.views:
        return st.pool
    return Pool(_baked(st.pool.params, st.views["head"][0], st.views["embed"][0]),
                st.pool.active)


def _evaluate(st: _State, rd: RunData, setup: Setup, out: str | None = None):
    """Held-out (PSNR, SSIM), (None, None) without held-out views; renders beside the ground
    truth written to `out` when given."""
    if not rd.test_cams:
        return None, None
    images, st.eval_capacity = render_views(_scene(st), rd.test_cams, jnp.asarray(rd.background),
                                            setup.backend, st.eval_capacity,
                                            setup.settings.raster)
    if out:
        report.save_renders(out, images, rd.test_images, rd.test_names)
    return report.heldout_metrics(images, rd.test_images)


def _lower_step(args, size: tuple, *, setup: Setup):
    """`train_step` lowered for `args` at `size` = (capacity, rows) (module level, so that
    `ahead`'s child process can unpickle it)."""
    return train_step.lower(*args, setup=setup, capacity=size[0], rows=size[1])


def _stepper(setup: Setup, mode: str | None) -> Stepper:
    """`train_step` of this run behind an `ahead.Stepper` of `mode`."""
    s = setup.settings
    return Stepper(lambda a, size: train_step(*a, setup=setup, capacity=size[0], rows=size[1]),
                   functools.partial(_lower_step, setup=setup),
                   Sizes(s.pair_headroom, s.row_headroom), mode)


def _one_step(setup: Setup, st: _State, rd: RunData, feed: TrainViews, key, background, say,
              stepper: Stepper, clock):
    """Run step st.step (capacity grown until nothing overflows); returns its metrics."""
    images, idx = feed.args(st.step)
    while True:
        args = (st.pool, st.opt_state, st.strategy_state, st.views, rd.train_cams, images, idx,
                background, st.step, key)
        sig = signature(args)
        size = (st.capacity, st.rows)
        new = stepper.run(args, size, sig)
        feed.prefetch(st.step + 1)  # while the step runs
        stepper.prepare(args, size, sig)
        m = {k: v.item() for k, v in jax.device_get(new[4]).items()}
        if not (m["overflow"] or m["row_overflow"]):
            st.pool, st.opt_state, st.strategy_state, st.views = new[:4]
            return m
        need = (m["pairs"], m["walked"])
        (st.capacity, st.rows), waited, ahead = stepper.grow(size, need, sig)
        if (st.capacity, st.rows) == size:  # never loop on a size that cannot hold the step
            raise RuntimeError(f"step {st.step + 1}: (pairs, rows) {size} overflowed, "
                               f"{need} needed")
        clock.waited(waited)
        grown = [f"{what} grown to {new_size}" for what, new_size, old_size in
                 (("pair capacity", st.capacity, size[0]), ("backward rows", st.rows, size[1]))
                 if new_size != old_size]
        say(f"step {st.step + 1}: {' and '.join(grown)} "
            + (f"(compiled ahead; waited {waited:.1f} s)" if ahead else "(one recompile)")
            + (f"; the compile ahead failed: {stepper.failure}" if stepper.failure else ""))


def _place(setup: Setup, st: _State) -> None:
    """A data-parallel run's state whole on each of its devices (`step.replicated`; a no-op
    where it is already, and for one device)."""
    where = replicated(setup.devices)
    if where is not None:
        st.pool, st.opt_state, st.strategy_state, st.views = jax.device_put(st.saved, where)


def _refine(setup: Setup, st: _State, key, cap: int, say, record) -> int:
    """The strategy's refinement at step st.step, recorded, the pool's growth logged; returns
    the number of active Gaussians after it."""
    st.strategy_state, st.pool, st.opt_state, rep = refine(
        setup.strategy, st.strategy_state, st.pool, st.opt_state, st.step, key, cap)
    _place(setup, st)
    if rep["grown_to"]:
        say(f"step {st.step}: pool grown to {rep['grown_to']} slots (one recompile)")
    if not rep["ok"]:
        say(f"step {st.step}: refinement skipped: it would make parameters non-finite")
    count = int(jnp.sum(st.pool.active))
    record(refine_step=st.step, **rep, gaussians=count)
    return count


_shown = jax.jit(render_gaussians)


class _Watch:
    """Calls `fn(step, gaussians, metrics)` with the pool as `render` sees it (inactive slots
    as culled placeholders, every SH band; on one device) when `every` seconds have passed
    since the last call, or when forced."""

    def __init__(self, fn, every: float, devices: int):
        self.fn, self.every, self.devices, self.last = fn, every, devices, -float("inf")

    def __call__(self, st: _State, metrics: dict, force: bool = False) -> None:
        now = time.perf_counter()
        if self.fn is None or not (force or now - self.last >= self.every):
            return
        pool = _scene(st)
        g = _shown(pool.params, pool.active)
        if self.devices > 1:  # replicated: one device's copy, no transfer
            g = jax.tree.map(lambda x: x.addressable_data(0), g)
        self.fn(st.step, g, metrics)
        self.last = now


def _loop(out, setup: Setup, st: _State, rd: RunData, seed: int, cap: int, log, clock,
          ahead_mode: str | None, watch: _Watch):
    """Steps st.step .. setup.steps (module docstring); returns the seconds spent in steps
    (their compilation, timed by `clock`, included; `watch`'s calls not)."""
    progress, s = report.Progress(st.step, setup.steps), setup.settings
    key, background = jax.random.key(seed), jnp.asarray(rd.background)
    say = lambda message: progress.write(log, message)
    stepper = _stepper(setup, ahead_mode)
    size = nbytes(rd.train_images)
    feed = TrainViews(rd.train_images, s.batch, seed, streams(size, s.stream_images),
                      rd.groups())
    if feed.stream:
        say(f"training images streamed ({size / 2**30:.1f} GiB in all)")
    if len(rd.sizes) > 1:
        say(f"training images of {len(rd.sizes)} sizes ("
            + ", ".join(f"{w}x{h}" for w, h in rd.sizes) + "): a step's views share one, "
            "and each size compiles its own step")
    busy = 0.0
    _place(setup, st)
    watch(st, dict(gaussians=int(jnp.sum(st.pool.active))), force=True)
    try:
        with open(os.path.join(out, "metrics.jsonl"), "a", buffering=1) as f:
            record = lambda **row: f.write(json.dumps(row) + "\n")
            while st.step < setup.steps:
                t0 = time.perf_counter()
                with clock:
                    m = _one_step(setup, st, rd, feed, key, background, say, stepper,
                                  clock)
                    if setup.strategy.refine_due(st.step):
                        m["count"] = _refine(setup, st, key, cap, say, record)
                if not m["ok"]:
                    st.skipped += 1
                    say(f"step {st.step + 1}: skipped (loss, gradients or parameters not finite)")
                st.step += 1
                busy += time.perf_counter() - t0
                record(step=st.step, loss=m["loss"], psnr=m["psnr"], gaussians=m["count"],
                       seconds=busy, **({} if m["ok"] else dict(skipped=True)))
                progress.step(m["loss"], m["psnr"], m["count"])
                watch(st, dict(loss=m["loss"], psnr=m["psnr"], gaussians=m["count"]),
                      force=st.step == setup.steps)
                if st.step % s.eval_every == 0 and st.step < setup.steps and rd.test_cams:
                    psnr, ssim = _evaluate(st, rd, setup)
                    record(step=st.step, heldout_psnr=psnr, heldout_ssim=ssim)
                    say(f"step {st.step}: held-out PSNR {psnr:.2f} dB, SSIM {ssim:.4f}")
                if st.step % s.checkpoint_every == 0 or st.step == setup.steps:
                    _save(out, setup, st, seed)
    finally:
        progress.close()
        stepper.close()
        feed.close()
    return busy


def _check_args(steps, max_gaussians, settings: Settings) -> None:
    """Raise `ValueError` naming the argument for counts and names `fit` cannot use."""
    for name, v, low in (("steps", steps, 0), ("max_gaussians", max_gaussians, 1),
                         ("settings.batch", settings.batch, 1),
                         ("settings.eval_every", settings.eval_every, 1),
                         ("settings.checkpoint_every", settings.checkpoint_every, 1),
                         ("settings.sh_every", settings.sh_every, 1),
                         ("settings.init_points", settings.init_points, 1)):
        if not isinstance(v, (int, np.integer)) or isinstance(v, bool) or v < low:
            raise ValueError(f"{name}: expected an int >= {low}, got {v!r}")
    number = lambda v: isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(
        v, bool)
    h, r = settings.pair_headroom, settings.row_headroom
    if not (number(h) and h >= 1):
        raise ValueError(f"settings.pair_headroom: expected a number >= 1 (fewer slots than "
                         f"pairs would drop pairs), got {h!r}")
    if not (r is None or (number(r) and r >= 1)):
        raise ValueError(f"settings.row_headroom: expected None or a number >= 1, got {r!r}")
    for name in ("antialiased", "pose_opt", "color_opt", "bilateral_grid", "app_opt",
                 "train_on_all", "stream_images"):
        v = getattr(settings, name)
        if not (isinstance(v, bool) or (v is None and name == "stream_images")):
            raise ValueError(f"settings.{name}: expected a bool"
                             + (" or None" if name == "stream_images" else "") + f", got {v!r}")
    for name, v, known in (("settings.convention", settings.convention, CONVENTIONS),
                           ("settings.ssim_padding", settings.ssim_padding, PADDINGS)):
        if v not in known:
            raise ValueError(f"{name}: expected one of {known}, got {v!r}")


def _check_devices(devices, batch: int) -> None:
    """Raise `ValueError` unless `devices` is an int in 1..len(jax.devices()) dividing batch."""
    have = len(jax.devices())
    if not isinstance(devices, (int, np.integer)) or isinstance(devices, bool) \
            or not 1 <= devices <= have:
        raise ValueError(f"devices: expected an int from 1 to {have} (the {jax.default_backend()}"
                         f" devices here), got {devices!r}")
    if batch % devices:
        raise ValueError(f"devices: {devices} devices split settings.batch = {batch} views "
                         f"unevenly; make the batch a multiple of them")


def _prepare_out(out: str, data, downscale, crop, resume, overwrite, settings) -> RunData:
    """Check OUT and load the data (before touching OUT: a bad folder deletes nothing)."""
    problem = checkpoint.run_dir_problem(out, resume, overwrite)
    if problem:
        raise ValueError(f"out: {problem}")
    rd = prepare(data, downscale, crop, settings.train_on_all)
    if settings.batch > len(rd.train_names):
        raise ValueError(f"settings.batch: {settings.batch} views per step, but the data has "
                         f"{len(rd.train_names)} training views")
    if overwrite and os.path.isdir(out):
        for name in checkpoint.run_files(out):
            os.remove(os.path.join(out, name))
    os.makedirs(out, exist_ok=True)
    return rd


def fit(data, steps: int, out: str, *, strategy: Strategy | None = None,
        settings: Settings = Settings(), max_gaussians: int = 1_000_000, downscale: int = 1,
        crop=None, seed: int = 0, backend: str | None = None, pool_size: int | None = None,
        resume: bool = False, overwrite: bool = False,
        compile_ahead: bool | str | None = None, devices: int = 1, watch=None,
        watch_every: float = 1.0, log=print) -> dict:
    """Train on `data` (a dataset folder or a `Dataset`) for `steps` steps into run directory
    `out`; returns the final metrics (also in OUT/result.json).

    strategy: `DefaultStrategy()` (default) or `MCMCStrategy()`, or your own `Strategy`.
    max_gaussians: the pool's cap (MCMC's hard cap too); pool_size: initial slots (default the
    next power of two above the initial count): preallocate the cap to avoid recompiles.
    downscale: integer image downscale at load; crop = (x0, y0, w, h): train and evaluate on a
    window of every image. backend: a differentiable backend of `render` (default `pallas` on
    GPUs, `tiles` elsewhere). `out` must be new or empty unless `resume` (continue from its
    checkpoint, bit-identically) or `overwrite` (delete its previous run's files first).
    compile_ahead: compile the step for the next pair capacity while training (`ahead.py`; the
    same results, fewer waits on compiles as the pairs grow): True or "thread" in a background
    thread, "process" in a child process through JAX's persistent compilation cache (no
    contention for Python's lock; 7% less wall time than the thread in one skull run on the
    H200, `ahead.py`), False not at all; None (default):
    "thread" where the step runs on a GPU, so that the compile takes host cores the step does
    not use (on a CPU it competes with the step for them), else False.
    devices: split each step's views across this many of `jax.devices()` (data parallel: each
    renders its share of the batch with the whole scene, the gradients summed across them;
    `settings.batch` a multiple of it); results equal one device's up to the order of that
    sum (float rounding).
    watch: None, or `watch(step, gaussians, metrics)` called on the training thread with the
    Gaussians as rendered (a `Gaussians` of the pool's size, inactive slots transparent) at
    the start, after a step when `watch_every` seconds have passed since its last call, and
    after the last step; metrics: loss, psnr (the step's training views), gaussians (active).
    Its time is not the steps'. `lgs_jax.viewer.Served.show` shows them in a browser while
    training (`fit --viewer-port`).
    Progress is a tqdm bar on stderr; `log` gets the other lines. The result: held-out PSNR
    and SSIM, Gaussians, pool size, skipped steps, seconds (the whole call), ms_per_step (wall
    time of the steps and refinements, their compilation included, evaluations and checkpoints
    not; None when no step ran) and compile_seconds (of that, the time spent compiling or
    waiting for a compile ahead; compiles ahead that finish in time cost the run nothing).
    """
    _check_args(steps, max_gaussians, settings)
    _check_devices(devices, settings.batch)
    if watch is not None and not callable(watch):
        raise ValueError(f"watch: expected None or a callable, got {type(watch).__name__}")
    if not (isinstance(watch_every, (int, float, np.integer, np.floating))
            and not isinstance(watch_every, bool) and watch_every >= 0):
        raise ValueError(f"watch_every: expected seconds >= 0, got {watch_every!r}")
    ahead_mode = mode_of(compile_ahead)
    rd = _prepare_out(out, data, downscale, crop, resume, overwrite, settings)
    backend = backend or default_backend()
    setup = Setup(settings, strategy or DefaultStrategy(), steps, rd.scene_scale, backend,
                  devices)
    if resume and os.path.exists(os.path.join(out, "checkpoint.json")):
        st = _resumed(out, setup, rd, seed, log)
    else:
        st = _fresh(setup, rd, seed, max_gaussians, pool_size, log)
    start, t0, clock = st.step, time.perf_counter(), report.CompileClock()
    with clock.listening():
        busy = _loop(out, setup, st, rd, seed, max_gaussians, log, clock, ahead_mode,
                     _Watch(watch, float(watch_every), devices))
    return _finish(out, setup, st, rd, start, busy, time.perf_counter() - t0, log,
                   clock.seconds)


def _cameras(st: _State, rd: RunData) -> list:
    """The training cameras (at their optimized poses with `Settings.pose_opt`), then the
    held-out ones."""
    cams = rd.train_cams
    if st.views is not None and "pose" in st.views:
        cams = camera_opt.adjusted(cams, jax.device_get(st.views["pose"][0]))
    train = [rd.train_camera(i, cams) for i in range(len(rd.train_names))]
    return train + list(rd.test_cams)


def _finish(out, setup: Setup, st: _State, rd: RunData, start, busy, seconds, log,
            compile_seconds) -> dict:
    """Final evaluation and outputs (module docstring); returns the result."""
    psnr, ssim = _evaluate(st, rd, setup, out)
    if psnr is None:
        log(f"step {st.step}: no held-out views to evaluate (trained on every view)")
    else:
        with open(os.path.join(out, "metrics.jsonl"), "a") as f:
            f.write(json.dumps(dict(step=st.step, heldout_psnr=psnr, heldout_ssim=ssim)) + "\n")
        log(f"step {st.step}: held-out PSNR {psnr:.2f} dB, SSIM {ssim:.4f}")
    save_ply(os.path.join(out, "scene.ply"), active_gaussians(_scene(st)))
    if st.views is not None and "head" in st.views:
        keep = np.asarray(st.pool.active)
        appearance.save(os.path.join(out, "appearance.npz"),
                        np.asarray(st.pool.params["features"])[keep], st.views["embed"][0],
                        jax.device_get(st.views["head"][0]), rd.train_names)
    save_cameras(os.path.join(out, "cameras.json"), _cameras(st, rd),
                 rd.train_names + rd.test_names)
    if st.views is not None and "color" in st.views:
        color_opt.save(os.path.join(out, "colors.json"), st.views["color"][0], rd.train_names)
    if st.views is not None and "grid" in st.views:
        bilateral_grid.save(os.path.join(out, "bilateral_grids.npz"), st.views["grid"][0],
                            rd.train_names)
    report.plot_curves(report.read_metrics(os.path.join(out, "metrics.jsonl")),
                       os.path.join(out, "curves.png"))
    ran = max(setup.steps - start, 0)
    result = dict(steps=setup.steps, heldout_psnr=psnr, heldout_ssim=ssim,
                  gaussians=int(jnp.sum(st.pool.active)), pool_size=st.pool.size,
                  skipped_steps=st.skipped, seconds=seconds,
                  ms_per_step=1e3 * busy / ran if ran else None,
                  compile_seconds=compile_seconds,
                  strategy=type(setup.strategy).__name__, backend=setup.backend,
                  device=jax.devices()[0].device_kind, devices=setup.devices)
    with open(os.path.join(out, "result.json"), "w") as f:
        json.dump(result, f, indent=1)
    return result
