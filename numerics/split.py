"""The split centre as the study takes it: μ = hi + lo from float32 parameters (the library's
arithmetic, lgs_jax.twofloat: one implementation), the plain float32 centre beside it, and the
offsets taken from it (numerics.centre measures what it removes).

`centre_split` computes μ = fx·tx/tz + cx (and y) with t = W·m + T from float32 world means
to O(u²)·|μ| (`lgs_jax.twofloat.camera_coordinates`, `screen_centre`), as
`lgs_jax.projection` carries it (mean2d, mean2d_lo); `plain_centre` is μ computed in float32
in one number, as 3DGS does (and the projection's derivative). `offset` forms d = (hi − p) + lo
(or Δ = (hi − T) + lo), the large parts cancelling exactly before lo is added.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from lgs_jax import hoist, twofloat
from lgs_jax.twofloat import offset

from . import forms


def plain_centre(means, viewmat, fx, fy, cx, cy):
    """μ = fx·tx/tz + cx (and y), t = W·m + T, in float32 in one number (N, 2): the centre
    without the split, whose rounding is the floor numerics.centre measures."""
    t = [viewmat[i, 0] * means[:, 0] + viewmat[i, 1] * means[:, 1] + viewmat[i, 2] * means[:, 2]
         + viewmat[i, 3] for i in range(3)]
    return jnp.stack([fx * t[0] / t[2] + cx, fy * t[1] / t[2] + cy], -1)


def centre_split(means, viewmat, fx, fy, cx, cy, compensated_transform=True):
    """The screen-space centres of float32 world means (N, 3) as (hi, lo), each (N, 2) float32,
    hi + lo = fx·tx/tz + cx (and y) to O(u²)·|μ| (lgs_jax.twofloat, as the projection). Without
    `compensated_transform` the camera transform t = W·m + T is the plain float32 one, the
    rest split (the study's variant: the library always compensates)."""
    m = [means[:, k] for k in range(3)]
    if compensated_transform:
        t = twofloat.camera_coordinates(viewmat, m)
    else:
        zero = jnp.zeros_like(m[0])
        t = [(viewmat[i, 0] * m[0] + viewmat[i, 1] * m[1] + viewmat[i, 2] * m[2]
              + viewmat[i, 3], zero) for i in range(3)]
    (hx, lx), (hy, ly) = twofloat.screen_centre(*t, fx, fy, cx, cy)
    return jnp.stack([hx, hy], -1), jnp.stack([lx, ly], -1)


def split_to_integer(hi, lo):
    """The tile-relative storage of a split centre: (K, r) with K = round(hi) (an integer,
    exact in float32 below 2^24) and r = (hi − K) + lo (hi − K exact), μ = K + r."""
    k = jnp.round(hi)
    return k, (hi - k) + lo


def log_alpha_split(form, hi, lo, pixel, conic, log_o):
    """ln α of the difference or local_corner form with the offset taken from a split centre
    (`offset`); float32 in, float32 out (NumPy)."""
    if form == "difference":
        d = np.asarray(offset(hi, lo, pixel))
        zero = np.zeros_like(pixel)
        return forms.log_alpha("difference", d, zero, conic, log_o)
    origin = forms.tile_origin("local_corner", pixel).astype(pixel.dtype)
    delta = np.asarray(offset(hi, lo, origin))
    v = np.asarray(hoist.hoist(delta, conic, log_o, np.zeros_like(delta)))
    local = pixel - origin
    return np.sum(v * np.asarray(hoist.basis(local[..., 0], local[..., 1])), -1,
                  dtype=pixel.dtype)
