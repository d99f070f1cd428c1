"""`fit` over several processes (JAX's multi-controller model, `jax.distributed.initialize`):
every process makes the same `fit` call, Gaussian parallel over the mesh of all the processes'
devices, and together they train one model; process 0 alone touches the run folder.

- `writer()`: whether this process writes the run folder (checked and locked, the checkpoints,
  metrics.jsonl, scene.ply, result.json, every output file): process 0, or the one process.
  The others write nothing and do not even create the folder; what they read from the device
  they read as process 0 does (`parallel.to_host`: a read of an array split over the processes
  is a collective, made by every process in the same order).
- `problem(config, watch)`: `ValueError` naming the field of what is not built across
  processes.
- `claimed(config, data_path)`: the folder checked and locked by process 0
  (`rundir.claimed`), its verdict told to the others (`multihost_utils.broadcast_one_to_all`):
  a folder that process 0 refuses stops every process, and all of them start fresh or resume
  alike.
- `synced(name)`: every process waits here for the others (after process 0 has changed a file
  that all of them read next).
- `together(fn)`: fn() on every process, an error on one raised on all (a process that failed
  to read the checkpoint stops the others, which would wait for it at the next collective).

On several processes every decision of the loop (when to refine, evaluate, checkpoint, grow a
buffer, stop early) follows from values every process reads alike, so all of them run the
same programs in the same order. Resuming reads the checkpoint on every process: OUT must be
on a file system that every process sees.
"""

from __future__ import annotations

import contextlib
import os

import jax
import numpy as np
from jax.experimental import multihost_utils

from . import rundir

REFUSED, FRESH, RESUME = 0, 1, 2  # process 0's verdict on the folder (`claimed`)


def several() -> bool:
    """Whether the run spans several processes (`jax.process_count()` > 1)."""
    return jax.process_count() > 1


def writer() -> bool:
    """Whether this process writes the run folder: process 0 (module docstring)."""
    return jax.process_index() == 0


def problem(config, watch) -> None:
    """Raise `ValueError` naming the field that a run over several processes does not take: a
    mesh short of the processes' devices (`gaussian_devices` times `devices` must be
    `jax.device_count()`, Gaussian parallel: each process holds blocks of the pool), view rows
    (`devices` > 1), and a `watch` (its calls, timed on each process's clock, would change the
    order of the programs on one process only)."""
    if not several():
        return
    count, processes = jax.device_count(), jax.process_count()
    if config.devices != 1:
        raise ValueError(f"devices: not with {processes} processes (a mesh of view rows is not "
                         f"built across processes); got {config.devices}")
    if config.gaussian_devices != count:
        raise ValueError(f"gaussian_devices: {processes} processes train Gaussian parallel "
                         f"over all {count} devices; got {config.gaussian_devices}")
    if watch is not None:
        raise ValueError(f"watch: not with {processes} processes (the viewer and watch hooks "
                         "run on one process)")


@contextlib.contextmanager
def claimed(config, data_path: str):
    """The run folder checked and locked for the block (`rundir.claimed`) by the writer, and
    whether the run resumes (config.resume and a checkpoint there), the same on every process;
    a folder that process 0 refuses raises its error there and `RunDirError` ("out") on the
    others."""
    resume = lambda: config.resume and os.path.exists(os.path.join(config.out,
                                                                    "checkpoint.json"))
    if not several():
        with rundir.claimed(config, data_path):
            yield resume()
        return
    with contextlib.ExitStack() as stack:
        verdict = REFUSED
        try:
            if writer():
                stack.enter_context(rundir.claimed(config, data_path))
                verdict = RESUME if resume() else FRESH
        finally:  # told even where process 0 raises
            verdict = int(multihost_utils.broadcast_one_to_all(np.int32(verdict)))
        if verdict == REFUSED:
            raise rundir.RunDirError("out", f"process 0 refused the run folder {config.out} "
                                            "(its error says why)")
        yield verdict == RESUME


def synced(name: str) -> None:
    """Every process waits for the others here (`multihost_utils.sync_global_devices`); a
    no-op on one process."""
    if several():
        multihost_utils.sync_global_devices(name)


def together(fn):
    """fn() on every process; where it raises on some process, it raises there and every other
    process raises `RuntimeError` naming the processes that failed, rather than wait for them
    at a collective. On one process, fn()."""
    if not several():
        return fn()
    error, result = None, None
    try:
        result = fn()
    except Exception as e:  # told to the others, then raised
        error = e
    failed = np.flatnonzero(multihost_utils.process_allgather(np.int32(error is not None)))
    if error is not None:
        raise error
    if len(failed):
        raise RuntimeError(f"processes {failed.tolist()} failed (their errors say why)")
    return result
