"""lgs_jax.slot_fill: the emission's slot fill as a kernel gives `binning.expand_slots`' integers
(in interpret mode off GPUs), batched too, and lowers for the GPU inside `render`, whose images
it leaves unchanged."""

import dataclasses

import jax
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import lgs_jax
from lgs_jax import binning, slot_fill
from lgs_jax.config import KernelConfig, RasterConfig
from lgs_jax.projection import project
from tests import scenes
from tests.devices import ON_GPU

W, H = 96, 64


def _plan(g, cam, capacity):
    return binning.slot_plan(project(g, cam), W, H, capacity)[0]


def _fill(plan, lanes):
    return slot_fill.fill(plan.order, plan.start, plan.kept, plan.rect, plan.n_tiles,
                          plan.tiles_x, plan.capacity, interpret=not ON_GPU, lanes=lanes)


@pytest.mark.parametrize("capacity,lanes", [(4096, 32), (60, 64)])
@settings(max_examples=4)
@given(seed=st.integers(0, 2**32 - 1), yaw=st.floats(-0.3, 0.3))
def test_kernel_fills_the_slots_as_expand_slots(capacity, lanes, seed, yaw):
    """Adversarial scenes (huge and unbounded Gaussians binned to many tiles, invalid rows,
    depth ties), a capacity that holds every pair or drops the tail mid-run."""
    plan = jax.jit(_plan, static_argnums=2)(scenes.scene(seed), scenes.camera(W, H, yaw=yaw),
                                            capacity)
    assert (int(plan.total) > capacity) == (capacity == 60)
    want = binning.expand_slots(plan)
    got = _fill(plan, lanes)
    for x, y in zip(got, want):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


def test_batched_kernel_fills_each_view_as_alone():
    cams = [scenes.camera(W, H, yaw=y) for y in (-0.2, 0.25)]
    g = scenes.scene(3)
    plans = [_plan(g, c, 512) for c in cams]
    stacked = jax.tree.map(lambda *xs: np.stack(xs), *[tuple(p[:4]) for p in plans])
    tile, gauss = jax.vmap(lambda o, s, k, r: slot_fill.fill(
        o, s, k, r, plans[0].n_tiles, plans[0].tiles_x, 512, interpret=not ON_GPU))(*stacked)
    for i, plan in enumerate(plans):
        np.testing.assert_array_equal(tile[i], binning.expand_slots(plan)[0])
        np.testing.assert_array_equal(gauss[i], binning.expand_slots(plan)[1])


def test_render_with_the_kernel_fill_lowers_for_the_gpu_and_equals_xla_here(monkeypatch):
    from jax._src.pallas.triton import gpu_info

    monkeypatch.setattr(gpu_info, "get_gpu_info",
                        lambda: gpu_info.get_gpu_info_from_version(gpu_info.GpuVersion.H100))
    config = RasterConfig(tuning=KernelConfig(slot_fill="kernel"))
    g, cam = scenes.scene(1), scenes.camera(W, H)
    image = lambda g, c: lgs_jax.render(g, c, backend="tiles", config=config,
                                        capacity=scenes.CAPACITY).image
    text = jax.jit(image).trace(g, cam).lower(lowering_platforms=("cuda",)).as_text()
    assert "slot_fill" in text
    xla = dataclasses.replace(config, tuning=KernelConfig())
    np.testing.assert_array_equal(  # the same pairs (off GPUs the same path)
        image(g, cam), lgs_jax.render(g, cam, backend="tiles", config=xla,
                                      capacity=scenes.CAPACITY).image)


def test_lanes_must_fill_warps():
    plan = _plan(scenes.scene(0), scenes.camera(W, H), 64)
    with pytest.raises(ValueError, match="lanes: expected a multiple of 32"):
        _fill(plan, 48)
