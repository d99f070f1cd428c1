"""The Mosaic GPU kernels' per-Gaussian table (`pairs.gaussian_table`) written by a Pallas
Triton kernel (`gaussian_table`), beside its plain-jnp reference (`reference`).

XLA writes the table, a concatenate along the minor axis, one column at a time: a warp's 32
stores of a column land a row apart, one memory sector each. Here each program reads `lanes`
Gaussians' fields as (N,) columns (`pairs.table_columns`) and stores their rows as one
(lanes, 16) block masked to the TABLE_COLUMNS (12), whose consecutive lanes write consecutive
bytes. Every value is a copy: the table equals `reference`'s bit for bit.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
from jax import lax
from jax.experimental import pallas as pl
from jax.experimental.pallas import triton as plt

from ... import pairs
from ...projection import Projected

LANES = 256  # Gaussians per program (eight warps)
WIDTH = 16  # the stored block's columns: TABLE_COLUMNS rounded up to a power of two


def _kernel(*refs, n: int, lanes: int):
    *column_refs, table_ref = refs
    # Lanes past the last Gaussian copy it again (the same bits to the same row).
    g = jnp.minimum(pl.program_id(0) * lanes + lax.iota(jnp.int32, lanes), n - 1)
    cols = [ref[g] for ref in column_refs]
    c = lax.broadcasted_iota(jnp.int32, (lanes, WIDTH), 1)
    block = jnp.zeros((lanes, WIDTH), table_ref.dtype)
    for i, col in enumerate(cols):
        block = jnp.where(c == i, col[:, None], block)
    plt.store(table_ref.at[g[:, None], c], block, mask=c < pairs.TABLE_COLUMNS)


def reference(p: Projected):
    """The table in jnp: `pairs.gaussian_table(p)`, (N, TABLE_COLUMNS)."""
    return pairs.gaussian_table(p)


def gaussian_table(p: Projected, interpret: bool = False, lanes: int = LANES):
    """`reference(p)` by the kernel (`interpret`: Pallas' interpreter; `lanes`: a multiple of
    32)."""
    if lanes % 32:
        raise ValueError(f"lanes: expected a multiple of 32, got {lanes}")
    columns = pairs.table_columns(p)
    n, dt = p.mean2d.shape[0], p.mean2d.dtype
    return pl.pallas_call(
        functools.partial(_kernel, n=n, lanes=lanes),
        out_shape=jax.ShapeDtypeStruct((n, pairs.TABLE_COLUMNS), dt),
        grid=(pl.cdiv(n, lanes),), interpret=interpret,
        compiler_params=plt.CompilerParams(num_warps=lanes // 32, num_stages=1),
        name="gaussian_table",
    )(*columns)
