"""EWA projection of 3D Gaussians to screen space, as gsplat 1.5.3's pinhole model.

Implements docs/conventions.md, "Camera and projection":
  t = R·μ + T (camera space), valid iff near < t_z < far;
  Σ = R(q) S Sᵀ R(q)ᵀ,  Σc = W Σ Wᵀ;
  J = [[fx/tz, 0, −fx·tx'/tz²], [0, fy/tz, −fy·ty'/tz²]] at the clamped point
      tx' = tz·clip(tx/tz, −lim_x−, lim_x+),  lim_x+ = (W − cx)/fx + 0.3·W/(2fx),
      lim_x− = cx/fx + 0.3·W/(2fx) (y likewise);
  Σ2 = J Σc Jᵀ + 0.3·I;  det = Σ2xx·Σ2yy − Σ2xy², invalid if det <= 0;
  conic (a, b, c) = (Σ2yy, −Σ2xy, Σ2xx)/det;  μ = (fx·tx/tz + cx, fy·ty/tz + cy),
      carried as mean2d + mean2d_lo (float32: the split centre of lgs_jax.twofloat, from the
      same float32 parameters to O(u²)·|μ|; mean2d is μ rounded to float32, the derivative
      is that of μ, mean2d_lo is a constant correction; float64: mean2d_lo = 0);
  rgb = max(SH(dir) + 0.5, 0), dir = normalise(μ − camera centre);
  or, given per-Gaussian `colors` (N, C), rgb = colors as given (any C >= 1, no clamp).
Antialiased (`RasterConfig(antialiased=True)`, gsplat's rasterize_mode="antialiased", the
Mip-Splatting 2D filter): the dilation keeps each Gaussian's integral, the opacity scaled by
  ρ = sqrt(max(det(J Σc Jᵀ) / det(Σ2), 0))  (≤ 1; 0 where J Σc Jᵀ is singular in rounding),
and the validity test (opacity ≥ 1/255) applies to the scaled opacity.
All products are written as explicit multiply-adds on per-Gaussian columns (no matmul), so TF32
never applies on GPUs and XLA fuses the whole projection.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Any

import jax
import jax.numpy as jnp
from jax import lax

from . import twofloat
from .config import ALPHA_MIN
from .scene import Camera, Gaussians
from .sh import sh_basis_terms, sh_sums

EPS2D = 0.3  # low-pass dilation added to the 2D covariance


@jax.tree_util.register_dataclass
@dataclasses.dataclass
class Projected:
    """Per-Gaussian screen-space quantities (all (N, ...) arrays in the scene's dtype).

    `invalid` marks Gaussians the contract calls invalid: NaN anywhere, ±inf in means or quats,
    +inf in log_scales, a zero quaternion, a centre outside (near, far), det <= 0, or a projection
    that overflows the dtype (non-finite mean2d, conic or colour; with `colors`, a
    non-finite colour). `valid` marks those that can reach the image: not invalid and
    opacity >= 1/255. Rows that are not valid hold finite placeholders (unit conic, zero
    colour, opacity and depth), so no NaN can leak.

    The centre is μ = mean2d + mean2d_lo (lgs_jax.twofloat): every consumer forms its offset
    as (mean2d − p) + mean2d_lo (`twofloat.offset`), so that it rounds at its own size, not at
    the image's. Code that builds a `Projected` from a centre it holds in one number passes
    mean2d_lo = zeros.
    """

    mean2d: Any  # (N, 2) pixel coordinates (x, y) of the centre μ, rounded to the dtype
    mean2d_lo: Any  # (N, 2) μ − mean2d (|mean2d_lo| <= ulp(mean2d)/2; not differentiated)
    cov2d: Any  # (N, 3) Σ2 as (xx, xy, yy), dilation included
    conic: Any  # (N, 3) (a, b, c) = Σ2⁻¹ entries (xx, xy, yy)
    depth: Any  # (N,) camera-space z
    opacity: Any  # (N,)
    rgb: Any  # (N, 3), or (N, C): the `colors` given to `project`
    valid: Any  # (N,) bool: can reach the image
    invalid: Any  # (N,) bool: invalid per the contract (a subset of ~valid)


def shifted(p: Projected, offsets) -> Projected:
    """`p` with its centres moved by `offsets` (N, 2) pixels, exactly: μ + offsets carried as
    mean2d + mean2d_lo again (the sum's rounding goes to mean2d_lo, `twofloat.two_sum`),
    differentiated as mean2d + offsets. Zero offsets return `p`'s values."""
    offsets = offsets.astype(p.mean2d.dtype)
    moved = p.mean2d + offsets
    s, e = twofloat.two_sum(lax.stop_gradient(p.mean2d), lax.stop_gradient(offsets))
    hi, lo = twofloat.two_sum(s, lax.stop_gradient(p.mean2d_lo) + e)
    return dataclasses.replace(p, mean2d=twofloat.with_tangent_of(hi, moved), mean2d_lo=lo)


def quat_to_rotmat(q):
    """Rotation matrices (N, 3, 3) from quaternions (N, 4) w, x, y, z (normalised here)."""
    q = q / jnp.linalg.norm(q, axis=-1, keepdims=True)
    rows = _rotation(q[..., 0], q[..., 1], q[..., 2], q[..., 3])
    return jnp.stack([jnp.stack(row, -1) for row in rows], -2)


def camera_center(viewmat):
    """World-space camera centre −Rᵀ·T of a world-to-camera matrix."""
    r, t = viewmat[:3, :3], viewmat[:3, 3]
    return -jnp.sum(r * t[:, None], axis=0)


def _rotation(qw, qx, qy, qz):
    """Rows of R(q) (3 x 3 nested lists of (N,) arrays) of unit quaternions w, x, y, z."""
    return [[1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qw * qz), 2 * (qx * qz + qw * qy)],
            [2 * (qx * qy + qw * qz), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qw * qx)],
            [2 * (qx * qz - qw * qy), 2 * (qy * qz + qw * qx), 1 - 2 * (qx * qx + qy * qy)]]


def _camera_covariance(rot, scales, w):
    """The six entries (xx, xy, xz, yy, yz, zz) of Σc = W Σ Wᵀ, Σ = R S Sᵀ Rᵀ: with
    M = W R S (columns scaled by s), Σc = M Mᵀ. rot: R(q) rows; w: the camera rotation W's
    rows (scalars); scales: (s_x, s_y, s_z)."""
    m = [[sum(w[i][l] * rot[l][j] for l in range(3)) * scales[j] for j in range(3)]
         for i in range(3)]
    dot = lambda i, j: m[i][0] * m[j][0] + m[i][1] * m[j][1] + m[i][2] * m[j][2]
    return dot(0, 0), dot(0, 1), dot(0, 2), dot(1, 1), dot(1, 2), dot(2, 2)


def project(g: Gaussians, cam: Camera, antialiased: bool = False, colors=None,
            sh_bands=None) -> Projected:
    """Project Gaussians `g` through camera `cam` (all arithmetic in g's dtype); `antialiased`
    scales each opacity by ρ (module docstring). `colors`: optional (N, C) values that take
    the SH colour's place (`rgb` is then (N, C), `g.sh` is not read). `sh_bands`: optional
    (K,) factors of the SH coefficients (`render`'s), applied inside the checkpoint: the
    backward keeps `g.sh` as given, not a scaled copy.

    Written on per-Gaussian (N,) columns, every step elementwise (no stacked 3x3 matrices, no
    reductions over small axes), so that XLA fuses the projection and its autodiff backward
    into a few passes over the Gaussians; `jax.checkpoint` makes the backward recompute these
    elementwise intermediates instead of storing them.

    The fields are materialised once (an optimization barrier), so every consumer (the pair
    emission's tile rectangles, the depth order, the kernels' Gaussian table, the counts that
    size the pair buffer) reads the same stored bits. Fused into each consumer instead, XLA
    recomputed the projection per consumer (a large share of a forward at scale), and each
    recomputation could contract multiplies and adds into FMAs its own way, so two consumers
    could see different bits of one Gaussian's mean or conic.

    The checkpoint takes `g`'s fields whole and slices them into columns inside: JAX keeps a
    checkpoint's inputs for the backward behind an optimization barrier, so with columns as
    its inputs XLA copied each one out (16 column copies, live at the peak of the gradient's
    memory).

    The barrier holds the fields as (N,) columns, stacked into `Projected`'s (N, 2) and (N, 3)
    fields after it: a consumer that reads columns (the Gaussian table's kernel, the emission's
    fusions) then reads the stored columns, and no stacked copy is written unless a consumer
    needs one whole. Behind the barrier the stacks were three XLA concatenates written and read
    back, and in the backward the cotangents arrived stacked too."""
    return _stacked(lax.optimization_barrier(_project(g, cam, bool(antialiased), colors,
                                                      sh_bands)))


@functools.partial(jax.checkpoint, static_argnums=(2,))
def _project(g: Gaussians, cam: Camera, antialiased: bool, colors=None, sh_bands=None) -> dict:
    columns = gaussian_columns(g.means, g.quats, g.log_scales, g.logit_opacities)
    sh = g.sh
    if sh_bands is not None and colors is None:
        sh = sh * jnp.asarray(sh_bands)[None, :, None].astype(sh.dtype)
    return _projected_columns(*columns, sh, cam, antialiased, colors)


def _stacked(cols: dict) -> Projected:
    """`Projected` of `_projected_columns`' columns (vector fields stacked on the last axis)."""
    return Projected(**{k: jnp.stack(v, -1) if isinstance(v, tuple) else v
                        for k, v in cols.items()})


@jax.custom_vjp
def gaussian_columns(means, quats, log_scales, logit_opacities):
    """The fields of a `Gaussians` but its SH coefficients as (N,) columns, as
    `_projected_columns` takes them: (mean x, y, z), (quaternion w, x, y, z), (log scales),
    the opacity logits.

    Its vjp stores the columns' cotangents (an optimization barrier), then stacks them into
    the fields. Differentiated as plain slices instead, each field's cotangent is a sum of
    per-column pads, which XLA fused into the projection's backward: it split that into two
    fusions with 32 (N,) arrays between them. Behind the barrier the backward writes (N,)
    columns only (docs/design-notes.md). The SH coefficients stay whole (`sh_sums`).
    Being a `custom_vjp`, it has no forward-mode derivative (`jax.jvp`), as the rasterizers."""
    return _columns(means, quats, log_scales, logit_opacities)


def _columns(means, quats, log_scales, logit_opacities):
    return ([means[:, i] for i in range(3)], [quats[:, i] for i in range(4)],
            [log_scales[:, i] for i in range(3)], logit_opacities)


def _columns_fwd(*fields):
    return _columns(*fields), None


def _columns_bwd(_, cts):
    mean, quat, log_scale, logit = lax.optimization_barrier(cts)
    return jnp.stack(mean, -1), jnp.stack(quat, -1), jnp.stack(log_scale, -1), logit


gaussian_columns.defvjp(_columns_fwd, _columns_bwd)


def _projected_columns(mean, quat, log_scale, logit_opacities, sh, cam: Camera,
                       antialiased: bool = False, colors=None) -> dict:
    """`project` on `gaussian_columns` and the SH coefficients `sh` (N, K, 3), or the
    `colors` (N, C) in their place: `Projected`'s fields as (N,) columns, a tuple of them for
    each vector field."""
    dt = mean[0].dtype
    viewmat = jnp.asarray(cam.viewmat, dt)
    fx, fy, cx, cy, near, far = (jnp.asarray(v, dt) for v in
                                 (cam.fx, cam.fy, cam.cx, cam.cy, cam.near, cam.far))
    colour_in = ([sh[:, k, c] for k in range(sh.shape[1]) for c in range(3)] if colors is None
                 else [colors[:, c] for c in range(colors.shape[1])])
    all_of = lambda xs: functools.reduce(jnp.logical_and, xs)
    input_ok = all_of([jnp.isfinite(x) for x in mean + quat]
                      + [~jnp.isnan(x) & (x != jnp.inf) for x in log_scale]
                      + [~jnp.isnan(logit_opacities)] + [~jnp.isnan(x) for x in colour_in]
                      + [sum(q * q for q in quat) > 0])
    # Placeholders keep invalid rows finite so no NaN can leak through a masked arithmetic path.
    mean = [jnp.where(input_ok, x, 0.0) for x in mean]
    quat = [jnp.where(input_ok, x, float(i == 0)) for i, x in enumerate(quat)]
    log_scale = [jnp.where(input_ok, x, 0.0) for x in log_scale]

    w = [[viewmat[i, j] for j in range(3)] for i in range(3)]
    tx, ty, tz = (w[i][0] * mean[0] + w[i][1] * mean[1] + w[i][2] * mean[2] + viewmat[i, 3]
                  for i in range(3))
    in_range = (tz > near) & (tz < far)
    tz_safe = jnp.where(in_range, tz, 1.0)

    norm = jnp.sqrt(sum(q * q for q in quat))
    rot = _rotation(*(q / norm for q in quat))
    cxx, cxy, cxz, cyy, cyz, czz = _camera_covariance(rot, [jnp.exp(x) for x in log_scale], w)

    width, height = jnp.asarray(cam.width, dt), jnp.asarray(cam.height, dt)
    tan_fovx, tan_fovy = 0.5 * width / fx, 0.5 * height / fy
    lim_xp, lim_xn = (width - cx) / fx + 0.3 * tan_fovx, cx / fx + 0.3 * tan_fovx
    lim_yp, lim_yn = (height - cy) / fy + 0.3 * tan_fovy, cy / fy + 0.3 * tan_fovy
    tx_c = tz_safe * jnp.clip(tx / tz_safe, -lim_xn, lim_xp)
    ty_c = tz_safe * jnp.clip(ty / tz_safe, -lim_yn, lim_yp)
    j00, j11 = fx / tz_safe, fy / tz_safe
    j02, j12 = -fx * tx_c / (tz_safe * tz_safe), -fy * ty_c / (tz_safe * tz_safe)
    # Σ2 = J Σc Jᵀ with J = [[j00, 0, j02], [0, j11, j12]].
    axx = j00 * (j00 * cxx + j02 * cxz) + j02 * (j00 * cxz + j02 * czz)
    sxy = j00 * (j11 * cxy + j12 * cxz) + j02 * (j11 * cyz + j12 * czz)
    ayy = j11 * (j11 * cyy + j12 * cyz) + j12 * (j11 * cyz + j12 * czz)
    sxx, syy = axx + EPS2D, ayy + EPS2D
    det = sxx * syy - sxy * sxy
    det_ok = det > 0
    det_safe = jnp.where(det_ok, det, 1.0)
    conic = (syy / det_safe, -sxy / det_safe, sxx / det_safe)
    mean2d, mean2d_lo = _centre(mean, viewmat, (fx, fy, cx, cy), in_range,
                                (fx * tx / tz_safe + cx, fy * ty / tz_safe + cy))

    opacity = jax.nn.sigmoid(jnp.where(input_ok, logit_opacities, 0.0))
    if antialiased:
        opacity = opacity * _compensation(axx * ayy - sxy * sxy, det_safe)
    rgb = (_sh_colour(mean, sh, viewmat, input_ok) if colors is None
           else [jnp.where(input_ok, x, 0.0) for x in colour_in])

    finite = all_of([jnp.isfinite(x) for x in mean2d + mean2d_lo + conic + tuple(rgb)])
    invalid = ~(input_ok & in_range & det_ok & finite)
    valid = ~invalid & (opacity >= jnp.asarray(ALPHA_MIN, dt))
    keep = lambda xs, fill: tuple(jnp.where(valid, x, f) for x, f in zip(xs, fill))
    return dict(
        mean2d=keep(mean2d, (0.0, 0.0)),
        mean2d_lo=keep(mean2d_lo, (0.0, 0.0)),
        cov2d=keep((sxx, sxy, syy), (1.0, 0.0, 1.0)),
        conic=keep(conic, (1.0, 0.0, 1.0)),
        depth=jnp.where(valid, tz, 0.0),
        opacity=jnp.where(valid, opacity, 0.0),
        rgb=keep(rgb, (0.0,) * len(rgb)),
        valid=valid,
        invalid=invalid,
    )


def _centre(mean, viewmat, intrinsics, in_range, plain):
    """(mean2d, mean2d_lo) columns of the centre whose float32 rounding is `plain` (μ computed
    in the dtype): in float32 the split centre of the same parameters (lgs_jax.twofloat:
    t = W·m + T compensated, then the perspective step in double-float32; the division by 1
    where t_z is out of range, as `plain`'s), differentiated as `plain`; otherwise `plain` and
    zeros."""
    if plain[0].dtype != jnp.float32:
        return plain, tuple(jnp.zeros_like(x) for x in plain)
    fixed = lax.stop_gradient  # the correction is a constant: bit masks have no derivative
    t = twofloat.camera_coordinates(fixed(viewmat), [fixed(m) for m in mean])
    tz = (jnp.where(in_range, t[2][0], 1.0), jnp.where(in_range, t[2][1], 0.0))
    split = twofloat.screen_centre(t[0], t[1], tz, *(fixed(v) for v in intrinsics))
    return (tuple(twofloat.with_tangent_of(hi, like) for (hi, _), like in zip(split, plain)),
            tuple(lo for _, lo in split))


def _sh_colour(mean, sh, viewmat, input_ok):
    """rgb = max(SH(dir) + 0.5, 0) per Gaussian, dir = normalise(mean − camera centre)."""
    centre = camera_center(viewmat)
    d = [mean[i] - centre[i] for i in range(3)]
    # The square root of a guarded square: at a mean on the camera centre (an invalid row's
    # placeholder mean 0 seen from a camera at the origin) sqrt's derivative is infinite, and
    # its zero cotangent times it made the camera's gradient NaN.
    d2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
    dnorm = jnp.sqrt(jnp.where(d2 > 0, d2, 1.0))
    d = [jnp.where(d2 > 0, x / dnorm, 0.0) for x in d]
    basis = sh_basis_terms(*d, sh.shape[1])
    return [jnp.maximum(s + 0.5, 0.0) for s in sh_sums(basis, sh, input_ok)]


def _compensation(det_raw, det):
    """ρ = sqrt(max(det_raw / det, 0)) with a zero gradient where the ratio is <= 0 (the
    square root's derivative at 0 would be inf·0 = NaN)."""
    ratio = det_raw / det
    positive = ratio > 0
    return jnp.where(positive, jnp.sqrt(jnp.where(positive, ratio, 1.0)), 0.0)


def float_sort_key(x):
    """Unsigned integers in the order of the floats x (no NaN): IEEE 754 bits with all bits of
    the negatives flipped and the sign bit of the rest set, −0 taken as +0 first (as JAX's sort
    comparator does), so a stable sort of the keys is a stable sort of x. Where XLA flushes
    subnormals to zero (CPUs, GPUs), x == 0 holds for them too, as in its float sort.

    XLA sorts either kind with CUB's radix sort on GPUs, but float keys through JAX's total-order
    comparator (its zero and NaN selects), which costs more.
    """
    bits = {2: jnp.uint16, 4: jnp.uint32, 8: jnp.uint64}[x.dtype.itemsize]
    u = jax.lax.bitcast_convert_type(jnp.where(x == 0, jnp.zeros_like(x), x), bits)
    sign = jnp.asarray(1, bits) << (8 * x.dtype.itemsize - 1)
    return u ^ jnp.where((u & sign) != 0, ~jnp.zeros_like(u), sign)


def depth_order(p: Projected):
    """Gaussian indices sorted by (depth, index), valid ones first (docs/conventions.md,
    "Order")."""
    idx = jnp.arange(p.depth.shape[0], dtype=jnp.int32)
    key = float_sort_key(jnp.where(p.valid, p.depth, jnp.inf))
    return jax.lax.sort((key, idx), num_keys=1, is_stable=True)[1]  # stable: ties by index
