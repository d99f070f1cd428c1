"""Command line: `python -m lgs_jax render ...`, `video ...` (lgs_jax.video), `info SCENE.ply`
and `fit --data DIR --out DIR [--strategy default|mcmc] [--steps N] ...` (lgs_jax.train).

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

from .config import CONVENTIONS

IMAGE_EXTENSIONS = (".png", ".jpg", ".jpeg", ".tiff", ".webp")  # matplotlib.image.imsave writes
VIDEO_EXTENSIONS = (".mp4",)  # lgs_jax.video.write_video (H.264)
EXIT_FAILURE, EXIT_USAGE = 1, 2


class UsageError(Exception):
    """A bad command line found before any work starts (exit code 2)."""


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors (no usage dump), exit code 2."""

    def error(self, message):
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message} (see --help)\n")


def _number_at_least(low, kind=int):
    """An argparse type: a finite number of `kind` (int or float) >= `low`."""
    name = "an integer" if kind is int else "a number"

    def parse(text: str):
        try:
            v = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {name}, got {text!r}") from None
        if not math.isfinite(v):
            raise argparse.ArgumentTypeError(f"must be finite, got {text!r}")
        if v < low:
            raise argparse.ArgumentTypeError(f"must be >= {low}, got {v}")
        return v
    return parse


def _int_at_least(low: int):
    """An argparse type: an int >= `low`."""
    return _number_at_least(low, int)


def _finite_float(text: str) -> float:
    """An argparse type: a finite float (no nan or inf)."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"must be finite, got {text!r}")
    return v


def _check_input(path: str, what: str) -> None:
    """Raise `UsageError` unless `path` is an existing file."""
    if not os.path.exists(path):
        raise UsageError(f"{what}: {path}: no such file")
    if not os.path.isfile(path):
        raise UsageError(f"{what}: {path}: not a file")


def _check_out(path: str, extensions=IMAGE_EXTENSIONS, kind: str = "an image") -> None:
    """Raise `UsageError` unless `path` can be written as `kind`: one of `extensions` in an
    existing, writable directory (checked before rendering, not after)."""
    ext = os.path.splitext(path)[1].lower()
    if ext not in extensions:
        raise UsageError(f"--out: {path}: extension {ext or '(none)'!r} is not {kind} format "
                         f"written here; use {' or '.join(extensions)}")
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise UsageError(f"--out: {path}: directory {folder} does not exist")
    if os.path.isdir(path):
        raise UsageError(f"--out: {path} is a directory")
    if not os.access(folder, os.W_OK) or (os.path.exists(path) and not os.access(path, os.W_OK)):
        raise UsageError(f"--out: {path}: not writable")


def _camera(args):
    """The camera to render: --view of --cameras (0 by default), or of the default scene (its
    framing camera by default), resized by --width/--height."""
    import lgs_jax
    from lgs_jax import data

    if args.cameras:
        cams = lgs_jax.load_cameras(args.cameras, width=args.width, height=args.height)
        if not cams:
            raise UsageError(f"--cameras: {args.cameras} holds no cameras")
        view = args.view or 0
        if view >= len(cams):
            raise UsageError(f"--view: {view} is out of range: {args.cameras} has {len(cams)} "
                             f"cameras (0..{len(cams) - 1})")
        return cams[view]
    if args.scene:
        raise UsageError("--cameras: needed to render a scene file (the default scene has its own)")
    if args.view is not None and args.view >= data.ORBIT_VIEWS:
        raise UsageError(f"--view: {args.view} is out of range: the default scene has "
                         f"{data.ORBIT_VIEWS} orbit views (0..{data.ORBIT_VIEWS - 1})")
    return lgs_jax.default_camera(args.view, args.width, args.height)


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
            _check_input(path, what)
    _check_out(args.out)
    scene = lgs_jax.load_ply(args.scene) if args.scene else lgs_jax.default_scene()
    cam = _camera(args)
    out, seconds, compiling = _timed_render(
        scene, cam, background=np.asarray(args.background, np.float32), backend=args.backend,
        config=lgs_jax.RasterConfig(convention=args.convention))
    s = out.stats
    print(f"scene: {scene.num} Gaussians (SH degree {scene.sh_degree}); image {cam.width}x"
          f"{cam.height}; backend {s.backend}; device {jax.devices()[0].platform}")
    print(f"time: {seconds:.3f} s, of which {compiling:.3f} s compiling (a first call at a new "
          f"size compiles) and {seconds - compiling:.3f} s rendering")
    if s.interpreted:
        print("note: the Pallas kernel ran in interpret mode (no GPU): exact but slow")
    print(f"valid {int(s.n_valid)}, invalid {int(s.n_invalid)}, below 1/255 "
          f"{int(s.n_transparent)}, unbounded {int(s.n_unbounded)}; tile-Gaussian pairs "
          f"{int(s.pairs_required)} (capacity {int(s.capacity)})")
    import matplotlib.image

    matplotlib.image.imsave(args.out, np.clip(np.asarray(out.image), 0.0, 1.0))
    print(f"wrote {args.out}")
    return 0


def _video_cameras(args):
    """The cameras a video's path is fitted to: --cameras, or the default scene's 8 orbit views,
    at --width/--height."""
    import lgs_jax
    from lgs_jax import data

    if args.cameras:
        cams = lgs_jax.load_cameras(args.cameras, width=args.width, height=args.height)
        if not cams:
            raise UsageError(f"--cameras: {args.cameras} holds no cameras")
    elif args.scene:
        raise UsageError("--cameras: needed for a video of a scene file (the default scene has "
                         "its own)")
    else:
        cams = [lgs_jax.default_camera(v, args.width, args.height)
                for v in range(data.ORBIT_VIEWS)]
    if cams[0].width % 2 or cams[0].height % 2:
        raise UsageError(f"--width/--height: H.264 needs an even width and height, got "
                         f"{cams[0].width}x{cams[0].height}")
    return cams


def _video(args) -> int:
    """`video`: check the arguments, fit the path, render every frame, write the MP4."""
    import jax
    from tqdm import tqdm

    import lgs_jax
    from lgs_jax import video

    for path, what in ((args.scene, "scene"), (args.cameras, "--cameras")):
        if path:
            _check_input(path, what)
    _check_out(args.out, VIDEO_EXTENSIONS, "a video")
    cams = _video_cameras(args)
    try:
        path = (video.orbit_path(cams, args.frames, args.turns) if args.path == "orbit"
                else video.camera_path(cams, args.frames))
    except ValueError as e:
        raise UsageError(f"--path {args.path}: {e}") from None
    scene = lgs_jax.load_ply(args.scene) if args.scene else lgs_jax.default_scene()
    frames = video.render_frames(
        scene, tqdm(path, desc="frames", unit="frame"), backend=args.backend,
        background=np.asarray(args.background, np.float32),
        config=lgs_jax.RasterConfig(convention=args.convention))
    t0 = time.time()
    count = video.write_video(args.out, frames, fps=args.fps)
    seconds = time.time() - t0
    print(f"scene: {scene.num} Gaussians; {count} frames {path[0].width}x{path[0].height} at "
          f"{args.fps:g} fps; device {jax.devices()[0].platform}; {seconds:.1f} s "
          f"(the first frame compiles)")
    print(f"wrote {args.out}")
    return 0


def _info(args) -> int:
    """`info`: counts, SH degree, bounds and non-finite values of a PLY."""
    import lgs_jax

    _check_input(args.scene, "scene")
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
    import dataclasses

    from . import train

    if not (os.path.isdir(args.data) or (os.path.isfile(args.data)
                                         and args.data.endswith(".json"))):
        raise UsageError(f"--data: {args.data}: not a dataset folder or .json file")
    problem = train.run_dir_problem(args.out, args.resume, args.overwrite)
    if problem:
        raise UsageError(f"--out: {problem}")
    settings = dataclasses.replace(train.Settings(), batch=args.batch,
                                   eval_every=args.eval_every, init_points=args.init_points,
                                   convention=args.convention, pair_headroom=args.pair_headroom,
                                   row_headroom=args.row_headroom)
    if args.strategy == "mcmc":
        strategy = train.MCMCStrategy(cap_max=args.max_gaussians)
    else:
        strategy = train.DefaultStrategy(opacity_reset=args.opacity_reset)
    result = train.fit(args.data, args.steps, args.out, strategy=strategy, settings=settings,
                       max_gaussians=args.max_gaussians, downscale=args.downscale,
                       crop=tuple(args.crop) if args.crop else None, seed=args.seed,
                       backend=args.backend, pool_size=args.pool_size, resume=args.resume,
                       overwrite=args.overwrite,
                       compile_ahead=ahead_mode(args))
    print(json.dumps(result, indent=1))
    return 0


def _view_options(p) -> None:
    """The options `render` and `video` share: the scene, its cameras, the image size, the
    backend (lgs_jax.BACKENDS), the compositing rule and the background."""
    from .render import BACKENDS

    p.add_argument("scene", nargs="?", help="INRIA PLY file (default: the bundled fruit_drops "
                                            "scene, a label reading MIXED DROPS)")
    p.add_argument("--cameras", help="cameras.json or transforms.json (needed with a scene file)")
    p.add_argument("--width", type=_int_at_least(1),
                   help="image width in pixels (default: the camera's, 1280 for the default scene)")
    p.add_argument("--height", type=_int_at_least(1),
                   help="image height in pixels (default: the camera's, 720 for the default scene)")
    p.add_argument("--backend", default=None, choices=BACKENDS,
                   help="rasterizer (default: the fastest exact one for the platform, pallas on "
                        "a GPU, tiles elsewhere; pallas and pallas_vanilla run interpreted "
                        "without a GPU)")
    p.add_argument("--convention", default="3dgs", choices=CONVENTIONS,
                   help="compositing rule (default: 3dgs)")
    p.add_argument("--background", type=_finite_float, nargs=3, default=[0.0, 0.0, 0.0],
                   metavar=("R", "G", "B"), help="background colour (default: 0 0 0, black)")


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
    _view_options(r)
    r.add_argument("--view", type=_int_at_least(0),
                   help="camera index (default: 0 of --cameras; for the default scene its "
                        "framing camera, or orbit view 0..7)")
    r.add_argument("--out", default="out.png",
                   help=f"image to write, {'/'.join(IMAGE_EXTENSIONS)} (default: out.png)")
    r.set_defaults(func=_render)


def _video_parser(sub, common) -> None:
    """The `video` subcommand's options (lgs_jax.video)."""
    v = sub.add_parser(
        "video", parents=[common], help="render a video along a camera path",
        description="Render a camera path and write it as an H.264 MP4 (--out): an orbit fitted "
                    "to the cameras (the point nearest their optical axes, about their mean up "
                    "axis, at their mean height and distance; lgs_jax.video.orbit_path) or the "
                    "cameras themselves in order, poses interpolated between them. The frames "
                    "share one compiled render. Sizes as `render`'s, and even (H.264).")
    _view_options(v)
    v.add_argument("--path", choices=["orbit", "cameras"], default="orbit",
                   help="orbit (default) or the cameras in order")
    v.add_argument("--frames", type=_int_at_least(1), default=120, help="default: 120")
    v.add_argument("--fps", type=_number_at_least(1.0, float), default=30.0,
                   help="frames per second (default: 30)")
    v.add_argument("--turns", type=_finite_float, default=1.0,
                   help="times around the orbit (default: 1; negative turns the other way)")
    v.add_argument("--out", default="video.mp4", help="video to write, .mp4 (default: video.mp4)")
    v.set_defaults(func=_video)


def _fit_parser(sub, common) -> None:
    """The `fit` subcommand's options."""
    from .train.settings import Settings

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
    f.add_argument("--steps", type=_int_at_least(0), default=30000,
                   help="training steps (default: 30000)")
    f.add_argument("--strategy", choices=["default", "mcmc"], default="default",
                   help="densification: default (3DGS clone/split/prune, gsplat's "
                        "DefaultStrategy) or mcmc (3DGS as MCMC, gsplat's MCMCStrategy, with "
                        "its recipe: init opacity 0.5, scale 0.1, regularisers 0.01)")
    f.add_argument("--max-gaussians", type=_int_at_least(1), default=1_000_000,
                   help="cap on the number of Gaussians (the pool's; MCMC's cap_max) "
                        "(default: 1000000)")
    f.add_argument("--downscale", type=_int_at_least(1), default=1,
                   help="integer image downscale at load (default: 1)")
    f.add_argument("--pool-size", type=_int_at_least(1),
                   help="initial pool slots (default: the next power of two above the initial "
                        "count; the pool doubles when it must, recompiling once each time)")
    f.add_argument("--init-points", type=_int_at_least(1), default=100_000,
                   help="random initial points for datasets without SfM points (default: "
                        "100000)")
    f.add_argument("--opacity-reset", action="store_true",
                   help="default strategy: reset opacities every 3000 steps (3DGS; gsplat "
                        "1.5.3 never does, through a bug)")
    f.add_argument("--batch", type=_int_at_least(1), default=1, help="views per step")
    f.add_argument("--convention", choices=CONVENTIONS, default="3dgs",
                   help="compositing rule of training and evaluation renders (alpha cap 0.99 "
                        "or gsplat's 0.999)")
    f.add_argument("--eval-every", type=_int_at_least(1), default=500,
                   help="steps between held-out evaluations (default: 500)")
    f.add_argument("--pair-headroom", type=_number_at_least(1.0, float),
                   default=Settings.pair_headroom,
                   help="pair buffer size as a multiple of a view's pairs, at the start and at "
                        "each growth (a recompile); larger: fewer recompiles, larger buffers "
                        f"(default: {Settings.pair_headroom:g})")
    f.add_argument("--row-headroom", type=_number_at_least(1.0, float), default=None,
                   help="size the Pallas backward's gradient rows to this multiple of the "
                        "walked pairs, growing them when a view walks more (a recompile each): "
                        "less memory, the same results (default: a row per pair slot)")
    ahead = f.add_mutually_exclusive_group()
    ahead.add_argument("--compile-ahead-process", action="store_true",
                       help="compile the step for a grown pair buffer ahead in a child process, "
                            "through the persistent compilation cache, instead of a thread (no "
                            "contention for Python's lock; the same results)")
    ahead.add_argument("--no-compile-ahead", action="store_true",
                       help="compile the step for a grown pair buffer only when a step needs "
                            "it (default on a GPU: compile it in a background thread before; "
                            "the same results)")
    f.add_argument("--crop", type=_int_at_least(0), nargs=4, metavar=("X0", "Y0", "W", "H"),
                   help="train and evaluate on this window of every image (quick checks)")
    f.add_argument("--seed", type=int, default=0,
                   help="seed of the start, the view order and the strategies' draws")
    f.add_argument("--backend", default=None,
                   choices=["reference", "tiles", "pallas", "pallas_vanilla"],
                   help="differentiable backend (default: pallas on GPUs, tiles elsewhere)")
    again = f.add_mutually_exclusive_group()
    again.add_argument("--resume", action="store_true", help="continue from OUT's checkpoint")
    again.add_argument("--overwrite", action="store_true",
                       help="delete OUT's previous run (its checkpoint, metrics and renders)")
    f.set_defaults(func=_fit)


def _parser() -> argparse.ArgumentParser:
    """The command line: `render`, `video`, `info` and `fit`, each with `--debug`."""
    common = _Parser(add_help=False)
    common.add_argument("--debug", action="store_true", help="show tracebacks of errors")
    ap = _Parser(prog="python -m lgs_jax", description=__doc__,
                 formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    _render_parser(sub, common)
    _video_parser(sub, common)
    i = sub.add_parser("info", parents=[common],
                       help="print counts, SH degree, bounds and non-finite values")
    i.add_argument("scene")
    i.set_defaults(func=_info)
    _fit_parser(sub, common)
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
    args = _parser().parse_args(argv)
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
