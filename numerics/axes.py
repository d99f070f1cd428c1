"""The principal axes of the projected covariance in float32, from its factor (the robust form's
setup without float64).

`lgs_jax.projection` forms Σ2 = J·Σc·Jᵀ + 0.3·I entry by entry and inverts it: for a needle the
entries are ~σmax² while the small eigenvalue is ~0.3, so the float32 entries (absolute error
~u·σmax²) fix the small eigenvalue, and the conic, only to a relative error of u·σmax²/0.3 (the
needle error of numerics/results/REPORT.md). The same matrix has the factor

    Σ2 = A·Aᵀ + 0.3·I,   A = J·W·R(q)·S   (2x3),

and the factor's singular values σ₁ >= σ₂ carry an absolute error of ~u·σ₁ only, so
λᵢ = σᵢ² + 0.3 errs by ~2u·σ₁·σᵢ, which is small against 0.3 where it matters. `principal_axes`
computes them without forming A·Aᵀ: a QR factorisation of Aᵀ (3x2, modified Gram–Schmidt with
one re-orthogonalisation) gives the 2x2 upper-triangular R with A·Aᵀ = Rᵀ·R, whose eigenvalues
follow without cancellation from their sum r₁₁² + r₁₂² + r₂₂² and product (r₁₁·r₂₂)², and the
major axis at θ = ½·atan2(2·r₁₁·r₁₂, r₁₁² − r₁₂² − r₂₂²). Per Gaussian: the factor (as the
projection's W·R·S, then J), ~40 multiply-adds of QR, a square root, an atan2, a sine and a
cosine, all float32; per exponent the principal-axes form of numerics.forms.
"""

from __future__ import annotations

import jax.numpy as jnp

from lgs_jax.projection import EPS2D, quat_to_rotmat


def factor(means, quats, log_scales, viewmat, fx, fy, cx, cy, width, height):
    """A = J·W·R(q)·S (N, 2, 3) of float32 Gaussians, J the EWA Jacobian at the clamped
    camera-space centre (as lgs_jax.projection computes it)."""
    w = viewmat[:3, :3]
    t = means @ w.T + viewmat[:3, 3]
    tz = t[:, 2]
    tan_x, tan_y = 0.5 * width / fx, 0.5 * height / fy
    tx = tz * jnp.clip(t[:, 0] / tz, -(cx / fx + 0.3 * tan_x), (width - cx) / fx + 0.3 * tan_x)
    ty = tz * jnp.clip(t[:, 1] / tz, -(cy / fy + 0.3 * tan_y), (height - cy) / fy + 0.3 * tan_y)
    zero = jnp.zeros_like(tz)
    jac = jnp.stack([jnp.stack([fx / tz, zero, -fx * tx / (tz * tz)], -1),
                     jnp.stack([zero, fy / tz, -fy * ty / (tz * tz)], -1)], -2)
    wrs = jnp.einsum("ij,njk->nik", w, quat_to_rotmat(quats),
                     precision="highest") * jnp.exp(log_scales)[:, None, :]
    return jnp.einsum("nij,njk->nik", jac, wrs, precision="highest")


def _dot(a, b):
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


def principal_axes(a):
    """(λ₁, λ₂, e₁) of Σ2 = A·Aᵀ + EPS2D·I from factors A (N, 2, 3): λ₁ >= λ₂, e₁ (N, 2) the
    unit axis of λ₁ (module docstring)."""
    c1, c2 = a[:, 0], a[:, 1]
    r11 = jnp.sqrt(_dot(c1, c1))
    q1 = c1 / jnp.where(r11 > 0, r11, 1.0)[:, None]
    r12 = _dot(q1, c2)
    v = c2 - r12[:, None] * q1
    s = _dot(q1, v)  # re-orthogonalise once: v loses q1's component to rounding
    v = v - s[:, None] * q1
    r12 = r12 + s
    r22 = jnp.sqrt(_dot(v, v))
    total = r11 * r11 + r12 * r12 + r22 * r22
    gap = r11 * r11 - r12 * r12 - r22 * r22
    cross = 2 * r11 * r12
    big = 0.5 * (total + jnp.sqrt(gap * gap + cross * cross))
    small = (r11 * r22) ** 2 / jnp.where(big > 0, big, 1.0)
    theta = 0.5 * jnp.arctan2(cross, gap)
    return big + EPS2D, small + EPS2D, jnp.stack([jnp.cos(theta), jnp.sin(theta)], -1)
