"""Per-pixel front-to-back compositing, exactly as docs/conventions.md "Compositing" defines it.

For each pixel, over Gaussians in (depth, index) order:
    d = (mean2d − pixel_centre) + mean2d_lo  (the centre μ = mean2d + mean2d_lo,
        lgs_jax.projection; the large parts cancel before the correction is added);
    power = −½(a·dx² + c·dy²) − b·dx·dy
    skip if power > 0;  α = min(cap, o·exp(power));  skip if α < 1/255
    test_T = T·(1 − α);  if test_T < 1e-4 (<= in the gsplat convention): pixel done, not blended
    else C += rgb·α·T;  D += z·α·T;  T = test_T
Output: image = C + T·background, alpha = 1 − T, depth = D.

This module is the readable reference that every backend's blending is tested against.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp

from . import twofloat
from .config import ALPHA_MIN, T_STOP, RasterConfig


@jax.tree_util.register_dataclass
@dataclasses.dataclass
class PixelState:
    """Running compositing state of a set of P pixels."""

    color: Any  # (P, 3) accumulated Σ rgb·α·T
    trans: Any  # (P,) transmittance T
    depth: Any  # (P,) accumulated Σ z·α·T
    done: Any  # (P,) bool: the stop test fired

    @classmethod
    def empty(cls, shape, dtype) -> "PixelState":
        """Nothing blended yet (T = 1) for pixels of the given shape (int or tuple)."""
        shape = (shape,) if isinstance(shape, int) else tuple(shape)
        return cls(color=jnp.zeros(shape + (3,), dtype), trans=jnp.ones(shape, dtype),
                   depth=jnp.zeros(shape, dtype), done=jnp.zeros(shape, bool))


def stops(trans, config: RasterConfig):
    """The stop test on a (candidate) transmittance: T < 1e-4, or T <= 1e-4 for gsplat."""
    t_stop = jnp.asarray(T_STOP, trans.dtype)
    return (trans <= t_stop) if config.stop_inclusive else (trans < t_stop)


def centre_offsets(mean2d, mean2d_lo, px, py):
    """d = μ − pixel centre (dx, dy) of a centre μ = mean2d + mean2d_lo (pairs (x, y)) at
    pixel centres (px, py): (mean2d − p) + mean2d_lo (`lgs_jax.twofloat.offset`)."""
    return (twofloat.offset(mean2d[0], mean2d_lo[0], px),
            twofloat.offset(mean2d[1], mean2d_lo[1], py))


def gaussian_alpha(d, conic, opacity, cap):
    """(power, α) of one Gaussian at offsets d = (dx, dy) from its centre (`centre_offsets`),
    in the 3DGS difference form."""
    dx, dy = d
    power = -0.5 * (conic[0] * dx * dx + conic[2] * dy * dy) - conic[1] * dx * dy
    alpha = jnp.minimum(cap, opacity * jnp.exp(power))
    return power, alpha


def passes(power, alpha):
    """The contract's alpha test of the difference form: power <= 0 and α >= 1/255."""
    return (power <= 0) & (alpha >= jnp.asarray(ALPHA_MIN, alpha.dtype))


def blend_weights(trans, alpha, hit, config: RasterConfig):
    """The blending rule of one Gaussian at pixels with transmittance T: (w, new T, stopped),
    with C += rgb·w, D += z·w by the caller. `hit`: the Gaussian passes the alpha test there
    (and, in exact blending, the pixel is not done). Every backend blends through this.

    exact (the contract): test_T = T·(1 − α); a hit whose test_T passes the stop test ends the
           pixel unblended (stopped); any other hit blends, w = α·T, T = test_T.
    fast (Sec. III-D, warp-coherent blending): w = α·T, T −= w for every hit; no per-pixel
           stop (stopped is None): the caller ends a strip when all its pixels have T < 1e-4.
    Written with `hit ^ (hit & stop)` for hit & ~stop: Mosaic GPU cannot negate a bool vector.
    """
    if config.blend == "fast":
        w = jnp.where(hit, alpha * trans, 0)
        return w, trans - w, None
    test_t = trans * (1 - alpha)
    stopped = hit & stops(test_t, config)
    take = hit ^ stopped
    return jnp.where(take, alpha * trans, 0), jnp.where(take, test_t, trans), stopped


def blend(state: PixelState, mean2d, mean2d_lo, conic, opacity, rgb, depth, active, px, py,
          config: RasterConfig) -> PixelState:
    """Composite one Gaussian over pixels (px, py) with exact blending (`blend_weights`);
    `active` (scalar bool) gates it entirely."""
    dt = state.trans.dtype
    power, alpha = gaussian_alpha(centre_offsets(mean2d, mean2d_lo, px, py), conic, opacity,
                                  jnp.asarray(config.alpha_cap, dt))
    hit = active & ~state.done & passes(power, alpha)
    w, trans, stopped = blend_weights(state.trans, alpha, hit, config)
    return PixelState(color=state.color + w[:, None] * rgb, trans=trans,
                      depth=state.depth + w * depth, done=state.done | stopped)


def finish(state: PixelState, background):
    """(image, alpha, depth) from a final state: image = C + T·background, alpha = 1 − T."""
    return state.color + state.trans[:, None] * background, 1 - state.trans, state.depth
