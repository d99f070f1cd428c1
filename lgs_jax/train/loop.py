"""`fit`: train Gaussians on a capture, with a densification strategy, into a run directory.

Per step s (0-based): the views of `feed.views_for_step` at the step's image level
(`levels.LevelFeed`: full resolution unless `Recipe.levels` > 1), one `step.train_step` (through
`ahead.Stepper`; redone with a larger pair capacity whenever a view overflows: no pair is
dropped; the capacity starts at and grows to `pair_capacity(pairs, config.pair_headroom)`,
or to a kept size near that, whose program an earlier run exported (`Stepper.kept`),
and with several levels starts again at each level's first step, sized to its first view;
likewise the backward's rows, sized by `config.row_headroom`, `ahead.Sizes`), then
`step.refine` where the strategy asks (the pool doubles when it needs room, up to
`max_gaussians`: a recompile; both are logged). A step whose loss or gradients would not be
finite is skipped (nothing changes), logged and recorded. The step donates the run's state
(`RunState`'s pool, optimizer, strategy and views): after a step only its outputs are used.
Where nothing between two steps reads or replaces the state (no refinement, evaluation,
checkpoint, watch, early-stop check, level change or stop), step s + 1 is dispatched before
step s's metrics are read, so the device never waits for the host's read (`_ahead`); step
s + 1 gets step s's `fits` as its `go`, so where s overflowed, s + 1 changes nothing and both
run again in order: the same bits as one step after another.

The run folder (`rundir`) is checked and locked before any work. OUT/metrics.jsonl gets a row
per step (loss, training-view PSNR, active Gaussians, seconds; the peak where it rose,
`report.PeakRise`; the first step's the memory by part, `report.memory_parts`), per
refinement (its counts), per growth of a step's buffers (their new sizes) and per evaluation
(held-out PSNR/SSIM: `heldout.Evaluations`, scored on the device), the last three with the
device's memory in use and its peak so far (`report.device_memory`, on a GPU); a checkpoint
(`checkpoint`, `state.save`; bit-identical resume) every config.checkpoint_every steps, at the
end, and at Ctrl-C (`interrupt`: the run stops at the next step boundary and raises
`Interrupted`); the outputs at the end (`outputs.finish`), which with `Recipe.early_stop` may
come before config.steps (`early_stop`: when the training loss stops falling).
"""

from __future__ import annotations

import dataclasses
import os
import time

import jax
import jax.numpy as jnp

from ..render import default_backend, pair_capacity
from . import heldout, outputs, processes, recipes, report, rundir, sharded_state, state
from .ahead import Sizes, Stepper, mode_of, signature
from .checkpoint import data_of
from .config import FitConfig, Setup, devices_problem
from .early_stop import EarlyStop
from .feed import RunData, nbytes, prepare, streams
from .init import wide_start
from .interrupt import Interrupted, StopRequest
from .levels import LevelFeed, check as check_levels
from .sharded import mesh_of
from .watch import Watch, check_hooks
from .state import RunState
from .step import distinct, lowering, read_metrics, refine, replicated, train_step


# A step's second buffer beside the pairs (`ahead.Sizes`' second size): the RunState field
# that holds it, the metrics that report its overflow and need, and its name in the log. One
# device: the backward's rows; Gaussian parallel: the exchange's records (`sharded`).
SECOND = {False: ("rows", "row_overflow", "walked", "backward rows"),
          True: ("exchange", "exchange_overflow", "exchange_required", "exchange capacity")}


def stepper(config: FitConfig, setup: Setup) -> Stepper:
    """`train_step` of this run (keyed by `setup.for_step`) behind an `ahead.Stepper` of the
    configured mode, lowered through export entries (`step.lowering`), on one device; with Gaussian
    parallel, the exchange capacity grown with the pair headroom. Neither on several devices
    (an executable is for arguments on one device: their shardings are not in the shapes)."""
    keyed = setup.for_step  # runs differing only in the loop's settings share the programs
    if setup.gaussian_devices > 1:
        static = lambda size: dict(setup=keyed, capacity=size[0], exchange=size[1])
        return Stepper(train_step, static, Sizes(config.pair_headroom, config.pair_headroom), None)
    static = lambda size: dict(setup=keyed, capacity=size[0], rows=size[1])
    mode = mode_of(config.compile_ahead) if setup.devices == 1 else None
    return Stepper(train_step, static, state.sizes(config), mode,
                   lowering() if setup.devices == 1 and mode != "process" else None)


@dataclasses.dataclass
class _Run:
    """What the loop's pieces share: the configuration, its setup, the data, the state, the
    run's key and background, the caller's `log`, the loop's log (`say`, above the progress
    bar) and metrics (`record`), and whether the early stop ended the run."""

    config: FitConfig
    setup: Setup
    rd: RunData
    st: RunState
    log: object
    say: object = None
    record: object = None
    evaluations: heldout.Evaluations | None = None
    pending: dict | None = None  # the metrics (on the device) of the next step, dispatched ahead
    stopped_early: bool = False
    level: int | None = None  # the image level of the last step run (`levels`)
    next_level: tuple | None = None  # (level, pair capacity) compiled ahead (`_level_ahead`)
    eval_seconds: float = 0.0  # held-out evaluations during the run
    checkpoint_seconds: float = 0.0  # checkpoints during the run
    device_wait_seconds: float = 0.0  # the loop blocked reading steps' metrics (`_one_step`)

    def __post_init__(self):
        self.key = jax.random.key(self.config.seed)
        self.background = jnp.asarray(self.rd.background)
        self.go = jnp.ones((), bool)  # `train_step`'s go where the previous step was read
        if (where := replicated(self.setup)) is not None:
            self.go = jax.device_put(self.go, where)


def _enter_level(run: _Run, feed: LevelFeed, steps: Stepper) -> None:
    """At the run's first step and, with several image levels, at the first step of a level:
    the pair capacity, or a kept one near it (`Stepper.kept`: the size another seed's run
    compiled; above it only at a single level's start, whose pairs were not counted). One
    level: the capacity the run's state has (`state.fresh`'s, or a checkpoint's). Several:
    sized to the level's first training view, as `state.fresh` sizes it at full resolution (a
    coarse level's step needs a fraction of the pairs; the capacity changes no bit,
    `docs/determinism-and-capacities.md`), times the pool's slots over its active Gaussians:
    room for the pairs of a pool filled during the level (the fast recipe's budget rises
    through the coarse levels), so a level compiles once rather than at every growth. Where
    the level's step was compiled ahead (`_level_ahead`) at a capacity that holds this one and
    is at most twice it, that capacity."""
    st, level = run.st, feed.level(run.st.step)
    if level == run.level:
        return
    run.level, lv = level, feed.levels[level]
    images, idx = feed.args(st.step)
    sig = signature(_args(run, feed.cams(st.step), images, idx, st.step, run.go))
    if len(feed.levels) == 1:
        field = SECOND[run.setup.gaussian_devices > 1][0]
        st.capacity = steps.kept(sig, (st.capacity, getattr(st, field)))[0]
        return
    st.capacity = _level_capacity(run, lv, steps, sig)
    ahead = run.next_level
    took = ahead is not None and ahead[0] == level and st.capacity <= ahead[1] <= 2 * st.capacity
    if took:
        st.capacity = ahead[1]
    run.say(f"step {st.step + 1}: images at {lv.sizes[0][0]}x{lv.sizes[0][1]} "
            f"({'full size' if lv.factor == 1 else f'1/{lv.factor}'}), pair capacity "
            f"{st.capacity}" + (" (compiled ahead)" if took else ""))


def _level_capacity(run: _Run, lv, steps: Stepper, sig: tuple) -> int:
    """The pair capacity of level `lv` for the pool as it is (`_enter_level`), or a kept one
    near it for the level's step shaped `sig` (`Stepper.kept`, down to `Sizes.least`: the
    size another seed's run compiled)."""
    st = run.st
    pairs = state.pairs(st.pool, lv.camera(0), run.setup.recipe.antialiased)
    filled = int(pairs * st.pool.size / max(state.active_count(st.pool), 1))
    need = pair_capacity(filled, run.config.pair_headroom)
    field = SECOND[run.setup.gaussian_devices > 1][0]
    return steps.kept(sig, (need, getattr(st, field)), filled)[0]


def _level_ahead(run: _Run, feed: LevelFeed, steps: Stepper) -> None:
    """Halfway through a level that has a next one, where the stepper compiles ahead: the
    next level's step compiled in the background (`Stepper.ahead`, for its first training
    view's image size) at the capacity `_enter_level` would give it with the pool as it is
    now, so that the coarse steps hide the trace, lowering and compile of the finer one. Such
    a level compiles no grown capacity ahead (`_dispatch`): its capacity is sized for a full
    pool, and the stepper's one thread would compile that before the next level's step."""
    st = run.st
    level = feed.level(st.step)
    if not steps.compiles_ahead or level + 1 >= len(feed.levels):
        return
    start, end = feed.starts[level], feed.starts[level + 1]
    if st.step < (start + end) // 2 or run.next_level is not None and run.next_level[0] > level:
        return
    lv = feed.levels[level + 1]
    images, idx = feed.args(st.step)
    width, height = lv.sizes[0]
    shaped = jax.ShapeDtypeStruct((images.shape[0], height, width) + images.shape[3:],
                                  images.dtype)
    args = _args(run, lv.cams, shaped, idx, end, run.go)
    run.next_level = (level + 1, _level_capacity(run, lv, steps, signature(args)))
    field = SECOND[run.setup.gaussian_devices > 1][0]
    steps.ahead(args, (run.next_level[1], getattr(st, field)))


def _args(run: _Run, cams, images, idx, step: int, go) -> tuple:
    """`train_step`'s arguments for 0-based `step` on the run's state."""
    st = run.st
    return (st.pool, st.opt_state, st.strategy_state, st.views, cams, images, idx,
            run.background, step, run.key, st.order, go)


def _dispatch(run: _Run, feed: LevelFeed, steps: Stepper, step: int, size: tuple, go):
    """Start 0-based step `step` at `size` on the run's state, which becomes the step's
    outputs (the arguments were donated; a step that does not apply returns them unchanged);
    returns (its metrics on the device, the signature of its arguments)."""
    st = run.st
    images, idx = feed.args(step)
    args = _args(run, feed.cams(step), images, idx, step, go)
    sig = signature(args)
    new = steps.run(args, size, sig)
    feed.prefetch(step + 1)  # while the step runs
    if feed.level(step) + 1 == len(feed.levels):  # else the next level's step (`_level_ahead`)
        steps.prepare(args, size, sig)
    st.pool, st.opt_state, st.strategy_state, st.views = new[:4]
    return new[4], sig


def _one_step(run: _Run, feed: LevelFeed, steps: Stepper, clock, then_next: bool) -> dict:
    """Run step st.step (capacity grown until nothing overflows), unless it was dispatched
    ahead (run.pending); with `then_next`, dispatch step st.step + 1 before reading step
    st.step's metrics (module docstring). Returns step st.step's metrics."""
    st = run.st
    field, flag, needed, name = SECOND[run.setup.gaussian_devices > 1]
    pending, run.pending = run.pending, None
    if pending is None:
        _enter_level(run, feed, steps)
    _level_ahead(run, feed, steps)
    while True:
        size = (st.capacity, getattr(st, field))
        if pending is not None:
            (metrics, sig), pending = pending, None
        else:
            metrics, sig = _dispatch(run, feed, steps, st.step, size, run.go)
        if then_next:
            run.pending = _dispatch(run, feed, steps, st.step + 1, size, metrics["fits"])
        clock.waited(steps.take_waited())
        t0 = time.perf_counter()
        m = read_metrics(metrics)
        run.device_wait_seconds += time.perf_counter() - t0
        if not (m["overflow"] or m[flag]):
            return m
        run.pending = None  # it changed nothing: the state is this step's inputs again
        need = (m["pairs"], m[needed])
        grown_size, waited, ahead = steps.grow(size, need, sig)
        if grown_size == size:  # never loop on a size that cannot hold the step
            raise RuntimeError(f"step {st.step + 1}: (pairs, {name}) {size} overflowed, "
                               f"{need} needed")
        st.capacity = grown_size[0]
        setattr(st, field, grown_size[1])
        clock.waited(waited)
        grown = [f"{what} grown to {new_size}" for what, new_size, old_size in
                 (("pair capacity", grown_size[0], size[0]), (name, grown_size[1], size[1]))
                 if new_size != old_size]
        run.record(grown_step=st.step + 1, pair_capacity=grown_size[0],
                   **{field: grown_size[1]}, **report.device_memory())
        run.say(f"step {st.step + 1}: {' and '.join(grown)} "
                + (f"(compiled ahead; waited {waited:.1f} s)" if ahead else
                   "(a size kept from an earlier run)" if steps.took_kept else "(one recompile)")
                + (f"; the compile ahead failed: {steps.failure}" if steps.failure else ""))


def _place(setup: Setup, st: RunState) -> None:
    """No array in two places of the run's state (`step.distinct`: the step donates the state;
    a state built outside the step, at the start or by a refinement, may share one; copied
    first, as `jax.device_put` of one array twice gives two arrays of one buffer), then a
    data-parallel run's state whole on each of its devices (`step.replicated`), a
    Gaussian-parallel run's in blocks over its mesh (`sharded`); a no-op where it is already,
    and for one device."""
    st.pool, st.opt_state, st.strategy_state, st.views = distinct(st.saved)
    if setup.gaussian_devices > 1:
        (st.pool, st.opt_state, st.strategy_state), st.views = sharded_state.place(
            mesh_of(setup), (st.pool, st.opt_state, st.strategy_state), st.views)
    elif (where := replicated(setup)) is not None:
        st.pool, st.opt_state, st.strategy_state, st.views = jax.device_put(st.saved, where)


def _refine(run: _Run) -> int:
    """The strategy's refinement at step st.step, recorded, the pool's growth logged; returns
    the number of active Gaussians after it."""
    st, setup = run.st, run.setup
    if setup.gaussian_devices > 1:
        st.strategy_state, st.pool, st.opt_state, rep, st.order = sharded_state.refine(
            setup.strategy, st.strategy_state, st.pool, st.opt_state, st.order, st.step,
            run.key, run.config.max_gaussians, mesh_of(setup),
            state.balance_cameras(run.rd), setup.recipe.antialiased)
    else:
        st.strategy_state, st.pool, st.opt_state, rep = refine(
            setup.strategy, st.strategy_state, st.pool, st.opt_state, st.step, run.key,
            run.config.max_gaussians, in_place=True)
    _place(setup, st)
    if rep["grown_to"]:
        run.say(f"step {st.step}: pool grown to {rep['grown_to']} slots (one recompile)")
    if not rep["ok"]:
        run.say(f"step {st.step}: refinement skipped: it would make parameters non-finite")
    count = state.active_count(st.pool)
    run.record(refine_step=st.step, **rep, gaussians=count, **report.device_memory())
    return count


def _feed(run: _Run) -> LevelFeed:
    """The training views' feed (streamed or whole, at the recipe's levels), its choices
    logged."""
    rd, config, recipe = run.rd, run.config, run.config.recipe
    size = nbytes(rd.train_images)
    feed = LevelFeed(rd, recipe.batch, config.seed, streams(size, config.stream_images),
                     recipe.levels, config.steps, recipe.full_resolution_at)
    if recipe.levels > 1:
        run.say(feed.describe())
    if feed.stream:
        run.say(f"training images streamed ({size / 2**30:.1f} GiB in all)")
    if len(rd.sizes) > 1:
        run.say(f"training images of {len(rd.sizes)} sizes ("
                + ", ".join(f"{w}x{h}" for w, h in rd.sizes) + "): a step's views share one, "
                "and each size compiles its own step")
    return feed


def _after_step(run: _Run, m: dict, watch: Watch, data: dict, last: bool) -> None:
    """A step's watch, evaluation and checkpoint; `last`: the run's last step."""
    st, config = run.st, run.config
    if run.pending is None:  # else the state is the next step's (`_ahead`: not due then)
        watch(st, dict(loss=m["loss"], psnr=m["psnr"], gaussians=m["count"]), force=last)
    if run.evaluations is not None:  # their programs compiled ahead, beside the steps
        run.evaluations.after_step(st.step, config.eval_every, config.steps,
                                   lambda: state.scene(st))
    if run.evaluations is not None and st.step % config.eval_every == 0 and not last:
        t0 = time.perf_counter()
        psnr, ssim = run.evaluations.score(state.scene(st))
        st.eval_capacity = run.evaluations.capacity
        run.eval_seconds += time.perf_counter() - t0
        run.record(step=st.step, heldout_psnr=psnr, heldout_ssim=ssim, **report.device_memory())
        run.say(f"step {st.step}: held-out PSNR {psnr:.2f} dB, SSIM {ssim:.4f}")
    if st.step % config.checkpoint_every == 0 or last:
        t0 = time.perf_counter()
        state.save(config.out, config, st, data)
        run.checkpoint_seconds += time.perf_counter() - t0


def _early_stop(run: _Run, feed: LevelFeed) -> EarlyStop:
    """The run's early stop (`Recipe.early_stop`), with the losses of the steps done so far (a
    resumed run's, from metrics.jsonl)."""
    path = os.path.join(run.config.out, "metrics.jsonl")
    on = run.config.recipe.early_stop and os.path.exists(path)
    return EarlyStop.of(run.config.recipe, feed.starts[-1],
                        report.read_metrics(path) if on else [], path, run.st.step)


def _stops_early(run: _Run, early: EarlyStop) -> bool:
    """Whether the early stop ends the run now (after st.step steps), said and noted."""
    step = run.st.step
    if not early.due(step):
        return False
    before, recent = early.means(step)
    run.say(f"step {step}: early stop: the training loss's mean over the last {early.window} "
            f"steps, {recent:.5g}, fell less than {early.gain:g} below the window's before "
            f"({before:.5g})")
    run.stopped_early = True
    return True


def _ahead(run: _Run, feed: LevelFeed, early: EarlyStop, watch: Watch, stop: StopRequest,
           step: int) -> bool:
    """Whether step `step` + 1 may be dispatched before step `step`'s metrics are read:
    it is a step of the run and nothing between the two reads or replaces the state (a
    refinement, an evaluation, a checkpoint, the watch, the early stop's check, a new image
    level, a requested stop)."""
    config, after = run.config, step + 1
    return (after < config.steps and not run.setup.strategy.refine_due(step)
            and after % config.checkpoint_every != 0
            and (run.evaluations is None or after % config.eval_every != 0)
            and not early.checks(after) and feed.level(after) == feed.level(step)
            and not watch.due() and not stop.requested)


def _loop(run: _Run, clock, watch: Watch, stop: StopRequest, data: dict) -> float:
    """Steps st.step .. config.steps (module docstring), until `stop` is requested or the early
    stop ends the run; returns the seconds spent in steps (their compilation, timed by `clock`,
    included; `watch`'s calls not). `data`: the run's data as checkpoints record it."""
    st, config = run.st, run.config
    progress = report.Progress(st.step, config.steps)
    run.say = lambda message: progress.write(run.log, message)
    steps, feed, busy, start = stepper(config, run.setup), _feed(run), 0.0, st.step
    peak = report.PeakRise()
    early = _early_stop(run, feed)
    if run.rd.test_cams:
        kind = (sharded_state.Evaluations if run.setup.gaussian_devices > 1
                else heldout.Evaluations)
        run.evaluations = kind(run.rd.test_cams, run.rd.test_images, run.rd.background,
                               run.setup, st.eval_capacity, config.pair_headroom,
                               mode_of(config.compile_ahead) if run.setup.devices == 1 else None)
    _place(run.setup, st)
    watch(st, dict(gaussians=state.active_count(st.pool)), force=True)
    try:
        with report.metrics_rows(config.out) as run.record:
            # a stop requested while a step was dispatched ahead ends after that step
            while st.step < config.steps and (not stop.requested or run.pending is not None):
                if _stops_early(run, early):
                    break
                t0 = time.perf_counter()
                with clock:
                    m = _one_step(run, feed, steps, clock,
                                  _ahead(run, feed, early, watch, stop, st.step))
                    if run.setup.strategy.refine_due(st.step):
                        m["count"] = _refine(run)
                if not m["ok"]:
                    st.skipped += 1
                    run.say(f"step {st.step + 1}: skipped (loss or gradients not finite)")
                st.step += 1
                busy += time.perf_counter() - t0
                first = st.step == start + 1  # its row: the device memory by part
                run.record(step=st.step, loss=m["loss"], psnr=m["psnr"], gaussians=m["count"],
                           seconds=busy, **({} if m["ok"] else dict(skipped=True)), **peak(),
                           **(dict(memory=report.memory_parts(
                               state.parts(st), steps.temporaries())) if first else {}))
                progress.step(m["loss"], m["psnr"], m["count"],
                              (st.step - start) / max(busy - clock.seconds, 1e-9))
                early.record(st.step, m["loss"])
                _after_step(run, m, watch, data, st.step == config.steps or early.due(st.step))
    finally:
        progress.close()
        steps.close()
        feed.close()
    return busy


def fit(config: FitConfig, dataset=None, *, watch=None, watch_every: float = 1.0,
        log=print) -> dict:
    """Train as `config` says (`FitConfig`: data, run folder, steps, recipe, strategy, ...) into
    config.out; returns the final metrics (also in OUT/result.json).

    dataset: the `Dataset` to train on, already loaded (config.data then only names it: its
    folder is recorded for resuming), or None to load config.data. watch: None, or
    `watch(step, gaussians, metrics)` called on the training thread with the Gaussians as
    rendered (a `Gaussians` of the pool's size, inactive slots transparent) at the start,
    after a step when `watch_every` seconds have passed since its last call, and after the
    last step; metrics: loss, psnr (the step's training views), gaussians (active). Its time
    is not the steps'. `lgs_jax.viewer.Served.show` shows them in a browser while training
    (`fit --viewer-port`). Progress is a tqdm bar on stderr (its rate and ETA leave out the
    time spent compiling); `log` gets the other lines.

    Before any work: the configuration and OUT are checked (`check_out`; `rundir.RunDirError`
    and other `ValueError`s name the field) and OUT is locked for the run. Ctrl-C stops the run
    at the next step boundary, writes a checkpoint and raises `interrupt.Interrupted`. The
    result: held-out PSNR and SSIM, Gaussians, pool size, skipped steps, seconds (the whole
    call), ms_per_step (wall time of the steps and refinements, their compilation included,
    evaluations and checkpoints not; None when no step ran), compile_seconds (of that, the
    time spent compiling or waiting for a compile ahead) with its parts and programs
    (`report.CompileClock.result`), the parts of `seconds` (load_seconds: data and the start
    or resume; step_seconds: steps and refinements, of which device_wait_seconds the loop
    blocked reading their metrics while the device computed; eval_seconds and
    checkpoint_seconds during the run; finish_seconds: the final evaluation and the output
    files; logged in one line at the end), peak_mib (the device's peak memory in the process,
    MiB; None on the CPU), memory (the device memory by part at the end,
    `report.memory_parts`) and stopped_early_at (the step the early stop ended the run at, or
    None).

    Several processes (`jax.distributed.initialize`, docs/multi-gpu.md "Several hosts"): every
    process makes the same call, with gaussian_devices = `jax.device_count()` and the same
    data, and they train one model; process 0 alone checks, locks and writes config.out (the
    others write nothing, not even the folder); every process returns the result. A resume
    reads the checkpoint on every process. Refused there (`ValueError` naming the field):
    other gaussian_devices, devices > 1, a watch (`processes.problem`).
    """
    if not isinstance(config, FitConfig):
        raise ValueError(f"config: expected a FitConfig, got {type(config).__name__}")
    check_hooks(watch, watch_every)
    config = recipes.for_start(config, lambda: wide_start(
        dataset if dataset is not None else config.data), log)
    devices_problem(config)
    processes.problem(config, watch)
    mode_of(config.compile_ahead)  # checks "process" has its cache
    data_path = dataset.path if dataset is not None else config.data
    with processes.claimed(config, data_path) as resuming:
        return _run(config, dataset, data_path, Watch(watch, float(watch_every), config.devices,
                                                      config.gaussian_devices > 1), log, resuming)


def _run(config: FitConfig, dataset, data_path: str, watch: Watch, log, resuming: bool) -> dict:
    """`fit` in its claimed folder: load, start or resume (`resuming`), loop, finish."""
    t0, out = time.perf_counter(), config.out
    rd = prepare(dataset if dataset is not None else config.data, config.downscale, config.crop,
                 config.train_on_all, config.image_dtype)
    if config.recipe.batch > len(rd.train_names):
        raise ValueError(f"recipe.batch: {config.recipe.batch} views per step, but the data "
                         f"has {len(rd.train_names)} training views")
    check_levels(rd.train_sizes, config.recipe.levels)
    if config.overwrite and processes.writer():
        for name in rundir.run_files(out):
            os.remove(os.path.join(out, name))
    setup = Setup.of(config, rd.scene_scale, default_backend())
    run = None
    try:
        with StopRequest() as stop:
            if resuming:
                st = state.resumed(config, setup, rd, log)
            else:
                st = state.fresh(config, setup, rd, log)
            start, clock, data = st.step, report.CompileClock(), data_of(config, data_path)
            run = _Run(config, setup, rd, st, log)
            loaded = time.perf_counter() - t0
            with clock.listening():
                busy = _loop(run, clock, watch, stop, data)
            if st.step < config.steps and not run.stopped_early:  # stopped by Ctrl-C
                state.save(out, config, st, data)
                raise Interrupted(st.step, config.steps, out)
        ran = max(st.step - start, 0)
        times = dict(seconds=time.perf_counter() - t0,
                     ms_per_step=1e3 * busy / ran if ran else None,
                     **clock.result(), load_seconds=loaded, step_seconds=busy,
                     device_wait_seconds=run.device_wait_seconds, eval_seconds=run.eval_seconds,
                     checkpoint_seconds=run.checkpoint_seconds,
                     stopped_early_at=st.step if run.stopped_early else None)
        return outputs.finish(out, setup, st, rd, times, log, run.evaluations)
    finally:  # the held-out evaluations' compiles ahead end with the run
        if run is not None and run.evaluations is not None:
            run.evaluations.close()
