"""Independent float64 numpy implementation of docs/conventions.md, for tests only.

Written from the contract text, not from lgs_jax: projection (gsplat 1.5.3 pinhole EWA) and
brute-force per-pixel compositing over all Gaussians in (depth, index) order.
"""

from __future__ import annotations

import numpy as np

C0 = 0.28209479177387814


def sh_rgb(sh, d):
    """Degree-0..3 SH colour (same constants as 3DGS), rgb = max(SH + 0.5, 0)."""
    x, y, z = d
    k = sh.shape[0]
    b = [C0]
    if k > 1:
        b += [-0.4886025119029199 * y, 0.4886025119029199 * z, -0.4886025119029199 * x]
    if k > 4:
        b += [1.0925484305920792 * x * y, -1.0925484305920792 * y * z,
              0.31539156525252005 * (2 * z * z - x * x - y * y), -1.0925484305920792 * x * z,
              0.5462742152960396 * (x * x - y * y)]
    if k > 9:
        b += [-0.5900435899266435 * y * (3 * x * x - y * y), 2.890611442640554 * x * y * z,
              -0.4570457994644658 * y * (4 * z * z - x * x - y * y),
              0.3731763325901154 * z * (2 * z * z - 3 * x * x - 3 * y * y),
              -0.4570457994644658 * x * (4 * z * z - x * x - y * y),
              1.445305721320277 * z * (x * x - y * y), -0.5900435899266435 * x * (x * x - 3 * y * y)]
    return np.maximum(np.asarray(b) @ sh + 0.5, 0.0)


def project_one(mean, quat, log_scale, logit, sh, view, fx, fy, cx, cy, w, h, near, far,
                antialiased=False):
    """Returns None for an invalid / culled Gaussian, else dict(mean2d, conic, cov2d, depth, o, rgb).
    antialiased: o scaled by sqrt(max(det(J Σc Jᵀ) / det(J Σc Jᵀ + 0.3 I), 0)) (gsplat's
    add_blur compensation)."""
    vals = [mean, quat, log_scale, [logit], sh.ravel()]
    if any(np.isnan(np.asarray(v, float)).any() for v in vals):
        return None
    if not (np.isfinite(mean).all() and np.isfinite(quat).all()) or np.any(log_scale == np.inf):
        return None
    qn = np.linalg.norm(quat)
    if qn == 0:
        return None
    qw, qx, qy, qz = np.asarray(quat, float) / qn
    rot = np.array([[1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qw * qz), 2 * (qx * qz + qw * qy)],
                    [2 * (qx * qy + qw * qz), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qw * qx)],
                    [2 * (qx * qz - qw * qy), 2 * (qy * qz + qw * qx), 1 - 2 * (qx * qx + qy * qy)]])
    s = np.exp(np.asarray(log_scale, float))
    cov = rot @ np.diag(s * s) @ rot.T
    r, t = view[:3, :3], view[:3, 3]
    tc = r @ mean + t
    if not (near < tc[2] < far):
        return None
    covc = r @ cov @ r.T
    tanx, tany = 0.5 * w / fx, 0.5 * h / fy
    limxp, limxn = (w - cx) / fx + 0.3 * tanx, cx / fx + 0.3 * tanx
    limyp, limyn = (h - cy) / fy + 0.3 * tany, cy / fy + 0.3 * tany
    tz = tc[2]
    tx = tz * min(limxp, max(-limxn, tc[0] / tz))
    ty = tz * min(limyp, max(-limyn, tc[1] / tz))
    jac = np.array([[fx / tz, 0, -fx * tx / tz**2], [0, fy / tz, -fy * ty / tz**2]])
    raw = jac @ covc @ jac.T
    cov2 = raw + 0.3 * np.eye(2)
    det = cov2[0, 0] * cov2[1, 1] - cov2[0, 1] ** 2
    if not det > 0:
        return None
    conic = np.array([cov2[1, 1], -cov2[0, 1], cov2[0, 0]]) / det
    o = 1.0 / (1.0 + np.exp(-logit)) if logit != np.inf else 1.0
    rho = np.sqrt(max(np.linalg.det(raw) / np.linalg.det(cov2), 0.0)) if antialiased else 1.0
    o *= rho
    if o < 1 / 255:
        return None
    campos = -r.T @ t
    d = mean - campos
    d = d / np.linalg.norm(d)
    return dict(mean2d=np.array([fx * tc[0] / tz + cx, fy * tc[1] / tz + cy]), conic=conic,
                cov2d=np.array([cov2[0, 0], cov2[0, 1], cov2[1, 1]]), depth=tz, o=o, rho=rho,
                terms=np.abs(jac) @ np.abs(covc) @ np.abs(jac).T,
                rgb=sh_rgb(np.asarray(sh, float), d))


def project_all(g, cam, antialiased=False, colors=None):
    """Oracle projection of every Gaussian: list of dicts or None. `colors` (N, C): each
    Gaussian's colour instead of its SH colour (the SH coefficients unread; a non-finite
    colour makes the Gaussian invalid)."""
    args = [np.asarray(cam.viewmat, float)] + [float(np.asarray(v)) for v in
                                               (cam.fx, cam.fy, cam.cx, cam.cy)]
    out = []
    for i in range(np.shape(g.means)[0]):
        sh = np.asarray(g.sh[i], float) if colors is None else np.zeros((1, 3))
        p = project_one(np.asarray(g.means[i], float), np.asarray(g.quats[i], float),
                        np.asarray(g.log_scales[i], float), float(g.logit_opacities[i]), sh,
                        *args, cam.width, cam.height, float(np.asarray(cam.near)),
                        float(np.asarray(cam.far)), antialiased)
        if p is not None and colors is not None:
            rgb = np.asarray(colors[i], float)
            p = dict(p, rgb=rgb) if np.all(np.isfinite(rgb)) else None
        out.append(p)
    return out


def composite(g, cam, background=(0, 0, 0), cap=0.99, inclusive=False, antialiased=False,
              colors=None):
    """Brute-force float64 compositing: (image (H,W,C), alpha (H,W), depth (H,W)), C = 3 or
    the channels of `colors` (`project_all`)."""
    proj = project_all(g, cam, antialiased, colors)
    order = sorted((p["depth"], i) for i, p in enumerate(proj) if p is not None)
    w, h = cam.width, cam.height
    px, py = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    channels = 3 if colors is None else np.shape(colors)[1]
    color, depth = np.zeros((h, w, channels)), np.zeros((h, w))
    trans, done = np.ones((h, w)), np.zeros((h, w), bool)
    for _, i in order:
        p = proj[i]
        dx, dy = p["mean2d"][0] - px, p["mean2d"][1] - py
        a, b, c = p["conic"]
        power = -0.5 * (a * dx * dx + c * dy * dy) - b * dx * dy
        alpha = np.minimum(cap, p["o"] * np.exp(power))
        hit = ~done & (power <= 0) & (alpha >= 1 / 255)
        test_t = trans * (1 - alpha)
        stop = (test_t <= 1e-4) if inclusive else (test_t < 1e-4)
        take = hit & ~stop
        wgt = np.where(take, alpha * trans, 0.0)
        color += wgt[..., None] * p["rgb"]
        depth += wgt * p["depth"]
        trans = np.where(take, test_t, trans)
        done |= hit & stop
    return color + trans[..., None] * np.asarray(background, float), 1 - trans, depth
