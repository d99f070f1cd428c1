"""The training views' own parameters, optimized beside the scene's: each view's pose delta
(`camera_opt`, `Recipe.pose_opt`), colour correction (`color_opt`, `Recipe.color_opt`),
bilateral grid (`bilateral_grid`, `Recipe.bilateral_grid`) and appearance embedding with the
head the views share (`appearance`, `Recipe.app_opt`).

The state is a dict, part name -> (params, their optimizer state), holding the parts switched
on, or None with none (`init`): a part's params are (views, SIZE) float32, zero at the start,
or, for a part marked `shared` (the appearance head), one pytree every view uses, from the
part's `init(recipe, views, key)`. A step's views take their rows as onehot(idx) · P
(`rows`: exact, one nonzero term a row; a shared part whole), so each view's
gradient is onehot(idx)ᵀ times the rows' gradients: a dot, summed in one order where a view
comes twice in a batch, with no scatter-add (deterministic on GPUs). The other views' rows get
no gradient. After each part's update (`update`) the part's `project` runs (the colour
corrections and grids are centred over the views). A part's `regularizer`, where it has one,
adds to the loss over every view's parameters (`regularizer`: the grids' total variation).
A step's render is corrected by the colour map, then by the grid (`corrected`); with
embeddings, each view sees the Gaussians' band 0 moved by the head (`appearance.seen`).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import optax

from . import appearance, bilateral_grid, camera_opt, color_opt

PARTS = {"color": color_opt, "grid": bilateral_grid, "pose": camera_opt, "embed": appearance,
         "head": appearance.HEAD}
"""name -> module (or object) with SIZE, enabled(recipe), optimizer(recipe, steps),
project(params), and optionally regularizer(recipe, params); a `shared` part has init
instead of SIZE."""
APPEARANCE = ("color", "grid")  # the parts that correct a render, in the order they apply


def init(recipe, views: int, steps: int, key=None):
    """{name: (params, optimizer state)} of the parts `recipe` switches on, for a run of
    `steps`, or None: zeros (views, SIZE), a shared part's from its init with `key` (a JAX key;
    the run's seed's)."""
    state = {}
    for name, part in PARTS.items():
        if part.enabled(recipe):
            if _shared(part):
                p = part.init(recipe, views, jax.random.key(0) if key is None else key)
            else:
                p = jnp.zeros((views, part.SIZE), jnp.float32)
            state[name] = (p, part.optimizer(recipe, steps).init(p))
    return state or None


def _shared(part) -> bool:
    return getattr(part, "shared", False)


def params(state):
    """{name: params (views, SIZE)} of `state`, or None."""
    return None if state is None else {name: p for name, (p, _) in state.items()}


def rows(params_, idx):
    """{name: rows (B, SIZE) of the views idx (B,)} (module docstring), a shared part's params
    whole, or None."""
    if params_ is None:
        return None
    per_view = {name: p for name, p in params_.items() if not _shared(PARTS[name])}
    views = next(iter(per_view.values())).shape[0]  # a shared part comes with a per-view one
    onehot = (idx[:, None] == jnp.arange(views)[None, :]).astype(jnp.float32)
    return {name: p if name not in per_view else
            jnp.einsum("bv,vk->bk", onehot, p, precision=jax.lax.Precision.HIGHEST)
            for name, p in params_.items()}


def regularizer(recipe, params_):
    """The loss's terms of the views' parameters {name: (views, SIZE)} (or None): 0 without."""
    return sum(PARTS[name].regularizer(recipe, p) for name, p in (params_ or {}).items()
               if hasattr(PARTS[name], "regularizer"))


def corrected(image, own: dict):
    """`image` (H, W, 3) of a view corrected by its rows `own` {name: (SIZE,)} of the
    appearance parts it has (colour map, then grid)."""
    for name in APPEARANCE:
        if name in own:
            image = PARTS[name].corrected(image, own[name])
    return image


def update(recipe, steps: int, state, grads):
    """`state` after one step of a run of `steps` with the gradients {name: (views, SIZE)} of
    its params."""
    new = {}
    for name, (p, opt_state) in state.items():
        part = PARTS[name]
        updates, opt_state = part.optimizer(recipe, steps).update(grads[name], opt_state, p)
        new[name] = (part.project(optax.apply_updates(p, updates)), opt_state)
    return new
