"""Training, ours against gsplat 1.5.3's trainer, in one call on one GPU.

    python benchmarks/train_vs_gsplat.py [--data-root DIR] [--scenes lego skull] [--steps 7000]
        [--strategy mcmc|default] [--eval-every 500] [--seed 0] [--out DIR] [--no-gsplat] ...

Per scene, `lgs_jax.train.fit` and then a small gsplat trainer, each in a subprocess of its own
(each its own peak memory; JAX off the GPU while gsplat runs), on the same:
  data     `lgs_jax.load_dataset` (lego_train 200x200 on white; skull, COLMAP, and fox, lens
           undistorted, on black), images 8-bit on the device where the files are (--images),
           the same split (every 8th image held out; Lego ids 0, 10, ..., 90), the same views
           in the same order (`views_for_step`, one per step);
  start    `init.start_gaussians` (SfM points, or 100,000 random ones for Lego), the same arrays;
  recipe   Adam (eps 1e-15) with lr means 1.6e-4 x scene scale decaying to 1% (ExponentialLR),
           quats 1e-3, scales 5e-3, opacities 5e-2, SH DC 2.5e-3, SH rest 2.5e-3 / 20; loss
           0.8 L1 + 0.2 (1 - SSIM) with the same 11x11 Gaussian SSIM (zero-padded "same", 3DGS's,
           or --ssim-padding valid, simple_trainer's fused-ssim; torch conv2d here, checked
           against ours at start); SH degree +1 every 1000 steps;
  strategy gsplat's `MCMCStrategy(cap_max=cap)` with regularisers 0.01 (opacity, scale) or its
           `DefaultStrategy()`, against ours with the same settings (`lgs_jax.train.strategy`);
  metrics  held-out PSNR / SSIM as scikit-image's defaults every --eval-every steps and at the
           end, renders clipped to [0, 1] (ours during the run: `train.heldout`, the same
           formulas on the device; the final ones and gsplat's: `report.heldout_metrics`).
Each renders with its own rasterizer (ours: --backend, `pallas` on a GPU by default, with the
3DGS compositing rule, alpha cap 0.99, or gsplat's with --convention gsplat; gsplat's: 0.999).
Time per step: the loop's wall time (gsplat's: a host sync per step, as simple_trainer's bar
does; ours: `fit`'s, a step dispatched before the last one's read) without evaluations;
ours also without compilation (compiling ahead in a thread counts only its waits:
--compile-ahead off for the steps alone); gsplat's after one warm-up render.
Wall time (`process_s`): each worker from its start to its last output, imports, data and
compiles included. Peak memory: torch's max_memory_allocated, JAX's peak_bytes_in_use.
Outputs in OUT: curves.csv (scene, trainer, step, held-out PSNR, SSIM, Gaussians), summary.csv
(final and best PSNR/SSIM, times, peak MB, Gaussians, the lgs_jax folder that ran), <scene>_
<trainer>.json, curves_<scene>.png; our runs in --run-dir (default: a temporary folder).
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import importlib.util
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DEVICE = "cuda"  # gsplat's; its rasterization has no CPU path
SCENES = {  # folder in the data root, image downscale, Gaussian cap
    "lego": dict(folder="lego_train", downscale=1, cap=300_000),
    "skull": dict(folder="skull", downscale=1, cap=500_000),
    "fox": dict(folder="fox", downscale=1, cap=500_000),  # lens distortion: undistorted at load
}


def parse(argv=None) -> argparse.Namespace:
    """The command line (module docstring)."""
    from lgs_jax.config import CONVENTIONS
    from lgs_jax.train import FitConfig

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data-root", default=os.environ.get(
        "LGS_JAX_DATA", os.path.join(ROOT, "..", "shared", "data")))
    ap.add_argument("--scenes", nargs="+", default=list(SCENES), choices=list(SCENES))
    ap.add_argument("--strategy", choices=["mcmc", "default"], default="mcmc")
    ap.add_argument("--steps", type=int, default=7000)
    ap.add_argument("--eval-every", type=int, default=500)
    ap.add_argument("--cap", type=int, help="Gaussian cap for every scene (default: SCENES)")
    ap.add_argument("--refine-from", type=int,
                    help="both strategies' refine_start_iter (e.g. the step count: no "
                         "refinement, to tell its effect apart; default: the strategy's)")
    ap.add_argument("--downscale", type=int, help="image downscale for every scene (default: 1)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--images", choices=["auto", "float32"], default="auto",
                    help="both trainers' images on the device: auto (fit's default) or float32")
    ap.add_argument("--backend", help="our backend (default: pallas on a GPU, tiles elsewhere)")
    ap.add_argument("--convention", choices=CONVENTIONS, default="3dgs",
                    help="our compositing rule (gsplat's trainer's: always gsplat's)")
    ap.add_argument("--ssim-padding", choices=["same", "valid"], default="same",
                    help="both trainers' loss SSIM: same (3DGS's) or valid (simple_trainer's)")
    ap.add_argument("--out", default="train_vs_gsplat_out", help="CSVs, JSON and figures")
    ap.add_argument("--run-dir", help="our runs' folders (large; default: a temporary one)")
    ap.add_argument("--no-gsplat", action="store_true")
    ap.add_argument("--no-ours", action="store_true")  # then our FitConfig's fields:
    ap.add_argument("--compile-ahead", choices=["thread", "process", "off"],
                    help="default: thread on a GPU, off elsewhere")
    ap.add_argument("--pair-headroom", type=float, default=FitConfig.pair_headroom)
    ap.add_argument("--row-headroom", type=float, help="default: a row per pair slot")
    ap.add_argument("--stream-images", action=argparse.BooleanOptionalAction)  # default: fit's
    ap.add_argument("--inline", action="store_true", help="run the trainers in this process")
    ap.add_argument("--worker", choices=["ours", "gsplat"], help=argparse.SUPPRESS)
    ap.add_argument("--scene", help=argparse.SUPPRESS)
    return ap.parse_args(argv)


def scene_setup(args, scene: str, out: str = ""):
    """(Dataset, our FitConfig) of a scene, run into `out`; random starts of gsplat's
    simple_trainer's size (100,000 points)."""
    import lgs_jax
    from lgs_jax import train

    cfg = SCENES[scene]
    d = lgs_jax.load_dataset(os.path.join(args.data_root, cfg["folder"]),
                             downscale=args.downscale or cfg["downscale"],
                             dtype="auto" if args.images == "auto" else np.float32)
    cap = args.cap or cfg["cap"]
    strategy = (train.MCMCStrategy(cap_max=cap) if args.strategy == "mcmc"
                else train.DefaultStrategy())
    if args.refine_from is not None:
        strategy = dataclasses.replace(strategy, refine_start_iter=args.refine_from)
    config = train.FitConfig(
        data=d.path, out=out, steps=args.steps, strategy=strategy,
        recipe=train.Recipe(ssim_padding=args.ssim_padding, convention=args.convention),
        max_gaussians=cap,
        init_points=100_000, seed=args.seed, backend=args.backend,
        pair_headroom=args.pair_headroom, row_headroom=args.row_headroom,
        compile_ahead=args.compile_ahead, eval_every=args.eval_every,
        stream_images=args.stream_images, checkpoint_every=max(args.steps, 1),
        overwrite=True)
    return d, config


def eval_steps(args) -> list[int]:
    """Completed-step counts at which both trainers evaluate (fit's rule)."""
    return [s for s in range(args.eval_every, args.steps, args.eval_every)] + [args.steps]


def run_ours(args, scene: str) -> dict:
    """lgs_jax.train.fit on the scene; its curve, times and peak memory. Compiled programs go
    to the command line's persistent cache (`lgs_jax.cli.use_compile_cache`), so repeated runs
    (other seeds) load them; compile_s is whatever compiling remained."""
    import jax

    from lgs_jax import train
    from lgs_jax.cli import use_compile_cache
    from lgs_jax.train import report

    use_compile_cache()
    out = os.path.join(args.run_dir or tempfile.mkdtemp(prefix="lgs_bench_"), f"{scene}_ours")
    d, config = scene_setup(args, scene, out)
    result = train.fit(config, d)
    rows = report.read_metrics(os.path.join(out, "metrics.jsonl"))
    count = {r["step"]: r["gaussians"] for r in rows if "gaussians" in r and "step" in r}
    curve = [dict(step=r["step"], psnr=r["heldout_psnr"], ssim=r["heldout_ssim"],
                  gaussians=count.get(r["step"], result["gaussians"]))
             for r in rows if "heldout_psnr" in r]
    stats = jax.devices()[0].memory_stats() or {}
    ms, compile_s = result["ms_per_step"], result["compile_seconds"]
    return dict(scene=scene, trainer="lgs_jax", steps=args.steps, curve=curve,
                ms_per_step=ms, compile_s=compile_s,
                ms_per_step_excl_compile=ms - 1e3 * compile_s / args.steps if ms else None,
                peak_mb=stats.get("peak_bytes_in_use", 0) / 2**20 or None,
                gaussians=result["gaussians"], skipped_steps=result["skipped_steps"],
                device=result["device"], backend=result["backend"], package=package_root())


def torch_ssim(img, ref, padding: str = "same"):
    """Our loss's SSIM in torch: (H, W, 3) images, 11x11 Gaussian window (σ 1.5) by conv2d with
    zero padding, mean over pixels and channels, or over the interior for padding "valid"
    (`lgs_jax.train.losses.ssim`)."""
    import torch
    import torch.nn.functional as F

    from lgs_jax.train.losses import gaussian_window

    w1 = torch.tensor(gaussian_window(), dtype=img.dtype, device=img.device)
    win = (w1[:, None] * w1[None, :]).expand(3, 1, 11, 11).contiguous()
    x, y = img.permute(2, 0, 1)[None], ref.permute(2, 0, 1)[None]
    blur = lambda t: F.conv2d(t, win, padding=5, groups=3)
    mu_x, mu_y = blur(x), blur(y)
    var_x, var_y = blur(x * x) - mu_x**2, blur(y * y) - mu_y**2
    cov = blur(x * y) - mu_x * mu_y
    c1, c2 = 0.01**2, 0.03**2
    s = ((2 * mu_x * mu_y + c1) * (2 * cov + c2)
         / ((mu_x**2 + mu_y**2 + c1) * (var_x + var_y + c2)))
    return (s[..., 5:-5, 5:-5] if padding == "valid" else s).mean()


def check_torch_ssim() -> float:
    """Largest |torch_ssim − ours| on random images, both paddings; raises if over 1e-5."""
    import jax.numpy as jnp
    import torch

    from lgs_jax.train.losses import ssim

    rng = np.random.default_rng(0)
    a = rng.uniform(0, 1, (37, 53, 3)).astype(np.float32)
    b = np.clip(a + rng.normal(0, 0.1, a.shape), 0, 1).astype(np.float32)
    worst = 0.0
    for padding in ("same", "valid"):
        ours = float(ssim(jnp.asarray(a), jnp.asarray(b), padding=padding))
        theirs = float(torch_ssim(torch.from_numpy(a), torch.from_numpy(b), padding))
        if abs(ours - theirs) > 1e-5:
            raise RuntimeError(f"torch SSIM {theirs} differs from ours {ours} ({padding})")
        worst = max(worst, abs(ours - theirs))
    return worst


def _gsplat_model(g0, rd, settings, strategy, steps: int):
    """(params, optimizers, scheduler, gsplat strategy, its state) as simple_trainer builds
    them, from our initial Gaussians and our recipe's rates."""
    import torch
    from gsplat.strategy import DefaultStrategy, MCMCStrategy

    t = lambda x: torch.nn.Parameter(torch.tensor(np.asarray(x), dtype=torch.float32,
                                                  device=DEVICE))
    sh = np.asarray(g0.sh)
    params = torch.nn.ParameterDict(dict(
        means=t(g0.means), scales=t(g0.log_scales), quats=t(g0.quats),
        opacities=t(g0.logit_opacities), sh0=t(sh[:, :1]), shN=t(sh[:, 1:])))
    s = settings
    rates = dict(means=s.lr_means * rd.scene_scale, scales=s.lr_log_scales, quats=s.lr_quats,
                 opacities=s.lr_logit_opacities, sh0=s.lr_sh_dc, shN=s.lr_sh_rest)
    opts = {k: torch.optim.Adam([{"params": params[k], "lr": lr, "name": k}], eps=1e-15,
                                betas=(0.9, 0.999), fused=DEVICE == "cuda")
            for k, lr in rates.items()}
    sched = torch.optim.lr_scheduler.ExponentialLR(
        opts["means"], gamma=s.lr_means_decay ** (1.0 / max(steps, 1)))
    mcmc = type(strategy).__name__ == "MCMCStrategy"
    cls = MCMCStrategy if mcmc else DefaultStrategy
    shared = {f.name: getattr(strategy, f.name) for f in dataclasses.fields(cls)
              if f.name in {g.name for g in dataclasses.fields(strategy)}}
    theirs = cls(**shared)  # gsplat's strategy with our settings (cap_max, refine_start_iter...)
    state = (theirs.initialize_state() if mcmc
             else theirs.initialize_state(scene_scale=rd.scene_scale))
    theirs.check_sanity(params, opts)
    return params, opts, sched, theirs, state


def _gsplat_render(params, viewmat, K, rd, sh_degree: int):
    """gsplat's rasterization of one view (1, H, W, 3) over the dataset's background."""
    import torch
    from gsplat import rasterization

    colors = torch.cat([params["sh0"], params["shN"]], 1)
    bg = torch.tensor(rd.background, device=DEVICE)[None]
    h, w = rd.train_images.shape[1:3]
    return rasterization(params["means"], params["quats"], torch.exp(params["scales"]),
                         torch.sigmoid(params["opacities"]), colors, viewmat, K, w, h,
                         sh_degree=sh_degree, near_plane=0.01, far_plane=1e10, packed=False,
                         absgrad=False, rasterize_mode="classic", backgrounds=bg)


def _cams_torch(cams):
    """(viewmats (N, 4, 4), Ks (N, 3, 3)) tensors of stacked (or listed) cameras."""
    import torch

    cams = cams if isinstance(cams, list) else [cams]
    vm = np.concatenate([np.asarray(c.viewmat, np.float32).reshape(-1, 4, 4) for c in cams])
    f = lambda name: np.concatenate([np.asarray(getattr(c, name), np.float32).reshape(-1)
                                     for c in cams])
    fx, fy, cx, cy = f("fx"), f("fy"), f("cx"), f("cy")
    ks = np.zeros((len(fx), 3, 3), np.float32)
    ks[:, 0, 0], ks[:, 1, 1], ks[:, 0, 2], ks[:, 1, 2], ks[:, 2, 2] = fx, fy, cx, cy, 1
    return torch.tensor(vm, device=DEVICE), torch.tensor(ks, device=DEVICE)


def _gsplat_eval(params, rd, test_vm, test_k):
    """Held-out (PSNR, SSIM) of gsplat's model (scikit-image, renders clipped to [0, 1])."""
    import torch

    from lgs_jax.train import report

    with torch.no_grad():
        images = [_gsplat_render(params, test_vm[i:i + 1], test_k[i:i + 1], rd, 3)[0][0]
                  .clamp(0, 1).cpu().numpy() for i in range(len(test_vm))]
    return report.heldout_metrics(images, rd.test_images)


def _sync():
    if DEVICE == "cuda":
        __import__("torch").cuda.synchronize()


def _gsplat_loop(args, rd, model, settings, strategy, log):
    """simple_trainer's loop (module docstring): returns (curve, training seconds)."""
    import torch

    from lgs_jax.train.feed import views_for_step

    params, opts, sched, theirs, state = model
    vm, ks = _cams_torch(rd.train_cams)
    test_vm, test_k = _cams_torch(rd.test_cams)
    images = torch.tensor(np.asarray(rd.train_images), device=DEVICE)
    mcmc, evals, curve, busy = hasattr(theirs, "cap_max"), set(eval_steps(args)), [], 0.0
    with torch.no_grad():  # loads gsplat's CUDA extension (or builds it) before the clock
        _gsplat_render(params, vm[:1], ks[:1], rd, 0)
    _sync()
    t0 = time.perf_counter()
    for step in range(args.steps):
        i = int(views_for_step(step, 1, len(vm), args.seed)[0])
        deg = min(step // settings.sh_every, settings.sh_degree)
        renders, _, info = _gsplat_render(params, vm[i:i + 1], ks[i:i + 1], rd, deg)
        if not mcmc:
            theirs.step_pre_backward(params, opts, state, step, info)
        img, target = renders[0], images[i]
        if target.dtype == torch.uint8:  # x / 255 in float32, as fit's feed converts them
            target = target.float() / 255
        loss = torch.lerp((img - target).abs().mean(),
                          1 - torch_ssim(img, target, settings.ssim_padding),
                          settings.ssim_lambda)
        if mcmc:
            loss = (loss + strategy.opacity_reg * torch.sigmoid(params["opacities"]).mean()
                    + strategy.scale_reg * torch.exp(params["scales"]).mean())
        loss.backward()
        for opt in opts.values():
            opt.step()
            opt.zero_grad(set_to_none=True)
        sched.step()
        if mcmc:
            theirs.step_post_backward(params, opts, state, step, info, lr=sched.get_last_lr()[0])
        else:
            theirs.step_post_backward(params, opts, state, step, info, packed=False)
        loss.item()  # one host sync per step, as simple_trainer's progress bar
        if step + 1 in evals:
            busy += time.perf_counter() - t0
            psnr, ssim = _gsplat_eval(params, rd, test_vm, test_k)
            curve.append(dict(step=step + 1, psnr=psnr, ssim=ssim, gaussians=len(params["means"])))
            log(f"gsplat step {step + 1}: held-out PSNR {psnr:.2f} dB, SSIM {ssim:.4f}, "
                f"{len(params['means'])} Gaussians")
            _sync()
            t0 = time.perf_counter()
    return curve, busy


def run_gsplat(args, scene: str) -> dict:
    """gsplat 1.5.3's trainer on the scene; its curve, time per step and peak memory."""
    import torch

    from lgs_jax.train.feed import prepare
    from lgs_jax.train.init import start_gaussians

    torch.backends.cuda.matmul.allow_tf32 = False  # float32 arithmetic, as ours
    torch.backends.cudnn.allow_tf32 = False
    check_torch_ssim()
    torch.manual_seed(args.seed)
    d, config = scene_setup(args, scene)
    rd = prepare(d)
    g0 = start_gaussians(rd, config)
    settings, strategy = config.recipe, config.strategy
    cuda = DEVICE == "cuda"
    if cuda:
        torch.cuda.reset_peak_memory_stats()
    model = _gsplat_model(g0, rd, settings, strategy, args.steps)
    curve, busy = _gsplat_loop(args, rd, model, settings, strategy, print)
    return dict(scene=scene, trainer="gsplat", steps=args.steps, curve=curve,
                ms_per_step=1e3 * busy / args.steps if args.steps else None,
                peak_mb=torch.cuda.max_memory_allocated() / 2**20 if cuda else None,
                gaussians=len(model[0]["means"]),
                device=torch.cuda.get_device_name() if cuda else DEVICE)


def package_root() -> str:
    """The folder of the lgs_jax this process imports, which the workers import too: the first
    on its path (PYTHONPATH=TREE for an A/B of two versions), else this repository."""
    spec = importlib.util.find_spec("lgs_jax")
    origin = spec.origin if spec else None
    return os.path.dirname(os.path.dirname(os.path.abspath(origin))) if origin else ROOT


def _run(args, argv, scene: str, trainer: str) -> dict:
    """One trainer on one scene: inline, or in a subprocess (JAX off the GPU for gsplat's)."""
    path = os.path.join(args.out, f"{scene}_{trainer}.json")
    if args.inline:
        result = (run_ours if trainer == "ours" else run_gsplat)(args, scene)
    else:
        env = dict(os.environ, PYTHONUNBUFFERED="1")
        env["PYTHONPATH"] = os.pathsep.join(filter(None, (package_root(), env.get("PYTHONPATH"))))
        if trainer == "gsplat":
            env["JAX_PLATFORMS"] = "cpu"
        cmd = [sys.executable, os.path.abspath(__file__), *argv, "--worker", trainer,
               "--scene", scene]
        t0 = time.perf_counter()
        if subprocess.run(cmd, env=env).returncode != 0 or not os.path.exists(path):
            return dict(scene=scene, trainer=trainer, error="the run failed (see its output)")
        with open(path) as f:
            result = json.load(f)
        result["process_s"] = time.perf_counter() - t0  # process start to its last output
        with open(path, "w") as f:
            json.dump(result, f, indent=1)
        return result
    with open(path, "w") as f:
        json.dump(result, f, indent=1)
    return result


SUMMARY = ("scene", "trainer", "steps", "final_psnr", "final_ssim", "best_psnr", "best_step",
           "process_s", "ms_per_step", "ms_per_step_excl_compile", "compile_s", "peak_mb",
           "gaussians", "device", "package", "error")


def summary_row(r: dict) -> dict:
    """A result's line of summary.csv: the curve's last and best points and the costs."""
    curve = r.get("curve") or []
    best = max(curve, key=lambda c: c["psnr"]) if curve else {}
    row = {k: r.get(k) for k in SUMMARY}
    row.update(final_psnr=curve[-1]["psnr"] if curve else None,
               final_ssim=curve[-1]["ssim"] if curve else None,
               best_psnr=best.get("psnr"), best_step=best.get("step"))
    return row


def write_csvs(out: str, results: list[dict]) -> None:
    """curves.csv and summary.csv (module docstring)."""
    with open(os.path.join(out, "curves.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["scene", "trainer", "step", "heldout_psnr", "heldout_ssim", "gaussians"])
        for r in results:
            for c in r.get("curve") or []:
                w.writerow([r["scene"], r["trainer"], c["step"], f"{c['psnr']:.4f}",
                            f"{c['ssim']:.5f}", c["gaussians"]])
    with open(os.path.join(out, "summary.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=SUMMARY)
        w.writeheader()
        w.writerows(summary_row(r) for r in results)


def print_table(results: list[dict]) -> None:
    """The summary and, per scene with both trainers, ours against gsplat's."""
    fmt = lambda v, spec: "-" if v is None else format(v, spec)
    print(f"{'scene':6} {'trainer':8} {'PSNR':>6} {'SSIM':>6} {'best':>6} {'@step':>6} "
          f"{'ms/step':>8} {'(-jit)':>7} {'peak MB':>8} {'Gaussians':>9}")
    rows = [summary_row(r) for r in results]
    for r in rows:
        print(f"{r['scene']:6} {r['trainer']:8} {fmt(r['final_psnr'], '6.2f')} "
              f"{fmt(r['final_ssim'], '6.4f')} {fmt(r['best_psnr'], '6.2f')} "
              f"{fmt(r['best_step'], '6d')} {fmt(r['ms_per_step'], '8.2f')} "
              f"{fmt(r['ms_per_step_excl_compile'], '7.2f')} {fmt(r['peak_mb'], '8.0f')} "
              f"{fmt(r['gaussians'], '9d')} {r['error'] or ''}")
    for scene in dict.fromkeys(r["scene"] for r in rows):
        pair = {r["trainer"]: r for r in rows if r["scene"] == scene}
        a, b = pair.get("lgs_jax"), pair.get("gsplat")
        if not (a and b) or a["final_psnr"] is None or b["final_psnr"] is None:
            continue
        ms = a["ms_per_step_excl_compile"] or a["ms_per_step"]
        memory = (f", peak memory x{a['peak_mb'] / b['peak_mb']:.2f}"
                  if a["peak_mb"] and b["peak_mb"] else "")
        print(f"{scene} (ours against gsplat's): PSNR {a['final_psnr'] - b['final_psnr']:+.2f} "
              f"dB, SSIM {a['final_ssim'] - b['final_ssim']:+.4f}, time per step "
              f"x{ms / b['ms_per_step']:.2f}{memory}")


def print_curves(results: list[dict]) -> None:
    """Held-out PSNR / SSIM against the step, the trainers side by side, per scene."""
    for scene in dict.fromkeys(r["scene"] for r in results):
        runs = [r for r in results if r["scene"] == scene and r.get("curve")]
        print(f"{scene}: held-out PSNR / SSIM / Gaussians by step")
        print("  step " + "".join(f"{r['trainer']:>28}" for r in runs))
        by_step = [{c["step"]: c for c in r["curve"]} for r in runs]
        for step in sorted(set().union(*by_step)):
            cells = [f"{c['psnr']:7.2f} {c['ssim']:7.4f} {c['gaussians']:10d}" if c else " " * 26
                     for c in (b.get(step) for b in by_step)]
            print(f"{step:6d} " + "".join(f"{x:>28}" for x in cells))


def plot_curves(out: str, scene: str, runs: list[dict]) -> None:
    """curves_<scene>.png: held-out PSNR, SSIM and Gaussians against the step, per trainer."""
    from matplotlib.figure import Figure

    runs = [r for r in runs if r.get("curve")]
    if not runs:
        return
    fig = Figure(figsize=(13, 3.6))
    axes = fig.subplots(1, 3)
    for r in runs:
        steps = [c["step"] for c in r["curve"]]
        for ax, key in zip(axes, ("psnr", "ssim", "gaussians")):
            ax.plot(steps, [c[key] for c in r["curve"]], "o-", ms=3, label=r["trainer"])
    for ax, title in zip(axes, ("held-out PSNR (dB)", "held-out SSIM", "Gaussians")):
        ax.set(title=f"{scene}: {title}", xlabel="step")
        ax.legend()
    fig.tight_layout()
    fig.savefig(os.path.join(out, f"curves_{scene}.png"), dpi=100)


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    args = parse(argv)
    os.makedirs(args.out, exist_ok=True)
    if args.worker:
        _run(argparse.Namespace(**dict(vars(args), inline=True)), argv, args.scene, args.worker)
        return 0
    trainers = [t for t, skip in (("ours", args.no_ours), ("gsplat", args.no_gsplat)) if not skip]
    results = []
    for scene in args.scenes:
        for trainer in trainers:
            results.append(_run(args, argv, scene, trainer))
            write_csvs(args.out, results)  # after each run: a later failure keeps these
        plot_curves(args.out, scene, [r for r in results if r["scene"] == scene])
    print_curves(results)
    print_table(results)
    return 1 if any(r.get("error") for r in results) else 0


if __name__ == "__main__":
    sys.exit(main())
