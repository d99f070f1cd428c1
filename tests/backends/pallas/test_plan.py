"""lgs_jax.backends.pallas.plan and KernelConfig: what runs for a configuration, and the
settings' validation."""

import dataclasses

import pytest

import lgs_jax
from lgs_jax.backends import pallas
from lgs_jax.backends.pallas import mosaic_forward

C = lgs_jax.RasterConfig
K = lgs_jax.KernelConfig


def test_plan_resolves_the_lowering():
    """kernel="auto" runs Mosaic GPU on the GPU and Triton in interpret mode, forward and
    backward alike; an explicit kernel runs everywhere."""
    gpu, interp = C(tuning=K(interpret=False)), C(tuning=K(interpret=True))
    assert [pallas.plan(gpu, v, 1).kernel_name for v in (False, True)] == [
        "localgs-mosaic", "vanilla-mosaic"]
    assert [pallas.plan(interp, v, 1).kernel_name for v in (False, True)] == [
        "localgs-triton", "vanilla-triton"]
    assert pallas.plan(dataclasses.replace(gpu, kernel="triton"), False, 1).kernel == "triton"
    assert pallas.plan(dataclasses.replace(interp, kernel="mosaic"), False, 1).kernel == "mosaic"
    assert pallas.plan(interp, False, 1).interpret and not pallas.plan(gpu, False, 1).interpret


def test_plan_resolves_block_sizes():
    """Mosaic GPU forward blocks: half tiles for the compacted Local-GS forward (exact blending
    with warp culling), else whole tiles from `whole_tile_from` tiles on and half tiles below,
    unless fixed; backward blocks whole tiles unless set to None (then by the same rule)."""
    gpu = C(tuning=K(interpret=False))
    full = C(warp_cull=False, tuning=K(interpret=False))  # not compacted
    for config, vanilla in ((full, False), (gpu, True)):
        assert [pallas.plan(config, vanilla, t).forward_pixels
                for t in (1, 8191, 8192, 32400)] == [128, 128, 256, 256]
    assert [pallas.plan(gpu, False, t).forward_pixels for t in (1, 32400)] == [128, 128]
    fixed = C(tuning=K(interpret=False, forward_pixels=256))
    assert pallas.plan(fixed, False, 1).forward_pixels == 128  # compacted: half tiles always
    assert pallas.plan(fixed, True, 1).forward_pixels == 256
    assert [pallas.plan(gpu, False, t).backward_pixels for t in (1, 8160, 32400)] == [256] * 3
    by_tiles = C(tuning=K(backward_pixels=None))
    assert [pallas.plan(by_tiles, False, t).backward_pixels for t in (8191, 8192)] == [128, 256]


def test_plan_resolves_output_layouts():
    """The colour as an image where the forward is the Local-GS Mosaic GPU kernel in blocks of
    128 pixels; block stops wherever the forward is the Local-GS Mosaic GPU kernel; planes and
    pixel stops for the vanilla and Triton kernels."""
    mosaic = C(kernel="mosaic")
    default = pallas.plan(mosaic, False, 10**5)
    assert default.image and default.block_stops
    vanilla = pallas.plan(mosaic, True, 10**5)
    assert not vanilla.image and not vanilla.block_stops
    whole = pallas.plan(C(kernel="mosaic", blend="fast"), False, 10**5)  # blocks of 256
    assert whole.forward_pixels == 256 and not whole.image and whole.block_stops
    triton = pallas.plan(C(kernel="triton"), False, 10**5)
    assert not triton.image and not triton.block_stops


def test_plan_resolves_the_backward_segment():
    """The split backward applies where the Local-GS Mosaic GPU forward stores its
    checkpoints; the vanilla and Triton kernels walk whole tiles."""
    assert pallas.plan(C(kernel="mosaic"), False, 1).segment == 1024
    assert pallas.plan(C(kernel="mosaic"), True, 1).segment is None
    assert pallas.plan(C(kernel="triton"), False, 1).segment is None
    none = C(kernel="mosaic", tuning=K(backward_segment=None))
    assert pallas.plan(none, False, 1).segment is None
    assert pallas.plan(C(kernel="mosaic"), True, 1).model.hoist is False


def test_compaction_applies_where_its_conditions_hold():
    """The Local-GS Mosaic GPU forward walks per-warp lists with exact blending, strip masks
    and the split backward's entries at chunk starts (segments of a multiple of 128 pairs, or
    whole walks), in either α form; elsewhere it walks every pair."""
    for on in (C(), C(hoist=False), C(tuning=K(backward_segment=None)),
               C(tuning=K(backward_segment=256))):
        assert mosaic_forward.compacts(on)
    for off in (C(blend="fast"), C(warp_cull=False), C(tuning=K(backward_segment=64))):
        assert not mosaic_forward.compacts(off)


@pytest.mark.parametrize("tuning,match", [
    (dict(unroll=0), "tuning.unroll"), (dict(unroll=6), "tuning.unroll: must divide"),
    (dict(forward_pixels=64), "tuning.forward_pixels"),
    (dict(backward_pixels=512), "tuning.backward_pixels"),
    (dict(whole_tile_from=-1), "tuning.whole_tile_from"),
    (dict(backward_segment=0), "tuning.backward_segment"),
    (dict(backward_segment=2.0), "tuning.backward_segment"),
    (dict(backward_segment=12), "tuning.backward_segment: 12 is not a multiple of unroll=8"),
    (dict(interpret="yes"), "tuning.interpret"),
])
def test_bad_kernel_settings_raise(tuning, match):
    with pytest.raises(ValueError, match=match):
        K(**tuning)


def test_kernel_config_keeps_only_tuning():
    """Six settings: the block shapes and schedule, and interpret mode."""
    assert [f.name for f in dataclasses.fields(K)] == [
        "unroll", "forward_pixels", "backward_pixels", "whole_tile_from", "backward_segment",
        "interpret"]
    with pytest.raises(ValueError, match="config.tuning"):
        C(tuning=dict(unroll=8))
