"""lgs_jax.backends.pallas.inline.any_equal, the blend loops' test as one `bar.red` over the
warpgroup: it builds for both block sizes' layouts (one or two pixels per lane) and, on a GPU,
is jnp.any(x == value) wherever the value sits (GPU only: inline Mosaic GPU code does not run in
interpret mode)."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax import lax
from jax.experimental import pallas as pl
from jax.experimental.pallas import mosaic_gpu as plgpu

from lgs_jax.backends.pallas import inline as mosaic_inline
from tests.devices import gpu_only

GPU_ONLY = gpu_only("inline Mosaic GPU code runs on a GPU only")
VALUE = np.iinfo(np.int32).max  # the stop pair of a pixel not done (kernel_steps.NOT_STOPPED)


def _kernel(x_ref, out_ref, *, lanes: int):
    b = lax.axis_index("b")
    cols = pl.ds(0, lanes)
    x = x_ref[b, cols]
    first = mosaic_inline.any_equal(x, VALUE)
    second = mosaic_inline.any_equal(x + 1, VALUE)  # the same barrier again, another answer
    out_ref[b, cols] = x * 0 + first * 2 + second


def _any_equal_kernel(lanes: int, blocks: int):
    out = jax.ShapeDtypeStruct((blocks, lanes), jnp.int32)
    return plgpu.kernel(functools.partial(_kernel, lanes=lanes), out_type=out, grid=(blocks,),
                        grid_names=("b",), kernel_name="any_equal_test")


@pytest.mark.parametrize("lanes", [128, 256])
def test_any_equal_lowers_for_the_gpu(lanes):
    x = jax.ShapeDtypeStruct((4, lanes), jnp.int32)
    text = jax.jit(_any_equal_kernel(lanes, 4)).trace(x).lower(
        lowering_platforms=("cuda",)).as_text()
    assert "mosaic_gpu" in text


@GPU_ONLY
@pytest.mark.parametrize("lanes", [128, 256])
def test_any_equal_is_any_lane_equal(lanes):
    """Block b's vector holds VALUE at no lane, one lane (each lane in turn: every warp, both
    elements of a thread), or several; VALUE − 1 elsewhere in some blocks (so x + 1 hits)."""
    rows = [np.zeros(lanes, np.int32)]
    for lane in range(lanes):
        row = np.zeros(lanes, np.int32)
        row[lane] = VALUE
        rows.append(row)
    rows.append(np.full(lanes, VALUE, np.int32))
    near = np.zeros(lanes, np.int32)
    near[lanes - 1] = VALUE - 1
    rows.append(near)
    x = np.stack(rows)
    out = np.asarray(_any_equal_kernel(lanes, len(rows))(jnp.asarray(x)))
    want = 2 * np.any(x == VALUE, axis=1) + np.any(x + 1 == VALUE, axis=1)
    np.testing.assert_array_equal(out, np.repeat(want[:, None], lanes, axis=1).astype(np.int32))
