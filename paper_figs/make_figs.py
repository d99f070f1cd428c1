"""Figures from the recorded results (CPU only, no GPU needed), from the repository root:

    python -m paper_figs            (or: python paper_figs/make_figs.py)

Each figure reads recorded CSV files (`FIGURES`: the files and the command that writes them);
a figure whose file is missing is skipped with a message naming the file and that command.

- speedup_vs_scene_size.png (Table III analog): the Local-GS Mosaic GPU forward against our
  vanilla 3DGS kernel (rasterization stage) and against gsplat 1.5.3 (rasterization and end
  to end), against the number of Gaussians, H200 (`benchmarks.scale --full`).
- ablation.png (Table IV analog, XLA `tiles` backend): rasterization time (row − prep) of the
  cumulative ablation baseline → +hoisting → +warp culling → +coherent blending, and local
  coordinates off, with each row's max error against float64; the CPU and H100 runs of
  `benchmarks.ablation`.
- ablation_mosaic.png: the same for the Mosaic GPU kernels (`MOSAIC_ABLATION`).
- precision_tradeoff.png (Table V analog): forward time against PSNR vs float64 per exponent
  form, H100 Pallas kernel (`numerics.render_study --backend pallas`).
- table_v_photos.png (Table V against the photos): held-out PSNR of each training run per
  exponent form and training precision, one point per seed, skull and lego_train
  (`benchmarks.precision_vs_photos`, H100).
- cancellation_vs_resolution.png: the worst float32 error of ln α against image width, per
  form (`numerics.study`: the paper's Eq. 11 cancellation); from float32 world parameters
  (`numerics.centre`), the centre floor with and without the split centre, and needles with
  the principal axes computed in float32 from the covariance's factor.
- culling_per_tile.png (the paper's Fig. 1 idea): per tile of a real scene, the share of
  strip–Gaussian pairs that warp culling skips (`paper_figs.culling`).
"""

from __future__ import annotations

import csv
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
DPI = 110
FWD = "bench_results/render_vs_gsplat"  # fwd_<scene>.csv per scene (benchmarks.scale)
FWD_SCENES = ("lego_800", "guitar_720p", "guitar_4k", "lego_x16_1080p", "guitar_x16_1080p",
              "synthetic4M_1080p", "guitar_x64_1080p", "guitar_x110_4k", "synthetic10M_4k")
FULL_FWD = [f"{FWD}/fwd_{s}.csv" for s in FWD_SCENES]
CPU_ABLATION = "bench_results/cpu_backends/bench.csv"
MOSAIC_ABLATION = "bench_results/ablation/gpu.csv"
PHOTOS = [f"bench_results/precision_vs_photos/results_{k}.csv"
          for k in ("local", "global", "difference", "float64")]
ABLATION_STEPS = ("baseline", "+hoisting", "+warp_culling", "+coherent_blending",
                  "global_coords")


def rows(path):
    with open(os.path.join(ROOT, path)) as f:
        return list(csv.DictReader(f))


def save(fig, name):
    fig.tight_layout()
    fig.savefig(os.path.join(HERE, name), dpi=DPI)
    plt.close(fig)


def speedup_vs_scene_size(paths=FULL_FWD):
    """Speed-ups of the Local-GS row over `vanilla` and `gsplat` against Gaussians."""
    data = [r for path in paths for r in rows(path)]
    by = {(r["scene"], r["row"]): r for r in data}
    scenes = sorted({r["scene"] for r in data}, key=lambda s: int(by[s, "localgs"]["gaussians"]))
    fig, axs = plt.subplots(1, 2, figsize=(12, 4.2), sharex=True)
    series = (("vanilla", "raster_ms", axs[0], "our vanilla 3DGS kernel"),
              ("gsplat", "raster_ms", axs[0], "gsplat 1.5.3 rasterize_to_pixels"),
              ("gsplat", "e2e_ms", axs[1], "gsplat 1.5.3, end to end"))
    for other, key, ax, label in series:
        for res, marker in (("720", "o"), ("800", "s"), ("1080", "D"), ("2160", "^")):
            sel = [s for s in scenes if by[s, "localgs"]["height"] == res and (s, other) in by]
            if not sel:
                continue
            x = [int(by[s, "localgs"]["gaussians"]) for s in sel]
            y = [float(by[s, other][key]) / float(by[s, "localgs"][key]) for s in sel]
            ax.scatter(x, y, marker=marker, label=f"vs {label}, height {res}",
                       color="C0" if other == "vanilla" else ("C1" if key == "raster_ms"
                                                              else "C2"))
            for s, xi, yi in zip(sel, x, y):
                ax.annotate(s, (xi, yi), fontsize=6, alpha=0.7)
    for ax, title in zip(axs, ("rasterization stage", "end-to-end forward")):
        ax.axhline(1, color="k", lw=0.8)
        ax.set_xscale("log")
        ax.set_xlabel("Gaussians")
        ax.set_title(title)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=6)
    axs[0].set_ylabel("speed-up of Local-GS (other / Local-GS time)")
    fig.suptitle(f"Local-GS forward on the H200 ({FWD}/fwd_*.csv)", fontsize=8)
    save(fig, "speedup_vs_scene_size.png")


def _ablation_panel(ax, data, scene, title):
    prep = float(next(r["median_ms"] for r in data if r["scene"] == scene and
                      r["row"] == "prep"))
    sel = {r["row"].split(":", 1)[1]: r for r in data if r["scene"] == scene and ":" in r["row"]
           and r["row"].split(":", 1)[1] in ABLATION_STEPS}
    steps = [s for s in ABLATION_STEPS if s in sel]
    times = [float(sel[s].get("raster_ms") or 0) or float(sel[s]["median_ms"]) - prep
             for s in steps]
    bars = ax.bar(range(len(steps)), times, color=["C0"] * 4 + ["C3"])
    for bar, s in zip(bars, steps):
        err = sel[s].get("max_abs_err")
        if err:
            ax.annotate(f"{float(err):.1e}", (bar.get_x() + bar.get_width() / 2,
                                              bar.get_height()), ha="center", fontsize=6)
    ax.set_xticks(range(len(steps)), [s.replace("_", " ") for s in steps], rotation=30,
                  fontsize=7, ha="right")
    ax.set_title(title, fontsize=8)
    ax.grid(axis="y", alpha=0.3)


def ablation(sources=(("CPU, 2 cores", CPU_ABLATION),), name="ablation.png"):
    """Table IV analog, one panel per (source, scene): raster time per cumulative step, with
    the max error against float64 over each bar."""
    panels = [(label, data, scene) for label, path in sources for data in [rows(path)]
              for scene in dict.fromkeys(r["scene"] for r in data)]
    fig, axs = plt.subplots(1, len(panels), figsize=(max(2.6 * len(panels), 4.6), 3.6),
                            squeeze=False)
    for ax, (label, data, scene) in zip(axs[0], panels):
        w = next(r["width"] for r in data if r["scene"] == scene)
        h = next(r["height"] for r in data if r["scene"] == scene)
        _ablation_panel(ax, data, scene, f"{label}\n{scene} {w}x{h}")
    axs[0][0].set_ylabel("rasterization ms (row − prep)")
    fig.suptitle("cumulative ablation (bar labels: max |error| vs float64)", fontsize=8)
    save(fig, name)


def precision_tradeoff(path="numerics/results/render/render_summary_pallas.csv"):
    data = rows(path)
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    for form, marker in zip(["difference", "global", "local_corner", "local_center"], "osD^"):
        sel = [r for r in data if r["form"] == form]
        ax.scatter([float(r["time_ms"]) for r in sel], [float(r["psnr_db"]) for r in sel],
                   marker=marker, label=form)
    for r in data:
        if r["form"] == "global":
            ax.annotate(f"{r['scene']} {r['resolution']}", (float(r["time_ms"]),
                                                            float(r["psnr_db"])), fontsize=6)
    ax.set_xscale("log")
    ax.set_xlabel("forward time, ms (H100, Pallas Local-GS kernel)")
    ax.set_ylabel("PSNR vs float64 render (dB)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    save(fig, "precision_tradeoff.png")


def table_v_photos(paths=PHOTOS, evals=(("skull", "downscale2"), ("lego_train", "200x200"))):
    """One panel per scene: PSNR against the photos per (form, precision), seeds as points
    (a line joins each seed's float32 and float64 runs), the mean as a bar."""
    data = [dict(r, precision=r.get("precision") or "float32") for p in paths for r in rows(p)]
    forms, colours = ("local", "global", "difference"), {"float32": "C0", "float64": "C3"}
    fig, axs = plt.subplots(1, len(evals), figsize=(4.2 * len(evals), 3.6), squeeze=False)
    for ax, (scene, ev) in zip(axs[0], evals):
        for i, form in enumerate(forms):
            by = {prec: {r["seed"]: float(r["psnr"]) for r in data if (r["scene"], r["eval"],
                  r["form"], r["precision"]) == (scene, ev, form, prec) and r["psnr"]}
                  for prec in colours}
            for j, (prec, seeds) in enumerate(by.items()):
                x = i + (j - 0.5) * 0.35
                ax.bar(x, np.mean(list(seeds.values())) if seeds else 0, width=0.3,
                       color=colours[prec], alpha=0.25, label=prec if i == 0 else None)
                ax.scatter([x] * len(seeds), list(seeds.values()), s=10, color=colours[prec])
            for s in set(by["float32"]) & set(by["float64"]):
                ax.plot([i - 0.175, i + 0.175], [by["float32"][s], by["float64"][s]],
                        color="grey", lw=0.6)
        ys = [float(r["psnr"]) for r in data if (r["scene"], r["eval"]) == (scene, ev)]
        ax.set_ylim(min(ys) - 0.3, max(ys) + 0.3)
        ax.set_xticks(range(len(forms)), forms)
        ax.set_title(f"{scene}, held-out at {ev}", fontsize=9)
        ax.set_ylabel("PSNR against the photos (dB)")
        ax.grid(alpha=0.3, axis="y")
    axs[0][0].legend(fontsize=8, title="trained in", title_fontsize=8)
    fig.suptitle("Table V against the photos: 2,000 steps, 4 seeds (lines pair a seed)",
                 fontsize=9)
    save(fig, "table_v_photos.png")


def _worst_by_width(ax, data, forms=None):
    """One line per form: the worst ln α error of `data`'s rows at each image width."""
    for form in forms or dict.fromkeys(r["form"] for r in data):
        xs = sorted({int(r["resolution"]) for r in data if r["form"] == form})
        ys = [max(float(r["max_abs_total_err"]) for r in data
                  if r["form"] == form and int(r["resolution"]) == x) for x in xs]
        ax.loglog(xs, ys, "o-", label=form, base=2)
    ax.set_xlabel("image width (px)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)


def cancellation_vs_resolution(study="numerics/results/summary.csv",
                               centre="numerics/results/centre.csv"):
    """Worst ln α error against width: per form over the whole study (the paper's
    cancellation); the centre floor (κ = 1, centres within 16 px) with and without the split
    centre; needles (κ = 1e6) with the float32 principal axes."""
    fig, axs = plt.subplots(1, 3, figsize=(16, 4.2))
    _worst_by_width(axs[0], [r for r in rows(study) if r["max_abs_total_err"]
                             and "@" not in r["form"] and not r["form"].startswith("paper")])
    pipeline = rows(centre)
    _worst_by_width(axs[1], [r for r in pipeline if float(r["anisotropy"]) == 1.0
                             and int(r["offset_px"]) <= 16])
    _worst_by_width(axs[2], [r for r in pipeline if float(r["anisotropy"]) == 1e6],
                    ("difference", "local_corner", "local_corner+split",
                     "whitened+split"))
    axs[1].annotate("local_corner+split lies under +split_exact", (0.02, 0.02),
                    xycoords="axes fraction", fontsize=7)
    axs[0].set_ylabel("worst |error| of ln α, float32")
    for ax, title in zip(axs, ("forms (numerics.study: all offsets, κ to 1e6)",
                               "the centre floor: κ = 1, centres within 16 px",
                               "needles: κ = 1e6, centres 0–1024 px away")):
        ax.set_title(title, fontsize=9)
    save(fig, "cancellation_vs_resolution.png")


def culling_per_tile(scenes=("default", "guitar")):
    """Per tile, the share of strip–Gaussian pairs warp culling skips, over the render."""
    fig, axs = plt.subplots(1, len(scenes), figsize=(5.6 * len(scenes) + 1, 3.6), squeeze=False,
                            layout="constrained")
    for ax, name in zip(axs[0], scenes):
        data = rows(f"paper_figs/data/culling_{name}.csv")
        tx = np.array([int(r["tile_x"]) for r in data])
        ty = np.array([int(r["tile_y"]) for r in data])
        share = np.full((ty.max() + 1, tx.max() + 1), np.nan)
        for r, x, y in zip(data, tx, ty):
            share[y, x] = float(r["skipped_share"]) if r["skipped_share"] else np.nan
        w, h = int(data[0]["width"]), int(data[0]["height"])
        ax.imshow(plt.imread(os.path.join(HERE, "data", f"culling_{name}.png")),
                  extent=(0, w, h, 0))
        im = ax.imshow(share, extent=(0, 16 * share.shape[1], 16 * share.shape[0], 0),
                       cmap="viridis", vmin=0, vmax=1, alpha=0.55)
        pairs = sum(int(r["pairs"]) for r in data)
        strips = sum(int(r["strip_pairs"]) for r in data)
        ax.set_title(f"{name} {w}x{h}: warp culling skips {1 - strips / (8 * pairs):.0%}\n"
                     f"of {8 * pairs:,} strip–Gaussian pairs", fontsize=9)
        ax.set_xlim(0, w)
        ax.set_ylim(h, 0)
        ax.axis("off")
    fig.colorbar(im, ax=axs[0].tolist(), shrink=0.8, label="share of strip pairs skipped")
    fig.savefig(os.path.join(HERE, "culling_per_tile.png"), dpi=DPI)
    plt.close(fig)


FIGURES = {
    "speedup_vs_scene_size.png": (speedup_vs_scene_size, FULL_FWD,
                                  "python -m benchmarks.scale --scenes S --csv FILE (GPU)"),
    "ablation.png": (ablation, [CPU_ABLATION],
                     "python -m benchmarks.ablation --preset cpu --csv FILE (CPU)"),
    "ablation_mosaic.png": (lambda: ablation((("GPU, Mosaic GPU kernels", MOSAIC_ABLATION),),
                                             "ablation_mosaic.png"), [MOSAIC_ABLATION],
                            "python -m benchmarks.ablation --preset gpu --csv FILE (GPU)"),
    "precision_tradeoff.png": (precision_tradeoff,
                               ["numerics/results/render/render_summary_pallas.csv"],
                               "python -m numerics.render_study --backend pallas (GPU)"),
    "table_v_photos.png": (table_v_photos, PHOTOS,
                           "python -m benchmarks.precision_vs_photos [--precision float64] (GPU)"),
    "cancellation_vs_resolution.png": (cancellation_vs_resolution,
                                       ["numerics/results/summary.csv",
                                        "numerics/results/centre.csv"],
                                       "python -m numerics.study / python -m numerics.centre"),
    "culling_per_tile.png": (culling_per_tile, ["paper_figs/data/culling_default.csv",
                                                "paper_figs/data/culling_guitar.csv"],
                             "python -m paper_figs.culling (CPU)"),
}


def main(argv=None) -> int:
    """Draw every figure whose files exist; name each skipped one. Exit 0 either way."""
    for name, (draw, paths, command) in FIGURES.items():
        missing = [p for p in paths if not os.path.exists(os.path.join(ROOT, p))]
        if missing:
            print(f"skipped {name}: missing {', '.join(missing)} (written by: {command})")
            continue
        draw()
        print(f"wrote paper_figs/{name}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
