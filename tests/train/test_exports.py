"""`train.exports`: a program lowered through an export entry is traced once across runs (the
entry written by the first lowering, read by the next), computes the same bits as the function
lowered directly, keeps its donation, and is keyed by its static arguments and shapes; a program
that cannot be exported is lowered directly, with a warning; a process compiles a program
once."""

import functools
import os

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from lgs_jax.train import exports
from lgs_jax.train.pool import Pool

TRACES = []


@functools.partial(jax.jit, static_argnames=("scale",), donate_argnums=(0,),
                   compiler_options={"xla_gpu_autotune_level": 0})
def _update(pool: Pool, extra, step, *, scale: float):
    TRACES.append(scale)  # runs once per trace
    means = pool.params["means"] * scale + jnp.sin(step.astype(jnp.float32))
    return Pool(dict(pool.params, means=means), pool.active), {"sum": jnp.sum(means),
                                                                "none": None}


def _args(n=5):
    pool = Pool({"means": jnp.arange(3.0 * n, dtype=jnp.float32).reshape(n, 3)},
                jnp.arange(n) % 2 == 0)
    return pool, None, jnp.int32(3)


def _lowering(tmp_path):
    return exports.Lowering(str(tmp_path), donate=(0,),
                            compiler_options={"xla_gpu_autotune_level": 0})


def _abstract(args):
    return jax.tree.map(lambda x: jax.ShapeDtypeStruct(x.shape, x.dtype), args)


def test_an_entry_is_traced_once_and_computes_the_direct_bits(tmp_path):
    want = _update(*_args(), scale=1.5)
    TRACES.clear()
    first = _lowering(tmp_path)(_update, _abstract(_args()), dict(scale=1.5)).compile()
    assert TRACES == [1.5] and len(os.listdir(tmp_path)) == 1  # traced, the entry written
    again = _lowering(tmp_path)(_update, _abstract(_args()), dict(scale=1.5)).compile()
    assert TRACES == [1.5]  # read, not traced
    for executable in (first, again):
        args = _args()
        got = executable(*args)
        assert args[0].params["means"].is_deleted()  # donated, as `_update` donates it
        assert jax.tree.structure(got) == jax.tree.structure(want)
        for a, b in zip(jax.tree.leaves(got), jax.tree.leaves(want)):
            np.testing.assert_array_equal(a, b)


def test_entries_are_keyed_by_static_arguments_and_shapes(tmp_path):
    lower = _lowering(tmp_path)
    for scale, n in ((1.5, 5), (2.0, 5), (1.5, 6)):
        lower(_update, _abstract(_args(n)), dict(scale=scale)).compile()
    assert len(os.listdir(tmp_path)) == 3
    assert lower.failure is None
    base = exports.key("f", _abstract(_args()), dict(scale=1.5))
    assert base != exports.key("g", _abstract(_args()), dict(scale=1.5))
    assert base != exports.key("f", _abstract(_args()), dict(scale=2.0))


def test_a_program_that_cannot_be_exported_is_lowered_directly_with_a_warning(tmp_path):
    @jax.jit
    def host(x):  # a host callback: not exportable
        return jax.pure_callback(lambda v: np.asarray(v) + 1, jax.ShapeDtypeStruct((), x.dtype),
                                 x)

    lower = exports.Lowering(str(tmp_path))
    with pytest.warns(UserWarning, match="export entry was not used"):
        executable = lower(host, (jax.ShapeDtypeStruct((), jnp.float32),), {}).compile()
    assert lower.failure and float(executable(jnp.float32(2))) == 3.0


def test_a_process_compiles_a_program_once(tmp_path):
    """A process's later runs take the executable it compiled (as jit's own cache would)."""
    first = _lowering(tmp_path).compiled(_update, _abstract(_args()), dict(scale=3.0))
    assert _lowering(tmp_path).compiled(_update, _abstract(_args()), dict(scale=3.0)) is first


def test_no_directory_lowers_directly():
    lowered = exports.Lowering(None)(_update, _abstract(_args()), dict(scale=1.0))
    assert lowered.compile()(*_args())[1]["sum"] == _update(*_args(), scale=1.0)[1]["sum"]
