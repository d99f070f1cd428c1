"""Warp-level culling masks (Local-GS Sec. III-C, Eq. 13–21), made conservative.

Each 16x16 tile is eight 16x2 strips (one 32-lane warp each). For a (tile, Gaussian) pair, the
tight box bounds the ellipse a·x̃² + 2b·x̃ỹ + c·ỹ² <= τ (Eq. 13, x̃ = pixel − μ) inside the tile's
column of pixel centres x̃ ∈ [x̃0, x̃1] (Eq. 14). Its top ỹ_max is

  case A, −b·d_y < a·x̃0 (peak left of the column):  ỹ_max = (−b·x̃0 + √(cτ − det·x̃0²))/c  (Eq. 17)
  case B, −b·d_y > a·x̃1 (peak right of the column): ỹ_max = (−b·x̃1 + √(cτ − det·x̃1²))/c  (Eq. 18)
  case C, otherwise (peak inside):                   ỹ_max = d_y = √(aτ/det)              (Eq. 16)

and symmetrically ỹ_min (the bottom point sits at x̃ = +b·d_y/a). Rows whose centres lie in
[μy + ỹ_min, μy + ỹ_max] map to strips by (row − tile_top) >> 1 (Eq. 20), and the mask is the run of
bits from the first to the last strip (Eq. 21).

Unlike the paper's published code (which shrinks the box by 0.95 and loses pixels) the mask is
conservative: τ is the padded threshold of the evaluated form (the difference form's bound from
lgs_jax.binning, widened by lgs_jax.hoist.error_bound for the pair records' forms, which take
their offsets from the tile's origin: lgs_jax.pairs), the determinant is a lower bound, and
every square root and coordinate gets outward slack for its own rounding. The box is
centred at mean2d, within |mean2d_lo| <= u·|mean2d| of the centre the forms evaluate from
(lgs_jax.projection), which the slack on x̃ (4u·(|left| + 16 + |μx|)) and on the rows
(8u·(|μy| + ...)) holds besides the rounding it pads.
"""

from __future__ import annotations

import jax.numpy as jnp

from .layout import STRIPS, TILE

FULL_MASK = (1 << STRIPS) - 1


def tight_box(a, b, c, tau, det, x0, x1):
    """(ỹ_min, ỹ_max, empty) of the ellipse q <= τ, conic (a, b, c), over the column
    x̃ ∈ [x̃0, x̃1] (Eq. 14–19).

    All arguments broadcast (columns, not stacked arrays: the Mosaic GPU forward evaluates this
    on lane vectors); `det` must be a positive lower bound of ac − b². The result is padded
    outward for the rounding of this computation, in the arrays' dtype.
    """
    u = jnp.finfo(a.dtype).eps / 2
    rx = jnp.sqrt(tau * c / det) * (1 + 8 * u)
    d_y = jnp.sqrt(tau * a / det) * (1 + 8 * u)  # Eq. 16
    x0c, x1c = jnp.maximum(x0, -rx), jnp.minimum(x1, rx)
    empty = x0c > x1c

    def edge(x, sign):
        """Upper (sign=+1) or lower (sign=−1) ellipse boundary at column x̃ = x, padded outward."""
        disc = jnp.maximum(c * tau - det * x * x, 0.0) + 4 * u * (c * tau + det * x * x)
        root = jnp.sqrt(disc)
        y = (-b * x + sign * root) / c
        return y + sign * 8 * u * (jnp.abs(b * x) + root) / c

    peak = -b * d_y  # compare with a·x̃ (division-free, as in the paper)
    y_max = jnp.where(peak < a * x0c, edge(x0c, 1.0),  # case A
                      jnp.where(peak > a * x1c, edge(x1c, 1.0), d_y))  # case B, C
    y_min = jnp.where(-peak < a * x0c, edge(x0c, -1.0),
                      jnp.where(-peak > a * x1c, edge(x1c, -1.0), -d_y))
    return jnp.maximum(y_min, -d_y), jnp.minimum(y_max, d_y), empty


def _floor(x):
    """floor(x) as int32 for |x| < 2^31, by truncation and one comparison (Mosaic GPU lowers
    neither floor nor ceil); exactly jnp.floor(x).astype(int32)."""
    i = x.astype(jnp.int32)
    return i - jnp.where(x < i.astype(x.dtype), 1, 0)


def _ceil(x):
    """ceil(x) as int32 for |x| < 2^31, as `_floor`."""
    i = x.astype(jnp.int32)
    return i + jnp.where(x > i.astype(x.dtype), 1, 0)


def strip_mask(mx, my, a, b, c, tau, det, tile_x, tile_y):
    """8-bit strip masks (Eq. 20–21) for Gaussians centred at (mx, my) with conic (a, b, c) in
    tiles (tile_x, tile_y) (int32; all arguments broadcast)."""
    dt = a.dtype
    u = jnp.finfo(dt).eps / 2
    left = (tile_x * TILE).astype(dt) + 0.5  # pixel-centre columns of the tile
    right = left + (TILE - 1)
    slack_x = 4 * u * (jnp.abs(left) + TILE + jnp.abs(mx))
    y_min, y_max, empty = tight_box(a, b, c, tau, det, left - mx - slack_x, right - mx + slack_x)
    top = (tile_y * TILE).astype(dt)
    slack_y = 8 * u * (jnp.abs(my) + jnp.maximum(jnp.abs(y_min), jnp.abs(y_max)) + 1.0)
    lo = jnp.clip(my + y_min - 0.5 - slack_y - top, -1.0, TILE)  # tile-local rows
    hi = jnp.clip(my + y_max - 0.5 + slack_y - top, -1.0, TILE)
    r0 = jnp.maximum(_ceil(lo), 0)
    r1 = jnp.minimum(_floor(hi), TILE - 1)
    w0, w1 = r0 >> 1, r1 >> 1
    mask = ((1 << (w1 - w0 + 1)) - 1) << w0  # Eq. 21
    return jnp.where(empty | (r0 > r1), 0, mask).astype(jnp.int32)
