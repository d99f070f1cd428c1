"""Cost of each exponent form: jitted float32 evaluation of ln α on the default JAX device.

    python -m numerics.cost [--gaussians G] [--repeat N] [--csv FILE]

One call evaluates G Gaussians at the 256 pixel centres of one 16x16 tile, the work a tile does
per Gaussian, split as a renderer splits it: `setup` runs once per Gaussian (difference: nothing;
hoisted forms: the 6-vector V of Eq. 8 relative to the tile origin; principal_axes: the 2x2
eigendecomposition in float64, then λ and e₁ rounded to float32), `evaluate` once per
(Gaussian, pixel). Reported: median ns per Gaussian for each part and per exponent for the
evaluation, each form timed in the same interleaved rounds (benchmarks.common.median_ms). The
evaluation arithmetic is that of `numerics.forms.log_alpha` (tests/numerics/test_forms.py checks
they agree).
"""

from __future__ import annotations

import argparse
import csv

import jax
import jax.numpy as jnp
import numpy as np

from benchmarks.common import median_ms
from lgs_jax import hoist

from . import forms, split

FORMS = forms.FORMS + ("difference+split", "local_corner+split")
"""`+split`: the centre as (hi, lo) (numerics.centre): the offset is (hi − p) + lo per exponent
(difference) or (hi − T) + lo per pair before Eq. 8 (local_corner)."""

TILE_ORIGIN = {"global": (1024.0, 512.0), "local_corner": (0.0, 0.0), "local_center": (8.0, 8.0)}
"""Where the timed tile's pixel (0, 0) sits in each form's coordinates (global: a tile at
(1024, 512) of a large image; local: the tile-local frames)."""


def tile_pixels(form):
    """The 256 pixel centres of the tile, (256, 2) float32, in the form's coordinates."""
    y, x = np.mgrid[0:16, 0:16] + 0.5
    shift = np.asarray(TILE_ORIGIN.get(form, (1024.0, 512.0)), np.float32)
    if form == "local_center":
        shift = -shift
    return jnp.asarray(np.stack([x.ravel(), y.ravel()], -1).astype(np.float32) + shift)


def setup(form, mean, conic, log_o, cov64):
    """Per-Gaussian work of a form (float32 outputs; cov64 used by principal_axes only; the
    split forms take mean = (hi, lo))."""
    if form == "local_corner+split":
        hi, lo = mean
        return hoist.hoist(split.offset(hi, lo, jnp.zeros_like(hi)), conic, log_o,
                           jnp.zeros_like(hi))
    if form in ("difference", "difference+split"):
        return mean, conic, log_o
    if form == "principal_axes":
        lam1, lam2, e1 = forms.principal_axes(cov64)
        return mean, (1 / lam1).astype(jnp.float32), (1 / lam2).astype(jnp.float32), \
            e1.astype(jnp.float32), log_o
    origin = jnp.zeros_like(mean)  # the tile origin in the form's own coordinates
    return hoist.hoist(mean, conic, log_o, origin)


def evaluate(form, state, pixels):
    """ln α for every (Gaussian, pixel): (G, P) float32."""
    if form == "difference":
        mean, conic, log_o = (s[:, None] for s in state)
        return forms.log_alpha(form, mean, pixels[None], conic, log_o)
    if form == "difference+split":
        (hi, lo), conic, log_o = state
        d = split.offset(hi[:, None], lo[:, None], pixels[None])
        return forms.log_alpha("difference", d, jnp.zeros_like(d), conic[:, None],
                               log_o[:, None])
    if form == "principal_axes":
        mean, inv1, inv2, e1, log_o = (s[:, None] for s in state)
        d = mean - pixels[None]
        t1 = e1[..., 0] * d[..., 0] + e1[..., 1] * d[..., 1]
        t2 = e1[..., 0] * d[..., 1] - e1[..., 1] * d[..., 0]
        return log_o - 0.5 * (t1 * t1 * inv1 + t2 * t2 * inv2)
    return jnp.einsum("gk,pk->gp", state, hoist.basis(pixels[:, 0], pixels[:, 1]),
                      precision=jax.lax.Precision.HIGHEST)


def scene(n, seed=0):
    """G Gaussians around the timed tile, in each form's coordinates: (mean, conic, log_o, cov64)
    per form; float32 except cov64."""
    rng = np.random.default_rng(seed)
    mean = rng.uniform(-24, 40, (n, 2))
    lam = rng.uniform(0.3, 200, (n, 2))
    cov = forms.covariance(lam[:, 0], lam[:, 1], rng.uniform(0, np.pi, n))
    conic = forms.conic(cov)
    log_o = np.log(rng.uniform(0.05, 1, n))
    f32 = lambda x: jnp.asarray(x, jnp.float32)
    out = {}
    for form in FORMS:
        shift = np.asarray(TILE_ORIGIN.get(form.split("+")[0], (1024.0, 512.0)))
        shift = -shift if form == "local_center" else shift
        m = mean + shift
        if form.endswith("+split"):
            hi = f32(m)
            m = (hi, f32(m - np.asarray(hi, np.float64)))
        else:
            m = f32(m)
        out[form] = (m, f32(conic), f32(log_o), jnp.asarray(cov))
    return out


def measure(n=16384, repeat=20):
    """Rows (form, setup_ns_per_gaussian, eval_ns_per_exponent, device): each form's setup and
    evaluation timed in the same interleaved rounds (benchmarks.common.median_ms)."""
    data = scene(n)
    setups = {f: jax.jit(lambda m, q, o, c, f=f: setup(f, m, q, o, c)) for f in FORMS}
    evals = {f: jax.jit(lambda s, p, f=f: evaluate(f, s, p)) for f in FORMS}
    states = {f: jax.block_until_ready(setups[f](*data[f])) for f in FORMS}
    pixels = {f: tile_pixels(f.split("+")[0]) for f in FORMS}
    fns = {}
    for f in FORMS:
        fns["setup", f] = lambda f=f: jax.block_until_ready(setups[f](*data[f]))
        fns["eval", f] = lambda f=f: jax.block_until_ready(evals[f](states[f], pixels[f]))
    ms = median_ms(fns, repeat)
    dev = jax.devices()[0]
    return [dict(form=f, gaussians=n, setup_ns_per_gaussian=1e6 * ms["setup", f] / n,
                 eval_ns_per_exponent=1e6 * ms["eval", f] / (n * 256),
                 device=f"{dev.platform} ({dev.device_kind})", jax=jax.__version__)
            for f in FORMS]


def plain_centre(means, viewmat, fx, fy, cx, cy):
    """μ = fx·tx/tz + cx (and y), t = W·m + T, in float32 as `lgs_jax.projection` computes it."""
    t = [viewmat[i, 0] * means[:, 0] + viewmat[i, 1] * means[:, 1] + viewmat[i, 2] * means[:, 2]
         + viewmat[i, 3] for i in range(3)]
    return jnp.stack([fx * t[0] / t[2] + cx, fy * t[1] / t[2] + cy], -1)


def measure_centre(n=16384, repeat=20):
    """Rows (centre, ns_per_gaussian, device): the screen-space centre of n Gaussians from their
    float32 world means, plain (`plain_centre`) and split (`numerics.split.centre_split`),
    timed in the same interleaved rounds."""
    rng = np.random.default_rng(0)
    view = np.eye(4, dtype=np.float32)
    view[:3, :3] = np.linalg.qr(rng.normal(size=(3, 3)))[0]  # a rotation (or a reflection)
    view[:3, 3] = rng.normal(0, 3, 3)
    fx = fy = np.float32(0.9 * 4096)
    cx, cy = np.float32(2048), np.float32(1152)
    ahead = view[:3, :3].T.astype(np.float64) @ ([0.0, 0.0, 6.0] - view[:3, 3])  # 6 in front
    means = jnp.asarray((rng.normal(0, 1, (n, 3)) + ahead).astype(np.float32))
    args = (means, jnp.asarray(view)) + tuple(jnp.float32(v) for v in (fx, fy, cx, cy))
    fns = {"plain": jax.jit(plain_centre), "split": jax.jit(split.centre_split)}
    for f in fns.values():
        jax.block_until_ready(f(*args))
    ms = median_ms({k: (lambda f=f: jax.block_until_ready(f(*args))) for k, f in fns.items()},
                   repeat)
    dev = jax.devices()[0]
    return [dict(centre=k, gaussians=n, ns_per_gaussian=1e6 * ms[k] / n,
                 device=f"{dev.platform} ({dev.device_kind})", jax=jax.__version__)
            for k in fns]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m numerics.cost", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--gaussians", type=int, default=16384)
    ap.add_argument("--repeat", type=int, default=20)
    ap.add_argument("--csv")
    args = ap.parse_args(argv)
    jax.config.update("jax_enable_x64", True)  # principal_axes' setup is float64
    rows = measure(args.gaussians, args.repeat)
    for r in rows:
        print(f"{r['form']:>18s}  setup {r['setup_ns_per_gaussian']:8.2f} ns/Gaussian  "
              f"evaluate {r['eval_ns_per_exponent']:7.3f} ns/exponent  ({r['device']})")
    for r in measure_centre(args.gaussians, args.repeat):
        print(f"{'centre ' + r['centre']:>18s}  {r['ns_per_gaussian']:8.2f} ns/Gaussian")
    if args.csv:
        with open(args.csv, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
