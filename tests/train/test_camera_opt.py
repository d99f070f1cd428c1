"""lgs_jax.train.camera_opt: the 6-D rotation against Gram-Schmidt in float64, the adjusted
view matrix against the inverse of the moved camera-to-world pose, zero deltas changing no bit,
and a perturbed camera found again by gradient descent on its image."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import optax

import lgs_jax
from lgs_jax.train import camera_opt


def _gram_schmidt(a):
    b1 = a[:3] / np.linalg.norm(a[:3])
    b2 = a[3:] - (b1 @ a[3:]) * b1
    b2 /= np.linalg.norm(b2)
    return np.stack([b1, b2, np.cross(b1, b2)])


def test_rotation_6d_is_gram_schmidt_and_exact_at_the_identity():
    a = np.random.default_rng(0).normal(size=(5, 6))
    got = np.asarray(camera_opt.rotation_6d(jnp.asarray(a)))
    for g, x in zip(got, a):
        np.testing.assert_allclose(g, _gram_schmidt(x), atol=1e-12)
        np.testing.assert_allclose(g @ g.T, np.eye(3), atol=1e-12)
        assert np.linalg.det(g) > 0
    eye = camera_opt.rotation_6d(jnp.asarray(camera_opt.IDENTITY_6D, jnp.float32))
    np.testing.assert_array_equal(np.asarray(eye), np.eye(3))


def _batch(views):
    return lgs_jax.stack_cameras([lgs_jax.default_camera(v, 64, 36) for v in views])


def test_adjusted_moves_the_camera_to_world_pose_and_zero_changes_no_bit():
    cams = _batch([0, 3])
    same = camera_opt.adjusted(cams, jnp.zeros((2, 9)))
    np.testing.assert_array_equal(np.asarray(same.viewmat), np.asarray(cams.viewmat))
    deltas = np.random.default_rng(1).normal(scale=0.1, size=(2, 9))
    got = np.asarray(camera_opt.adjusted(jax.tree.map(lambda x: jnp.asarray(x, jnp.float64)
                                                      if hasattr(x, "dtype") else x, cams),
                                         jnp.asarray(deltas)).viewmat)
    for i in range(2):
        move = np.eye(4)
        move[:3, :3] = _gram_schmidt(deltas[i, 3:] + camera_opt.IDENTITY_6D)
        move[:3, 3] = deltas[i, :3]
        c2w = np.linalg.inv(np.asarray(cams.viewmat[i], np.float64))
        np.testing.assert_allclose(got[i], np.linalg.inv(c2w @ move), atol=1e-6)


@pytest.mark.slow  # CI time: an optimization of 100s of steps
def test_a_perturbed_camera_is_found_again():
    """The image of view 2 from a camera moved by a known delta: Adam on the delta's image
    loss brings the pose back (the rendering's camera gradient)."""
    scene, cams = lgs_jax.default_scene(), _batch([2])
    target = lgs_jax.render(scene, jax.tree.map(lambda x: x[0], cams), capacity=16384).image
    true = jnp.asarray([[0.02, -0.01, 0.015, 0.0, 0.03, 0.0, -0.02, 0.0, 0.0]])
    start = camera_opt.adjusted(cams, true)  # the wrong pose we start from

    def loss(d):
        cam = jax.tree.map(lambda x: x[0], camera_opt.adjusted(start, d))
        return jnp.mean((lgs_jax.render(scene, cam, capacity=16384).image - target) ** 2)

    step = jax.jit(jax.value_and_grad(loss))
    opt = optax.adam(3e-3)
    d, state = jnp.zeros((1, 9)), None
    state = opt.init(d)
    first = None
    for _ in range(60):
        value, g = step(d)
        first = value if first is None else first
        updates, state = opt.update(g, state, d)
        d = optax.apply_updates(d, updates)
    moved = np.asarray(camera_opt.adjusted(start, d).viewmat[0])
    error = lambda v: np.abs(v - np.asarray(cams.viewmat[0])).max()
    assert float(loss(d)) < 0.2 * float(first)
    assert error(moved) < 0.5 * error(np.asarray(start.viewmat[0]))
