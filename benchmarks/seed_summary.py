"""Ours against gsplat's trainer over several runs (seeds) of `benchmarks/train_vs_gsplat.py`.

    python benchmarks/seed_summary.py RUN/curves.csv [RUN2/curves.csv ...] [--scene skull]
        [--from-step 1000]

One held-out score of one run on a hard capture moves more than the differences we look for
(BENCHMARKS.md §5), so a claim about the trainers rests on several seeds. Per curves.csv (both
trainers' held-out PSNR / SSIM at the same steps) this prints ours − gsplat's at the last step
and averaged over the steps >= --from-step, then the mean over the runs with its standard error
(sd / sqrt(runs); none for one run).
"""

from __future__ import annotations

import argparse
import csv
import math
import statistics
import sys


def differences(path: str, scene: str | None = None, from_step: int = 0) -> dict:
    """{final_psnr, final_ssim, curve_psnr, curve_ssim}: ours − gsplat's in one curves.csv, at
    the last step both evaluated and averaged over the shared steps >= from_step."""
    by = {"lgs_jax": {}, "gsplat": {}}
    with open(path, newline="") as f:
        for r in csv.DictReader(f):
            if r["trainer"] in by and (scene is None or r["scene"] == scene):
                by[r["trainer"]][int(r["step"])] = (float(r["heldout_psnr"]),
                                                    float(r["heldout_ssim"]))
    steps = sorted(set(by["lgs_jax"]) & set(by["gsplat"]))
    if not steps:
        raise ValueError(f"{path}: no step evaluated by both trainers"
                         + (f" for scene {scene}" if scene else ""))
    d = {s: [a - b for a, b in zip(by["lgs_jax"][s], by["gsplat"][s])] for s in steps}
    late = [s for s in steps if s >= from_step] or steps[-1:]
    return dict(final_psnr=d[steps[-1]][0], final_ssim=d[steps[-1]][1],
                curve_psnr=statistics.fmean(d[s][0] for s in late),
                curve_ssim=statistics.fmean(d[s][1] for s in late))


def mean_and_error(values: list[float]) -> tuple[float, float | None]:
    """(mean, standard error of the mean), the error None for fewer than two values."""
    m = statistics.fmean(values)
    return m, (statistics.stdev(values) / math.sqrt(len(values)) if len(values) > 1 else None)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("curves", nargs="+", help="curves.csv files of train_vs_gsplat runs")
    ap.add_argument("--scene", help="the scene to read (default: every row)")
    ap.add_argument("--from-step", type=int, default=0,
                    help="first step of the curve average (default: all)")
    args = ap.parse_args(argv)
    rows = [differences(p, args.scene, args.from_step) for p in args.curves]
    keys = ("final_psnr", "final_ssim", "curve_psnr", "curve_ssim")
    print("ours - gsplat's " + "".join(f"{k:>12}" for k in keys) + "  run")
    for path, r in zip(args.curves, rows):
        print(" " * 15 + "".join(f"{r[k]:+12.4f}" for k in keys) + f"  {path}")
    cells = []
    for k in keys:
        m, e = mean_and_error([r[k] for r in rows])
        cells.append(f"{m:+.4f}" + (f" ± {e:.4f}" if e is not None else ""))
    print(f"mean ± s.e. ({len(rows)} runs): " + ", ".join(f"{k} {c}" for k, c in zip(keys, cells)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
