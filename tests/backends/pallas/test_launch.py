"""Launch geometry: every Pallas kernel's grid holds up to the library's pair limit (2^31 − 1
pairs, `binning.MAX_PAIRS`) and images to 16384 x 16384, within CUDA's limits (gridDim.x up to
2^31 − 1, y and z up to 65535). Mosaic GPU puts a Pallas grid's first axis on y, so the long
axis (tiles, segments) folds onto z beyond 65535 blocks (`mosaic_forward.grid`); a folded grid
renders and differentiates as an unfolded one (checked in interpret mode with a tiny limit).
The GPU run past 2^25 pairs, where an unfolded backward grid failed to launch, is in the GPU
test set."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lgs_jax
from lgs_jax import binning
from lgs_jax.backends.pallas import gaussian_grads, mosaic_forward, table
from lgs_jax.layout import TILE_PIXELS, tile_grid
from tests import scenes
from tests.devices import ON_GPU, gpu_only

C = lgs_jax.RasterConfig
K = lgs_jax.KernelConfig
CUDA_X, CUDA_YZ = 2**31 - 1, 65535
SIZES = [(16, 16), (3840, 2160), (7680, 4320), (16384, 16384)]


def _fits(launch):
    """Whether a Mosaic GPU grid fits CUDA: Pallas (a, b[, c]) is CUDA (x, y[, z]) reversed."""
    cuda = tuple(reversed(launch))
    return cuda[0] <= CUDA_X and all(d <= CUDA_YZ for d in cuda[1:])


@pytest.mark.parametrize("width,height", SIZES)
@pytest.mark.parametrize("pixels", [128, 256])
def test_mosaic_grids_fit_cuda_up_to_the_pair_limit(width, height, pixels):
    """The forward's (tiles x blocks per tile) and the backward's (tiles + capacity / segment
    segments x blocks) grids, at every block size and segment length, for pair capacities up
    to 2^31 − 1."""
    tiles_x, tiles_y = tile_grid(width, height)
    n_tiles = tiles_x * tiles_y
    launch, _, _ = mosaic_forward.grid(n_tiles, TILE_PIXELS // pixels)
    assert _fits(launch), (n_tiles, launch)
    for capacity in (2**16, 2**25 + 2**24, binning.MAX_PAIRS):
        for segment in (128, 1024):
            segments = n_tiles + capacity // segment
            launch, _, rows = mosaic_forward.grid(segments, TILE_PIXELS // pixels)
            assert _fits(launch), (segments, launch)
            covered = launch[0] if rows is None else launch[0] * launch[1]
            assert covered >= segments


def test_triton_grids_fit_cuda():
    """The Triton kernels' one-dimensional grids (x): the Gaussian table and the per-Gaussian
    sums for up to 2^31 − 1 Gaussians, the Local-GS forward's strips and the backward's tiles
    for a 16384 x 16384 image."""
    n = 2**31 - 1
    assert -(-n // table.LANES) <= CUDA_X and -(-n // gaussian_grads.LANES) <= CUDA_X
    tiles_x, tiles_y = tile_grid(16384, 16384)
    assert tiles_x * tiles_y * 8 <= CUDA_X


def test_grid_folds_only_past_the_limit_and_refuses_beyond_cuda():
    assert mosaic_forward.grid(65535, 2) == ((65535, 2), ("tile", "wg"), None)
    launch, names, rows = mosaic_forward.grid(65536, 1)
    assert launch == (2, 65535, 1) and names == ("hi", "tile", "wg") and rows == 65535
    with pytest.raises(ValueError, match="exceed CUDA's grid"):
        mosaic_forward.grid(65535**2 + 1, 1)


@pytest.mark.skipif(ON_GPU, reason="interpret mode: the folded launch itself runs on the GPU "
                                   "in test_gradients_past_2_to_the_25_pairs")
def test_a_folded_grid_renders_and_differentiates_as_an_unfolded_one(monkeypatch):
    """With the limit at 4 blocks, the forward's 6 tiles and the backward's segments fold onto
    a third axis (idle blocks past the end): the same image and gradients, bit for bit."""
    dtype = np.float32
    g, cam = scenes.cast(scenes.scene(5), dtype), scenes.camera(dtype=dtype)
    w = np.random.default_rng(5).normal(size=(cam.height, cam.width, 3)).astype(dtype)
    config = C(kernel="mosaic", tuning=K(backward_segment=128))

    def run(g, capacity):
        def loss(g):
            out = lgs_jax.render(g, cam, backend="pallas", config=config, capacity=capacity)
            return jnp.sum(out.image * w), out.image
        return jax.grad(loss, has_aux=True)(g)

    def both(g):
        """Both in one program (one compile, a third less than two): the second traced under
        the patched limit, at another capacity (render's own jit traces it anew)."""
        want = run(g, scenes.CAPACITY)
        monkeypatch.setattr(mosaic_forward, "MAX_GRID_YZ", 4)
        return want, run(g, scenes.CAPACITY + 8)

    want, got = jax.jit(both)(g)
    assert mosaic_forward.MAX_GRID_YZ == 4  # the folded one was traced under the patch
    for a, b in zip(jax.tree.leaves(got), jax.tree.leaves(want)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


@pytest.mark.slow
@gpu_only("a scene of more than 2^25 tile-Gaussian pairs (about 3 GB of GPU memory)")
def test_gradients_past_2_to_the_25_pairs():
    """A synthetic scene at 3840x2160 needing more than 2^25 pairs renders and differentiates:
    finite gradients, and the backward's segment grid folded (more than 65535 blocks)."""
    from lgs_jax.synthetic import random_scene, synthetic_camera

    cam = synthetic_camera(3840, 2160)
    base = random_scene(2_000_000, seed=0)
    for boost in (0.0, 0.5, 1.0, 1.5, 2.0):  # larger Gaussians, more tiles each
        g = dataclasses.replace(base, log_scales=base.log_scales + np.float32(boost))
        pairs = int(lgs_jax.count_pairs(g, cam))
        if pairs > 2**25:
            break
    assert 2**25 < pairs < 2**27, pairs
    capacity = lgs_jax.pair_capacity(pairs)
    tiles_x, tiles_y = tile_grid(cam.width, cam.height)
    assert mosaic_forward.grid(tiles_x * tiles_y + capacity // 1024, 1)[2] is not None
    grads = jax.jit(jax.grad(lambda g: jnp.sum(lgs_jax.render(
        g, cam, backend="pallas", capacity=capacity).image)))(g)
    for leaf in jax.tree.leaves(grads):
        assert np.all(np.isfinite(np.asarray(leaf)))
