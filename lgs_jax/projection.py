"""EWA projection of 3D Gaussians to screen space, as gsplat 1.5.3's pinhole model.

Implements conventions.md, "Camera and projection":
  t = R·μ + T (camera space), valid iff near < t_z < far;
  Σ = R(q) S Sᵀ R(q)ᵀ,  Σc = W Σ Wᵀ;
  J = [[fx/tz, 0, −fx·tx'/tz²], [0, fy/tz, −fy·ty'/tz²]] at the clamped point
      tx' = tz·clip(tx/tz, −lim_x−, lim_x+),  lim_x+ = (W − cx)/fx + 0.3·W/(2fx),
      lim_x− = cx/fx + 0.3·W/(2fx) (y likewise);
  Σ2 = J Σc Jᵀ + 0.3·I;  det = Σ2xx·Σ2yy − Σ2xy², invalid if det <= 0;
  conic (a, b, c) = (Σ2yy, −Σ2xy, Σ2xx)/det;  mean2d = (fx·tx/tz + cx, fy·ty/tz + cy);
  rgb = max(SH(dir) + 0.5, 0), dir = normalise(μ − camera centre).
All products are written as explicit multiply-adds (no matmul), so TF32 never applies on GPUs.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp

from .config import ALPHA_MIN
from .scene import Camera, Gaussians
from .sh import sh_to_rgb

EPS2D = 0.3  # low-pass dilation added to the 2D covariance


@jax.tree_util.register_dataclass
@dataclasses.dataclass
class Projected:
    """Per-Gaussian screen-space quantities (all (N, ...) arrays in the scene's dtype).

    `invalid` marks Gaussians the contract calls invalid: NaN anywhere, ±inf in means or quats,
    +inf in log_scales, a zero quaternion, a centre outside (near, far), det <= 0, or a projection
    that overflows the dtype (non-finite mean2d, conic or colour). `valid` marks those that can
    reach the image: not invalid and opacity >= 1/255. Rows that are not valid hold finite
    placeholders (unit conic, zero colour, opacity and depth), so no NaN can leak.
    """

    mean2d: Any  # (N, 2) pixel coordinates (x, y)
    cov2d: Any  # (N, 3) Σ2 as (xx, xy, yy), dilation included
    conic: Any  # (N, 3) (a, b, c) = Σ2⁻¹ entries (xx, xy, yy)
    depth: Any  # (N,) camera-space z
    opacity: Any  # (N,)
    rgb: Any  # (N, 3)
    valid: Any  # (N,) bool: can reach the image
    invalid: Any  # (N,) bool: invalid per the contract (a subset of ~valid)


def quat_to_rotmat(q):
    """Rotation matrices (N, 3, 3) from quaternions (N, 4) w, x, y, z (normalised here)."""
    q = q / jnp.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return jnp.stack([
        jnp.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        jnp.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        jnp.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def _matmul(a, b):
    """Batched a @ b for tiny matrices, unrolled into elementwise multiply-adds: exact float32 on
    GPUs (no TF32), and fused by XLA (a broadcast-and-sum becomes a slow batched dot on CPU)."""
    rows = []
    for i in range(a.shape[-2]):
        rows.append(jnp.stack([sum(a[..., i, l] * b[..., l, j] for l in range(a.shape[-1]))
                               for j in range(b.shape[-1])], -1))
    return jnp.stack(rows, -2)


def camera_center(viewmat):
    """World-space camera centre −Rᵀ·T of a world-to-camera matrix."""
    r, t = viewmat[:3, :3], viewmat[:3, 3]
    return -jnp.sum(r * t[:, None], axis=0)


def project(g: Gaussians, cam: Camera) -> Projected:
    """Project Gaussians `g` through camera `cam` (all arithmetic in g's dtype)."""
    dt = g.dtype
    viewmat = jnp.asarray(cam.viewmat, dt)
    fx, fy, cx, cy, near, far = (jnp.asarray(v, dt) for v in
                                 (cam.fx, cam.fy, cam.cx, cam.cy, cam.near, cam.far))
    means, quats = g.means, g.quats
    input_ok = (jnp.all(jnp.isfinite(means), -1) & jnp.all(jnp.isfinite(quats), -1)
                & ~jnp.any(jnp.isnan(g.log_scales), -1) & ~jnp.any(g.log_scales == jnp.inf, -1)
                & ~jnp.isnan(g.logit_opacities) & jnp.all(~jnp.isnan(g.sh), (-1, -2))
                & (jnp.sum(quats * quats, -1) > 0))
    # Placeholders keep invalid rows finite so no NaN can leak through a masked arithmetic path.
    safe = input_ok[:, None]
    means = jnp.where(safe, means, 0.0)
    quats = jnp.where(safe, quats, jnp.array([1.0, 0.0, 0.0, 0.0], dt))
    log_scales = jnp.where(safe, g.log_scales, 0.0)

    r_cam, t_cam = viewmat[:3, :3], viewmat[:3, 3]
    t = jnp.sum(r_cam[None] * means[:, None, :], -1) + t_cam  # (N, 3)
    tz = t[:, 2]
    in_range = (tz > near) & (tz < far)
    tz_safe = jnp.where(in_range, tz, 1.0)

    rot = quat_to_rotmat(quats)
    m = rot * jnp.exp(log_scales)[:, None, :]  # R S
    cov3 = _matmul(m, jnp.swapaxes(m, -1, -2))
    w = jnp.broadcast_to(r_cam, cov3.shape)
    cov_c = _matmul(_matmul(w, cov3), jnp.swapaxes(w, -1, -2))

    width, height = jnp.asarray(cam.width, dt), jnp.asarray(cam.height, dt)
    tan_fovx, tan_fovy = 0.5 * width / fx, 0.5 * height / fy
    lim_xp, lim_xn = (width - cx) / fx + 0.3 * tan_fovx, cx / fx + 0.3 * tan_fovx
    lim_yp, lim_yn = (height - cy) / fy + 0.3 * tan_fovy, cy / fy + 0.3 * tan_fovy
    tx = tz_safe * jnp.clip(t[:, 0] / tz_safe, -lim_xn, lim_xp)
    ty = tz_safe * jnp.clip(t[:, 1] / tz_safe, -lim_yn, lim_yp)
    zero = jnp.zeros_like(tz_safe)
    jac = jnp.stack([
        jnp.stack([fx / tz_safe, zero, -fx * tx / (tz_safe * tz_safe)], -1),
        jnp.stack([zero, fy / tz_safe, -fy * ty / (tz_safe * tz_safe)], -1),
    ], -2)  # (N, 2, 3)
    cov2 = _matmul(_matmul(jac, cov_c), jnp.swapaxes(jac, -1, -2))
    sxx, sxy, syy = cov2[:, 0, 0] + EPS2D, cov2[:, 0, 1], cov2[:, 1, 1] + EPS2D
    det = sxx * syy - sxy * sxy
    det_ok = det > 0
    det_safe = jnp.where(det_ok, det, 1.0)
    conic = jnp.stack([syy / det_safe, -sxy / det_safe, sxx / det_safe], -1)
    mean2d = jnp.stack([fx * t[:, 0] / tz_safe + cx, fy * t[:, 1] / tz_safe + cy], -1)

    opacity = jax.nn.sigmoid(jnp.where(input_ok, g.logit_opacities, 0.0))
    dirs = means - camera_center(viewmat)
    norm = jnp.sqrt(jnp.sum(dirs * dirs, -1, keepdims=True))
    dirs = jnp.where(norm > 0, dirs / jnp.where(norm > 0, norm, 1.0), 0.0)
    rgb = sh_to_rgb(jnp.where(safe[:, :, None], g.sh, 0.0), dirs)

    finite = (jnp.all(jnp.isfinite(mean2d), -1) & jnp.all(jnp.isfinite(conic), -1)
              & jnp.all(jnp.isfinite(rgb), -1))
    invalid = ~(input_ok & in_range & det_ok & finite)
    valid = ~invalid & (opacity >= jnp.asarray(ALPHA_MIN, dt))
    vm = valid[:, None]
    return Projected(
        mean2d=jnp.where(vm, mean2d, 0.0),
        cov2d=jnp.where(vm, jnp.stack([sxx, sxy, syy], -1), jnp.array([1.0, 0.0, 1.0], dt)),
        conic=jnp.where(vm, conic, jnp.array([1.0, 0.0, 1.0], dt)),
        depth=jnp.where(valid, tz, 0.0),
        opacity=jnp.where(valid, opacity, 0.0),
        rgb=jnp.where(vm, rgb, 0.0),
        valid=valid,
        invalid=invalid,
    )


def depth_order(p: Projected):
    """Gaussian indices sorted by (depth, index), valid ones first (conventions.md, "Order")."""
    idx = jnp.arange(p.depth.shape[0], dtype=jnp.int32)
    key = jnp.where(p.valid, p.depth, jnp.inf)
    return jax.lax.sort((key, idx), num_keys=1, is_stable=True)[1]  # stable: ties by index
