"""Traced programs kept across runs: each training step's `jax.export` artefact beside JAX's
persistent compilation cache, so that a later run loads the lowered program instead of tracing
it again.

JAX's persistent cache (`jax_compilation_cache_dir`) saves XLA's compile, not the trace and
lowering that come before its lookup; for the training step those are seconds per program
(several programs a run: one per image size and pair capacity). `Lowering` turns (fn, abstract
arguments, static keyword arguments) into a `jax.stages.Lowered`: without a directory,
`fn.lower(...)`; with one, the serialized `jax.export.Exported` of that program, found by its
`key` (the library's source, JAX's version, the platform and device kind, the configuration
flags that change a trace, the static arguments, and the arguments' tree and abstract values),
or on a miss exported and written, then lowered as `jax.jit(exported.call)` with `fn`'s
donation and compiler options. The run that writes an entry and the runs that read it compile
the same module (its executable then comes from the persistent cache): the same bits. A
program that cannot be exported or loaded is lowered directly, and `failure` says why.
"""

from __future__ import annotations

import collections
import functools
import hashlib
import os
import pickle
import tempfile
import threading
import warnings

import jax
import jaxlib

# Pallas' Triton kernels (the fused SSIM on a GPU): a custom call whose IR JAX does not promise
# to keep stable across versions, which is why export checks for it; the key holds JAX's
# version, so an entry is only read by the JAX that wrote it.
UNCHECKED = ("__gpu$xla.gpu.triton",)
FLAGS = ("jax_enable_x64", "jax_default_matmul_precision", "jax_default_prng_impl",
         "jax_threefry_partitionable", "jax_numpy_rank_promotion")
"""JAX settings that change what a trace produces (part of the key)."""


@functools.cache
def source_digest() -> str:
    """SHA-256 of the package's Python source (every module a trace may run)."""
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    h = hashlib.sha256()
    for folder, dirs, files in sorted(os.walk(root)):
        dirs.sort()
        for name in sorted(f for f in files if f.endswith(".py")):
            path = os.path.join(folder, name)
            h.update(os.path.relpath(path, root).encode() + b"\0")
            with open(path, "rb") as f:
                h.update(f.read() + b"\0")
    return h.hexdigest()


def key(name: str, abstract, static: dict) -> str:
    """The entry of program `name` (the function's module and name) for arguments shaped as
    `abstract` (`jax.ShapeDtypeStruct`s) and the static keyword arguments `static` (their
    reprs: frozen dataclasses and numbers)."""
    leaves, tree = jax.tree.flatten(abstract)
    device = jax.devices()[0]
    parts = [name, source_digest(), jax.__version__, jaxlib.__version__, device.platform,
             device.device_kind, repr([(f, getattr(jax.config, f)) for f in FLAGS]),
             repr(sorted(static.items())), repr(tree),
             repr([(x.shape, str(x.dtype), x.weak_type) for x in leaves])]
    return hashlib.sha256("\n".join(parts).encode()).hexdigest()


class Lowering:
    """Lowers `fn` for abstract arguments and static keyword arguments (module docstring):
    through the export entries in `directory`, or directly where `directory` is None.
    `donate` (positional indices) and `compiler_options` must be `fn`'s own (its `jax.jit`'s),
    so that the loaded program updates its state in place as `fn` does. `compiled` compiles
    a program once per process (as `jax.jit`'s own cache would: a process's later runs reuse
    it). `failure`: why the last lowering did not go through an entry (None: it did, or there
    is no directory)."""

    def __init__(self, directory: str | None, donate: tuple = (),
                 compiler_options: dict | None = None):
        self.directory, self.donate, self.compiler_options = directory, donate, compiler_options
        self.failure = None

    def __call__(self, fn, abstract, static: dict):
        if self.directory is None:
            return fn.lower(*abstract, **static)
        return self._lowered(fn, abstract, static, key(_name(fn), abstract, static))

    def _lowered(self, fn, abstract, static: dict, entry: str):
        """`self(...)` with a directory, for the program whose key is `entry`."""
        try:
            exported, out_tree = self._exported(fn, abstract, static, entry)

            def call(*args):
                return jax.tree.unflatten(out_tree, exported.call(*jax.tree.leaves(args)))

            lowered = jax.jit(call, donate_argnums=self.donate,
                              compiler_options=self.compiler_options).lower(*abstract)
        except Exception as e:  # noqa: BLE001 - any failure: the program is lowered directly
            self.failure = f"{type(e).__name__}: {(str(e).splitlines() or [''])[0]}"
            if self.failure not in _warned:
                _warned.add(self.failure)
                warnings.warn(f"lgs_jax: a program's export entry was not used, so it is "
                              f"traced at every run ({self.failure})", stacklevel=2)
            return fn.lower(*abstract, **static)
        self.failure = None
        return lowered

    def _memo(self, entry: str) -> tuple:
        """The key of program `entry`'s executable in this process (`_executables`): the
        entry, and how this lowering loads and compiles it."""
        return entry, self.directory, self.donate, repr(self.compiler_options)

    def holds(self, fn, abstract, static: dict) -> bool:
        """Whether the program is kept: compiled by this process (`compiled`) or its entry in
        the directory (another run's export, whose executable the persistent cache then
        holds too): taking it costs a load, not a trace and compile."""
        entry = key(_name(fn), abstract, static)
        with _lock:
            if self._memo(entry) in _executables:
                return True
        return self.directory is not None and os.path.exists(
            os.path.join(self.directory, entry + ".export"))

    def compiled(self, fn, abstract, static: dict):
        """`self(fn, abstract, static).compile()`, or the executable this process compiled
        for the same program before (the `KEPT` latest kept)."""
        entry = key(_name(fn), abstract, static)
        memo = self._memo(entry)
        with _lock:
            if memo in _executables:
                _executables.move_to_end(memo)
                return _executables[memo]
        lowered = (fn.lower(*abstract, **static) if self.directory is None
                   else self._lowered(fn, abstract, static, entry))
        executable = lowered.compile()
        with _lock:
            _executables[memo] = executable
            while len(_executables) > KEPT:
                _executables.popitem(last=False)
        return executable

    def _exported(self, fn, abstract, static: dict, entry: str):
        """(`Exported` of `fn` on the arguments' leaves, the tree of its outputs): read from
        the entry, or exported and written (atomically: a concurrent run reads a whole entry
        or none). The program is exported over flat leaves, so that the entry holds no
        pytree types (their tree is pickled beside it)."""
        path = os.path.join(self.directory, entry + ".export")
        if os.path.exists(path):
            with open(path, "rb") as f:
                out_tree, blob = pickle.load(f)
            return jax.export.deserialize(bytearray(blob)), out_tree
        leaves, in_tree = jax.tree.flatten(abstract)
        trees, inner = [], getattr(fn, "__wrapped__", fn)  # a jitted fn's own function: its
        # compiler options are for a top-level jit only (the call's jit carries them)

        def flat(*leaves):
            out = inner(*jax.tree.unflatten(in_tree, leaves), **static)
            trees.append(jax.tree.structure(out))
            return jax.tree.leaves(out)

        checks = [jax.export.DisabledSafetyCheck.custom_call(t) for t in UNCHECKED]
        exported = jax.export.export(jax.jit(flat), disabled_checks=checks)(*leaves)
        os.makedirs(self.directory, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=self.directory, suffix=".tmp")
        try:
            with os.fdopen(fd, "wb") as f:
                pickle.dump((trees[0], bytes(exported.serialize())), f)
            os.replace(tmp, path)
        finally:
            if os.path.exists(tmp):
                os.remove(tmp)
        return exported, trees[0]


_warned: set = set()  # the failures warned of in this process
KEPT = 16  # executables `Lowering.compiled` keeps in a process
_executables: collections.OrderedDict = collections.OrderedDict()
_lock = threading.Lock()


def _name(fn) -> str:
    """`fn`'s module and name (part of its programs' keys)."""
    return f"{getattr(fn, '__module__', '')}.{getattr(fn, '__qualname__', repr(fn))}"


def directory() -> str | None:
    """Where the entries live: `lgs_jax_exports/` in JAX's persistent compilation cache
    directory, or None where no persistent cache is set (nothing kept across runs then)."""
    cache = jax.config.jax_compilation_cache_dir
    return os.path.join(cache, "lgs_jax_exports") if cache else None
