"""The optimizer: Adam per parameter group, and how its moments follow the Gaussians.

`optimizer(recipe, steps, scene_scale)` is gsplat's simple_trainer recipe: Adam (β = 0.9,
0.999, ε = 1e-15) on every group, learning rates means 1.6e-4 · scene_scale decaying
exponentially to 1% of that over the run (lr_s = lr_0 · 0.01^(s / steps) at update s, torch's
ExponentialLR with γ = 0.01^(1 / steps)), quats 1e-3, log-scales 5e-3, logit opacities 5e-2,
SH band 0 2.5e-3, higher bands 2.5e-3 / 20 (one group, `sh`, its rate a pair: band 0's and
the others'), appearance features (`appearance`, where the pool has them) 2.5e-3. It is one
`optax.scale_by_adam` over the whole
parameter dict followed by a per-group rate, so the Adam moments `mu` and `nu` are dicts shaped
like the parameters, and `zero_moments` starts rows afresh.

Moments under densification (gsplat 1.5.3's strategy ops, `ops.py`): a row that receives a new
Gaussian has its moments zeroed or kept as gsplat does (none is copied to another row); Adam's
step count is shared and never reset (torch keeps the per-parameter `step` too).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax

from .pool import GROUPS, OPTIONAL_GROUPS, rows


class GroupRateState(NamedTuple):
    count: jax.Array  # updates applied so far


def scale_by_group_rates(rates: dict) -> optax.GradientTransformation:
    """updates[g] ← −rate_g(count) · updates[g] per parameter group g; a rate is a float, an
    optax schedule of the update count, or a pair of floats (band 0's, the other bands') for
    SH coefficients (N, K, 3), which scales their axis 1."""
    def init(params):
        del params
        return GroupRateState(jnp.zeros([], jnp.int32))

    def update(updates, state, params=None):
        del params
        lr = {k: r(state.count) if callable(r) else r for k, r in rates.items()}
        updates = {k: (-_per_band(lr[k], u) * u).astype(u.dtype) for k, u in updates.items()}
        return updates, GroupRateState(optax.safe_increment(state.count))

    return optax.GradientTransformation(init, update)


def _per_band(rate, u):
    """`rate`, or for a pair (band 0's, the other bands') the rate of each of u's K bands
    (1, K, 1), in u's dtype (as a float multiplying u would be rounded)."""
    if not isinstance(rate, tuple):
        return rate
    k = u.shape[1]
    return np.where(np.arange(k) == 0, rate[0], rate[1]).reshape(1, k, 1).astype(u.dtype)


def means_schedule(recipe, steps: int, scene_scale: float):
    """The means' learning rate at update s: lr_means · scene_scale · ratio^(s / steps)."""
    lr0 = recipe.lr_means * scene_scale
    return optax.exponential_decay(lr0, max(steps, 1), recipe.lr_means_decay)


def optimizer(recipe, steps: int, scene_scale: float) -> optax.GradientTransformation:
    """Adam per group with the recipe's rates (module docstring)."""
    rates = dict(means=means_schedule(recipe, steps, scene_scale), quats=recipe.lr_quats,
                 log_scales=recipe.lr_log_scales,
                 logit_opacities=recipe.lr_logit_opacities,
                 sh=(recipe.lr_sh_dc, recipe.lr_sh_rest), features=recipe.lr_features)
    return optax.chain(optax.scale_by_adam(b1=0.9, b2=0.999, eps=1e-15),
                       scale_by_group_rates(rates))


def torch_adam(lr, weight_decay: float, eps: float = 1e-8) -> optax.GradientTransformation:
    """torch.optim.Adam at rate `lr` (a float, or a schedule of the update count) with β = 0.9,
    0.999 and `eps` (torch's default 1e-8), and L2 `weight_decay` added to the gradient (torch's
    coupled weight decay; none where 0): the optimizer of the views' own parameters
    (`camera_opt`, `color_opt`, `bilateral_grid`), as gsplat's trainer builds them."""
    decay = [optax.add_decayed_weights(weight_decay)] if weight_decay else []
    return optax.chain(*decay, optax.scale_by_adam(b1=0.9, b2=0.999, eps=eps),
                       optax.scale_by_learning_rate(lr))


def _is_moments(x) -> bool:
    return isinstance(x, dict) and set(GROUPS) <= set(x) <= set(GROUPS + OPTIONAL_GROUPS)


def map_moments(opt_state, fn):
    """opt_state with every parameter-shaped dict (Adam's mu and nu) mapped group-wise:
    d[g] ← fn(g, d[g])."""
    def f(x):
        return {k: fn(k, v) for k, v in x.items()} if _is_moments(x) else x
    return jax.tree.map(f, opt_state, is_leaf=_is_moments)


def zero_moments(opt_state, fresh, groups=None):
    """Moments of the rows in `fresh` zeroed, in `groups` (None: every group): elementwise, so
    that a donated state is written in place."""
    def f(group, m):
        if groups is not None and group not in groups:
            return m
        return jnp.where(rows(fresh, m), jnp.zeros((), m.dtype), m)
    return map_moments(opt_state, f)

