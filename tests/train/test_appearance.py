"""lgs_jax.train.appearance: the head against its float64 formula; a view's colour change
added to the SH colour before the clamp (through `project`); the start (zero last layer) and
the views' average as plain scenes; a run's scene as a training photo shows it (`as_photo`);
the shared head's rows and update in `view_params`; the features and their moments carried by
densification."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from lgs_jax import Camera
from lgs_jax.projection import project
from lgs_jax.scene import Gaussians
from lgs_jax.train import Recipe, appearance, view_params
from lgs_jax.train.ops import duplicate
from lgs_jax.train.optim import optimizer
from lgs_jax.train.pool import Pool, render_gaussians


def _head(seed=0, scale=0.3):
    """A head whose last layer is not zero (random weights of the start's shapes)."""
    rng = np.random.default_rng(seed)
    head = appearance.init_head(jax.random.key(seed))
    return {k: (jnp.asarray(rng.normal(size=v.shape) * scale, jnp.float32)
                if k in ("w3", "b3") else v) for k, v in head.items()}


def _params(n=40, seed=1):
    rng = np.random.default_rng(seed)
    f = lambda *shape: jnp.asarray(rng.normal(size=(n,) + shape), jnp.float32)
    return dict(means=f(3) * 0.5 + jnp.asarray([0.0, 0.0, 4.0]), quats=f(4),
                log_scales=f(3) * 0.2 - 2.5, logit_opacities=f() + 2.0,
                sh=jnp.concatenate([f(1, 3) * 0.3 + 1.5, f(3, 3) * 0.05], 1),
                features=appearance.init_features(jax.random.key(seed), n))


def test_colour_change_is_the_mlp_in_float64():
    head, rng = _head(), np.random.default_rng(3)
    e = rng.normal(size=appearance.EMBED).astype(np.float32)
    f = rng.uniform(size=(50, appearance.FEATURES)).astype(np.float32)
    h = {k: np.asarray(v, np.float64) for k, v in head.items()}
    x = np.concatenate([np.broadcast_to(e, (50, appearance.EMBED)), f], 1).astype(np.float64)
    x = np.maximum(x @ h["w1"] + h["b1"], 0)
    x = np.maximum(x @ h["w2"] + h["b2"], 0)
    want = x @ h["w3"] + h["b3"]
    got = np.asarray(appearance.colour_change(head, jnp.asarray(e), jnp.asarray(f)))
    assert np.abs(want).max() > 0.1
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-5)


def test_a_view_sees_its_colour_change_added_before_the_clamp():
    params, head = _params(), _head(scale=2.0)
    e = jnp.asarray(np.random.default_rng(4).normal(size=appearance.EMBED), jnp.float32)
    active = jnp.ones(40, bool)
    cam = Camera(viewmat=np.eye(4, dtype=np.float32), fx=np.float32(60), fy=np.float32(60),
                 cx=np.float32(32), cy=np.float32(32), width=64, height=64)
    plain = project(render_gaussians(params, active), cam)
    moved = project(render_gaussians(appearance.seen(params, head, e), active), cam)
    h = np.asarray(appearance.colour_change(head, e, params["features"]))
    rgb = np.asarray(plain.rgb)
    assert rgb.min() > 0.5 and np.abs(h).max() > 0.1  # no clamp at the plain colours
    np.testing.assert_allclose(np.asarray(moved.rgb), np.maximum(rgb + h, 0), atol=2e-6)
    assert np.any(rgb + h < 0)  # some clamp where the change is large and negative
    # every other field of the projection is untouched
    np.testing.assert_array_equal(np.asarray(moved.conic), np.asarray(plain.conic))


def test_the_start_and_the_views_average_are_plain_scenes():
    params = _params()
    start = appearance.init_head(jax.random.key(0))
    e = jnp.ones(appearance.EMBED, jnp.float32)
    assert np.asarray(appearance.seen(params, start, e)["sh"]).tobytes() == np.asarray(
        params["sh"]).tobytes()
    head = _head()
    embeddings = jnp.asarray(np.random.default_rng(7).normal(size=(3, appearance.EMBED)),
                             jnp.float32)
    baked = appearance.baked(params, head, embeddings)
    assert "features" not in baked and set(baked) == set(params) - {"features"}
    views = [appearance.seen(params, head, e)["sh"][:, :1] for e in embeddings]
    np.testing.assert_allclose(np.asarray(baked["sh"][:, :1]), np.mean(np.asarray(views), 0),
                               atol=1e-5)
    assert np.asarray(baked["sh"][:, 1:]).tobytes() == np.asarray(params["sh"][:, 1:]).tobytes()
    assert np.abs(np.asarray(views[0]) - np.asarray(views[1])).max() > 0.1


def test_the_shared_head_is_whole_in_every_step_and_moves():
    settings = Recipe(app_opt=True)
    state = view_params.init(settings, 3, 10, jax.random.key(5))
    assert sorted(state) == ["embed", "head"] and state["embed"][0].shape == (3, 16)
    rows = view_params.rows(view_params.params(state), jnp.asarray([2, 0]))
    assert rows["head"] is state["head"][0] and rows["embed"].shape == (2, 16)
    grads = {"embed": jnp.zeros((3, 16)).at[1].set(1.0),
             "head": jax.tree.map(jnp.ones_like, state["head"][0])}
    new = view_params.update(settings, 10, state, grads)
    p = np.asarray(new["embed"][0])
    assert p[1, 0] < 0 < p[0, 0] and p[0, 0] == p[2, 0]
    np.testing.assert_allclose(p.sum(0), 0, atol=1e-9)  # centred: zero is their mean
    assert np.all(np.asarray(new["head"][0]["w3"]) < 0)  # the head moved against its gradient


def test_densification_carries_the_features_and_their_moments():
    params = _params(8)
    active = jnp.arange(8) < 5
    pool = Pool(params, active)
    opt = optimizer(Recipe(app_opt=True), 100, 1.0)
    state = opt.init(params)
    grads = jax.tree.map(jnp.ones_like, params)
    _, state = opt.update(grads, state, params)  # nonzero moments
    mask = jnp.arange(8) == 2
    new, new_state, granted = duplicate(pool, state, mask)
    assert bool(granted[2]) and bool(new.active[5])
    np.testing.assert_array_equal(np.asarray(new.params["features"][5]),
                                  np.asarray(params["features"][2]))
    mu = new_state[0].mu["features"]
    assert np.all(np.asarray(mu[5]) == 0) and np.all(np.asarray(mu[2]) != 0)



def test_a_runs_scene_as_a_training_photo_shows_it(tmp_path):
    params, head = _params(), _head()
    rng = np.random.default_rng(6)
    embeddings = rng.normal(size=(2, appearance.EMBED)).astype(np.float32)
    path = str(tmp_path / "appearance.npz")
    appearance.save(path, params["features"], embeddings, head, ["a", "b"])
    baked = appearance.baked(params, head, jnp.asarray(embeddings))
    scene = Gaussians(baked["means"], baked["quats"], baked["log_scales"],
                      baked["logit_opacities"], baked["sh"])
    for k, name in enumerate(["a", "b"]):
        want = appearance.seen(params, head, jnp.asarray(embeddings[k]))["sh"][:, :1]
        got = appearance.as_photo(scene, path, name).sh[:, :1]
        np.testing.assert_allclose(np.asarray(got), np.asarray(want), atol=1e-5)
    with pytest.raises(ValueError, match="name: 'c'"):
        appearance.as_photo(scene, path, "c")
