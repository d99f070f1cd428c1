"""The training step compiled for the next pair capacity before a step needs it.

A step whose views need more tile–Gaussian pairs than the capacity grows it (`loop._one_step`), and
the step is compiled again for the new capacity: about 20 s on an H200, three times in a 7k-step
skull run at the default headroom (BENCHMARKS.md §7). Pairs grow gradually (densification), so the
next capacity is predictable: the smallest one a growth can pick, `pair_capacity(capacity + 1,
headroom)`. `Stepper` compiles the step for it in a background thread while training goes on (XLA
compiles outside Python's global lock, and the main thread mostly waits on the device), and at the
growth uses that executable if it holds the pairs and was compiled for the same argument shapes (a
pool that grew since needs its own compile, as before), for every step at that capacity (and the
same backward rows, `Sizes`: a growth of the rows, where `fit` sizes them, is compiled when it
happens). It is the program `jax.jit` compiles for that capacity, compiled with XLA's autotuning
off (`step.COMPILER_OPTIONS`), so that a compile beside running steps picks no other kernel
configuration than one on an idle GPU: the same bits (tests/train: a run with and one without, bit
for bit, on the CPU). On the H200, two skull runs at headroom 3 compiled ahead (thread, process)
ended at 25.96 dB where four without compiling ahead ended at 26.81, before autotuning was turned
off (BENCHMARKS.md §7, "Dec 2, midday"); with it off, skull runs of 1500 steps, twice without and
once with a compile ahead in a thread (two growths, one compiled ahead at step 604 and used for 800
steps), ended with the same checkpoint bits on the H200.

In a thread, tracing and lowering the step (Python: Mosaic GPU's layout inference, about 6 s
per capacity, `scripts/lower_time.py`) hold Python's lock, and the training loop's steps ran
about 6x slower while it did on the H200 (BENCHMARKS.md §7). Mode "process" compiles in a child
process instead (`ahead_child`), into JAX's persistent compilation cache: at the growth the
jitted step lowers again in this process and loads the executable from the cache. It needs
the cache (`jax_compilation_cache_dir`); a child that fails, or a cache entry the step does not
find (a JAX setting the child lacks), costs only the compile it was to save. Skull, 7k steps,
headroom 3, H200: 19.42 ms per step with a thread (the steps slowed beside its lowering), 18.04
with a child (which starts Python and JAX first: it waited 15 s at each of the two early
growths, where the thread waited 3–5 s), 22.46 with no compile ahead; one run each. (Sending the
executable back serialized, `jax.experimental.serialize_executable`, would spare this process
the lowering too, but on the CPU the train step so loaded failed at run time, "NOT_FOUND:
Function broadcast_divide_fusion.5 not found", where the cache's own loading works.)
"""

from __future__ import annotations

import concurrent.futures
import dataclasses
import os
import pickle
import subprocess
import sys
import time
from typing import Callable

import jax

from ..render import pair_capacity

MODES = ("thread", "process")
KEPT_SIGNATURES = 8  # `Stepper` keeps compiles ahead for the shapes of this many latest steps

# JAX settings a child compile must share with this process for its cache entry to be the one
# this process looks up (the cache's key covers the program, the devices and the options).
SHARED_CONFIG = ("jax_enable_x64", "jax_compilation_cache_dir", "jax_platforms",
                 "jax_persistent_cache_min_compile_time_secs",
                 "jax_persistent_cache_min_entry_size_bytes", "jax_default_matmul_precision")


def mode_of(compile_ahead) -> str | None:
    """`fit`'s compile_ahead as a `Stepper` mode: None (default) is "thread" where the step
    runs on a GPU (the compile takes host cores the step does not use; on a CPU it would
    compete with the step for them) and no compile ahead elsewhere; True is "thread", False
    None; "thread" and "process" (which needs JAX's persistent compilation cache) as they are."""
    if compile_ahead is None:
        return "thread" if jax.default_backend() == "gpu" else None
    if compile_ahead is True or compile_ahead is False:
        return "thread" if compile_ahead else None
    if compile_ahead not in MODES:
        raise ValueError(f"compile_ahead: expected one of {MODES}, True, False or None, got "
                         f"{compile_ahead!r}")
    if compile_ahead == "process" and not jax.config.jax_compilation_cache_dir:
        raise ValueError("compile_ahead='process' compiles into JAX's persistent compilation "
                         "cache, which is off (set jax_compilation_cache_dir, or call "
                         "lgs_jax.cli.use_compile_cache())")
    return compile_ahead


def signature(args) -> tuple:
    """What an executable compiled for `args` requires of later arguments: their tree and
    abstract values (shape, dtype, weak type)."""
    leaves, tree = jax.tree.flatten(args)
    return tree, tuple(jax.typeof(x) for x in leaves)


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
    pairs. `following` is the size a growth of the pairs picks first (compiled ahead),
    `grown` the size for a need the current size does not hold: what overflowed grows to
    `pair_capacity(need, headroom)`, the rest stays.
    """

    pair_headroom: float
    row_headroom: float | None = None

    def following(self, size: tuple) -> tuple:
        return pair_capacity(size[0] + 1, self.pair_headroom), size[1]

    def holds(self, size: tuple, need: tuple) -> bool:
        return size[0] >= need[0] and (size[1] is None or size[1] >= need[1])

    def grown(self, size: tuple, need: tuple) -> tuple:
        pairs, rows = size
        if pairs < need[0]:
            pairs = pair_capacity(need[0], self.pair_headroom)
        if rows is not None and rows < need[1]:
            rows = pair_capacity(need[1], self.row_headroom)
        return pairs, rows


class Stepper:
    """Runs the step at a size (`run`), compiles the next size's step ahead (`prepare`), and
    picks the size of a growth (`grow`); sizes are `Sizes`' (pair capacity, rows).

    `step(args, size)` is the jitted step; `lower(args, size)` its `jax.stages.Lowered`
    (args may be `jax.ShapeDtypeStruct`s; for mode "process" `lower` must pickle: a module-level
    function or a `functools.partial` of one). `mode`: "thread", "process" (module docstring) or
    None, which only runs the jitted step and grows to `sizes.grown`. Compiles ahead and their
    executables are kept per argument signature: a capture of several image sizes runs a step
    per size, each with its own compile ahead. Those of the `KEPT_SIGNATURES` signatures run
    latest are kept; older ones (a pool since grown) are dropped.
    """

    def __init__(self, step: Callable, lower: Callable, sizes: Sizes,
                 mode: str | None = "thread"):
        if mode not in (None, *MODES):
            raise ValueError(f"mode: expected one of {MODES} or None, got {mode!r}")
        self._step, self._lower, self._sizes, self._mode = step, lower, sizes, mode
        self._threads = concurrent.futures.ThreadPoolExecutor(1) if mode else None
        # per signature (a capture of several image sizes has one per size):
        self._jobs = {}  # signature -> (size, future) of the background compile
        self._ready = {}  # signature -> (size, executable) taken from a finished job
        self._latest = []  # the signatures run latest, oldest first
        self.failure = None  # why the last growth's compile ahead failed (None: it did not)

    def run(self, args, size: tuple, sig: tuple):
        """One step at `size`; `sig` = signature(args)."""
        if not self._latest or self._latest[-1] != sig:  # another shape than the last step's
            self._keep_latest(sig)
        ready = self._ready.get(sig)
        if ready is not None and ready[0] == size:
            return ready[1](*args)
        return self._step(args, size)

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
        """Start compiling the step for the size after `size` (`Sizes.following`, module
        docstring), unless it is under way or done for these shapes."""
        if self._threads is None:
            return
        following = self._sizes.following(size)
        job = self._jobs.get(sig)
        if job is not None:
            if job[0] == following:
                return
            job[1].cancel()  # not started yet (else it finishes, unused)
        abstract = _abstract(args)
        if self._mode == "process":
            compile_ = lambda: _compile_in_child(self._lower, abstract, following)
        else:
            compile_ = lambda: self._lower(abstract, following).compile()
        self._jobs[sig] = (following, self._threads.submit(compile_))

    def grow(self, size: tuple, need: tuple, sig: tuple) -> tuple[tuple, float, bool]:
        """(new size, seconds waited for the compile ahead, whether it was used) for a step at
        `size` that needs `need` = (pairs, walked): the prepared size if it holds them and fits
        the shapes `sig` (waiting for its compile if unfinished), else `Sizes.grown` (compiled
        by the next `run`; also when the compile ahead failed, which `failure` then says, else
        None)."""
        job, self.failure = self._jobs.pop(sig, None), None
        self._ready.pop(sig, None)
        if job is not None and self._sizes.holds(job[0], need):
            t0 = time.perf_counter()
            try:
                executable = job[1].result()  # None from a child: the jitted step loads it
                if executable is not None:
                    self._ready[sig] = (job[0], executable)
                return job[0], time.perf_counter() - t0, True
            except Exception as e:  # noqa: BLE001 - any failure: the jitted step compiles instead
                self.failure = _reason(e)
        return self._sizes.grown(size, need), 0.0, False

    def close(self) -> None:
        """Forget the executables; a compile under way finishes in the background unwaited."""
        self._jobs, self._ready, self._latest = {}, {}, []
        if self._threads is not None:
            self._threads.shutdown(wait=False, cancel_futures=True)


def _reason(e: Exception) -> str:
    """One line on why a compile ahead failed (a child's last line of stderr)."""
    lines = (getattr(e, "stderr", None) or b"").decode(errors="replace").strip().splitlines()
    return lines[-1] if lines else f"{type(e).__name__}: {e}"


def _compile_in_child(lower: Callable, abstract, size: tuple) -> None:
    """Compile `lower(abstract, size)` in a child process (`ahead_child`) into the persistent
    compilation cache, with this process's `SHARED_CONFIG`; raises if the child fails."""
    config = {name: jax.config.values[name] for name in SHARED_CONFIG
              if name in jax.config.values}
    env = dict(os.environ, XLA_PYTHON_CLIENT_PREALLOCATE="false")  # this process holds the GPU
    subprocess.run([sys.executable, "-m", "lgs_jax.train.ahead_child"], env=env, check=True,
                   input=pickle.dumps(config) + pickle.dumps((lower, abstract, size)),
                   capture_output=True)
