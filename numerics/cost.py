"""Cost of each exponent form: jitted float32 evaluation of ln α on the default JAX device.

    python -m numerics.cost [--gaussians G] [--repeat N] [--csv FILE]

One call evaluates G Gaussians at the 256 pixel centres of one 16x16 tile, the work a tile does
per Gaussian, split as a renderer splits it: `setup` runs once per Gaussian, or pair
(difference: nothing; hoisted forms: the 6-vector V of Eq. 8 relative to the tile origin;
principal_axes and whitened: the 2x2 eigendecomposition in float64, then rounded to float32),
`evaluate` once per (Gaussian, pixel). `FORMS` adds the split centre's forms (numerics.split).
Reported: median ns per Gaussian for each part and per exponent for the evaluation, each form
timed in the same interleaved rounds (`median_cpu_ms`: the process's CPU time, all threads
summed, so that other processes on a shared machine do not count); then per Gaussian the work
that differs upstream (`measure_per_gaussian`: the centre plain or split, the 2D shape as a
conic or as float32 principal axes). The evaluation arithmetic is that of
`numerics.forms.log_alpha` (tests/numerics/test_cost.py checks they agree).
"""

from __future__ import annotations

import argparse
import csv
import os
import statistics
import time

import jax
import jax.numpy as jnp
import numpy as np

from lgs_jax import hoist

from lgs_jax.projection import EPS2D

from . import axes, forms, split

FORMS = forms.FORMS + ("whitened", "difference+split", "local_corner+split", "whitened+split")
"""`+split`: the centre as (hi, lo) (numerics.split): the offset is (hi − p) + lo per exponent
(difference, whitened) or (hi − T) + lo per pair before Eq. 8 (local_corner)."""

TILE_ORIGIN = {"global": (1024.0, 512.0), "local_corner": (0.0, 0.0), "local_center": (8.0, 8.0)}
"""Where the timed tile's pixel (0, 0) sits in each form's coordinates (global: a tile at
(1024, 512) of a large image; local: the tile-local frames)."""


def median_cpu_ms(fns: dict, repeat: int) -> dict:
    """{name: median ms of this process's CPU time} of each blocking callable over `repeat`
    rounds, all callables in turn within each round, after one untimed call each. CPU time
    (`time.process_time`, every thread of XLA's pool summed) rather than wall time: on a
    machine shared with other work, wall time counts the other processes' turns too."""
    for f in fns.values():
        f()
    times = {name: [] for name in fns}
    for _ in range(repeat):
        for name, f in fns.items():
            t0 = time.process_time()
            f()
            times[name].append(time.process_time() - t0)
    return {name: 1e3 * statistics.median(t) for name, t in times.items()}


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
    if form.startswith("whitened"):
        w1, w2 = forms.whitening(*forms.principal_axes(cov64))
        return mean, w1.astype(jnp.float32), w2.astype(jnp.float32), log_o
    if form.startswith("principal_axes"):
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
    if form.startswith("whitened"):
        mean, w1, w2, log_o = state
        w1, w2, log_o = w1[:, None], w2[:, None], log_o[:, None]
        d = (split.offset(mean[0][:, None], mean[1][:, None], pixels[None]) if form.endswith(
            "+split") else mean[:, None] - pixels[None])
        t1 = w1[..., 0] * d[..., 0] + w1[..., 1] * d[..., 1]
        t2 = w2[..., 0] * d[..., 0] + w2[..., 1] * d[..., 1]
        return log_o - 0.5 * (t1 * t1 + t2 * t2)
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
    evaluation timed in the same interleaved rounds (`median_cpu_ms`)."""
    data = scene(n)
    setups = {f: jax.jit(lambda m, q, o, c, f=f: setup(f, m, q, o, c)) for f in FORMS}
    evals = {f: jax.jit(lambda s, p, f=f: evaluate(f, s, p)) for f in FORMS}
    states = {f: jax.block_until_ready(setups[f](*data[f])) for f in FORMS}
    pixels = {f: tile_pixels(f.split("+")[0]) for f in FORMS}
    fns = {}
    for f in FORMS:
        fns["setup", f] = lambda f=f: jax.block_until_ready(setups[f](*data[f]))
        fns["eval", f] = lambda f=f: jax.block_until_ready(evals[f](states[f], pixels[f]))
    ms = median_cpu_ms(fns, repeat)
    dev = jax.devices()[0]
    load = os.getloadavg()[0]  # how shared the machine was
    return [dict(form=f, gaussians=n, setup_ns_per_gaussian=1e6 * ms["setup", f] / n,
                 eval_ns_per_exponent=1e6 * ms["eval", f] / (n * 256),
                 device=f"{dev.platform} ({dev.device_kind})", jax=jax.__version__,
                 load_average=load, cores=os.cpu_count())
            for f in FORMS]


def conic_from_factor(*args):
    """The conic (N, 3) from Σ2 = A·Aᵀ + 0.3·I (numerics.axes.factor), entry by entry as
    `lgs_jax.projection` forms and inverts it."""
    a = axes.factor(*args)
    sxx, sxy, syy = (axes._dot(a[:, i], a[:, j]) for i, j in ((0, 0), (0, 1), (1, 1)))
    sxx, syy = sxx + EPS2D, syy + EPS2D
    det = sxx * syy - sxy * sxy
    return jnp.stack([syy / det, -sxy / det, sxx / det], -1)


def axes_from_factor(*args):
    """The whitened axes (w₁, w₂) from the same factor (numerics.axes.principal_axes, then
    numerics.forms.whitening): the per-Gaussian setup of the robust form in float32."""
    return forms.whitening(*axes.principal_axes(axes.factor(*args)))


def measure_per_gaussian(n=16384, repeat=20):
    """Rows (centre, ns_per_gaussian, device) of per-Gaussian work, timed in the same
    interleaved rounds: the screen-space centre from float32 world means, plain
    (`numerics.split.plain_centre`) and split (`numerics.split.centre_split`, the library's
    arithmetic, as lgs_jax.projection computes it); the 2D shape from the 3D one,
    as a conic (`conic_from_factor`) and as principal axes (`axes_from_factor`)."""
    rng = np.random.default_rng(0)
    view = np.eye(4, dtype=np.float32)
    view[:3, :3] = np.linalg.qr(rng.normal(size=(3, 3)))[0]  # a rotation (or a reflection)
    view[:3, 3] = rng.normal(0, 3, 3)
    fx = fy = np.float32(0.9 * 4096)
    cx, cy = np.float32(2048), np.float32(1152)
    ahead = view[:3, :3].T.astype(np.float64) @ ([0.0, 0.0, 6.0] - view[:3, 3])  # 6 in front
    means = jnp.asarray((rng.normal(0, 1, (n, 3)) + ahead).astype(np.float32))
    args = (means, jnp.asarray(view)) + tuple(jnp.float32(v) for v in (fx, fy, cx, cy))
    shape_args = (means, jnp.asarray(rng.normal(size=(n, 4)).astype(np.float32)),
                  jnp.asarray(rng.uniform(-6, -2, (n, 3)).astype(np.float32))) + args[1:]
    fns = {"plain": (jax.jit(split.plain_centre), args),
           "split": (jax.jit(split.centre_split), args),
           "conic": (jax.jit(conic_from_factor, static_argnums=(8, 9)), shape_args + (4096, 2304)),
           "axes": (jax.jit(axes_from_factor, static_argnums=(8, 9)), shape_args + (4096, 2304))}
    for f, a in fns.values():
        jax.block_until_ready(f(*a))
    ms = median_cpu_ms({k: (lambda f=f, a=a: jax.block_until_ready(f(*a)))
                    for k, (f, a) in fns.items()}, repeat)
    dev = jax.devices()[0]
    return [dict(work=k, gaussians=n, ns_per_gaussian=1e6 * ms[k] / n,
                 device=f"{dev.platform} ({dev.device_kind})", jax=jax.__version__)
            for k in fns]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m numerics.cost", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--gaussians", type=int, default=16384)
    ap.add_argument("--repeat", type=int, default=20)
    ap.add_argument("--csv", help="write the forms' rows here, the per-Gaussian rows to "
                    "FILE_per_gaussian.csv")
    args = ap.parse_args(argv)
    jax.config.update("jax_enable_x64", True)  # principal_axes' setup is float64
    rows = measure(args.gaussians, args.repeat)
    for r in rows:
        print(f"{r['form']:>18s}  setup {r['setup_ns_per_gaussian']:8.2f} ns/Gaussian  "
              f"evaluate {r['eval_ns_per_exponent']:7.3f} ns/exponent  ({r['device']})")
    per_gaussian = measure_per_gaussian(args.gaussians, args.repeat)
    for r in per_gaussian:
        print(f"{'per Gaussian: ' + r['work']:>20s}  {r['ns_per_gaussian']:8.2f} ns")
    if args.csv:
        for path, table in ((args.csv, rows),
                            (args.csv.removesuffix(".csv") + "_per_gaussian.csv", per_gaussian)):
            with open(path, "w", newline="") as f:
                w = csv.DictWriter(f, fieldnames=list(table[0]))
                w.writeheader()
                w.writerows(table)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
