"""lgs_jax.train.ssim_kernel: the fused SSIM kernels against `losses.ssim_reference` (JAX's
gradient of the XLA SSIM) and the XLA `ssim`, values and both images' gradients, on images whose
sizes are no multiple of the kernels' blocks (37x53: a partial row block and a partial column
block; 64x48: whole row blocks), with both paddings; in short and long row blocks; under vmap
(the training step's views); `losses.ssim` running them on a GPU; and their lowering for the
GPU.

Without a GPU the kernels run in Pallas interpret mode (what CI exercises); on a GPU the same
tests run the compiled kernels. The default set runs each shape with one padding in float32 and
both paddings in float64; the other two float32 cases are marked slow.

Tolerances: float64 kernels equal the reference to float64 rounding (SSIM_F64, relative to the
largest gradient); float32 kernels stay within SSIM_F32 of the float64 reference (a few float32
ulps of a value of order one; the gradients relative to their largest magnitude), as the
float32 XLA `ssim` does.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from lgs_jax import train
from lgs_jax.train import losses, ssim_kernel
from tests.devices import ON_GPU

INTERPRET = not ON_GPU
SSIM_F64 = 1e-12
SSIM_F32 = 2e-6
SHAPES = {"37x53": (37, 53, 3), "64x48": (64, 48, 3)}
SCALE = 2.5  # a cotangent other than 1 (the loss weighs 1 − SSIM by λ)


def _images(shape, seed=0):
    rng = np.random.default_rng(seed)
    a = rng.uniform(0, 1, shape)
    return a, np.clip(a + rng.normal(0, 0.15, shape), 0, 1)


def _kernel(a, b, padding="same"):
    return ssim_kernel.ssim(a, b, tuple(losses.gaussian_window()), 1.0, padding, INTERPRET)


def _value_and_grads(f, a, b, padding, dt):
    g = jax.jit(jax.value_and_grad(lambda x, y: SCALE * f(x, y, padding=padding), (0, 1)))
    return g(jnp.asarray(a, dt), jnp.asarray(b, dt))


def _max_diff(got, want):
    """Largest difference of the values, and of each gradient relative to its largest
    magnitude."""
    (v, grads), (w, wgrads) = got, want
    rel = [float(jnp.max(jnp.abs(g - e)) / jnp.max(jnp.abs(e))) for g, e in zip(grads, wgrads)]
    return abs(float(v) - float(w)) / SCALE, max(rel)


@pytest.mark.parametrize("shape,padding", [
    pytest.param(SHAPES["37x53"], "same", id="37x53-same"),
    pytest.param(SHAPES["64x48"], "valid", id="64x48-valid"),
    pytest.param(SHAPES["37x53"], "valid", id="37x53-valid", marks=pytest.mark.slow),
    pytest.param(SHAPES["64x48"], "same", id="64x48-same", marks=pytest.mark.slow),
])
def test_float32_kernels_equal_the_reference(shape, padding):
    """Float32 value and gradients within SSIM_F32 of the float64 reference, and of the
    float32 XLA `ssim`."""
    a, b = _images(shape)
    exact = _value_and_grads(losses.ssim_reference, a, b, padding, jnp.float64)
    got = _value_and_grads(_kernel, a, b, padding, jnp.float32)
    xla = _value_and_grads(losses.xla_ssim, a, b, padding, jnp.float32)
    assert all(x.dtype == jnp.float32 for x in got[1])
    assert max(_max_diff(got, exact)) < SSIM_F32
    assert max(_max_diff(xla, exact)) < SSIM_F32  # the bound holds the XLA path too
    assert max(_max_diff(got, xla)) < 2 * SSIM_F32


@pytest.mark.parametrize("padding", ["same", "valid"])
def test_float64_kernels_equal_the_reference(padding):
    """In float64 the kernels compute the reference's equations to float64 rounding (a wrong
    term or weight, masked at float32 tolerance, shows here)."""
    a, b = _images(SHAPES["37x53"], seed=1)
    exact = _value_and_grads(losses.ssim_reference, a, b, padding, jnp.float64)
    got = _value_and_grads(_kernel, a, b, padding, jnp.float64)
    assert max(_max_diff(got, exact)) < SSIM_F64


def test_kernels_under_vmap():
    """A batch of views through vmap (the training step's `vectorize`): each view's value and
    gradients as alone."""
    pairs = [_images(SHAPES["37x53"], seed=s) for s in (2, 3)]
    a, b = (jnp.asarray(np.stack(x), jnp.float32) for x in zip(*pairs))
    f = jax.value_and_grad(lambda x, y: SCALE * _kernel(x, y), (0, 1))
    v, (da, db) = jax.jit(jax.vmap(f))(a, b)
    for i in range(2):
        vi, (dai, dbi) = jax.jit(f)(a[i], b[i])
        np.testing.assert_array_equal(v[i], vi)
        np.testing.assert_array_equal(da[i], dai)
        np.testing.assert_array_equal(db[i], dbi)


def test_the_row_block_changes_no_gradient_bit():
    """Small images sweep in short row blocks (`block_rows`: more programs), large ones in long
    blocks: the same image in 32-row blocks gives the gradients of 8-row blocks to the bit
    (each pixel's partials and blur are its own), the value within the rounding of its sum (the
    programs' sums are added in another grouping)."""
    h, w, c = SHAPES["37x53"]
    assert ssim_kernel.block_rows(h, w * c) == 8 and ssim_kernel.block_rows(533, 951 * 3) == 32
    a, b = _images(SHAPES["37x53"], seed=4)
    short = _value_and_grads(_kernel, a, b, "same", jnp.float32)
    long = _value_and_grads(lambda x, y, padding: ssim_kernel.ssim(
        x, y, tuple(losses.gaussian_window()), 1.0, padding, INTERPRET, rows=32), a, b, "same",
        jnp.float32)
    for x, y in zip(short[1], long[1]):
        np.testing.assert_array_equal(x, y)
    assert abs(float(short[0]) - float(long[0])) <= 8 * np.finfo(np.float32).eps * SCALE


def test_bad_arguments():
    a = jnp.zeros((10, 40, 3))
    with pytest.raises(ValueError, match="'valid' counts no pixel of a 10x40 image"):
        train.ssim(a, a, padding="valid")
    with pytest.raises(ValueError, match="'valid' counts no pixel of a 10x40 image"):
        losses.ssim_reference(a, a, padding="valid")
    with pytest.raises(ValueError, match=r"two \(H, W, C\) images of one shape"):
        _kernel(a, a[:, :30])


def _fake_h100(monkeypatch):
    from jax._src.pallas.triton import gpu_info

    monkeypatch.setattr(gpu_info, "get_gpu_info",
                        lambda: gpu_info.get_gpu_info_from_version(gpu_info.GpuVersion.H100))


@pytest.mark.parametrize("dtype", [jnp.float32, jnp.float64])
def test_kernels_lower_for_the_gpu(dtype, monkeypatch):
    """The forward (alone, and with the partial maps under grad) and the backward kernel lower
    through the Pallas Triton lowering for an H100 (the GPU description faked), also under vmap
    (the views one more grid axis)."""
    _fake_h100(monkeypatch)
    one = jax.ShapeDtypeStruct(SHAPES["37x53"], dtype)
    views = jax.ShapeDtypeStruct((2,) + SHAPES["37x53"], dtype)
    lower = lambda f, x: jax.jit(f).trace(x, x).lower(lowering_platforms=("cuda",)).as_text()
    grad = jax.grad(lambda a, b: ssim_kernel.ssim(a, b, tuple(losses.gaussian_window()), 1.0,
                                                  "same", False), (0, 1))
    value = lower(lambda a, b: ssim_kernel.ssim(a, b, (0.25, 0.5, 0.25), 1.0, "valid", False),
                  one)
    assert value.count("__gpu$xla.gpu.triton") == 1 and "ssim_forward" in value
    for both in (lower(grad, one), lower(jax.vmap(grad), views)):
        assert both.count("__gpu$xla.gpu.triton") == 2
        assert "ssim_forward" in both and "ssim_backward" in both


def test_training_loss_runs_the_kernels_on_a_gpu(monkeypatch):
    """`loss_fn` (the training step's loss) differentiated: on a GPU backend `losses.ssim`
    lowers to the two kernels for an image of more than `losses.SMALL_IMAGE` pixels, to XLA
    alone for a smaller one; on another backend, to XLA alone."""
    _fake_h100(monkeypatch)
    large = jax.ShapeDtypeStruct((201, 200, 3), jnp.float32)
    small = jax.ShapeDtypeStruct((200, 200, 3), jnp.float32)
    lower = lambda x: jax.jit(jax.grad(lambda a, b: train.loss_fn(a, b, padding="valid"))).trace(
        x, x).lower(lowering_platforms=("cuda",)).as_text()  # traced afresh on each call
    if not ON_GPU:
        assert "__gpu$xla.gpu.triton" not in lower(large)
    monkeypatch.setattr(jax, "default_backend", lambda: "gpu")
    text = lower(large)
    assert "ssim_forward" in text and "ssim_backward" in text
    assert "__gpu$xla.gpu.triton" not in lower(small)
