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

from . import cost, forms

RESOLUTIONS = (1024, 2048, 4096, 8192, 16384)
OFFSETS = (0, 4, 16, 64, 256, 1024, 4096)
ANISOTROPY = (1.0, 1e2, 1e4, 1e6)
OPACITIES = (1.5 / 255, 0.05, 0.5, 1.0)  # the opacity sweep (4096 px wide; empty column elsewhere)
LN255 = np.log(255.0)


def sample(rng, n, resolution, offset, kappa, opacity=None):
    """Float64 Gaussians (mean, pixel, cov, log_o) with the pixel inside the 1/255 ellipse
    (opacity uniform in [2/255, 1] unless given)."""
    height = resolution * 9 // 16
    pixel = np.floor(rng.uniform([0, 0], [resolution, height], (n, 2))) + 0.5
    phi = rng.uniform(0, 2 * np.pi, n)
    d = (offset + rng.uniform(0, 1, n))[:, None] * np.stack([np.cos(phi), np.sin(phi)], -1)
    theta = rng.uniform(0, np.pi, n)
    c, s = np.cos(theta), np.sin(theta)
    lam = np.stack([np.full(n, kappa), np.ones(n)], -1)  # shape, scaled below
    log_o = np.log(rng.uniform(2 / 255, 1.0, n) if opacity is None else np.full(n, opacity))
    tau = 2 * (LN255 + log_o)
    level = tau * rng.uniform(0.01, 1.0, n)  # target q at the pixel
    # q(d) for eigenvalues lam·scale: scale = q(d; lam) / level.
    t1, t2 = c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]
    scale = (t1 * t1 / lam[:, 0] + t2 * t2 / lam[:, 1]) / level
    lam = lam * scale[:, None]
    lam = np.maximum(lam, 0.3 + 1e-3 * rng.uniform(0, 1, (n, 2)))  # the dilation floor
    return pixel + d, pixel, forms.covariance(lam[:, 0], lam[:, 1], theta), log_o


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


def _worst(data, form, **kw):
    """Worst total exponent error of a form over the rows matching every kw."""
    return max(r["max_abs_total_err"] for r in data
               if r["form"] == form and all(r[k] == v for k, v in kw.items()))


def _paper_section(rows):
    eq = {r["form"]: r for r in rows if r["form"].startswith("paper")}
    below = all(eq[k]["max_abs_power_err"] <= b for k, b in (("paper_eq11_global", 3.81),
                                                            ("paper_eq12_local", 2.44e-4)))
    return ["## The paper's bounds (Eq. 11–12)", "",
            f"- Global quadratic, x, μ in [3990, 4010]: measured "
            f"{eq['paper_eq11_global']['max_abs_power_err']:.3g}; paper's Eq. 11: 3.81; rigorous "
            f"bound 2u·S: {eq['paper_eq11_global']['bound']:.3g}.",
            f"- Local quadratic, x, μ in [−16, 32]: measured "
            f"{eq['paper_eq12_local']['max_abs_power_err']:.3g}; paper's Eq. 12: 2.44e-4; "
            f"rigorous bound: {eq['paper_eq12_local']['bound']:.3g}.",
            "- Eq. 11–12 count one rounding per term; float32 rounds each product and each sum, "
            "so a rigorous bound is twice theirs. In this run the measured errors "
            + ("stay below the paper's figures" if below else "exceed a paper figure") +
            " and below the rigorous bounds; the global/local ratio (~1e4) is the paper's point "
            "and holds."]


def _forms_section(data):
    near = lambda form: max(r["max_abs_total_err"] for r in data
                            if r["form"] == form and r["offset_px"] <= 16)
    far = lambda form: max(r["max_abs_total_err"] for r in data
                           if r["form"] == form and r["offset_px"] >= 1024)
    flips = lambda form: max(r["flip_share"] for r in data if r["form"] == form)
    lines = ["## Forms, centres within 16 px of the pixel vs 1024 px or more away", "",
             "| form | worst error, offset <= 16 px | worst error, offset >= 1024 px | worst "
             "1/255-flip share |", "|---|---:|---:|---:|"]
    for form in forms.FORMS:
        lines.append(f"| {form} | {near(form):.3g} | {far(form):.3g} | {flips(form):.2%} |")
    lines += ["", "## By anisotropy (all offsets and resolutions)", "",
              "| form | " + " | ".join(f"κ={k:g}" for k in ANISOTROPY) + " |",
              "|---|" + "---:|" * len(ANISOTROPY)]
    for form in forms.FORMS:
        lines.append(f"| {form} | " + " | ".join(
            f"{_worst(data, form, anisotropy=k):.3g}" for k in ANISOTROPY) + " |")
    return lines


def _reading_section(data):
    floor = {res: _worst(data, "difference", anisotropy=1.0, resolution=res)
             for res in (RESOLUTIONS[0], RESOLUTIONS[-1])}
    return ["## Reading", "",
            f"- Isotropic Gaussians (κ = 1) share one floor in every form, growing with the "
            f"image: {floor[RESOLUTIONS[0]]:.2g} at {RESOLUTIONS[0]} px wide, "
            f"{floor[RESOLUTIONS[-1]]:.2g} at {RESOLUTIONS[-1]} px. It is the float32 rounding "
            "of the centre coordinate itself (ulp ≈ 1e-3 px at 16K), which no evaluation form "
            "removes: only carrying the centre relative to its tile from higher precision would.",
            "- The global expansion's error grows with resolution, as Eq. 11 says; the paper's "
            "claim that tile-local coordinates remove it holds against the global expansion.",
            "- The original 3DGS difference form never expands globally; compare its column with "
            "the local forms before crediting the hoist with accuracy.",
            "- For needles (large κ) far from the pixel every screen-space form is limited by "
            "the float32 conic itself (max_abs_total_err vs max_abs_power_err in summary.csv); "
            "the principal-axes form, with axes computed once per Gaussian in float64, is the "
            "robust alternative."]


def _opacity_section(data):
    swept = [r for r in data if r["opacity"] != ""]
    lines = ["## By opacity (4096 px wide, offsets 0 and 256 px, κ = 1 and 1e4)", "",
             "| form | " + " | ".join(f"o={o:.3g}" for o in OPACITIES) + " | 1/255 flips, "
             f"o={OPACITIES[0]:.3g} |", "|---|" + "---:|" * (len(OPACITIES) + 1)]
    for form in forms.FORMS:
        sel = lambda o: [r for r in swept if r["form"] == form and r["opacity"] == o]
        lines.append(f"| {form} | " + " | ".join(
            f"{max(r['max_abs_total_err'] for r in sel(o)):.3g}" for o in OPACITIES)
            + f" | {max(r['flip_share'] for r in sel(OPACITIES[0])):.2%} |")
    flip0 = lambda form: max(r["flip_share"] for r in swept
                             if r["form"] == form and r["opacity"] == OPACITIES[0])
    return lines + [
        "", "At o just above 1/255 the alpha ellipse is small (τ = 2 ln(255·o) ≈ 0.8) and "
        "every sample sits near the 1/255 threshold; even there the local forms flip "
        f"{flip0('local_corner'):.2%} of the decisions and the global expansion "
        f"{flip0('global'):.2%}. The local forms' error grows with opacity because τ, and "
        "with it the reach |d| of the ellipse and the size of the terms, grows."]


def _half_precision_section(rows):
    low = [r for r in rows if "@" in r["form"]]
    lines = ["## Half precision (κ <= 100, centres within 64 px; total error)", "",
             "| form | width | worst ln α error | worst α error | 1/255 flips |",
             "|---|---:|---:|---:|---:|"]
    for form in sorted({r["form"] for r in low}):
        for res in sorted({r["resolution"] for r in low}):
            sel = [r for r in low if r["form"] == form and r["resolution"] == res]
            lines.append(f"| {form} | {res} | {max(r['max_abs_total_err'] for r in sel):.3g} | "
                         f"{max(r['max_alpha_err'] for r in sel):.3g} | "
                         f"{max(r['flip_share'] for r in sel):.2%} |")
    w16 = lambda form: max(r["max_abs_total_err"] for r in low if r["form"] == form)
    a16 = lambda form: max(r["max_alpha_err"] for r in low if r["form"] == form)
    return lines + [
        "", "Here the hoist hurts: with 11 significant bits (float16) the expansion's terms, "
        "which reach hundreds inside a tile before cancelling, lose what the difference "
        f"form keeps (worst ln α error {w16('local_corner@float16'):.2g} vs "
        f"{w16('difference@float16'):.2g}; α {a16('local_corner@float16'):.2g} vs "
        f"{a16('difference@float16'):.2g}). bfloat16 (8 bits) is unusable in either form. "
        "A half-precision kernel should evaluate the difference form from float32 "
        "offsets, never the hoisted one; float32 is where the hoist is free."]


def _cost_section(data, costs):
    by_cost = {c["form"]: c for c in costs}
    lines = [f"## Cost ({costs[0]['device']}, `python -m numerics.cost`, same run)", "",
             "| form | setup, ns per Gaussian | evaluation, ns per exponent | worst error |",
             "|---|---:|---:|---:|"]
    for form in forms.FORMS:
        c = by_cost[form]
        lines.append(f"| {form} | {c['setup_ns_per_gaussian']:.1f} | "
                     f"{c['eval_ns_per_exponent']:.3f} | {_worst(data, form):.3g} |")
    return lines


def _recommendation_section(data, costs):
    by_cost = {c["form"]: c for c in costs}
    ratio = lambda key: by_cost["principal_axes"][key] / max(by_cost["local_corner"][key], 1e-12)
    alpha_err = lambda form: max(r["max_alpha_err"] for r in data if r["form"] == form)
    worst = lambda form: _worst(data, form)
    return ["## Recommendation", "",
            "- The renderer should evaluate in tile-local coordinates (`local_coords=True`, "
            "the default; corner or centre origin are equivalent to within 0.6 dB): it is as "
            "accurate as the original difference form, and the hoist saves per-exponent "
            f"arithmetic ({by_cost['local_corner']['eval_ns_per_exponent']:.3f} vs "
            f"{by_cost['difference']['eval_ns_per_exponent']:.3f} ns here; whether that shows "
            "in a whole render depends on the backend: numerics/results/render/tradeoff.png). "
            "Never the global expansion: its worst exponent error here is "
            f"{worst('global'):.3g} (an α off by up to {alpha_err('global'):.2g}) and "
            "it grows with the image.",
            "- principal_axes is the only form that survives κ = 1e6 needles "
            f"({worst('principal_axes'):.3g} vs {worst('local_corner'):.3g}), at "
            f"{ratio('setup_ns_per_gaussian'):.1f}x "
            "the per-Gaussian setup (a float64 eigendecomposition) and "
            f"{ratio('eval_ns_per_exponent'):.1f}x "
            "the evaluation here. The renderer does not need it: the 0.3 px² dilation caps "
            "screen-space anisotropy at λ_max/0.3, so κ = 1e6 needs σ_max ≈ 550 px, "
            "and at rendering level (numerics/results/render/README.md, H100) the local forms "
            "are within 1/255 of float64 on all but 8e-7 of the pixels up to 8K. It is the "
            "form to use where the conic itself is ill-conditioned (no dilation, or "
            "half-precision storage).",
            "- The floor that remains at 8K–16K is the float32 centre coordinate; carrying "
            "means relative to their tile (projection in tile-local coordinates) would remove "
            "it and is the next step if 16K rendering matters."]


def report(rows, costs, out):
    """DIR/REPORT.md: every number computed from this run's rows and costs."""
    data = [r for r in rows if r["form"] in forms.FORMS]
    sections = [_paper_section(rows), _forms_section(data), _reading_section(data),
                _opacity_section(data), _half_precision_section(rows),
                _cost_section(data, costs), _recommendation_section(data, costs)]
    lines = ["# Float32 exponent study (exponent level)", "",
             "Generated by `python -m numerics.study`; every number below is computed by that run "
             "(summary.csv). Errors are worst absolute errors of ln α in float32."]
    for section in sections:
        lines += [""] + section
    with open(os.path.join(out, "REPORT.md"), "w") as f:
        f.write("\n".join(lines) + "\n")


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
    costs = cost.measure(4096 if args.quick else 16384, 5 if args.quick else 20)
    with open(os.path.join(args.out, "cost.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(costs[0]))
        w.writeheader()
        w.writerows(costs)
    plot(rows, args.out)
    plot_cost(rows, costs, args.out)
    report(rows, costs, args.out)
    print(f"wrote {len(rows)} rows, plots and REPORT.md to {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
