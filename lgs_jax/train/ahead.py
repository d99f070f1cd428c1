"""A jitted step compiled ahead for the next size of its buffers, before a step needs it.

A training step is compiled for static sizes (`Sizes`: the pair capacity and the backward's
rows); when a step's views need more pairs than the capacity, `fit` grows it and the step is
compiled again for the new size (and the backward's rows with it, `Sizes`). Pairs grow
gradually (densification), so the next size is predictable: the smallest one a growth can
pick, `pair_capacity(capacity + 1, headroom)`.
`Stepper` wraps a jitted function (`step.train_step`): it calls it at a size, and compiles it for
the following size in the background while steps go on; at the growth it uses that executable if
it holds the pairs and was compiled for the same argument shapes (a pool that grew since needs
its own compile), for every step at that size. `ahead` compiles for a later step's shapes (the
next image level's, `fit` with several levels) at a given size, taken by the first step of
those shapes at that size. The executable is the program `jax.jit` compiles
for that size (with XLA's autotuning off, `step.COMPILER_OPTIONS`, so that a compile beside
running steps picks the same kernels as one on an idle GPU): the same bits. Where the step's
programs are kept across runs (`exports`), a size becomes a kept one near it (`Stepper.kept`: up
to `REUSE` times it, or below it down to half the headroom's room): runs whose pairs differ a
little (seeds) share their compiles.

Modes: "thread" compiles in a background thread. XLA compiles outside Python's lock, but tracing
and lowering hold it: each time the loop's thread waits on the device (a step's metrics) it
gives the lock up, and it gets it back only when the compiling thread's switch interval has run
(Python's default, 5 ms, is a step's length), so while a compile ahead traces, the interval is
`SWITCH_INTERVAL` (`sys.setswitchinterval`, restored after). "process" compiles in a child
process (`ahead_child`)
into JAX's persistent compilation cache, from which the jitted function loads the executable at
the growth: it needs the cache (`jax_compilation_cache_dir`), and a child that fails, or a cache
entry the step does not find (a JAX setting the child lacks), costs only the compile it was to
save.
"""

from __future__ import annotations

import concurrent.futures
import dataclasses
import os
import pickle
import subprocess
import sys
import threading
import time
from typing import Callable

import jax

from ..render import pair_capacity

MODES = ("thread", "process")
KEPT_SIGNATURES = 8  # `Stepper` keeps compiles ahead for the shapes of this many latest steps
SWITCH_INTERVAL = 1e-4  # seconds: Python's thread switch interval while a thread compiles ahead
REUSE = 1.25  # `Stepper.kept`: a kept program's pair capacity taken up to this much above a size

# JAX settings a child compile must share with this process for its cache entry to be the one
# this process looks up (the cache's key covers the program, the devices and the options).
SHARED_CONFIG = ("jax_enable_x64", "jax_compilation_cache_dir", "jax_platforms",
                 "jax_persistent_cache_min_compile_time_secs", "jax_compilation_cache_max_size",
                 "jax_persistent_cache_min_entry_size_bytes", "jax_default_matmul_precision")


def mode_of(compile_ahead: str | None) -> str | None:
    """`FitConfig.compile_ahead` as a `Stepper` mode: None (default) is "thread" where the step
    runs on a GPU (the compile takes host cores the step does not use; on a CPU it would
    compete with the step for them) and none elsewhere; "off" none; "thread" and "process"
    (which needs JAX's persistent compilation cache) as they are."""
    if compile_ahead is None:
        return "thread" if jax.default_backend() == "gpu" else None
    if compile_ahead not in MODES + ("off",):
        raise ValueError(f"compile_ahead: expected one of {MODES + ('off',)} or None, got "
                         f"{compile_ahead!r}")
    if compile_ahead == "process" and not jax.config.jax_compilation_cache_dir:
        raise ValueError("compile_ahead='process' compiles into JAX's persistent compilation "
                         "cache, which is off (set jax_compilation_cache_dir, or call "
                         "lgs_jax.cli.use_compile_cache())")
    return None if compile_ahead == "off" else compile_ahead


def signature(args) -> tuple:
    """What an executable compiled for `args` requires of later arguments: their tree and
    abstract values (shape, dtype, weak type; `jax.typeof`, a jax.Array's own `aval` read
    directly: the loop takes a signature every step)."""
    leaves, tree = jax.tree.flatten(args)
    return tree, tuple(x.aval if isinstance(x, jax.Array) else jax.typeof(x) for x in leaves)


def _abstract_of(sig: tuple):
    """Arguments shaped as signature `sig` (`jax.ShapeDtypeStruct`s)."""
    tree, avals = sig
    return jax.tree.unflatten(tree, [jax.ShapeDtypeStruct(a.shape, a.dtype,
                                                          weak_type=a.weak_type)
                                     for a in avals])


def _abstract(args):
    """`args` as shapes and dtypes (a compile needs no values, and holds no arrays alive)."""
    def one(x):
        t = jax.typeof(x)
        return jax.ShapeDtypeStruct(t.shape, t.dtype, weak_type=t.weak_type)

    return jax.tree.map(one, args)


@dataclasses.dataclass(frozen=True)
class Sizes:
    """The static sizes of a training step, (pair capacity, backward rows), and how they grow.

    The rows are `render`'s row_capacity (None: a row per pair slot, which nothing overflows).
    A step needs (pairs, walked): its views' largest pair count and largest count of walked
    pairs (the pairs some pixel reached: among the pairs, so never more rows than pair slots
    are needed). A capacity sized for p pairs (`pair_capacity(p, pair_headroom)`) comes with
    rows for `row_headroom` times p (`rows_for`): the rows grow with the pairs, in one program.
    `following` is the size compiled ahead, the smallest a growth of the pairs can pick;
    `grown` the size for a need the current size does not hold: the pairs, where they
    overflowed, to `pair_capacity(need, pair_headroom)` and their rows; the rows, where the
    walked pairs overflowed them, to `pair_capacity(walked, row_headroom)`; never smaller.
    """

    pair_headroom: float
    row_headroom: float | None = None

    def rows_for(self, capacity: int) -> int | None:
        """The rows a pair capacity comes with: `pair_capacity` of `row_headroom` times the
        pairs it holds at `pair_headroom`, at most a row per slot; None without a row
        headroom."""
        if self.row_headroom is None:
            return None
        return min(capacity, pair_capacity(capacity * self.row_headroom / self.pair_headroom))

    def rows_at(self, rows: int | None, capacity: int) -> int | None:
        """Rows `rows` taken to a larger `capacity`: those it comes with (`rows_for`), never
        fewer than `rows`; None stays None (a row per pair slot)."""
        return None if rows is None else max(rows, self.rows_for(capacity))

    def following(self, size: tuple) -> tuple:
        pairs = pair_capacity(size[0] + 1, self.pair_headroom)
        return pairs, self.rows_at(size[1], pairs)

    def least(self, pairs: int) -> int:
        """The smallest pair capacity a kept program may have for `pairs` pairs
        (`Stepper.kept`): half the headroom's room, and at least the pairs."""
        return pair_capacity(pairs, max(1.0, self.pair_headroom / 2))

    def holds(self, size: tuple, need: tuple) -> bool:
        return size[0] >= need[0] and (size[1] is None or size[1] >= need[1])

    def grown(self, size: tuple, need: tuple) -> tuple:
        pairs, rows = size
        if pairs < need[0]:
            pairs = pair_capacity(need[0], self.pair_headroom)
            rows = self.rows_at(rows, pairs)
        if rows is not None and rows < need[1]:
            rows = min(pairs, pair_capacity(need[1], self.row_headroom))
        return pairs, rows


class Stepper:
    """Calls the jitted `fn` at a size (`run`), compiles it for the next size ahead
    (`prepare`), and picks the size of a growth (`grow`); sizes are `Sizes`' (pair capacity,
    rows).

    `fn` is called as `fn(*args, **static(size))` and lowered as `fn.lower(*args,
    **static(size))` (args may be `jax.ShapeDtypeStruct`s): a `jax.jit` function whose static
    arguments `static` gives for a size. For mode "process" the child imports `fn` by its
    module and name (a module-level function) and unpickles `static(size)`. `mode`: "thread",
    "process" (module docstring) or None, which only calls `fn` and grows to `sizes.grown`.
    Compiles ahead and their executables are kept per argument signature: a capture of
    several image sizes runs a step per size, each with its own compile ahead. Those of the
    `KEPT_SIGNATURES` signatures run latest are kept; older ones (a pool since grown) are
    dropped. `lowering` (an `exports.Lowering`; not with mode "process", whose child compiles
    `fn` itself): every program, the steps' own as those compiled ahead, is compiled by its
    `compiled`, rather than by calling `fn`.
    """

    def __init__(self, fn, static: Callable[[tuple], dict], sizes: Sizes,
                 mode: str | None = "thread", lowering=None):
        if mode not in (None, *MODES):
            raise ValueError(f"mode: expected one of {MODES} or None, got {mode!r}")
        if lowering is not None and mode == "process":
            raise ValueError("lowering: not with mode 'process' (its child lowers fn itself)")
        self._fn, self._static, self._sizes, self._mode = fn, static, sizes, mode
        self._lowering = lowering
        self._threads = concurrent.futures.ThreadPoolExecutor(1) if mode else None
        # per signature (a capture of several image sizes has one per size):
        self._jobs = {}  # signature -> (size, future) of the background compile
        self._ready = {}  # signature -> (size, executable) taken from a finished job
        self._latest = []  # the signatures run latest, oldest first
        self.failure = None  # why the last growth's compile ahead failed (None: it did not)
        self.took_kept = False  # whether the last growth took a kept size (`kept`)
        self._waited = 0.0  # seconds `run` waited for compiles ahead since `take_waited`
        self._last_executable = None  # the executable of the last `run` (`temporaries`)

    def run(self, args, size: tuple, sig: tuple):
        """One call at `size`; `sig` = signature(args)."""
        if not self._latest or self._latest[-1] != sig:  # another shape than the last step's
            self._keep_latest(sig)
        job = self._jobs.get(sig)
        if job is not None and job[0] == size:  # compiled ahead for these shapes (`ahead`)
            self._waited += self._take(sig, self._jobs.pop(sig))[0]
        ready = self._ready.get(sig)
        if ready is not None and ready[0] == size:
            self._last_executable = ready[1]
            return ready[1](*args)
        if self._lowering is None:
            self._last_executable = None
            return self._fn(*args, **self._static(size))
        executable = self._lowering.compiled(self._fn, _abstract(args), self._static(size))
        self._ready[sig] = (size, executable)
        self._last_executable = executable
        return executable(*args)

    def temporaries(self) -> float | None:
        """The MiB of XLA temporaries the executable of the last `run` holds while it runs
        (its `memory_analysis`), or None where `run` called `fn` itself or the backend does
        not say."""
        if self._last_executable is None:
            return None
        try:
            analysis = self._last_executable.memory_analysis()
        except Exception:  # noqa: BLE001 - a backend without the analysis
            return None
        return None if analysis is None else analysis.temp_size_in_bytes / 2**20

    @property
    def compiles_ahead(self) -> bool:
        """Whether this stepper compiles ahead at all (a mode)."""
        return self._threads is not None

    def take_waited(self) -> float:
        """The seconds `run` waited for compiles ahead since the last call."""
        waited, self._waited = self._waited, 0.0
        return waited

    def _take(self, sig: tuple, job: tuple) -> tuple[float, bool]:
        """(seconds waited, whether it compiled) for the finished or awaited compile `job` of
        `sig`, its executable then ready for `run`; a failure is said in `failure`."""
        t0 = time.perf_counter()
        try:
            executable = job[1].result()  # None from a child: the jitted step loads it
        except Exception as e:  # noqa: BLE001 - any failure: the jitted step compiles instead
            self.failure = _reason(e)
            return time.perf_counter() - t0, False
        if executable is not None:
            self._ready[sig] = (job[0], executable)
        return time.perf_counter() - t0, True

    def ahead(self, args, size: tuple) -> None:
        """Start compiling `fn` at `size` for arguments shaped as `args` (arrays or
        `jax.ShapeDtypeStruct`s: a later step's, whose arrays need not exist yet), unless one
        is under way or done for those shapes; the first `run` of those shapes at `size` takes
        it, waiting where it is unfinished."""
        if self._threads is None:
            return
        sig = signature(args)
        if sig in self._jobs or sig in self._ready:
            return
        self._keep_latest(sig)  # kept among the latest until its step runs
        self._submit(args, size, sig)

    def _keep_latest(self, sig: tuple) -> None:
        """`sig` the latest signature run; forget the compiles of those no longer among the
        `KEPT_SIGNATURES` latest."""
        self._latest = [s for s in self._latest if s != sig][-(KEPT_SIGNATURES - 1):] + [sig]
        for old in set(self._jobs) | set(self._ready):
            if old not in self._latest:
                self._ready.pop(old, None)
                job = self._jobs.pop(old, None)
                if job is not None:
                    job[1].cancel()  # not started yet (else it finishes, unused)

    def prepare(self, args, size: tuple, sig: tuple) -> None:
        """Start compiling `fn` for the size after `size` (`Sizes.following`, module
        docstring), unless it is under way or done for these shapes."""
        if self._threads is None:
            return
        self.prepare_at(args, self._sizes.following(size), sig)

    def prepare_at(self, args, size: tuple, sig: tuple) -> None:
        """Start compiling `fn` at `size` for the shapes `sig` of `args`, the one a growth
        takes (`grow`), unless it is under way or done; a compile ahead at another size for
        those shapes is dropped."""
        if self._threads is None:
            return
        job = self._jobs.get(sig)
        if job is not None:
            if job[0] == size:
                return
            job[1].cancel()  # not started yet (else it finishes, unused)
        self._submit(args, size, sig)

    def _submit(self, args, size: tuple, sig: tuple) -> None:
        """Compile `fn` at `size` for `args`' shapes in the background, as the job of `sig`."""
        abstract, static = _abstract(args), self._static(size)
        if self._mode == "process":
            compile_ = lambda: _compile_in_child(self._fn, abstract, static)
        else:
            compile_ = lambda: _compile_switching_often(
                lambda: self._lowering.compiled(self._fn, abstract, static) if self._lowering
                else self._fn.lower(*abstract, **static).compile())
        self._jobs[sig] = (size, self._threads.submit(compile_))

    def kept(self, sig: tuple, size: tuple, pairs: int | None = None) -> tuple:
        """`size`, or where its program for the shapes `sig` is not kept (`exports.Lowering.
        holds`: compiled in this process or exported by an earlier run) and that of another
        pair capacity near it is, that size: the smallest kept one above `size`, at most
        `REUSE` times it, else, given the `pairs` the size is for, the largest kept one below
        it down to `Sizes.least(pairs)`. A buffer a little larger than the need changes no
        bit; a little smaller (still room for the pairs) at worst grows sooner. Either way a
        load instead of a compile: a run whose pairs differ a little from the run that filled
        the cache (another seed) takes that run's sizes. Each capacity is looked for with the
        rows it comes with (`Sizes.rows_for`; above `size`, at least its rows: below, a view
        walking more than they hold grows the rows alone). Without a lowering, `size`."""
        if self._lowering is None or self._lowering.directory is None:
            return size
        abstract = _abstract_of(sig)
        held = lambda size: self._lowering.holds(self._fn, abstract, self._static(size))
        above = size[0]
        while above <= REUSE * size[0]:
            if held(candidate := (above, self._sizes.rows_at(size[1], above))):
                return candidate
            above = pair_capacity(above + 1)
        below, capacity = None, size[0] if pairs is None else self._sizes.least(pairs)
        while capacity < size[0]:
            if held(candidate := (capacity, self._sizes.rows_for(capacity))):
                below = candidate
            capacity = pair_capacity(capacity + 1)
        return size if below is None else below


    def grow(self, size: tuple, need: tuple, sig: tuple) -> tuple[tuple, float, bool]:
        """(new size, seconds waited for the compile ahead, whether it was used) for a step at
        `size` that needs `need` = (pairs, walked): where the pairs overflowed, the prepared
        size if it holds them and fits the shapes `sig` (waiting for its compile if
        unfinished; a growth of the rows alone keeps the pair capacity), else `Sizes.grown`
        (compiled by the next `run`; also when the compile ahead failed, which `failure` then
        says, else None) or a kept size near it (`kept`, down to `Sizes.least` of the pairs;
        `took_kept` then says so)."""
        job, self.failure, self.took_kept = self._jobs.pop(sig, None), None, False
        self._ready.pop(sig, None)
        if job is not None and need[0] > size[0] and self._sizes.holds(job[0], need):
            waited, compiled = self._take(sig, job)
            if compiled:
                return job[0], waited, True
        grown = self._sizes.grown(size, need)
        kept = self.kept(sig, grown, need[0] if grown[0] != size[0] else None)
        if not self._sizes.holds(kept, need):  # rows below the walked pairs: no use
            kept = grown
        self.took_kept = kept != grown
        return kept, 0.0, False

    def close(self) -> None:
        """Forget the executables; a compile under way finishes in the background unwaited."""
        self._jobs, self._ready, self._latest = {}, {}, []
        if self._threads is not None:
            self._threads.shutdown(wait=False, cancel_futures=True)


def _reason(e: Exception) -> str:
    """One line on why a compile ahead failed (a child's last line of stderr)."""
    lines = (getattr(e, "stderr", None) or b"").decode(errors="replace").strip().splitlines()
    return lines[-1] if lines else f"{type(e).__name__}: {e}"


_switching = dict(compiles=0, before=None)  # compiles under way in threads (any Stepper's)
_switching_lock = threading.Lock()


def _compile_switching_often(compile_: Callable):
    """`compile_()` with Python's switch interval at `SWITCH_INTERVAL` while any such compile
    is under way (module docstring), the interval before the first restored after the last."""
    with _switching_lock:
        if _switching["compiles"] == 0:
            _switching["before"] = sys.getswitchinterval()
            sys.setswitchinterval(SWITCH_INTERVAL)
        _switching["compiles"] += 1
    try:
        return compile_()
    finally:
        with _switching_lock:
            _switching["compiles"] -= 1
            if _switching["compiles"] == 0:
                sys.setswitchinterval(_switching["before"])


def _compile_in_child(fn, abstract, static: dict) -> None:
    """Compile `fn.lower(*abstract, **static)` in a child process (`ahead_child`) into the
    persistent compilation cache, with this process's `SHARED_CONFIG`; raises if the child
    fails."""
    config = {name: jax.config.values[name] for name in SHARED_CONFIG
              if name in jax.config.values}
    env = dict(os.environ, XLA_PYTHON_CLIENT_PREALLOCATE="false")  # this process holds the GPU
    job = (fn.__module__, fn.__qualname__, abstract, static)
    subprocess.run([sys.executable, "-m", "lgs_jax.train.ahead_child"], env=env, check=True,
                   input=pickle.dumps(config) + pickle.dumps(job), capture_output=True)
