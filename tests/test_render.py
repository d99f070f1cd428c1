"""Public API behaviour: jit / vmap, capacity rules, precision, and bad-input errors."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lgs_jax
from tests import scenes


@pytest.fixture(scope="module")
def scene32():
    return scenes.cast(scenes.scene(2, kinds=("normal", "opaque", "layers", "huge_far")),
                       np.float32)


def test_jit_and_vmap_over_cameras_match_single_renders(scene32):
    cams = [scenes.camera(yaw=y) for y in (-0.2, 0.0, 0.3)]
    batch = lgs_jax.stack_cameras(cams)
    cap = scenes.CAPACITY
    # The scene is an argument, not a closed-over constant: XLA would constant-fold its
    # projection with different rounding than the eager render.
    f = jax.jit(jax.vmap(lambda g, c: lgs_jax.render(g, c, capacity=cap), in_axes=(None, 0)))
    out = f(scene32, batch)
    assert out.image.shape == (3, scenes.H, scenes.W, 3)
    for i, c in enumerate(cams):
        one = lgs_jax.render(scene32, c, capacity=cap)
        # XLA vectorises the batched projection differently (CPU and GPU): its colours and
        # covariances may differ by an ulp, so pixels may too (BENCHMARKS.md §3).
        np.testing.assert_allclose(out.image[i], one.image, rtol=0, atol=1e-6)
        assert int(out.stats.pairs_required[i]) == int(one.stats.pairs_required)


def test_new_camera_pose_does_not_recompile(scene32):
    f = scenes.jit_render  # shared by the tests that trace a render: compiled once per worker
    f(scene32, scenes.camera(yaw=0.1))
    size = f._cache_size()
    f(scene32, scenes.camera(yaw=-0.3))
    assert f._cache_size() == size


def test_capacity_none_under_jit_raises(scene32):
    with pytest.raises(ValueError, match="capacity"):
        jax.jit(lambda c: lgs_jax.render(scene32, c).image)(scenes.camera())


def test_eager_overflow_raises_with_required_size(scene32):
    with pytest.raises(lgs_jax.CapacityError, match="pass capacity >=") as err:
        lgs_jax.render(scene32, scenes.camera(), capacity=4)
    assert err.value.required > 4


def test_row_capacity_is_ignored_where_the_backward_stores_no_pair_rows(scene32):
    """`tiles` stores no pair rows: row_capacity changes nothing; its stats are its own (the
    strip pairs), the Pallas backends' (walked pairs, row overflow) on the Pallas backends."""
    cam, cap = scenes.camera(), scenes.CAPACITY  # the pair buffer of the other tests' renders
    plain = lgs_jax.render(scene32, cam, backend="tiles", capacity=cap)
    small = lgs_jax.render(scene32, cam, backend="tiles", capacity=cap, row_capacity=1)
    np.testing.assert_array_equal(small.image, plain.image)
    assert small.stats.backend_stats == plain.stats.backend_stats or (
        int(small.stats.backend_stats.strip_pairs) == int(plain.stats.backend_stats.strip_pairs))
    assert not hasattr(small.stats.backend_stats, "row_overflow")
    assert lgs_jax.render(scene32, cam, backend="reference",
                          capacity=cap).stats.backend_stats is None


def test_render_growing_settles_on_enough_capacity(scene32):
    # Larger Gaussians (158 pairs): the buffer grows from 2 (tests/test_binning.py's program
    # too) to scenes.CAPACITY, whose program test_new_camera_pose_does_not_recompile compiled.
    g = dataclasses.replace(scene32, log_scales=scene32.log_scales + np.float32(1.0))
    out, cap = lgs_jax.render_growing(scenes.jit_render, g, scenes.camera(), capacity=2)
    assert not bool(out.stats.overflow) and cap >= int(out.stats.pairs_required)
    assert cap == scenes.CAPACITY
    np.testing.assert_array_equal(out.image, lgs_jax.render(g, scenes.camera(),
                                                            capacity=scenes.CAPACITY).image)


def test_pair_capacity_is_a_power_of_two_then_eight_sizes_per_octave():
    cap = lgs_jax.pair_capacity
    for k in range(17):  # up to 2^16: the power of two above
        assert cap(2**k) == 2**k and (k < 2 or cap(2**k - 1) == 2**k)
        assert cap(2**k + 1) == (2 ** (k + 1) if k < 16 else 2**16 + 2**13)
    assert cap(0) == cap(1) == 1
    for n in [2**16 + 1, 70_001, 99_999, 2**17, 2**20 + 5, 3_141_592, 10**8, 2**30 + 1]:
        c, step = cap(n), 2 ** (n.bit_length() - 4)
        assert c % step == 0 and c % 8192 == 0 and n <= c < 1.125 * n + 1, n
    caps = [cap(n) for n in range(1, 2**19, 97)] + [cap(n) for n in range(2**19, 2**24, 4099)]
    assert all(a <= b for a, b in zip(caps, caps[1:]))
    assert len(set(cap(n) for n in range(2**20 + 1, 2**21 + 1, 1024))) == 8
    assert cap(100_000, 1.5) == cap(150_000) and cap(1000, 2) == 2048
    assert cap(2**31 - 10) == cap(2**40) == 2**31 - 1
    for bad in (0.99, 0, np.nan):
        with pytest.raises(ValueError, match="headroom"):
            cap(10, bad)


def test_float32_stays_float32_with_x64_and_float64_is_float64(scene32):
    """The outputs' dtypes, which tracing decides (`jax.eval_shape`: nothing compiled)."""
    assert jax.config.jax_enable_x64
    shapes = lambda g, cam: jax.eval_shape(
        lambda g, cam: lgs_jax.render(g, cam, capacity=scenes.CAPACITY), g, cam)
    out = shapes(scene32, scenes.camera(dtype=np.float64))
    assert out.image.dtype == out.alpha.dtype == out.depth.dtype == jnp.float32
    out64 = shapes(scenes.cast(scene32, np.float64), scenes.camera())
    assert out64.image.dtype == jnp.float64


def test_empty_scene_renders_background():
    g = scenes.cast(scenes.scene(0), np.float32)
    empty = jax.tree.map(lambda x: x[:0], g)
    out = lgs_jax.render(empty, scenes.camera(), background=np.array([0.1, 0.2, 0.3]))
    np.testing.assert_allclose(out.image, np.broadcast_to([0.1, 0.2, 0.3], out.image.shape),
                               rtol=1e-7)
    assert np.all(np.asarray(out.alpha) == 0)


def test_invalid_gaussians_never_reach_the_image():
    g = scenes.cast(scenes.scene(4, kinds=("invalid", "behind")), np.float32)
    out = lgs_jax.render(g, scenes.camera(), background=np.ones(3), capacity=scenes.CAPACITY)
    assert np.all(np.isfinite(np.asarray(out.image)))
    assert int(out.stats.n_invalid) == scenes.N and int(out.stats.n_valid) == 0
    np.testing.assert_array_equal(out.image, np.ones_like(out.image))


def test_repeated_renders_are_bit_identical(scene32):
    # capacity None: the eager render's own sizing (the other tests pass the shared capacity)
    a = lgs_jax.render(scene32, scenes.camera(yaw=0.2))
    b = lgs_jax.render(scene32, scenes.camera(yaw=0.2))
    np.testing.assert_array_equal(a.image, b.image)
    np.testing.assert_array_equal(a.depth, b.depth)


def _replace(obj, **kw):
    return dataclasses.replace(obj, **kw)


@pytest.mark.parametrize("field,value,match", [
    ("means", np.zeros((3, 2), np.float32), "gaussians.means"),
    ("quats", np.zeros((scenes.N, 3), np.float32), "gaussians.quats"),
    ("logit_opacities", np.zeros((scenes.N, 1), np.float32), "gaussians.logit_opacities"),
    ("sh", np.zeros((scenes.N, 5, 3), np.float32), "gaussians.sh"),
    ("sh", np.zeros((scenes.N, 4), np.float32), "gaussians.sh"),
    ("log_scales", np.zeros((scenes.N, 3), np.int32), "gaussians.log_scales"),
    ("log_scales", np.zeros((scenes.N, 3), np.float64), "gaussians.log_scales"),
    ("means", np.zeros((scenes.N, 3), np.float16), "gaussians"),
])
def test_bad_gaussians_raise_naming_the_field(scene32, field, value, match):
    with pytest.raises(ValueError, match=match):
        lgs_jax.render(_replace(scene32, **{field: value}), scenes.camera())


@pytest.mark.parametrize("change,match", [
    (dict(width=0), "camera.width"), (dict(height=-3), "camera.height"),
    (dict(width=10.5), "camera.width"), (dict(viewmat=np.eye(3)), "camera.viewmat"),
    (dict(fx=-1.0), "camera.fx"), (dict(fy=np.nan), "camera.fy"),
    (dict(viewmat=np.full((4, 4), np.inf)), "camera.viewmat"),
    (dict(near=2.0, far=1.0), "near"), (dict(near=0.0), "camera.near"),
    (dict(cx=np.array([1.0, 2.0])), "camera.cx"),
])
def test_bad_cameras_raise_naming_the_argument(scene32, change, match):
    with pytest.raises(ValueError, match=match):
        lgs_jax.render(scene32, _replace(scenes.camera(), **change))


@pytest.mark.parametrize("kwargs,match", [
    (dict(background=np.zeros(4)), "background"), (dict(backend="cuda"), "backend"),
    (dict(capacity=0), "capacity"), (dict(capacity=2.5), "capacity"),
    (dict(row_capacity=0), "row_capacity"), (dict(row_capacity=64.0), "row_capacity"),
    (dict(config="3dgs"), "config"),
])
def test_bad_arguments_raise(scene32, kwargs, match):
    with pytest.raises(ValueError, match=match):
        lgs_jax.render(scene32, scenes.camera(), **kwargs)


def test_bad_convention_raises():
    with pytest.raises(ValueError, match="config.convention"):
        lgs_jax.RasterConfig(convention="cuda")


def test_stack_cameras_needs_one_size():
    with pytest.raises(ValueError, match="cameras"):
        lgs_jax.stack_cameras([scenes.camera(), scenes.camera(width=32)])


def test_float64_without_x64_raises(scene32):
    g64 = scenes.cast(scene32, np.float64)
    with jax.enable_x64(False):
        with pytest.raises(ValueError, match="gaussians.means: float64 needs .*jax_enable_x64"):
            lgs_jax.render(g64, scenes.camera())
        with pytest.raises(ValueError, match="gaussians.sh: dtype float64 differs"):
            lgs_jax.render(_replace(scene32, sh=np.asarray(scene32.sh, np.float64)),
                           scenes.camera())


@pytest.mark.parametrize("field", ["means", "logit_opacities", "sh"])
def test_python_lists_as_gaussian_fields_raise(scene32, field):
    value = np.asarray(getattr(scene32, field)).tolist()
    with pytest.raises(ValueError, match=f"gaussians.{field}: expected a numpy or JAX array, "
                                         "got list"):
        lgs_jax.render(_replace(scene32, **{field: value}), scenes.camera())


def _rot_z(angle):
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


@pytest.mark.parametrize("rotation,last_row,match", [
    (np.eye(3), [0, 0, 0.5, 1], "last row must be"),
    (np.eye(3), [0, 0, 0, 2], "last row must be"),
    (np.diag([1.0, 1.0, 1.001]), [0, 0, 0, 1], "not orthonormal"),
    (2 * _rot_z(0.3), [0, 0, 0, 1], "not orthonormal"),
    (np.diag([1.0, -1.0, 1.0]), [0, 0, 0, 1], "reflection"),
])
def test_bad_viewmat_values_raise(scene32, rotation, last_row, match):
    view = np.eye(4)
    view[:3, :3], view[3] = rotation, last_row
    with pytest.raises(ValueError, match=f"camera.viewmat: .*{match}"):
        lgs_jax.render(scene32, _replace(scenes.camera(), viewmat=view.astype(np.float32)))


def test_viewmat_within_float32_rounding_and_traced_cameras_pass(scene32):
    view = np.eye(4, dtype=np.float32)
    view[:3, :3] = _rot_z(0.3) * (1 + 2e-7)  # float32 rounding of a stored rotation
    lgs_jax.render(scene32, _replace(scenes.camera(), viewmat=view), capacity=scenes.CAPACITY)
    bad = np.eye(4, dtype=np.float32) * 2  # not checked when traced (values unknown)
    scenes.jit_render(scene32, _replace(scenes.camera(), viewmat=bad))


def test_viewmat_as_list_raises(scene32):
    with pytest.raises(ValueError, match="camera.viewmat: expected a numpy or JAX array"):
        lgs_jax.render(scene32, _replace(scenes.camera(), viewmat=np.eye(4).tolist()))


@pytest.mark.parametrize("background", [[np.nan, 0, 0], np.array([0, np.inf, 0])])
def test_non_finite_background_raises(scene32, background):
    with pytest.raises(ValueError, match="background: must be finite"):
        lgs_jax.render(scene32, scenes.camera(), background=background)


def test_background_list_is_accepted(scene32):
    out = lgs_jax.render(scene32, scenes.camera(), background=[0.1, 0.2, 0.3],
                         capacity=scenes.CAPACITY)
    assert out.image.dtype == np.float32


def test_default_backend_is_the_fastest_exact_one_for_the_platform(scene32):
    """No backend given: `pallas` on a GPU, `tiles` elsewhere (BENCHMARKS.md), reported in
    stats.backend; an explicit choice stays."""
    want = "pallas" if jax.default_backend() == "gpu" else "tiles"
    assert lgs_jax.default_backend() == want
    assert lgs_jax.render(scene32, scenes.camera(), capacity=scenes.CAPACITY).stats.backend == want
    out = lgs_jax.render(scene32, scenes.camera(), backend="reference", capacity=scenes.CAPACITY)
    assert out.stats.backend == "reference"


def test_sh_bands_colour_as_the_masked_coefficients_and_differentiate_alike(scene32):
    """`sh_bands` (applied inside the projection) renders and differentiates as the
    coefficients multiplied by the mask before the render: the same bits, on the `reference`
    backend (every backend's projection is one; the cheapest to compile); a mask of the wrong
    length is refused by name."""
    cam, cap = scenes.camera(), scenes.CAPACITY
    k = scene32.sh.shape[1]
    mask = jnp.asarray([1.0] + [0.0] * (k - 1), jnp.float32)
    w = jnp.asarray(np.random.default_rng(0).normal(size=(scenes.H, scenes.W, 3)), jnp.float32)

    def loss(sh, bands):
        g = dataclasses.replace(scene32, sh=sh if bands else sh * mask[None, :, None])
        out = lgs_jax.render(g, cam, backend="reference", capacity=cap,
                             sh_bands=mask if bands else None)
        return jnp.sum(out.image * w), out.image

    f = jax.jit(jax.value_and_grad(loss, has_aux=True), static_argnums=1)
    (_, inside), d_inside = f(scene32.sh, True)
    (_, before), d_before = f(scene32.sh, False)
    assert np.asarray(inside).tobytes() == np.asarray(before).tobytes()
    assert np.asarray(d_inside).tobytes() == np.asarray(d_before).tobytes()
    assert not np.asarray(d_inside)[:, 1:].any() and np.asarray(d_inside)[:, 0].any()
    with pytest.raises(ValueError, match=r"sh_bands: expected shape \(%d,\)" % k):
        lgs_jax.render(scene32, cam, capacity=cap, sh_bands=mask[:1])
