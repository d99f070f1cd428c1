"""Time to quality: `fit --recipe fast` against gsplat 1.5.3's trainer at 7,000 steps, on one GPU.

    python -m benchmarks.time_to_quality [--data-root DIR] [--scenes skull fox lego_train]
        [--seeds 4] [--out DIR] [--cold] [--ablate] [--eval-every N] [--dry-run] ...
    python -m benchmarks.time_to_quality --summary [--out DIR] [--figure PNG]

Per scene, seed after seed, back to back on one machine, each run a subprocess of its own:
  gsplat   gsplat's trainer as `benchmarks/train_vs_gsplat.py` runs it (`run_gsplat`:
           simple_trainer's recipe and --gsplat-strategy, --gsplat-steps steps, our data, split,
           view order and start), JAX kept off the GPU; wall time: the worker process from its
           start to its exit (imports, data, the CUDA extension's load, training, the final
           held-out evaluation);
  ours     `python -m lgs_jax fit --recipe fast --seed S --eval-every BIG --checkpoint-every
           BIG` (no evaluation or checkpoint inside the run unless --eval-every), wall time
           from the process's start to its final scene.ply (the file's modification time: the
           final held-out evaluation, which comes before it, included), with a warm compile
           cache (its own, CACHE/SCENE, --cache-dir, default OUT/jax_cache (on a device
           call, a folder outside $OUT): an untimed run of the scene first fills it;
           with --cold that first run starts from an empty cache and is recorded as
           lgs_jax_cold).
Rows (results.csv, one per trainer x scene x seed; a rerun replaces its rows, so several
invocations, e.g. one per scene, fill one file): held-out PSNR and SSIM (scikit-image's, the
renders clipped to [0, 1]), wall seconds, steps done (the early stop's), Gaussians, compile
seconds, our runs' parts (`fit`'s load, step and finish seconds), device; our runs' logs in
OUT/logs. curves.csv: held-out PSNR and SSIM against wall seconds where the runs evaluated
inside (--eval-every; a point's time: the run's wall time less the training seconds after it).
--ablate: the fast recipe with each technique switched off in turn (`ABLATIONS`), seed 0, into
ablation.csv. --summary: the markdown tables (mean ± standard error over seeds; the target:
ours >= gsplat's − one standard error of the paired difference, in at most `LIMITS` seconds)
and the figure (PSNR against wall time). Without torch and gsplat (a CPU), the gsplat runs are
skipped with a note; a CPU smoke run: --scenes lego_train --seeds 1 --steps 20 --downscale 8.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if __package__ in (None, ""):  # run as a file: make `benchmarks` importable
    sys.path.insert(0, ROOT)

from benchmarks import train_vs_gsplat as tvg  # noqa: E402
from benchmarks.rows import merge, number as _number, read_csv  # noqa: E402
from benchmarks.seed_summary import mean_and_error  # noqa: E402

SCENES = {  # folder under the data root, gsplat's Gaussian cap (its MCMC strategy)
    "skull": dict(folder="skull", cap=500_000),
    "fox": dict(folder="fox", cap=500_000),
    "lego_train": dict(folder="lego_train", cap=300_000),
}
LIMITS = {"skull": 60.0, "fox": 60.0, "lego_train": 30.0}  # the issue's wall-time targets, s
ABLATIONS = {  # variant -> the fit options that switch one technique off
    "fast": [],
    "levels_1": ["--levels", "1"],
    "batch_1": ["--batch", "1"],
    "strategy_mcmc": ["--strategy", "mcmc"],
    "strategy_default": ["--strategy", "default"],  # 3DGS's clone and split in the schedule
    "budget_3": ["--budget", "3"],  # a smaller Gaussian budget (3x the start)
    "budget_5": ["--budget", "5"],
    "no_early_stop": ["--no-early-stop"],
    "growth_mcmc": ["--growth", "mcmc"],
    "unseen_off": ["--unseen-after", "0"],
    "sh_every_1000": ["--sh-every", "1000"],  # the default recipe's SH schedule: bands later
    "sh_degree_0": ["--sh-degree", "0"],  # view-independent colours
}
DEFAULT_ABLATIONS = ["fast", "levels_1", "batch_1", "strategy_mcmc", "no_early_stop"]
BIG = 10**9  # --eval-every / --checkpoint-every: never inside the run
FIELDS = ("scene", "trainer", "seed", "psnr", "ssim", "wall_s", "steps", "stopped_early_at",
          "gaussians", "compile_s", "load_s", "step_s", "finish_s", "device", "error")
CURVE_FIELDS = ("scene", "trainer", "seed", "step", "wall_s", "psnr", "ssim")


def parse(argv=None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data-root", default=os.environ.get(
        "LGS_JAX_DATA", os.path.join(ROOT, "..", "shared", "data")))
    ap.add_argument("--scenes", nargs="+", default=list(SCENES), choices=list(SCENES))
    ap.add_argument("--seeds", type=int, default=4, help="seeds 0 .. N-1 (default 4)")
    ap.add_argument("--first-seed", type=int, default=0, help="start at this seed (a "
                                                              "partial rerun)")
    ap.add_argument("--trainers", nargs="+", default=["gsplat", "ours"],
                    choices=["gsplat", "ours"])
    ap.add_argument("--out", default="time_to_quality_out", help="CSVs (merged across runs)")
    ap.add_argument("--cache-dir", help="compilation caches, one per scene (default OUT/jax_cache)")
    ap.add_argument("--run-dir", help="the runs' folders (default: a temporary one, removed)")
    ap.add_argument("--downscale", type=int, default=1, help="image downscale, both trainers")
    ap.add_argument("--steps", type=int, help="our steps (default: the fast recipe's)")
    ap.add_argument("--gsplat-steps", type=int, default=7000)
    ap.add_argument("--gsplat-strategy", choices=["default", "mcmc"], default="default",
                    help="gsplat's densification (default: simple_trainer's default)")
    ap.add_argument("--eval-every", type=int, default=0,
                    help="held-out evaluations inside the runs every N steps, for curves.csv "
                         "(they cost wall time; default 0: at the end only)")
    ap.add_argument("--fit-args", default="", help="more options for our fit (one string)")
    ap.add_argument("--cold", action="store_true",
                    help="the untimed first run of each scene starts from an empty compile "
                         "cache and is recorded (lgs_jax_cold)")
    ap.add_argument("--no-warmup", action="store_true",
                    help="skip the untimed first run (the scenes' caches are warm already)")
    ap.add_argument("--warm-ablation", action="store_true",
                    help="run each ablation variant once untimed first (doubles its time; "
                         "without it a variant's wall time includes its compiles, compile_s)")
    ap.add_argument("--ablate", action="store_true", help="the ablation (seed --first-seed)")
    ap.add_argument("--variants", nargs="+", default=DEFAULT_ABLATIONS, choices=list(ABLATIONS))
    ap.add_argument("--summary", action="store_true", help="print tables, draw the figure")
    ap.add_argument("--figure", default=os.path.join(ROOT, "docs", "time_to_quality.png"))
    ap.add_argument("--dry-run", action="store_true", help="print the commands only")
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--scene", help=argparse.SUPPRESS)
    ap.add_argument("--seed", type=int, help=argparse.SUPPRESS)
    ap.add_argument("--worker-out", help=argparse.SUPPRESS)
    return ap.parse_args(argv)


# ----------------------------------------------------------------------------------- runs

def have_gsplat() -> bool:
    return all(importlib.util.find_spec(m) is not None for m in ("torch", "gsplat"))


def _env(cache: str | None = None, cpu_jax: bool = False) -> dict:
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    env["PYTHONPATH"] = os.pathsep.join(filter(None, (tvg.package_root(), ROOT,
                                                      env.get("PYTHONPATH"))))
    if cache is not None:
        env["LGS_JAX_CACHE"] = cache
    if cpu_jax:
        env["JAX_PLATFORMS"] = "cpu"  # JAX off the GPU while gsplat trains
    return env


def fit_command(args, scene: str, seed: int, out: str, extra=()) -> list[str]:
    """Our run of `scene` (module docstring) into `out`."""
    every = args.eval_every or BIG
    cmd = [sys.executable, "-m", "lgs_jax", "fit", "--data",
           os.path.join(args.data_root, SCENES[scene]["folder"]), "--recipe", "fast",
           "--seed", str(seed), "--out", out, "--overwrite", "--downscale", str(args.downscale),
           "--eval-every", str(every), "--checkpoint-every", str(BIG)]
    if args.steps is not None:
        cmd += ["--steps", str(args.steps)]
    return cmd + list(extra) + args.fit_args.split()


def _cache_root(args) -> str:
    """The folder of the scenes' compilation caches (--cache-dir, default OUT/jax_cache)."""
    return os.path.abspath(args.cache_dir or os.path.join(args.out, "jax_cache"))


def run_ours(args, scene: str, seed: int, cache: str, trainer: str = "lgs_jax_fast",
             extra=()) -> tuple[dict, list[dict]]:
    """(row, curve points) of one of our runs (module docstring)."""
    row = dict(scene=scene, trainer=trainer, seed=seed)
    if args.dry_run:
        print("$ " + " ".join(fit_command(args, scene, seed, "RUN", extra)), flush=True)
        return row, []
    base = args.run_dir or tempfile.mkdtemp(prefix="ttq_")
    out = os.path.join(base, f"{scene}_{trainer}_{seed}")
    cmd = fit_command(args, scene, seed, out, extra)
    print("$ " + " ".join(cmd), flush=True)
    t0 = time.time()
    os.makedirs(os.path.join(args.out, "logs"), exist_ok=True)
    with open(os.path.join(args.out, "logs", f"{scene}_{trainer}_{seed}.log"), "w") as log:
        done = subprocess.run(cmd, env=_env(cache), stdout=log, stderr=subprocess.STDOUT)
    ply = os.path.join(out, "scene.ply")
    if done.returncode != 0 or not os.path.exists(os.path.join(out, "result.json")):
        return dict(row, error=f"fit exited with {done.returncode}"), []
    wall = os.path.getmtime(ply) - t0
    with open(os.path.join(out, "result.json")) as f:
        r = json.load(f)
    row.update(psnr=r["heldout_psnr"], ssim=r["heldout_ssim"], wall_s=wall, steps=r["steps"],
               stopped_early_at=r["stopped_early_at"], gaussians=r["gaussians"],
               compile_s=r["compile_seconds"], load_s=r["load_seconds"],
               step_s=r["step_seconds"], finish_s=r["finish_seconds"], device=r["device"])
    curve = _our_curve(os.path.join(out, "metrics.jsonl"), row)
    if not args.run_dir:
        shutil.rmtree(base, ignore_errors=True)
    return row, curve


def _our_curve(path: str, row: dict) -> list[dict]:
    """Held-out points of metrics.jsonl at wall seconds: the run's wall time less the training
    seconds after the point (the steps' `seconds`)."""
    from lgs_jax.train.report import read_metrics

    rows = read_metrics(path)
    busy = {r["step"]: r["seconds"] for r in rows if "seconds" in r}
    end = busy.get(row["steps"], 0.0)
    return [dict(scene=row["scene"], trainer=row["trainer"], seed=row["seed"], step=r["step"],
                 wall_s=row["wall_s"] - (end - busy.get(r["step"], end)),
                 psnr=r["heldout_psnr"], ssim=r["heldout_ssim"])
            for r in rows if "heldout_psnr" in r]


def gsplat_worker(args) -> int:
    """In the worker process: gsplat's trainer on --scene at --seed (`tvg.run_gsplat`), its
    result as JSON in --worker-out."""
    tvg.SCENES.update({name: dict(folder=s["folder"], downscale=args.downscale, cap=s["cap"])
                       for name, s in SCENES.items()})
    every = args.eval_every or args.gsplat_steps
    targs = tvg.parse(["--data-root", args.data_root, "--steps", str(args.gsplat_steps),
                       "--eval-every", str(every), "--seed", str(args.seed),
                       "--strategy", args.gsplat_strategy])
    result = tvg.run_gsplat(targs, args.scene)
    with open(args.worker_out, "w") as f:
        json.dump(result, f)
    return 0


def run_gsplat(args, scene: str, seed: int) -> tuple[dict, list[dict]]:
    """(row, curve points) of gsplat's trainer on `scene` (module docstring)."""
    row = dict(scene=scene, trainer="gsplat", seed=seed)
    path = "RESULT.json"
    if not args.dry_run:
        fd, path = tempfile.mkstemp(suffix=".json")
        os.close(fd)
    cmd = [sys.executable, "-m", "benchmarks.time_to_quality", "--worker", "--scene", scene,
           "--seed", str(seed), "--worker-out", path, "--data-root", args.data_root,
           "--downscale", str(args.downscale), "--gsplat-steps", str(args.gsplat_steps),
           "--gsplat-strategy", args.gsplat_strategy, "--eval-every", str(args.eval_every)]
    print("$ " + " ".join(cmd), flush=True)
    if args.dry_run:
        return row, []
    t0 = time.time()
    done = subprocess.run(cmd, env=_env(cpu_jax=True), cwd=ROOT)
    wall = time.time() - t0
    if done.returncode != 0:
        return dict(row, error=f"gsplat's worker exited with {done.returncode}"), []
    with open(path) as f:
        r = json.load(f)
    os.remove(path)
    last = r["curve"][-1]
    row.update(psnr=last["psnr"], ssim=last["ssim"], wall_s=wall, steps=r["steps"],
               gaussians=r["gaussians"], device=r["device"])
    per_step = (r["ms_per_step"] or 0.0) / 1e3
    curve = [dict(scene=scene, trainer="gsplat", seed=seed, step=c["step"],
                  wall_s=wall - (r["steps"] - c["step"]) * per_step, psnr=c["psnr"],
                  ssim=c["ssim"]) for c in r["curve"]]
    return row, curve


# ---------------------------------------------------------------------------------- files

# -------------------------------------------------------------------------------- summary

def _cell(values: list[float], spec: str) -> str:
    if not values:
        return "-"
    m, e = mean_and_error(values)
    return format(m, spec) + ("" if e is None else " ± " + format(e, spec))


def _column(rows, key):
    return [v for v in (_number(r.get(key)) for r in rows) if v is not None]


def results_table(rows: list[dict]) -> list[str]:
    """Markdown: per scene and trainer, mean ± standard error over the seeds."""
    out = ["| scene | trainer | seeds | held-out PSNR (dB) | SSIM | wall (s) | steps | "
           "Gaussians |", "|---|---|---|---|---|---|---|---|"]
    for scene in dict.fromkeys(r["scene"] for r in rows):
        for trainer in dict.fromkeys(r["trainer"] for r in rows if r["scene"] == scene):
            mine = [r for r in rows if (r["scene"], r["trainer"]) == (scene, trainer)
                    and not r.get("error")]
            out.append(f"| {scene} | {trainer} | {len(mine)} | "
                       f"{_cell(_column(mine, 'psnr'), '.2f')} | "
                       f"{_cell(_column(mine, 'ssim'), '.4f')} | "
                       f"{_cell(_column(mine, 'wall_s'), '.1f')} | "
                       f"{_cell(_column(mine, 'steps'), '.0f')} | "
                       f"{_cell(_column(mine, 'gaussians'), '.0f')} |")
    return out


def target_rows(rows: list[dict]) -> list[dict]:
    """Per scene with both trainers: ours − gsplat's held-out PSNR paired by seed (mean, its
    standard error), our mean wall time, and whether each target holds."""
    found = []
    for scene in dict.fromkeys(r["scene"] for r in rows):
        by = {t: {r["seed"]: r for r in rows if (r["scene"], r["trainer"]) == (scene, t)
                  and not r.get("error")} for t in ("lgs_jax_fast", "gsplat")}
        seeds = sorted(set(by["lgs_jax_fast"]) & set(by["gsplat"]))
        if not seeds:
            continue
        diff = [_number(by["lgs_jax_fast"][s]["psnr"]) - _number(by["gsplat"][s]["psnr"])
                for s in seeds]
        d, e = mean_and_error(diff)
        wall, _ = mean_and_error([_number(by["lgs_jax_fast"][s]["wall_s"]) for s in seeds])
        limit = LIMITS.get(scene, 60.0)
        found.append(dict(scene=scene, seeds=len(seeds), diff=d, error=e, wall=wall,
                          limit=limit, quality=d >= -(e or 0.0), time=wall <= limit))
    return found


def target_table(rows: list[dict]) -> list[str]:
    out = ["| scene | seeds | ours − gsplat PSNR (dB) | quality target | ours wall (s) | "
           "limit (s) | time target |", "|---|---|---|---|---|---|---|"]
    for t in target_rows(rows):
        err = "" if t["error"] is None else f" ± {t['error']:.2f}"
        out.append(f"| {t['scene']} | {t['seeds']} | {t['diff']:+.2f}{err} | "
                   f"{'met' if t['quality'] else 'missed'} | {t['wall']:.1f} | "
                   f"{t['limit']:.0f} | {'met' if t['time'] else 'missed'} |")
    return out


def ablation_table(rows: list[dict]) -> list[str]:
    """Markdown: each variant's held-out PSNR, SSIM and wall time, and its change from fast."""
    out = ["| scene | variant | PSNR (dB) | Δ PSNR | SSIM | wall (s) | Δ wall | compile (s) | "
           "steps | Gaussians |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        base = next((b for b in rows if b["scene"] == r["scene"] and b["trainer"] == "fast"),
                    None)
        p, w = _number(r.get("psnr")), _number(r.get("wall_s"))
        dp = (f"{p - _number(base['psnr']):+.2f}" if base and p is not None
              and _number(base.get("psnr")) is not None else "-")
        dw = (f"{w - _number(base['wall_s']):+.1f}" if base and w is not None
              and _number(base.get("wall_s")) is not None else "-")
        f = lambda k, spec: "-" if _number(r.get(k)) is None else format(_number(r[k]), spec)
        out.append(f"| {r['scene']} | {r['trainer']} | {f('psnr', '.2f')} | {dp} | "
                   f"{f('ssim', '.4f')} | {f('wall_s', '.1f')} | {dw} | {f('compile_s', '.1f')}"
                   f" | {r.get('steps') or '-'} | {r.get('gaussians') or '-'} |")
    return out


def draw(path: str, rows: list[dict], curves: list[dict]) -> None:
    """The figure: per scene, held-out PSNR against wall seconds, each run a point (its curve
    where it has one), the time limit a dashed line."""
    from matplotlib.figure import Figure

    scenes = list(dict.fromkeys(r["scene"] for r in rows))
    if not scenes:
        return
    fig = Figure(figsize=(4.2 * len(scenes), 3.6))
    axes = fig.subplots(1, len(scenes), squeeze=False)[0]
    colors = {"gsplat": "tab:blue", "lgs_jax_fast": "tab:orange", "lgs_jax_cold": "tab:red"}
    for ax, scene in zip(axes, scenes):
        for trainer, color in colors.items():
            mine = [r for r in rows if (r["scene"], r["trainer"]) == (scene, trainer)
                    and _number(r.get("psnr")) is not None]
            ax.plot([_number(r["wall_s"]) for r in mine], [_number(r["psnr"]) for r in mine],
                    "o", color=color, label=trainer if mine else None)
            for seed in dict.fromkeys(c["seed"] for c in curves):
                line = [c for c in curves if (c["scene"], c["trainer"], c["seed"])
                        == (scene, trainer, seed)]
                ax.plot([_number(c["wall_s"]) for c in line], [_number(c["psnr"]) for c in line],
                        "-", color=color, alpha=0.5)
        ax.axvline(LIMITS.get(scene, 60.0), ls="--", color="grey")
        ax.set(title=scene, xlabel="wall time from process start (s)",
               ylabel="held-out PSNR (dB)")
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def summary(args) -> int:
    rows = read_csv(os.path.join(args.out, "results.csv"))
    ablation = read_csv(os.path.join(args.out, "ablation.csv"))
    if not rows and not ablation:
        print(f"{args.out}: no results.csv or ablation.csv to summarise")
        return 1
    lines = ["## Time to quality (mean ± standard error over seeds)", ""]
    lines += results_table(rows) + [""]
    if ablation:
        lines += ["## Ablation (one seed)", ""] + ablation_table(ablation) + [""]
    lines += ["## Targets", ""] + target_table(rows)
    print("\n".join(lines))
    if rows:
        draw(args.figure, rows, read_csv(os.path.join(args.out, "curves.csv")))
        print(f"\nfigure: {args.figure}")
    return 0


# ----------------------------------------------------------------------------------- main

def _scene_runs(args, scene: str, gsplat: bool) -> list[dict]:
    """The rows of one scene (each with its curve kept as its run ends, `_kept`): the first
    (untimed, or --cold) run, then each seed's gsplat and ours back to back."""
    cache = os.path.join(_cache_root(args), scene)
    rows = []
    if "ours" in args.trainers and (args.cold or not args.no_warmup):
        if args.cold and not args.dry_run:
            shutil.rmtree(cache, ignore_errors=True)
        first, _ = run_ours(args, scene, args.first_seed, cache, "lgs_jax_cold")
        if args.cold:
            rows.append(_kept(args, first, []))
    for seed in range(args.first_seed, args.first_seed + args.seeds):
        if gsplat:
            rows.append(_kept(args, *run_gsplat(args, scene, seed)))
        if "ours" in args.trainers:
            rows.append(_kept(args, *run_ours(args, scene, seed, cache)))
    return rows


def _kept(args, row: dict, curve: list[dict]) -> dict:
    """`row` (and its curve) merged into the CSVs as soon as its run ends (a call cut short
    keeps the runs it finished) and printed; returns `row`."""
    if not args.dry_run:
        merge(os.path.join(args.out, "results.csv"), [row], FIELDS, ("scene", "trainer", "seed"))
        if curve:
            merge(os.path.join(args.out, "curves.csv"), curve, CURVE_FIELDS,
                  ("scene", "trainer", "seed"))
        short_table([row])
    return row


def _ablate(args, scene: str) -> list[dict]:
    cache = os.path.join(_cache_root(args), scene)
    rows = []
    for name in args.variants:
        if args.warm_ablation:  # fills the cache
            run_ours(args, scene, args.first_seed, cache, name, ABLATIONS[name])
        row, _ = run_ours(args, scene, args.first_seed, cache, name, ABLATIONS[name])
        if not args.dry_run:  # kept as each run ends (a call cut short keeps the rows done)
            merge(os.path.join(args.out, "ablation.csv"), [row], FIELDS,
                  ("scene", "trainer", "seed"))
            short_table([row])
        rows.append(row)
    return rows


def short_table(rows: list[dict]) -> None:
    print(f"{'scene':11} {'trainer':14} {'seed':>4} {'PSNR':>6} {'SSIM':>6} {'wall s':>7} "
          f"{'steps':>6} {'Gaussians':>9}")
    for r in rows:
        f = lambda k, spec: "-" if _number(r.get(k)) is None else format(_number(r[k]), spec)
        print(f"{r['scene']:11} {r['trainer']:14} {r['seed']:>4} {f('psnr', '6.2f')} "
              f"{f('ssim', '6.4f')} {f('wall_s', '7.1f')} {f('steps', '6.0f')} "
              f"{f('gaussians', '9.0f')} {r.get('error') or ''}")


def main(argv=None) -> int:
    args = parse(argv)
    args.data_root = os.path.abspath(args.data_root)
    if args.worker:
        return gsplat_worker(args)
    if args.summary:
        return summary(args)
    os.makedirs(args.out, exist_ok=True)
    gsplat = "gsplat" in args.trainers and not args.ablate
    if gsplat and not (have_gsplat() or args.dry_run):
        print("torch or gsplat is not installed here: the gsplat runs are skipped")
        gsplat = False
    from benchmarks.common import device_line

    print(device_line(), flush=True)
    every = []
    for scene in args.scenes:
        if args.ablate:
            rows = _ablate(args, scene)
        else:
            rows = _scene_runs(args, scene, gsplat)  # each row kept as its run ended
        every += rows
    if not args.dry_run:
        short_table(every)
    return 1 if any(r.get("error") for r in every) else 0


if __name__ == "__main__":
    sys.exit(main())
