"""Run time against error: every backend and Local-GS ablation on the same scene and camera.

    python -m benchmarks.ablation [--scene SPEC ...] [--data DIR] [--repeat N] [--csv FILE]
        [--no-error] [--rows ROW ...]
    python -m benchmarks.ablation --preset cpu --csv bench_results/ablation/cpu.csv
    python -m benchmarks.ablation --preset gpu --csv bench_results/ablation/gpu.csv  # Table IV

The `cpu` preset runs the `tiles` rows (`common.TILES_ROWS`), the `gpu` preset the Pallas
kernels' cumulative ablation (`common.ABLATION_ROWS` without `brute`: vanilla, baseline,
+hoisting, +warp culling, +coherent blending, and local coordinates off).

Scene SPECs: benchmarks.common (e.g. `guitar@640x360`, `default@640x360`,
`synthetic:100000@640x360`). Every row (`common.TILES_ROWS`) is compiled first (compile time
reported separately); then `--repeat` rounds each call every row once, in turn
(`common.median_ms`); a row's time is its median over the rounds. Rows report tile–Gaussian and
strip–Gaussian pairs and the error against the float64 reference backend (max abs and PSNR over
the image). The `prep` row times projection and binning alone (shared by all tiled backends): a
row's time minus prep is its rasterization time.
"""

from __future__ import annotations

import argparse
import csv
import sys

import jax
import numpy as np

import lgs_jax
from lgs_jax.binning import bin_gaussians
from lgs_jax.layout import tile_grid
from lgs_jax.pairs import strip_pair_count
from lgs_jax.projection import project

from .common import (ABLATION_ROWS, TILES_ROWS, Case, add_data_argument, device_line,
                     median_ms, parse_scene, psnr, timed)

ROWS = {**TILES_ROWS, **ABLATION_ROWS}
PRESETS = {"cpu": ["guitar@640x360", "lego_sh3@400x400", "synthetic:100000@640x360"],
           "gpu": ["guitar_720p", "guitar_x16_1080p", "synthetic4M_1080p", "synthetic10M_4k"]}
PRESET_ROWS = {"cpu": list(TILES_ROWS),
               "gpu": ["reference"] + [r for r in ABLATION_ROWS if r != "brute"]}


def _prep(cap: int):
    return jax.jit(lambda g, c: bin_gaussians(project(g, c), c.width, c.height, cap).tile_start)


def _strip_pairs(out, g, cam, config, cap: int) -> int:
    """The row's strip–Gaussian pairs: as its backend reports them, or counted in XLA
    (`pairs.strip_pair_count`) where the Mosaic GPU kernels do not count them (−1)."""
    reported = int(getattr(out.stats.backend_stats, "strip_pairs", 0))
    if reported >= 0:
        return reported
    p = jax.jit(project)(g, cam)
    bins = jax.jit(lambda p: bin_gaussians(p, cam.width, cam.height, cap))(p)
    count = jax.jit(strip_pair_count, static_argnums=(2, 3))(
        p, bins, tile_grid(cam.width, cam.height)[0], config)
    return int(count)


def run_case(case: Case, rows, repeat: int, with_error: bool):
    render = lgs_jax.render
    g, cam = case.scene, case.camera
    first = render(g, cam)
    cap = int(first.stats.capacity)
    truth = None
    if with_error:
        g64 = jax.tree.map(lambda x: np.asarray(x, np.float64), g)
        truth = np.asarray(render(g64, cam, backend="reference", capacity=cap).image)
    fns, outs, compile_s = {"prep": _prep(cap)}, {}, {}
    for name in rows:
        backend, config = ROWS[name]
        fns[name] = jax.jit(lambda g, c, b=backend, cf=config: render(g, c, backend=b, config=cf,
                                                                      capacity=cap))
    for name, f in fns.items():
        outs[name], compile_s[name] = timed(f, g, cam)
    times = median_ms({name: lambda f=f: jax.block_until_ready(f(g, cam)) for name, f in
                       fns.items()}, repeat, warmup=False)
    prep = dict(scene=case.name, width=cam.width, height=cam.height, gaussians=g.num, row="prep",
                median_ms=times["prep"], compile_s=compile_s["prep"],
                pairs=int(first.stats.pairs_required), strip_pairs=0)
    print(_format(prep), flush=True)
    results = [prep]
    for name in rows:
        out = outs[name]
        row = dict(scene=case.name, width=cam.width, height=cam.height, gaussians=g.num,
                   row=name, median_ms=times[name],
                   compile_s=compile_s[name], pairs=int(out.stats.pairs_required),
                   strip_pairs=_strip_pairs(out, g, cam, ROWS[name][1], cap))
        if truth is not None:
            err = np.abs(np.asarray(out.image, np.float64) - truth)
            row.update(max_abs_err=float(err.max()), psnr_db=psnr(out.image, truth))
        results.append(row)
        print(_format(row), flush=True)
    ref = next((r for r in results if r["row"] == "reference"), None)
    for r in results:
        if ref and r["row"] != "prep":
            r["speedup_vs_reference"] = ref["median_ms"] / r["median_ms"]
            r["raster_ms"] = r["median_ms"] - prep["median_ms"]
    return results


def _format(r):
    err = (f"  max|err| {r['max_abs_err']:.2e}  PSNR {r['psnr_db']:6.1f} dB"
           if "max_abs_err" in r else "")
    return (f"{r['scene']:>16s} {r['width']}x{r['height']} {r['row']:<26s} "
            f"{r['median_ms']:9.1f} ms (compile {r['compile_s']:5.1f} s)  pairs {r['pairs']:>9d} "
            f"strip-pairs {r['strip_pairs']:>10d}{err}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.ablation", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", action="append", default=[], help="scene SPEC (repeatable)")
    ap.add_argument("--preset", choices=sorted(PRESETS))
    add_data_argument(ap)
    ap.add_argument("--rows", nargs="+", choices=list(ROWS),
                    help="rows to run (default: the preset's, else the cpu rows)")
    ap.add_argument("--repeat", type=int, default=7, help="timing rounds")
    ap.add_argument("--no-error", action="store_true", help="skip the float64 reference")
    ap.add_argument("--csv", help="write rows to this CSV file")
    args = ap.parse_args(argv)
    jax.config.update("jax_enable_x64", True)  # for the float64 ground truth; renders stay f32
    specs = args.scene + (PRESETS[args.preset] if args.preset else [])
    if not specs:
        specs = ["default@640x360"]
    args.rows = args.rows or PRESET_ROWS[args.preset or "cpu"]
    print(device_line())
    rows = []
    for spec in specs:
        rows += run_case(parse_scene(spec, args.data), args.rows, args.repeat, not args.no_error)
    print("\nspeedup vs reference (same run; raster = row − prep):")
    for r in rows:
        if "speedup_vs_reference" in r:
            print(f"  {r['scene']:>16s} {r['row']:<26s} {r['speedup_vs_reference']:6.2f}x"
                  f"   raster {r['raster_ms']:8.1f} ms")
    if args.csv:
        with open(args.csv, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=sorted({k for r in rows for k in r}))
            w.writeheader()
            w.writerows(rows)
        print(f"wrote {args.csv}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
