"""A rasterizer with a custom backward, from its two halves: the one way reverse-mode enters a
backend whose forward walks pairs in while loops (which `jax.grad` cannot differentiate)."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
from jax.custom_derivatives import SymbolicZero

from ..projection import Projected


def differentiable(forward, gradients, forward_for_gradients=None):
    """composite(p, bins, extra, width, height, static) -> (color, trans, depth, stop_at,
    stats), per tile (stop_at: int32, not differentiated), from

      forward(p, bins, extra, width, height, static) -> (state, stop_at, stats, saved): the
        composited PixelState (n_tiles, 256), the stop pairs, the backend's stats and what the
        backward reuses (`saved`, O(pairs));
      gradients(p, bins, extra, width, height, static, trans, stop_at, saved, (ḡ_C, ḡ_T, ḡ_D))
        -> (N, 10) per-Gaussian ∂L/∂(mean2d, conic, opacity, rgb, depth) (backward.PAIR_COLUMNS
        order); ḡ_D is None where the loss does not reach the depth (a symbolic zero:
        `backward.depth_cotangent`).

    `extra`: per-Gaussian inputs the backend built beforehand (not differentiated; None where
    there are none); `static`: the backend's hashable configuration. `forward_for_gradients`
    (same signature; default `forward`) is the forward run when the backward will follow
    (under `jax.grad` / `jax.vjp`). The projection's other fields (cov2d, valid, invalid) get
    no cotangent: the backward's gradients are the projected fields' whole derivative; nor
    does mean2d_lo, a constant correction of the centre (lgs_jax.projection).
    """
    @functools.partial(jax.custom_vjp, nondiff_argnums=(3, 4, 5))
    def composite(p: Projected, bins, extra, width: int, height: int, static):
        state, stop_at, stats, _ = forward(p, bins, extra, width, height, static)
        return state.color, state.trans, state.depth, stop_at, stats

    def composite_fwd(p, bins, extra, width, height, static):
        # symbolic_zeros: the leaves come as CustomVJPPrimal(value, perturbed)
        p, bins, extra = jax.tree.map(lambda x: x.value, (p, bins, extra))
        state, stop_at, stats, saved = (forward_for_gradients or forward)(p, bins, extra, width,
                                                                          height, static)
        return ((state.color, state.trans, state.depth, stop_at, stats),
                (p, bins, extra, state.trans, stop_at, saved))

    def composite_bwd(width, height, static, residuals, cotangents):
        p, bins, extra, trans, stop_at, saved = residuals
        g_color, g_trans, g_depth = cotangents[:3]
        g_color, g_trans = (jnp.zeros(g.shape, g.dtype) if isinstance(g, SymbolicZero) else g
                            for g in (g_color, g_trans))
        g_depth = None if isinstance(g_depth, SymbolicZero) else g_depth
        per = gradients(p, bins, extra, width, height, static, trans, stop_at, saved,
                        (g_color, g_trans, g_depth))
        grad_p = Projected(mean2d=per[:, 0:2], mean2d_lo=None, cov2d=None, conic=per[:, 2:5],
                           depth=per[:, 9], opacity=per[:, 5], rgb=per[:, 6:9], valid=None,
                           invalid=None)
        return grad_p, None, None

    # Symbolic zeros: a loss of the image alone leaves the depth's cotangent a symbolic zero,
    # which the backward then neither materialises nor reads nor multiplies per pair.
    composite.defvjp(composite_fwd, composite_bwd, symbolic_zeros=True)
    return composite
