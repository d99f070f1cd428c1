"""The Gaussian exponent ln α = ln o − ½·dᵀQd in the forms the study compares.

d = μ − p (Gaussian centre minus pixel centre), Q = [[a, b], [b, c]] the conic. Labels:

  difference     original 3DGS: d first, then ln o − ½(a·dx² + c·dy²) − b·dx·dy
  global         Eq. 7–10 hoisted expansion in global screen coordinates (origin (0, 0))
  local_corner   the same in tile-local coordinates, origin at the tile corner (Eq. 1–3, 8)
  local_center   the same with the origin at the tile centre
  principal_axes d in the Gaussian's principal frame: ln o − ½((e₁·d)²/λ₁ + (e₂·d)²/λ₂), with
                 (λ, e) of the 2D covariance computed once per Gaussian in float64 (the cost: one
                 2x2 eigendecomposition per Gaussian in higher precision) and stored in the
                 evaluation dtype
  whitened       the principal-axes form with the axes scaled per Gaussian, wᵢ = eᵢ/√λᵢ:
                 ln o − ½((w₁·d)² + (w₂·d)²), one product fewer per axis and exponent (not in
                 FORMS, the study's sweep: numerics.centre and numerics.cost use it)

Every form takes arrays in one dtype and returns ln α in it; `evaluation_bound` bounds the
rounding of that evaluation (inputs taken as exact), so that errors from rounding the inputs
(the conic itself) and from evaluating them can be told apart.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from lgs_jax import hoist

FORMS = ("difference", "global", "local_corner", "local_center", "principal_axes")
TILE = 16


def _xp(x):
    """jax.numpy for JAX arrays (traced or not), numpy otherwise."""
    return jnp if isinstance(x, jax.Array) else np


def tile_origin(form: str, pixel):
    """The hoisting origin of a pixel (..., 2) for a form (zeros for global/difference)."""
    xp = _xp(pixel)
    corner = xp.floor(pixel / TILE) * TILE
    if form == "local_corner":
        return corner
    if form == "local_center":
        return corner + TILE / 2
    return xp.zeros_like(pixel)


def covariance(lam_major, lam_minor, theta):
    """2x2 covariances (..., 3) as (xx, xy, yy) with eigenvalues (λ_major, λ_minor), the major
    axis at angle θ (NumPy)."""
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([c * c * lam_major + s * s * lam_minor, c * s * (lam_major - lam_minor),
                     s * s * lam_major + c * c * lam_minor], -1)


def conic(cov):
    """Conic (a, b, c) = Σ⁻¹ entries of covariances (..., 3), in the covariance's dtype (as the
    projection computes it)."""
    det = cov[..., 0] * cov[..., 2] - cov[..., 1] * cov[..., 1]
    return np.stack([cov[..., 2] / det, -cov[..., 1] / det, cov[..., 0] / det], -1)


def principal_axes(cov):
    """(λ₁, λ₂, e₁) of 2x2 covariances (..., 3) as (xx, xy, yy), computed in float64:
    λ₁ >= λ₂, e₁ the unit eigenvector of λ₁ (e₂ = e₁ rotated by 90°). NumPy or JAX arrays (JAX
    computes in float64 only with jax_enable_x64)."""
    xp = _xp(cov)
    sxx, sxy, syy = (xp.asarray(cov[..., i], xp.float64) for i in range(3))
    half_diff = 0.5 * (sxx - syy)
    root = xp.hypot(half_diff, sxy)
    mid = 0.5 * (sxx + syy)
    lam1 = mid + root
    lam2 = (sxx * syy - sxy * sxy) / lam1  # no cancellation in mid − root
    theta = 0.5 * xp.arctan2(2 * sxy, sxx - syy)
    return lam1, lam2, xp.stack([xp.cos(theta), xp.sin(theta)], -1)


def whitening(lam1, lam2, e1):
    """The whitened axes (w₁, w₂), each (..., 2), w₁ = e₁/√λ₁, w₂ = e₂/√λ₂ with e₂ = e₁ turned
    by 90°, in the arrays' dtype: dᵀΣ⁻¹d = (w₁·d)² + (w₂·d)²."""
    xp = _xp(e1)
    s1, s2 = 1 / xp.sqrt(lam1), 1 / xp.sqrt(lam2)
    return (xp.stack([e1[..., 0] * s1, e1[..., 1] * s1], -1),
            xp.stack([-e1[..., 1] * s2, e1[..., 0] * s2], -1))


def log_alpha(form: str, mean, pixel, conic, log_o, axes=None):
    """ln α of Gaussians (mean (..., 2), conic (..., 3), log_o (...)) at pixels (..., 2).

    All arrays share one float dtype, in which the form is evaluated. `axes` = (λ₁, λ₂, e₁) in
    that dtype, needed by principal_axes only. NumPy in, NumPy out; JAX arrays in, JAX out (so
    that `numerics.cost` can jit and time the same code).
    """
    if form == "difference":
        dx, dy = mean[..., 0] - pixel[..., 0], mean[..., 1] - pixel[..., 1]
        a, b, c = conic[..., 0], conic[..., 1], conic[..., 2]
        return log_o + (-0.5 * (a * dx * dx + c * dy * dy) - b * dx * dy)
    if form == "principal_axes":
        lam1, lam2, e1 = axes
        dx, dy = mean[..., 0] - pixel[..., 0], mean[..., 1] - pixel[..., 1]
        t1 = e1[..., 0] * dx + e1[..., 1] * dy
        t2 = e1[..., 0] * dy - e1[..., 1] * dx
        return log_o - 0.5 * (t1 * t1 / lam1 + t2 * t2 / lam2)
    if form == "whitened":
        w1, w2 = whitening(*axes)
        dx, dy = mean[..., 0] - pixel[..., 0], mean[..., 1] - pixel[..., 1]
        t1 = w1[..., 0] * dx + w1[..., 1] * dy
        t2 = w2[..., 0] * dx + w2[..., 1] * dy
        return log_o - 0.5 * (t1 * t1 + t2 * t2)
    if form not in FORMS:
        raise ValueError(f"form: expected one of {FORMS}, got {form!r}")
    xp = _xp(pixel)
    origin = tile_origin(form, pixel).astype(pixel.dtype)
    v = xp.asarray(hoist.hoist(mean, conic, log_o, origin))
    local = pixel - origin
    basis = xp.asarray(hoist.basis(local[..., 0], local[..., 1]))
    return xp.sum(v * basis, axis=-1, dtype=pixel.dtype)


def evaluation_bound(form: str, mean, pixel, conic, log_o, axes=None, dtype=np.float32):
    """Upper bound on |fl(form) − form| for exactly-represented inputs (float64 arithmetic).

    difference: every term of the sum errs by at most 6u of its size (one rounding of d, then
    products and sums), so γ = 8u times S = ½(a·dx² + c·dy²) + |b·dx·dy| + |ln o|.
    hoisted forms: `lgs_jax.hoist.error_bound` (γ = 16u over the expansion's terms).
    principal_axes: t = e·d errs by |δt| <= 5u·|d| (d's rounding, two products, a sum), so
    t²/λ errs by <= (2|t|·|δt| + δt²)/λ plus 4u of its size; inside the ellipse |t₂| <= √(τλ₂),
    which is why this form gains √κ over the others on needles.
    whitened: likewise with t = w·d, |δt| <= 8u·|d|/√λ (w's own rounding: a square root, a
    division, a product).
    """
    u = np.finfo(dtype).eps / 2
    f64 = lambda x: np.asarray(x, np.float64)
    mean, pixel, conic, log_o = f64(mean), f64(pixel), f64(conic), f64(log_o)
    dx, dy = mean[..., 0] - pixel[..., 0], mean[..., 1] - pixel[..., 1]
    if form == "difference":
        a, b, c = conic[..., 0], np.abs(conic[..., 1]), conic[..., 2]
        return 8 * u * (0.5 * (a * dx * dx + c * dy * dy) + b * np.abs(dx * dy) + np.abs(log_o))
    if form == "principal_axes":
        lam1, lam2, e1 = f64(axes[0]), f64(axes[1]), f64(axes[2])
        t1 = e1[..., 0] * dx + e1[..., 1] * dy
        t2 = e1[..., 0] * dy - e1[..., 1] * dx
        dt = 5 * u * np.hypot(dx, dy)
        term = lambda t, lam: (2 * np.abs(t) * dt + dt * dt) / lam + 4 * u * t * t / lam
        return 0.5 * (term(t1, lam1) + term(t2, lam2)) + 4 * u * np.abs(log_o)
    if form == "whitened":
        lam1, lam2, e1 = f64(axes[0]), f64(axes[1]), f64(axes[2])
        dist = np.hypot(dx, dy)
        total = 0.0
        for t, lam in ((e1[..., 0] * dx + e1[..., 1] * dy, lam1),
                       (e1[..., 0] * dy - e1[..., 1] * dx, lam2)):
            t = t / np.sqrt(lam)
            dt = 8 * u * dist / np.sqrt(lam)  # w's rounding (√, ÷, ×), d's, two products, a sum
            total = total + 2 * np.abs(t) * dt + dt * dt + 3 * u * t * t
        return 0.5 * total + 4 * u * np.abs(log_o)
    origin = tile_origin(form, pixel)
    local = np.abs(pixel - origin)
    return np.asarray(hoist.error_bound(mean, conic, log_o, origin, local[..., 0], local[..., 1],
                                        16 * u))
