"""The training step compiled for the next pair capacity before a step needs it.

A step whose views need more tile–Gaussian pairs than the capacity grows it (`loop._one_step`),
and the step is compiled again for the new capacity: about 20 s on an H200, eight times in a
7k-step skull run (175 s of its 263 s; BENCHMARKS.md §5). Pairs grow gradually (densification),
so the next capacity is predictable: the smallest one a growth can pick, `pair_capacity(capacity
+ 1, headroom)`. `Stepper` compiles the step for it in a background thread while training goes
on (XLA compiles outside Python's global lock, and the main thread mostly waits on the device),
and at the growth uses that executable if it holds the pairs and was compiled for the same
argument shapes (a pool that grew since needs its own compile, as before), for every step at
that capacity. It is the program `jax.jit` compiles for that capacity, and compiling it does
not depend on timing (the step has no matrix product or convolution for XLA to autotune): the
same bits (tests/train: a run with and one without, bit for bit).
"""

from __future__ import annotations

import concurrent.futures
import time
from typing import Callable

import jax

from ..render import pair_capacity


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


class Stepper:
    """Runs the step at a capacity (`run`), compiles the next capacity's step ahead
    (`prepare`), and picks the capacity of a growth (`grow`).

    `step(args, capacity)` is the jitted step; `lower(args, capacity)` its `jax.stages.Lowered`
    (args may be `jax.ShapeDtypeStruct`s). With `ahead=False` it only runs the jitted step and
    grows to `pair_capacity(pairs, headroom)`, as before.
    """

    def __init__(self, step: Callable, lower: Callable, headroom: float, ahead: bool = True):
        self._step, self._lower, self._headroom = step, lower, headroom
        self._threads = concurrent.futures.ThreadPoolExecutor(1) if ahead else None
        self._job = None  # (capacity, signature, future) of the background compile
        self._ready = None  # (capacity, signature, executable) taken from a finished job

    def run(self, args, capacity: int, sig: tuple):
        """One step at `capacity`; `sig` = signature(args)."""
        if self._ready is not None and self._ready[:2] == (capacity, sig):
            return self._ready[2](*args)
        return self._step(args, capacity)

    def prepare(self, args, capacity: int, sig: tuple) -> None:
        """Start compiling the step for the capacity after `capacity` (module docstring), unless
        it is under way or done for these shapes."""
        if self._threads is None:
            return
        following = pair_capacity(capacity + 1, self._headroom)
        if self._job is not None:
            if self._job[:2] == (following, sig):
                return
            self._job[2].cancel()  # not started yet (else it finishes, unused)
        abstract = _abstract(args)
        self._job = (following, sig, self._threads.submit(
            lambda: self._lower(abstract, following).compile()))

    def grow(self, pairs: int, sig: tuple) -> tuple[int, float, bool]:
        """(new capacity, seconds waited for the compile ahead, whether it was used) for a
        step that needs `pairs` pairs: the prepared capacity if it holds them and fits the
        shapes `sig` (waiting for its compile if unfinished), else `pair_capacity(pairs,
        headroom)` (compiled by the next `run`; also when the compile ahead failed)."""
        job, self._job = self._job, None
        if job is not None and job[0] >= pairs and job[1] == sig:
            t0 = time.perf_counter()
            try:
                self._ready = (job[0], sig, job[2].result())
                return job[0], time.perf_counter() - t0, True
            except Exception:  # noqa: BLE001 - any failure: the jitted step compiles instead
                pass
        return pair_capacity(pairs, self._headroom), 0.0, False

    def close(self) -> None:
        """Forget the executables; a compile under way finishes in the background unwaited."""
        self._job = self._ready = None
        if self._threads is not None:
            self._threads.shutdown(wait=False, cancel_futures=True)
