"""Camera files: INRIA cameras.json and NeRF-synthetic transforms.json."""

from __future__ import annotations

import json
import math
import os

import numpy as np

from ..scene import Camera


def _inria_camera(c: dict, width: int | None, height: int | None) -> Camera:
    """`rotation` holds the camera-to-world rotation (rows), `position` the camera centre."""
    rot = np.asarray(c["rotation"], np.float64)
    pos = np.asarray(c["position"], np.float64)
    view = np.eye(4)
    view[:3, :3] = rot.T
    view[:3, 3] = -rot.T @ pos
    cam = Camera(viewmat=view.astype(np.float32), fx=np.float32(c["fx"]), fy=np.float32(c["fy"]),
                 cx=np.float32(c.get("cx", c["width"] / 2)),
                 cy=np.float32(c.get("cy", c["height"] / 2)),
                 width=int(c["width"]), height=int(c["height"]))
    if width is not None or height is not None:
        cam = cam.scaled(width or cam.width, height or cam.height)
    return cam


def _image_size(path: str) -> tuple[int, int]:
    import matplotlib.image

    h, w = matplotlib.image.imread(path).shape[:2]
    return w, h


def _nerf_cameras(meta: dict, root: str, width, height) -> list[Camera]:
    frames = meta["frames"]
    if width is None or height is None:
        first = os.path.join(root, frames[0]["file_path"])
        if not os.path.splitext(first)[1]:
            first += ".png"
        w, h = _image_size(first)
        width, height = width or w, height or h
    fx = 0.5 * width / math.tan(0.5 * meta["camera_angle_x"])
    fy = 0.5 * height / math.tan(0.5 * meta["camera_angle_y"]) if "camera_angle_y" in meta else fx
    cams = []
    for fr in frames:
        c2w = np.asarray(fr["transform_matrix"], np.float64)
        c2w[:3, 1:3] *= -1  # Blender/OpenGL camera axes -> OpenCV (y down, z forward)
        view = np.linalg.inv(c2w)
        cams.append(Camera(viewmat=view.astype(np.float32), fx=np.float32(fx), fy=np.float32(fy),
                           cx=np.float32(width / 2), cy=np.float32(height / 2),
                           width=int(width), height=int(height)))
    return cams


def load_cameras(path, *, width: int | None = None, height: int | None = None) -> list[Camera]:
    """Cameras from an INRIA cameras.json (list of views) or a NeRF transforms.json.

    `width`/`height` rescale INRIA cameras (intrinsics scaled per axis); for NeRF files they give
    the image size, read from the first frame's image where not given.
    """
    path = os.fspath(path)
    with open(path) as f:
        meta = json.load(f)
    if isinstance(meta, list):
        return [_inria_camera(c, width, height) for c in meta]
    if isinstance(meta, dict) and "frames" in meta:
        return _nerf_cameras(meta, os.path.dirname(path), width, height)
    raise ValueError(f"{path}: neither an INRIA cameras.json list nor a transforms.json")
