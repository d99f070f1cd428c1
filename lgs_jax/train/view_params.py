"""The training views' own parameters, optimized beside the scene's: each view's pose delta
(`camera_opt`, `Settings.pose_opt`) and colour correction (`color_opt`, `Settings.color_opt`).

The state is a dict, part name -> (params (views, SIZE) float32, zero at the start, their
optimizer state), holding the parts switched on, or None with neither (`init`). A step's views
take their rows as onehot(idx) · P (`rows`: exact, one nonzero term a row), so each view's
gradient is onehot(idx)ᵀ times the rows' gradients: a dot, summed in one order where a view
comes twice in a batch, with no scatter-add (deterministic on GPUs). The other views' rows get
no gradient. After each part's update (`update`) the part's `project` runs (the colour
corrections are centred over the views).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import optax

from . import camera_opt, color_opt

PARTS = {"color": color_opt, "pose": camera_opt}
"""name -> module with SIZE, enabled(settings), optimizer(settings), project(params)."""


def init(settings, views: int):
    """{name: (zeros (views, SIZE), optimizer state)} of the parts `settings` switches on, or
    None."""
    state = {}
    for name, part in PARTS.items():
        if part.enabled(settings):
            p = jnp.zeros((views, part.SIZE), jnp.float32)
            state[name] = (p, part.optimizer(settings).init(p))
    return state or None


def params(state):
    """{name: params (views, SIZE)} of `state`, or None."""
    return None if state is None else {name: p for name, (p, _) in state.items()}


def rows(params_, idx):
    """{name: rows (B, SIZE) of the views idx (B,)} (module docstring), or None."""
    if params_ is None:
        return None
    views = next(iter(params_.values())).shape[0]
    onehot = (idx[:, None] == jnp.arange(views)[None, :]).astype(jnp.float32)
    return {name: jnp.einsum("bv,vk->bk", onehot, p, precision=jax.lax.Precision.HIGHEST)
            for name, p in params_.items()}


def update(settings, state, grads):
    """`state` after one step with the gradients {name: (views, SIZE)} of its params."""
    new = {}
    for name, (p, opt_state) in state.items():
        part = PARTS[name]
        updates, opt_state = part.optimizer(settings).update(grads[name], opt_state, p)
        new[name] = (part.project(optax.apply_updates(p, updates)), opt_state)
    return new
