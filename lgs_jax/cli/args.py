"""The command line's shared pieces (lgs_jax.cli and its subcommands' modules): one-line usage
errors (exit code 2), option types that name the option and the bad value, input and output path
checks made before any work, and the view options `render` and `video` share."""

from __future__ import annotations

import argparse
import math
import os
import tempfile

from ..config import CONVENTIONS

IMAGE_EXTENSIONS = (".png", ".jpg", ".jpeg", ".tiff", ".webp")  # matplotlib.image.imsave writes
VIDEO_EXTENSIONS = (".mp4",)  # lgs_jax.video.write_video (H.264)
EXIT_FAILURE, EXIT_USAGE, EXIT_INTERRUPTED = 1, 2, 130


class UsageError(Exception):
    """A bad command line found before any work starts (exit code 2)."""


class Parser(argparse.ArgumentParser):
    """argparse with one-line errors (no usage dump), exit code 2."""

    def error(self, message):
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message} (see --help)\n")


def number_at_least(low, kind=int, high=None):
    """An argparse type: a finite number of `kind` (int or float) >= `low` (and <= `high`)."""
    name = "an integer" if kind is int else "a number"

    def parse(text: str):
        try:
            v = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {name}, got {text!r}") from None
        if not math.isfinite(v):
            raise argparse.ArgumentTypeError(f"must be finite, got {text!r}")
        if v < low or (high is not None and v > high):
            bound = f">= {low}" if high is None else f"from {low} to {high}"
            raise argparse.ArgumentTypeError(f"must be {bound}, got {v}")
        return v
    return parse


def int_at_least(low: int):
    """An argparse type: an int >= `low`."""
    return number_at_least(low, int)


finite_float = number_at_least(-math.inf, float)  # an argparse type: a finite float
port = number_at_least(1, int, 65535)  # an argparse type: a TCP port


def check_input(path: str, what: str) -> None:
    """Raise `UsageError` unless `path` is an existing file."""
    if not os.path.exists(path):
        raise UsageError(f"{what}: {path}: no such file")
    if not os.path.isfile(path):
        raise UsageError(f"{what}: {path}: not a file")


def check_out(path: str, extensions=IMAGE_EXTENSIONS, kind: str = "an image") -> None:
    """Raise `UsageError` unless `path` can be written as `kind`: one of `extensions` in an
    existing directory where a file can be written (checked before rendering, not after)."""
    ext = os.path.splitext(path)[1].lower()
    if ext not in extensions:
        raise UsageError(f"--out: {path}: extension {ext or '(none)'!r} is not {kind} format "
                         f"written here; use {' or '.join(extensions)}")
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise UsageError(f"--out: {path}: directory {folder} does not exist")
    if os.path.isdir(path):
        raise UsageError(f"--out: {path} is a directory")
    if not os.access(folder, os.W_OK) or (os.path.exists(path) and not os.access(path, os.W_OK)) \
            or not _writable(folder):
        raise UsageError(f"--out: {path}: not writable")


def check_out_dir(path: str) -> None:
    """Raise `UsageError` unless folder `path` exists or can be made, and takes files (it is
    made here)."""
    if os.path.exists(path) and not os.path.isdir(path):
        raise UsageError(f"--out: {path} is a file, not a folder")
    try:
        os.makedirs(path, exist_ok=True)
    except OSError as e:
        raise UsageError(f"--out: {path}: cannot make the folder ({e.strerror or e})") from None
    if not (os.access(path, os.W_OK) and _writable(path)):
        raise UsageError(f"--out: {path}: not writable")


def _writable(folder: str) -> bool:
    """Whether a file can be made in `folder` (tried: permission bits do not tell for root,
    nor on file systems such as /proc)."""
    try:
        with tempfile.TemporaryFile(dir=folder):
            return True
    except OSError:
        return False


def view_options(p, sizes: bool = True) -> None:
    """The options `render`, `video` and `view` share: the scene, its cameras, the image size
    (with `sizes`), the backend (lgs_jax.BACKENDS), the compositing rule and the background."""
    from ..render import BACKENDS
    from ..video import OUTPUTS

    p.add_argument("scene", nargs="?", help="INRIA PLY file (default: the bundled fruit_drops "
                                            "scene, a label reading MIXED DROPS)")
    p.add_argument("--cameras", help="cameras.json or transforms.json (needed with a scene file)")
    if sizes:
        p.add_argument("--width", type=int_at_least(1), help="image width in pixels (default: "
                       "the camera's, 1280 for the default scene)")
        p.add_argument("--height", type=int_at_least(1), help="image height in pixels "
                       "(default: the camera's, 720 for the default scene)")
    p.add_argument("--backend", default=None, choices=BACKENDS,
                   help="rasterizer (default: the fastest exact one for the platform, pallas on "
                        "a GPU, tiles elsewhere; pallas and pallas_vanilla run interpreted "
                        "without a GPU)")
    p.add_argument("--convention", default="3dgs", choices=CONVENTIONS,
                   help="compositing rule (default: 3dgs)")
    p.add_argument("--antialiased", action="store_true",
                   help="scale opacities so that the 0.3-pixel dilation keeps each Gaussian's "
                        "integral (gsplat's antialiased mode; for scenes trained with it)")
    p.add_argument("--output", choices=OUTPUTS, default="image",
                   help="what to show: the image (default), the expected depth (colour-mapped "
                        "near to far) or the alpha")
    p.add_argument("--background", type=finite_float, nargs=3, default=[0.0, 0.0, 0.0],
                   metavar=("R", "G", "B"), help="background colour (default: 0 0 0, black)")


def load_scene(path: str | None):
    """The scene to render: the PLY at `path` (float64 values cast to float32, with a note,
    where JAX runs without float64: JAX_ENABLE_X64=1 keeps them), or the bundled default."""
    import sys

    import jax
    import numpy as np

    import lgs_jax

    if path is None:
        return lgs_jax.default_scene()
    scene = lgs_jax.load_ply(path)
    if scene.means.dtype == np.float64 and not jax.config.jax_enable_x64:
        print(f"note: {path} holds float64 values; rendering them as float32 "
              f"(JAX_ENABLE_X64=1 keeps float64)", file=sys.stderr)
        scene = lgs_jax.load_ply(path, dtype=np.float32)  # refuses values beyond float32
    return scene


def capture_cameras(args, purpose: str):
    """--cameras at --width/--height where the command has them (`Camera.resized` rules), or
    None for the default scene; a usage error for a file without cameras, or a scene file
    without --cameras (`purpose`: "to render", "to view", "for a video of")."""
    import lgs_jax

    if args.cameras:
        try:
            cams = lgs_jax.load_cameras(args.cameras, width=getattr(args, "width", None),
                                        height=getattr(args, "height", None))
        except UnicodeDecodeError:
            raise ValueError(f"{args.cameras}: not a cameras file (binary, not JSON text: a "
                             f"PLY scene?)") from None
        if not cams:
            raise UsageError(f"--cameras: {args.cameras} holds no cameras")
        return cams
    if args.scene:
        raise UsageError(f"--cameras: needed {purpose} a scene file (the default scene has its "
                         f"own)")
    return None


def chosen_camera(args, purpose: str):
    """The camera `purpose` ("to render", "to view"): `pick_view` of `capture_cameras`."""
    return pick_view(args, capture_cameras(args, purpose))


def pick_view(args, cams):
    """--view of `cams` (loaded by `capture_cameras`; 0 by default), or where `cams` is None of
    the default scene (its framing camera by default); a usage error out of range."""
    import lgs_jax
    from lgs_jax import assets as data

    if cams is not None:
        view = args.view or 0
        if view >= len(cams):
            raise UsageError(f"--view: {view} is out of range: {args.cameras} has {len(cams)} "
                             f"cameras (0..{len(cams) - 1})")
        return cams[view]
    if args.view is not None and args.view >= data.ORBIT_VIEWS:
        raise UsageError(f"--view: {args.view} is out of range: the default scene has "
                         f"{data.ORBIT_VIEWS} orbit views (0..{data.ORBIT_VIEWS - 1})")
    return lgs_jax.default_camera(args.view, getattr(args, "width", None),
                                  getattr(args, "height", None))


def raster_config(args):
    """The `RasterConfig` of --convention and --antialiased."""
    from ..config import RasterConfig

    return RasterConfig(args.convention, antialiased=args.antialiased)


def check_dataset(path: str) -> None:
    """A usage error for a --data that is neither a folder nor a .json file."""
    if not (os.path.isdir(path) or (os.path.isfile(path) and path.endswith(".json"))):
        raise UsageError(f"--data: {path}: not a dataset folder or .json file")
