"""Double-float32 arithmetic for the split screen-space centre μ = hi + lo.

A float32 centre μ = fx·tx/tz + cx carries the rounding of numbers as large as the image:
ulp(μ)/2 = 2^-24·|μ| (3e-5 px at 1K wide, 5e-4 px at 16K), and before that the camera
transform t = W·m + T rounds at the size of the scene's coordinates. Every exponent form takes
its offset d = μ − p (or Δ = μ − T) from μ, so that rounding is a floor in ln α which grows
with the image (|∂ln α/∂d| reaches ~6 px⁻¹ at the 1/255 edge with the 0.3 px² dilation).

`screen_centre` computes μ from float32 parameters to O(u²)·|μ| as two float32 numbers,
hi = μ rounded to float32 and lo = μ − hi (|lo| <= ulp(hi)/2): the camera transform as a
compensated dot product (`dot2`), the perspective division, the focal length and the principal
point in double-float32 arithmetic (`div2`, `mul_add2`). A consumer forms its small offset
first and adds lo after (`offset`):

    d = (hi − p) + lo,   Δ = (hi − T) + lo

where hi − p is exact when p is within a factor of two of hi (Sterbenz's lemma; otherwise
|hi − p| >= |hi|/2 >= |lo|/u), so the offset rounds at the size of d, not of μ: the 16K error
of ln α is back at the 1K level (numerics.centre measures it).

Error-free transformations (Knuth's TwoSum, Dekker's TwoProduct) under XLA: XLA's CPU and GPU
compilers contract a·b + c into a fused multiply-add where they choose, which breaks Veltkamp's
arithmetic splitting (c = 4097·a; a_hi = c − (c − a)) and any TwoSum whose operand is a rounded
product. `split_bits` splits by clearing the low 12 significand bits (a bit mask: no rounding
to contract), `two_prod` adds only exact partial products, and every other product is a
correction term, so that a contraction cannot change what the transformations compute. Float32
only: a 53-bit float64 significand has no bit-mask split whose partial products are exact
(float64's own floor, 2^-53·|μ|, is 2e-12 px at 16K; lgs_jax.projection keeps lo = 0 there).

Cost per Gaussian, as written (float32 operations on the (N,) columns, counted in the jaxpr by
tests/test_projection.py; XLA merges the repeated splits of t_z): `camera_coordinates` 309
additions, subtractions and multiplications and 3 bit masks (the plain t = W·m + T: 18),
`screen_centre` 154, 6 bit masks and 4 divisions (the plain centre: 4 and 2 divisions). The
projection keeps the plain centre for its derivative only (`with_tangent_of`). Per offset
(`offset`) one addition per axis more than the plain μ − p. Where the library pays that:

  per Gaussian  the split above; two columns more in `pairs.gaussian_table` (8 bytes in
                float32) and in each exchanged record of Gaussian parallelism;
  per pair      one addition per axis for Δ before Eq. 8, and 8 of the 48 bytes of the
                table row every pair gathers (float32); the Pallas kernels' difference
                records hold Δ = (hi − T) + lo, not μ (two operations per axis, which the
                vanilla kernel does per pair from its rows); the strip masks of
                the difference form take the hoisted form's error bound too
                (`pairs.strip_mask_columns`: 60 jaxpr equations more per pair, a logarithm
                among them; the hoisted form's masks: 8 more);
  per exponent  one addition per axis in the XLA difference form (lgs_jax.composite:
                reference, brute, tiles); none in the Pallas kernels (d = Δ − x', as the
                plain μ − p) nor in the hoisted forms (V·B, Eq. 10, unchanged).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp


def split_bits(a):
    """(hi, lo) with hi = a with its low 12 significand bits cleared, lo = a − hi (exact): both
    have at most 12 significant bits, so their products are exact in float32."""
    hi = jax.lax.bitcast_convert_type(
        jax.lax.bitcast_convert_type(a, jnp.uint32) & jnp.uint32(0xFFFFF000), jnp.float32)
    return hi, a - hi


def two_sum(a, b):
    """(s, e): s = fl(a + b), s + e = a + b exactly (Knuth; 6 operations)."""
    s = a + b
    bb = s - a
    return s, (a - (s - bb)) + (b - bb)


def two_prod(a, b):
    """(p, e): p + e = a·b to O(u²)·|a·b|, p ≈ fl(a·b) (`two_prod_split` of both split)."""
    return two_prod_split(split_bits(a), split_bits(b))


def two_prod_split(a, b):
    """`two_prod` of (hi, lo) halves from `split_bits` (a split operand is split once where it
    meets several): the four partial products (each exact) summed by `two_sum` (24
    operations). No product that rounds is ever added to anything, so a multiply-add
    contracted by the compiler computes the same bits (Dekker's p = fl(a·b) followed by a
    TwoSum of p lets XLA fuse p into the sum: measured wrong under jit on the CPU)."""
    (ah, al), (bh, bl) = a, b
    p, e1 = two_sum(ah * bh, ah * bl)
    p, e2 = two_sum(p, al * bh)
    p, e3 = two_sum(p, al * bl)
    return p, e1 + e2 + e3


def dot2(row, x, t):
    """Σ row[k]·x[k] + t as (hi, lo) with a compensated sum (Ogita–Rump–Oishi Dot2); `x` as
    `split_bits` halves, `row` and `t` plain."""
    s, err = t, jnp.zeros_like(x[0][0])
    for r, v in zip(row, x):
        p, ep = two_prod_split(split_bits(r), v)
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
    """f·(xh + xl) + c as (hi, lo) for float32 f, c."""
    p, ep = two_prod(f, xh)
    s, es = two_sum(p, c)
    return two_sum(s, es + ep + f * xl)


def camera_coordinates(viewmat, mean):
    """t = W·m + T of world means (three (N,) float32 columns) as three (hi, lo) pairs
    (`dot2`, each mean column split once)."""
    x = [split_bits(m) for m in mean]
    return [dot2([viewmat[i, j] for j in range(3)], x, viewmat[i, 3]) for i in range(3)]


def screen_centre(tx, ty, tz, fx, fy, cx, cy):
    """μ = (fx·tx/tz + cx, fy·ty/tz + cy) from camera coordinates given as (hi, lo) pairs:
    ((hi_x, lo_x), (hi_y, lo_y)), hi + lo = μ to O(u²)·|μ|, |lo| <= ulp(hi)/2."""
    return tuple(mul_add2(f, *div2(*t, *tz), c) for t, f, c in ((tx, fx, cx), (ty, fy, cy)))


def offset(hi, lo, point):
    """d = hi + lo − point as (hi − point) + lo: the large parts cancel first (module
    docstring), then one rounding at the size of d."""
    return (hi - point) + lo


@jax.custom_jvp
def with_tangent_of(value, like):
    """`value`, differentiated as `like` (a value computed another way, e.g. without
    error-free transformations, whose derivative is the one wanted: bit masks have none)."""
    del like
    return value


@with_tangent_of.defjvp
def _with_tangent_of_jvp(primals, tangents):
    return primals[0], tangents[1]
