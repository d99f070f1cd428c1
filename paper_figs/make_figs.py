"""Figures from the recorded results (no GPU needed): run from the repository root.

    python paper_figs/make_figs.py

- pallas_vs_gsplat.png: rasterization-kernel and end-to-end times per scene and camera (H100,
  bench_results/h100-2026-11/triton/gpu_bench.csv): the Table III analog (Local-GS vs vanilla
  kernel) with gsplat beside them.
- precision_tradeoff.png: run time against PSNR vs float64 per exponent form (H100 Pallas kernel,
  numerics/results/render/render_summary_pallas.csv): the Table V analog.
"""

import csv
import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)


def pallas_vs_gsplat():
    path = os.path.join(ROOT, "bench_results", "h100-2026-11", "triton", "gpu_bench.csv")
    rows = list(csv.DictReader(open(path)))
    cases = list(dict.fromkeys((r["scene"], r["width"], r["height"]) for r in rows))
    kinds = ["pallas", "pallas:fast", "pallas_vanilla", "gsplat"]
    fig, axs = plt.subplots(1, 2, figsize=(13, 4))
    x = np.arange(len(cases))
    for ax, key, title in zip(axs, ("raster_ms", "e2e_ms"),
                              ("rasterization stage", "end-to-end forward")):
        for i, kind in enumerate(kinds):
            vals = [float(next(r[key] for r in rows if (r["scene"], r["width"], r["height"])
                               == c and r["row"] == kind)) for c in cases]
            ax.bar(x + (i - 1.5) * 0.2, vals, 0.2, label=kind)
        short = lambda s: s.replace("synthetic1000000", "synth 1M").replace("synthetic3000000",
                                                                          "synth 3M")
        ax.set_xticks(x, [f"{short(s)}\n{w}x{h}" for s, w, h in cases], fontsize=7)
        ax.set_ylabel("ms (H100, median of 30)")
        ax.set_title(title)
        ax.grid(axis="y", alpha=0.3)
    axs[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(HERE, "pallas_vs_gsplat.png"), dpi=110)
    plt.close(fig)


def precision_tradeoff():
    path = os.path.join(ROOT, "numerics", "results", "render", "render_summary_pallas.csv")
    rows = list(csv.DictReader(open(path)))
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    for form, marker in zip(["difference", "global", "local_corner", "local_center"], "osD^"):
        sel = [r for r in rows if r["form"] == form]
        ax.scatter([float(r["time_ms"]) for r in sel], [float(r["psnr_db"]) for r in sel],
                   marker=marker, label=form)
    for r in rows:
        if r["form"] == "global":
            ax.annotate(f"{r['scene']} {r['resolution']}", (float(r["time_ms"]),
                                                            float(r["psnr_db"])), fontsize=6)
    ax.set_xscale("log")
    ax.set_xlabel("forward time, ms (H100, Pallas Local-GS kernel)")
    ax.set_ylabel("PSNR vs float64 render (dB)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(os.path.join(HERE, "precision_tradeoff.png"), dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    pallas_vs_gsplat()
    precision_tradeoff()
    print("wrote", ", ".join(f for f in os.listdir(HERE) if f.endswith(".png")))
