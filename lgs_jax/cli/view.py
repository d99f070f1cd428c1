"""`python -m lgs_jax view`: the scene in a browser (lgs_jax.viewer, viser's server), starting
at a camera of the capture; and `fit --viewer-port`'s viewer of the scene in training."""

from __future__ import annotations

import numpy as np

from .args import (capture_cameras, check_input, int_at_least, load_scene, pick_view, port,
                   raster_config, view_options)


def parser(sub, common) -> None:
    """The `view` subcommand's options."""
    v = sub.add_parser(
        "view", parents=[common], help="view a scene in a browser (viser)",
        description="Serve the scene to a browser (http://localhost:PORT): the mouse orbits, "
                    "pans and zooms, and every camera change renders the view at the canvas's "
                    "aspect ratio, its longer side --max-size pixels (a slider in the page "
                    "changes it; a new size compiles once). The cameras are drawn; a click on "
                    "one moves the view there. Needs viser: pip install "
                    "\"lgs_jax[viewer]\". Ctrl-C stops.")
    view_options(v, sizes=False)
    v.add_argument("--view", type=int_at_least(0),
                   help="the camera to start at (default: 0 of --cameras; for the default "
                        "scene its framing camera)")
    v.add_argument("--port", type=port, default=8080,
                   help="HTTP port (default: 8080; the next free one if taken)")
    v.add_argument("--host", default="0.0.0.0", help="address to listen on (default: all)")
    v.add_argument("--max-size", type=int_at_least(16), default=1024,
                   help="longer side of the rendered frames in pixels (default: 1024)")
    v.set_defaults(func=run)


def run(args) -> int:
    """`view`: check the arguments, load, serve until Ctrl-C."""
    from lgs_jax import viewer

    for path, what in ((args.scene, "scene"), (args.cameras, "--cameras")):
        if path:
            check_input(path, what)
    cams, start = _cameras(args)
    scene = load_scene(args.scene)
    viewer.serve(scene, cams, start=start, host=args.host, port=args.port,
                 max_size=args.max_size, output=args.output, backend=args.backend,
                 background=np.asarray(args.background, np.float32), config=raster_config(args))
    return 0


def _cameras(args):
    """(cameras drawn in the viewer, the one to start at): those of --cameras, or the default
    scene's orbit views (its framing camera first unless --view picks one)."""
    import lgs_jax
    from lgs_jax import assets as data

    cams = capture_cameras(args, "to view")
    chosen = pick_view(args, cams)  # checks --view
    if cams is not None:
        return cams, args.view or 0
    orbit = [lgs_jax.default_camera(v) for v in range(data.ORBIT_VIEWS)]
    return ([chosen] + orbit, 0) if args.view is None else (orbit, args.view)


def training_viewer(args, config, data):
    """(watch, served) for `fit --viewer-port`: a viewer of the training cameras of `data` (a
    `Dataset`; all of them with config.train_on_all), starting at the first, and `fit`'s
    `watch` that shows each scene it is given, with the step, the active Gaussians and the
    training loss and PSNR above the frames."""
    from lgs_jax import viewer

    cams = list(data.cameras) if config.train_on_all else [data.cameras[i] for i in data.train]
    served = viewer.serve(None, cams, host=args.viewer_host, port=args.viewer_port,
                          max_size=1024, block=False, headroom=2.0, backend=config.backend,
                          background=np.asarray(data.background, np.float32),
                          config=config.recipe.raster)

    def watch(step: int, gaussians, metrics: dict) -> None:
        text = f"step {step} of {config.steps}, {metrics['gaussians']:,} Gaussians"
        if "loss" in metrics:
            text += f", loss {metrics['loss']:.4f}, PSNR {metrics['psnr']:.2f} dB"
        served.show(gaussians, text)

    return watch, served
