"""Appearance embeddings (`Recipe.app_opt`, `fit --app-opt`): a photo collection whose
lighting, exposure or processing changes between photos in ways that differ over the scene (a
cloud's shadow, lamps switched on), which one colour map per view (`color_opt`) or per image
region (`bilateral_grid`) cannot follow: gsplat simple_trainer's `--app_opt`, in a form that
bakes exactly into a plain scene.

Each Gaussian i has a learned feature f_i (FEATURES values, the pool's group "features", drawn
uniform in [0, 1) at the start, carried by densification with the other groups); each training
view v an embedding e_v (EMBED values, zero at the start); a small MLP shared by all views (the
"head": (EMBED + FEATURES) -> WIDTH -> WIDTH -> 3, ReLU between, the last layer zero at the
start) maps them to a colour change h(e_v, f_i) of Gaussian i in view v. View v sees Gaussian i
with its SH band 0 moved by that change,

    sh_dc_iv = sh_dc_i + h(e_v, f_i) / C0      (C0 = Y_0^0 = 0.2820948, `sh.C0`),

so its colour is max(SH_i(dir) + 0.5 + h(e_v, f_i), 0): the change adds to the view-dependent
colour before the clamp, exactly as if band 0 had been trained to it (`seen`). Where gsplat's
head also takes the view direction and replaces the SH colour (colours = sigmoid(head + base)),
this one leaves the view dependence to the SH bands, so that the scene as one view sees it is a
plain scene, and so is the average over the training views V:

    sh_dc_i + (1/|V|) Σ_v h(e_v, f_i) / C0      (`baked`),

the views' average appearance, which held-out views and the written scene.ply use (`as_photo`
gives back a training photo's). The head's zero last layer makes the first step's renders those
of a run without embeddings.

After each update the embeddings are centred over the training views (`project`, as `color_opt`'s
corrections), so that they cannot drift together. Rates (gsplat's app_opt): the embeddings lr_app ·
10, the head lr_app (both Adam, torch's defaults, times sqrt(batch), L2 weight decay app_reg), the
features lr_features in the scene's Adam (`optim.optimizer`).

Memory: the head's two hidden layers for every Gaussian of a step's views are kept for the
backward, 2 · WIDTH floats per Gaussian and view (512 bytes: 0.5 GB at 1M Gaussians).
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np

from ..scene import Gaussians
from ..sh import C0
from .optim import torch_adam

FEATURES = 32  # per Gaussian (gsplat's feature_dim)
EMBED = 16  # per training view (gsplat's embed_dim)
WIDTH = 64  # the head's hidden layers (gsplat's mlp_width; two of them: mlp_depth 2)
SIZE = EMBED  # the `view_params` part "embed": this module
HIGHEST = jax.lax.Precision.HIGHEST


def enabled(recipe) -> bool:
    return recipe.app_opt


def optimizer(recipe, steps: int):
    """The embeddings' optimizer (module docstring; constant over the `steps`)."""
    return torch_adam(10 * recipe.lr_app * math.sqrt(recipe.batch), recipe.app_reg)


def project(p):
    """The embeddings (views, EMBED) centred over the views (module docstring)."""
    return p - jnp.mean(p, axis=0)


def init_features(key, n: int):
    """(n, FEATURES) features uniform in [0, 1) (gsplat's torch.rand)."""
    return jax.random.uniform(key, (n, FEATURES), jnp.float32)


def init_head(key):
    """The head's weights {w1, b1, w2, b2, w3, b3}: the hidden layers as torch's nn.Linear
    starts them (weights and biases uniform in ±1/sqrt(fan_in)), the last layer zero (module
    docstring)."""
    k1, k2, k3, k4 = jax.random.split(key, 4)

    def linear(kw, kb, fan_in, fan_out):
        bound = 1.0 / math.sqrt(fan_in)
        return (jax.random.uniform(kw, (fan_in, fan_out), jnp.float32, -bound, bound),
                jax.random.uniform(kb, (fan_out,), jnp.float32, -bound, bound))

    w1, b1 = linear(k1, k2, EMBED + FEATURES, WIDTH)
    w2, b2 = linear(k3, k4, WIDTH, WIDTH)
    return dict(w1=w1, b1=b1, w2=w2, b2=b2, w3=jnp.zeros((WIDTH, 3), jnp.float32),
                b3=jnp.zeros((3,), jnp.float32))


def colour_change(head: dict, embedding, features):
    """h(e, f_i) (N, 3) for one view's embedding e (EMBED,) and the features (N, FEATURES):
    relu(relu([e, f_i] W1 + b1) W2 + b2) W3 + b3, in float32 at full precision (no TF32)."""
    x = jnp.concatenate([jnp.broadcast_to(embedding, (features.shape[0], EMBED)), features], 1)
    x = jax.nn.relu(jnp.dot(x, head["w1"], precision=HIGHEST) + head["b1"])
    x = jax.nn.relu(jnp.dot(x, head["w2"], precision=HIGHEST) + head["b2"])
    return jnp.dot(x, head["w3"], precision=HIGHEST) + head["b3"]


def dc_change(head: dict, embedding, features):
    """The change of band 0 a view sees, h(e, f_i) / C0, shaped as band 0 of the pool's sh
    (N, 1, 3)."""
    return (colour_change(head, embedding, features) / C0)[:, None, :]


def seen(params: dict, head: dict, embedding) -> dict:
    """The pool's parameters as a view of embedding e (EMBED,) sees them: SH band 0 moved by
    `dc_change` (module docstring); the other groups as they are."""
    return dict(params, sh=band0_moved(params["sh"], dc_change(head, embedding,
                                                               params["features"])))


def band0_moved(sh, change):
    """SH coefficients (N, K, 3) with band 0 moved by `change` (N, 1, 3): sh[:, 0] + change,
    the other bands as they are."""
    sh = jnp.asarray(sh)
    return jnp.concatenate([sh[:, :1] + change, sh[:, 1:]], 1)


def with_dc_change(g: Gaussians, change) -> Gaussians:
    """`g` with its band 0 moved by `change` (N, 1, 3): sh[:, 0] + change, the other bands
    as they are."""
    return dataclasses.replace(g, sh=band0_moved(g.sh, change))


def mean_dc_change(head: dict, embeddings, features):
    """(1/V) Σ_v `dc_change`(e_v, f_i) (N, 1, 3) over the embeddings (V, EMBED), one view at a
    time (memory of one view's head), summed in view order."""
    def add(total, e):
        return total + dc_change(head, e, features), None

    total, _ = jax.lax.scan(add, jnp.zeros((features.shape[0], 1, 3), jnp.float32), embeddings)
    return total / embeddings.shape[0]


def baked(params: dict, head: dict, embeddings) -> dict:
    """The pool's parameters at the training views' average appearance (module docstring),
    without the features: a plain scene (held-out views, scene.ply)."""
    out = dict(params, sh=band0_moved(params["sh"], mean_dc_change(head, embeddings,
                                                                   params["features"])))
    del out["features"]
    return out


@dataclasses.dataclass(frozen=True)
class _Head:
    """The `view_params` part "head": the MLP every view shares (not one row per view)."""

    shared = True

    def enabled(self, recipe) -> bool:
        return recipe.app_opt

    def init(self, recipe, views: int, key):
        return init_head(key)

    def optimizer(self, recipe, steps: int):
        return torch_adam(recipe.lr_app * math.sqrt(recipe.batch), recipe.app_reg)

    def project(self, p):
        return p


HEAD = _Head()


HEAD_WEIGHTS = ("w1", "b1", "w2", "b2", "w3", "b3")


def save(path: str, features, embeddings, head: dict, names) -> None:
    """appearance.npz: the active Gaussians' features (in scene.ply's order), each training
    view's embedding (`names`, the same order) and the head's weights (`as_photo` reads it)."""
    np.savez(path, features=np.asarray(features), embeddings=np.asarray(embeddings),
             names=np.asarray(names), **{k: np.asarray(head[k]) for k in HEAD_WEIGHTS})


def as_photo(scene: Gaussians, path: str, name: str) -> Gaussians:
    """The scene of a run's scene.ply (`scene`: at the views' average appearance, `baked`) as
    its training photo `name` shows it, from the run's appearance.npz at `path`: band 0 moved
    by h(e_name, f_i) / C0 − (1/V) Σ_v h(e_v, f_i) / C0."""
    z = np.load(path)
    names = [str(n) for n in z["names"]]
    if name not in names:
        raise ValueError(f"name: {name!r} is not a training view of {path} ({names[:3]}, ...)")
    if z["features"].shape[0] != scene.num:
        raise ValueError(f"scene: {scene.num} Gaussians, but {path} holds features of "
                         f"{z['features'].shape[0]}")
    head = {k: jnp.asarray(z[k]) for k in HEAD_WEIGHTS}
    f = jnp.asarray(z["features"])
    embeddings = jnp.asarray(z["embeddings"])
    move = (dc_change(head, embeddings[names.index(name)], f)
            - mean_dc_change(head, embeddings, f))
    return with_dc_change(scene, move)
