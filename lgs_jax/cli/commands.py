"""Command line: `python -m lgs_jax render ...`, `video ...` (lgs_jax.video), `view ...`
(lgs_jax.viewer), `info SCENE.ply`, `fit --data DIR --out DIR [--strategy default|mcmc]
[--steps N] ...` (lgs_jax.train) and `eval SCENE.ply --data DIR` (lgs_jax.train.evaluate).

Compiled programs are kept in JAX's persistent cache (`use_compile_cache`: $LGS_JAX_CACHE,
default ~/.cache/lgs_jax/jax; LGS_JAX_CACHE="" turns it off).

Errors are one line on stderr: exit code 2 for a bad command line (checked before any work:
options, input paths, --view, --out, an existing fit run), 1 for a failure while working (a
malformed file, a render error), 130 for Ctrl-C; `--debug` shows the traceback instead.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time

import numpy as np

from . import eval as eval_cmd, fit as fit_cmd, video as video_cmd, view as view_cmd
from .args import (EXIT_FAILURE, EXIT_INTERRUPTED, EXIT_USAGE, IMAGE_EXTENSIONS, Parser,
                   UsageError, check_input, check_out, chosen_camera, int_at_least,
                   load_scene, raster_config, view_options)


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


    for path, what in ((args.scene, "scene"), (args.cameras, "--cameras")):
        if path:
            check_input(path, what)
    check_out(args.out)
    scene = load_scene(args.scene)
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

    from ..files import written
    from ..video import frame_pixels

    with written(args.out) as tmp:
        matplotlib.image.imsave(tmp, frame_pixels(out, args.output))
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
    fit_cmd.parser(sub, common)
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


CACHE_MAX_BYTES = 16 << 30
"""The persistent cache's size cap. With a cap JAX evicts the least recently used entries and
locks the folder around each read and write (the filelock package); without one it writes an
entry in place, unlocked, and a process sharing the folder (a second run) can read an entry
still being written and crash loading it. The cost: each write scans the folder (a
fraction of a second for thousands of entries)."""


def cache_into(path: str, least_seconds: float = 0.0) -> None:
    """JAX's persistent compilation cache in `path`: programs that took `least_seconds` or
    more to compile, the folder capped at `CACHE_MAX_BYTES` and locked around each access, so
    that processes may share it."""
    import jax

    jax.config.update("jax_compilation_cache_dir", path)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", least_seconds)
    jax.config.update("jax_compilation_cache_max_size", CACHE_MAX_BYTES)


def use_compile_cache() -> str | None:
    """Turn on JAX's persistent compilation cache for the command and return its folder: a
    later run with the same shapes loads its programs instead of compiling them again, every
    program however short its compile (JAX's default keeps only those that took a second or
    more; a run's dozens of small programs, the eager operations' included, each compile in a
    fraction of a second). The folder is $LGS_JAX_CACHE, else ~/.cache/lgs_jax/jax;
    LGS_JAX_CACHE="" turns it off; a folder the caller already configured
    (`jax_compilation_cache_dir`) is kept, with the caller's settings. `cache_into` sets it."""
    import jax

    if jax.config.jax_compilation_cache_dir:
        return jax.config.jax_compilation_cache_dir
    path = os.environ.get("LGS_JAX_CACHE",
                          os.path.join(os.path.expanduser("~"), ".cache", "lgs_jax", "jax"))
    if not path:
        return None
    cache_into(path)
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
    except KeyboardInterrupt:
        if args.debug:
            raise
        print(f"python -m lgs_jax {args.cmd}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except Exception as e:
        if args.debug:
            raise
        print(f"python -m lgs_jax {args.cmd}: error: {_one_line(e)}", file=sys.stderr)
        return EXIT_FAILURE


if __name__ == "__main__":
    sys.exit(main())
