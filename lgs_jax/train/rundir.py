"""Run directories: one run per folder, checked before any work, held by one process at a time.

A run directory holds one run: a new or empty one takes any run; one holding files needs
resume (and a checkpoint) or overwrite (the old run's files are deleted first), so two runs
never mix (`run_dir_problem`). A resumed run must be the saved one continued: the same data,
at least as many steps as were done, the same recipe, strategy and seed (`resume_problem`).
While `fit` runs it holds an exclusive lock on OUT/fit.lock (`Lock`, `fcntl.flock`; the file
holds the holder's process id): a second run on the same folder is refused at once.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import re
import tempfile

from . import checkpoint

LOCK = "fit.lock"
RUN_FILES = ("scene.ply", "checkpoint.npz", "checkpoint.json", "metrics.jsonl", "result.json",
             "curves.png", "cameras.json", "colors.json", "bilateral_grids.npz",
             "appearance.npz", "optimizer.npz")  # optimizer.npz: runs of the fixed-count trainer


class RunDirError(ValueError):
    """A run directory that cannot take this run (`field`: the configuration field to change:
    out, data, steps, ...)."""

    def __init__(self, field: str, message: str):
        super().__init__(f"{field}: {message}")
        self.field, self.message = field, message


def run_files(out: str) -> list[str]:
    """The files a run wrote into `out`: RUN_FILES and the held-out renders."""
    partial = r"\..+\.partial(\..+)?"  # `lgs_jax.files.written`'s temporary, left by a kill
    return [n for n in os.listdir(out) if n in RUN_FILES or re.fullmatch(r"heldout_.+\.png", n)
            or re.fullmatch(partial, n)]


def _contents(out: str) -> list[str]:
    return sorted(n for n in os.listdir(out) if n != LOCK)


def run_dir_problem(out: str, resume: bool = False, overwrite: bool = False) -> str | None:
    """Why the run directory `out` cannot take this run, or None if it can (module docstring).
    """
    if resume and overwrite:
        return "resume and overwrite exclude each other"
    if os.path.exists(out) and not os.path.isdir(out):
        return f"{out} exists and is not a directory"
    if not os.path.isdir(out) or not _contents(out) or overwrite:
        return None
    if resume:
        if os.path.exists(os.path.join(out, "checkpoint.json")):
            return None
        return f"{out} holds files but no checkpoint.json to resume from"
    return (f"{out} is not empty (it holds {', '.join(_contents(out)[:3])}, ...); pass --resume "
            "(resume=True) to continue its run or --overwrite (overwrite=True) to replace it")


def writable_problem(out: str) -> str | None:
    """Why folder `out` (made if missing) cannot take files, or None: a file is written and
    removed there (permission bits alone do not tell, e.g. for root under /proc)."""
    try:
        os.makedirs(out, exist_ok=True)
        with tempfile.TemporaryFile(dir=out):
            pass
    except OSError as e:
        return f"{out}: cannot write there ({e.strerror or e})"
    return None


def resume_problem(config, data_path: str) -> RunDirError | None:
    """Why `config` (resume) cannot continue the run in config.out, or None: its checkpoint
    unreadable (`checkpoint.CheckpointError`), other data (`data_path`, the dataset's folder),
    fewer steps than it did, another recipe, strategy or seed."""
    out = config.out
    if not (config.resume and os.path.exists(os.path.join(out, "checkpoint.json"))):
        return None
    meta = checkpoint.read_meta(out)
    saved = meta.get("data")
    current = checkpoint.data_of(config, data_path)
    if saved is not None and saved != current:
        return RunDirError("data", f"{out} trained on {checkpoint.describe(saved)}, not on "
                                   f"{checkpoint.describe(current)}; resume with the same data "
                                   f"or start a new run")
    if meta["step"] > config.steps:
        return RunDirError("steps", f"{config.steps} is fewer than the {meta['step']} steps "
                                    f"{out} has done (resume continues a run to --steps)")
    mismatch = checkpoint.config_mismatch(meta["config"], checkpoint.config_of(config),
                                          checkpoint.default_config(config))
    if mismatch:
        return RunDirError("resume", mismatch)
    return None


class Lock:
    """An exclusive lock on OUT/fit.lock for as long as the `with` block runs (module
    docstring); `RunDirError` when another process holds it. The file is removed on release."""

    def __init__(self, out: str):
        self.path, self.file = os.path.join(out, LOCK), None

    def __enter__(self):
        while True:
            f = open(self.path, "a+")
            try:
                fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                f.seek(0)
                holder = f.read().strip() or "another process"
                f.close()
                raise RunDirError("out", f"{os.path.dirname(self.path) or '.'} is in use by "
                                         f"another fit (process {holder}); wait for it or use "
                                         f"another --out") from None
            try:  # the holder before may have removed the file after we opened it
                same = os.path.samestat(os.fstat(f.fileno()), os.stat(self.path))
            except FileNotFoundError:
                same = False
            if same:
                break
            f.close()
        f.seek(0)
        f.truncate()
        f.write(str(os.getpid()))
        f.flush()
        self.file = f
        return self

    def __exit__(self, *exc):
        with contextlib.suppress(FileNotFoundError):
            os.remove(self.path)
        self.file.close()  # releases the lock


def check_out(config, data_path: str) -> None:
    """Raise `RunDirError` where config.out cannot take this run: a folder holding
    another run, one that cannot be written, or (resume) a checkpoint that does not continue
    with this configuration and `data_path` (`resume_problem`); a checkpoint that
    cannot be read raises `checkpoint.CheckpointError`. Nothing is written but the folder
    itself."""
    _check_folder(config)
    wrong = resume_problem(config, data_path)
    if wrong:
        raise wrong


def _check_folder(config) -> None:
    """Raise `RunDirError` where config.out holds another run or cannot be written."""
    problem = run_dir_problem(config.out, config.resume, config.overwrite)
    if problem is None:
        problem = writable_problem(config.out)
    if problem:
        raise RunDirError("out", problem)


@contextlib.contextmanager
def claimed(config, data_path: str):
    """config.out locked (`Lock`) for the block, and checked (`check_out`) under the
    lock (another run may fill it until then)."""
    _check_folder(config)
    with Lock(config.out):
        check_out(config, data_path)
        yield
