"""Importing lgs_jax fixes JAX's tracing context before any program is traced: a function
jitted before the first Pallas call is not traced again after it (the first pallas_call would
import `jax.experimental.pallas.fuser` lazily, which adds to the context)."""

import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(
    os.path.abspath(__file__)))))

CHILD = """
import jax, jax.numpy as jnp
import lgs_jax  # noqa: F401
from jax.experimental import pallas as pl
traces = []

@jax.jit
def f(x):
    traces.append(1)
    return x * 2

f(jnp.ones(3))
def k(x_ref, o_ref):
    o_ref[...] = x_ref[...] + 1
pl.pallas_call(k, out_shape=jax.ShapeDtypeStruct((8,), jnp.float32), interpret=True)(
    jnp.ones(8))
f(jnp.ones(3))
print(len(traces))
"""


def test_a_program_traced_before_the_first_pallas_call_is_not_traced_again():
    env = dict(os.environ, JAX_PLATFORMS="cpu", PYTHONPATH=ROOT)
    out = subprocess.run([sys.executable, "-c", CHILD], capture_output=True, text=True,
                         env=env, cwd=ROOT, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.split()[-1] == "1"
