"""A fixed-size pool of Gaussians with an active mask: training in static shapes.

Densification changes the number of Gaussians; JAX programs need static shapes. So the scene
lives in a pool of `size` slots, `active` marking those in use:
  - an inactive slot is rendered as a placeholder Gaussian (mean 0, quaternion (1, 0, 0, 0),
    log-scales 0, logit opacity −inf) with its stored SH coefficients: opacity 0 < 1/255, so
    projection culls it and it makes no tile pairs; `jnp.where` selects the placeholder, so its
    stored values get exactly zero gradient, its SH coefficients too (a culled Gaussian's colour
    reaches no pixel), and their Adam moments, zero when freed, stay zero: Adam then leaves it
    still. The SH coefficients go to the projection as stored, not masked: its checkpoint keeps
    its inputs for the backward, so a masked copy would be held through the whole backward (the
    largest temporary of a step beside the backward's rows; the inactive slots' coefficients
    are finite, as every stored value);
  - an inactive slot's stored values are not otherwise read: strategies overwrite them when
    they take the slot (`ops.allocate`);
  - the pool grows by doubling (`grow`), outside jit: a rare recompile, which `fit` logs.
Parameters are stored pre-activation, as in INRIA PLY files, in the optimizer's groups
(`GROUPS`; the SH coefficients one group, band 0 and the higher bands at their own learning
rates, `optim.optimizer`).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from ..parallel.shards import to_host
from ..scene import Gaussians

GROUPS = ("means", "quats", "log_scales", "logit_opacities", "sh")
OPTIONAL_GROUPS = ("features",)  # `appearance`'s per-Gaussian features, with Recipe.app_opt


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Pool:
    """params: dict GROUPS -> (size, ...) arrays (means (N, 3), quats (N, 4) w x y z,
    log_scales (N, 3), logit_opacities (N,), sh (N, K, 3); with
    appearance embeddings also features (N, appearance.FEATURES)); active: (size,) bool."""

    params: dict
    active: Any

    @property
    def size(self) -> int:
        return int(np.shape(self.active)[0])


def rows(mask, x):
    """A per-Gaussian (N,) mask reshaped to broadcast against x (N, ...)."""
    return jnp.reshape(mask, jnp.shape(mask) + (1,) * (jnp.ndim(x) - 1))


def from_gaussians(g: Gaussians, size: int | None = None) -> Pool:
    """A pool holding `g` active in its first g.num slots, `size` slots in all (default g.num)."""
    n = g.num
    size = n if size is None else size
    if size < n:
        raise ValueError(f"size: {size} slots cannot hold {n} Gaussians")
    params = dict(means=g.means, quats=g.quats, log_scales=g.log_scales,
                  logit_opacities=g.logit_opacities, sh=g.sh)
    params = {k: jnp.asarray(v) for k, v in params.items()}
    pool = Pool(params, jnp.ones(n, bool))
    return pad(pool, size)


def pad(pool: Pool, size: int) -> Pool:
    """`pool` with `size - pool.size` inactive slots (zeros) appended."""
    extra = size - pool.size
    params = {k: jnp.concatenate([v, jnp.zeros((extra,) + v.shape[1:], v.dtype)])
              for k, v in pool.params.items()}
    return Pool(params, jnp.concatenate([pool.active, jnp.zeros(extra, bool)]))


def sh_mask(step, num_bases: int, every: int):
    """(num_bases,) mask of the SH bands in use at 0-based `step`: degree min(step // every,
    max degree) (gsplat's simple_trainer: one more band every `every` steps)."""
    degree = jnp.minimum(step // every, int(round(np.sqrt(num_bases))) - 1)
    band = jnp.asarray([int(np.sqrt(k)) for k in range(num_bases)])
    return (band <= degree).astype(jnp.float32)


def render_gaussians(params: dict, active) -> Gaussians:
    """The Gaussians `render` sees: active slots as stored, inactive slots as the culled
    placeholder with their stored SH coefficients (module docstring; the SH bands a schedule
    has not enabled are `render`'s `sh_bands`, `sh_mask`)."""
    def pick(x, placeholder):
        return jnp.where(rows(active, x), x, jnp.asarray(placeholder, x.dtype))

    return Gaussians(pick(params["means"], 0.0),
                     pick(params["quats"], jnp.array([1.0, 0.0, 0.0, 0.0])),
                     pick(params["log_scales"], 0.0), pick(params["logit_opacities"], -jnp.inf),
                     params["sh"])


def active_gaussians(pool: Pool) -> Gaussians:
    """The active Gaussians (host numpy arrays, in slot order): what a PLY file holds."""
    active, params = to_host((pool.active, pool.params))  # `parallel.to_host`: any process
    p = {k: v[active] for k, v in params.items()}
    return Gaussians(p["means"], p["quats"], p["log_scales"], p["logit_opacities"], p["sh"])


def per_gaussian(tree, size: int, fn):
    """Apply fn to every array leaf of `tree` whose leading axis is `size` (per-Gaussian state:
    Adam moments, a strategy's accumulators); other leaves (counts, scalars) are kept."""
    def f(x):
        return fn(x) if hasattr(x, "shape") and np.ndim(x) >= 1 and x.shape[0] == size else x
    return jax.tree.map(f, tree)


def grow(pool: Pool, opt_state, strategy_state, size: int):
    """(pool, opt_state, strategy_state) with the pool enlarged to `size` slots: new slots
    inactive, their parameters, Adam moments and strategy accumulators zero; nothing else
    changes (the slot indices of the Gaussians included)."""
    if size <= pool.size:
        raise ValueError(f"size: {size} is not larger than the pool's {pool.size} slots")
    extra = size - pool.size

    def zero_pad(x):
        return jnp.concatenate([x, jnp.zeros((extra,) + x.shape[1:], x.dtype)])

    return (pad(pool, size), per_gaussian(opt_state, pool.size, zero_pad),
            per_gaussian(strategy_state, pool.size, zero_pad))
