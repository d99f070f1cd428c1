"""Gaussian parameter hoisting (Local-GS Sec. III-B, Eq. 1–10).

With the tile origin T (the tile's top-left corner, Eq. 1, or its centre) and Δ = μ − T (Eq. 2),

    ln α = ln o − ½[a(x' − Δx)² + 2b(x' − Δx)(y' − Δy) + c(y' − Δy)²]          (Eq. 6)
         = A x'² + B x'y' + C y'² + D x' + E y' + F                           (Eq. 7)

    [A, B, C, D, E, F] = [−½a, −b, −½c, aΔx + bΔy, bΔx + cΔy,
                          −½aΔx² − bΔxΔy − ½cΔy² + ln o]                      (Eq. 8)

so per-pixel ln α is one dot product V·[x'², x'y', y'², x', y', 1] (Eq. 9–10). In global
coordinates (`local_coords=False`) T = (0, 0) and x' is the global pixel centre.
"""

from __future__ import annotations

import jax.numpy as jnp


def hoist_terms(a, b, c, dx, dy, log_opacity):
    """The six components (A, B, C, D, E, F) of Eq. 8 from the conic and Δ = μ − T, as separate
    arrays (kernels keep them in registers; `hoist` stacks them)."""
    return (-0.5 * a, -b, -0.5 * c, a * dx + b * dy, b * dx + c * dy,
            -0.5 * a * dx * dx - b * dx * dy - 0.5 * c * dy * dy + log_opacity)


def hoist_terms_vjp(g, a, b, c, dx, dy):
    """The transpose of Eq. 8's Jacobian: ∂L/∂(a, b, c, Δx, Δy, ln o) from g = ∂L/∂V (six
    values; arrays or scalars), as the backward chains each pair's ∂L/∂V to its Gaussian:

        ∂a = −½g₀ + g₃Δx − ½g₅Δx²,   ∂b = −g₁ + g₃Δy + g₄Δx − g₅ΔxΔy,
        ∂c = −½g₂ + g₄Δy − ½g₅Δy²,   ∂Δx = g₃a + g₄b − g₅(aΔx + bΔy),
        ∂Δy = g₃b + g₄c − g₅(bΔx + cΔy),   ∂ln o = g₅.
    """
    g0, g1, g2, g3, g4, g5 = g
    return (-0.5 * g0 + g3 * dx - 0.5 * g5 * (dx * dx),
            -g1 + g3 * dy + g4 * dx - g5 * (dx * dy),
            -0.5 * g2 + g4 * dy - 0.5 * g5 * (dy * dy),
            g3 * a + g4 * b - g5 * (a * dx + b * dy),
            g3 * b + g4 * c - g5 * (b * dx + c * dy),
            g5)


def hoist(mean2d, conic, log_opacity, origin):
    """The hoisted 6-vector V (Eq. 8) of Gaussians (..., ) relative to tile origins (..., 2)."""
    dx, dy = mean2d[..., 0] - origin[..., 0], mean2d[..., 1] - origin[..., 1]
    return jnp.stack(hoist_terms(conic[..., 0], conic[..., 1], conic[..., 2], dx, dy,
                                 log_opacity), axis=-1)


def dot_basis(v, basis):
    """V·B (Eq. 10) as six elementwise products summed left to right: v (..., 6) and basis
    (..., 6) broadcast. No matrix unit, so no TF32 and no contraction order that depends on the
    batch shape: the tiles forward and its backward get the same bits (under vmap too)."""
    out = v[..., 0] * basis[..., 0]
    for i in range(1, 6):
        out = out + v[..., i] * basis[..., i]
    return out


def evaluate_terms(v, x, y):
    """ln α = A·x'² + B·x'y' + C·y'² + D·x' + E·y' + F (Eq. 10) from the six terms of Eq. 8, in
    this summation order (kernels; the tiles backend takes the same sum as a batched product)."""
    return v[0] * (x * x) + v[1] * (x * y) + v[2] * (y * y) + v[3] * x + v[4] * y + v[5]


def basis(x, y):
    """The local pixel basis B = [x'², x'y', y'², x', y', 1] (Eq. 9) at coordinates (x', y')."""
    return jnp.stack([x * x, x * y, y * y, x, y, jnp.ones_like(x)], axis=-1)


def error_bound(mean2d, conic, log_opacity, origin, reach_x, reach_y, gamma):
    """Bound on |fl(V·B) − ln α| over pixels with |x'| <= reach_x, |y'| <= reach_y.

    Every term of Eq. 7, and every term formed while computing V (Eq. 8), is bounded by the
    corresponding term of ½a(|Δx| + X)² + |b|(|Δx| + X)(|Δy| + Y) + ½c(|Δy| + Y)² + |ln o|; the
    float evaluation of V and the 6-term dot product errs by at most γ times that sum
    (γ = 16u is generous for both).
    """
    return error_bound_terms(conic[..., 0], conic[..., 1], conic[..., 2],
                             mean2d[..., 0] - origin[..., 0], mean2d[..., 1] - origin[..., 1],
                             log_opacity, reach_x, reach_y, gamma)


def error_bound_terms(a, b, c, dx, dy, log_opacity, reach_x, reach_y, gamma):
    """`error_bound` from the conic's and Δ = μ − T's components (separate arrays, as
    `hoist_terms` takes them)."""
    dx = jnp.abs(dx) + reach_x
    dy = jnp.abs(dy) + reach_y
    return gamma * (0.5 * a * dx * dx + jnp.abs(b) * dx * dy + 0.5 * c * dy * dy
                    + jnp.abs(log_opacity))
