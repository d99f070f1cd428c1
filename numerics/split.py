"""The split centre: a screen-space centre μ = hi + lo as two float32 numbers, from float32
parameters, and the offsets taken from it (numerics.centre measures what it removes).

`centre_split` computes μ = fx·tx/tz + cx (and y) with t = W·m + T from float32 world means
to O(u²)·|μ|: the camera transform as a compensated dot product, then the division, the focal
length and the principal point in double-float32 arithmetic. `offset` forms d = (hi − p) + lo
(or Δ = (hi − T) + lo), the large parts cancelling exactly before lo is added.

Error-free transformations (Knuth's TwoSum, Dekker's TwoProduct) in float32 under XLA: XLA's CPU
and GPU compilers contract a·b + c into a fused multiply-add where they choose, which breaks
Veltkamp's arithmetic splitting (c = 4097·a; a_hi = c − (c − a)) and any TwoSum whose operand is
a rounded product. `split_bits` splits by clearing the low 12 significand bits (a bit mask: no
rounding to contract), `two_prod` adds only exact partial products, and every other product
is a correction term, so that a contraction cannot change what the transformations compute.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from lgs_jax import hoist

from . import forms


def split_bits(a):
    """(hi, lo) with hi = a with its low 12 significand bits cleared, lo = a − hi (exact): both
    have at most 12 significant bits, so their products are exact in float32."""
    hi = jax.lax.bitcast_convert_type(
        jax.lax.bitcast_convert_type(a, jnp.uint32) & jnp.uint32(0xFFFFF000), jnp.float32)
    return hi, a - hi


def two_sum(a, b):
    """(s, e): s = fl(a + b), s + e = a + b exactly (Knuth)."""
    s = a + b
    bb = s - a
    return s, (a - (s - bb)) + (b - bb)


def two_prod(a, b):
    """(p, e): p + e = a·b to O(u²)·|a·b|, p ≈ fl(a·b), from the four partial products of
    `split_bits` halves (each exact) summed by `two_sum`. No product that rounds is ever added
    to anything, so a multiply-add contracted by the compiler computes the same bits (Dekker's
    p = fl(a·b) followed by a TwoSum of p lets XLA fuse p into the sum: measured wrong under
    jit on the CPU)."""
    ah, al = split_bits(a)
    bh, bl = split_bits(b)
    p, e1 = two_sum(ah * bh, ah * bl)
    p, e2 = two_sum(p, al * bh)
    p, e3 = two_sum(p, al * bl)
    return p, e1 + e2 + e3


def dot2(row, x, t):
    """Σ row[k]·x[k] + t as (hi, lo) with a compensated sum (Ogita–Rump–Oishi Dot2)."""
    s, err = t, jnp.zeros_like(x[0])
    for r, v in zip(row, x):
        p, ep = two_prod(r, v)
        s, es = two_sum(s, p)
        err = err + (ep + es)
    return two_sum(s, err)


def div2(nh, nl, dh, dl):
    """(nh + nl) / (dh + dl) as (hi, lo), relative error O(u²)."""
    q = nh / dh
    p, ep = two_prod(q, dh)
    r = (((nh - p) - ep) + nl) - q * dl
    return two_sum(q, r / dh)


def mul_add2(f, xh, xl, c):
    """f·(xh + xl) + c as (hi, lo) for float32 scalars f, c."""
    p, ep = two_prod(f, xh)
    s, es = two_sum(p, c)
    return two_sum(s, es + ep + f * xl)


def centre_split(means, viewmat, fx, fy, cx, cy, compensated_transform=True):
    """The screen-space centres of float32 world means (N, 3) as (hi, lo), each (N, 2) float32,
    hi + lo = fx·tx/tz + cx (and y) to O(u²)·|μ|. Without `compensated_transform` the camera
    transform t = W·m + T is the plain float32 one (as `lgs_jax.projection`), the rest split."""
    m = [means[:, k] for k in range(3)]
    if compensated_transform:
        t = [dot2([viewmat[i, j] for j in range(3)], m, viewmat[i, 3]) for i in range(3)]
    else:
        zero = jnp.zeros_like(m[0])
        t = [(viewmat[i, 0] * m[0] + viewmat[i, 1] * m[1] + viewmat[i, 2] * m[2]
              + viewmat[i, 3], zero) for i in range(3)]
    out = []
    for (nh, nl), f, c in ((t[0], fx, cx), (t[1], fy, cy)):
        qh, ql = div2(nh, nl, *t[2])
        out.append(mul_add2(f, qh, ql, c))
    return jnp.stack([out[0][0], out[1][0]], -1), jnp.stack([out[0][1], out[1][1]], -1)


def split_to_integer(hi, lo):
    """The tile-relative storage of a split centre: (K, r) with K = round(hi) (an integer,
    exact in float32 below 2^24) and r = (hi − K) + lo (hi − K exact), μ = K + r."""
    k = jnp.round(hi)
    return k, (hi - k) + lo


def offset(hi, lo, point):
    """d = μ − point from a split centre: (hi − point) + lo, the large parts cancelling first."""
    return (hi - point) + lo


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
