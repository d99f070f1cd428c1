"""Rendering-level precision study (Table V analog): float32 forms against the float64 image.

    python -m numerics.render_study --scene NAME=PLY:CAMERAS[#VIEW] --res WxH [--res ...] --out DIR
        [--backend tiles|pallas] [--repeat N]

For each scene and resolution (the view's camera rescaled), renders the float64 `reference` image,
then the float32 image of `--backend` (`tiles`, or `pallas` on a GPU) in each exponent form
(difference: hoist off; global; local_corner; local_center; all exact blending), and writes
DIR/render_summary.csv (PSNR, SSIM from scikit-image, max abs error, share of pixels off by more
than 1/255, and the form's forward time: median over `--repeat` interleaved rounds of the jitted
render, compile excluded), per scene and resolution a PNG of where the global and local_corner
errors sit, and DIR/tradeoff.png (time against PSNR, one panel per scene and size). Full frames,
not crops: a crop re-bases pixel coordinates and would hide the global expansion's error. Meant
for the GPU.
"""

from __future__ import annotations

import argparse
import csv
import os

import jax
import numpy as np

from benchmarks.common import median_ms, psnr

FORMS = {
    "difference": dict(hoist=False),
    "global": dict(local_coords=False),
    "local_corner": dict(),
    "local_center": dict(origin="center"),
}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m numerics.render_study", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", action="append", required=True)
    ap.add_argument("--res", action="append", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--repeat", type=int, default=10, help="timing rounds")
    ap.add_argument("--backend", default="tiles", choices=["tiles", "pallas"])
    args = ap.parse_args(argv)
    jax.config.update("jax_enable_x64", True)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from skimage.metrics import structural_similarity

    import lgs_jax

    os.makedirs(args.out, exist_ok=True)
    rows = []
    for spec in args.scene:
        name, _, paths = spec.partition("=")
        ply, _, cams = paths.partition(":")
        cams, _, view = cams.partition("#")
        g = lgs_jax.load_ply(ply)
        g64 = jax.tree.map(lambda x: np.asarray(x, np.float64), g)
        base = lgs_jax.load_cameras(cams)[int(view or 0)]
        for res in args.res:
            w, h = (int(v) for v in res.split("x"))
            cam = base.scaled(w, h)
            truth = np.asarray(lgs_jax.render(g64, cam, backend="reference").image)
            clipped_truth = np.clip(truth, 0, 1)
            maps = {}
            images, times = _timed_forms(g, cam, args.repeat, args.backend)
            for form in FORMS:
                img = images[form]
                err = np.abs(img - truth).max(-1)
                ssim = structural_similarity(np.clip(img, 0, 1), clipped_truth, channel_axis=-1,
                                             data_range=1.0)
                rows.append(dict(scene=name, resolution=w, height=h, form=form,
                                 backend=args.backend,
                                 psnr_db=psnr(img, truth),
                                 ssim=float(ssim), max_abs_err=float(err.max()),
                                 share_over_1_255=float(np.mean(err > 1 / 255)),
                                 time_ms=times[form]))
                print(rows[-1], flush=True)
                maps[form] = err
            fig, axs = plt.subplots(1, 2, figsize=(12, 3.8))
            vmax = max(maps["global"].max(), 1e-6)
            for ax, form in zip(axs, ("global", "local_corner")):
                im = ax.imshow(np.log10(np.maximum(maps[form], 1e-7)), vmin=-7,
                               vmax=np.log10(vmax), cmap="magma")
                ax.set_title(f"{name} {w}x{h}: {form}, log10 |error|")
                ax.axis("off")
            fig.colorbar(im, ax=axs, shrink=0.8)
            fig.savefig(os.path.join(args.out, f"errmap_{name}_{w}.png"), dpi=80)
            plt.close(fig)
    with open(os.path.join(args.out, "render_summary.csv"), "w", newline="") as f:
        wr = csv.DictWriter(f, fieldnames=list(rows[0]))
        wr.writeheader()
        wr.writerows(rows)
    tradeoff_plot(rows, os.path.join(args.out, "tradeoff.png"))
    return 0


def _timed_forms(g, cam, repeat, backend):
    """Each form's float32 image (float64 numpy) and median forward time in ms, same run.

    Every form is a jitted `render` at one capacity; rounds call each form once in turn, so that
    drift in the machine's speed affects all forms alike (benchmarks.common.median_ms).
    """
    import lgs_jax

    cap = int(lgs_jax.render(g, cam).stats.capacity)
    g = jax.device_put(g)  # time rendering, not host-to-device copies
    fns = {form: jax.jit(lambda g, c, kw=kw: lgs_jax.render(
        g, c, backend=backend, config=lgs_jax.RasterConfig(**kw), capacity=cap).image)
        for form, kw in FORMS.items()}
    images = {form: np.asarray(jax.block_until_ready(f(g, cam)), np.float64)
              for form, f in fns.items()}
    times = median_ms({form: lambda f=f: jax.block_until_ready(f(g, cam))
                       for form, f in fns.items()}, repeat, warmup=False)
    return images, times


def tradeoff_plot(rows, path):
    """Run time against PSNR (vs the float64 render) of each form, one panel per scene and size."""
    import matplotlib.pyplot as plt

    cases = sorted({(r["scene"], int(r["resolution"]), int(r["height"])) for r in rows})
    fig, axs = plt.subplots(1, len(cases), figsize=(3.6 * len(cases), 3.4), squeeze=False)
    for ax, (scene, w, h) in zip(axs[0], cases):
        for form, marker in zip(FORMS, "osD^"):
            r = next(r for r in rows if (r["scene"], int(r["resolution"]), r["form"]) ==
                     (scene, w, form))
            ax.plot(float(r["time_ms"]), min(float(r["psnr_db"]), 150), marker, label=form)
        ax.set_title(f"{scene} {w}x{h}", fontsize=9)
        ax.set_xlabel("forward time (ms)")
        ax.grid(alpha=0.3)
    axs[0][0].set_ylabel("PSNR vs float64 (dB)")
    axs[0][-1].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


if __name__ == "__main__":
    raise SystemExit(main())
