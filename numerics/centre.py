"""The float32 centre floor, and the split centre that removes it (the library's centre).

    python -m numerics.centre [--quick] --out DIR

A float32 screen-space centre μ = fx·tx/tz + cx carried in one number (`split.plain_centre`,
as 3DGS computes it) carries the rounding of numbers as large as the image: ulp(μ)/2 =
2^-24·|μ| (3e-5 px at 1K, 5e-4 px at 16K), and before that the camera transform t = W·m + T
rounds at the size of the scene's coordinates. Every exponent form takes d = μ − p (or
Δ = μ − T for the hoist) from that μ, so they share a floor that grows with the image
(numerics/results/REPORT.md, "Reading"). The exponent's gradient at the 1/255 edge is
|Q·d| <= √(τ·λmax(Q)), up to ~6 px⁻¹ with the 0.3 px² dilation, so the floor in ln α is about
6·ulp(μ)/2.

The split centre carries μ as two float32 numbers, μ = hi + lo with |lo| <= ulp(hi)/2, computed
from the float32 parameters with error-free transformations (lgs_jax.twofloat): the camera
transform as a compensated dot product, then the perspective division, the focal length and
the principal point in double-float32 arithmetic. The library projects every centre so
(`lgs_jax.projection`: mean2d = hi, mean2d_lo = lo) and every consumer forms its small offset
first, where the large parts cancel exactly, and adds lo after:

    difference form   d  = (hi − p) + lo      (per exponent; lgs_jax.composite)
    hoisted forms     Δ  = (hi − T) + lo      (per pair, before Eq. 8; lgs_jax.pairs)

hi − p is exact when p is within a factor of two of hi (Sterbenz's lemma; otherwise |d| is
as large as |hi|/2 and the one rounding costs what it costs now), so the offset rounds once, at
the size of d (or Δ), not of μ: one float32 addition per axis. Storing
μ = K + r with K an integer (the tile-relative variant: K − T is exact integer arithmetic) is
the same arithmetic with hi rounded to an integer; `numerics.split.split_to_integer` converts.

Measured (DIR/centre.csv, one row per form, resolution, offset and anisotropy): the worst
|error of ln α| against the exponent of the same float32 parameters evaluated in float64
(`lgs_jax.projection.project` on the float64 cast, then the difference form in float64).
"""

from __future__ import annotations

import argparse
import csv
import os

import jax
import jax.numpy as jnp
import numpy as np

from lgs_jax.projection import EPS2D, project

from . import axes, forms
from .sampling import RESOLUTIONS, sample as sample_2d
from .split import centre_split, log_alpha_split, plain_centre

OFFSETS = (0, 16, 1024)
ANISOTROPY = (1.0, 1e2, 1e4, 1e6)
QUICK_SAMPLES, QUICK_RESOLUTIONS = 300, (1024, 16384)  # --quick (numerics.study's too)
FORMS = ("difference", "local_corner", "difference+split", "local_corner+split",
         "local_corner+split_perspective", "local_corner+split_exact", "whitened+split")
"""`difference`, `local_corner`: the centre in one float32 number (`split.plain_centre`);
`+split`: the library's centre, `lgs_jax.projection`'s (mean2d, mean2d_lo);
`+split_perspective`: the camera transform in plain float32, the rest split
(`centre_split(..., compensated_transform=False)`); `+split_exact`: hi, lo from the float64
centre (what a perfect centre would give: the remaining error is the conic's and the
evaluation's); `whitened+split`: the principal-axes form, whitened (numerics.forms), its axes
from the covariance's factor in float32 (numerics.axes), and the library's centre."""


# ------------------------------------------------------------------ the measurement

def camera(resolution, rng):
    """A 16:9 camera `resolution` px wide (focal 0.9·width) at a random pose: float32
    (viewmat (4, 4), fx, fy, cx, cy, width, height)."""
    from scipy.spatial.transform import Rotation

    height = resolution * 9 // 16
    view = np.eye(4)
    view[:3, :3] = Rotation.random(random_state=rng).as_matrix()
    view[:3, 3] = rng.normal(0, 3, 3)
    f = np.float32(0.9 * resolution)
    return (view.astype(np.float32), f, f, np.float32(resolution / 2), np.float32(height / 2),
            resolution, height)


def sample(rng, n, resolution, offset_px, kappa):
    """Float32 world-space Gaussians (lgs_jax.Gaussians) whose 1/255 ellipse holds a pixel, the
    camera, and the pixels (float64 centres). The screen-space design is that of
    `numerics.sampling.sample` (centre `offset_px` from the pixel, 2D condition number
    `kappa`); each is lifted to a flat 3D Gaussian at depth 2–10 (its covariance in the
    camera's x–y plane scaled by (z/f)², so that J·Σ·Jᵀ + 0.3·I is the designed 2D covariance)
    and moved into the world of a random camera pose."""
    import lgs_jax
    from scipy.spatial.transform import Rotation

    mean2d, pixel, cov, log_o = sample_2d(rng, n, resolution, offset_px, kappa)
    view, fx, fy, cx, cy, width, height = camera(resolution, rng)
    z = rng.uniform(2, 10, n)
    cam_mean = np.stack([(mean2d[:, 0] - cx) * z / fx, (mean2d[:, 1] - cy) * z / fy, z], -1)
    lam1, lam2, e1 = forms.principal_axes(cov)
    sig = np.sqrt(np.maximum(np.stack([lam1, lam2], -1) - EPS2D, 1e-12))
    scales = np.stack([sig[:, 0], sig[:, 1], 1e-4 * np.ones(n)], -1) * (z / fx)[:, None]
    angle = np.arctan2(e1[:, 1], e1[:, 0])
    rot_cam = Rotation.from_euler("z", angle[:, None])
    rot_world = Rotation.from_matrix(view[:3, :3].astype(np.float64).T) * rot_cam
    world = (cam_mean - view[:3, 3].astype(np.float64)) @ view[:3, :3].astype(np.float64)
    quat = rot_world.as_quat()[:, [3, 0, 1, 2]]  # scipy is scalar-last
    o = np.exp(log_o)
    g = lgs_jax.Gaussians(means=world, quats=quat, log_scales=np.log(scales),
                          logit_opacities=np.log(o / (1 - o)), sh=np.zeros((n, 1, 3)))
    g = jax.tree.map(lambda x: np.asarray(x, np.float32), g)
    return g, (view, fx, fy, cx, cy, width, height), pixel


def _camera(cam, dtype):
    import lgs_jax

    view, fx, fy, cx, cy, width, height = cam
    return lgs_jax.Camera(viewmat=np.asarray(view, dtype), fx=dtype(fx), fy=dtype(fy),
                          cx=dtype(cx), cy=dtype(cy), width=width, height=height)


_project = jax.jit(project)
_plain = jax.jit(plain_centre)
_split = jax.jit(centre_split, static_argnames="compensated_transform")
_axes = jax.jit(lambda *args: axes.principal_axes(axes.factor(*args)),
                static_argnums=(8, 9))


def measure(rng, n, resolution, offset_px, kappa):
    """Rows (one per form in FORMS) of the worst ln α and α errors of float32 exponents against
    the float64 exponent of the same float32 parameters, at pixels inside the 1/255 ellipse."""
    g, cam, pixel = sample(rng, n, resolution, offset_px, kappa)
    g64 = jax.tree.map(lambda x: np.asarray(x, np.float64), g)
    p64, p32 = _project(g64, _camera(cam, np.float64)), _project(g, _camera(cam, np.float32))
    f64 = lambda x: np.asarray(x, np.float64)
    log_o = np.log(f64(p64.opacity))
    exact = forms.log_alpha("difference", f64(p64.mean2d), pixel, f64(p64.conic), log_o)
    inside = np.asarray(p64.valid) & np.asarray(p32.valid) & (exact >= np.log(1 / 255))
    conic32 = np.asarray(p32.conic)
    log_o32, pixel32 = np.log(np.asarray(p32.opacity)), pixel.astype(np.float32)
    view, fx, fy, cx, cy = (jnp.asarray(v) for v in cam[:5])
    mean32 = np.asarray(_plain(g.means, view, fx, fy, cx, cy))
    splits = {"split": (p32.mean2d, p32.mean2d_lo),
              "split_perspective": _split(g.means, view, fx, fy, cx, cy,
                                          compensated_transform=False)}
    hi64 = f64(p64.mean2d).astype(np.float32)
    splits["split_exact"] = (hi64, (f64(p64.mean2d) - hi64).astype(np.float32))
    got = {f: forms.log_alpha(f, mean32, pixel32, conic32, log_o32)
           for f in ("difference", "local_corner")}
    for form in FORMS[2:-1]:
        base, kind = form.split("+")
        hi, lo = (np.asarray(x) for x in splits[kind])
        got[form] = log_alpha_split(base, hi, lo, pixel32, conic32, log_o32)
    hi, lo = (np.asarray(x) for x in splits["split"])
    lam1, lam2, e1 = (np.asarray(x) for x in _axes(
        g.means, g.quats, g.log_scales, view, fx, fy, cx, cy, *cam[5:]))
    d = (hi - pixel32) + lo
    got["whitened+split"] = forms.log_alpha("whitened", d, np.zeros_like(d),
                                                  conic32, log_o32, (lam1, lam2, e1))
    alpha = lambda x: np.minimum(0.99, np.exp(x))
    rows = []
    for form in FORMS:
        err = np.abs(f64(got[form]) - exact)[inside]
        aerr = np.abs(alpha(f64(got[form])) - alpha(exact))[inside]
        rows.append(dict(form=form, resolution=resolution, offset_px=offset_px,
                         anisotropy=kappa, samples=int(inside.sum()),
                         max_abs_total_err=float(err.max(initial=0.0)),
                         max_alpha_err=float(aerr.max(initial=0.0))))
    return rows


def sweep(rng, n, resolutions=RESOLUTIONS):
    """`measure` over resolutions x OFFSETS x ANISOTROPY, n samples each."""
    return [r for res in resolutions for off in OFFSETS for kappa in ANISOTROPY
            for r in measure(rng, n, res, off, kappa)]


def write(rows, out):
    """DIR/centre.csv; returns its path."""
    path = os.path.join(out, "centre.csv")
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    return path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m numerics.centre", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true",
                    help="fewer samples, 1K and 16K only (seconds, for tests)")
    ap.add_argument("--out", required=True)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    jax.config.update("jax_enable_x64", True)  # the float64 reference
    os.makedirs(args.out, exist_ok=True)
    rng = np.random.default_rng(args.seed)
    resolutions = QUICK_RESOLUTIONS if args.quick else RESOLUTIONS
    rows = sweep(rng, QUICK_SAMPLES if args.quick else 20000, resolutions)
    path = write(rows, args.out)
    print(f"worst |error of ln α|, κ = 1, centres within 16 px (rows of {path}):")
    print(f"{'form':>32s} " + " ".join(f"{r:>8d}" for r in resolutions))
    for form in FORMS:
        worst = [max(r["max_abs_total_err"] for r in rows if r["form"] == form and
                     r["resolution"] == res and r["anisotropy"] == 1.0 and r["offset_px"] <= 16)
                 for res in resolutions]
        print(f"{form:>32s} " + " ".join(f"{e:8.2g}" for e in worst))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
