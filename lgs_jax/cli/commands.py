"""Command line: `python -m lgs_jax render ...`, `video ...` (lgs_jax.video), `view ...`
(lgs_jax.viewer), `info SCENE.ply`, `fit --data DIR --out DIR [--strategy default|mcmc]
[--steps N] ...` (lgs_jax.train) and `eval SCENE.ply --data DIR` (lgs_jax.train.evaluate).

Compiled programs are kept in JAX's persistent cache (`use_compile_cache`: $LGS_JAX_CACHE,
default ~/.cache/lgs_jax/jax; LGS_JAX_CACHE="" turns it off).

Errors are one line on stderr: exit code 2 for a bad command line (checked before any work:
options, input paths, --view, --out, an existing fit run), 1 for a failure while working (a
malformed file, a render error); `--debug` shows the traceback instead.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time

import numpy as np

from . import eval as eval_cmd, video as video_cmd, view as view_cmd
from .args import (EXIT_FAILURE, EXIT_USAGE, IMAGE_EXTENSIONS, Parser, UsageError,
                       check_dataset, check_input, check_out, chosen_camera, int_at_least,
                       number_at_least, raster_config, view_options)
from ..config import CONVENTIONS


def _merged_seconds(spans) -> float:
    """Total length of the union of (start, end) intervals (nested compilations count once)."""
    total, reach = 0.0, -math.inf
    for start, end in sorted(spans):
        if end > reach:
            total += end - max(start, reach)
            reach = end
    return total


def _timed_render(scene, cam, **kwargs):
    """(output, seconds, compile seconds) of one `lgs_jax.render` call: the compile seconds are
    the wall time JAX spent tracing, lowering and compiling (or loading compiled code) in it."""
    import jax

    import lgs_jax

    spans = []

    def listener(event, start, end, **_):
        if event.startswith("/jax/core/compile/"):
            spans.append((start, end))

    jax.monitoring.register_event_time_span_listener(listener)
    try:
        t0 = time.time()
        out = jax.block_until_ready(lgs_jax.render(scene, cam, **kwargs))
        seconds = time.time() - t0
    finally:
        jax.monitoring.unregister_event_time_span_listener(listener)
    return out, seconds, _merged_seconds(spans)


def _render(args) -> int:
    """`render`: check the arguments, load, render once, report, write the image."""
    import jax

    import lgs_jax

    for path, what in ((args.scene, "scene"), (args.cameras, "--cameras")):
        if path:
            check_input(path, what)
    check_out(args.out)
    scene = lgs_jax.load_ply(args.scene) if args.scene else lgs_jax.default_scene()
    cam = chosen_camera(args, "to render")
    out, seconds, compiling = _timed_render(
        scene, cam, background=np.asarray(args.background, np.float32), backend=args.backend,
        config=raster_config(args))
    s = out.stats
    print(f"scene: {scene.num} Gaussians (SH degree {scene.sh_degree}); image {cam.width}x"
          f"{cam.height}; backend {s.backend}; device {jax.devices()[0].platform}")
    print(f"time: {seconds:.3f} s, of which {compiling:.3f} s compiling (a first call at a new "
          f"size compiles) and {seconds - compiling:.3f} s rendering")
    if getattr(s.backend_stats, "interpreted", False):
        print("note: the Pallas kernel ran in interpret mode (no GPU): exact but slow")
    print(f"valid {int(s.n_valid)}, invalid {int(s.n_invalid)}, below 1/255 "
          f"{int(s.n_transparent)}, unbounded {int(s.n_unbounded)}; tile-Gaussian pairs "
          f"{int(s.pairs_required)} (capacity {int(s.capacity)})")
    import matplotlib.image

    from ..video import frame_pixels

    matplotlib.image.imsave(args.out, frame_pixels(out, args.output))
    print(f"wrote {args.out}")
    return 0


def _info(args) -> int:
    """`info`: counts, SH degree, bounds and non-finite values of a PLY."""
    import lgs_jax

    check_input(args.scene, "scene")
    g = lgs_jax.load_ply(args.scene)
    print(f"{args.scene}: {g.num} Gaussians, SH degree {g.sh_degree}, dtype {g.means.dtype}")
    m = np.asarray(g.means)
    fin = np.all(np.isfinite(m), -1)
    if fin.any():
        print(f"bounds: min {m[fin].min(0)}, max {m[fin].max(0)}")
    for name in ("means", "quats", "log_scales", "logit_opacities", "sh"):
        v = np.asarray(getattr(g, name))
        print(f"{name:16s} nan {int(np.isnan(v).sum()):8d}  +inf {int((v == np.inf).sum()):8d}  "
              f"-inf {int((v == -np.inf).sum()):8d}")
    o = 1 / (1 + np.exp(-np.asarray(g.logit_opacities, np.float64)))
    print(f"opacity below 1/255: {int((o < 1 / 255).sum())}; exactly 1: {int((o == 1).sum())}")
    return 0


def _fit(args) -> int:
    """`fit`: check --data and --out (an existing run needs --resume or --overwrite), train."""
    from .. import train

    check_dataset(args.data)
    problem = train.run_dir_problem(args.out, args.resume, args.overwrite)
    if problem:
        raise UsageError(f"--out: {problem}")
    settings = train.Settings(batch=args.batch, eval_every=args.eval_every,
                              init_points=args.init_points, convention=args.convention,
                              antialiased=args.antialiased, pair_headroom=args.pair_headroom,
                              row_headroom=args.row_headroom, stream_images=args.stream_images,
                              pose_opt=args.pose_opt, color_opt=args.color_opt,
                              bilateral_grid=args.bilateral_grid, app_opt=args.app_opt,
                              train_on_all=args.train_on_all, sh_degree=args.sh_degree)
    data, watch, served = args.data, None, None
    if args.viewer_port is not None or args.uint8_images:
        data = _dataset(args)
    if args.viewer_port is not None:
        watch, served = view_cmd.training_viewer(args, data)
    if args.strategy == "mcmc":
        strategy = train.MCMCStrategy(cap_max=args.max_gaussians)
    else:
        strategy = train.DefaultStrategy(opacity_reset=args.opacity_reset)
    try:
        result = train.fit(data, args.steps, args.out, strategy=strategy, settings=settings,
                           max_gaussians=args.max_gaussians, downscale=args.downscale,
                           crop=tuple(args.crop) if args.crop else None, seed=args.seed,
                           backend=args.backend, pool_size=args.pool_size,
                           resume=args.resume, overwrite=args.overwrite,
                           compile_ahead=ahead_mode(args), devices=args.devices, watch=watch)
    except BaseException:  # the viewer's threads would keep the process alive
        if served is not None:
            served.stop()
        raise
    print(json.dumps(result, indent=1))
    if served is not None:
        from ..viewer import wait

        print("training done; the viewer shows the trained scene (Ctrl-C stops)", flush=True)
        wait(served)
    return 0


def _dataset(args):
    """The dataset `fit` trains on (`--data`, `--downscale`, `--uint8-images`), loaded here
    for its viewer or its image type."""
    from ..io.datasets import load_dataset

    return load_dataset(args.data, downscale=args.downscale,
                        dtype=np.uint8 if args.uint8_images else np.float32)


def _render_parser(sub, common) -> None:
    """The `render` subcommand's options."""
    r = sub.add_parser(
        "render", parents=[common], help="render a scene (the bundled default scene if none given)",
        description="Render one view once and write it as an image (--out). Prints the scene and "
                    "image size, the backend, the time (compilation separately), and the counts "
                    "of valid, invalid and culled Gaussians and tile-Gaussian pairs. Image size: "
                    "one of --width/--height keeps the camera's aspect ratio; both with another "
                    "aspect ratio scale the view to cover that size and crop its centre (never "
                    "stretched). Errors: one line on stderr, exit code 2 for a bad command line "
                    "(checked before rendering), 1 for a failure (e.g. a malformed file).")
    view_options(r)
    r.add_argument("--view", type=int_at_least(0),
                   help="camera index (default: 0 of --cameras; for the default scene its "
                        "framing camera, or orbit view 0..7)")
    r.add_argument("--out", default="out.png",
                   help=f"image to write, {'/'.join(IMAGE_EXTENSIONS)} (default: out.png)")
    r.set_defaults(func=_render)


def _fit_parser(sub, common) -> None:
    """The `fit` subcommand's options."""
    from ..train.settings import Settings

    f = sub.add_parser(
        "fit", parents=[common], help="train Gaussians on a capture (COLMAP, transforms.json, "
                                      "NeRF-synthetic) with densification",
        description="Train Gaussians on a dataset (lgs_jax.load_dataset: every 8th image held "
                    "out, NeRF-synthetic ids 0,10,..,90) with gsplat's recipe and a densification "
                    "strategy. Writes into OUT: metrics.jsonl, checkpoints (resume continues "
                    "bit-identically), scene.ply (INRIA PLY), heldout_*.png (render beside ground "
                    "truth), curves.png, result.json.")
    f.add_argument("--data", required=True, help="dataset folder (or transforms json)")
    f.add_argument("--out", required=True, help="run directory (new or empty, unless --resume "
                                                "or --overwrite)")
    f.add_argument("--steps", type=int_at_least(0), default=30000,
                   help="training steps (default: 30000)")
    f.add_argument("--strategy", choices=["default", "mcmc"], default="default",
                   help="densification: default (3DGS clone/split/prune, gsplat's "
                        "DefaultStrategy) or mcmc (3DGS as MCMC, gsplat's MCMCStrategy, with "
                        "its recipe: init opacity 0.5, scale 0.1, regularisers 0.01)")
    f.add_argument("--max-gaussians", type=int_at_least(1), default=1_000_000,
                   help="cap on the number of Gaussians (the pool's; MCMC's cap_max) "
                        "(default: 1000000)")
    f.add_argument("--downscale", type=int_at_least(1), default=1,
                   help="integer image downscale at load (default: 1)")
    f.add_argument("--pool-size", type=int_at_least(1),
                   help="initial pool slots (default: the next power of two above the initial "
                        "count; the pool doubles when it must, recompiling once each time)")
    f.add_argument("--init-points", type=int_at_least(1), default=100_000,
                   help="random initial points for datasets without SfM points (default: "
                        "100000)")
    f.add_argument("--opacity-reset", action="store_true",
                   help="default strategy: reset opacities every 3000 steps (3DGS; gsplat "
                        "1.5.3 never does, through a bug)")
    f.add_argument("--batch", type=int_at_least(1), default=1, help="views per step")
    f.add_argument("--sh-degree", type=int, choices=range(4), default=Settings.sh_degree,
                   help="highest SH degree of the colours, one band more every 1000 steps "
                        "(0: view-independent colours; default: 3)")
    f.add_argument("--devices", type=int_at_least(1), default=1,
                   help="split each step's views across this many devices (data parallel; "
                        "--batch a multiple of it; default 1)")
    f.add_argument("--convention", choices=CONVENTIONS, default="3dgs",
                   help="compositing rule of training and evaluation renders (alpha cap 0.99 "
                        "or gsplat's 0.999)")
    f.add_argument("--antialiased", action="store_true",
                   help="train and evaluate with antialiased renders (gsplat's "
                        "--antialiased: opacities scaled so that the 0.3-pixel dilation keeps "
                        "each Gaussian's integral); render the result with --antialiased too")
    _fit_view_options(f)
    f.add_argument("--train-on-all", action="store_true",
                   help="train on every view, the held-out ones too (a final scene; nothing "
                        "is evaluated)")
    f.add_argument("--eval-every", type=int_at_least(1), default=500,
                   help="steps between held-out evaluations (default: 500)")
    f.add_argument("--pair-headroom", type=number_at_least(1.0, float),
                   default=Settings.pair_headroom,
                   help="pair buffer size as a multiple of a view's pairs, at the start and at "
                        "each growth (a recompile); larger: fewer recompiles, larger buffers "
                        f"(default: {Settings.pair_headroom:g})")
    f.add_argument("--row-headroom", type=number_at_least(1.0, float), default=None,
                   help="size the Pallas backward's gradient rows to this multiple of the "
                        "walked pairs, growing them when a view walks more (a recompile each): "
                        "less memory, the same results (default: a row per pair slot)")
    _fit_run_options(f)
    f.set_defaults(func=_fit)


def _fit_view_options(f) -> None:
    """`fit`'s options that optimize the training views' own parameters (`view_params`)."""
    f.add_argument("--pose-opt", action="store_true",
                   help="also optimize each training view's camera pose (gsplat's --pose_opt: "
                        "a 9-D delta per view, Adam at 1e-5, weight decay 1e-6); held-out "
                        "views keep their poses")
    f.add_argument("--color-opt", action="store_true",
                   help="also optimize an affine colour correction of each training view "
                        "(exposure and white balance that change between photos; Adam at "
                        "1e-3); held-out views render at the views' average appearance; "
                        "colors.json holds the corrections")
    f.add_argument("--bilateral-grid", action="store_true",
                   help="also optimize a bilateral grid of affine colour maps per training "
                        "view (gsplat's --use_bilateral_grid: 16x16 cells by 8 brightness "
                        "levels, for camera processing that varies over the image; Adam at "
                        "2e-3, total variation weighted 10); held-out views render without "
                        "one; bilateral_grids.npz holds the grids")
    f.add_argument("--app-opt", action="store_true",
                   help="also optimize appearance embeddings (gsplat's --app_opt: a feature "
                        "per Gaussian, an embedding per training view and a small MLP giving "
                        "each Gaussian's colour change in each view, for lighting that changes "
                        "over the scene between photos); held-out views and scene.ply are the "
                        "scene at the views' average appearance; appearance.npz holds the rest")


def _fit_run_options(f) -> None:
    """`fit`'s options beside the recipe: the images' memory, compiles, the window, seed and
    backend, the viewer, resuming."""
    f.add_argument("--uint8-images", action="store_true",
                   help="hold the images as 8-bit values (a quarter of the memory, host and "
                        "device), rounded after compositing, undistortion and --downscale; "
                        "without those, the same results")
    f.add_argument("--stream-images", action=argparse.BooleanOptionalAction, default=None,
                   help="keep only each step's views on the device (copied while the step "
                        "before runs) instead of the whole capture; the same results (default: "
                        "when the images would take more than 1/8 of the device's memory)")
    ahead = f.add_mutually_exclusive_group()
    ahead.add_argument("--compile-ahead-process", action="store_true",
                       help="compile the step for a grown pair buffer ahead in a child process, "
                            "through the persistent compilation cache, instead of a thread (no "
                            "contention for Python's lock; the same results)")
    ahead.add_argument("--no-compile-ahead", action="store_true",
                       help="compile the step for a grown pair buffer only when a step needs "
                            "it (default on a GPU: compile it in a background thread before; "
                            "the same results)")
    f.add_argument("--crop", type=int_at_least(0), nargs=4, metavar=("X0", "Y0", "W", "H"),
                   help="train and evaluate on this window of every image (quick checks)")
    f.add_argument("--seed", type=int, default=0,
                   help="seed of the start, the view order and the strategies' draws")
    f.add_argument("--backend", default=None,
                   choices=["reference", "tiles", "pallas", "pallas_vanilla"],
                   help="differentiable backend (default: pallas on GPUs, tiles elsewhere)")
    f.add_argument("--viewer-port", type=int_at_least(1),
                   help="show the scene in training in a browser at this port (viser, "
                        "`pip install \"lgs_jax[viewer]\"`), updated about once a second, "
                        "and keep serving the trained scene after the run until Ctrl-C")
    f.add_argument("--viewer-host", default="0.0.0.0",
                   help="address the viewer listens on (default: all)")
    again = f.add_mutually_exclusive_group()
    again.add_argument("--resume", action="store_true", help="continue from OUT's checkpoint")
    again.add_argument("--overwrite", action="store_true",
                       help="delete OUT's previous run (its checkpoint, metrics and renders)")


def parser() -> argparse.ArgumentParser:
    """The command line: `render`, `video`, `view`, `info`, `fit` and `eval`, each with
    `--debug`."""
    common = Parser(add_help=False)
    common.add_argument("--debug", action="store_true", help="show tracebacks of errors")
    ap = Parser(prog="python -m lgs_jax", description=__doc__,
                 formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    _render_parser(sub, common)
    video_cmd.parser(sub, common)
    view_cmd.parser(sub, common)
    i = sub.add_parser("info", parents=[common],
                       help="print counts, SH degree, bounds and non-finite values")
    i.add_argument("scene")
    i.set_defaults(func=_info)
    _fit_parser(sub, common)
    eval_cmd.parser(sub, common)
    return ap


def _one_line(e: BaseException) -> str:
    """A one-line message for an error: the file and reason for OS errors, the message for
    ValueErrors (the library's bad-input errors), the type and message otherwise."""
    if isinstance(e, OSError) and e.strerror:
        text = f"{e.filename}: {e.strerror}" if e.filename else e.strerror
    elif isinstance(e, ValueError):
        text = str(e)
    else:
        text = f"{type(e).__name__}: {e} (--debug shows the traceback)"
    return " ".join(text.split())


def ahead_mode(args) -> bool | str | None:
    """`fit`'s compile_ahead from --no-compile-ahead / --compile-ahead-process (None: default)."""
    return False if args.no_compile_ahead else "process" if args.compile_ahead_process else None


def use_compile_cache() -> str | None:
    """Turn on JAX's persistent compilation cache for the command and return its folder: a
    later run with the same shapes loads its programs instead of compiling them again (`fit`
    compiles for 40–80 s on an H200, BENCHMARKS.md §5). The folder is $LGS_JAX_CACHE, else
    ~/.cache/lgs_jax/jax; LGS_JAX_CACHE="" turns it off; a folder the caller already configured
    (`jax_compilation_cache_dir`) is kept."""
    import jax

    if jax.config.jax_compilation_cache_dir:
        return jax.config.jax_compilation_cache_dir
    path = os.environ.get("LGS_JAX_CACHE",
                          os.path.join(os.path.expanduser("~"), ".cache", "lgs_jax", "jax"))
    if not path:
        return None
    jax.config.update("jax_compilation_cache_dir", path)
    return path


def main(argv=None) -> int:
    """Run the command line; returns the exit code (0 success, 1 failure, 2 usage error)."""
    args = parser().parse_args(argv)
    use_compile_cache()
    try:
        return args.func(args)
    except UsageError as e:
        if args.debug:
            raise
        print(f"python -m lgs_jax {args.cmd}: error: {e}", file=sys.stderr)
        return EXIT_USAGE
    except Exception as e:
        if args.debug:
            raise
        print(f"python -m lgs_jax {args.cmd}: error: {_one_line(e)}", file=sys.stderr)
        return EXIT_FAILURE


if __name__ == "__main__":
    sys.exit(main())
