"""lgs_jax.backends.pallas_emit: the emission's slots filled by a Pallas Triton kernel, one lane
per Gaussian (`KernelConfig.emit_kernel`), against XLA's per-slot search
(`binning.expand_slots`): the same arrays, bit for bit, on the suite's adversarial scenes (huge
Gaussians spanning every tile, invalid ones, Gaussians past the pair capacity)."""

import functools

import jax
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import lgs_jax
from lgs_jax import binning
from lgs_jax.backends import pallas_emit
from lgs_jax.projection import project
from tests import scenes

K = lgs_jax.KernelConfig
KERNEL = functools.partial(pallas_emit.expand, interpret=True)


@settings(max_examples=5)
@given(seed=st.integers(0, 2**32 - 1), dtype=st.sampled_from([np.float32, np.float64]),
       capacity=st.sampled_from([scenes.CAPACITY, 37, 1]))
def test_kernel_emission_is_xlas(seed, dtype, capacity):
    """Every field of `emit_pairs` (tiles, Gaussians, padding past the total, the per-Gaussian
    first slot and count, the totals), at the suite's capacity and at capacities the pairs
    overflow (the farthest Gaussians' slots cut, or all but the first slot)."""
    g = scenes.cast(scenes.scene(seed), dtype)
    cam = scenes.camera(dtype=dtype)
    p = project(g, cam)
    want = binning.emit_pairs(p, cam.width, cam.height, capacity)
    got = binning.emit_pairs(p, cam.width, cam.height, capacity, KERNEL)
    for name in ("tile", "gauss", "total", "n_unbounded", "first", "count"):
        np.testing.assert_array_equal(getattr(got, name), getattr(want, name), err_msg=name)


def test_kernel_emission_spans_every_tile_and_programs():
    """Gaussians binned to whole images (huge ones) next to small ones and to no tile, more
    Gaussians than one program's lanes: each program walks its Gaussians' slot range, steps
    whose slots change owner part-way and a last step cut short (masked lanes)."""
    g = scenes.cast(scenes.scene(3, kinds=("huge_far", "normal", "tiny"), n=3 * 40), np.float32)
    cam = scenes.camera(width=80, height=48)
    p = project(g, cam)
    capacity = 4096
    want = binning.emit_pairs(p, cam.width, cam.height, capacity)
    assert int(want.count.max()) >= 10  # some Gaussian spans many tiles
    got = binning.emit_pairs(p, cam.width, cam.height, capacity, KERNEL)
    for name in ("tile", "gauss", "first", "count"):
        np.testing.assert_array_equal(getattr(got, name), getattr(want, name), err_msg=name)


def test_render_with_the_kernel_emission_is_the_default_render():
    g = scenes.cast(scenes.scene(5), np.float32)
    cam = scenes.camera()
    config = lgs_jax.RasterConfig(tuning=K(emit_kernel=True))
    want = lgs_jax.render(g, cam, backend="tiles", capacity=scenes.CAPACITY)
    got = lgs_jax.render(g, cam, backend="tiles", config=config, capacity=scenes.CAPACITY)
    for a, b in zip(jax.tree.leaves(got), jax.tree.leaves(want)):
        np.testing.assert_array_equal(a, b)
    assert pallas_emit.slot_expander(lgs_jax.RasterConfig()) is binning.expand_slots
    with pytest.raises(ValueError, match="tuning.emit_kernel"):
        K(emit_kernel=1)


def test_kernel_emission_lowers_for_the_gpu(monkeypatch):
    """The kernel lowers through Triton for the GPU (masked scattered stores, a loop to the
    program's longest count, the aliased padding buffers): not what the GPU may still reject."""
    from jax._src.pallas.triton import gpu_info

    monkeypatch.setattr(gpu_info, "get_gpu_info",
                        lambda: gpu_info.get_gpu_info_from_version(gpu_info.GpuVersion.H100))
    g = scenes.cast(scenes.scene(0), np.float32)
    cam = scenes.camera()
    config = lgs_jax.RasterConfig(tuning=K(emit_kernel=True, interpret=False))
    text = jax.jit(lambda g, c: lgs_jax.render(g, c, backend="tiles", config=config,
                                               capacity=scenes.CAPACITY).image).trace(
        g, cam).lower(lowering_platforms=("cuda",)).as_text()
    assert "emit_pairs" in text
