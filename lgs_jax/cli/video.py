"""`python -m lgs_jax video`: a camera path (an orbit fitted to the cameras, or the cameras in
order) rendered and written as an H.264 MP4 (lgs_jax.video)."""

from __future__ import annotations

import time

import numpy as np

from .args import (VIDEO_EXTENSIONS, UsageError, capture_cameras, check_input, check_out,
                   finite_float, int_at_least, load_scene, number_at_least, raster_config,
                   view_options)


def parser(sub, common) -> None:
    """The `video` subcommand's options (lgs_jax.video)."""
    v = sub.add_parser(
        "video", parents=[common], help="render a video along a camera path",
        description="Render a camera path and write it as an H.264 MP4 (--out): an orbit fitted "
                    "to the cameras (the point nearest their optical axes, about their mean up "
                    "axis, at their mean height and distance; lgs_jax.video.orbit_path) or the "
                    "cameras themselves in order, poses interpolated between them. The frames "
                    "share one compiled render. Sizes as `render`'s, and even (H.264).")
    view_options(v)
    v.add_argument("--path", choices=["orbit", "cameras"], default="orbit",
                   help="orbit (default) or the cameras in order")
    v.add_argument("--frames", type=int_at_least(1), default=120, help="default: 120")
    v.add_argument("--fps", type=number_at_least(1.0, float), default=30.0,
                   help="frames per second (default: 30)")
    v.add_argument("--turns", type=finite_float, default=1.0,
                   help="times around the orbit (default: 1; negative turns the other way)")
    v.add_argument("--out", default="video.mp4", help="video to write, .mp4 (default: video.mp4)")
    v.set_defaults(func=run)


def _cameras(args):
    """The cameras a video's path is fitted to: --cameras, or the default scene's 8 orbit views,
    at --width/--height."""
    import lgs_jax
    from lgs_jax import assets as data

    cams = capture_cameras(args, "for a video of")
    if cams is None:
        cams = [lgs_jax.default_camera(v, args.width, args.height)
                for v in range(data.ORBIT_VIEWS)]
    if cams[0].width % 2 or cams[0].height % 2:
        raise UsageError(f"--width/--height: H.264 needs an even width and height, got "
                         f"{cams[0].width}x{cams[0].height}")
    return cams


def run(args) -> int:
    """`video`: check the arguments, fit the path, render every frame, write the MP4."""
    import jax
    from tqdm import tqdm

    from lgs_jax import video

    for path, what in ((args.scene, "scene"), (args.cameras, "--cameras")):
        if path:
            check_input(path, what)
    check_out(args.out, VIDEO_EXTENSIONS, "a video")
    cams = _cameras(args)
    try:
        path = (video.orbit_path(cams, args.frames, args.turns) if args.path == "orbit"
                else video.camera_path(cams, args.frames))
    except ValueError as e:
        raise UsageError(f"--path {args.path}: {e}") from None
    scene = load_scene(args.scene)
    frames = video.render_frames(
        scene, tqdm(path, desc="frames", unit="frame"), args.output, backend=args.backend,
        background=np.asarray(args.background, np.float32),
        config=raster_config(args))
    t0 = time.time()
    count = video.write_video(args.out, frames, fps=args.fps)
    seconds = time.time() - t0
    print(f"scene: {scene.num} Gaussians; {count} frames {path[0].width}x{path[0].height} at "
          f"{args.fps:g} fps; device {jax.devices()[0].platform}; {seconds:.1f} s "
          f"(the first frame compiles)")
    print(f"wrote {args.out}")
    return 0
