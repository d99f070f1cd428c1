"""The paper's Table V against ground truth: scenes trained in each exponent form (`fit
--alpha-form`), scored on their held-out views against the photos and against a float64 render.

    python -m benchmarks.precision_vs_photos [--data-root DIR] [--scenes lego_train skull]
        [--forms local global difference] [--seeds 4] [--steps N] [--backend tiles|pallas]
        [--precision float32|float64] [--shrink F] [--out DIR] [--dry-run]
    python -m benchmarks.precision_vs_photos --summary [--out DIR] [--inputs CSV ...]

Per scene, seed and form (forms innermost, so that a call cut short keeps whole seeds), in this
process: `fit --alpha-form FORM --seed S --downscale D --steps N` (`train.fit` from those
command-line words: the default recipe, no evaluation or checkpoint inside the run; its
compiled programs kept for the next seeds), then the run's scene.ply at each of the scene's
evaluation sizes (`SCENES`), every held-out view rendered twice:
  f32   with the form, on the backend the run trained with (the scene's own renders);
  f64   in float64 from the same parameters (`jax.enable_x64` around these renders only):
        the image that float32 evaluation approximates. `--f64-backend`: `tiles` with
        hoisting off (default) or `reference`, both the contract's difference form (the same
        image to float64 rounding, as is every form in float64).
Scores (means over the views; images clipped to [0, 1]): psnr/ssim f32 against the photos
(scikit-image's defaults, as fit's evaluation), psnr_f64/ssim_f64 f64 against the photos,
psnr_vs_f64 f32 against f64, max_abs_vs_f64 (the largest over the views), over_1_255 (share of
pixels whose f32 value is off f64's by more than 1/255 in a channel). An evaluation size above
the photos' (lego_train at 400x400: its photos are 200x200) renders through the camera scaled
up and compares its block mean (`io.datasets.block_mean`) with the photo (photo_size names
what was compared); the f64 comparison stays at the rendered size. fit_psnr: fit's own final
held-out PSNR at the training size (the first evaluation size's psnr must equal it: the
photos are the images as fit holds them, 8-bit where the files are).

Rows: OUT/results.csv, one per scene x form x seed x evaluation size, merged as each run ends
(a rerun replaces its rows; a call cut short keeps what finished). --summary (also printed at
the end of a run): mean ± standard deviation over the seeds per form and size, and each form's
PSNR change from local paired by seed (mean ± standard error), into OUT/summary.md.

Backends: the form switches reach `tiles` and `pallas` only (`train.config.FORM_BACKENDS`); fit
defaults to pallas on a GPU and tiles elsewhere, both honour them. `--precision float64` trains
in float64 (`fit --precision float64`: the Gaussians, Adam's state, the images, the renders and
their gradients, on `tiles`; jax_enable_x64 on for the process) and writes a float64 scene.ply:
its f64 render is then the float64-trained scene's own image, its f32 render that scene rounded
to float32. Rows carry their training precision; the summary pairs each float64-trained run
with the float32-trained one of the same scene, form and seed where both are there.
A CPU smoke run: --scenes lego_train --forms local global --seeds 1 --steps 50.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import itertools
import math
import os
import shutil
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if __package__ in (None, ""):  # run as a file: make `benchmarks` importable
    sys.path.insert(0, ROOT)

from benchmarks.rows import merge, number as _number, read_csv  # noqa: E402

FORMS = ("local", "global", "difference")
SCENES = {  # folder, training downscale, default steps, evaluation sizes: (label, the
    # photos' downscale, the camera's upscale from them)
    "lego_train": dict(folder="lego_train", downscale=1, steps=7000,
                       evals=(("200x200", 1, 1), ("400x400", 1, 2))),
    "skull": dict(folder="skull", downscale=2, steps=3000,
                  evals=(("downscale2", 2, 1), ("downscale1", 1, 1))),
}
BIG = 10**9  # --eval-every / --checkpoint-every: never inside the run
FIELDS = ("scene", "form", "precision", "seed", "eval", "width", "height", "photo_size", "views",
          "psnr", "ssim", "psnr_f64", "ssim_f64", "psnr_vs_f64", "max_abs_vs_f64", "over_1_255",
          "fit_psnr", "steps", "gaussians", "train_s", "eval_s", "backend", "f64_backend",
          "device", "error")
KEY = ("scene", "form", "precision", "seed", "eval")


def parse(argv=None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data-root", default=os.environ.get(
        "LGS_JAX_DATA", os.path.join(ROOT, "..", "shared", "data")))
    ap.add_argument("--scenes", nargs="+", default=list(SCENES), choices=list(SCENES))
    ap.add_argument("--forms", nargs="+", default=list(FORMS), choices=FORMS)
    ap.add_argument("--seeds", type=int, default=4, help="seeds 0 .. N-1 (default 4)")
    ap.add_argument("--first-seed", type=int, default=0, help="start at this seed")
    ap.add_argument("--steps", type=int, help="training steps (default: the scene's, SCENES)")
    ap.add_argument("--backend", choices=["tiles", "pallas"],
                    help="fit's backend (default: fit's: pallas on a GPU, tiles elsewhere)")
    ap.add_argument("--shrink", type=int, default=1,
                    help="every image size of the protocol divided by this (training and "
                         "evaluation; a CPU-sized run); rows say the sizes")
    ap.add_argument("--precision", choices=["float32", "float64"], default="float32",
                    help="fit's training precision (default float32)")
    ap.add_argument("--f64-backend", choices=["tiles", "reference"], default="tiles",
                    help="the float64 render's backend (default: tiles)")
    ap.add_argument("--fit-args", default="", help="more options for fit (one string)")
    ap.add_argument("--out", default="precision_vs_photos_out", help="results.csv, summary.md")
    ap.add_argument("--run-dir",
                    help="keep the runs' folders here (default: temporary ones, removed)")
    ap.add_argument("--summary", action="store_true", help="print and write the summary only")
    ap.add_argument("--inputs", nargs="+", metavar="CSV",
                    help="--summary of these results.csv files together (several calls' "
                         "rows; default: OUT/results.csv)")
    ap.add_argument("--dry-run", action="store_true", help="print the fit commands only")
    return ap.parse_args(argv)


# ------------------------------------------------------------------------------------ fit

def evals(args, scene: str) -> list[tuple[str, int, int]]:
    """`scene`'s evaluation sizes (label, photos' downscale, upscale) after --shrink (the
    label then says it: "downscale2/4")."""
    f = args.shrink
    return [(label + (f"/{f}" if f > 1 else ""), downscale * f, up)
            for label, downscale, up in SCENES[scene]["evals"]]


def fit_words(args, scene: str, form: str, seed: int, out: str) -> list[str]:
    """The `fit` command line of `scene` in `form` at `seed` into `out` (module docstring)."""
    s = SCENES[scene]
    words = ["fit", "--data", os.path.join(args.data_root, s["folder"]), "--out", out,
             "--overwrite", "--alpha-form", form, "--seed", str(seed), "--downscale",
             str(s["downscale"] * args.shrink), "--steps", str(args.steps or s["steps"]),
             "--eval-every", str(BIG), "--checkpoint-every", str(BIG)]
    if args.backend:
        words += ["--backend", args.backend]
    if args.precision != "float32":
        words += ["--precision", args.precision]
    return words + args.fit_args.split()


def run_fit(args, scene: str, form: str, seed: int, out: str) -> dict:
    """fit's result (result.json) of the run, in this process (its compiled programs kept for
    the next seeds), with train_s its wall seconds; {"error": ...} if it failed."""
    from lgs_jax import cli, train
    from lgs_jax.cli import fit as fit_cmd

    words = fit_words(args, scene, form, seed, out)
    print("$ python -m lgs_jax " + " ".join(words), flush=True)
    t0 = time.time()
    try:
        config = fit_cmd.config_of(cli.parser().parse_args(words))
        data = dataset(config.data, config.downscale, config.image_dtype)
        result = train.fit(config, data, log=lambda m: None)
    except Exception as e:  # noqa: BLE001 - kept as the rows' error; the next run goes on
        return dict(error=f"fit: {type(e).__name__}: {e}")
    return dict(result, train_s=time.time() - t0)


# ------------------------------------------------------------------------------ evaluation

@functools.cache
def dataset(data: str, downscale: int, dtype="auto"):
    """`data` at `downscale`, loaded once; dtype "auto": the images as fit holds them by
    default (8-bit where the files are)."""
    from lgs_jax.io.datasets import load_dataset

    return load_dataset(data, downscale=downscale, dtype=dtype)


@functools.cache
def held_out(data: str, downscale: int):
    """(cameras, photos float64, background) of `data`'s held-out views at `downscale`."""
    import numpy as np

    from lgs_jax.io.datasets import as_float

    d = dataset(data, downscale)
    return ([d.cameras[i] for i in d.test],
            [np.asarray(as_float(d.images[i]), np.float64) for i in d.test],
            np.asarray(d.background))


def _capacity(g, cams, antialiased: bool) -> int:
    """A pair buffer for every view of `cams` (a power of two: one compile per size and
    precision, the same across seeds unless a scene's pairs cross one)."""
    from lgs_jax.render import count_pairs, next_pow2

    return next_pow2(max(int(count_pairs(g, c, antialiased=antialiased)) for c in cams))


def _renders(g, cams, background, backend: str, config) -> list:
    """Each camera's image of `g` (float32 or float64 Gaussians: the render's precision, x64
    on for the latter only), float64 numpy clipped to [0, 1]."""
    import jax
    import numpy as np

    import lgs_jax

    dtype = g.means.dtype
    cast = lambda tree: jax.tree.map(lambda x: np.asarray(x, dtype), tree)
    with jax.enable_x64(dtype == np.float64):
        cams, bg = [cast(c) for c in cams], np.asarray(background, dtype)
        cap = _capacity(g, cams, config.antialiased)
        return [np.clip(np.asarray(lgs_jax.render(g, c, background=bg, backend=backend,
                                                  config=config, capacity=cap).image,
                                   np.float64), 0.0, 1.0) for c in cams]


def evaluate_run(args, scene: str, ply: str, form: str, backend: str) -> list[dict]:
    """One row (scores only) per evaluation size of `scene` for the scene at `ply`."""
    import numpy as np

    import lgs_jax
    from lgs_jax.io.datasets import block_mean
    from lgs_jax.train import Recipe
    from lgs_jax.train.report import view_metrics

    from benchmarks.common import psnr

    config = Recipe(alpha_form=form).raster
    f64_config = dataclasses.replace(config, hoist=False)  # the difference form
    g32 = lgs_jax.load_ply(ply, dtype=np.float32)
    g64 = lgs_jax.load_ply(ply, dtype=np.float64)
    rows = []
    for label, downscale, up in evals(args, scene):
        t0 = time.time()
        cams, photos, bg = held_out(os.path.join(args.data_root, SCENES[scene]["folder"]),
                                    downscale)
        cams = [c.scaled(c.width * up, c.height * up) if up > 1 else c for c in cams]
        f32 = _renders(g32, cams, bg, backend, config)
        f64 = _renders(g64, cams, bg, args.f64_backend, f64_config)
        at_photo = [[block_mean(i, up) if up > 1 else i for i in imgs] for imgs in (f32, f64)]
        ours, truth = (view_metrics(imgs, photos) for imgs in at_photo)
        err = [np.abs(a - b) for a, b in zip(f32, f64)]
        size = f"{photos[0].shape[1]}x{photos[0].shape[0]}"
        rows.append(dict(
            eval=label, width=cams[0].width, height=cams[0].height, views=len(cams),
            photo_size=size + (f" (render {up}x{up} block mean)" if up > 1 else ""),
            psnr=np.mean([p for p, _ in ours]), ssim=np.mean([s for _, s in ours]),
            psnr_f64=np.mean([p for p, _ in truth]), ssim_f64=np.mean([s for _, s in truth]),
            psnr_vs_f64=np.mean([psnr(a, b) for a, b in zip(f32, f64)]),
            max_abs_vs_f64=max(float(e.max()) for e in err),
            over_1_255=np.mean([np.mean(e.max(-1) > 1 / 255) for e in err]),
            eval_s=time.time() - t0, f64_backend=args.f64_backend))
    return rows


def run_one(args, scene: str, form: str, seed: int, device: str) -> list[dict]:
    """Fit, evaluate and keep (`keep`) the rows of one run."""
    base = dict(scene=scene, form=form, precision=args.precision, seed=seed, device=device)
    if args.dry_run:
        print("$ python -m lgs_jax " + " ".join(fit_words(args, scene, form, seed, "RUN")))
        return []
    base_dir = args.run_dir or tempfile.mkdtemp(prefix="precision_")
    out = os.path.join(base_dir, f"{scene}_{form}_{args.precision}_{seed}")
    r = run_fit(args, scene, form, seed, out)
    if "error" in r:
        rows = [dict(base, eval=label, error=r["error"]) for label, _, _ in
                evals(args, scene)]
    else:
        fit = dict(fit_psnr=r["heldout_psnr"], steps=r["steps"], gaussians=r["gaussians"],
                   train_s=r["train_s"], backend=r["backend"])
        try:
            rows = [dict(base, **fit, **row) for row in
                    evaluate_run(args, scene, os.path.join(out, "scene.ply"), form,
                                 r["backend"])]
        except Exception as e:  # noqa: BLE001 - kept as the row's error, the next run goes on
            rows = [dict(base, **fit, eval=label, error=f"{type(e).__name__}: {e}")
                    for label, _, _ in evals(args, scene)]
    if not args.run_dir:
        shutil.rmtree(base_dir, ignore_errors=True)
    keep(args.out, rows)
    return rows


# ----------------------------------------------------------------------------------- files

def keep(out: str, rows: list[dict]) -> None:
    """Merge `rows` into OUT/results.csv (replacing rows of the same KEY; a row without a
    precision is float32's) and print them."""
    rows = [dict(r, precision=r.get("precision") or "float32") for r in rows]
    merge(os.path.join(out, "results.csv"), rows, FIELDS, KEY)
    for r in rows:
        print(f"{r['scene']:10} {r['form']:10} {r['precision']} seed {r['seed']:>2} {r['eval']:10} "
              f"PSNR {_shown(r, 'psnr', '6.3f')} SSIM {_shown(r, 'ssim', '6.4f')} "
              f"vs f64 {_shown(r, 'psnr_vs_f64', '6.1f')} dB "
              f"(fit {_shown(r, 'fit_psnr', '6.3f')}) {r.get('error') or ''}", flush=True)


def _shown(row: dict, key: str, spec: str) -> str:
    return "-" if _number(row.get(key)) is None else format(float(row[key]), spec)


# --------------------------------------------------------------------------------- summary

def _stats(values: list[float]) -> tuple[float, float | None]:
    import statistics

    m = statistics.fmean(values)
    return m, statistics.stdev(values) if len(values) > 1 else None


def _cell(values: list[float], spec: str) -> str:
    if not values:
        return "-"
    m, sd = _stats(values)
    return format(m, spec) + ("" if sd is None else " ± " + format(sd, spec))


def _own(row: dict) -> float | None:
    """The PSNR of the scene's own image: its render in the precision it was trained in."""
    return _number(row["psnr_f64" if row["precision"] == "float64" else "psnr"])


def _paired(rows: list[dict], key: tuple, other: tuple) -> str:
    """Own PSNR (`_own`) of the runs of `key` − those of `other` (both (scene, eval, form,
    precision)), paired by seed: mean ± standard error; "-" where none pair or key == other."""

    by = {k: {r["seed"]: _own(r) for r in rows
              if (r["scene"], r["eval"], r["form"], r["precision"]) == k} for k in (key, other)}
    diff = [by[key][s] - by[other][s] for s in by[key] if s in by[other]]
    if key == other or not diff:
        return "-"
    m, sd = _stats(diff)
    return f"{m:+.3f}" + ("" if sd is None else f" ± {sd / math.sqrt(len(diff)):.3f}")


def summary_lines(rows: list[dict]) -> list[str]:
    """Markdown: per scene, evaluation size, form and training precision, mean ± sd over
    seeds (module docstring); Δ columns of the own PSNR (`_own`), paired by seed."""
    rows = [dict(r, precision=r.get("precision") or "float32") for r in rows
            if not r.get("error") and _number(r.get("psnr")) is not None]
    out = ["| scene | eval | form | trained in | seeds | PSNR (dB) | SSIM | Δ PSNR vs local "
           "(paired) | Δ PSNR vs float32 training (paired) | f64 PSNR | f64 SSIM | "
           "f32 vs f64 (dB) | max abs vs f64 | > 1/255 |",
           "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    col = lambda mine, k: [_number(r[k]) for r in mine if _number(r.get(k)) is not None]
    for scene in dict.fromkeys(r["scene"] for r in rows):
        for ev in dict.fromkeys(r["eval"] for r in rows if r["scene"] == scene):
            for form, precision in itertools.product(FORMS, ("float32", "float64")):
                key = (scene, ev, form, precision)
                mine = [r for r in rows if (r["scene"], r["eval"], r["form"], r["precision"])
                        == key]
                if not mine:
                    continue
                worst = max(col(mine, "max_abs_vs_f64"), default=math.nan)
                out.append(f"| {scene} | {ev} | {form} | {precision} | {len(mine)} | "
                           f"{_cell(col(mine, 'psnr'), '.3f')} | "
                           f"{_cell(col(mine, 'ssim'), '.4f')} | "
                           f"{_paired(rows, key, (scene, ev, 'local', precision))} | "
                           f"{_paired(rows, key, (scene, ev, form, 'float32'))} | "
                           f"{_cell(col(mine, 'psnr_f64'), '.3f')} | "
                           f"{_cell(col(mine, 'ssim_f64'), '.4f')} | "
                           f"{_cell(col(mine, 'psnr_vs_f64'), '.1f')} | {worst:.2g} | "
                           f"{_cell(col(mine, 'over_1_255'), '.2g')} |")
    return out


def summary(args) -> int:
    paths = args.inputs or [os.path.join(args.out, "results.csv")]
    rows = [r for p in paths for r in read_csv(p)]
    if not rows:
        print(f"{', '.join(paths)}: no rows to summarise")
        return 1
    devices = sorted({r["device"] for r in rows if r.get("device")})
    backends = sorted({r["backend"] for r in rows if r.get("backend")})
    lines = ["## Exponent forms against the photos and float64 (mean ± sd over seeds)", "",
             f"Device {', '.join(devices)}; training backend {', '.join(backends)}; rows: "
             f"{', '.join(paths)}.",
             ""] + summary_lines(rows)
    errors = [r for r in rows if r.get("error")]
    if errors:
        lines += ["", f"{len(errors)} rows failed: " + "; ".join(
            f"{r['scene']} {r['form']} seed {r['seed']} {r['eval']}: {r['error']}"
            for r in errors[:5])]
    text = "\n".join(lines)
    print(text)
    with open(os.path.join(args.out, "summary.md"), "w") as f:
        f.write(text + "\n")
    return 0


# ------------------------------------------------------------------------------------ main

def main(argv=None) -> int:
    args = parse(argv)
    args.data_root = os.path.abspath(args.data_root)
    os.makedirs(args.out, exist_ok=True)
    if args.summary:
        return summary(args)
    os.environ.setdefault("TQDM_DISABLE", "1")  # fit's progress bars: the rows say enough
    import jax

    from lgs_jax.cli.commands import use_compile_cache

    from benchmarks.common import device_line

    if args.precision == "float64":  # before any JAX work, as `fit --precision float64`
        jax.config.update("jax_enable_x64", True)
    use_compile_cache()
    print(device_line(), flush=True)
    device = jax.devices()[0].device_kind
    failed = False
    for scene in args.scenes:
        for seed in range(args.first_seed, args.first_seed + args.seeds):
            for form in args.forms:
                rows = run_one(args, scene, form, seed, device)
                failed |= any(r.get("error") for r in rows)
    if not args.dry_run:
        summary(args)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
