"""lgs_jax.train.color_opt and view_params: the correction against its float64 formula and the
identity to the bit at zero; centring; a step's rows taken exactly and their gradients summed
per view (a view twice in a batch: twice its row's gradient; other views: zero)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from lgs_jax.train import Recipe, color_opt, view_params


def test_correction_is_the_affine_map_and_zero_is_the_identity():
    rng = np.random.default_rng(0)
    image = rng.uniform(0, 1, (5, 7, 3)).astype(np.float32)
    p = rng.normal(0, 0.1, 12).astype(np.float32)
    got = np.asarray(color_opt.corrected(jnp.asarray(image), jnp.asarray(p)))
    a, b = p[:9].reshape(3, 3).astype(np.float64), p[9:].astype(np.float64)
    want = image @ (np.eye(3) + a).T + b
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-6)
    same = color_opt.corrected(jnp.asarray(image), jnp.zeros(12))
    np.testing.assert_array_equal(np.asarray(same), image)


def test_projection_centres_the_corrections():
    p = jnp.asarray(np.random.default_rng(1).normal(size=(4, 12)), jnp.float32)
    np.testing.assert_allclose(np.asarray(color_opt.project(p)).sum(0), 0, atol=1e-6)


@pytest.mark.parametrize("idx", [[2, 0], [1, 1], [3, 1, 3]])
def test_rows_are_exact_and_their_gradient_sums_per_view(idx):
    settings = Recipe(pose_opt=True, color_opt=True)
    state = view_params.init(settings, 4, 10)
    assert sorted(state) == ["color", "pose"] and state["pose"][0].shape == (4, 9)
    rng = np.random.default_rng(2)
    params = {k: jnp.asarray(rng.normal(size=p.shape), jnp.float32)
              for k, p in view_params.params(state).items()}
    idx = jnp.asarray(idx)
    rows = view_params.rows(params, idx)
    for k in params:
        np.testing.assert_array_equal(np.asarray(rows[k]), np.asarray(params[k])[np.asarray(idx)])
    weights = {k: jnp.asarray(rng.normal(size=r.shape), jnp.float32) for k, r in rows.items()}
    loss = lambda ps: sum(jnp.sum(weights[k] * r) for k, r in view_params.rows(ps, idx).items())
    grads = jax.grad(loss)(params)
    for k in params:
        want = np.zeros(params[k].shape, np.float32)
        for b, v in enumerate(np.asarray(idx)):
            want[v] += np.asarray(weights[k])[b]
        np.testing.assert_allclose(np.asarray(grads[k]), want, rtol=1e-6, atol=0)
    assert view_params.init(Recipe(), 4, 10) is None and view_params.rows(None, idx) is None


def test_update_moves_the_corrections_and_keeps_them_centred():
    settings = Recipe(color_opt=True)
    state = view_params.init(settings, 3, 10)
    grads = {"color": jnp.zeros((3, 12)).at[0].set(1.0)}
    new = view_params.update(settings, 10, state, grads)
    p = np.asarray(new["color"][0])
    assert p[0, 0] < 0 and p[1, 0] > 0 and p[1, 0] == p[2, 0]  # view 0 down, others up alike
    np.testing.assert_allclose(p.sum(0), 0, atol=1e-9)
