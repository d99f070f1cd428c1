"""The bundled default scene: `fruit_drops` (4,721 Gaussians, SH degree 3, MIT, PlayCanvas
SuperSplat; see LICENSE.fruit_drops.txt), a label reading "MIXED DROPS", with a framing camera
(the default) and its 8 orbit cameras (1280x720, vertical field of view 50°)."""

from __future__ import annotations

import math
from importlib import resources

import numpy as np

SCENE = "fruit_drops.ply"
CAMERAS = "fruit_drops_cameras.json"
ORBIT_VIEWS = 8  # cameras in CAMERAS
WIDTH, HEIGHT = 1280, 720  # the default image size (the orbit cameras')
FOV_Y = math.radians(50.0)  # the orbit cameras' vertical field of view
# The label lies in a plane z ~ -2.1 and is read from +z with world +y pointing down the text;
# the framing camera looks at it from the orbit's 20° elevation (head-on shows more streaks).
FORWARD = np.array([0.0, math.sin(math.radians(20.0)), -math.cos(math.radians(20.0))])
DOWN = np.array([0.0, 1.0, 0.0])
MARGIN = 0.05  # share of each half-image left empty around the scene's box
QUANTILE = 0.5  # percent of means left out on each side of the box (stray Gaussians)


def default_scene():
    """The bundled fruit_drops scene as float32 `Gaussians`."""
    from ..io.ply import load_ply

    with resources.as_file(resources.files(__name__) / SCENE) as path:
        return load_ply(path)


def default_camera(view: int | None = None, width: int | None = None,
                   height: int | None = None):
    """A camera of the default scene, 1280x720 unless another size is given.

    `view` None (the default): the framing camera, which shows the whole label in focus (see
    `framing_camera`), framed anew for the requested size. `view` 0..7: that orbit camera,
    resized with `Camera.resized` (one side given: the aspect ratio is kept; both: scaled to
    cover, centre-cropped). Raises `ValueError` for a view outside 0..7 or a bad size.
    """
    from ..io.cameras import load_cameras

    if view is None:
        width, height = _size(width, height)
        return framing_camera(default_scene(), FORWARD, DOWN, width, height)
    if not isinstance(view, (int, np.integer)) or isinstance(view, bool) \
            or not 0 <= view < ORBIT_VIEWS:
        raise ValueError(f"view: expected None (the framing camera) or an orbit view 0.."
                         f"{ORBIT_VIEWS - 1}, got {view!r}")
    with resources.as_file(resources.files(__name__) / CAMERAS) as path:
        return load_cameras(path, width=width, height=height)[view]


def _size(width, height) -> tuple[int, int]:
    """(width, height): WIDTHxHEIGHT by default; one given side keeps that aspect ratio."""
    from ..scene import check_size

    for name, v in (("width", width), ("height", height)):
        if v is not None:
            check_size(name, v)
    if width is None and height is None:
        return WIDTH, HEIGHT
    if width is None:
        return max(1, round(WIDTH * height / HEIGHT)), height
    if height is None:
        return width, max(1, round(HEIGHT * width / WIDTH))
    return width, height


def framing_camera(gaussians, forward, down, width: int, height: int, fov_y: float = FOV_Y,
                   margin: float = MARGIN, quantile: float = QUANTILE):
    """A pinhole camera looking along `forward` at the opacity-weighted centre of `gaussians`
    (image "down" as close to `down` as `forward` allows), from the nearest distance at which
    every corner of the box between the `quantile` and 100 − `quantile` percentiles of the
    finite means projects inside the image with `margin` of each half-image to spare."""
    from ..scene import Camera

    means = np.asarray(gaussians.means, np.float64)
    opacity = 1 / (1 + np.exp(-np.asarray(gaussians.logit_opacities, np.float64)))
    ok = np.all(np.isfinite(means), -1) & np.isfinite(opacity)
    means, opacity = means[ok], opacity[ok]
    centre = opacity @ means / opacity.sum()
    lo, hi = np.percentile(means, [quantile, 100 - quantile], axis=0)
    f = np.asarray(forward, np.float64) / np.linalg.norm(forward)
    right = np.cross(down, f)
    right /= np.linalg.norm(right)
    rot = np.stack([right, np.cross(f, right), f])  # world-to-camera rows: x right, y down, z
    corners = np.stack(np.meshgrid(*zip(lo, hi), indexing="ij"), -1).reshape(-1, 3)
    rel = (corners - centre) @ rot.T
    focal = 0.5 * height / math.tan(0.5 * fov_y)
    half = (1 - margin) * np.array([width / 2, height / 2])
    distance = max(np.max(focal * np.abs(rel[:, i]) / half[i] - rel[:, 2]) for i in (0, 1))
    view = np.eye(4)
    view[:3, :3] = rot
    view[:3, 3] = -rot @ (centre - distance * f)
    return Camera(viewmat=view.astype(np.float32), fx=np.float32(focal), fy=np.float32(focal),
                  cx=np.float32(width / 2), cy=np.float32(height / 2), width=width,
                  height=height)
