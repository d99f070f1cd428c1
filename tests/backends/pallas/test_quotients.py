"""lgs_jax.backends.pallas.quotients: the backward's quotients by 1 − α on the GPU are the
kernel's division to the bit (GPU only: inline Mosaic GPU code does not run in interpret
mode; test_mosaic_forward's lowering test builds it on the CPU)."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax import lax
from jax.experimental import pallas as pl
from jax.experimental.pallas import mosaic_gpu as plgpu

from lgs_jax.backends.pallas import quotients as mosaic_quotients
from tests.devices import gpu_only

GPU_ONLY = gpu_only("inline Mosaic GPU code runs on a GPU only")


def _kernel(y_ref, x_ref, divided_ref, quotients_ref, *, pixels: int):
    b = lax.axis_index("b")
    cols = pl.ds(0, pixels)
    y, xs = y_ref[b, cols], (x_ref[0, b, cols], x_ref[1, b, cols])
    for i, (d, q) in enumerate(zip((x / y for x in xs), mosaic_quotients.quotients(y, xs))):
        divided_ref[i, b, cols] = d
        quotients_ref[i, b, cols] = q


def _quotients_kernel(pixels: int, blocks: int):
    out = jax.ShapeDtypeStruct((2, blocks, pixels), jnp.float32)
    return plgpu.kernel(functools.partial(_kernel, pixels=pixels), out_type=(out, out),
                        grid=(blocks,), grid_names=("b",), kernel_name="quotients_test")


@pytest.mark.parametrize("pixels", [128, 256])
def test_quotients_lower_for_the_gpu(pixels):
    """The inline code builds for both block sizes' layouts (one or two pixels per lane)."""
    y = jax.ShapeDtypeStruct((4, pixels), jnp.float32)
    x = jax.ShapeDtypeStruct((2, 4, pixels), jnp.float32)
    text = jax.jit(_quotients_kernel(pixels, 4)).trace(y, x).lower(
        lowering_platforms=("cuda",)).as_text()
    assert "mosaic_gpu" in text


@GPU_ONLY
@pytest.mark.parametrize("pixels", [128, 256])
def test_quotients_are_the_kernels_division_to_the_bit(pixels):
    """x / (1 − α) by `quotients` (rcp.approx.ftz and mul.rn) against `/` (PTX div.full) in one
    Mosaic GPU kernel, for α over [0, 0.999] (a miss's 0, the cap, 1/255 and uniform draws)
    and numerators from 1e-30 to 1e30 of both signs: the same bits; and both within 2 ulp of
    the exact quotient."""
    rng = np.random.default_rng(0)
    blocks = 64
    alpha = rng.uniform(0, 0.999, (blocks, pixels)).astype(np.float32)
    alpha[:, :8], alpha[:, 8:16], alpha[:, 16:24] = 0, 0.999, 1 / 255
    y = np.float32(1) - alpha
    x = (rng.standard_normal((2, blocks, pixels))
         * 10.0 ** rng.uniform(-30, 30, (2, blocks, pixels))).astype(np.float32)
    divided, quotients = _quotients_kernel(pixels, blocks)(jnp.asarray(y), jnp.asarray(x))
    divided, quotients = np.asarray(divided), np.asarray(quotients)
    np.testing.assert_array_equal(quotients.view(np.uint32), divided.view(np.uint32))
    exact = x.astype(np.float64) / y.astype(np.float64)
    assert np.all(np.abs(quotients - exact) <= 2 * np.spacing(np.abs(exact).astype(np.float32)))
