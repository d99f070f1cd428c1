"""Exponent-level float32 study of the Gaussian exponent forms (numerics.forms).

    python -m numerics.study [--quick] --out DIR

Writes DIR/summary.csv (one row per measurement), DIR/cost.csv (numerics.cost on this machine),
PNG plots (errors against resolution, offset and anisotropy; cost against error) and DIR/REPORT.md.

Each measurement draws Gaussians whose 1/255 ellipse contains the sampled pixel (only such pixels
matter to an image): pixel uniform over a `resolution`-wide 16:9 image, centre `offset_px` away in
a random direction, 2D covariance with condition number `anisotropy` and smallest eigenvalue >= the
0.3 px² dilation, scaled so the pixel sits at a random level 0 < q <= τ of the ellipse.

Columns: form, resolution, offset_px, anisotropy, samples,
  max_abs_power_err   worst |fl32(form) − form| on float32 inputs (evaluation error: what `bound`
                      bounds, numerics.forms.evaluation_bound, maximised over the samples);
  bound
  max_abs_total_err   worst error against the exact exponent from float64 inputs (the covariance
                      rounded to float32 and the conic computed from it in float32, as the renderer
                      does; no bound derived: this is the conic's own rounding plus evaluation);
  max_alpha_err       worst |α32 − α64| (α = min(0.99, e^{ln α})), total;
  flip_share          share of samples whose α >= 1/255 decision differs from float64.
Rows `paper_eq11_global` / `paper_eq12_local` reproduce Eq. 11–12: the quadratic
x² − 2μx + μ² in float32 with x, μ in [3990, 4010] (global) and in [−16, 32] (local). Their
`bound` is the rigorous one, 2u·S·(1 + 2u) with S = x² + 2|μx| + μ² at its largest (each
product and each of the two sums rounds once); the paper's Eq. 11–12 count one rounding per term,
u·S (3.81 and 2.44e-4), which float32 can exceed by up to 2x. REPORT.md quotes both.
"""

from __future__ import annotations

import argparse
import csv
import os

import numpy as np

from lgs_jax import hoist

from . import centre, cost, forms
from .report import report
from .sampling import ANISOTROPY, OFFSETS, OPACITIES, RESOLUTIONS, sample



def measure(rng, n, resolution, offset, kappa, opacity=None):
    mean, pixel, cov, log_o = sample(rng, n, resolution, offset, kappa, opacity)
    exact = forms.log_alpha("difference", mean, pixel, forms.conic(cov), log_o)
    f32 = lambda x: np.asarray(x, np.float32)
    up = lambda x: np.asarray(x, np.float64)
    cov32 = f32(cov)
    args32 = (f32(mean), f32(pixel), forms.conic(cov32), f32(log_o))
    axes64 = forms.principal_axes(cov)
    axes32 = tuple(f32(a) for a in axes64)
    alpha64 = np.minimum(0.99, np.exp(exact))
    rows = []
    for form in forms.FORMS:
        got = up(forms.log_alpha(form, *args32, axes32))
        same_inputs = forms.log_alpha(form, *(up(a) for a in args32), tuple(up(a) for a in axes32))
        bound = forms.evaluation_bound(form, *args32, axes32)
        alpha32 = np.minimum(0.99, np.exp(got))
        rows.append(dict(
            form=form, resolution=resolution, offset_px=offset, anisotropy=kappa,
            opacity="" if opacity is None else opacity, samples=n,
            max_abs_power_err=float(np.max(np.abs(got - same_inputs))),
            bound=float(np.max(bound)),
            max_abs_total_err=float(np.max(np.abs(got - exact))),
            max_alpha_err=float(np.max(np.abs(alpha32 - alpha64))),
            flip_share=float(np.mean((alpha32 >= 1 / 255) != (alpha64 >= 1 / 255)))))
    return rows


def low_precision_rows(rng, n):
    """Half-precision evaluation (float16, bfloat16) after a float32 setup, the way a kernel
    would use half arithmetic: difference rounds d = μ − p (float32) and the conic to half and
    evaluates in half; local_corner builds V (Eq. 8) in float32, rounds V and the tile-local
    pixel basis to half and takes the dot product in half. κ <= 100, centres within 64 px; label
    `FORM@DTYPE`, total error against float64, no bound."""
    import ml_dtypes

    rows = []
    for dtype in (np.float16, ml_dtypes.bfloat16):
        half = lambda x: np.asarray(x, dtype)
        for resolution in (1024, 4096):
            for offset in (0, 16, 64):
                for kappa in (1.0, 1e2):
                    mean, pixel, cov, log_o = sample(rng, n, resolution, offset, kappa)
                    exact = forms.log_alpha("difference", mean, pixel, forms.conic(cov), log_o)
                    f32 = lambda x: np.asarray(x, np.float32)
                    mean32, pixel32, log_o32 = f32(mean), f32(pixel), f32(log_o)
                    conic32 = forms.conic(f32(cov))
                    d = half(mean32 - pixel32)
                    a, b, c = (half(conic32[:, k]) for k in range(3))
                    got = {"difference": half(log_o32) + (
                        half(-0.5) * (a * d[:, 0] * d[:, 0] + c * d[:, 1] * d[:, 1])
                        - b * d[:, 0] * d[:, 1])}
                    origin = np.floor(pixel32 / forms.TILE) * forms.TILE
                    v = half(hoist.hoist(mean32, conic32, log_o32, origin))
                    local = pixel32 - origin
                    basis = half(hoist.basis(local[:, 0], local[:, 1]))
                    got["local_corner"] = np.sum(v * basis, axis=-1, dtype=dtype)
                    alpha = lambda p: np.minimum(0.99, np.exp(p))
                    for form, value in got.items():
                        value = np.asarray(value, np.float64)
                        rows.append(dict(
                            form=f"{form}@{np.dtype(dtype).name}", resolution=resolution,
                            offset_px=offset, anisotropy=kappa, opacity="", samples=n,
                            max_abs_power_err="", bound="",
                            max_abs_total_err=float(np.max(np.abs(value - exact))),
                            max_alpha_err=float(np.max(np.abs(alpha(value) - alpha(exact)))),
                            flip_share=float(np.mean((alpha(value) >= 1 / 255) !=
                                                     (alpha(exact) >= 1 / 255)))))
    return rows


def paper_rows(rng, n):
    """Eq. 11–12: f(x) = x² − 2μx + μ² in float32, global (x ≈ μ ≈ 4000) and local ([−16, 32])."""
    out = []
    u = np.finfo(np.float32).eps / 2
    for name, lo, hi in (("paper_eq11_global", 3990.0, 4010.0), ("paper_eq12_local", -16.0, 32.0)):
        x = np.asarray(rng.uniform(lo, hi, n), np.float32)
        mu = np.asarray(np.clip(x + rng.uniform(-1, 1, n), lo, hi), np.float32)
        bound = 2 * u * 4 * max(abs(lo), abs(hi)) ** 2 * (1 + 2 * u)
        got = x * x - np.float32(2) * mu * x + mu * mu
        exact = (np.float64(x) - np.float64(mu)) ** 2
        out.append(dict(form=name, resolution=4000 if "global" in name else 16, offset_px=0,
                        anisotropy=1.0, opacity="", samples=n,
                        max_abs_power_err=float(np.max(np.abs(np.float64(got) - exact))),
                        bound=bound, max_abs_total_err="", max_alpha_err="", flip_share=""))
    return out


def plot(rows, out):
    """PNG plots of the worst error against resolution, offset and anisotropy (figures made
    without pyplot, so that no backend is switched: notebooks keep theirs)."""
    from matplotlib.figure import Figure

    data = [r for r in rows if r["form"] in forms.FORMS]
    for key, xlabel in (("resolution", "image width (px)"), ("offset_px", "centre offset (px)"),
                        ("anisotropy", "condition number κ")):
        fig = Figure(figsize=(6, 4))
        ax = fig.subplots()
        for form in forms.FORMS:
            xs = sorted({r[key] for r in data})
            ys = [max(r["max_abs_total_err"] for r in data if r["form"] == form and r[key] == x)
                  for x in xs]
            ax.loglog([max(x, 0.5) for x in xs], np.maximum(ys, 1e-9), "o-", label=form)
        ax.set_xlabel(xlabel)
        ax.set_ylabel("worst |error| of ln α (float32)")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(os.path.join(out, f"power_err_vs_{key}.png"), dpi=120)


def plot_cost(rows, costs, out):
    """Evaluation time per exponent against the worst total exponent error, one point per form."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(6, 4))
    ax = fig.subplots()
    for c in (c for c in costs if c["form"] in forms.FORMS):
        worst = max(r["max_abs_total_err"] for r in rows if r["form"] == c["form"])
        ax.loglog(c["eval_ns_per_exponent"], worst, "o", label=c["form"])
        ax.annotate(c["form"], (c["eval_ns_per_exponent"], worst), fontsize=7)
    ax.set_xlabel(f"evaluation time per exponent (ns, {costs[0]['device']})")
    ax.set_ylabel("worst |error| of ln α (float32)")
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "cost_vs_error.png"), dpi=120)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m numerics.study", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="fewer samples (seconds, for tests)")
    ap.add_argument("--out", required=True)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    os.makedirs(args.out, exist_ok=True)
    rng = np.random.default_rng(args.seed)
    n = 200 if args.quick else 20000
    rows = paper_rows(rng, 100 * n)
    for resolution in RESOLUTIONS:
        for offset in OFFSETS:
            for kappa in ANISOTROPY:
                rows += measure(rng, n, resolution, offset, kappa)
    for opacity in OPACITIES:
        for offset in (0, 256):
            for kappa in (1.0, 1e4):
                rows += measure(rng, n, 4096, offset, kappa, opacity)
    rows += low_precision_rows(rng, n // 4)
    fields = ["form", "resolution", "offset_px", "anisotropy", "opacity", "samples",
              "max_abs_power_err",
              "bound", "max_abs_total_err", "max_alpha_err", "flip_share"]
    with open(os.path.join(args.out, "summary.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=fields)
        w.writeheader()
        w.writerows(rows)
    import jax

    jax.config.update("jax_enable_x64", True)  # principal_axes' setup is float64
    centre_rows = (centre.sweep(rng, centre.QUICK_SAMPLES, centre.QUICK_RESOLUTIONS)
                   if args.quick else centre.sweep(rng, n, RESOLUTIONS))
    centre.write(centre_rows, args.out)
    costs = cost.measure(4096 if args.quick else 16384, 5 if args.quick else 20)
    per_gaussian = cost.measure_per_gaussian(4096 if args.quick else 16384,
                                             5 if args.quick else 20)
    for name, table in (("cost.csv", costs), ("cost_per_gaussian.csv", per_gaussian)):
        with open(os.path.join(args.out, name), "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(table[0]))
            w.writeheader()
            w.writerows(table)
    plot(rows, args.out)
    plot_cost(rows, costs, args.out)
    report(rows, costs, args.out, centre_rows, per_gaussian)
    print(f"wrote {len(rows)} rows, plots and REPORT.md to {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
