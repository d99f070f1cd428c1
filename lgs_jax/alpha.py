"""The α models, forward and derivative, one definition per form.

Every rasterizer evaluates α with one of these, elementwise on whatever arrays it holds (a tile's
pixels in XLA, a warp's lanes in a kernel), so the forward, the backward walk in XLA and the
Pallas kernels compute α with the same arithmetic in the same order, and each kernel's reference
is one call away. (Forward and backward must agree to the bit: a 1-ulp difference in α flips
alpha tests between them and, through T_k = T_{k+1}/(1 − α_k), grows into NaNs in training.)

Difference form (the contract, lgs_jax.composite), with d = μ − pixel centre formed by the
caller (`composite.centre_offsets`: (mean2d − p) + mean2d_lo; the Pallas kernels' pair records
from the tile corner, lgs_jax.backends.pallas.steps):
    power = −½(a·dx² + c·dy²) − b·dx·dy,  α = min(cap, o·e^power),
    hit = power <= 0 and α >= 1/255.
  Derivative, where the cap does not bind (o·e^power < cap), ∂α/∂power = α:
    ∂α/∂μx = −α·(a·dx + b·dy),  ∂α/∂μy = −α·(c·dy + b·dx),
    ∂α/∂a = −½α·dx²,  ∂α/∂b = −α·dx·dy,  ∂α/∂c = −½α·dy²,  ∂α/∂o = e^power.

Hoisted form (Local-GS Eq. 8–10), with raw = V·B the six-term dot product in the hoisting frame:
    ln α = min(raw, ln o)  (the clamp at the exact maximum ln o replaces the `power > 0` skip,
    which in the expanded form would fire on rounding at Gaussian centres),
    α = min(cap, e^{ln α}),  hit = ln α >= ln(1/255).
  e^{ln α} with `exp` (libdevice's `expf` on the GPU), not as 2^{ln α · log2 e}, which the GPU
  kernels would compile to one `ex2.approx`: fewer instructions, but an approximation whose
  effect on training was not shown to be nil (docs/design-notes.md). With `exp` the XLA paths,
  interpret mode and the GPU kernels compute the same e^{ln α} function.
  Derivative, where the cap does not bind (e^{ln α} < cap), ∂α/∂ln α = α:
    ∂α/∂raw = α where raw <= ln o (then ∂raw/∂V = B), ∂α/∂ln o = α where the clamp binds.
"""

from __future__ import annotations

import jax.numpy as jnp

from .composite import gaussian_alpha, passes
from .config import ALPHA_MIN


def difference(d, conic, opacity, cap):
    """(α, hit, power) of the difference form; d = (dx, dy) = μ − pixel, conic = (a, b, c)."""
    power, alpha = gaussian_alpha(d, conic, opacity, cap)
    return alpha, passes(power, alpha), power


def difference_vjp(d_alpha, alpha, power, d, conic, opacity, cap):
    """∂L/∂(μx, μy, a, b, c, o) per pixel from ∂L/∂α (zero where the pair does not hit), at
    the offsets d = (dx, dy) `difference` took."""
    unclamped = opacity * jnp.exp(power) < cap
    d_power = jnp.where(unclamped, d_alpha * alpha, 0)
    dx, dy = d
    a, b, c = conic
    return [-d_power * (a * dx + b * dy), -d_power * (c * dy + b * dx),
            -0.5 * d_power * dx * dx, -d_power * dx * dy, -0.5 * d_power * dy * dy,
            jnp.where(unclamped, d_alpha * jnp.exp(power), 0)]


def hoisted(raw, log_opacity, cap):
    """(α, hit, ln α) of the hoisted form from raw = V·B (`lgs_jax.hoist`) and ln o."""
    ln_a = jnp.minimum(raw, log_opacity)
    alpha = jnp.minimum(cap, jnp.exp(ln_a))
    return alpha, ln_a >= jnp.log(jnp.asarray(ALPHA_MIN, raw.dtype)), ln_a


def hoisted_vjp(d_alpha, alpha, ln_a, raw, log_opacity, cap):
    """(∂L/∂raw, ∂L/∂ln o) per pixel from ∂L/∂α and `hoisted`'s α, ln α; ∂L/∂V = ∂L/∂raw · B
    (Eq. 9's basis). The cap does not bind where α < cap, which is e^{ln α} < cap exactly
    (α = min(cap, e^{ln α}); both false for NaN), without a second exponential."""
    d_ln = jnp.where(alpha < cap, d_alpha * alpha, 0)
    on_v = raw <= log_opacity
    return jnp.where(on_v, d_ln, 0), jnp.where(on_v, 0, d_ln)
